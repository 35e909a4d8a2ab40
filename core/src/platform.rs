//! What the platform implements: the sensors behind sensor-based actions and the actuator
//! behaviours behind actuator-based actions.
//!
//! One implementation serves every sensor (or action) of a platform, dispatched by id: async
//! trait methods cannot be called through `dyn` without allocation, and a `match` on the id
//! compiles to a jump table. Methods take `&self` because sensors and actuators run at the same
//! time; platforms keep their state in cells or mutexes.

use core::future::Future;
use core::pin::Pin;
use core::task::{Context, Poll};

use embassy_futures::select::{Either, select};
use embassy_time::{Duration, Instant, Timer};

use crate::action::{ActionId, SensorId};
use crate::facts::FactSetOf;
use crate::failure::{SensorFault, Violation};
use crate::plan::PlanId;
use crate::store::{Entry, Key, MutualStore, SAMPLE_KEY, StoreFull, Value};

/// Most `(key, value)` pairs one [`Reading`] carries besides its main value.
pub const MAX_PAIRS: usize = 4;

/// One sample of a sensor: the measured value, the perception facts it makes true, and any
/// further `(k', v')` pairs the sensor puts into its own store (Algorithm 3 line 6: a sonar's
/// echo time, an IMU's three axes). In a runtime whose fact sets have `W` words (1 by default).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Reading<const W: usize = 1> {
    /// The measurement, stored under [`SAMPLE_KEY`] in the sensor's data store.
    pub value: Value,
    /// The facts of `per(s)` that hold according to this sample; the facts of `per(s)` not in
    /// `holds` are false. Facts outside `per(s)` are ignored.
    pub holds: FactSetOf<W>,
    pairs: [Option<(Key, Value)>; MAX_PAIRS],
}

/// [`Reading::put`] found no room, or was given [`SAMPLE_KEY`]: the pair is handed back.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PairRejected {
    /// The key.
    pub key: Key,
    /// The value that was not kept.
    pub value: Value,
}

impl<const W: usize> Reading<W> {
    /// A reading of `value` under which the facts `holds` of `per(s)` are true.
    pub const fn new(value: Value, holds: FactSetOf<W>) -> Self {
        Self {
            value,
            holds,
            pairs: [None; MAX_PAIRS],
        }
    }

    /// Adds a `(key, value)` pair for the sensor's store, or replaces the value of a key already
    /// added. At most [`MAX_PAIRS`] keys; [`SAMPLE_KEY`] belongs to [`value`](Self::value).
    /// The store keeps a key until a later sample puts it again (Algorithm 3 line 6 adds to the
    /// store), so a sensor whose readings carry a key only sometimes should put it every time,
    /// or readers compare its instant with the sample's.
    pub fn put(&mut self, key: Key, value: Value) -> Result<(), PairRejected> {
        let rejected = PairRejected { key, value };
        if key == SAMPLE_KEY {
            return Err(rejected);
        }
        let slot = self
            .pairs
            .iter_mut()
            .find(|p| p.is_none_or(|(k, _)| k == key))
            .ok_or(rejected)?;
        *slot = Some((key, value));
        Ok(())
    }

    /// A reading of `value` that decides every fact of `per(s)` one way: all hold when `holds`,
    /// none otherwise (a switch, a threshold on a distance).
    pub const fn of(value: Value, holds: bool) -> Self {
        Self::new(
            value,
            if holds {
                FactSetOf::ALL
            } else {
                FactSetOf::EMPTY
            },
        )
    }

    /// A yes/no sensor's reading: [`Value::Bool`] and, when `true`, every fact of `per(s)`.
    pub const fn flag(on: bool) -> Self {
        Self::of(Value::Bool(on), on)
    }

    /// The reading with the pair `(key, value)` added ([`put`](Self::put)).
    pub fn with(mut self, key: Key, value: Value) -> Result<Self, PairRejected> {
        self.put(key, value).map(|()| self)
    }

    /// The pairs besides the main value, in the order they were added.
    pub fn pairs(&self) -> impl Iterator<Item = (Key, Value)> + '_ {
        self.pairs.iter().flatten().copied()
    }
}

/// How an actuator behaviour ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Outcome {
    /// The action achieved its effects.
    Success,
    /// The action could not achieve its effects.
    Failure,
    /// The behaviour stopped because its precondition no longer held.
    Interrupted,
}

/// The sensors of a platform (the sensing side: the paper's sensory controller).
///
/// Every running sensor has a sampler of its own in [`SensingSide::run`](crate::SensingSide::run):
/// its methods are called for one sensor at a time, but calls for *different* sensors overlap.
///
/// * A call may await I/O for as long as the device needs (an ultrasonic echo up to 38 ms, a
///   time-of-flight conversion, a bus transaction): the await costs the other sensors nothing.
///   Their samplers keep their own instants, and nothing on the deciding side waits for it.
/// * A call must not *block* (spin on a register, `block_for`): that stalls the executor and
///   with it every sensor on it. Wait for an interrupt, a DMA completion or a timer instead.
/// * A call can be cancelled at an await point (dropped): when it outlives the sensor's
///   timeout, or when the state that needs the sensor ends. Leave the device in a state the
///   next call can start from.
/// * A sample describes the world at the instant it started: the runtime stamps its values
///   with that instant, and delivers them when the call returns.
///
/// `W` is the width of the runtime's fact sets in words (1, up to 64 facts, by default).
///
/// Which sensor a call is for is [`Self::Id`]: the `Sensor` enum of a mission compiled in with
/// [`include_mission!`](crate::include_mission) (`type Id = dock::Sensor;`), whose exhaustive
/// `match` the compiler checks, or [`SensorId`] for a mission loaded at run time.
#[allow(async_fn_in_trait)] // Runs on single-threaded executors: no `Send` bound wanted.
pub trait Sensor<const W: usize = 1> {
    /// How a call names its sensor: a compiled mission's `Sensor` enum, or [`SensorId`].
    type Id: FromId<SensorId>;

    /// Powers the sensor up. Called when a state that needs it starts (least commitment).
    async fn switch_on(&self, sensor: Self::Id) -> Result<(), SensorFault>;
    /// Powers the sensor down. Called when the action it serves ends.
    async fn switch_off(&self, sensor: Self::Id);
    /// Takes one sample. The runtime bounds it with the sensor's timeout. `Ok(None)` means this
    /// sample was lost (an echo that never came back); the runtime keeps the previous belief
    /// and fails the state after [`Config::max_lost`](crate::runtime::engine::Config::max_lost) losses in
    /// a row.
    async fn sample(&self, sensor: Self::Id) -> Result<Option<Reading<W>>, SensorFault>;

    /// Whether [`wake`](Self::wake) may complete. A platform whose sensors never make a sample
    /// due early may say `false`: the runtime then neither builds nor polls the `wake` future
    /// between samples (a few dozen instructions a sample on a host). With `false` an
    /// overridden `wake` is not called.
    const WAKES: bool = true;

    /// Completes when something makes a cyclic sensor's next sample due before its period
    /// ends: a bump switch's edge, a data-ready interrupt. The sampler then samples at once and
    /// keeps its period's grid afterwards. Awaited only between a cyclic sensor's samples, and
    /// dropped when the sample falls due; never completes by default.
    ///
    /// It should complete once per event (await the edge, not the level): a future that is
    /// always ready makes the sensor sample as fast as it can answer.
    async fn wake(&self, sensor: Self::Id) {
        let _ = sensor;
        core::future::pending::<()>().await;
    }
}

/// The actuator behaviours of a platform (the acting side of the deliberative controller), in
/// a runtime whose fact sets have `W` words (1 by default). Which action a call is for is
/// [`Self::Id`], as for [`Sensor`]: a compiled mission's `Action` enum, or [`ActionId`].
#[allow(async_fn_in_trait)] // Runs on single-threaded executors: no `Send` bound wanted.
pub trait Actuator<const W: usize = 1> {
    /// How a call names its action: a compiled mission's `Action` enum, or [`ActionId`].
    type Id: FromId<ActionId>;

    /// Runs actuator-based action `action` until it succeeds, fails or gives up.
    ///
    /// `io` gives the mutual data store (the latest samples of the sensors running beside the
    /// action), the precondition status, and a way to await the next change. When a percept
    /// makes the precondition false the behaviour is told at once ([`ActionIo::violation`]) and
    /// may stop, avoid, or return [`Outcome::Interrupted`].
    async fn run(&self, action: Self::Id, io: &ActionIo<'_, W>) -> Outcome;

    /// SMPA only: `true` at the start of a sense phase (the robot must stand still while the
    /// behaviour is not polled), `false` when acting resumes.
    fn hold(&self, action: Self::Id, held: bool) {
        let _ = (action, held);
    }

    /// The safety stop: the runtime cancelled the behaviour (a sensor fault, or the
    /// precondition stayed false), so bring the actuators to a safe stop now. Required: a
    /// robot that moves says how it stops (a platform with nothing to stop says so with an
    /// empty body). Called from the deciding side, synchronously: keep it short and never
    /// wait on time (`cargo xtask wcet` refuses a busy wait in it).
    fn halt(&self, action: Self::Id);
}

/// How a platform names the sensors or actions a call is for ([`Sensor::Id`],
/// [`Actuator::Id`]): from the runtime's id (`I`, a [`SensorId`] or an [`ActionId`]). The enums
/// `include_mission!` generates implement it; so do the ids themselves.
pub trait FromId<I>: Copy {
    /// The one of id `id`, or `None` when the platform has none of that id (its enum is another
    /// mission's).
    fn from_id(id: I) -> Option<Self>;
}

impl FromId<SensorId> for SensorId {
    fn from_id(id: SensorId) -> Option<Self> {
        Some(id)
    }
}

impl FromId<ActionId> for ActionId {
    fn from_id(id: ActionId) -> Option<Self> {
        Some(id)
    }
}

impl FromId<PlanId> for PlanId {
    fn from_id(id: PlanId) -> Option<Self> {
        Some(id)
    }
}

// Here, not beside `Failure`: `failure` is a layer above `platform`, which names `FromId`.
impl<const W: usize> crate::failure::Failure<W> {
    /// The action the failure is about, in the type the platform names actions by (a compiled
    /// mission's `Action`, or [`ActionId`]); `None` if it is about none.
    pub fn action<A: FromId<ActionId>>(&self) -> Option<A> {
        use crate::failure::Failure as F;
        match *self {
            F::ActionFailed { action }
            | F::ActionInterrupted { action }
            | F::PreconditionUnmet { action, .. }
            | F::PreconditionViolated { action, .. } => A::from_id(action),
            _ => None,
        }
    }

    /// The sensor the failure is about, as [`Failure::action`](crate::Failure::action) names
    /// an action.
    pub fn sensor<S: FromId<SensorId>>(&self) -> Option<S> {
        use crate::failure::Failure as F;
        match *self {
            F::SensorUnavailable { sensor } | F::SensorFault { sensor, .. } => S::from_id(sensor),
            _ => None,
        }
    }
}

/// A robot, or a simulated one: how the runtime's two sides share state on it. Implement
/// [`Sensor`] and [`Actuator`] on the same type: the one type a [`Runtime`](crate::Runtime) is
/// generic over besides its capacities. (Those two are not required here because they take the
/// fact-set width, which is one of the capacities.)
pub trait Platform {
    /// The mutex through which the sensing and deciding sides share state:
    /// `NoopRawMutex` where both run on one executor (or a host simulation),
    /// `CriticalSectionRawMutex` where sensing runs on a higher-priority executor.
    type Mutex: embassy_sync::blocking_mutex::raw::RawMutex;
}

/// What the runtime shares with a running behaviour, object safe so [`ActionIo`] needs no
/// type parameters.
pub(crate) trait Monitor<const W: usize> {
    fn beliefs(&self) -> FactSetOf<W>;
    fn violation(&self) -> Option<Violation<W>>;
    fn version(&self) -> u32;
    fn poll_changed(&self, cx: &mut Context<'_>, since: u32) -> Poll<u32>;
    fn request(&self, sensor: SensorId);
    fn user(&self, code: u16, value: i32);
}

/// What a running actuator behaviour sees: its mutual data store, the beliefs, the state of
/// its precondition, and a way to wait for the next change (fact sets of `W` words).
pub struct ActionIo<'io, const W: usize = 1> {
    pub(crate) action: ActionId,
    pub(crate) store: MutualStore<'io>,
    pub(crate) monitor: &'io dyn Monitor<W>,
}

impl<const W: usize> ActionIo<'_, W> {
    /// The action being run.
    pub fn action(&self) -> ActionId {
        self.action
    }

    /// The mutual data store `d_mutual(s_j, a_i)`.
    pub fn store(&self) -> &MutualStore<'_> {
        &self.store
    }

    /// The latest sample of a sensor running beside the action.
    pub fn sample(&self, sensor: SensorId) -> Option<Entry> {
        self.store.sample(sensor)
    }

    /// `get(d_mutual, k')`: what sensor `sensor`, running beside the action, put under `key`.
    pub fn get(&self, sensor: SensorId, key: Key) -> Option<Entry> {
        self.store.get(sensor, key)
    }

    /// The action's own value for `key`.
    pub fn own(&self, key: Key) -> Option<Entry> {
        self.store.own(key)
    }

    /// Writes into the action's own store, stamped now.
    pub fn put(&self, key: Key, value: Value) -> Result<(), StoreFull> {
        self.store.put(key, value, Instant::now())
    }

    /// The current beliefs `φ`.
    pub fn beliefs(&self) -> FactSetOf<W> {
        self.monitor.beliefs()
    }

    /// `Some` while the action's precondition is false according to the beliefs: the latest
    /// samples, and, for a fact no sensor of this state has sampled yet, the belief from
    /// before the state. A fact only an on-demand sensor perceives is therefore violated
    /// from the state's start until the behaviour asks for a sample that shows it, if it was
    /// false or never sensed before: give such an action a tolerance
    /// ([`ActuatorAction::max_violation`](crate::ActuatorAction::max_violation)) at least as long as that request takes.
    pub fn violation(&self) -> Option<Violation<W>> {
        self.monitor.violation()
    }

    /// A counter that moves on every sample and every change of the precondition.
    pub fn version(&self) -> u32 {
        self.monitor.version()
    }

    /// Waits until [`version`](Self::version) differs from `since` and returns the new value.
    /// Returns at once if it already differs.
    pub fn changed(&self, since: u32) -> Changed<'_, W> {
        // A future of its own, not an `async fn` around a `poll_fn`: a behaviour awaits it at
        // every step, and the wrapper's state machine showed in `profile_plan`'s callgrind
        // profile.
        Changed {
            monitor: self.monitor,
            since,
        }
    }

    /// Waits until [`version`](Self::version) differs from `since` or the instant `at` comes,
    /// whichever is first: `Some(new version)`, or `None` at the deadline. The loop of a
    /// behaviour that reacts to percepts and also has its own next instant.
    pub async fn changed_until(&self, since: u32, at: Option<Instant>) -> Option<u32> {
        let deadline = async {
            match at {
                Some(at) => Timer::at(at).await,
                None => core::future::pending().await,
            }
        };
        match select(self.changed(since), deadline).await {
            Either::First(v) => Some(v),
            Either::Second(()) => None,
        }
    }

    /// [`changed_until`](Self::changed_until) `timeout` from now.
    pub async fn changed_within(&self, since: u32, timeout: Duration) -> Option<u32> {
        self.changed_until(since, Some(Instant::now().saturating_add(timeout)))
            .await
    }

    /// Asks for a sample of an on-demand sensor running beside the action. Under SMPA the
    /// request is served in the next sense phase.
    pub fn request(&self, sensor: SensorId) {
        self.monitor.request(sensor);
    }

    /// Records an application-defined trace event.
    pub fn trace(&self, code: u16, value: i32) {
        self.monitor.user(code, value);
    }
}

/// The future of [`ActionIo::changed`]: the next [`version`](ActionIo::version) after `since`.
#[must_use = "futures do nothing unless polled"]
pub struct Changed<'io, const W: usize> {
    monitor: &'io dyn Monitor<W>,
    since: u32,
}

impl<const W: usize> Future for Changed<'_, W> {
    type Output = u32;

    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<u32> {
        self.monitor.poll_changed(cx, self.since)
    }
}

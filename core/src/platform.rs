//! What the platform implements: the sensors behind sensor-based actions and the actuator
//! behaviours behind actuator-based actions.
//!
//! One implementation serves every sensor (or action) of a platform's mission, dispatched by
//! the mission's enum: async trait methods cannot be called through `dyn` without allocation,
//! and a `match` on the enum compiles to a jump table. Methods take `&self` because sensors and
//! actuators run at the same time; platforms keep their state in cells or mutexes.

use crate::facts::FactSetOf;
use crate::failure::SensorFault;
use crate::spec::{Act, Mission, ReadingOf};
use crate::store::{Key, SAMPLE_KEY, Value};

/// Most `(key, value)` pairs one [`Reading`] carries besides its main value.
pub const MAX_PAIRS: usize = 4;

// A mission loaded at run time has room for a sample and all its pairs.
const _: () = assert!(crate::spec::RUN_TIME_KEYS == MAX_PAIRS + 1);

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
    /// The pairs, the first `len` of them.
    pairs: [(Key, Value); MAX_PAIRS],
    len: u8,
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
            pairs: [(SAMPLE_KEY, Value::NoEcho); MAX_PAIRS],
            len: 0,
        }
    }

    /// Adds a `(key, value)` pair for the sensor's store, or replaces the value of a key already
    /// added. At most [`MAX_PAIRS`] keys; [`SAMPLE_KEY`] belongs to [`value`](Self::value).
    /// The store keeps a key until a later sample puts it again (Algorithm 3 line 6 adds to the
    /// store), so a sensor whose readings carry a key only sometimes should put it every time,
    /// or readers compare its instant with the sample's.
    pub fn put(&mut self, key: impl Into<Key>, value: Value) -> Result<(), PairRejected> {
        let key = key.into();
        let rejected = PairRejected { key, value };
        if key == SAMPLE_KEY {
            return Err(rejected);
        }
        let len = usize::from(self.len);
        if let Some(pair) = self.pairs.iter_mut().take(len).find(|(k, _)| *k == key) {
            pair.1 = value;
            return Ok(());
        }
        let slot = self.pairs.get_mut(len).ok_or(rejected)?;
        *slot = (key, value);
        self.len = self.len.saturating_add(1);
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
    pub fn with(mut self, key: impl Into<Key>, value: Value) -> Result<Self, PairRejected> {
        self.put(key, value).map(|()| self)
    }

    /// The pairs besides the main value, in the order they were added.
    pub fn pairs(&self) -> impl Iterator<Item = (Key, Value)> + '_ {
        self.pairs.iter().take(usize::from(self.len)).copied()
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

/// The sensors of a platform for mission `M` (the sensing side: the paper's sensory
/// controller).
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
/// A call names its sensor by the mission's `Sensor` enum (`dock::Sensor`, from
/// [`include_mission!`](crate::include_mission)), whose exhaustive `match` the compiler
/// checks; a mission loaded at run time names it by [`SensorId`](crate::SensorId).
#[allow(async_fn_in_trait)] // Runs on single-threaded executors: no `Send` bound wanted.
#[diagnostic::on_unimplemented(
    message = "`{Self}` has no sensors for the mission `{M}`: it implements no `Sensor<{M}>`",
    label = "not a platform for `{M}`",
    note = "a platform is written for one mission: `impl Sensor<{M}> for ...`, with `{M}`'s `Sensor` enum"
)]
pub trait Sensor<M: Mission> {
    /// Powers the sensor up. Called when a state that needs it starts (least commitment).
    async fn switch_on(&self, sensor: M::Sensor) -> Result<(), SensorFault>;
    /// Powers the sensor down. Called when the action it serves ends.
    async fn switch_off(&self, sensor: M::Sensor);
    /// Takes one sample. The runtime bounds it with the sensor's timeout. `Ok(None)` means this
    /// sample was lost (an echo that never came back); the runtime keeps the previous belief
    /// and fails the state after [`Config::max_lost`](crate::Config::max_lost) losses in a row.
    async fn sample(&self, sensor: M::Sensor) -> Result<Option<ReadingOf<M>>, SensorFault>;

    /// Whether [`wake`](Self::wake) may complete. A platform whose sensors never make a sample
    /// due early may say `false`: the runtime then neither builds nor polls the `wake` future
    /// between samples. With `false` an overridden `wake` is not called.
    const WAKES: bool = true;

    /// Completes when something makes a cyclic sensor's next sample due before its period
    /// ends: a bump switch's edge, a data-ready interrupt. The sampler then samples at once and
    /// keeps its period's grid afterwards. Awaited only between a cyclic sensor's samples, and
    /// dropped when the sample falls due; never completes by default.
    ///
    /// It should complete once per event (await the edge, not the level): a future that is
    /// always ready makes the sensor sample as fast as it can answer.
    async fn wake(&self, sensor: M::Sensor) {
        let _ = sensor;
        core::future::pending::<()>().await;
    }
}

/// The actuator behaviours of a platform for mission `M` (the acting side of the
/// deliberative controller).
#[allow(async_fn_in_trait)] // Runs on single-threaded executors: no `Send` bound wanted.
#[diagnostic::on_unimplemented(
    message = "`{Self}` has no behaviours for the mission `{M}`: it implements no `Actuator<{M}>`",
    label = "not a platform for `{M}`",
    note = "a platform is written for one mission: `impl Actuator<{M}> for ...`, matching on `act.typed()`"
)]
pub trait Actuator<M: Mission> {
    /// Runs the action `act` names until it succeeds, fails or gives up.
    ///
    /// [`act.typed()`](Act::typed) is the mission's `Run` enum: one variant an action, each
    /// with the [`ActionIo`](crate::ActionIo) of that action, which reads the sensors running beside it (and
    /// no other: that is a compile error), their keys and the action's own, the precondition's
    /// status, and a way to await the next change. When a percept makes the precondition
    /// false the behaviour is told at once ([`ActionIo::violation`](crate::ActionIo::violation)) and may stop, avoid, or
    /// return [`Outcome::Interrupted`].
    async fn run(&self, act: Act<'_, M>) -> Outcome;

    /// SMPA only: `true` at the start of a sense phase (the robot must stand still while the
    /// behaviour is not polled), `false` when acting resumes.
    fn hold(&self, action: M::Action, held: bool) {
        let _ = (action, held);
    }

    /// The safety stop: the runtime cancelled the behaviour (a sensor fault, or the
    /// precondition stayed false), so bring the actuators to a safe stop now. Required: a
    /// robot that moves says how it stops (a platform with nothing to stop says so with an
    /// empty body). Called from the deciding side, synchronously: keep it short and never
    /// wait on time (`cargo xtask wcet` refuses a busy wait in it).
    fn halt(&self, action: M::Action);
}

/// A robot, or a simulated one: how the runtime's two sides share state on it. Implement
/// [`Sensor<M>`] and [`Actuator<M>`] on the same type for the mission `M` it runs.
pub trait Platform {
    /// The mutex through which the sensing and deciding sides share state:
    /// `NoopRawMutex` where both run on one executor (or a host simulation),
    /// `CriticalSectionRawMutex` where sensing runs on a higher-priority executor.
    type Mutex: embassy_sync::blocking_mutex::raw::RawMutex;
}

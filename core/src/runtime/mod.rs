//! The runtime: a mission's two sides, the state they share, its plans' states, the FSM, the
//! control loop.
//!
//! A [`Runtime`] is made for a mission type ([`Mission`]): a compiled mission's
//! (`include_mission!` generates the type and an alias, `dock::Runtime<'r, P, T>`) or a
//! mission loaded at run time (`&Tables`). It runs as two sides, handed out once by
//! [`Runtime::split`]:
//!
//! * **Sensing** ([`SensingSide`](crate::SensingSide), the paper's sensory controller): one
//!   sampler per sensor, each on its own schedule; a sample is read, stored, fused into the
//!   beliefs and checked against the running action's precondition, and whoever waits is
//!   woken ([`sensing`]).
//! * **Deciding** ([`DecidingSide`](crate::DecidingSide), the deliberative controller): the
//!   control loop (Algorithm 1, [`control`]), the plans' states (Algorithm 2: a compiled
//!   mission's plans are build-time state tables, [`Mission::states`]; others run through the [`fsm`]) and the
//!   actuator behaviours. It switches sensors on and off by telling the sensing side which
//!   sensors the running state needs (least commitment).
//!
//! The two sides share only the stores and an embassy-sync mutex over a little state, so a
//! platform may run them on one executor, or sensing on a higher-priority one (an
//! `InterruptExecutor` on a microcontroller); a long behaviour or planner poll then cannot
//! delay a sample.
//!
//! ```
//! use embassy_sync::blocking_mutex::raw::NoopRawMutex;
//! use psmpa_core::{Act, Actuator, Outcome, Platform, Reading, Sensor, SensorFault};
//!
//! psmpa_core::include_mission!(mod hello = "../testkit/tests/hello.json");
//! use hello::Hello;
//!
//! struct Robot;
//! # impl Sensor<Hello> for Robot {
//! #     async fn switch_on(&self, _: hello::Sensor) -> Result<(), SensorFault> { Ok(()) }
//! #     async fn switch_off(&self, _: hello::Sensor) {}
//! #     async fn sample(&self, _: hello::Sensor) -> Result<Option<Reading>, SensorFault> { Ok(None) }
//! # }
//! # impl Actuator<Hello> for Robot {
//! #     fn halt(&self, _: hello::Action) {} // nothing to stop
//! #     async fn run(&self, _: Act<'_, Hello>) -> Outcome { Outcome::Success }
//! # }
//! impl Platform for Robot {
//!     type Mutex = NoopRawMutex; // both sides on one executor
//! }
//!
//! type RobotRuntime<'r> = hello::Runtime<'r, Robot>;
//! ```

pub mod control;
pub mod fsm;
pub mod sensing;
pub(crate) mod shared;
pub mod sides;
mod state;

use core::cell::{Cell, RefCell};
use core::task::{Context, Poll};

use embassy_sync::blocking_mutex::Mutex;
use embassy_time::{Duration, Instant};

use crate::action::{ActuatorAction, SensorAction, SensorId, SensorSet};
use crate::facts::FactSetOf;
use crate::failure::{Failure, Violation};
use crate::model::{Task, WorldModel};
use crate::platform::{Platform, Reading};
use crate::spec::io::Monitor;
use crate::spec::storage::{Shared, poll_shared};
use crate::spec::{self, Mission, Storage, Width};
use crate::store::Entry;
use crate::trace::{TraceEvent, TraceHash, TraceSink, Tracer};
use control::{ControlError, Report};

/// How sensing and acting are scheduled.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum Policy {
    /// P-SMPA: sensors run in parallel with the action that needs them.
    PSmpa,
    /// Sequential SMPA: sense phases (sensors on, actuators idle) alternate with act phases
    /// (actuators on, sensors off).
    Smpa {
        /// Length of a sense phase.
        sense: Duration,
        /// Length of an act phase.
        act: Duration,
    },
}

/// How a compiled mission's library plans run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum Plans {
    /// From their build-time state tables ([`Mission::states`]): Algorithm 2 at build time.
    Compiled,
    /// Through the run-time FSM, as a plan the planner made: the same trace, for a check that
    /// the two paths agree.
    RunTime,
}

/// Settings of a runtime. A setting may be added in a minor version: start from
/// [`Config::default`] and set the fields you need.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub struct Config {
    /// The scheduling policy.
    pub policy: Policy,
    /// How long a running action's precondition may stay false before the runtime stops the
    /// action and takes the failure edge, for actions without their own
    /// ([`ActuatorAction::max_violation`](crate::ActuatorAction::max_violation)). The
    /// behaviour is told at once either way.
    pub max_violation: Duration,
    /// Plan failures tolerated: the control loop gives up at failure `max_failures + 1`.
    pub max_failures: u16,
    /// Plans after which the control loop gives up even if they all succeeded (a library whose
    /// plans never reach the goal would otherwise loop forever).
    pub max_plans: u16,
    /// Lost samples in a row after which a sensor counts as [`SensorFault::Silent`](crate::SensorFault::Silent).
    pub max_lost: u8,
    /// Search nodes the planner takes in one poll of the deciding side before it yields
    /// (at least 1): on one executor, a sample waits for at most one slice of a search. A
    /// slice's worst cost, for the timing analysis: `plan_slice` expansions, each one pass over
    /// the NA actions plus, for a heuristic search, one estimate per node generated (at most
    /// NA), an estimate being at most (facts + 1) passes over every action's pre and add
    /// facts. Breadth-first search needs no estimate.
    pub plan_slice: u16,
    /// How the library's plans run (compiled, by default).
    pub plans: Plans,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            policy: Policy::PSmpa,
            max_violation: Duration::from_secs(5),
            max_failures: 8,
            max_plans: 64,
            max_lost: 10,
            plan_slice: 16,
            plans: Plans::Compiled,
        }
    }
}

// Here, where every type it names is: the layers below name them through it.
impl<const W: usize> Width for FactSetOf<W> {
    type Reading = Reading<W>;
    type Failure = Failure<W>;
    type Violation = Violation<W>;
    type TraceEvent = TraceEvent<W>;
    type ControlError = ControlError<W>;
    type Report = Report<W>;
    type Task = Task<W>;
    type SensorAction<'a> = SensorAction<'a, W>;
    type ActuatorAction<'a> = ActuatorAction<'a, W>;
}

/// The storage of a runtime of mission `M` on platform `P`.
type StorageOf<M, P> = <M as Mission>::Storage<<P as Platform>::Mutex>;

/// A data store of a runtime of mission `M` on platform `P`.
pub type StoreOf<M, P> =
    <StorageOf<M, P> as Storage<<P as Platform>::Mutex, <M as Mission>::Facts>>::Store;

/// The per-sensor state of a runtime of mission `M` on platform `P`.
pub(crate) type SensorsOf<M, P> =
    <StorageOf<M, P> as Storage<<P as Platform>::Mutex, <M as Mission>::Facts>>::Sensors;

/// The shared state of a runtime of mission `M` on platform `P`.
type SharedOf<M, P> = Shared<<M as Mission>::Facts, SensorsOf<M, P>>;

/// The P-SMPA runtime of one robot: mission `M` (a compiled mission's type, or `&Tables` of
/// one loaded at run time), platform `P`, trace sink `T` (none by default). Everything lives
/// inside this value (every capacity is in `M`'s storage): put it in a `static` (with a
/// `StaticCell`) or on the stack of the task that runs it.
///
/// It runs as two sides, handed out once by [`split`](Self::split): the sensing side, which
/// never ends, and the deciding side's control loop. Run both: on one executor
/// ([`run_with_sensing`](Self::run_with_sensing) polls sensing first), or sensing in a task of
/// a higher-priority executor. With `P::Mutex = CriticalSectionRawMutex` and a `Sync`
/// platform it is `Sync`, and its sensing side `Send`.
pub struct Runtime<'r, M: Mission, P: Platform, T = ()> {
    pub(crate) mission: M,
    pub(crate) platform: &'r P,
    pub(crate) config: Config,
    pub(crate) storage: M::Storage<P::Mutex>,
    tracer: Mutex<P::Mutex, RefCell<Tracer<T>>>,
    trace_lost: Mutex<P::Mutex, Cell<u32>>,
}

impl<'r, M, P, T, const W: usize> Runtime<'r, M, P, T>
where
    M: Mission<Facts = FactSetOf<W>>,
    P: Platform,
    T: TraceSink<M>,
{
    /// A runtime of `mission` on `platform`, tracing into `sink`. The beliefs start at the
    /// task's initial state `τ0`.
    pub fn new(mission: M, platform: &'r P, sink: T, config: Config) -> Self {
        let mut storage = <M::Storage<P::Mutex> as Storage<_, _>>::NEW;
        // Owned: set without a lock (no critical section before anything runs).
        storage
            .shared_mut()
            .get_mut()
            .beliefs
            .set(mission.task().init);
        Self {
            mission,
            platform,
            config,
            storage,
            tracer: Mutex::new(RefCell::new(Tracer::new(sink))),
            trace_lost: Mutex::new(Cell::new(0)),
        }
    }

    /// The mission.
    pub fn mission(&self) -> &M {
        &self.mission
    }

    /// The settings.
    pub fn config(&self) -> Config {
        self.config
    }

    pub(crate) fn shared(&self) -> &Mutex<P::Mutex, SharedOf<M, P>> {
        self.storage.shared()
    }

    /// The current beliefs `φ`.
    pub fn beliefs(&self) -> FactSetOf<W> {
        self.shared().lock(|s| s.beliefs.get())
    }

    /// Percept facts a sample (or an action's effects) has shown to be false: facts never
    /// sensed are unknown, not false.
    pub fn known_false(&self) -> FactSetOf<W> {
        self.shared()
            .lock(|s| s.sensed.get().difference(s.beliefs.get()))
    }

    /// Percept facts neither believed nor shown by any sample or action's effects since the
    /// initial model: a sensor perceives them, and nothing says whether they hold. (A fact no
    /// sensor perceives follows the model.)
    pub fn unknown_facts(&self) -> FactSetOf<W> {
        self.knowledge().1
    }

    /// [`known_false`](Self::known_false), [`unknown_facts`](Self::unknown_facts) and
    /// [`faulty_sensors`](Self::faulty_sensors) in one lock.
    pub(crate) fn knowledge(&self) -> (FactSetOf<W>, FactSetOf<W>, SensorSet) {
        let perceivable =
            (self.mission.sensors().iter()).fold(FactSetOf::EMPTY, |acc, s| acc.union(s.per));
        self.shared().lock(|s| {
            let (sensed, beliefs) = (s.sensed.get(), s.beliefs.get());
            (
                sensed.difference(beliefs),
                perceivable.difference(sensed.union(beliefs)),
                s.faulty.get(),
            )
        })
    }

    /// A snapshot of the world model `M = <ω, φ, Π>` (`ω`: each sensor's latest percept, by
    /// id, for the first `N` sensors).
    pub fn model<const N: usize>(&self) -> WorldModel<N, W> {
        self.shared().lock(|s| WorldModel {
            percepts: core::array::from_fn(|i| {
                s.sensors.as_ref().get(i).and_then(|p| p.percept.get())
            }),
            beliefs: s.beliefs.get(),
            task: self.mission.task(),
        })
    }

    /// Sensor `sensor`'s latest percept: its value and when it was taken.
    pub fn percept(&self, sensor: impl spec::SensorOf<M>) -> Option<Entry> {
        let id = sensor.id();
        self.shared()
            .lock(|s| s.sensor(id).and_then(|p| p.percept.get()))
    }

    /// The data store of a sensor-based action.
    pub fn sensor_store(&self, sensor: impl spec::SensorOf<M>) -> Option<&StoreOf<M, P>> {
        self.storage.sensor_stores().get(sensor.id().index())
    }

    /// The data store of an actuator-based action.
    pub fn action_store(&self, action: impl spec::ActionOf<M>) -> Option<&StoreOf<M, P>> {
        self.storage.action_stores().get(action.id().index())
    }

    /// Samples sensor `sensor` every `period` from now on instead of the mission's period (a
    /// board's calibration, a scenario's); `None` restores the mission's. Takes effect at the
    /// sensor's next switch-on. Only for a cyclic sensor; a period of 0 is refused: `false`.
    pub fn set_period(&self, sensor: impl spec::SensorOf<M>, period: Option<Duration>) -> bool {
        let id = sensor.id();
        let cyclic = self
            .mission
            .sensors()
            .get(id.index())
            .is_some_and(|s| matches!(s.mode, crate::action::SensorMode::Cyclic { .. }));
        if !cyclic || period.is_some_and(|p| p.as_ticks() == 0) {
            return false;
        }
        self.shared().lock(|s| {
            s.sensor(id).is_some_and(|p| {
                p.period.set(period);
                true
            })
        })
    }

    /// The hash of the trace so far (the empty trace's with the sink `()`, which is not traced
    /// into).
    pub fn trace_hash(&self) -> TraceHash {
        self.tracer
            .lock(|t| t.try_borrow().map(|t| t.hash()).unwrap_or_default())
    }

    /// Number of trace events so far (0 with the sink `()`).
    pub fn trace_events(&self) -> u32 {
        self.tracer
            .lock(|t| t.try_borrow().map(|t| t.events()).unwrap_or(0))
    }

    /// Events that could not be recorded because the sink re-entered the runtime (a sink must
    /// not call back into the runtime); 0 in any correct program.
    pub fn trace_lost(&self) -> u32 {
        self.trace_lost.lock(Cell::get)
    }

    /// Gives the runtime up and returns the trace sink.
    pub fn into_sink(self) -> T {
        self.tracer.into_inner().into_inner().into_sink()
    }

    pub(crate) fn trace(&self, event: TraceEvent<W>) {
        // No sink (`()`): nothing to read, lock or hash.
        if !T::TRACES {
            return;
        }
        let at = Instant::now();
        let recorded = self.tracer.lock(|t| match t.try_borrow_mut() {
            Ok(mut t) => {
                t.record::<M, W>(at, &event);
                true
            }
            Err(_) => false,
        });
        if !recorded {
            self.trace_lost.lock(|n| n.set(n.get().saturating_add(1)));
        }
    }

    /// [`poll_shared`] for the deciding side.
    pub(crate) fn poll_deciding<R>(
        &self,
        cx: &mut Context<'_>,
        done: impl FnOnce(&SharedOf<M, P>) -> Option<R>,
    ) -> Poll<R> {
        poll_shared(self.shared(), cx, |s| &s.deciding, done)
    }

    /// [`poll_shared`] for a sampler.
    pub(crate) fn poll_sensing<R>(
        &self,
        cx: &mut Context<'_>,
        done: impl FnOnce(&SharedOf<M, P>) -> Option<R>,
    ) -> Poll<R> {
        poll_shared(self.shared(), cx, |s| &s.sensing, done)
    }

    /// The sensors that failed and are out of service: a state that needs one fails at once
    /// with [`Failure::SensorUnavailable`], and the planner
    /// does not count on them.
    pub fn faulty_sensors(&self) -> SensorSet {
        self.shared().lock(|s| s.faulty.get())
    }

    /// Puts every failed sensor back into service (after a repair or a reset of the device).
    pub fn clear_faults(&self) {
        self.shared().lock(|s| {
            s.faulty.set(SensorSet::EMPTY);
            for p in s.sensors.as_ref() {
                p.lost.set(0);
            }
        });
    }
}

impl<M, P, T, const W: usize> Monitor<M> for Runtime<'_, M, P, T>
where
    M: Mission<Facts = FactSetOf<W>>,
    P: Platform,
    T: TraceSink<M>,
{
    fn beliefs(&self) -> FactSetOf<W> {
        Runtime::beliefs(self)
    }

    fn violation(&self) -> Option<Violation<W>> {
        self.shared().lock(|s| {
            if s.alert.get() {
                s.violation.get()
            } else {
                None
            }
        })
    }

    fn version(&self) -> u32 {
        self.shared().lock(|s| s.version.get())
    }

    fn poll_changed(&self, cx: &mut Context<'_>, since: u32) -> Poll<u32> {
        self.poll_deciding(cx, |s| {
            let now = s.version.get();
            (now != since).then_some(now)
        })
    }

    fn request(&self, sensor: SensorId) {
        self.shared().lock(|s| {
            s.requests.set(s.requests.get().with(sensor));
            s.sensing.wake();
        });
    }

    fn user(&self, code: u16, value: i32) {
        self.trace(TraceEvent::User { code, value });
    }
}

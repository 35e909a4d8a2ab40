//! Executing compiled plans: Algorithm 2 at run time, under one of two scheduling policies.
//!
//! * [`Policy::PSmpa`]: a parallel state `δ'_i` switches its sensors on, samples them once,
//!   then runs the actuator behaviour and the sensors side by side. Every sample updates the
//!   beliefs; when a percept makes `pre(a_i)` false the behaviour is told at once
//!   ([`ActionIo::violation`]), and if it stays false longer than
//!   [`Config::max_violation`] the runtime stops the behaviour and takes the failure edge. The
//!   sensors are switched off when the action ends (least commitment).
//! * [`Policy::Smpa`]: the baseline. The same state alternates a sense phase (sensors on,
//!   actuators held) and an act phase (behaviour polled, sensors off). Only the policy differs:
//!   the actions, sensors, behaviours and precondition checks are the same code.
//!
//! Cost per step: one sample is one store write, one belief update and a precondition check,
//! all O(1); choosing the next sensor to sample is O(NS).

use core::cell::{Cell, RefCell};
use core::future::{pending, poll_fn};
use core::pin::pin;
use core::task::{Context, Poll};

use embassy_futures::select::{Either, select};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_sync::waitqueue::MultiWakerRegistration;
use embassy_time::{Duration, Instant, Timer, with_timeout};
use heapless::Vec;

use crate::action::{ActionId, ActuatorAction, SensorId, SensorMode, SensorSet};
use crate::facts::FactSet;
use crate::fmt::debug;
use crate::fsm::{BehaviourState, Edge, Fsm, Target};
use crate::mission::Mission;
use crate::model::WorldModel;
use crate::platform::{Actuator, Outcome, Sensor, SensorFault};
use crate::store::{DataStore, Entry, Key, MutualStore, SAMPLE_KEY, StoreAccess, StoreFull, Value};
use crate::trace::{Phase, TraceEvent, TraceHash, TraceSink, Tracer};

/// How sensing and acting are scheduled.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
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

/// Settings of a runtime.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Config {
    /// The scheduling policy.
    pub policy: Policy,
    /// How long a running action's precondition may stay false before the runtime stops the
    /// action and takes the failure edge. The behaviour is told at once either way.
    pub max_violation: Duration,
    /// Plan failures tolerated: the control loop gives up at failure `max_failures + 1`.
    pub max_failures: u16,
    /// Plans after which the control loop gives up even if they all succeeded (a library whose
    /// plans never reach the goal would otherwise loop forever).
    pub max_plans: u16,
    /// Lost samples in a row after which a sensor counts as [`SensorFault::Silent`].
    pub max_lost: u8,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            policy: Policy::PSmpa,
            max_violation: Duration::from_secs(5),
            max_failures: 8,
            max_plans: 64,
            max_lost: 10,
        }
    }
}

/// Why a behaviour state took its failure edge.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum Failure {
    /// The behaviour returned [`Outcome::Failure`].
    ActionFailed {
        /// The action.
        action: ActionId,
    },
    /// The behaviour returned [`Outcome::Interrupted`].
    ActionInterrupted {
        /// The action.
        action: ActionId,
    },
    /// Facts of `pre(a)` that no sensor of the state decides did not hold when it started.
    PreconditionUnmet {
        /// The action.
        action: ActionId,
        /// The facts that did not hold.
        missing: FactSet,
    },
    /// A percept made `pre(a)` false and it stayed false longer than
    /// [`Config::max_violation`].
    PreconditionViolated {
        /// The action.
        action: ActionId,
        /// The facts that did not hold.
        missing: FactSet,
    },
    /// A sensor the state needs cannot run: `pre(s)` does not hold, or the FSM names a state
    /// or sensor that does not exist.
    SensorUnavailable {
        /// The sensor.
        sensor: SensorId,
    },
    /// A sensor did not switch on, or failed to deliver a sample.
    SensorFault {
        /// The sensor.
        sensor: SensorId,
        /// What went wrong.
        fault: SensorFault,
    },
    /// A sensor's store had no room for its sample.
    StoreFull {
        /// The key that found no room.
        key: Key,
    },
    /// The FSM has no state `state`, or its success edge leads to failure.
    InvalidFsm {
        /// The state index.
        state: u8,
    },
}

/// A running action's precondition is false.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Violation {
    /// The facts of `pre(a)` that do not hold.
    pub missing: FactSet,
    /// The first sample that showed it.
    pub since: Instant,
    /// The latest sample that showed it.
    pub last_seen: Instant,
}

/// What the runtime shares with a running behaviour, object safe so [`ActionIo`] needs no
/// type parameters.
trait Monitor {
    fn beliefs(&self) -> FactSet;
    fn violation(&self) -> Option<Violation>;
    fn version(&self) -> u32;
    fn poll_changed(&self, cx: &mut Context<'_>, since: u32) -> Poll<u32>;
    fn request(&self, sensor: SensorId);
    fn user(&self, code: u16, value: i32);
}

/// What a running actuator behaviour sees: its mutual data store, the beliefs, the state of
/// its precondition, and a way to wait for the next change.
pub struct ActionIo<'io> {
    action: ActionId,
    store: MutualStore<'io>,
    monitor: &'io dyn Monitor,
}

impl ActionIo<'_> {
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

    /// `get(d_mutual, key)`: own value first, then the linked sensors'.
    pub fn get(&self, key: Key) -> Option<Entry> {
        self.store.get(key)
    }

    /// Writes into the action's own store, stamped now.
    pub fn put(&self, key: Key, value: Value) -> Result<(), StoreFull> {
        self.store.put(key, value, Instant::now())
    }

    /// The current beliefs `φ`.
    pub fn beliefs(&self) -> FactSet {
        self.monitor.beliefs()
    }

    /// `Some` while the action's precondition is false according to the latest samples.
    pub fn violation(&self) -> Option<Violation> {
        self.monitor.violation()
    }

    /// A counter that moves on every sample and every change of the precondition.
    pub fn version(&self) -> u32 {
        self.monitor.version()
    }

    /// Waits until [`version`](Self::version) differs from `since` and returns the new value.
    /// Returns at once if it already differs.
    pub async fn changed(&self, since: u32) -> u32 {
        poll_fn(|cx| self.monitor.poll_changed(cx, since)).await
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

/// State the control path shares with running behaviours. Only `Cell`s, so reads and writes
/// cannot fail; the waker list is the one `RefCell`, never borrowed across a call out.
struct Shared<const NS: usize> {
    beliefs: Cell<FactSet>,
    percepts: [Cell<Option<Entry>>; NS],
    /// What each sensor's latest sample says of its `per(s)`.
    holds: [Cell<FactSet>; NS],
    /// The sensors switched on for the current state (or the initial model).
    running: Cell<SensorSet>,
    /// The running sensors that have sampled since they were switched on.
    fresh: Cell<SensorSet>,
    /// Samples lost in a row, per sensor.
    lost: [Cell<u8>; NS],
    /// Facts some sample has decided (true or false) since the start.
    sensed: Cell<FactSet>,
    /// Sensors that failed: out of service for the rest of the mission.
    faulty: Cell<SensorSet>,
    violation: Cell<Option<Violation>>,
    requests: Cell<SensorSet>,
    version: Cell<u32>,
    waiters: RefCell<MultiWakerRegistration<4>>,
}

/// When each sensor of a running state is due.
struct Slot {
    sensor: SensorId,
    mode: SensorMode,
    due: Option<Instant>,
}

struct Schedule<const NS: usize> {
    slots: Vec<Slot, NS>,
}

impl<const NS: usize> Schedule<NS> {
    /// Cyclic sensors are due at `start`, one-shot ones too when `one_shots`; on-demand sensors
    /// wait for a request.
    fn new<const NA: usize>(
        domain: &crate::domain::Domain<'_, NS, NA>,
        sensors: SensorSet,
        start: Instant,
        one_shots: bool,
    ) -> Self {
        let mut slots = Vec::new();
        for sensor in sensors.iter() {
            let Some(spec) = domain.sensor(sensor) else {
                continue;
            };
            let due = match spec.mode {
                SensorMode::Cyclic { .. } => Some(start),
                SensorMode::OneShot if one_shots => Some(start),
                SensorMode::OneShot | SensorMode::OnDemand => None,
            };
            // At most NS sensors exist, so this cannot overflow.
            let _ = slots.push(Slot {
                sensor,
                mode: spec.mode,
                due,
            });
        }
        Self { slots }
    }

    fn next_due(&self) -> Option<Instant> {
        self.slots.iter().filter_map(|s| s.due).min()
    }

    fn on_demand(&self) -> SensorSet {
        self.slots
            .iter()
            .filter(|s| s.mode == SensorMode::OnDemand)
            .map(|s| s.sensor)
            .collect()
    }
}

impl Slot {
    fn reschedule(&mut self, now: Instant) {
        self.due = match (self.mode, self.due) {
            (SensorMode::Cyclic { period }, Some(due)) => {
                // Keep the sampling phase; skip samples missed while the executor was busy.
                let period = period.max(Duration::from_ticks(1));
                let next = due.saturating_add(period);
                Some(if next <= now {
                    now.saturating_add(period)
                } else {
                    next
                })
            }
            _ => None,
        };
    }
}

async fn sleep_until(at: Option<Instant>) {
    match at {
        Some(at) => Timer::at(at).await,
        None => pending().await,
    }
}

fn outcome_result(action: ActionId, outcome: Outcome) -> Result<(), Failure> {
    match outcome {
        Outcome::Success => Ok(()),
        Outcome::Failure => Err(Failure::ActionFailed { action }),
        Outcome::Interrupted => Err(Failure::ActionInterrupted { action }),
    }
}

/// The P-SMPA runtime of one robot: the mission, the platform, the data stores of every
/// behaviour, the beliefs and the trace.
///
/// Capacities: `NS` sensors, `NA` actions, `NP` plans of at most `L` actions, `K` keys per
/// data store. Everything lives inside this value; put it in a `static` (with a
/// `StaticCell`) or on the stack of the task that runs it.
pub struct Runtime<
    'r,
    'a,
    M: RawMutex,
    S: Sensor,
    A: Actuator,
    T: TraceSink,
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const K: usize,
> {
    pub(crate) mission: &'r Mission<'a, NS, NA, NP, L>,
    sensors: &'r S,
    actuators: &'r A,
    pub(crate) config: Config,
    sensor_stores: [DataStore<M, K>; NS],
    action_stores: [DataStore<M, K>; NA],
    shared: Mutex<M, Shared<NS>>,
    tracer: Mutex<M, RefCell<Tracer<T>>>,
    trace_lost: Mutex<M, Cell<u32>>,
}

impl<
    'r,
    'a,
    M: RawMutex,
    S: Sensor,
    A: Actuator,
    T: TraceSink,
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const K: usize,
> Runtime<'r, 'a, M, S, A, T, NS, NA, NP, L, K>
{
    /// A runtime for `mission` on a platform, tracing into `sink`. The beliefs start at the
    /// task's initial state `τ0`.
    pub fn new(
        mission: &'r Mission<'a, NS, NA, NP, L>,
        sensors: &'r S,
        actuators: &'r A,
        sink: T,
        config: Config,
    ) -> Self {
        Self {
            mission,
            sensors,
            actuators,
            config,
            sensor_stores: [const { DataStore::new() }; NS],
            action_stores: [const { DataStore::new() }; NA],
            shared: Mutex::new(Shared {
                beliefs: Cell::new(mission.task.init),
                percepts: [const { Cell::new(None) }; NS],
                holds: [const { Cell::new(FactSet::EMPTY) }; NS],
                running: Cell::new(SensorSet::EMPTY),
                fresh: Cell::new(SensorSet::EMPTY),
                lost: [const { Cell::new(0) }; NS],
                sensed: Cell::new(FactSet::EMPTY),
                faulty: Cell::new(SensorSet::EMPTY),
                violation: Cell::new(None),
                requests: Cell::new(SensorSet::EMPTY),
                version: Cell::new(0),
                waiters: RefCell::new(MultiWakerRegistration::new()),
            }),
            tracer: Mutex::new(RefCell::new(Tracer::new(sink))),
            trace_lost: Mutex::new(Cell::new(0)),
        }
    }

    /// The mission.
    pub fn mission(&self) -> &'r Mission<'a, NS, NA, NP, L> {
        self.mission
    }

    /// The settings.
    pub fn config(&self) -> Config {
        self.config
    }

    /// The current beliefs `φ`.
    pub fn beliefs(&self) -> FactSet {
        self.shared.lock(|s| s.beliefs.get())
    }

    /// Percept facts a sample has shown to be false (facts never sensed are unknown, not false).
    pub fn known_false(&self) -> FactSet {
        self.shared
            .lock(|s| s.sensed.get().difference(s.beliefs.get()))
    }

    pub(crate) fn set_beliefs(&self, beliefs: FactSet) {
        self.shared.lock(|s| s.beliefs.set(beliefs));
        self.notify();
    }

    /// A snapshot of the world model `M = <ω, φ, Π>`.
    pub fn model(&self) -> WorldModel<NS> {
        self.shared.lock(|s| WorldModel {
            percepts: core::array::from_fn(|i| s.percepts.get(i).and_then(Cell::get)),
            beliefs: s.beliefs.get(),
            task: self.mission.task,
        })
    }

    /// The data store of a sensor-based action.
    pub fn sensor_store(&self, sensor: SensorId) -> Option<&DataStore<M, K>> {
        self.sensor_stores.get(sensor.index())
    }

    /// The data store of an actuator-based action.
    pub fn action_store(&self, action: ActionId) -> Option<&DataStore<M, K>> {
        self.action_stores.get(action.index())
    }

    /// The hash of the trace so far.
    pub fn trace_hash(&self) -> TraceHash {
        self.tracer
            .lock(|t| t.try_borrow().map(|t| t.hash()).unwrap_or_default())
    }

    /// Number of trace events so far.
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

    pub(crate) fn trace(&self, event: TraceEvent) {
        let at = Instant::now();
        let recorded = self.tracer.lock(|t| match t.try_borrow_mut() {
            Ok(mut t) => {
                t.record(at, &event);
                true
            }
            Err(_) => false,
        });
        if !recorded {
            self.trace_lost.lock(|n| n.set(n.get().saturating_add(1)));
        }
    }

    /// Something behaviours may wait for changed: bump the version and wake the waiters.
    fn notify(&self) {
        self.shared.lock(|s| {
            s.version.set(s.version.get().wrapping_add(1));
            if let Ok(mut w) = s.waiters.try_borrow_mut() {
                w.wake();
            }
        });
    }

    fn register(&self, cx: &mut Context<'_>) {
        self.shared.lock(|s| {
            if let Ok(mut w) = s.waiters.try_borrow_mut() {
                w.register(cx.waker());
            }
        });
    }

    /// Waits until a behaviour requests one of `sensors`.
    async fn requested(&self, sensors: SensorSet) {
        if sensors.is_empty() {
            return pending().await;
        }
        poll_fn(|cx| {
            let pending_requests = self
                .shared
                .lock(|s| s.requests.get().bits() & sensors.bits());
            if pending_requests != 0 {
                Poll::Ready(())
            } else {
                self.register(cx);
                Poll::Pending
            }
        })
        .await;
    }

    fn take_requests(&self, sensors: SensorSet) -> SensorSet {
        self.shared.lock(|s| {
            let all = s.requests.get();
            s.requests
                .set(SensorSet::from_bits(all.bits() & !sensors.bits()));
            SensorSet::from_bits(all.bits() & sensors.bits())
        })
    }

    fn sensor_timeout(&self, sensor: SensorId) -> Duration {
        self.mission
            .domain
            .sensor(sensor)
            .map_or(crate::action::SensorAction::DEFAULT_TIMEOUT, |s| s.timeout)
    }

    /// A sensor failed: it is out of service for the rest of the mission (a state that needs
    /// it fails at once, the planner does not count on it), until [`clear_faults`](Self::clear_faults).
    fn sensor_failed(&self, sensor: SensorId, fault: SensorFault) -> Failure {
        self.shared
            .lock(|s| s.faulty.set(s.faulty.get().with(sensor)));
        self.trace(TraceEvent::SensorFailed { sensor, fault });
        Failure::SensorFault { sensor, fault }
    }

    /// The sensors that failed and are out of service.
    pub fn faulty_sensors(&self) -> SensorSet {
        self.shared.lock(|s| s.faulty.get())
    }

    /// Puts every failed sensor back into service (after a repair or a reset of the device).
    pub fn clear_faults(&self) {
        self.shared.lock(|s| s.faulty.set(SensorSet::EMPTY));
    }

    /// Declares which sensors run from now on (for sensor fusion); none has sampled yet.
    pub(crate) fn set_running(&self, sensors: SensorSet) {
        self.shared.lock(|s| {
            s.running.set(sensors);
            s.fresh.set(SensorSet::EMPTY);
        });
    }

    /// Switches `sensors` on in id order; on a fault, switches back off those already on.
    pub(crate) async fn switch_on(&self, sensors: SensorSet) -> Result<(), Failure> {
        for sensor in sensors.iter() {
            let fault =
                match with_timeout(self.sensor_timeout(sensor), self.sensors.switch_on(sensor))
                    .await
                {
                    Ok(Ok(())) => {
                        self.trace(TraceEvent::SensorOn { sensor });
                        continue;
                    }
                    Ok(Err(fault)) => fault,
                    Err(_) => SensorFault::Timeout,
                };
            let on: SensorSet = sensors.iter().take_while(|s| *s != sensor).collect();
            self.switch_off(on).await;
            return Err(self.sensor_failed(sensor, fault));
        }
        Ok(())
    }

    /// Switches `sensors` off in id order. A sensor that does not answer is traced and counted
    /// off: the runtime will not use it again until it is switched on.
    pub(crate) async fn switch_off(&self, sensors: SensorSet) {
        for sensor in sensors.iter() {
            if with_timeout(self.sensor_timeout(sensor), self.sensors.switch_off(sensor))
                .await
                .is_err()
            {
                self.trace(TraceEvent::SensorFailed {
                    sensor,
                    fault: SensorFault::Timeout,
                });
            }
            self.trace(TraceEvent::SensorOff { sensor });
        }
    }

    /// Takes one sample: stores it (Algorithm 3 line 6), updates `ω` and the perception facts
    /// of `φ`, traces it and wakes the behaviour. Besides the platform's own sampling, bounded
    /// work: one store write (O(K) worst case), sensor fusion over the running sensors (O(NS)),
    /// one trace event (O(1)).
    pub(crate) async fn sample(&self, sensor: SensorId) -> Result<(), Failure> {
        let spec = self
            .mission
            .domain
            .sensor(sensor)
            .ok_or(Failure::SensorUnavailable { sensor })?;
        let reading = match with_timeout(spec.timeout, self.sensors.sample(sensor)).await {
            Ok(Ok(Some(reading))) => reading,
            Ok(Ok(None)) => {
                self.trace(TraceEvent::SampleLost { sensor });
                let lost = self.shared.lock(|s| {
                    s.lost.get(sensor.index()).map_or(u8::MAX, |n| {
                        n.set(n.get().saturating_add(1));
                        n.get()
                    })
                });
                if lost >= self.config.max_lost {
                    return Err(self.sensor_failed(sensor, SensorFault::Silent));
                }
                return Ok(());
            }
            Ok(Err(fault)) => return Err(self.sensor_failed(sensor, fault)),
            Err(_) => return Err(self.sensor_failed(sensor, SensorFault::Timeout)),
        };
        self.shared.lock(|s| {
            if let Some(n) = s.lost.get(sensor.index()) {
                n.set(0);
            }
        });
        let now = Instant::now();
        let holds = reading.holds.intersection(spec.per);
        let entry = Entry {
            value: reading.value,
            at: now,
        };
        self.sensor_stores
            .get(sensor.index())
            .ok_or(Failure::SensorUnavailable { sensor })?
            .put(SAMPLE_KEY, reading.value, now)
            .map_err(|e| Failure::StoreFull { key: e.key })?;
        let domain = &self.mission.domain;
        self.shared.lock(|s| {
            if let Some(h) = s.holds.get(sensor.index()) {
                h.set(holds);
            }
            let fresh = s.fresh.get().with(sensor);
            s.fresh.set(fresh);
            // Sensor fusion by conjunction: a fact of per(s) holds only if no running sensor that
            // perceives it and has sampled says otherwise (the sonar sees a box while the bumper
            // feels nothing: the path is not clear).
            let sampled = SensorSet::from_bits(s.running.get().bits() & fresh.bits()).with(sensor);
            let decided = sampled.iter().fold(spec.per, |acc, t| {
                let per_t = domain.sensor(t).map_or(FactSet::EMPTY, |t| t.per);
                let holds_t = s.holds.get(t.index()).map_or(FactSet::EMPTY, Cell::get);
                acc.difference(per_t.difference(holds_t))
            });
            s.beliefs
                .set(s.beliefs.get().difference(spec.per).union(decided));
            s.sensed.set(s.sensed.get().union(spec.per));
            if let Some(p) = s.percepts.get(sensor.index()) {
                p.set(Some(entry));
            }
        });
        self.trace(TraceEvent::Sample {
            sensor,
            value: reading.value,
            holds,
        });
        self.notify();
        Ok(())
    }

    /// When the latest sample was taken that says one of `missing` does not hold: the newest
    /// evidence of a violation. Samples of other sensors that only repeat the fused verdict are
    /// not evidence.
    fn evidence(&self, missing: FactSet) -> Option<Instant> {
        let domain = &self.mission.domain;
        self.shared.lock(|s| {
            let sampled = SensorSet::from_bits(s.running.get().bits() & s.fresh.get().bits());
            sampled
                .iter()
                .filter(|t| {
                    let per_t = domain.sensor(*t).map_or(FactSet::EMPTY, |t| t.per);
                    let holds_t = s.holds.get(t.index()).map_or(FactSet::EMPTY, Cell::get);
                    per_t.difference(holds_t).intersects(missing)
                })
                .filter_map(|t| s.percepts.get(t.index()).and_then(Cell::get))
                .map(|e| e.at)
                .max()
        })
    }

    /// Compares `pre(a)` with the beliefs after new samples; tells the behaviour about a change
    /// and fails once the precondition has been false for `max_violation`.
    fn monitor_precondition(&self, action: ActionId, pre: FactSet) -> Result<(), Failure> {
        let now = Instant::now();
        let missing = pre.difference(self.beliefs());
        let before = self.shared.lock(|s| s.violation.get());
        match (missing.is_empty(), before) {
            (true, None) => return Ok(()),
            (true, Some(_)) => {
                self.shared.lock(|s| s.violation.set(None));
                self.trace(TraceEvent::PreconditionRestored { action });
            }
            (false, None) => {
                let seen = self.evidence(missing).unwrap_or(now);
                self.shared.lock(|s| {
                    s.violation.set(Some(Violation {
                        missing,
                        since: seen,
                        last_seen: seen,
                    }))
                });
                self.trace(TraceEvent::PreconditionViolated { action, missing });
            }
            (false, Some(v)) => {
                let last_seen = self.evidence(missing).unwrap_or(v.last_seen);
                let changed = v.missing != missing || last_seen != v.last_seen;
                self.shared.lock(|s| {
                    s.violation.set(Some(Violation {
                        missing,
                        last_seen,
                        ..v
                    }))
                });
                if v.missing != missing {
                    self.trace(TraceEvent::PreconditionViolated { action, missing });
                }
                if now.saturating_duration_since(v.since) >= self.config.max_violation {
                    return Err(Failure::PreconditionViolated { action, missing });
                }
                if !changed {
                    return Ok(());
                }
            }
        }
        self.notify();
        Ok(())
    }

    fn violation_deadline(&self) -> Option<Instant> {
        self.shared
            .lock(|s| s.violation.get())
            .map(|v| v.since.saturating_add(self.config.max_violation))
    }

    /// Samples every sensor of `schedule` that is due at `now` or was requested.
    async fn sample_due(
        &self,
        schedule: &mut Schedule<NS>,
        now: Instant,
        requested: SensorSet,
    ) -> Result<(), Failure> {
        for slot in schedule.slots.iter_mut() {
            if slot.due.is_some_and(|d| d <= now) || requested.contains(slot.sensor) {
                self.sample(slot.sensor).await?;
                slot.reschedule(now);
            }
        }
        Ok(())
    }

    /// The sensor side of a parallel state: samples on schedule and on request, monitors the
    /// precondition, until `until` (SMPA sense phase) or until a failure.
    async fn sense(
        &self,
        action: ActionId,
        pre: FactSet,
        schedule: &mut Schedule<NS>,
        until: Option<Instant>,
    ) -> Result<(), Failure> {
        let on_demand = schedule.on_demand();
        loop {
            let wake = [schedule.next_due(), self.violation_deadline(), until]
                .into_iter()
                .flatten()
                .min();
            select(sleep_until(wake), self.requested(on_demand)).await;
            let now = Instant::now();
            if until.is_some_and(|u| now >= u) {
                return Ok(());
            }
            let requested = self.take_requests(on_demand);
            self.sample_due(schedule, now, requested).await?;
            self.monitor_precondition(action, pre)?;
        }
    }

    /// P-SMPA: `δ'_i = δ_i ∥ {s_k}`; the sensors end when the action ends.
    async fn run_parallel(
        &self,
        action: ActionId,
        spec: &ActuatorAction<'a>,
        sensors: SensorSet,
        io: &ActionIo<'_>,
    ) -> Result<Outcome, Failure> {
        self.switch_on(sensors).await?;
        self.set_running(sensors);
        let result = async {
            let start = Instant::now();
            let mut schedule = Schedule::new(&self.mission.domain, sensors, start, true);
            // Fresh percepts before the behaviour starts.
            self.sample_due(&mut schedule, start, SensorSet::EMPTY)
                .await?;
            self.monitor_precondition(action, spec.pre)?;
            let mut behaviour = pin!(self.actuators.run(action, io));
            match select(
                behaviour.as_mut(),
                self.sense(action, spec.pre, &mut schedule, None),
            )
            .await
            {
                Either::First(outcome) => Ok(outcome),
                // `sense` without an end returns only on failure.
                Either::Second(Ok(())) => Ok(behaviour.await),
                Either::Second(Err(failure)) => {
                    self.actuators.halt(action);
                    Err(failure)
                }
            }
        }
        .await;
        self.switch_off(sensors).await;
        result
    }

    /// One SMPA sense phase: sensors on, actuators idle, samples until `until`, sensors off.
    async fn sense_phase(
        &self,
        action: ActionId,
        spec: &ActuatorAction<'a>,
        sensors: SensorSet,
        until: Instant,
        first: bool,
    ) -> Result<(), Failure> {
        self.switch_on(sensors).await?;
        self.set_running(sensors);
        let result = async {
            let start = Instant::now();
            let mut schedule = Schedule::new(&self.mission.domain, sensors, start, first);
            self.sample_due(&mut schedule, start, SensorSet::EMPTY)
                .await?;
            self.monitor_precondition(action, spec.pre)?;
            self.sense(action, spec.pre, &mut schedule, Some(until))
                .await
        }
        .await;
        self.switch_off(sensors).await;
        result
    }

    /// SMPA: sense phase, act phase, sense phase, ... until the behaviour ends.
    async fn run_alternating(
        &self,
        action: ActionId,
        spec: &ActuatorAction<'a>,
        sensors: SensorSet,
        io: &ActionIo<'_>,
        sense: Duration,
        act: Duration,
    ) -> Result<Outcome, Failure> {
        // A phase of no time would alternate forever at one instant.
        let (sense, act) = (
            sense.max(Duration::from_ticks(1)),
            act.max(Duration::from_ticks(1)),
        );
        let mut behaviour = pin!(self.actuators.run(action, io));
        let mut first = true;
        loop {
            self.trace(TraceEvent::PhaseStarted {
                action,
                phase: Phase::Sense,
            });
            self.actuators.hold(action, true);
            let until = Instant::now().saturating_add(sense);
            let sensed = self.sense_phase(action, spec, sensors, until, first).await;
            first = false;
            self.actuators.hold(action, false);
            if let Err(failure) = sensed {
                self.actuators.halt(action);
                return Err(failure);
            }
            self.trace(TraceEvent::PhaseStarted {
                action,
                phase: Phase::Act,
            });
            let act_end = Instant::now().saturating_add(act);
            if let Either::First(outcome) = select(behaviour.as_mut(), Timer::at(act_end)).await {
                return Ok(outcome);
            }
        }
    }

    /// Runs one behaviour state to its end and applies the action's effects on success.
    async fn run_state(&self, index: u8, state: &BehaviourState) -> Result<(), Failure> {
        let action = state.action;
        let sensors = state.sensors;
        self.trace(TraceEvent::StateEntered {
            state: index,
            action,
            sensors,
        });
        let result = self.run_action(action, sensors).await;
        self.shared.lock(|s| {
            s.violation.set(None);
            s.requests.set(SensorSet::EMPTY);
        });
        self.set_running(SensorSet::EMPTY);
        let (outcome, result) = match result {
            Ok(outcome) => (Some(outcome), outcome_result(action, outcome)),
            Err(failure) => (None, Err(failure)),
        };
        if result.is_ok() {
            if let Some(spec) = self.mission.domain.action(action) {
                let beliefs = self.beliefs().apply(spec.add, spec.del);
                self.set_beliefs(beliefs);
                self.trace(TraceEvent::EffectsApplied { action, beliefs });
            }
        }
        self.trace(TraceEvent::StateLeft {
            state: index,
            action,
            outcome,
        });
        result
    }

    async fn run_action(&self, action: ActionId, sensors: SensorSet) -> Result<Outcome, Failure> {
        let domain = &self.mission.domain;
        let spec = domain
            .action(action)
            .ok_or(Failure::ActionFailed { action })?;
        // Facts of pre(a) that no running sensor decides must already hold.
        let beliefs = self.beliefs();
        let missing = spec
            .pre
            .difference(domain.perception_of(sensors))
            .difference(beliefs);
        if !missing.is_empty() {
            return Err(Failure::PreconditionUnmet { action, missing });
        }
        if let Some(sensor) = sensors.iter().find(|s| {
            domain
                .sensor(*s)
                .is_none_or(|spec| !spec.pre.is_subset(beliefs))
        }) {
            return Err(Failure::SensorUnavailable { sensor });
        }
        let own = self
            .action_stores
            .get(action.index())
            .ok_or(Failure::ActionFailed { action })?;
        let io = ActionIo {
            action,
            store: MutualStore::link(own, &self.sensor_stores, sensors),
            monitor: self,
        };
        debug!(
            "action {} starts with sensors {:?}",
            action.index(),
            sensors.bits()
        );
        if sensors.is_empty() {
            return Ok(self.actuators.run(action, &io).await);
        }
        match self.config.policy {
            Policy::PSmpa => self.run_parallel(action, spec, sensors, &io).await,
            Policy::Smpa { sense, act } => {
                self.run_alternating(action, spec, sensors, &io, sense, act)
                    .await
            }
        }
    }

    /// `executePlans` for one plan: runs its FSM from the initial state along the transition
    /// rules `T` until [`Target::Done`] or [`Target::Failed`]. Between two states the work is
    /// bounded: the transition is O(1), switching sensors off and on O(NS), the effects O(1).
    pub async fn execute(&self, fsm: &Fsm<L>) -> Result<(), Failure> {
        let mut index = 0u8;
        loop {
            let state = fsm
                .state(index)
                .ok_or(Failure::InvalidFsm { state: index })?;
            let result = self.run_state(index, state).await;
            let edge = if result.is_ok() {
                Edge::Success
            } else {
                Edge::Failure
            };
            match state.next(edge) {
                Target::State(next) => index = next,
                Target::Done => return result,
                // Compiled machines only fail on the failure edge; anything else is a broken FSM.
                Target::Failed => return result.and(Err(Failure::InvalidFsm { state: index })),
            }
        }
    }
}

impl<
    M: RawMutex,
    S: Sensor,
    A: Actuator,
    T: TraceSink,
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const K: usize,
> Monitor for Runtime<'_, '_, M, S, A, T, NS, NA, NP, L, K>
{
    fn beliefs(&self) -> FactSet {
        Runtime::beliefs(self)
    }

    fn violation(&self) -> Option<Violation> {
        self.shared.lock(|s| s.violation.get())
    }

    fn version(&self) -> u32 {
        self.shared.lock(|s| s.version.get())
    }

    fn poll_changed(&self, cx: &mut Context<'_>, since: u32) -> Poll<u32> {
        let now = Monitor::version(self);
        if now != since {
            return Poll::Ready(now);
        }
        self.register(cx);
        Poll::Pending
    }

    fn request(&self, sensor: SensorId) {
        self.shared
            .lock(|s| s.requests.set(s.requests.get().with(sensor)));
        self.notify();
    }

    fn user(&self, code: u16, value: i32) {
        self.trace(TraceEvent::User { code, value });
    }
}

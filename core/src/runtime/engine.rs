//! Executing compiled plans: Algorithm 2 at run time, on two sides that run concurrently.
//!
//! * **Sensing** ([`SensingSide`](crate::SensingSide), the paper's sensory controller): one sampler per
//!   sensor, each on its own schedule; a sample is read, stored, fused into the beliefs and
//!   checked against the running action's precondition, and whoever waits is woken. See
//!   [`crate::runtime::sensing`].
//! * **Deciding** ([`DecidingSide`](crate::DecidingSide), the deliberative controller): the control loop
//!   (Algorithm 1), the FSM of the selected plan and the actuator behaviours. It switches
//!   sensors on and off by telling the sensing side which sensors the running state needs
//!   (least commitment), and learns what they perceive from the beliefs and the data stores.
//!
//! The two sides share only the stores and an embassy-sync mutex over a little state, so a
//! platform may run them on one executor, or sensing on a higher-priority one (an
//! `InterruptExecutor` on a microcontroller); a long behaviour or planner poll then cannot
//! delay a sample. Under either policy:
//!
//! * [`Policy::PSmpa`]: a parallel state `δ'_i` has its sensors switched on and sampled once,
//!   then runs the actuator behaviour while they keep sampling. When the beliefs make
//!   `pre(a_i)` false (a percept, or at the start a fact still believed false that no sensor
//!   of the state has sampled yet, as an on-demand sensor's until it is asked) the behaviour
//!   is told at once ([`ActionIo::violation`]); if it stays false longer
//!   than the action's [`max_violation`](crate::ActuatorAction::max_violation) (or
//!   [`Config::max_violation`]) the runtime stops the behaviour and takes the failure edge. The sensors are switched off when the action ends.
//! * [`Policy::Smpa`]: the baseline. The same state alternates a sense phase (sensors on,
//!   actuators held) and an act phase (behaviour polled, sensors off). Only the policy differs:
//!   the actions, sensors, behaviours and precondition checks are the same code.
//!
//! Cost: starting or ending a state is O(NS) plus the sensors' own switching; a sample's cost
//! on the sensing side is in [`crate::runtime::sensing`].

use core::cell::{Cell, RefCell};
use core::future::poll_fn;
use core::pin::pin;
use core::task::{Context, Poll};

use embassy_futures::select::{Either, select};
use embassy_sync::blocking_mutex::Mutex;
use embassy_time::{Duration, Instant, Timer};

use crate::action::{ActionId, ActuatorAction, SensorId, SensorSet};
use crate::facts::FactSetOf;
use crate::failure::{Failure, Violation};
use crate::fmt::debug;
use crate::mission::Mission;
use crate::model::WorldModel;
use crate::platform::{ActionIo, Actuator, FromId, Monitor, Outcome, Platform, Sensor};
use crate::runtime::fsm::{BehaviourState, Edge, Fsm, Target};
use crate::runtime::shared::{Command, Mode, Shared, Waiter, Watch, poll_shared};
use crate::store::{DataStore, MutualStore};
use crate::trace::{Phase, TraceEvent, TraceHash, TraceSink, Tracer};

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
    /// ([`ActuatorAction::max_violation`]). The behaviour is told at once either way.
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
        }
    }
}

fn outcome_result<const W: usize>(action: ActionId, outcome: Outcome) -> Result<(), Failure<W>> {
    match outcome {
        Outcome::Success => Ok(()),
        Outcome::Failure => Err(Failure::ActionFailed { action }),
        Outcome::Interrupted => Err(Failure::ActionInterrupted { action }),
    }
}

/// What a [`Runtime`](crate::Runtime) does: the mission, the platform, the data stores of
/// every behaviour, the beliefs and the trace. Name it through [`Runtime`](crate::Runtime)
/// and [`Caps`](crate::Caps); its capacities are `NS` sensors, `NA` actions, `NP` plans of at
/// most `L` actions, `K` keys per data store, `NF` facts in fact sets of `W` words.
///
/// It runs as two sides, handed out once by [`split`](Self::split): the sensing side, which
/// never ends, and the deciding side's control loop. Run both: on one executor
/// ([`run_with_sensing`](Self::run_with_sensing) polls sensing first), or sensing in a task
/// of a higher-priority executor.
pub struct Engine<
    'r,
    P: Platform,
    T,
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const K: usize,
    const W: usize = 1,
    const NF: usize = 64,
> {
    pub(crate) mission: &'r Mission<'r, NS, NA, NP, L, W, NF>,
    pub(crate) platform: &'r P,
    pub(crate) config: Config,
    pub(crate) sensor_stores: [DataStore<P::Mutex, K>; NS],
    action_stores: [DataStore<P::Mutex, K>; NA],
    pub(crate) shared: Mutex<P::Mutex, Shared<NS, W>>,
    tracer: Mutex<P::Mutex, RefCell<Tracer<T>>>,
    trace_lost: Mutex<P::Mutex, Cell<u32>>,
}

impl<
    'r,
    P: Platform + Sensor<W> + Actuator<W>,
    T: TraceSink<W>,
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const K: usize,
    const W: usize,
    const NF: usize,
> Engine<'r, P, T, NS, NA, NP, L, K, W, NF>
{
    /// A runtime for `mission` on `platform`, tracing into `sink`. The beliefs start at the
    /// task's initial state `τ0`.
    pub fn new(
        mission: &'r Mission<'r, NS, NA, NP, L, W, NF>,
        platform: &'r P,
        sink: T,
        config: Config,
    ) -> Self {
        Self {
            mission,
            platform,
            config,
            sensor_stores: [const { DataStore::new() }; NS],
            action_stores: [const { DataStore::new() }; NA],
            shared: Mutex::new(Shared {
                beliefs: Cell::new(mission.task.init),
                percepts: [const { Cell::new(None) }; NS],
                holds: [const { Cell::new(FactSetOf::EMPTY) }; NS],
                running: Cell::new(SensorSet::EMPTY),
                fresh: Cell::new(SensorSet::EMPTY),
                lost: [const { Cell::new(0) }; NS],
                last_read: [const { Cell::new(None) }; NS],
                sensed: Cell::new(FactSetOf::EMPTY),
                faulty: Cell::new(SensorSet::EMPTY),
                violation: Cell::new(None),
                requests: Cell::new(SensorSet::EMPTY),
                version: Cell::new(0),
                command: Cell::new(Command {
                    epoch: 0,
                    sensors: SensorSet::EMPTY,
                    mode: Mode::Parallel,
                    watch: None,
                    start: Instant::from_ticks(0),
                }),
                ready: Cell::new(SensorSet::EMPTY),
                active: Cell::new(SensorSet::EMPTY),
                failure: Cell::new(None),
                epoch: Cell::new(0),
                deciding: Waiter::new(),
                sensing: Waiter::new(),
            }),
            tracer: Mutex::new(RefCell::new(Tracer::new(sink))),
            trace_lost: Mutex::new(Cell::new(0)),
        }
    }

    /// The mission.
    pub fn mission(&self) -> &'r Mission<'r, NS, NA, NP, L, W, NF> {
        self.mission
    }

    /// The settings.
    pub fn config(&self) -> Config {
        self.config
    }

    /// The current beliefs `φ`.
    pub fn beliefs(&self) -> FactSetOf<W> {
        self.shared.lock(|s| s.beliefs.get())
    }

    /// Percept facts a sample (or an action's effects) has shown to be false: facts never
    /// sensed are unknown, not false.
    pub fn known_false(&self) -> FactSetOf<W> {
        self.shared
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
        let perceivable = (self.mission.domain.sensors().iter())
            .fold(FactSetOf::EMPTY, |acc, s| acc.union(s.per));
        self.shared.lock(|s| {
            let (sensed, beliefs) = (s.sensed.get(), s.beliefs.get());
            (
                sensed.difference(beliefs),
                perceivable.difference(sensed.union(beliefs)),
                s.faulty.get(),
            )
        })
    }

    pub(crate) fn set_beliefs(&self, beliefs: FactSetOf<W>) {
        self.shared.lock(|s| s.beliefs.set(beliefs));
        self.notify();
    }

    /// A snapshot of the world model `M = <ω, φ, Π>`.
    pub fn model(&self) -> WorldModel<NS, W> {
        self.shared.lock(|s| WorldModel {
            percepts: core::array::from_fn(|i| s.percepts.get(i).and_then(Cell::get)),
            beliefs: s.beliefs.get(),
            task: self.mission.task,
        })
    }

    /// The data store of a sensor-based action.
    pub fn sensor_store(&self, sensor: SensorId) -> Option<&DataStore<P::Mutex, K>> {
        self.sensor_stores.get(sensor.index())
    }

    /// The data store of an actuator-based action.
    pub fn action_store(&self, action: ActionId) -> Option<&DataStore<P::Mutex, K>> {
        self.action_stores.get(action.index())
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
                t.record(at, &event);
                true
            }
            Err(_) => false,
        });
        if !recorded {
            self.trace_lost.lock(|n| n.set(n.get().saturating_add(1)));
        }
    }

    /// Something the deciding side may wait for changed: bump the version and wake it.
    pub(crate) fn notify(&self) {
        self.shared.lock(Shared::notify);
    }

    /// Something a sampler may wait for changed (a command, a request): wake the sensing side.
    pub(crate) fn wake_sensing(&self) {
        self.shared.lock(|s| {
            s.sensing.wake();
        });
    }

    /// [`poll_shared`] for the deciding side.
    fn poll_deciding<R>(
        &self,
        cx: &mut Context<'_>,
        done: impl FnOnce(&Shared<NS, W>) -> Option<R>,
    ) -> Poll<R> {
        poll_shared(&self.shared, cx, |s| &s.deciding, done)
    }

    /// [`poll_shared`] for a sampler.
    pub(crate) fn poll_sensing<R>(
        &self,
        cx: &mut Context<'_>,
        done: impl FnOnce(&Shared<NS, W>) -> Option<R>,
    ) -> Poll<R> {
        poll_shared(&self.shared, cx, |s| &s.sensing, done)
    }

    /// The sensors that failed and are out of service: a state that needs one fails at once
    /// with [`Failure::SensorUnavailable`], and the planner does not count on them.
    pub fn faulty_sensors(&self) -> SensorSet {
        self.shared.lock(|s| s.faulty.get())
    }

    /// Puts every failed sensor back into service (after a repair or a reset of the device).
    pub fn clear_faults(&self) {
        self.shared.lock(|s| {
            s.faulty.set(SensorSet::EMPTY);
            for lost in &s.lost {
                lost.set(0);
            }
        });
    }

    /// Tells the sensing side to run `sensors` from now on; returns the command's epoch.
    pub(crate) fn command(
        &self,
        sensors: SensorSet,
        mode: Mode,
        watch: Option<(ActionId, FactSetOf<W>)>,
    ) -> u32 {
        let start = Instant::now();
        let epoch = self.shared.lock(|s| {
            let epoch = s.command.get().epoch.wrapping_add(1);
            s.command.set(Command {
                epoch,
                sensors,
                mode,
                watch,
                start,
            });
            s.epoch.set(epoch);
            s.ready.set(SensorSet::EMPTY);
            s.failure.set(None);
            epoch
        });
        self.wake_sensing();
        epoch
    }

    /// How long the sensing side may take to answer for `sensors`: `steps` calls of the
    /// slowest one's timeout, and a tick.
    fn answer_within(&self, sensors: SensorSet, steps: u32) -> Duration {
        let slowest = sensors
            .iter()
            .filter_map(|s| self.mission.domain.sensor(s))
            .map(|s| s.timeout)
            .max()
            .unwrap_or(Duration::from_ticks(0));
        let ticks = slowest.as_ticks().saturating_mul(u64::from(steps));
        Duration::from_ticks(ticks.saturating_add(1))
    }

    /// Waits until `sensors` are on and have attempted the samples due at the command's start
    /// (a sample lost there counts: waiting for the next one could take a period), or one of
    /// them failed.
    pub(crate) async fn ready(&self, epoch: u32, sensors: SensorSet) -> Result<(), Failure<W>> {
        // Switching on and the first sample are each bounded by the sensor's timeout.
        let limit = Instant::now().saturating_add(self.answer_within(sensors, 2));
        let answered = poll_fn(|cx| {
            self.poll_deciding(cx, |s| {
                if let Some((_, failure)) = s.failure.get().filter(|(e, _)| *e == epoch) {
                    return Some(Err(failure));
                }
                (sensors.bits() & !s.ready.get().bits() == 0).then_some(Ok(()))
            })
        });
        match select(answered, Timer::at(limit)).await {
            Either::First(result) => result,
            Either::Second(()) => Err(Failure::SensingStalled),
        }
    }

    /// Tells the sensing side to switch every sensor off, and waits until it has.
    pub(crate) async fn stop(&self) -> Result<(), Failure<W>> {
        let active = self.shared.lock(|s| s.active.get());
        self.command(SensorSet::EMPTY, Mode::Parallel, None);
        if active.is_empty() {
            return Ok(());
        }
        // A sampler may still be switching on (after another sensor failed), then off.
        let limit = Instant::now().saturating_add(self.answer_within(active, 2));
        let off = poll_fn(|cx| self.poll_deciding(cx, |s| s.active.get().is_empty().then_some(())));
        match select(off, Timer::at(limit)).await {
            Either::First(()) => Ok(()),
            Either::Second(()) => Err(Failure::SensingStalled),
        }
    }

    /// Watches the running action under command `epoch`: returns the first failure the
    /// sensing side reports, or the violation of `pre(a)` once it has lasted the action's
    /// `max_violation` (or [`Config::max_violation`]). Never returns while all is well. One lock
    /// a poll; woken by every delivery, and by a timer at the deadline of a violation.
    fn watch(&self, epoch: u32, action: ActionId) -> Watch<'_, P::Mutex, NS, W> {
        let max = self
            .mission
            .domain
            .action(action)
            .and_then(|a| a.max_violation)
            .unwrap_or(self.config.max_violation);
        Watch {
            shared: &self.shared,
            epoch,
            action,
            max,
            alarm: None,
            registered: false,
        }
    }

    /// P-SMPA: `δ'_i = δ_i ∥ {s_k}`; the sensors end when the action ends.
    async fn run_parallel(
        &self,
        action: ActionId,
        name: <P as Actuator<W>>::Id,
        spec: &ActuatorAction<'r, W>,
        sensors: SensorSet,
        io: &ActionIo<'_, W>,
    ) -> Result<Outcome, Failure<W>> {
        let epoch = self.command(sensors, Mode::Parallel, Some((action, spec.pre)));
        let result = async {
            // Fresh percepts before the behaviour starts, checked against its precondition.
            self.ready(epoch, sensors).await?;
            self.check_precondition();
            // The watch first: a failure reported at this instant stops the behaviour before
            // it takes another step.
            let behaviour = self.platform.run(name, io);
            match select(self.watch(epoch, action), behaviour).await {
                Either::First(failure) => {
                    self.platform.halt(name);
                    Err(failure)
                }
                Either::Second(outcome) => Ok(outcome),
            }
        }
        .await;
        let stopped = self.stop().await;
        result.and_then(|outcome| stopped.map(|()| outcome))
    }

    /// One SMPA sense phase: sensors on, actuators idle, samples until `until`, sensors off.
    async fn sense_phase(
        &self,
        action: ActionId,
        spec: &ActuatorAction<'r, W>,
        sensors: SensorSet,
        until: Instant,
        first: bool,
    ) -> Result<(), Failure<W>> {
        let epoch = self.command(sensors, Mode::Phase { first }, Some((action, spec.pre)));
        let result = async {
            self.ready(epoch, sensors).await?;
            self.check_precondition();
            match select(self.watch(epoch, action), Timer::at(until)).await {
                Either::First(failure) => Err(failure),
                Either::Second(()) => Ok(()),
            }
        }
        .await;
        let stopped = self.stop().await;
        result.and(stopped)
    }

    /// SMPA: sense phase, act phase, sense phase, ... until the behaviour ends.
    async fn run_alternating(
        &self,
        action: ActionId,
        name: <P as Actuator<W>>::Id,
        spec: &ActuatorAction<'r, W>,
        sensors: SensorSet,
        io: &ActionIo<'_, W>,
        (sense, act): (Duration, Duration),
    ) -> Result<Outcome, Failure<W>> {
        // A phase of no time would alternate forever at one instant.
        let (sense, act) = (
            sense.max(Duration::from_ticks(1)),
            act.max(Duration::from_ticks(1)),
        );
        let mut behaviour = pin!(self.platform.run(name, io));
        let mut first = true;
        loop {
            self.trace(TraceEvent::PhaseStarted {
                action,
                phase: Phase::Sense,
            });
            self.platform.hold(name, true);
            let until = Instant::now().saturating_add(sense);
            let sensed = self.sense_phase(action, spec, sensors, until, first).await;
            first = false;
            self.platform.hold(name, false);
            if let Err(failure) = sensed {
                self.platform.halt(name);
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
    async fn run_state(&self, index: u8, state: &BehaviourState) -> Result<(), Failure<W>> {
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
        let (outcome, result) = match result {
            Ok(outcome) => (Some(outcome), outcome_result(action, outcome)),
            Err(failure) => (None, Err(failure)),
        };
        if result.is_ok()
            && let Some(spec) = self.mission.domain.action(action)
        {
            let beliefs = self.beliefs().apply(spec.add, spec.del);
            // The effects are known, as a sample's percepts are: a percept fact an action
            // deleted is known false, not unknown.
            self.shared
                .lock(|s| s.sensed.set(s.sensed.get().union(spec.add).union(spec.del)));
            self.set_beliefs(beliefs);
            self.trace(TraceEvent::EffectsApplied { action, beliefs });
        }
        self.trace(TraceEvent::StateLeft {
            state: index,
            action,
            outcome,
        });
        result
    }

    async fn run_action(
        &self,
        action: ActionId,
        sensors: SensorSet,
    ) -> Result<Outcome, Failure<W>> {
        let domain = &self.mission.domain;
        let spec = domain
            .action(action)
            .ok_or(Failure::ActionFailed { action })?;
        // A sensor out of service cannot watch the action: fail before moving anything.
        let faulty = self.faulty_sensors();
        if let Some(sensor) = sensors.iter().find(|s| faulty.contains(*s)) {
            return Err(Failure::SensorUnavailable { sensor });
        }
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
        // The platform's name of the action (`Actuator::Id`); none: it cannot run it.
        let Some(name) = <P as Actuator<W>>::Id::from_id(action) else {
            return Ok(Outcome::Failure);
        };
        if sensors.is_empty() {
            return Ok(self.platform.run(name, &io).await);
        }
        match self.config.policy {
            Policy::PSmpa => self.run_parallel(action, name, spec, sensors, &io).await,
            Policy::Smpa { sense, act } => {
                self.run_alternating(action, name, spec, sensors, &io, (sense, act))
                    .await
            }
        }
    }

    /// `executePlans` for one plan: runs its FSM from the initial state along the transition
    /// rules `T` until [`Target::Done`] or [`Target::Failed`]. Between two states the work is
    /// bounded: the transition is O(1), switching sensors off and on O(NS), the effects O(1).
    pub(crate) async fn execute(&self, fsm: &Fsm<L>) -> Result<(), Failure<W>> {
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
    'r,
    P: Platform + Sensor<W> + Actuator<W>,
    T: TraceSink<W>,
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const K: usize,
    const W: usize,
    const NF: usize,
> Monitor<W> for Engine<'r, P, T, NS, NA, NP, L, K, W, NF>
{
    fn beliefs(&self) -> FactSetOf<W> {
        Engine::beliefs(self)
    }

    fn violation(&self) -> Option<Violation<W>> {
        self.shared.lock(|s| s.violation.get())
    }

    fn version(&self) -> u32 {
        self.shared.lock(|s| s.version.get())
    }

    fn poll_changed(&self, cx: &mut Context<'_>, since: u32) -> Poll<u32> {
        self.poll_deciding(cx, |s| {
            let now = s.version.get();
            (now != since).then_some(now)
        })
    }

    fn request(&self, sensor: SensorId) {
        self.shared
            .lock(|s| s.requests.set(s.requests.get().with(sensor)));
        self.wake_sensing();
    }

    fn user(&self, code: u16, value: i32) {
        self.trace(TraceEvent::User { code, value });
    }
}

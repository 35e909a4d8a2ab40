//! The deciding side's states: one behaviour state `δ_i` (or parallel state `δ'_i`) from its
//! start to its end, under either policy. One future runs a plan's states in turn
//! (`run_plan`): a compiled mission's from its constant states
//! ([`Mission::states`](crate::Mission::states)), a plan of the run-time FSM from states read
//! from the tables.
//!
//! * [`Policy::PSmpa`]: a parallel state `δ'_i` has its sensors switched on and sampled once,
//!   then runs the actuator behaviour while they keep sampling. When the beliefs make
//!   `pre(a_i)` false (a percept, or at the start a fact still believed false that no sensor
//!   of the state has sampled yet, as an on-demand sensor's until it is asked) the behaviour
//!   is told at once ([`ActionIo::violation`]); if it stays false longer than the action's
//!   `max_violation` (or [`Config::max_violation`](crate::Config::max_violation)) the runtime
//!   stops the behaviour and takes the failure edge. The sensors are switched off when the
//!   action ends.
//! * [`Policy::Smpa`]: the baseline. The same state alternates a sense phase (sensors on,
//!   actuators held) and an act phase (behaviour polled, sensors off). Only the policy differs:
//!   the actions, sensors, behaviours and precondition checks are the same code.
//!
//! Cost: starting or ending a state is O(NS) plus the sensors' own switching; a sample's cost
//! on the sensing side is in [`crate::runtime::sensing`].

use core::future::{Future, poll_fn};
use core::marker::PhantomData;
use core::pin::{Pin, pin};
use core::task::{Context, Poll};

use embassy_futures::select::{Either, select};
use embassy_time::{Duration, Instant, Timer};
use pin_project_lite::pin_project;

use crate::action::{SensorSet, perception_of};
use crate::facts::FactSetOf;
use crate::failure::Failure;
use crate::fmt::debug;
use crate::plan::PlanId;
use crate::platform::{Actuator, Outcome, Platform, Sensor};
use crate::runtime::fsm::{Edge, Fsm, Target};
use crate::runtime::shared::Watch;
use crate::runtime::{Plans, Policy, Runtime};
use crate::spec::storage::{Command, Mode};
use crate::spec::{Act, ActionIo};
use crate::spec::{ActionOf, Mission, State, Storage};
use crate::store::MutualStore;
use crate::trace::{Phase, TraceEvent, TraceSink};

fn outcome_result<const W: usize>(
    action: crate::action::ActionId,
    outcome: Outcome,
) -> Result<(), Failure<W>> {
    match outcome {
        Outcome::Success => Ok(()),
        Outcome::Failure => Err(Failure::ActionFailed { action }),
        Outcome::Interrupted => Err(Failure::ActionInterrupted { action }),
    }
}

impl<'r, M, P, T, const W: usize> Runtime<'r, M, P, T>
where
    M: Mission<Facts = FactSetOf<W>>,
    P: Platform + Sensor<M> + Actuator<M>,
    T: TraceSink<M>,
{
    /// Tells the sensing side to run `sensors` from now on; returns the command's epoch.
    pub(crate) fn command(
        &self,
        sensors: SensorSet,
        mode: Mode,
        watch: Option<(crate::action::ActionId, FactSetOf<W>)>,
    ) -> u32 {
        let start = Instant::now();
        self.shared().lock(|s| {
            let epoch = s.command.get().epoch.wrapping_add(1);
            s.command.set(Command {
                epoch,
                sensors,
                mode,
                start,
            });
            s.watch.set(watch);
            s.epoch.set(epoch);
            s.ready.set(SensorSet::EMPTY);
            s.set_failure(None);
            s.sensing.wake();
            epoch
        })
    }

    /// How long the sensing side may take to answer for `sensors`: `steps` calls of the
    /// slowest one's timeout, and a tick.
    fn answer_within(&self, sensors: SensorSet, steps: u32) -> Duration {
        let table = self.mission.sensors();
        let slowest = sensors
            .iter()
            .filter_map(|s| table.get(s.index()))
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
        let active = self.shared().lock(|s| s.active.get());
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

    /// The watch of the running action under command `epoch`
    /// ([`Watch`](crate::runtime::shared::Watch)).
    fn watch(&self, epoch: u32, state: State<M>) -> Watch<FactSetOf<W>> {
        Watch {
            epoch,
            action: state.action.id(),
            max: state.max_violation.unwrap_or(self.config.max_violation),
            alarm: None,
            registered: false,
            _facts: PhantomData,
        }
    }

    /// One SMPA sense phase: sensors on, actuators idle, samples until `until`, sensors off.
    async fn sense_phase(
        &self,
        state: State<M>,
        until: Instant,
        first: bool,
    ) -> Result<(), Failure<W>> {
        let sensors = state.sensors;
        let watch = Some((state.action.id(), state.pre));
        let epoch = self.command(sensors, Mode::Phase { first }, watch);
        let result = async {
            self.ready(epoch, sensors).await?;
            self.check_precondition();
            let mut watch = self.watch(epoch, state);
            let watched = poll_fn(|cx| watch.poll(self.shared(), cx));
            match select(watched, Timer::at(until)).await {
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
        state: State<M>,
        io: ActionIo<'_, M>,
        (sense, act): (Duration, Duration),
    ) -> Result<Outcome, Failure<W>> {
        let action = state.action;
        // A phase of no time would alternate forever at one instant.
        let (sense, act) = (
            sense.max(Duration::from_ticks(1)),
            act.max(Duration::from_ticks(1)),
        );
        let mut behaviour = pin!(self.platform.run(Act::new(io)));
        let mut first = true;
        loop {
            self.trace(TraceEvent::PhaseStarted {
                action: action.id(),
                phase: Phase::Sense,
            });
            self.platform.hold(action, true);
            let until = Instant::now().saturating_add(sense);
            let sensed = self.sense_phase(state, until, first).await;
            first = false;
            self.platform.hold(action, false);
            if let Err(failure) = sensed {
                self.platform.halt(action);
                return Err(failure);
            }
            self.trace(TraceEvent::PhaseStarted {
                action: action.id(),
                phase: Phase::Act,
            });
            let act_end = Instant::now().saturating_add(act);
            if let Either::First(outcome) = select(behaviour.as_mut(), Timer::at(act_end)).await {
                return Ok(outcome);
            }
            // The phase ended: a behaviour due at that same instant ends in it. (On a chip the
            // poll that found the phase over may have started a tick earlier, before the
            // behaviour's own deadline.)
            if let Poll::Ready(outcome) =
                poll_fn(|cx| Poll::Ready(behaviour.as_mut().poll(cx))).await
            {
                return Ok(outcome);
            }
        }
    }

    /// What a state needs before it starts: its sensors in service, the facts of `pre(a)`
    /// that none of them decides already believed, each sensor's `pre(s)`; then the
    /// behaviour's I/O.
    fn prepare(&self, state: State<M>) -> Result<ActionIo<'_, M>, Failure<W>> {
        let action = state.action.id();
        let sensors = state.sensors;
        let table = self.mission.sensors();
        let (beliefs, faulty) = self.shared().lock(|s| (s.beliefs.get(), s.faulty.get()));
        // A sensor out of service cannot watch the action: fail before moving anything.
        if let Some(sensor) = sensors.iter().find(|s| faulty.contains(*s)) {
            return Err(Failure::SensorUnavailable { sensor });
        }
        // Facts of pre(a) that no running sensor decides must already hold.
        let missing = state
            .pre
            .difference(perception_of(table, sensors))
            .difference(beliefs);
        if !missing.is_empty() {
            return Err(Failure::PreconditionUnmet { action, missing });
        }
        if let Some(sensor) = sensors.iter().find(|s| {
            table
                .get(s.index())
                .is_none_or(|spec| !spec.pre.is_subset(beliefs))
        }) {
            return Err(Failure::SensorUnavailable { sensor });
        }
        let own = self
            .storage
            .action_stores()
            .get(action.index())
            .ok_or(Failure::ActionFailed { action })?;
        debug!(
            "action {} starts with sensors {:?}",
            action.index(),
            sensors.bits()
        );
        Ok(ActionIo {
            action: state.action,
            store: MutualStore::link(own, self.storage.sensor_table(), sensors),
            monitor: self,
            typed: PhantomData,
        })
    }

    /// `executePlans` for one plan: runs its FSM `f(Λ, T)` (its states from `source`) from its
    /// initial state along the transition rules `T` until [`Target::Done`] or
    /// [`Target::Failed`]. Between two states the work is bounded: the transition is O(1),
    /// switching sensors off and on O(NS), the effects O(1).
    pub(crate) async fn run_plan(&self, source: Source<'_, M>) -> Result<(), Failure<W>> {
        let mut index = 0u8;
        loop {
            let (state, next) = self.state_of(&source, index)?;
            // The state, from its start to its end, in this one future (the P-SMPA path in
            // it, the SMPA one apart): a behaviour's step is polled through as few futures as
            // can be.
            let action = state.action.id();
            let sensors = state.sensors;
            self.trace(TraceEvent::StateEntered {
                state: state.index,
                action,
                sensors,
            });
            let result = match (self.prepare(state), self.config.policy) {
                (Err(failure), _) => Err(failure),
                (Ok(io), _) if sensors.is_empty() => Ok(self.platform.run(Act::new(io)).await),
                // P-SMPA: `δ'_i = δ_i ∥ {s_k}`; the sensors end when the action ends.
                (Ok(io), Policy::PSmpa) => {
                    let epoch = self.command(sensors, Mode::Parallel, Some((action, state.pre)));
                    // Fresh percepts before the behaviour starts, checked against its
                    // precondition.
                    let result = match self.ready(epoch, sensors).await {
                        Err(failure) => Err(failure),
                        Ok(()) => {
                            self.check_precondition();
                            // The watch first, in one future with the behaviour: a failure
                            // reported at this instant stops the behaviour before it takes
                            // another step.
                            let parallel = Parallel {
                                watch: self.watch(epoch, state),
                                runtime: self,
                                behaviour: self.platform.run(Act::new(io)),
                            };
                            match parallel.await {
                                Either::First(failure) => {
                                    self.platform.halt(state.action);
                                    Err(failure)
                                }
                                Either::Second(outcome) => Ok(outcome),
                            }
                        }
                    };
                    let stopped = self.stop().await;
                    result.and_then(|outcome| stopped.map(|()| outcome))
                }
                (Ok(io), Policy::Smpa { sense, act }) => {
                    self.run_alternating(state, io, (sense, act)).await
                }
            };
            let result = self.state_ended(state, result);
            let target = if result.is_ok() { next.0 } else { next.1 };
            match target {
                Target::State(next) => index = next,
                Target::Done => return result,
                // Machines only fail on the failure edge; anything else is a broken FSM.
                Target::Failed => return result.and(Err(Failure::InvalidFsm { state: index })),
            }
        }
    }

    /// State `index` of `source` and its transition rules (success, failure).
    fn state_of(
        &self,
        source: &Source<'_, M>,
        index: u8,
    ) -> Result<(State<M>, (Target, Target)), Failure<W>> {
        match source {
            Source::Compiled(states) => {
                let state = *states
                    .get(usize::from(index))
                    .ok_or(Failure::InvalidFsm { state: index })?;
                let last = usize::from(index).saturating_add(1) >= states.len();
                let next = if last {
                    Target::Done
                } else {
                    Target::State(index.saturating_add(1))
                };
                Ok((state, (next, Target::Failed)))
            }
            Source::Fsm(fsm) => {
                let table = self.mission.actions();
                let state = fsm
                    .state(index, table, self.mission.sensors())
                    .ok_or(Failure::InvalidFsm { state: index })?;
                let unknown = Failure::ActionFailed {
                    action: state.action,
                };
                let spec = table.get(state.action.index()).ok_or(unknown)?;
                let action = M::Action::from_id(state.action).ok_or(unknown)?;
                let next = (state.next(Edge::Success), state.next(Edge::Failure));
                let state = State {
                    index,
                    action,
                    sensors: state.sensors,
                    pre: spec.pre,
                    add: spec.add,
                    del: spec.del,
                    max_violation: spec.max_violation,
                };
                Ok((state, next))
            }
        }
    }

    /// State `state` ended with `result`: the violation and requests cleared, the action's
    /// effects applied on success, the end traced.
    fn state_ended(
        &self,
        state: State<M>,
        result: Result<Outcome, Failure<W>>,
    ) -> Result<(), Failure<W>> {
        let action = state.action.id();
        self.shared().lock(|s| {
            s.set_violation(None);
            s.requests.set(SensorSet::EMPTY);
        });
        let (outcome, result) = match result {
            Ok(outcome) => (Some(outcome), outcome_result(action, outcome)),
            Err(failure) => (None, Err(failure)),
        };
        if result.is_ok() {
            let (add, del) = (state.add, state.del);
            // The effects are known, as a sample's percepts are: a percept fact an action
            // deleted is known false, not unknown.
            let beliefs = self.shared().lock(|s| {
                let beliefs = s.beliefs.get().apply(add, del);
                s.sensed.set(s.sensed.get().union(add).union(del));
                s.beliefs.set(beliefs);
                s.notify();
                beliefs
            });
            self.trace(TraceEvent::EffectsApplied { action, beliefs });
        }
        self.trace(TraceEvent::StateLeft {
            state: state.index,
            action,
            outcome,
        });
        result
    }

    /// Where the library's plan `plan`'s states come from: computed when the mission was
    /// compiled (unless the [`Config::plans`](crate::Config::plans) say otherwise), or the
    /// run-time FSM.
    pub(crate) fn source(&self, plan: PlanId) -> Result<Source<'_, M>, Failure<W>> {
        let compiled = match self.config.plans {
            Plans::Compiled => self.mission.states(plan),
            Plans::RunTime => None,
        };
        if let Some(states) = compiled {
            return Ok(Source::Compiled(states));
        }
        let p = self
            .mission
            .plan(plan)
            .ok_or(Failure::InvalidFsm { state: 0 })?;
        let fsm = Fsm::compile(plan, p.body, self.mission.actions())
            .map_err(|_| Failure::InvalidFsm { state: 0 })?;
        Ok(Source::Fsm(fsm))
    }
}

/// Where a plan's states come from.
pub(crate) enum Source<'a, M: Mission> {
    /// Computed when the mission was compiled ([`Mission::states`]).
    Compiled(&'a [State<M>]),
    /// Computed from the tables as the run-time FSM reaches them.
    Fsm(Fsm<'a>),
}

pin_project! {
    /// A parallel state's one future: the watch, then the behaviour, in one poll.
    struct Parallel<'a, 'r, M: Mission, P: Platform, T, B> {
        watch: Watch<M::Facts>,
        runtime: &'a Runtime<'r, M, P, T>,
        #[pin]
        behaviour: B,
    }
}

impl<M, P, T, B, const W: usize> Future for Parallel<'_, '_, M, P, T, B>
where
    M: Mission<Facts = FactSetOf<W>>,
    P: Platform,
    B: Future<Output = Outcome>,
{
    type Output = Either<Failure<W>, Outcome>;

    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Self::Output> {
        let this = self.project();
        if let Poll::Ready(failure) = this.watch.poll(this.runtime.storage.shared(), cx) {
            return Poll::Ready(Either::First(failure));
        }
        this.behaviour.poll(cx).map(Either::Second)
    }
}

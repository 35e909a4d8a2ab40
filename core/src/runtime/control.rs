//! Algorithm 1, the control loop of the P-SMPA architecture:
//!
//! ```text
//! establishInitialModel: S -D-> M
//! loop
//!     generatePlans: M -> P          BDI selection from the plan library
//!     executePlans:  S x P -D-> A    the plan's FSM (Algorithm 2) under the runtime's policy
//!     updateModel:   A x S -> M      percepts while running, effects when an action succeeds
//! end loop                           ... until the goal holds, or a clear error
//! ```

use crate::action::{ActuatorAction, SensorId, SensorMode, SensorSet};
use crate::action::{perception_of, sensors_serving};
use crate::domain::EventId;
use crate::facts::FactSetOf;
use crate::failure::Failure;
use crate::fmt::{info, warning};
use crate::plan::{FailureMemory, PlanId, PlanSet};
use crate::planner::{Planner, PlanningError, Search};
use crate::platform::{Actuator, Platform, Sensor};
use crate::runtime::Runtime;
use crate::runtime::fsm::{Fsm, FsmError};
use crate::runtime::state::Source;
use crate::spec::storage::Mode;
use crate::spec::{Body, Mission};
use crate::trace::{TraceEvent, TraceSink};
use core::convert::Infallible;

use embassy_futures::select::{Either, select};
use embassy_futures::yield_now;

/// How a mission that reached its goal went (fact sets of `W` words).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Report<const W: usize = 1> {
    /// Plans selected and started.
    pub plans_started: u16,
    /// Plans that failed.
    pub plans_failed: u16,
    /// The beliefs at the end.
    pub beliefs: FactSetOf<W>,
}

/// `run` with `sensing` beside it, sensing polled first; ends when `run` does.
pub(crate) async fn beside_sensing<R>(
    sensing: impl Future<Output = Infallible>,
    run: impl Future<Output = R>,
) -> R {
    match select(sensing, run).await {
        Either::First(never) => match never {},
        Either::Second(result) => result,
    }
}

/// Why the control loop stopped before the goal held (fact sets of `W` words).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum ControlError<const W: usize = 1> {
    /// No plan of the library is applicable to the task's event under the beliefs.
    NoApplicablePlan {
        /// The event.
        event: EventId,
        /// The beliefs.
        beliefs: FactSetOf<W>,
    },
    /// Every plan applicable to the event (and not already failed under these beliefs) was
    /// passed over, and none was started: its first
    /// action needs a fact a percept has already shown false and has no tolerance of its own
    /// to wait with ([`ActuatorAction::may_start_violated`]), or its `context_not` needs a
    /// fact false that no sample has shown yet, or one of its actions needs a sensor out of
    /// service ([`Runtime::faulty_sensors`]).
    Inapplicable {
        /// The event.
        event: EventId,
        /// The plans passed over.
        skipped: PlanSet,
        /// The facts percepts showed false that a passed-over plan's first action needs.
        known_false: FactSetOf<W>,
        /// The facts a passed-over plan's `context_not` needs false that no sample has shown.
        unknown: FactSetOf<W>,
        /// The sensors out of service that a passed-over plan's actions need.
        faulty: SensorSet,
    },
    /// Every applicable plan already failed under the current beliefs.
    Exhausted {
        /// The event.
        event: EventId,
        /// The plans that failed.
        failed: PlanSet,
        /// The beliefs.
        beliefs: FactSetOf<W>,
        /// The sensors out of service ([`Runtime::faulty_sensors`]): a plan that failed on a
        /// sensor fault says so here.
        faulty: SensorSet,
    },
    /// More plans failed than [`Config::max_failures`](crate::Config::max_failures).
    TooManyFailures {
        /// Plans that failed.
        failures: u16,
        /// The last failure.
        last: Failure<W>,
    },
    /// More plans ran than [`Config::max_plans`](crate::Config::max_plans) without reaching
    /// the goal.
    PlanLimit {
        /// Plans started.
        plans: u16,
    },
    /// A plan of the library does not compile.
    Compile {
        /// The plan.
        plan: PlanId,
        /// Why.
        error: FsmError,
    },
    /// No library plan applied and the planner found none.
    Planning {
        /// Why.
        error: PlanningError,
        /// The sensors out of service: the planner leaves out every action they would
        /// monitor.
        faulty: SensorSet,
    },
    /// The initial model could not be established (a sensor fault, a full store).
    InitialModel {
        /// What went wrong.
        failure: Failure<W>,
    },
}

impl<'r, M, P, T, const W: usize> Runtime<'r, M, P, T>
where
    M: Mission<Facts = FactSetOf<W>>,
    P: Platform + Sensor<M> + Actuator<M>,
    T: TraceSink<M>,
{
    /// Algorithm 1 line 2: the beliefs start at `τ0`; every cyclic or one-shot sensor in service
    /// whose `pre(s)` holds is switched on, sampled once and switched off again, all at once.
    pub(crate) async fn establish_initial_model(&self) -> Result<FactSetOf<W>, ControlError<W>> {
        let init = self.mission.task().init;
        // A new model: what earlier runs sensed is not known now.
        let faulty = self.shared().lock(|s| {
            s.sensed.set(FactSetOf::EMPTY);
            s.beliefs.set(init);
            s.notify();
            s.faulty.get()
        });
        let eligible: SensorSet = self
            .mission
            .sensors()
            .iter()
            .enumerate()
            .filter(|(_, s)| s.mode != SensorMode::OnDemand && s.pre.is_subset(init))
            .filter_map(|(i, _)| SensorId::new(i))
            .filter(|s| !faulty.contains(*s))
            .collect();
        let epoch = self.command(eligible, Mode::Once, None);
        let sampled = self.ready(epoch, eligible).await;
        let stopped = self.stop().await;
        sampled
            .and(stopped)
            .map_err(|failure| ControlError::InitialModel { failure })?;
        let beliefs = self.beliefs();
        self.trace(TraceEvent::ModelEstablished { beliefs });
        Ok(beliefs)
    }

    /// Algorithm 1 with plans from the library only ([`DecidingSide::run`](crate::runtime::sides::DecidingSide::run)).
    pub(crate) async fn run(&self) -> Result<Report<W>, ControlError<W>> {
        self.control(NoPlanner).await
    }

    /// Algorithm 1 with the planner as fallback ([`DecidingSide::run_planning`](crate::runtime::sides::DecidingSide::run_planning)).
    pub(crate) async fn run_planning<const N: usize>(
        &self,
        planner: &Planner<N, W>,
        space: &mut Search<N, W>,
    ) -> Result<Report<W>, ControlError<W>> {
        self.control((planner, space)).await
    }

    /// The actions with the preconditions the planner must satisfy from the beliefs: facts
    /// that a sensor running beside the action perceives are checked by that sensor when the
    /// action runs, so they are assumed to hold unless a sample already showed them false (and
    /// even then for an action that [may start violated](ActuatorAction::may_start_violated)).
    /// An action beside a sensor that failed cannot be monitored: it never applies.
    fn planning_actions(&self) -> M::Actions<'_> {
        let sensors = self.mission.sensors();
        let known_false = self.known_false();
        let faulty = self.faulty_sensors();
        self.mission
            .actions()
            .iter()
            .map(|a| {
                let serving = sensors_serving(sensors, a.pre);
                let checked = perception_of(sensors, serving);
                let pre = if serving.intersects(faulty) {
                    FactSetOf::ALL
                } else if a.may_start_violated() {
                    a.pre.difference(checked)
                } else {
                    a.pre.difference(checked.difference(known_false))
                };
                ActuatorAction { pre, ..*a }
            })
            .collect()
    }

    /// `generatePlans: M -> P` from the library: the first applicable plan that could run,
    /// else why none applies. A plan is passed over when
    /// * its first action needs a fact a percept has shown false: started, it would only wait
    ///   for that fact. Unless that action has a tolerance of its own
    ///   ([`ActuatorAction::may_start_violated`]): it was written to ride such a violation out;
    /// * its `context_not` needs a fact false that a sensor perceives but no sample has shown
    ///   (never sensed is unknown, not false: "express only when not loaded" does not run on
    ///   a load cell that never answered);
    /// * one of its actions needs a sensor out of service: it could not be monitored (the
    ///   planner's view of the actions leaves those out too).
    ///
    /// O(NP · L · NS).
    // Out of line: inlined into the deciding task's poll it made the firmware larger.
    #[inline(never)]
    fn select(
        &self,
        memory: &FailureMemory<W>,
        beliefs: FactSetOf<W>,
    ) -> Result<PlanId, ControlError<W>> {
        let task = self.mission.task();
        let sensors = self.mission.sensors();
        let actions = self.mission.actions();
        let excluded = memory.excluded(task.event, beliefs);
        let (known_false, unknown, out_of_service) = self.knowledge();
        let mut skipped = PlanSet::EMPTY;
        let mut why = (FactSetOf::EMPTY, FactSetOf::EMPTY, SensorSet::EMPTY);
        // Plans in the library's order: the first applicable one not passed over.
        let candidates = (0..self.mission.plan_count())
            .filter_map(PlanId::new)
            .filter(|id| !excluded.contains(*id));
        for id in candidates {
            let Some(plan) = self.mission.plan(id) else {
                break;
            };
            if !plan.applicable(task.event, beliefs) {
                continue;
            }
            let first_false = plan
                .body
                .first()
                .and_then(|a| actions.get(a.index()))
                .filter(|a| !a.may_start_violated())
                .map_or(FactSetOf::EMPTY, |a| a.pre.intersection(known_false));
            let unsure = plan.context_not.intersection(unknown);
            let faulty = if out_of_service.is_empty() {
                SensorSet::EMPTY
            } else {
                plan.body
                    .iter()
                    .filter_map(|a| actions.get(a.index()))
                    .fold(SensorSet::EMPTY, |acc, a| {
                        acc.union(sensors_serving(sensors, a.pre))
                    })
                    .intersection(out_of_service)
            };
            if first_false.is_empty() && unsure.is_empty() && faulty.is_empty() {
                return Ok(id);
            }
            skipped = skipped.with(id);
            why = (
                why.0.union(first_false),
                why.1.union(unsure),
                why.2.union(faulty),
            );
        }
        Err(if !skipped.is_empty() {
            ControlError::Inapplicable {
                event: task.event,
                skipped,
                known_false: why.0,
                unknown: why.1,
                faulty: why.2,
            }
        } else if excluded.is_empty() {
            ControlError::NoApplicablePlan {
                event: task.event,
                beliefs,
            }
        } else {
            ControlError::Exhausted {
                event: task.event,
                failed: excluded,
                beliefs,
                faulty: out_of_service,
            }
        })
    }

    /// `generatePlans: M -> P` by the planner, from `beliefs` to the task's goal, one slice of
    /// the search per poll.
    async fn generate<G: Fallback<W>>(
        &self,
        planner: &mut G,
        beliefs: FactSetOf<W>,
    ) -> Result<M::Body, ControlError<W>> {
        let goal = self.mission.task().goal;
        let actions = self.planning_actions();
        let actions = actions.as_ref();
        planner.start(actions, beliefs, goal);
        let slice = u32::from(self.config.plan_slice.max(1));
        let (body, expanded) = loop {
            if let Some(result) = planner.step::<M::Body>(actions, slice) {
                break result.map_err(|error| ControlError::Planning {
                    error,
                    faulty: self.faulty_sensors(),
                })?;
            }
            // Let sensing, and everything else ready, run between two slices.
            yield_now().await;
        };
        let length = body.as_ref().len();
        self.trace(TraceEvent::PlanGenerated {
            length: u8::try_from(length).unwrap_or(u8::MAX),
            expanded,
        });
        info!("generated a plan of {} actions", length);
        Ok(body)
    }

    /// `planner` is a type, not an `Option`: a run without one then links no search (an
    /// option lives in the future's state, where the compiler cannot see that it stays `None`).
    async fn control<G: Fallback<W>>(&self, mut planner: G) -> Result<Report<W>, ControlError<W>> {
        let task = self.mission.task();
        self.establish_initial_model().await?;
        let mut memory = FailureMemory::new();
        let mut generated_failed: Option<FactSetOf<W>> = None;
        let mut report = Report::default();
        loop {
            let beliefs = self.beliefs();
            report.beliefs = beliefs;
            if task.goal.is_subset(beliefs) {
                self.trace(TraceEvent::GoalReached { beliefs });
                info!("goal reached after {} plans", report.plans_started);
                return Ok(report);
            }
            if report.plans_started >= self.config.max_plans {
                return Err(ControlError::PlanLimit {
                    plans: report.plans_started,
                });
            }
            let (plan, generated) = match self.select(&memory, beliefs) {
                Ok(plan) => (plan, None),
                // The same search from the same beliefs would give the plan that just failed.
                Err(no_plan) if G::PLANS && generated_failed != Some(beliefs) => {
                    match self.generate(&mut planner, beliefs).await {
                        Ok(body) => (PlanId::GENERATED, Some(body)),
                        // The planner proved there is no plan either: plans passed over, and
                        // why, say more than "unsolvable" does. (A search out of budget says
                        // so itself: a larger budget may find one.)
                        Err(ControlError::Planning {
                            error: PlanningError::Unsolvable { .. },
                            ..
                        }) if matches!(no_plan, ControlError::Inapplicable { .. }) => {
                            return Err(no_plan);
                        }
                        Err(error) => return Err(error),
                    }
                }
                Err(no_plan) => return Err(no_plan),
            };
            self.trace(TraceEvent::PlanSelected {
                plan,
                event: task.event,
            });
            report.plans_started = report.plans_started.saturating_add(1);
            // executePlans and updateModel (percepts and effects are applied as they happen).
            let source = match &generated {
                // Algorithm 2 at run time for the plan the planner made.
                Some(body) => match Fsm::compile(plan, body.as_ref(), self.mission.actions()) {
                    Ok(fsm) => Ok(Source::Fsm(fsm)),
                    Err(error) => return Err(ControlError::Compile { plan, error }),
                },
                None => self.source(plan),
            };
            let executed = match source {
                Ok(source) => self.run_plan(source).await,
                Err(failure) => Err(failure),
            };
            match executed {
                Ok(()) => self.trace(TraceEvent::PlanSucceeded { plan }),
                Err(reason) => {
                    self.trace(TraceEvent::PlanFailed { plan, reason });
                    warning!("plan {} failed: {:?}", plan.index(), reason);
                    report.plans_failed = report.plans_failed.saturating_add(1);
                    if plan == PlanId::GENERATED {
                        generated_failed = Some(self.beliefs());
                    } else {
                        memory.record(plan, task.event, self.beliefs());
                    }
                    if report.plans_failed > self.config.max_failures {
                        return Err(ControlError::TooManyFailures {
                            failures: report.plans_failed,
                            last: reason,
                        });
                    }
                }
            }
        }
    }
}

/// What `generatePlans` falls back on when no library plan applies: a planner and its search
/// space, or [`NoPlanner`]. A type, not an `Option`: a run without a planner then links no
/// search (an option lives in the future's state, where the compiler cannot see that it stays
/// `None`).
pub(crate) trait Fallback<const W: usize> {
    /// Whether there is a planner.
    const PLANS: bool;
    /// Sets a search up from `init` to `goal`.
    fn start(&mut self, actions: &[ActuatorAction<'_, W>], init: FactSetOf<W>, goal: FactSetOf<W>);
    /// Runs `slice` nodes of it: the plan and the nodes expanded once it ended.
    fn step<B: Body>(
        &mut self,
        actions: &[ActuatorAction<'_, W>],
        slice: u32,
    ) -> Option<Result<(B, u32), PlanningError>>;
}

/// The library's plans only.
pub(crate) struct NoPlanner;

impl<const W: usize> Fallback<W> for NoPlanner {
    const PLANS: bool = false;
    fn start(&mut self, _: &[ActuatorAction<'_, W>], _: FactSetOf<W>, _: FactSetOf<W>) {}
    fn step<B: Body>(
        &mut self,
        _: &[ActuatorAction<'_, W>],
        _: u32,
    ) -> Option<Result<(B, u32), PlanningError>> {
        Some(Err(PlanningError::Unsolvable { expanded: 0 }))
    }
}

impl<const N: usize, const W: usize> Fallback<W> for (&Planner<N, W>, &mut Search<N, W>) {
    const PLANS: bool = true;
    // Out of line, both: a search's start and its slices are timed on the chip
    // (`cargo xtask hil`'s `decision_cycles`).
    #[inline(never)]
    fn start(&mut self, actions: &[ActuatorAction<'_, W>], init: FactSetOf<W>, goal: FactSetOf<W>) {
        self.1.start(self.0, actions, init, goal);
    }
    #[inline(never)]
    fn step<B: Body>(
        &mut self,
        actions: &[ActuatorAction<'_, W>],
        slice: u32,
    ) -> Option<Result<(B, u32), PlanningError>> {
        B::step(self.1, actions, slice)
    }
}

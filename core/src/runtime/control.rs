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

use heapless::Vec;

use crate::action::{ActionId, ActuatorAction, SensorId, SensorMode, SensorSet};
use crate::domain::EventId;
use crate::facts::FactSetOf;
use crate::failure::Failure;
use crate::fmt::{info, warning};
use crate::plan::{FailureMemory, Plan, PlanId, PlanSet};
use crate::planner::{Found, Planner, PlanningError, Search};
use crate::platform::{Actuator, FromId, Platform, Sensor};
use crate::runtime::engine::Engine;
use crate::runtime::fsm::{Fsm, FsmError};
use crate::runtime::shared::Mode;
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
    /// service ([`Engine::faulty_sensors`]).
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
        /// The sensors out of service ([`Engine::faulty_sensors`]): a plan that failed on a
        /// sensor fault says so here.
        faulty: SensorSet,
    },
    /// More plans failed than [`Config::max_failures`](crate::runtime::engine::Config::max_failures).
    TooManyFailures {
        /// Plans that failed.
        failures: u16,
        /// The last failure.
        last: Failure<W>,
    },
    /// More plans ran than [`Config::max_plans`](crate::runtime::engine::Config::max_plans) without reaching
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
    /// The platform names no sensor or no action of an id of the mission: its
    /// [`Sensor::Id`] or [`Actuator::Id`] is another mission's (checked before anything runs).
    Unbound {
        /// The first sensor the platform has no name for.
        sensor: Option<SensorId>,
        /// The first action the platform has no name for.
        action: Option<ActionId>,
    },
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
    /// Every sensor and action of the mission has a name on the platform ([`Sensor::Id`],
    /// [`Actuator::Id`]): a platform written for another mission is an error before anything
    /// runs, not a sensor fault or a failed action halfway through.
    fn bound(&self) -> Result<(), ControlError<W>> {
        let domain = &self.mission.domain;
        let sensor = (0..domain.sensors().len())
            .filter_map(SensorId::new)
            .find(|s| <P as Sensor<W>>::Id::from_id(*s).is_none());
        let action = (0..domain.actions().len())
            .filter_map(ActionId::new)
            .find(|a| <P as Actuator<W>>::Id::from_id(*a).is_none());
        match (sensor, action) {
            (None, None) => Ok(()),
            (sensor, action) => Err(ControlError::Unbound { sensor, action }),
        }
    }

    /// Algorithm 1 line 2: the beliefs start at `τ0`; every cyclic or one-shot sensor in service
    /// whose `pre(s)` holds is switched on, sampled once and switched off again, all at once.
    pub(crate) async fn establish_initial_model(&self) -> Result<FactSetOf<W>, ControlError<W>> {
        let init = self.mission.task.init;
        // A new model: what earlier runs sensed is not known now.
        self.shared.lock(|s| s.sensed.set(FactSetOf::EMPTY));
        self.set_beliefs(init);
        let faulty = self.faulty_sensors();
        let eligible: SensorSet = self
            .mission
            .domain
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
    fn planning_actions(&self) -> Vec<ActuatorAction<'r, W>, NA> {
        let domain = &self.mission.domain;
        let known_false = self.known_false();
        let faulty = self.faulty_sensors();
        domain
            .actions()
            .iter()
            .map(|a| {
                let serving = domain.sensors_serving(a.pre);
                let checked = domain.perception_of(serving);
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
    ) -> Result<(PlanId, Vec<ActionId, L>), ControlError<W>> {
        let task = self.mission.task;
        let library = &self.mission.library;
        let domain = &self.mission.domain;
        let excluded = memory.excluded(task.event, beliefs);
        let (known_false, unknown, out_of_service) = self.knowledge();
        let mut skipped = PlanSet::EMPTY;
        let mut why = (FactSetOf::EMPTY, FactSetOf::EMPTY, SensorSet::EMPTY);
        while let Some(id) = library.select(task.event, beliefs, excluded.union(skipped)) {
            let Some(plan) = library.get(id) else {
                break; // An id the library gave: never the case.
            };
            let first_false = plan
                .body
                .first()
                .and_then(|a| domain.action(*a))
                .filter(|a| !a.may_start_violated())
                .map_or(FactSetOf::EMPTY, |a| a.pre.intersection(known_false));
            let unsure = plan.context_not.intersection(unknown);
            let faulty = if out_of_service.is_empty() {
                SensorSet::EMPTY
            } else {
                plan.body
                    .iter()
                    .filter_map(|a| domain.action(*a))
                    .fold(SensorSet::EMPTY, |acc, a| {
                        acc.union(domain.sensors_serving(a.pre))
                    })
                    .intersection(out_of_service)
            };
            if first_false.is_empty() && unsure.is_empty() && faulty.is_empty() {
                // Copied once, for the plan that runs.
                return Ok((id, plan.body.clone()));
            }
            if skipped.contains(id) {
                break; // An id without a bit: never the case in a library.
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
    ) -> Result<Vec<ActionId, L>, ControlError<W>> {
        let goal = self.mission.task.goal;
        let actions = self.planning_actions();
        planner.start(&actions, beliefs, goal);
        let slice = u32::from(self.config.plan_slice.max(1));
        let found: Found<L> = loop {
            if let Some(result) = planner.step(&actions, slice) {
                break result.map_err(|error| ControlError::Planning {
                    error,
                    faulty: self.faulty_sensors(),
                })?;
            }
            // Let sensing, and everything else ready, run between two slices.
            yield_now().await;
        };
        self.trace(TraceEvent::PlanGenerated {
            length: u8::try_from(found.body.len()).unwrap_or(u8::MAX),
            expanded: found.expanded,
        });
        info!("generated a plan of {} actions", found.body.len());
        Ok(found.body)
    }

    /// `planner` is a type, not an `Option`: a run without one then links no search (an
    /// option lives in the future's state, where the compiler cannot see that it stays `None`).
    async fn control<G: Fallback<W>>(&self, mut planner: G) -> Result<Report<W>, ControlError<W>> {
        let task = self.mission.task;
        self.bound()?;
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
            let (plan, body) = match self.select(&memory, beliefs) {
                Ok(selected) => selected,
                // The same search from the same beliefs would give the plan that just failed.
                Err(no_plan) if G::PLANS && generated_failed != Some(beliefs) => {
                    match self.generate(&mut planner, beliefs).await {
                        Ok(body) => (PlanId::GENERATED, body),
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
            let named = Plan {
                name: self
                    .mission
                    .library
                    .get(plan)
                    .map_or("generated", |p| p.name),
                trigger: task.event,
                context: FactSetOf::EMPTY,
                context_not: FactSetOf::EMPTY,
                body,
            };
            let fsm: Fsm<L> = Fsm::compile(plan, &named, &self.mission.domain)
                .map_err(|error| ControlError::Compile { plan, error })?;
            self.trace(TraceEvent::PlanSelected {
                plan,
                event: task.event,
            });
            report.plans_started = report.plans_started.saturating_add(1);
            // executePlans and updateModel (percepts and effects are applied as they happen).
            match self.execute(&fsm).await {
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
    /// Runs `slice` nodes of it: the result once it ended.
    fn step<const L: usize>(
        &mut self,
        actions: &[ActuatorAction<'_, W>],
        slice: u32,
    ) -> Option<Result<Found<L>, PlanningError>>;
}

/// The library's plans only.
pub(crate) struct NoPlanner;

impl<const W: usize> Fallback<W> for NoPlanner {
    const PLANS: bool = false;
    fn start(&mut self, _: &[ActuatorAction<'_, W>], _: FactSetOf<W>, _: FactSetOf<W>) {}
    fn step<const L: usize>(
        &mut self,
        _: &[ActuatorAction<'_, W>],
        _: u32,
    ) -> Option<Result<Found<L>, PlanningError>> {
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
    fn step<const L: usize>(
        &mut self,
        actions: &[ActuatorAction<'_, W>],
        slice: u32,
    ) -> Option<Result<Found<L>, PlanningError>> {
        self.1.step(actions, slice)
    }
}

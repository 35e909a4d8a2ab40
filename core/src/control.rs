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

use embassy_sync::blocking_mutex::raw::RawMutex;

use crate::action::{SensorId, SensorMode, SensorSet};
use crate::domain::EventId;
use crate::exec::{Failure, Runtime};
use crate::facts::FactSet;
use crate::fmt::{info, warning};
use crate::fsm::{Fsm, FsmError};
use crate::plan::{FailureMemory, PlanId, PlanSet};
use crate::platform::{Actuator, Sensor};
use crate::trace::{TraceEvent, TraceSink};

/// How a mission that reached its goal went.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Report {
    /// Plans selected and started.
    pub plans_started: u16,
    /// Plans that failed.
    pub plans_failed: u16,
    /// The beliefs at the end.
    pub beliefs: FactSet,
}

/// Why the control loop stopped before the goal held.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum ControlError {
    /// No plan of the library is applicable to the task's event under the beliefs.
    NoApplicablePlan {
        /// The event.
        event: EventId,
        /// The beliefs.
        beliefs: FactSet,
    },
    /// Every applicable plan already failed under the current beliefs.
    Exhausted {
        /// The event.
        event: EventId,
        /// The plans that failed.
        failed: PlanSet,
        /// The beliefs.
        beliefs: FactSet,
    },
    /// More plans failed than [`Config::max_failures`](crate::exec::Config::max_failures).
    TooManyFailures {
        /// Plans that failed.
        failures: u16,
        /// The last failure.
        last: Failure,
    },
    /// More plans ran than [`Config::max_plans`](crate::exec::Config::max_plans) without reaching
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
    /// The initial model could not be established (a sensor fault, a full store).
    InitialModel {
        /// What went wrong.
        failure: Failure,
    },
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
> Runtime<'_, '_, M, S, A, T, NS, NA, NP, L, K>
{
    /// Algorithm 1 line 2: the beliefs start at `τ0`; every cyclic or one-shot sensor whose
    /// `pre(s)` holds is switched on, sampled once and switched off again.
    pub async fn establish_initial_model(&self) -> Result<FactSet, ControlError> {
        let init = self.mission.task.init;
        self.set_beliefs(init);
        let eligible: SensorSet = self
            .mission
            .domain
            .sensors()
            .iter()
            .enumerate()
            .filter(|(_, s)| s.mode != SensorMode::OnDemand && s.pre.is_subset(init))
            .filter_map(|(i, _)| SensorId::new(i))
            .collect();
        // Fused as if they ran together, although each is on only for its one sample.
        self.set_running(eligible);
        for sensor in eligible.iter() {
            let one = SensorSet::EMPTY.with(sensor);
            let to_error = |failure| ControlError::InitialModel { failure };
            self.switch_on(one).await.map_err(to_error)?;
            let sampled = self.sample(sensor).await;
            self.switch_off(one).await;
            sampled.map_err(to_error)?;
        }
        self.set_running(SensorSet::EMPTY);
        let beliefs = self.beliefs();
        self.trace(TraceEvent::ModelEstablished { beliefs });
        Ok(beliefs)
    }

    /// Algorithm 1: establishes the model, then selects and executes plans until the task's
    /// goal holds. Ends with an error, never a hang, when no plan applies, every applicable
    /// plan failed, or the failure or plan limit of the [`Config`](crate::exec::Config) is
    /// reached.
    pub async fn run(&self) -> Result<Report, ControlError> {
        let task = self.mission.task;
        let library = &self.mission.library;
        self.establish_initial_model().await?;
        let mut memory = FailureMemory::new();
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
            // generatePlans: M -> P
            let excluded = memory.excluded(task.event, beliefs);
            let Some(plan) = library.select(task.event, beliefs, excluded) else {
                return Err(if excluded.is_empty() {
                    ControlError::NoApplicablePlan {
                        event: task.event,
                        beliefs,
                    }
                } else {
                    ControlError::Exhausted {
                        event: task.event,
                        failed: excluded,
                        beliefs,
                    }
                });
            };
            let body = library.get(plan).ok_or(ControlError::Compile {
                plan,
                error: FsmError::EmptyBody,
            })?;
            let fsm: Fsm<L> = Fsm::compile(plan, body, &self.mission.domain)
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
                    memory.record(plan, task.event, self.beliefs());
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

//! Algorithm 2, the parallel behaviour scheduling algorithm: a plan is compiled into a finite
//! state machine `f(Λ, T)`.
//!
//! * `Λ`: one behaviour state `δ_i` per action `a_i` of the body. When sensors `s_k` with
//!   `per(s_k) ⊆ pre(a_i)` exist, the state is the parallel state `δ'_i = δ_i ∥ {s_k}`: those
//!   sensors run beside the action and stop when it ends (the stop condition `e_δ`). No other
//!   sensor runs (least commitment).
//! * `T`: the transition rules. `a_i ≺ a_(i+1)`: success of `δ_i` leads to `δ_(i+1)`, success of
//!   the last state to [`Target::Done`]; the failure edge of every state (the action failed, or
//!   a percept made its precondition false and it stayed false) leads to [`Target::Failed`].

use heapless::Vec;

use crate::action::{ActionId, SensorSet};
use crate::domain::Domain;
use crate::plan::{Plan, PlanId};

/// Where a transition leads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Target {
    /// The behaviour state with this index.
    State(u8),
    /// The plan succeeded.
    Done,
    /// The plan failed.
    Failed,
}

/// Which way a behaviour state ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Edge {
    /// The action succeeded; its effects were applied.
    Success,
    /// The action failed or was interrupted.
    Failure,
}

/// A behaviour state `δ_i`, or the parallel state `δ'_i` when `sensors` is not empty.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BehaviourState {
    /// The actuator-based action `a_i` the state runs.
    pub action: ActionId,
    /// The sensors `{s_k | per(s_k) ⊆ pre(a_i)}` that run in parallel with it.
    pub sensors: SensorSet,
    /// Transition rule taken when the action succeeds.
    pub on_success: Target,
    /// Transition rule taken when the action fails.
    pub on_failure: Target,
}

impl BehaviourState {
    /// Whether this is a parallel state `δ'_i`.
    pub const fn is_parallel(&self) -> bool {
        !self.sensors.is_empty()
    }

    /// The transition rule for `edge`. O(1): a field read, the whole of an FSM transition.
    pub const fn next(&self, edge: Edge) -> Target {
        match edge {
            Edge::Success => self.on_success,
            Edge::Failure => self.on_failure,
        }
    }
}

/// Why a plan could not be compiled.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum FsmError {
    /// The plan body names an action the domain does not have.
    UnknownAction(ActionId),
    /// The plan body is empty.
    EmptyBody,
    /// The body has more actions than a state index can address (255).
    TooManyStates,
}

impl core::fmt::Display for FsmError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::UnknownAction(a) => write!(
                f,
                "its body names action #{}, which the domain does not have",
                a.index()
            ),
            Self::EmptyBody => f.write_str("its body is empty"),
            Self::TooManyStates => f.write_str("its body has more than 255 actions"),
        }
    }
}

impl core::error::Error for FsmError {}

/// A finite state machine `f(Λ, T)` compiled from a plan of at most `L` actions.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Fsm<const L: usize> {
    plan: PlanId,
    states: Vec<BehaviourState, L>,
}

impl<const L: usize> Fsm<L> {
    /// Algorithm 2 for one plan. O(L · NS).
    // Out of line: one decision, timed on the chip (`cargo xtask hil`'s `decision_cycles`).
    #[inline(never)]
    pub fn compile<const NS: usize, const NA: usize, const W: usize, const NF: usize>(
        id: PlanId,
        plan: &Plan<'_, L, W>,
        domain: &Domain<'_, NS, NA, W, NF>,
    ) -> Result<Self, FsmError> {
        let last = plan.body.len().checked_sub(1).ok_or(FsmError::EmptyBody)?;
        let mut states = Vec::new();
        for (i, &action) in plan.body.iter().enumerate() {
            let a = domain
                .action(action)
                .ok_or(FsmError::UnknownAction(action))?;
            // Lines 4-10: the state and its ordering rule; lines 11-15: the parallel sensors.
            let on_success = if i == last {
                Target::Done
            } else {
                let next =
                    u8::try_from(i.saturating_add(1)).map_err(|_| FsmError::TooManyStates)?;
                Target::State(next)
            };
            let state = BehaviourState {
                action,
                sensors: domain.sensors_serving(a.pre),
                on_success,
                on_failure: Target::Failed,
            };
            states.push(state).map_err(|_| FsmError::TooManyStates)?;
        }
        Ok(Self { plan: id, states })
    }

    /// The plan this machine was compiled from.
    pub const fn plan(&self) -> PlanId {
        self.plan
    }

    /// The states `Λ`, in order; the first is the initial state.
    pub fn states(&self) -> &[BehaviourState] {
        &self.states
    }

    /// The state with index `index`.
    pub fn state(&self, index: u8) -> Option<&BehaviourState> {
        self.states.get(usize::from(index))
    }

    /// The sensors that run in any state of the machine.
    pub fn all_sensors(&self) -> SensorSet {
        SensorSet::from_bits(self.states.iter().fold(0, |acc, s| acc | s.sensors.bits()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::action::{ActuatorAction, SensorAction, SensorMode};
    use crate::facts::FactSet;
    use embassy_time::Duration;

    #[test]
    fn parallel_states_get_exactly_the_sensors_their_precondition_needs() {
        let mut d: Domain<'_, 4, 4> = Domain::new();
        let clear = d.add_fact("path_clear").unwrap();
        let handle = d.add_fact("handle_seen").unwrap();
        let at_door = d.add_fact("at_door").unwrap();
        let lit = d.add_fact("lit").unwrap();
        let cyclic = SensorMode::Cyclic {
            period: Duration::from_millis(100),
        };
        let sonar = d
            .add_sensor(SensorAction::new("sonar", FactSet::single(clear), cyclic))
            .unwrap();
        let camera = d
            .add_sensor(SensorAction::new(
                "camera",
                FactSet::single(handle),
                SensorMode::OneShot,
            ))
            .unwrap();
        // per(s) = {path_clear, lit}: not a subset of pre(go) = {path_clear}.
        d.add_sensor(SensorAction::new(
            "wide",
            FactSet::single(clear).with(lit),
            cyclic,
        ))
        .unwrap();
        // Perceives nothing: never runs beside anything.
        d.add_sensor(SensorAction::new("mute", FactSet::EMPTY, cyclic))
            .unwrap();
        let go = d
            .add_action(ActuatorAction::new(
                "go",
                FactSet::single(clear),
                FactSet::single(at_door),
                FactSet::EMPTY,
            ))
            .unwrap();
        let open = d
            .add_action(ActuatorAction::new(
                "open",
                FactSet::single(at_door).with(handle),
                FactSet::EMPTY,
                FactSet::EMPTY,
            ))
            .unwrap();
        let rest = d
            .add_action(ActuatorAction::new(
                "rest",
                FactSet::single(at_door),
                FactSet::EMPTY,
                FactSet::EMPTY,
            ))
            .unwrap();
        let ev = d.add_event("e").unwrap();
        let plan: Plan<'_, 3> = Plan::new("p", ev, FactSet::EMPTY, &[go, open, rest]).unwrap();
        let fsm = Fsm::compile(PlanId::new(0).unwrap(), &plan, &d).unwrap();

        let states = fsm.states();
        assert_eq!(states.len(), 3);
        assert_eq!(states[0].sensors, SensorSet::EMPTY.with(sonar));
        assert_eq!(states[1].sensors, SensorSet::EMPTY.with(camera));
        assert!(!states[2].is_parallel());
        assert_eq!(states[0].next(Edge::Success), Target::State(1));
        assert_eq!(states[1].next(Edge::Success), Target::State(2));
        assert_eq!(states[2].next(Edge::Success), Target::Done);
        assert!(
            states
                .iter()
                .all(|s| s.next(Edge::Failure) == Target::Failed)
        );
        assert_eq!(fsm.all_sensors(), SensorSet::EMPTY.with(sonar).with(camera));
    }

    #[test]
    fn unknown_action_is_an_error() {
        let d: Domain<'_, 1, 1> = Domain::new();
        let mut d2 = d.clone();
        let ev = d2.add_event("e").unwrap();
        let plan: Plan<'_, 1> =
            Plan::new("p", ev, FactSet::EMPTY, &[ActionId::new(3).unwrap()]).unwrap();
        assert_eq!(
            Fsm::compile(PlanId::new(0).unwrap(), &plan, &d),
            Err(FsmError::UnknownAction(ActionId::new(3).unwrap()))
        );
    }
}

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

use crate::action::{ActionId, ActuatorAction, SensorAction, SensorSet};
use crate::plan::PlanId;

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

/// A finite state machine `f(Λ, T)` compiled from a plan at run time: a plan the planner made,
/// or a library plan of a mission loaded at run time (a compiled mission's plans are
/// build-time state tables, [`Mission::states`](crate::Mission::states)). It borrows the plan's
/// body and computes a state `δ_i` from the domain's tables when asked, so it needs no room of
/// its own.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fsm<'p> {
    plan: PlanId,
    body: &'p [ActionId],
}

impl<'p> Fsm<'p> {
    /// Algorithm 2 for one plan of body `body`, with the domain's actions `actions`: checks
    /// that every action exists and the states can be addressed. O(L).
    // Out of line: one decision, timed on the chip (`cargo xtask hil`'s `decision_cycles`).
    #[inline(never)]
    pub fn compile<const W: usize>(
        id: PlanId,
        body: &'p [ActionId],
        actions: &[ActuatorAction<'_, W>],
    ) -> Result<Self, FsmError> {
        if body.is_empty() {
            return Err(FsmError::EmptyBody);
        }
        if body.len() > usize::from(u8::MAX) {
            return Err(FsmError::TooManyStates);
        }
        if let Some(unknown) = body.iter().find(|a| actions.get(a.index()).is_none()) {
            return Err(FsmError::UnknownAction(*unknown));
        }
        Ok(Self { plan: id, body })
    }

    /// The plan this machine was compiled from.
    pub const fn plan(&self) -> PlanId {
        self.plan
    }

    /// How many states `Λ` it has.
    pub const fn len(&self) -> usize {
        self.body.len()
    }

    /// Whether it has no state (never: a compiled plan has one at least).
    pub const fn is_empty(&self) -> bool {
        self.body.is_empty()
    }

    /// The state with index `index` (lines 4-10: the state and its ordering rule; lines
    /// 11-15: the parallel sensors), from the domain's `actions` and `sensors`. O(NS).
    pub fn state<const W: usize>(
        &self,
        index: u8,
        actions: &[ActuatorAction<'_, W>],
        sensors: &[SensorAction<'_, W>],
    ) -> Option<BehaviourState> {
        let i = usize::from(index);
        let action = *self.body.get(i)?;
        let a = actions.get(action.index())?;
        let on_success = if i.saturating_add(1) == self.body.len() {
            Target::Done
        } else {
            Target::State(index.checked_add(1)?)
        };
        Some(BehaviourState {
            action,
            sensors: crate::action::sensors_serving(sensors, a.pre),
            on_success,
            on_failure: Target::Failed,
        })
    }

    /// The states `Λ`, in order; the first is the initial state.
    pub fn states<'t, const W: usize>(
        &self,
        actions: &'t [ActuatorAction<'_, W>],
        sensors: &'t [SensorAction<'_, W>],
    ) -> impl Iterator<Item = BehaviourState> + 't
    where
        'p: 't,
    {
        let fsm = *self;
        (0..=u8::MAX)
            .take(self.body.len())
            .filter_map(move |i| fsm.state(i, actions, sensors))
    }

    /// The sensors that run in any state of the machine.
    pub fn all_sensors<const W: usize>(
        &self,
        actions: &[ActuatorAction<'_, W>],
        sensors: &[SensorAction<'_, W>],
    ) -> SensorSet {
        self.states(actions, sensors)
            .fold(SensorSet::EMPTY, |acc, s| acc.union(s.sensors))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::action::SensorMode;
    use crate::domain::Domain;
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
        let body = [go, open, rest];
        let fsm = Fsm::compile(PlanId::new(0).unwrap(), &body, d.actions()).unwrap();

        let states: std::vec::Vec<_> = fsm.states(d.actions(), d.sensors()).collect();
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
        assert_eq!(
            fsm.all_sensors(d.actions(), d.sensors()),
            SensorSet::EMPTY.with(sonar).with(camera)
        );
    }

    #[test]
    fn unknown_action_is_an_error() {
        let d: Domain<'_, 1, 1> = Domain::new();
        let body = [ActionId::new(3).unwrap()];
        assert_eq!(
            Fsm::compile(PlanId::new(0).unwrap(), &body, d.actions()),
            Err(FsmError::UnknownAction(ActionId::new(3).unwrap()))
        );
        assert_eq!(
            Fsm::compile(PlanId::new(0).unwrap(), &[], d.actions()),
            Err(FsmError::EmptyBody)
        );
    }
}

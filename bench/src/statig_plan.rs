//! The workload ([`crate::workload`]) with [`statig`] 0.4, a hierarchical state machine library.
//!
//! The plan is a state machine with one state per action, `Action { index }` (the index in
//! state-local storage), plus the terminal states `Done` and `Failed`. It is driven by one
//! `Event::Step` per tick, handled with `handle`. The machine's shared storage, the type
//! the `#[state_machine]` impl is on, owns the sensor and the blackboard. On each step the
//! current action samples the sensor and checks [`path_clear`] (a `Transition` to `Failed`
//! if it does not hold), then reads its progress counter from the blackboard and writes the
//! incremented value back; after its 10th step it transitions to the next action, after the
//! last one to `Done`.

use statig::prelude::*;

use crate::workload::{ACTIONS, STEPS_PER_ACTION, Sonar, path_clear};

/// The data the actions share: each action's progress, in steps.
#[derive(Debug, Default)]
struct Blackboard {
    progress: [u32; ACTIONS as usize],
}

impl Blackboard {
    /// Action steps run so far, over all actions.
    fn steps(&self) -> u32 {
        self.progress.iter().sum()
    }
}

/// The event that drives the machine: one per tick.
enum Event {
    /// Run one step of the current action.
    Step,
}

/// The machine's shared storage: the sensor and the blackboard.
struct Plan<S> {
    /// The range sensor: one reading, mm, per call.
    sensor: S,
    blackboard: Blackboard,
}

#[state_machine(initial = "State::action(0)", visibility = "pub(crate)")]
impl<S> Plan<S>
where
    S: FnMut() -> i32,
{
    /// One action of the plan, `index` in `0..ACTIONS`.
    #[state]
    fn action(&mut self, index: &mut usize, event: &Event) -> Outcome<State> {
        match event {
            Event::Step => {
                if !path_clear((self.sensor)()) {
                    return Transition(State::failed());
                }
                let progress = self.blackboard.progress[*index] + 1;
                self.blackboard.progress[*index] = progress;
                if progress < STEPS_PER_ACTION {
                    Handled
                } else if *index + 1 < ACTIONS as usize {
                    Transition(State::action(*index + 1))
                } else {
                    Transition(State::done())
                }
            }
        }
    }

    /// The plan succeeded.
    #[state]
    fn done(event: &Event) -> Outcome<State> {
        match event {
            Event::Step => Handled,
        }
    }

    /// An action failed: the path was not clear.
    #[state]
    fn failed(event: &Event) -> Outcome<State> {
        match event {
            Event::Step => Handled,
        }
    }
}

/// Runs the plan once with the given sensor (one reading, mm, per call) until it succeeds or
/// fails; returns the action steps it ran.
pub fn run_plan_with(sensor: impl FnMut() -> i32) -> u32 {
    let plan = Plan {
        sensor,
        blackboard: Blackboard::default(),
    };
    let mut machine = plan.uninitialized_state_machine().init();
    while let State::Action { .. } = machine.state() {
        machine.handle(&Event::Step);
    }
    machine.inner().blackboard.steps()
}

/// Runs the plan once with a [`Sonar`]; returns the action steps it ran
/// ([`crate::workload::EXPECTED_STEPS`]).
pub fn run_plan() -> u32 {
    let mut sonar = Sonar::new();
    run_plan_with(|| sonar.sample())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::workload::{EXPECTED_STEPS, assert_fails_when_blocked};

    #[test]
    fn runs_every_step() {
        assert_eq!(run_plan(), EXPECTED_STEPS);
    }

    #[test]
    fn fails_when_the_path_is_blocked() {
        assert_fails_when_blocked(|sensor| run_plan_with(sensor));
    }
}

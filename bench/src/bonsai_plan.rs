//! The workload ([`crate::workload`]) with [`bonsai_bt`] 0.14, a behavior tree library.
//!
//! The plan is a `Sequence` (with memory) of three actions. Each action is a reactive
//! `Sequence([Action(PathClear), Action(Act(i))]).memory(false)`, the library's idiom for
//! "run B while re-checking A on every tick": every tick the `PathClear` leaf samples the
//! sensor and checks [`path_clear`] (`Failure` fails the action, hence the plan), then the
//! `Act(i)` leaf reads action `i`'s progress counter from the tree's blackboard (a typed
//! struct) and writes the incremented value back, returning `Running` until its 10th step and
//! `Success` on it. The tree is ticked with a fixed dt until it returns `Success` (or
//! `Failure`). A sequence carries on into its next child in the same tick when one succeeds,
//! so the 30 action steps take 28 ticks.

use bonsai_bt::{
    Action, ActionArgs, BT, Behavior, Event, Failure, Float, RUNNING, Sequence, Status, Success,
    UpdateArgs,
};

use crate::workload::{ACTIONS, STEPS_PER_ACTION, Sonar, path_clear};

/// The tick period, s.
const DT: Float = 0.01;

/// The leaves of the tree.
#[derive(Debug, Clone, Copy)]
enum Leaf {
    /// The sensor condition: nothing within the threshold.
    PathClear,
    /// One step of action `i` of the plan.
    Act(usize),
}

/// The tree's blackboard: each action's progress, in steps.
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

/// The plan: the actions in sequence, each re-checking the sensor condition every tick.
fn plan() -> Behavior<Leaf> {
    Sequence(
        (0..ACTIONS as usize)
            .map(|i| Sequence(vec![Action(Leaf::PathClear), Action(Leaf::Act(i))]).memory(false))
            .collect(),
    )
}

/// Runs the plan once with the given sensor (one reading, mm, per call) until it succeeds or
/// fails; returns the action steps it ran.
pub fn run_plan_with(mut sensor: impl FnMut() -> i32) -> u32 {
    let mut bt = BT::new(plan(), Blackboard::default());
    let tick: Event = UpdateArgs { dt: DT }.into();
    let mut leaf = |args: ActionArgs<Event, Leaf>, bb: &mut Blackboard| -> (Status, Float) {
        match *args.action {
            Leaf::PathClear => {
                if path_clear(sensor()) {
                    (Success, args.dt)
                } else {
                    (Failure, args.dt)
                }
            }
            Leaf::Act(i) => {
                let progress = bb.progress[i] + 1;
                bb.progress[i] = progress;
                if progress < STEPS_PER_ACTION {
                    RUNNING
                } else {
                    (Success, 0.0)
                }
            }
        }
    };
    while let Some((Status::Running, _)) = bt.tick(&tick, &mut leaf) {}
    bt.blackboard().steps()
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

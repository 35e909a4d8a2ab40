//! The workload ([`crate::workload`]) as a hand-written enum state machine with a struct
//! blackboard: the floor, nothing can do the same work for less.

use crate::workload::{ACTIONS, STEPS_PER_ACTION, Sonar, path_clear};

/// The machine's states.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum State {
    /// Running action `index`, `step` steps done.
    Acting {
        index: u32,
        step: u32,
    },
    Done,
    Failed,
}

/// The blackboard: what the actions read and write.
#[derive(Debug, Default)]
pub struct Blackboard {
    /// The latest reading, mm.
    pub reading_mm: i32,
    /// The running action's progress.
    pub progress: i32,
}

/// One tick: a sample, the condition, a read and a write, the transition.
fn tick(state: State, sonar: &mut Sonar, board: &mut Blackboard) -> State {
    let State::Acting { index, step } = state else {
        return state;
    };
    let mm = sonar.sample();
    if !path_clear(mm) {
        return State::Failed;
    }
    board.reading_mm = mm;
    let read = board.progress;
    board.progress = read.wrapping_add(board.reading_mm);
    match (step + 1, index + 1) {
        (s, _) if s < STEPS_PER_ACTION => State::Acting { index, step: s },
        (_, next) if next < ACTIONS => {
            board.progress = 0;
            State::Acting {
                index: next,
                step: 0,
            }
        }
        _ => State::Done,
    }
}

/// Runs the plan with `sonar`; returns the action steps run and whether it succeeded.
pub fn run_plan_with(mut sonar: Sonar) -> (u32, bool) {
    let mut board = Blackboard::default();
    let mut state = State::Acting { index: 0, step: 0 };
    let mut steps = 0;
    loop {
        match state {
            State::Done => return (steps, true),
            State::Failed => return (steps, false),
            State::Acting { .. } => {
                state = tick(state, std::hint::black_box(&mut sonar), &mut board);
                steps += u32::from(state != State::Failed);
            }
        }
    }
}

/// Runs the plan once; returns the action steps it ran.
pub fn run_plan() -> u32 {
    run_plan_with(Sonar::new()).0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::workload::EXPECTED_STEPS;

    #[test]
    fn the_plan_runs_thirty_action_steps() {
        assert_eq!(run_plan_with(Sonar::new()), (EXPECTED_STEPS, true));
    }
}

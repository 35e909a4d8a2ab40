//! The workload every library expresses in its own idiom: a plan of 3 actions in sequence, each
//! lasting 10 steps beside a sensor condition checked every step, with one data-store read and
//! one data-store write per action step.
//!
//! One action step is:
//! 1. the sensor takes a sample ([`Sonar::sample`]) and the condition ([`path_clear`]) is
//!    checked on it; were it false, the action would fail (in this workload it always holds);
//! 2. the action reads one value from its data store (blackboard, context) and writes one.
//!
//! The action succeeds after its 10th step, and the next one starts; the plan succeeds after
//! the last. Every implementation returns the number of action steps it ran, which the
//! benchmarks assert equals [`EXPECTED_STEPS`].

/// Actions in the plan.
pub const ACTIONS: u32 = 3;
/// Steps each action lasts.
pub const STEPS_PER_ACTION: u32 = 10;
/// Action steps in one run of the plan.
pub const EXPECTED_STEPS: u32 = ACTIONS * STEPS_PER_ACTION;
/// The condition's threshold, mm.
pub const THRESHOLD_MM: i32 = 500;

/// A deterministic range sensor: readings between 1000 and 1006 mm.
#[derive(Debug, Default, Clone)]
pub struct Sonar {
    n: u32,
}

impl Sonar {
    /// A sensor at its first reading.
    pub const fn new() -> Self {
        Self { n: 0 }
    }

    /// One reading, mm.
    pub fn sample(&mut self) -> i32 {
        self.n = self.n.wrapping_add(1);
        1000 + (self.n % 7) as i32
    }
}

/// The sensor condition every action step checks: nothing within the threshold.
pub fn path_clear(mm: i32) -> bool {
    mm > THRESHOLD_MM
}

/// Checks a plan runner (`run` runs the plan with the given sensor and returns its action
/// steps) against a path that is clear for 14 readings and then blocked: action 1 fails at
/// its 5th step, after 14 steps were run, and no reading is taken after the failure.
#[cfg(test)]
pub(crate) fn assert_fails_when_blocked(run: impl FnOnce(&mut dyn FnMut() -> i32) -> u32) {
    let mut sonar = Sonar::new();
    let mut readings = 0;
    let steps = run(&mut || {
        readings += 1;
        if readings <= 14 {
            sonar.sample()
        } else {
            THRESHOLD_MM
        }
    });
    assert_eq!(steps, 14);
    assert_eq!(readings, 15);
}

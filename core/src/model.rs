//! The world model `M = <ω, φ, Π>` (paper §4.2) and the task `Π = <Δ, τ0, τG>`.

pub use psmpa_model::task::Task;

use crate::action::SensorId;
use crate::facts::FactSetOf;
use crate::store::Entry;

/// A snapshot of the world model `M = <ω, φ, Π>` of a runtime with `NS` sensors and fact sets
/// of `W` words.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WorldModel<const NS: usize, const W: usize = 1> {
    /// `ω`: the latest sample of every sensor, with its timestamp.
    pub percepts: [Option<Entry>; NS],
    /// `φ`: the beliefs, the current state `τ`.
    pub beliefs: FactSetOf<W>,
    /// `Π`: the task.
    pub task: Task<W>,
}

impl<const NS: usize, const W: usize> WorldModel<NS, W> {
    /// Whether the goal holds: `τG ⊆ φ`.
    pub fn goal_holds(&self) -> bool {
        self.task.goal.is_subset(self.beliefs)
    }

    /// The latest sample of `sensor`.
    pub fn percept(&self, sensor: SensorId) -> Option<Entry> {
        self.percepts.get(sensor.index()).copied().flatten()
    }
}

//! A mission: everything the runtime needs to know about a robot's job, `<S, A, P>` and the
//! task `Π`, held in fixed-capacity structures.

use crate::domain::Domain;
use crate::model::Task;
use crate::plan::PlanLibrary;

/// The domain (facts, events, sensor-based and actuator-based actions), the plan library and
/// the task of one robot, with room for `NS` sensors, `NA` actions, `NP` plans of at most `L`
/// actions each.
#[derive(Clone, Debug)]
pub struct Mission<'a, const NS: usize, const NA: usize, const NP: usize, const L: usize> {
    /// `Δ`: facts, events, `S` and `A`.
    pub domain: Domain<'a, NS, NA>,
    /// `P`: the plan library.
    pub library: PlanLibrary<'a, NP, L>,
    /// `Π`: what to achieve from where.
    pub task: Task,
}

//! The task `Π = <Δ, τ0, τG>` (paper §4.2): what a robot is to achieve, from where.

use crate::domain::EventId;
use crate::facts::FactSetOf;

/// A task `Π = <Δ, τ0, τG>`; the domain `Δ` is the mission's [`Domain`](crate::domain::Domain).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Task<const W: usize = 1> {
    /// The event posted to the plan library until the goal holds (for example "fetch tea").
    pub event: EventId,
    /// `τ0`: the initial state.
    pub init: FactSetOf<W>,
    /// `τG`: the goal; reached when `τG ⊆ τ`.
    pub goal: FactSetOf<W>,
}

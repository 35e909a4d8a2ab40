//! Task-oriented plans `p = <t(p), c(p), bd(p)>` and the plan library `P` (paper §4.2), with
//! BDI plan selection.
//!
//! A plan is *applicable* to an event when its trigger `t(p)` is that event and its context
//! `c(p)` holds in the beliefs: `c(p) ⊆ τ`. Selection takes the first applicable plan in
//! library order (library order is priority), skipping the plans that already failed for the
//! same event while the beliefs have not changed since ([`FailureMemory`]).

use heapless::Vec;

use crate::action::ActionId;
use crate::domain::EventId;
use crate::facts::FactSetOf;

/// Most plans a library can hold: the width of a [`PlanSet`].
pub const MAX_PLANS: usize = 32;

/// Index of a plan in its library, `0..MAX_PLANS`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PlanId(u8);

impl PlanId {
    /// The plan of index `I`, checked when the program is built: an index out of range
    /// fails the build, never a run (the ids of a mission compiled in with `include_mission!`).
    pub const fn of<const I: usize>() -> Self {
        const {
            // Evaluated at compile time only.
            #[allow(clippy::panic)]
            match Self::new(I) {
                Some(id) => id,
                None => panic!("plan index out of range"),
            }
        }
    }

    /// The id of a plan the planner generated (not in the library).
    pub const GENERATED: Self = Self(u8::MAX);

    /// The plan with index `index`, or `None` when `index >= MAX_PLANS`.
    pub const fn new(index: usize) -> Option<Self> {
        if index < MAX_PLANS {
            Some(Self(index as u8))
        } else {
            None
        }
    }

    /// The index of this plan in its library.
    pub const fn index(self) -> usize {
        self.0 as usize
    }
}

/// A set of plans.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PlanSet(u32);

impl PlanSet {
    /// No plan.
    pub const EMPTY: Self = Self(0);

    const fn bit(plan: PlanId) -> u32 {
        // Generated plans (and any id past the width) have no bit.
        match 1u32.checked_shl(plan.0 as u32) {
            Some(bit) => bit,
            None => 0,
        }
    }

    /// Whether `plan` is in the set.
    pub const fn contains(self, plan: PlanId) -> bool {
        self.0 & Self::bit(plan) != 0
    }

    /// The set with `plan` added; a generated plan is never in a set.
    #[must_use]
    pub const fn with(self, plan: PlanId) -> Self {
        Self(self.0 | Self::bit(plan))
    }

    /// The plans in either set.
    #[must_use]
    pub const fn union(self, other: Self) -> Self {
        Self(self.0 | other.0)
    }

    /// Whether the set is empty.
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// The raw bits (bit `i` is plan `i`).
    pub const fn bits(self) -> u32 {
        self.0
    }
}

/// A task-oriented plan `p = <t(p), c(p), bd(p)>` whose body holds at most `L` actions.
#[derive(Clone, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Plan<'a, const L: usize, const W: usize = 1> {
    /// Name, as missions and traces call it.
    pub name: &'a str,
    /// `t(p)`: the event that makes the plan a candidate.
    pub trigger: EventId,
    /// `c(p)`: the facts that must hold for the plan to be applicable.
    pub context: FactSetOf<W>,
    /// The facts that must *not* hold for the plan to be applicable (a plan for when the
    /// battery is not ok).
    pub context_not: FactSetOf<W>,
    /// `bd(p) = <a0, ..., an>`: the actuator-based actions, in order.
    pub body: Vec<ActionId, L>,
}

/// Why a plan could not be built or added.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum PlanError {
    /// The body would exceed `capacity` actions.
    BodyTooLong {
        /// The most actions a body can hold.
        capacity: usize,
    },
    /// The body has no action.
    EmptyBody,
    /// The library already holds `capacity` plans.
    LibraryFull {
        /// The most plans the library can hold.
        capacity: usize,
    },
    /// A plan of that name is already in the library.
    Duplicate,
    /// A plan has an empty name (or one of white space only).
    EmptyName,
}

impl core::fmt::Display for PlanError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::BodyTooLong { capacity } => {
                write!(f, "the body is longer than {capacity} actions")
            }
            Self::EmptyBody => f.write_str("the body has no action"),
            Self::LibraryFull { capacity } => {
                write!(f, "the library already holds {capacity} plans")
            }
            Self::Duplicate => f.write_str("a plan of that name is already in the library"),
            Self::EmptyName => f.write_str("a plan has an empty name"),
        }
    }
}

impl core::error::Error for PlanError {}

impl<'a, const L: usize, const W: usize> Plan<'a, L, W> {
    /// A plan from its trigger, context and body.
    pub fn new(
        name: &'a str,
        trigger: EventId,
        context: FactSetOf<W>,
        body: &[ActionId],
    ) -> Result<Self, PlanError> {
        if body.is_empty() {
            return Err(PlanError::EmptyBody);
        }
        let body = Vec::from_slice(body).map_err(|_| PlanError::BodyTooLong { capacity: L })?;
        Ok(Self {
            name,
            trigger,
            context,
            context_not: FactSetOf::EMPTY,
            body,
        })
    }

    /// A plan from its parts, built at compile time (`include_mission!`). Nothing is checked
    /// here (a body of at least one action of the domain); a body longer than `L` does not
    /// compile.
    pub const fn from_parts<const M: usize>(
        name: &'a str,
        trigger: EventId,
        context: FactSetOf<W>,
        context_not: FactSetOf<W>,
        body: [ActionId; M],
    ) -> Self {
        Self {
            name,
            trigger,
            context,
            context_not,
            body: Vec::from_array(body),
        }
    }

    /// The same plan, applicable only while none of `facts` holds.
    #[must_use]
    pub fn with_context_not(mut self, facts: FactSetOf<W>) -> Self {
        self.context_not = facts;
        self
    }

    /// Whether the plan is applicable: `t(p) = event`, `c(p) ⊆ beliefs` and no fact of
    /// [`context_not`](Self::context_not) holds. O(1).
    pub fn applicable(&self, event: EventId, beliefs: FactSetOf<W>) -> bool {
        applicable(
            (self.trigger, self.context, self.context_not),
            event,
            beliefs,
        )
    }
}

/// Whether a plan of trigger `t(p)`, context `c(p)` and negative context (`trigger, context,
/// context_not`) is applicable to `event` under `beliefs`: `t(p) = event`, `c(p) ⊆ beliefs`
/// and no fact of the negative context holds. O(1).
pub fn applicable<const W: usize>(
    (trigger, context, context_not): (EventId, FactSetOf<W>, FactSetOf<W>),
    event: EventId,
    beliefs: FactSetOf<W>,
) -> bool {
    trigger == event && context.is_subset(beliefs) && !context_not.intersects(beliefs)
}

/// The plan library `P`: at most `NP` plans of at most `L` actions each.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PlanLibrary<'a, const NP: usize, const L: usize, const W: usize = 1> {
    plans: Vec<Plan<'a, L, W>, NP>,
}

impl<'a, const NP: usize, const L: usize, const W: usize> PlanLibrary<'a, NP, L, W> {
    /// An empty library.
    pub const fn new() -> Self {
        Self { plans: Vec::new() }
    }

    /// A library of `plans`, built at compile time (`include_mission!`). Nothing is checked
    /// here; more plans than the capacity does not compile.
    pub const fn from_plans<const M: usize>(plans: [Plan<'a, L, W>; M]) -> Self {
        Self {
            plans: Vec::from_array(plans),
        }
    }

    /// Empties the library in place.
    pub fn clear(&mut self) {
        self.plans.clear();
    }

    /// Adds a plan and returns its id.
    pub fn add(&mut self, plan: Plan<'a, L, W>) -> Result<PlanId, PlanError> {
        let full = PlanError::LibraryFull {
            capacity: if NP < MAX_PLANS { NP } else { MAX_PLANS },
        };
        if crate::domain::blank(plan.name) {
            return Err(PlanError::EmptyName);
        }
        if self
            .plans
            .iter()
            .any(|p| crate::domain::same_name(p.name, plan.name))
        {
            return Err(PlanError::Duplicate);
        }
        let id = PlanId::new(self.plans.len()).ok_or(full)?;
        self.plans.push(plan).map_err(|_| full)?;
        Ok(id)
    }

    /// A plan of the library.
    pub fn get(&self, id: PlanId) -> Option<&Plan<'a, L, W>> {
        self.plans.get(id.index())
    }

    /// All plans, in priority order.
    pub fn plans(&self) -> &[Plan<'a, L, W>] {
        &self.plans
    }

    /// The id of the plan called `name`.
    pub fn id_of(&self, name: &str) -> Option<PlanId> {
        self.plans
            .iter()
            .position(|p| p.name == name)
            .and_then(PlanId::new)
    }

    /// BDI selection: the first plan, in priority order, that is applicable to `event` under
    /// `beliefs` and not in `excluded`. O(NP).
    pub fn select(
        &self,
        event: EventId,
        beliefs: FactSetOf<W>,
        excluded: PlanSet,
    ) -> Option<PlanId> {
        self.plans
            .iter()
            .enumerate()
            .filter_map(|(i, p)| PlanId::new(i).map(|id| (id, p)))
            .find(|(id, p)| !excluded.contains(*id) && p.applicable(event, beliefs))
            .map(|(id, _)| id)
    }

    /// Whether any plan, failed or not, is applicable to `event` under `beliefs`. O(NP).
    pub fn any_applicable(&self, event: EventId, beliefs: FactSetOf<W>) -> bool {
        self.plans.iter().any(|p| p.applicable(event, beliefs))
    }
}

/// Remembers which plans failed for an event, so that a failed plan is not retried for the
/// same event until the model (the beliefs) changes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FailureMemory<const W: usize = 1> {
    event: Option<EventId>,
    beliefs: FactSetOf<W>,
    failed: PlanSet,
}

impl<const W: usize> FailureMemory<W> {
    /// Nothing has failed.
    pub const fn new() -> Self {
        Self {
            event: None,
            beliefs: FactSetOf::EMPTY,
            failed: PlanSet::EMPTY,
        }
    }

    /// Records that `plan` failed for `event` when the beliefs were `beliefs`. O(1).
    pub fn record(&mut self, plan: PlanId, event: EventId, beliefs: FactSetOf<W>) {
        if self.event != Some(event) || self.beliefs != beliefs {
            *self = Self {
                event: Some(event),
                beliefs,
                failed: PlanSet::EMPTY,
            };
        }
        self.failed = self.failed.with(plan);
    }

    /// The plans to skip for `event` under `beliefs`: the recorded failures if neither the
    /// event nor the beliefs changed since, else none. O(1).
    pub fn excluded(&self, event: EventId, beliefs: FactSetOf<W>) -> PlanSet {
        if self.event == Some(event) && self.beliefs == beliefs {
            self.failed
        } else {
            PlanSet::EMPTY
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::facts::{FactId, FactSet};

    fn ev(i: usize) -> EventId {
        EventId::new(i).unwrap()
    }
    fn act(i: usize) -> ActionId {
        ActionId::new(i).unwrap()
    }

    #[test]
    fn selection_respects_trigger_context_priority_and_failures() {
        let door_open = FactSet::single(FactId::new(0).unwrap());
        let mut lib: PlanLibrary<'_, 4, 3> = PlanLibrary::new();
        let front = lib
            .add(Plan::new("front", ev(0), door_open, &[act(0), act(1)]).unwrap())
            .unwrap();
        let back = lib
            .add(Plan::new("back", ev(0), FactSet::EMPTY, &[act(2)]).unwrap())
            .unwrap();
        lib.add(Plan::new("other", ev(1), FactSet::EMPTY, &[act(2)]).unwrap())
            .unwrap();

        assert_eq!(lib.select(ev(0), door_open, PlanSet::EMPTY), Some(front));
        // Context does not hold: the next plan for the event.
        assert_eq!(
            lib.select(ev(0), FactSet::EMPTY, PlanSet::EMPTY),
            Some(back)
        );

        let mut memory = FailureMemory::new();
        memory.record(front, ev(0), door_open);
        let excluded = memory.excluded(ev(0), door_open);
        assert_eq!(lib.select(ev(0), door_open, excluded), Some(back));
        memory.record(back, ev(0), door_open);
        assert_eq!(
            lib.select(ev(0), door_open, memory.excluded(ev(0), door_open)),
            None
        );
        assert!(lib.any_applicable(ev(0), door_open));
        // The model changed: both plans are candidates again.
        let changed = door_open.with(FactId::new(5).unwrap());
        assert_eq!(memory.excluded(ev(0), changed), PlanSet::EMPTY);
        assert_eq!(
            lib.select(ev(0), changed, memory.excluded(ev(0), changed)),
            Some(front)
        );
    }

    #[test]
    fn plans_reject_empty_long_and_duplicate() {
        assert_eq!(
            Plan::<'_, 2>::new("p", ev(0), FactSet::EMPTY, &[]),
            Err(PlanError::EmptyBody)
        );
        assert_eq!(
            Plan::<'_, 2>::new("p", ev(0), FactSet::EMPTY, &[act(0), act(1), act(2)]),
            Err(PlanError::BodyTooLong { capacity: 2 })
        );
        let mut lib: PlanLibrary<'_, 1, 2> = PlanLibrary::new();
        let p = Plan::new("p", ev(0), FactSet::EMPTY, &[act(0)]).unwrap();
        lib.add(p.clone()).unwrap();
        assert_eq!(lib.add(p.clone()), Err(PlanError::Duplicate));
        let q = Plan::new("q", ev(0), FactSet::EMPTY, &[act(0)]).unwrap();
        assert_eq!(lib.add(q), Err(PlanError::LibraryFull { capacity: 1 }));
    }
}

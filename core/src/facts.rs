//! Facts and fact sets: the STRIPS world state `τ`.
//!
//! A state is a fixed-width set of facts. `pre`, `add` and `del` of an action and the
//! perception `per(s)` of a sensor are fact sets too, so the paper's state update
//! `τ' = add(a) ∪ (τ \ del(a))` is one bitwise expression ([`FactSet::apply`]).
//!
//! Every operation here is O(1): a handful of integer instructions on a `u64`.

use core::fmt;

/// How many distinct facts a domain can name: the width of a [`FactSet`].
pub const MAX_FACTS: usize = 64;

/// Index of a fact in its domain's fact table, `0..MAX_FACTS`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FactId(u8);

impl FactId {
    /// The first fact of a domain.
    pub const FIRST: Self = Self(0);

    /// The fact with index `index`, or `None` when `index >= MAX_FACTS`.
    pub const fn new(index: usize) -> Option<Self> {
        if index < MAX_FACTS {
            Some(Self(index as u8))
        } else {
            None
        }
    }

    /// The index of this fact in its domain's fact table.
    pub const fn index(self) -> usize {
        self.0 as usize
    }
}

/// A set of facts: a world state `τ`, or a `pre`/`add`/`del`/`per` set.
#[derive(Clone, Copy, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FactSet(u64);

impl FactSet {
    /// The empty set `∅`.
    pub const EMPTY: Self = Self(0);

    /// Every fact a set can hold: as a precondition, one that never holds in practice.
    pub const ALL: Self = Self(u64::MAX);

    /// The set whose members are the set bits of `bits` (bit `i` is fact `i`).
    pub const fn from_bits(bits: u64) -> Self {
        Self(bits)
    }

    /// The raw bits of the set (bit `i` is fact `i`).
    pub const fn bits(self) -> u64 {
        self.0
    }

    /// The set `{fact}`.
    pub const fn single(fact: FactId) -> Self {
        Self(1u64 << fact.0)
    }

    /// The set of the given facts.
    pub const fn of(facts: &[FactId]) -> Self {
        let mut bits = 0u64;
        let mut rest = facts;
        while let [first, tail @ ..] = rest {
            bits |= 1u64 << first.0;
            rest = tail;
        }
        Self(bits)
    }

    /// Whether the set is `∅`.
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// Number of facts in the set.
    pub const fn len(self) -> usize {
        self.0.count_ones() as usize
    }

    /// Whether `fact ∈ self`.
    pub const fn contains(self, fact: FactId) -> bool {
        self.0 & (1u64 << fact.0) != 0
    }

    /// `self ∪ {fact}`.
    #[must_use]
    pub const fn with(self, fact: FactId) -> Self {
        Self(self.0 | (1u64 << fact.0))
    }

    /// `self \ {fact}`.
    #[must_use]
    pub const fn without(self, fact: FactId) -> Self {
        Self(self.0 & !(1u64 << fact.0))
    }

    /// `self ∪ other`.
    #[must_use]
    pub const fn union(self, other: Self) -> Self {
        Self(self.0 | other.0)
    }

    /// `self ∩ other`.
    #[must_use]
    pub const fn intersection(self, other: Self) -> Self {
        Self(self.0 & other.0)
    }

    /// `self \ other`.
    #[must_use]
    pub const fn difference(self, other: Self) -> Self {
        Self(self.0 & !other.0)
    }

    /// `self ⊆ other`: every fact of `self` holds in `other`.
    pub const fn is_subset(self, other: Self) -> bool {
        self.0 & !other.0 == 0
    }

    /// Whether the two sets share a fact.
    pub const fn intersects(self, other: Self) -> bool {
        self.0 & other.0 != 0
    }

    /// The STRIPS state update `add ∪ (self \ del)` (paper §4.2).
    #[must_use]
    pub const fn apply(self, add: Self, del: Self) -> Self {
        Self(add.0 | (self.0 & !del.0))
    }

    /// The facts of the set in increasing index order.
    pub fn iter(self) -> FactIter {
        FactIter(self.0)
    }
}

impl fmt::Debug for FactSet {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_set()
            .entries(self.iter().map(FactId::index))
            .finish()
    }
}

impl FromIterator<FactId> for FactSet {
    fn from_iter<I: IntoIterator<Item = FactId>>(iter: I) -> Self {
        iter.into_iter().fold(Self::EMPTY, Self::with)
    }
}

/// Iterator over the facts of a [`FactSet`], lowest index first.
#[derive(Clone, Debug)]
pub struct FactIter(u64);

impl Iterator for FactIter {
    type Item = FactId;

    fn next(&mut self) -> Option<FactId> {
        if self.0 == 0 {
            return None;
        }
        let index = self.0.trailing_zeros();
        // Clear the lowest set bit.
        self.0 &= self.0.wrapping_sub(1);
        Some(FactId(index as u8))
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let n = self.0.count_ones() as usize;
        (n, Some(n))
    }
}

impl ExactSizeIterator for FactIter {}

#[cfg(test)]
mod tests {
    use super::*;

    fn f(i: usize) -> FactId {
        FactId::new(i).unwrap()
    }

    #[test]
    fn fact_ids_stop_at_the_width() {
        assert!(FactId::new(MAX_FACTS - 1).is_some());
        assert!(FactId::new(MAX_FACTS).is_none());
    }

    #[test]
    fn apply_is_add_union_state_minus_del() {
        let state = FactSet::of(&[f(0), f(1), f(2)]);
        let add = FactSet::of(&[f(2), f(5)]);
        let del = FactSet::of(&[f(1), f(2)]);
        // add wins over del for a fact in both, as in τ' = add ∪ (τ \ del).
        assert_eq!(state.apply(add, del), FactSet::of(&[f(0), f(2), f(5)]));
    }

    #[test]
    fn subset_and_set_algebra() {
        let a = FactSet::of(&[f(3), f(63)]);
        let b = a.with(f(7));
        assert!(a.is_subset(b));
        assert!(!b.is_subset(a));
        assert!(FactSet::EMPTY.is_subset(a));
        assert_eq!(b.difference(a), FactSet::single(f(7)));
        assert_eq!(a.intersection(b), a);
        assert_eq!(b.len(), 3);
        assert_eq!(
            b.iter().map(FactId::index).collect::<heapless::Vec<_, 4>>(),
            [3, 7, 63]
        );
        assert!(b.without(f(63)).contains(f(3)));
        assert!(!b.without(f(63)).contains(f(63)));
    }
}

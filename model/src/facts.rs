//! Facts and fact sets: the STRIPS world state `τ`.
//!
//! A state is a fixed-width set of facts. `pre`, `add` and `del` of an action and the
//! perception `per(s)` of a sensor are fact sets too, so the paper's state update
//! `τ' = add(a) ∪ (τ \ del(a))` is one bitwise expression ([`FactSet::apply`]).
//!
//! The width is a capacity: `FactSetOf<W>` holds `64 · W` facts in `W` words, `FactSet` (one
//! word, 64 facts) by default. Every operation is O(W): a handful of integer instructions a
//! word, the same instructions as a plain `u64` for the default width.

use core::fmt;

/// How many distinct facts a domain of the default width can name: one word of a [`FactSet`].
pub const MAX_FACTS: usize = 64;

/// The widest fact set, in words: 4,096 facts (a [`FactId`] is 16 bits; wider does not
/// compile).
pub const MAX_WORDS: usize = 64;

/// Index of a fact in its domain's fact table, below its fact sets' capacity.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FactId(u16);

impl FactId {
    /// The fact of index `I`, checked when the program is built: an index out of range
    /// fails the build, never a run (the ids of a mission compiled in with `include_mission!`).
    pub const fn of<const I: usize>() -> Self {
        const {
            // Evaluated at compile time only.
            #[allow(clippy::panic)]
            match Self::within(I, MAX_WORDS * 64) {
                Some(id) => id,
                None => panic!("fact index out of range"),
            }
        }
    }

    /// The first fact of a domain.
    pub const FIRST: Self = Self(0);

    /// The fact with index `index`, or `None` when `index >= MAX_FACTS` (the default width).
    pub const fn new(index: usize) -> Option<Self> {
        Self::within(index, MAX_FACTS)
    }

    /// The fact with index `index`, or `None` when `index >= capacity` or past the widest set.
    pub const fn within(index: usize, capacity: usize) -> Option<Self> {
        if index < capacity && index < MAX_WORDS * 64 {
            Some(Self(index as u16))
        } else {
            None
        }
    }

    /// The index of this fact in its domain's fact table.
    pub const fn index(self) -> usize {
        self.0 as usize
    }

    /// Word and bit of this fact in a set of `W` words, or `None` past the set's width.
    const fn place<const W: usize>(self) -> Option<(usize, u64)> {
        let word = (self.0 >> 6) as usize;
        if word < W {
            Some((word, 1u64 << (self.0 & 63)))
        } else {
            None
        }
    }
}

/// A set of facts: a world state `τ`, or a `pre`/`add`/`del`/`per` set; `64 · W` facts wide.
/// [`FactSet`] is the one-word set most robots use.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FactSetOf<const W: usize>([u64; W]);

/// A set of at most 64 facts ([`MAX_FACTS`]): one word, what a robot's runtime uses.
pub type FactSet = FactSetOf<1>;

impl<const W: usize> Default for FactSetOf<W> {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl FactSet {
    /// The set whose members are the set bits of `bits` (bit `i` is fact `i`).
    pub const fn from_bits(bits: u64) -> Self {
        Self([bits])
    }

    /// The raw bits of the set (bit `i` is fact `i`).
    pub const fn bits(self) -> u64 {
        let [bits] = self.0;
        bits
    }
}

impl<const W: usize> FactSetOf<W> {
    /// How many facts the set can hold.
    pub const CAPACITY: usize = {
        assert!(
            W >= 1 && W <= MAX_WORDS,
            "a fact set is 1 to MAX_WORDS words"
        );
        W.saturating_mul(64)
    };

    /// The empty set `∅`.
    pub const EMPTY: Self = Self([0; W]);

    /// Every fact a set can hold: as a precondition, one that never holds in practice.
    pub const ALL: Self = Self([u64::MAX; W]);

    /// The set of the given words (bit `i` of word `w` is fact `64 · w + i`).
    pub const fn from_words(words: [u64; W]) -> Self {
        Self(words)
    }

    /// The words of the set (bit `i` of word `w` is fact `64 · w + i`).
    pub const fn words(self) -> [u64; W] {
        self.0
    }

    /// The set `{fact}` (empty for a fact past the set's width, never another fact).
    pub const fn single(fact: FactId) -> Self {
        Self::EMPTY.with(fact)
    }

    /// The set of the given facts.
    pub const fn of(facts: &[FactId]) -> Self {
        let mut set = Self::EMPTY;
        let mut rest = facts;
        while let [first, tail @ ..] = rest {
            set = set.with(*first);
            rest = tail;
        }
        set
    }

    /// Whether the set is `∅`.
    pub const fn is_empty(self) -> bool {
        if let [w] = self.0.as_slice() {
            return *w == 0;
        }
        let mut rest: &[u64] = &self.0;
        while let [w, tail @ ..] = rest {
            if *w != 0 {
                return false;
            }
            rest = tail;
        }
        true
    }

    /// Number of facts in the set.
    pub const fn len(self) -> usize {
        if let [w] = self.0.as_slice() {
            return w.count_ones() as usize;
        }
        let (mut n, mut rest): (usize, &[u64]) = (0, &self.0);
        while let [w, tail @ ..] = rest {
            n = n.saturating_add(w.count_ones() as usize);
            rest = tail;
        }
        n
    }

    /// Whether `fact ∈ self`.
    pub const fn contains(self, fact: FactId) -> bool {
        let Some((at, bit)) = fact.place::<W>() else {
            return false;
        };
        if let [word] = self.0.as_slice() {
            return *word & bit != 0;
        }
        let (mut i, mut rest): (usize, &[u64]) = (0, &self.0);
        while let [word, tail @ ..] = rest {
            if i == at {
                return *word & bit != 0;
            }
            (i, rest) = (i.saturating_add(1), tail);
        }
        false
    }

    /// `self ∪ {fact}` (`self` for a fact past the set's width).
    #[must_use]
    pub const fn with(self, fact: FactId) -> Self {
        self.update(fact, true)
    }

    /// `self \ {fact}`.
    #[must_use]
    pub const fn without(self, fact: FactId) -> Self {
        self.update(fact, false)
    }

    const fn update(mut self, fact: FactId, member: bool) -> Self {
        let Some((at, bit)) = fact.place::<W>() else {
            return self;
        };
        if let [word] = &mut self.0 as &mut [u64] {
            *word = if member { *word | bit } else { *word & !bit };
            return self;
        }
        let (mut i, mut rest): (usize, &mut [u64]) = (0, &mut self.0);
        while let [word, tail @ ..] = rest {
            if i == at {
                *word = if member { *word | bit } else { *word & !bit };
                break;
            }
            (i, rest) = (i.saturating_add(1), tail);
        }
        self
    }

    /// `self ∪ other`.
    #[must_use]
    pub const fn union(self, other: Self) -> Self {
        self.apply(other, Self::EMPTY)
    }

    /// `self ∩ other`.
    #[must_use]
    pub const fn intersection(self, other: Self) -> Self {
        // `self \ (self \ other)`: one word loop, `apply`'s, serves every set operation.
        self.difference(self.difference(other))
    }

    /// `self \ other`.
    #[must_use]
    pub const fn difference(self, other: Self) -> Self {
        self.apply(Self::EMPTY, other)
    }

    /// `self ⊆ other`: every fact of `self` holds in `other`.
    pub const fn is_subset(self, other: Self) -> bool {
        if let ([a], [b]) = (self.0.as_slice(), other.0.as_slice()) {
            return *a & !*b == 0;
        }
        let (mut a, mut b): (&[u64], &[u64]) = (&self.0, &other.0);
        while let ([x, ar @ ..], [y, br @ ..]) = (a, b) {
            if *x & !*y != 0 {
                return false;
            }
            (a, b) = (ar, br);
        }
        true
    }

    /// Whether the two sets share a fact.
    pub const fn intersects(self, other: Self) -> bool {
        if let ([a], [b]) = (self.0.as_slice(), other.0.as_slice()) {
            return *a & *b != 0;
        }
        let (mut a, mut b): (&[u64], &[u64]) = (&self.0, &other.0);
        while let ([x, ar @ ..], [y, br @ ..]) = (a, b) {
            if *x & *y != 0 {
                return true;
            }
            (a, b) = (ar, br);
        }
        false
    }

    /// The STRIPS state update `add ∪ (self \ del)` (paper §4.2).
    #[must_use]
    pub const fn apply(self, add: Self, del: Self) -> Self {
        let mut out = self.0;
        if let ([x], [y], [z]) = (&mut out as &mut [u64], add.0.as_slice(), del.0.as_slice()) {
            *x = *y | (*x & !*z);
            return Self(out);
        }
        let (mut s, mut a, mut d): (&mut [u64], &[u64], &[u64]) = (&mut out, &add.0, &del.0);
        while let ([x, sr @ ..], [y, ar @ ..], [z, dr @ ..]) = (s, a, d) {
            *x = *y | (*x & !*z);
            (s, a, d) = (sr, ar, dr);
        }
        Self(out)
    }

    /// The facts of the set in increasing index order.
    pub fn iter(self) -> FactIter<W> {
        FactIter {
            words: self.0,
            word: 0,
        }
    }
}

impl<const W: usize> fmt::Debug for FactSetOf<W> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_set()
            .entries(self.iter().map(FactId::index))
            .finish()
    }
}

impl<const W: usize> FromIterator<FactId> for FactSetOf<W> {
    fn from_iter<I: IntoIterator<Item = FactId>>(iter: I) -> Self {
        iter.into_iter().fold(Self::EMPTY, Self::with)
    }
}

/// Iterator over the facts of a [`FactSet`], lowest index first.
#[derive(Clone, Debug)]
pub struct FactIter<const W: usize = 1> {
    words: [u64; W],
    word: usize,
}

impl<const W: usize> Iterator for FactIter<W> {
    type Item = FactId;

    fn next(&mut self) -> Option<FactId> {
        // One word (the default width): the plain bit loop, no word index.
        if let [bits] = self.words.as_mut_slice() {
            if *bits == 0 {
                return None;
            }
            let index = bits.trailing_zeros() as u16;
            *bits &= bits.wrapping_sub(1);
            return Some(FactId(index));
        }
        loop {
            let bits = self.words.get_mut(self.word)?;
            if *bits != 0 {
                let index = bits.trailing_zeros() as usize;
                // Clear the lowest set bit.
                *bits &= bits.wrapping_sub(1);
                let at = self.word.saturating_mul(64).saturating_add(index);
                return FactId::within(at, W.saturating_mul(64));
            }
            self.word = self.word.saturating_add(1);
        }
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let n = self
            .words
            .iter()
            .skip(self.word)
            .map(|w| w.count_ones() as usize)
            .sum();
        (n, Some(n))
    }
}

impl<const W: usize> ExactSizeIterator for FactIter<W> {}

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

    #[test]
    fn wide_sets_span_their_words() {
        let id = |i: usize| FactId::within(i, 256).unwrap();
        let a = FactSetOf::<4>::of(&[id(0), id(63), id(64), id(200)]);
        assert_eq!(a.len(), 4);
        assert!(a.contains(id(64)) && a.contains(id(200)) && !a.contains(id(65)));
        assert_eq!(
            a.iter().map(FactId::index).collect::<heapless::Vec<_, 8>>(),
            [0, 63, 64, 200]
        );
        let add = FactSetOf::<4>::single(id(255));
        let del = FactSetOf::<4>::of(&[id(63), id(200)]);
        let b = a.apply(add, del);
        assert_eq!(
            b.iter().map(FactId::index).collect::<heapless::Vec<_, 8>>(),
            [0, 64, 255]
        );
        assert!(FactSetOf::<4>::single(id(64)).is_subset(b));
        assert!(!b.is_subset(a));
        assert!(b.intersects(a) && !b.difference(a).intersects(a));
        // A fact past a set's width is never another fact (no wrap into a lower word).
        assert_eq!(FactSetOf::<1>::single(id(64)), FactSetOf::<1>::EMPTY);
        assert!(!FactSet::ALL.contains(id(64)));
        assert_eq!(FactSetOf::<4>::CAPACITY, 256);
    }
}

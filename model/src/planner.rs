//! The embedded planner: `generatePlans: M -> P` (Algorithm 1 line 4) when no plan of the
//! library applies. Forward state-space search over fact sets from the current beliefs to the
//! goal, with STRIPS semantics (`τ' = add(a) ∪ (τ \ del(a))`).
//!
//! * [`Strategy::BreadthFirst`] finds a shortest plan.
//! * [`Strategy::AStar`] with the admissible [`Heuristic::Max`] (h_max) also finds a shortest
//!   plan, expanding fewer nodes; [`Strategy::Greedy`] with [`Heuristic::Add`] (h_add) finds a
//!   plan fast in larger domains, not necessarily a shortest one.
//!
//! Memory is fixed: `N` search nodes (`8 · W + 8` bytes each: 16 for one-word fact sets), a
//! visited table of `N` slots and an open list of `N` entries, all on the stack of the call.
//! Work is bounded: at most `budget` nodes, and at most 7/8 of `N`, are generated; running out is [`PlanningError::Budget`], never a hang, and an
//! exhausted search space is [`PlanningError::Unsolvable`]. Each expansion costs O(NA) set
//! operations plus, for heuristic search, O(NA · |facts|) per generated node.

use heapless::Vec;
use heapless::binary_heap::{BinaryHeap, Min};

use crate::action::{ActionId, ActuatorAction, MAX_ACTIONS};
use crate::facts::{FactId, FactSetOf};

/// Estimates of the number of actions still needed (for unit action costs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Heuristic {
    /// Goal facts that do not hold yet. Not admissible when an action adds several.
    GoalCount,
    /// h_max: the most expensive goal fact in the delete relaxation. Admissible.
    Max,
    /// h_add: the sum over goal facts in the delete relaxation. Informative, not admissible.
    Add,
}

/// How the search space is explored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Strategy {
    /// Breadth-first: shortest plans.
    BreadthFirst,
    /// A*: `f = g + h`; shortest plans with an admissible heuristic.
    AStar(Heuristic),
    /// Greedy best-first: `f = h`; fast, not necessarily shortest.
    Greedy(Heuristic),
}

/// Why no plan was found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum PlanningError {
    /// Every reachable state was explored: no plan exists.
    Unsolvable {
        /// Nodes expanded.
        expanded: u32,
    },
    /// The node budget ran out before a plan was found.
    Budget {
        /// Nodes expanded.
        expanded: u32,
        /// The budget.
        limit: u32,
    },
    /// A plan exists but is longer than a plan body can hold.
    TooLong {
        /// The most actions a body holds.
        limit: u32,
    },
    /// More actions than an [`ActionId`] can index (refused rather than wrapped).
    TooManyActions {
        /// The most actions a search takes ([`MAX_ACTIONS`]).
        limit: u32,
    },
}

impl core::fmt::Display for PlanningError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Unsolvable { expanded } => {
                write!(f, "no plan exists ({expanded} states searched)")
            }
            Self::Budget { limit, .. } => write!(f, "none found within {limit} nodes"),
            Self::TooLong { limit } => {
                write!(f, "the shortest plan is longer than {limit} actions")
            }
            Self::TooManyActions { limit } => {
                write!(f, "more than {limit} actions, the most a search takes")
            }
        }
    }
}

impl core::error::Error for PlanningError {}

/// A plan and what finding it cost.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Found<const L: usize> {
    /// The actions, in order.
    pub body: Vec<ActionId, L>,
    /// Nodes expanded.
    pub expanded: u32,
    /// Nodes generated.
    pub generated: u32,
}

const NONE: u32 = u32::MAX;
const INFINITE: u32 = u32::MAX;

/// `8 · W + 8` bytes: node and action indices as wide as their capacities (`u32` nodes, [`ActionId`]'s
/// 16 bits), never truncated.
#[derive(Clone, Copy)]
struct Node<const W: usize> {
    state: FactSetOf<W>,
    parent: u32,
    action: u16,
    g: u16,
}

/// A forward planner with room for `N` search nodes over fact sets of `W` words (one by
/// default: 64 facts).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Planner<const N: usize, const W: usize = 1> {
    /// How to search.
    pub strategy: Strategy,
    /// Most nodes to generate, set per call; capped at 7/8 of `N` ([`Planner::capacity`]).
    pub budget: u32,
}

impl<const N: usize, const W: usize> Default for Planner<N, W> {
    fn default() -> Self {
        Self {
            strategy: Strategy::BreadthFirst,
            budget: u32::MAX,
        }
    }
}

/// Visited states: open addressing over `N` slots holding node index + 1. At most 7/8 of `N`
/// nodes are ever stored, so a probe always ends at a free slot, and soon: linear probing
/// slows down sharply as a table fills (a lookup in a full one scans it all).
struct Visited<const N: usize> {
    slots: [u32; N],
}

impl<const N: usize> Visited<N> {
    fn start<const W: usize>(state: FactSetOf<W>) -> usize {
        // A word at a time, then splitmix64's finaliser: every bit of every word reaches the
        // low bits the remainder keeps. (A multiply alone moves bits only upwards, so with
        // `N` a power of two the top 12 bits of the last word, facts 244-255 of four words,
        // never reached the slot: states differing only there all probed one run.)
        let mut h = state.words().iter().fold(0u64, |h, w| {
            (h.rotate_left(5) ^ w).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        });
        h = (h ^ (h >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        h = (h ^ (h >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        h ^= h >> 31;
        (h as usize).checked_rem(N).unwrap_or(0)
    }

    /// The node holding `state`, or the free slot where it would go.
    fn find<const W: usize>(&self, arena: &[Node<W>], state: FactSetOf<W>) -> (usize, Option<u32>) {
        let mut slot = Self::start(state);
        for _ in 0..N {
            match self.slots.get(slot).copied() {
                Some(0) | None => return (slot, None),
                Some(i) => {
                    let index = i.wrapping_sub(1);
                    if arena.get(index as usize).is_some_and(|n| n.state == state) {
                        return (slot, Some(index));
                    }
                }
            }
            slot = slot.wrapping_add(1).checked_rem(N).unwrap_or(0);
        }
        (slot, None)
    }

    fn set(&mut self, slot: usize, node: u32) {
        if let Some(s) = self.slots.get_mut(slot) {
            *s = node.wrapping_add(1);
        }
    }

    /// Empties the slots of `arena`'s states, in O(arena + slots used) rather than O(N).
    /// Every used slot lies on the probe run from some stored state's start slot, and each
    /// walk clears to the end of its run, so no used slot is left behind.
    fn clear<const W: usize>(&mut self, arena: &[Node<W>]) {
        for node in arena {
            let mut slot = Self::start(node.state);
            for _ in 0..N {
                match self.slots.get_mut(slot) {
                    Some(s) if *s != 0 => *s = 0,
                    _ => break,
                }
                slot = slot.wrapping_add(1).checked_rem(N).unwrap_or(0);
            }
        }
    }
}

/// The relaxed cost of fact `f`, kept 64 to a word of the fact sets.
fn cost_of<const W: usize>(cost: &[[u32; 64]; W], f: FactId) -> u32 {
    cost.get(f.index() >> 6)
        .and_then(|c| c.get(f.index() & 63))
        .copied()
        .unwrap_or(INFINITE)
}

fn cost_mut<const W: usize>(cost: &mut [[u32; 64]; W], f: FactId) -> Option<&mut u32> {
    cost.get_mut(f.index() >> 6)?.get_mut(f.index() & 63)
}

/// Relaxed (delete-free) cost of reaching `goal` from `state`: the max or the sum over goal
/// facts of their h_max / h_add cost. [`INFINITE`] when some goal fact is unreachable.
fn relaxed<const W: usize>(
    actions: &[ActuatorAction<'_, W>],
    state: FactSetOf<W>,
    goal: FactSetOf<W>,
    sum: bool,
) -> u32 {
    // A cost per fact, 64 to a word of the fact sets.
    let mut cost = [[INFINITE; 64]; W];
    for f in state.iter() {
        if let Some(c) = cost_mut(&mut cost, f) {
            *c = 0;
        }
    }
    let combine = |acc: u32, c: u32| {
        if sum {
            acc.saturating_add(c)
        } else {
            acc.max(c)
        }
    };
    // Bellman-Ford style: at most one round per fact until nothing improves.
    for _ in 0..=FactSetOf::<W>::CAPACITY {
        let mut changed = false;
        for a in actions {
            let pre = a.pre.iter().map(|f| cost_of(&cost, f)).fold(0, combine);
            if pre == INFINITE {
                continue;
            }
            let through = pre.saturating_add(1);
            for f in a.add.iter() {
                if let Some(c) = cost_mut(&mut cost, f)
                    && through < *c
                {
                    *c = through;
                    changed = true;
                }
            }
        }
        if !changed {
            break;
        }
    }
    goal.iter().map(|f| cost_of(&cost, f)).fold(0, combine)
}

fn estimate<const W: usize>(
    h: Heuristic,
    actions: &[ActuatorAction<'_, W>],
    state: FactSetOf<W>,
    goal: FactSetOf<W>,
) -> u32 {
    match h {
        Heuristic::GoalCount => goal.difference(state).len() as u32,
        Heuristic::Max => relaxed(actions, state, goal, false),
        Heuristic::Add => relaxed(actions, state, goal, true),
    }
}

impl<const N: usize, const W: usize> Planner<N, W> {
    /// A planner with `strategy` and the largest budget its capacity allows.
    pub const fn new(strategy: Strategy) -> Self {
        Self {
            strategy,
            budget: u32::MAX,
        }
    }

    /// The most nodes a search in `N` nodes of space generates: 7/8 of `N` (less one), so
    /// that the visited table never fills up.
    pub const fn capacity() -> u32 {
        let c = N.saturating_sub(N / 8).saturating_sub(1);
        if c < (NONE - 1) as usize {
            c as u32
        } else {
            NONE - 1
        }
    }

    fn limit(&self) -> u32 {
        self.budget.min(Self::capacity())
    }

    /// Searches a plan from `init` to a state where `goal` holds, with actions indexed by their
    /// [`ActionId`], to the end. The plan is at most `L` actions long. The search space is on
    /// this call's stack; [`Search`] runs the same search in slices, in space the caller keeps.
    pub fn plan<const L: usize>(
        &self,
        actions: &[ActuatorAction<'_, W>],
        init: FactSetOf<W>,
        goal: FactSetOf<W>,
    ) -> Result<Found<L>, PlanningError> {
        let mut search = Search::<N, W>::new();
        search.start(self, actions, init, goal);
        loop {
            if let Some(result) = search.step(actions, u32::MAX) {
                return result;
            }
        }
    }
}

/// The space of one search, run in slices: `N` nodes of `8 · W + 8` bytes, a visited table of
/// `N` 4-byte slots and an open list of `N` 12-byte entries (`32 · N` bytes for one-word fact
/// sets), wherever the caller keeps it (a `static` on a microcontroller). [`start`](Self::start) sets a search up in place,
/// [`step`](Self::step) runs it a slice at a time: between two slices the caller may yield, so
/// that a search never holds a cooperative executor for longer than one slice.
pub struct Search<const N: usize, const W: usize = 1> {
    strategy: Strategy,
    limit: u32,
    goal: FactSetOf<W>,
    arena: Vec<Node<W>, N>,
    visited: Visited<N>,
    open: BinaryHeap<(u32, u32, u32), Min, N>,
    /// Breadth-first: the next node to expand.
    head: usize,
    expanded: u32,
    /// Decided before any expansion: the plan ends at this node, or there is none.
    early: Option<Result<usize, PlanningError>>,
}

impl<const N: usize, const W: usize> Default for Search<N, W> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize, const W: usize> Search<N, W> {
    /// An empty search space; usable in a `static`.
    pub const fn new() -> Self {
        Self {
            strategy: Strategy::BreadthFirst,
            limit: 0,
            goal: FactSetOf::EMPTY,
            arena: Vec::new(),
            visited: Visited { slots: [0; N] },
            open: BinaryHeap::new(),
            head: 0,
            expanded: 0,
            early: Some(Err(PlanningError::Unsolvable { expanded: 0 })),
        }
    }

    /// Sets up `planner`'s search from `init` to a state where `goal` holds over `actions`, in
    /// place: O(nodes the last search used) to clear the space, not O(N), and O(NA · |facts|)
    /// for a heuristic's first estimate.
    pub fn start<const P: usize>(
        &mut self,
        planner: &Planner<P, W>,
        actions: &[ActuatorAction<'_, W>],
        init: FactSetOf<W>,
        goal: FactSetOf<W>,
    ) {
        self.strategy = planner.strategy;
        self.limit = planner
            .budget
            .min(Planner::<N, W>::new(planner.strategy).limit());
        self.goal = goal;
        self.visited.clear(&self.arena);
        self.arena.clear();
        self.open.clear();
        self.head = 0;
        self.expanded = 0;
        self.early = None;
        let root = Node {
            state: init,
            parent: NONE,
            action: 0,
            g: 0,
        };
        if actions.len() > MAX_ACTIONS {
            self.early = Some(Err(PlanningError::TooManyActions {
                limit: MAX_ACTIONS as u32,
            }));
            return;
        }
        if self.limit == 0 || self.arena.push(root).is_err() {
            self.early = Some(Err(PlanningError::Budget {
                expanded: 0,
                limit: self.limit,
            }));
            return;
        }
        let (slot, _) = self.visited.find(&self.arena, init);
        self.visited.set(slot, 0);
        if goal.is_subset(init) {
            self.early = Some(Ok(0));
            return;
        }
        if let Some(h) = self.heuristic() {
            let h0 = estimate(h, actions, init, goal);
            if h0 == INFINITE {
                self.early = Some(Err(PlanningError::Unsolvable { expanded: 0 }));
                return;
            }
            let _ = self.open.push((self.score(0, h0), h0, 0));
        }
    }

    fn heuristic(&self) -> Option<Heuristic> {
        match self.strategy {
            Strategy::BreadthFirst => None,
            Strategy::AStar(h) | Strategy::Greedy(h) => Some(h),
        }
    }

    fn score(&self, g: u16, h: u32) -> u32 {
        match self.strategy {
            Strategy::Greedy(_) => h,
            _ => u32::from(g).saturating_add(h),
        }
    }

    /// Nodes expanded so far.
    pub fn expanded(&self) -> u32 {
        self.expanded
    }

    /// Takes at most `slice` nodes from the open list and expands them, with the same
    /// `actions` the search started with; `None` while the search goes on, else the plan (at
    /// most `L` actions) or why there is none. Each node costs O(NA) set operations plus, for
    /// heuristic search, O(NA · |facts|) per generated node.
    pub fn step<const L: usize>(
        &mut self,
        actions: &[ActuatorAction<'_, W>],
        slice: u32,
    ) -> Option<Result<Found<L>, PlanningError>> {
        self.step_until(actions, slice, || false)
    }

    /// [`Search::step`], asking `out_of_time` before each node it takes and each node it
    /// generates (a heuristic's estimate is the costly part): when it answers `true`, the
    /// search ends with [`PlanningError::Budget`]. A tool bounds its wall time with it; a
    /// robot bounds its slices by `slice`.
    pub fn step_until<const L: usize>(
        &mut self,
        actions: &[ActuatorAction<'_, W>],
        slice: u32,
        mut out_of_time: impl FnMut() -> bool,
    ) -> Option<Result<Found<L>, PlanningError>> {
        if let Some(early) = self.early {
            return Some(early.and_then(|node| extract(&self.arena, node, self.expanded)));
        }
        let (goal, limit, heuristic) = (self.goal, self.limit, self.heuristic());
        let mut taken = 0u32;
        loop {
            if taken >= slice {
                return None;
            }
            taken = taken.saturating_add(1);
            let expanded = self.expanded;
            if out_of_time() {
                return Some(Err(PlanningError::Budget { expanded, limit }));
            }
            // Next node: FIFO order for breadth-first, lowest (f, h, index) otherwise.
            let index = match heuristic {
                None => {
                    if self.head >= self.arena.len() {
                        return Some(Err(PlanningError::Unsolvable { expanded }));
                    }
                    self.head = self.head.saturating_add(1);
                    self.head.saturating_sub(1)
                }
                Some(_) => match self.open.pop() {
                    Some((_, _, i)) => i as usize,
                    None => return Some(Err(PlanningError::Unsolvable { expanded })),
                },
            };
            let Some(node) = self.arena.get(index).copied() else {
                return Some(Err(PlanningError::Unsolvable { expanded }));
            };
            // A cheaper path to this state was found after it was queued: skip the stale entry.
            if heuristic.is_some()
                && self.visited.find(&self.arena, node.state).1 != Some(index as u32)
            {
                continue;
            }
            if heuristic.is_some() && goal.is_subset(node.state) {
                return Some(extract(&self.arena, index, expanded));
            }
            self.expanded = expanded.saturating_add(1);
            let expanded = self.expanded;
            for (a, action) in actions.iter().enumerate() {
                if !action.pre.is_subset(node.state) {
                    continue;
                }
                let state = node.state.apply(action.add, action.del);
                let g = node.g.saturating_add(1);
                let (slot, known) = self.visited.find(&self.arena, state);
                if let Some(k) = known {
                    // Seen at least as cheaply: nothing new.
                    if self.arena.get(k as usize).is_some_and(|n| n.g <= g) {
                        continue;
                    }
                }
                let h = match heuristic {
                    Some(h) => {
                        if out_of_time() {
                            return Some(Err(PlanningError::Budget { expanded, limit }));
                        }
                        let h = estimate(h, actions, state, goal);
                        if h == INFINITE {
                            continue;
                        }
                        h
                    }
                    None => 0,
                };
                // At most `limit` nodes, the start included.
                if self.arena.len() as u32 >= limit {
                    return Some(Err(PlanningError::Budget { expanded, limit }));
                }
                // Both fit: the arena holds fewer than `NONE` nodes, and `start` refused more
                // actions than an `ActionId` indexes.
                let child = self.arena.len() as u32;
                let pushed = self.arena.push(Node {
                    state,
                    parent: index as u32,
                    action: a as u16,
                    g,
                });
                if pushed.is_err() {
                    return Some(Err(PlanningError::Budget { expanded, limit }));
                }
                self.visited.set(slot, child);
                if heuristic.is_none() && goal.is_subset(state) {
                    // Breadth-first: the first goal generated is at the least depth.
                    return Some(extract(&self.arena, child as usize, expanded));
                }
                let score = self.score(g, h);
                if heuristic.is_some() && self.open.push((score, h, child)).is_err() {
                    return Some(Err(PlanningError::Budget { expanded, limit }));
                }
            }
        }
    }
}

/// The plan that ends at node `goal`: the actions on the path from the root, in order.
fn extract<const L: usize, const W: usize>(
    arena: &[Node<W>],
    goal: usize,
    expanded: u32,
) -> Result<Found<L>, PlanningError> {
    let too_long = PlanningError::TooLong { limit: L as u32 };
    let mut body: Vec<ActionId, L> = Vec::new();
    let mut at = goal;
    while let Some(node) = arena.get(at) {
        if node.parent == NONE {
            break;
        }
        body.push(ActionId::new(usize::from(node.action)).ok_or(too_long)?)
            .map_err(|_| too_long)?;
        at = node.parent as usize;
    }
    body.reverse();
    Ok(Found {
        body,
        expanded,
        generated: arena.len() as u32,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::domain::Domain;
    use crate::facts::FactSet;
    use std::boxed::Box;
    use std::format;
    use std::string::String;
    use std::vec::Vec as StdVec;

    struct Action {
        name: String,
        sets: [StdVec<String>; 3],
    }

    /// A STRIPS domain built from owned names.
    struct Strips {
        facts: StdVec<String>,
        actions: StdVec<Action>,
    }

    impl Strips {
        fn new() -> Self {
            Self {
                facts: StdVec::new(),
                actions: StdVec::new(),
            }
        }
        fn fact(&mut self, f: String) {
            self.facts.push(f);
        }
        fn action(&mut self, name: String, pre: &[&str], add: &[&str], del: &[&str]) {
            let own = |v: &[&str]| v.iter().map(|f| String::from(*f)).collect();
            self.actions.push(Action {
                name,
                sets: [own(pre), own(add), own(del)],
            });
        }
        fn domain(&self) -> Domain<'_, 1, 64> {
            let mut d = Domain::new();
            for f in &self.facts {
                d.add_fact(f).unwrap();
            }
            let names = |d: &Domain<'_, 1, 64>, v: &[String]| {
                let v: StdVec<&str> = v.iter().map(String::as_str).collect();
                d.facts(&v).unwrap()
            };
            for a in &self.actions {
                let [pre, add, del] = &a.sets;
                let a =
                    ActuatorAction::new(&a.name, names(&d, pre), names(&d, add), names(&d, del));
                d.add_action(a).unwrap();
            }
            d
        }
    }

    fn s(v: &str) -> String {
        String::from(v)
    }

    fn blocks(n: usize) -> Strips {
        let names: StdVec<String> = (0..n)
            .map(|i| format!("{}", (b'A' + i as u8) as char))
            .collect();
        let mut w = Strips::new();
        w.fact(s("handempty"));
        for x in &names {
            w.fact(format!("ontable {x}"));
            w.fact(format!("clear {x}"));
            w.fact(format!("holding {x}"));
            for y in &names {
                if x != y {
                    w.fact(format!("on {x} {y}"));
                }
            }
        }
        for x in &names {
            let (ontable, clear, holding) = (
                format!("ontable {x}"),
                format!("clear {x}"),
                format!("holding {x}"),
            );
            w.action(
                format!("pickup {x}"),
                &[clear.as_str(), ontable.as_str(), "handempty"],
                &[holding.as_str()],
                &[ontable.as_str(), clear.as_str(), "handempty"],
            );
            w.action(
                format!("putdown {x}"),
                &[holding.as_str()],
                &[ontable.as_str(), clear.as_str(), "handempty"],
                &[holding.as_str()],
            );
            for y in &names {
                if x == y {
                    continue;
                }
                let (on, clear_y) = (format!("on {x} {y}"), format!("clear {y}"));
                w.action(
                    format!("stack {x} {y}"),
                    &[holding.as_str(), clear_y.as_str()],
                    &[on.as_str(), clear.as_str(), "handempty"],
                    &[holding.as_str(), clear_y.as_str()],
                );
                w.action(
                    format!("unstack {x} {y}"),
                    &[on.as_str(), clear.as_str(), "handempty"],
                    &[holding.as_str(), clear_y.as_str()],
                    &[on.as_str(), clear.as_str(), "handempty"],
                );
            }
        }
        w
    }

    fn gripper(balls: usize) -> Strips {
        let mut w = Strips::new();
        let rooms = ["a", "b"];
        let hands = ["left", "right"];
        for r in rooms {
            w.fact(format!("robby {r}"));
        }
        for h in hands {
            w.fact(format!("free {h}"));
        }
        for b in 0..balls {
            for r in rooms {
                w.fact(format!("at {b} {r}"));
            }
            for h in hands {
                w.fact(format!("carry {b} {h}"));
            }
        }
        for (from, to) in [("a", "b"), ("b", "a")] {
            w.action(
                format!("move {from} {to}"),
                &[format!("robby {from}").as_str()],
                &[format!("robby {to}").as_str()],
                &[format!("robby {from}").as_str()],
            );
        }
        for b in 0..balls {
            for r in rooms {
                for h in hands {
                    let (at, carry, free, robby) = (
                        format!("at {b} {r}"),
                        format!("carry {b} {h}"),
                        format!("free {h}"),
                        format!("robby {r}"),
                    );
                    w.action(
                        format!("pick {b} {r} {h}"),
                        &[at.as_str(), robby.as_str(), free.as_str()],
                        &[carry.as_str()],
                        &[at.as_str(), free.as_str()],
                    );
                    w.action(
                        format!("drop {b} {r} {h}"),
                        &[carry.as_str(), robby.as_str()],
                        &[at.as_str(), free.as_str()],
                        &[carry.as_str()],
                    );
                }
            }
        }
        w
    }

    fn set(d: &Domain<'_, 1, 64>, names: &[&str]) -> FactSet {
        d.facts(names).unwrap()
    }

    const STRATEGIES: [Strategy; 2] = [Strategy::BreadthFirst, Strategy::AStar(Heuristic::Max)];

    /// Runs every optimal strategy and checks the plan length, and that the plan really reaches
    /// the goal when applied step by step.
    fn optimal(d: &Domain<'_, 1, 64>, init: FactSet, goal: FactSet, length: usize) -> [u32; 2] {
        let mut expanded = [0; 2];
        for (i, strategy) in STRATEGIES.into_iter().enumerate() {
            let found = Planner::<4096>::new(strategy)
                .plan::<32>(d.actions(), init, goal)
                .unwrap();
            assert_eq!(found.body.len(), length, "{strategy:?}");
            let end = found.body.iter().fold(init, |state, a| {
                let a = d.action(*a).unwrap();
                assert!(
                    a.pre.is_subset(state),
                    "{strategy:?}: {} not applicable",
                    a.name
                );
                state.apply(a.add, a.del)
            });
            assert!(goal.is_subset(end));
            expanded[i] = found.expanded;
        }
        expanded
    }

    #[test]
    fn sussman_anomaly_takes_six_actions() {
        let w = blocks(3);
        let d = w.domain();
        let init = set(
            &d,
            &[
                "on C A",
                "ontable A",
                "ontable B",
                "clear C",
                "clear B",
                "handempty",
            ],
        );
        let goal = set(&d, &["on A B", "on B C"]);
        optimal(&d, init, goal, 6);
    }

    #[test]
    fn reversing_a_four_block_tower_takes_eight_actions() {
        let w = blocks(4);
        let d = w.domain();
        let init = set(
            &d,
            &[
                "on A B",
                "on B C",
                "on C D",
                "ontable D",
                "clear A",
                "handempty",
            ],
        );
        let goal = set(&d, &["on D C", "on C B", "on B A"]);
        let [bfs, astar] = optimal(&d, init, goal, 8);
        assert!(
            astar < bfs,
            "h_max guides the search: A* {astar} vs breadth-first {bfs} expansions"
        );
        // Greedy h_add finds a plan too, not necessarily a shortest one.
        let greedy = Planner::<4096>::new(Strategy::Greedy(Heuristic::Add))
            .plan::<32>(d.actions(), init, goal)
            .unwrap();
        assert!(greedy.body.len() >= 8);
    }

    #[test]
    fn gripper_with_four_balls_takes_eleven_actions() {
        let w = gripper(4);
        let d = w.domain();
        let init = set(
            &d,
            &[
                "robby a",
                "free left",
                "free right",
                "at 0 a",
                "at 1 a",
                "at 2 a",
                "at 3 a",
            ],
        );
        let goal = set(&d, &["at 0 b", "at 1 b", "at 2 b", "at 3 b"]);
        optimal(&d, init, goal, 11);
    }

    #[test]
    fn fetch_tea_takes_three_actions_by_either_door() {
        let json = include_bytes!("../../missions/fetch-tea.json");
        let m: crate::mission::Loaded<'_, (), (), 4, 8, 2, 4> =
            crate::mission::load(json, &crate::mission::AnyBehaviour).unwrap();
        let d = &m.mission.domain;
        let goal = d.facts(&["in_kitchen"]).unwrap();
        let open = d
            .facts(&["path_clear", "door_unlocked", "handle_seen"])
            .unwrap();
        let found = Planner::<256>::new(Strategy::BreadthFirst)
            .plan::<4>(d.actions(), open, goal)
            .unwrap();
        let names: StdVec<&str> = found
            .body
            .iter()
            .map(|a| d.action(*a).unwrap().name)
            .collect();
        assert_eq!(names, ["go to door", "open door", "enter kitchen"]);
        let locked = d.facts(&["path_clear", "handle_seen"]).unwrap();
        let found = Planner::<256>::new(Strategy::AStar(Heuristic::Max))
            .plan::<4>(d.actions(), locked, goal)
            .unwrap();
        let names: StdVec<&str> = found
            .body
            .iter()
            .map(|a| d.action(*a).unwrap().name)
            .collect();
        assert_eq!(
            names,
            ["go to back door", "open back door", "enter by back door"]
        );
    }

    #[test]
    fn unsolvable_and_too_large_problems_are_errors() {
        let w = blocks(4);
        let d = w.domain();
        let init = set(
            &d,
            &[
                "on A B",
                "on B C",
                "on C D",
                "ontable D",
                "clear A",
                "handempty",
            ],
        );
        // Holding two blocks at once is impossible.
        let impossible = set(&d, &["holding A", "holding B"]);
        assert!(matches!(
            Planner::<4096>::new(Strategy::BreadthFirst).plan::<32>(d.actions(), init, impossible),
            Err(PlanningError::Unsolvable { .. })
        ));
        // h_max sees at once that no action ever adds an unknown goal: nothing is expanded.
        let w2 = blocks(2);
        let d2 = w2.domain();
        let none_adds = FactSet::single(crate::facts::FactId::new(60).unwrap());
        assert_eq!(
            Planner::<64>::new(Strategy::AStar(Heuristic::Max)).plan::<8>(
                d2.actions(),
                FactSet::EMPTY,
                none_adds
            ),
            Err(PlanningError::Unsolvable { expanded: 0 })
        );
        let goal = set(&d, &["on D C", "on C B", "on B A"]);
        let small = Planner::<4096> {
            strategy: Strategy::BreadthFirst,
            budget: 20,
        };
        match small.plan::<32>(d.actions(), init, goal) {
            Err(PlanningError::Budget {
                expanded,
                limit: 20,
            }) => assert!(expanded <= 20),
            other => panic!("expected a budget error, got {other:?}"),
        }
        // Capacity is a budget too: 16 nodes cannot hold the search.
        assert!(matches!(
            Planner::<16>::new(Strategy::AStar(Heuristic::Max)).plan::<32>(d.actions(), init, goal),
            Err(PlanningError::Budget { limit: 13, .. })
        ));
        // A plan longer than the body capacity.
        assert_eq!(
            Planner::<4096>::new(Strategy::BreadthFirst)
                .plan::<4>(d.actions(), init, goal)
                .map(|f| f.body.len()),
            Err(PlanningError::TooLong { limit: 4 })
        );
    }

    /// The budget counts every node generated, the start included: a one-action plan needs two.
    #[test]
    fn a_budget_of_n_nodes_generates_at_most_n() {
        let mut d: Domain<'_, 1, 64> = Domain::new();
        let a = d.add_fact("a").unwrap();
        d.add_action(ActuatorAction::new(
            "make a",
            FactSet::EMPTY,
            FactSet::single(a),
            FactSet::EMPTY,
        ))
        .unwrap();
        let with = |budget| Planner::<64> {
            strategy: Strategy::BreadthFirst,
            budget,
        };
        let goal = FactSet::single(a);
        assert!(matches!(
            with(1).plan::<4>(d.actions(), FactSet::EMPTY, goal),
            Err(PlanningError::Budget { limit: 1, .. })
        ));
        assert_eq!(
            with(2)
                .plan::<4>(d.actions(), FactSet::EMPTY, goal)
                .map(|f| f.body.len()),
            Ok(1)
        );
    }

    /// A search run in slices of one node finds what one call finds, over as many calls as it
    /// takes nodes: a cooperative executor gets its turn back after every node.
    #[test]
    fn a_search_in_slices_finds_the_same_plan_one_node_at_a_time() {
        let w = blocks(4);
        let d = w.domain();
        let init = set(
            &d,
            &[
                "handempty",
                "ontable A",
                "on B A",
                "on C B",
                "on D C",
                "clear D",
            ],
        );
        let goal = set(&d, &["ontable D", "on C D", "on B C", "on A B"]);
        for strategy in STRATEGIES {
            let planner = Planner::<4096>::new(strategy);
            let whole = planner.plan::<32>(d.actions(), init, goal).unwrap();
            let mut search: Box<Search<4096>> = Box::default();
            search.start(&planner, d.actions(), init, goal);
            let mut calls = 1;
            let sliced = loop {
                if let Some(result) = search.step::<32>(d.actions(), 1) {
                    break result.unwrap();
                }
                calls += 1;
            };
            assert_eq!(sliced, whole, "{strategy:?}");
            // Every node taken was one call; the problem is not trivial.
            assert!(calls >= whole.expanded, "{strategy:?}: {calls} calls");
            assert!(
                whole.expanded >= 10,
                "{strategy:?}: {} nodes",
                whole.expanded
            );
        }
        // A search decided before any node (the goal holds already) answers at the first call.
        let mut done = Search::<16>::new();
        done.start(
            &Planner::<16>::new(Strategy::BreadthFirst),
            d.actions(),
            goal,
            goal,
        );
        assert_eq!(
            done.step::<32>(d.actions(), 1)
                .map(|r| r.map(|f| f.body.len())),
            Some(Ok(0))
        );
    }

    #[test]
    fn an_empty_goal_needs_no_action() {
        let w = blocks(2);
        let d = w.domain();
        let found = Planner::<8>::default()
            .plan::<2>(d.actions(), FactSet::EMPTY, FactSet::EMPTY)
            .unwrap();
        assert!(found.body.is_empty());
    }

    /// A chain of `steps` facts (`f0 -> f1 -> ...`) among `total` actions: the step actions
    /// sit at the given indices, every other action adds a fact nothing needs.
    fn chain(total: usize, at: &[usize]) -> StdVec<ActuatorAction<'static>> {
        let f = |i: usize| FactSet::single(crate::facts::FactId::new(i).unwrap());
        let mut actions: StdVec<ActuatorAction<'static>> = (0..total)
            .map(|i| ActuatorAction::new("noise", f(0), f(63 - i % 8), FactSet::EMPTY))
            .collect();
        for (step, &index) in at.iter().enumerate() {
            actions[index] = ActuatorAction::new("step", f(step), f(step + 1), FactSet::EMPTY);
        }
        actions
    }

    /// A plan as action indices, checked step by step from `init` to `goal`.
    fn replay(actions: &[ActuatorAction<'_>], body: &[ActionId], init: FactSet) -> FactSet {
        body.iter().fold(init, |state, id| {
            let a = &actions[id.index()];
            assert!(
                a.pre.is_subset(state),
                "action {} not applicable",
                id.index()
            );
            state.apply(a.add, a.del)
        })
    }

    #[test]
    fn actions_past_256_are_planned_with_their_own_ids() {
        // 600 actions; the plan needs 257, 329 and 566 (once truncated to 1, 73 and 54).
        let at = [257, 329, 566];
        let actions = chain(600, &at);
        let f = |i: usize| FactSet::single(crate::facts::FactId::new(i).unwrap());
        for strategy in [
            Strategy::BreadthFirst,
            Strategy::AStar(Heuristic::Max),
            Strategy::AStar(Heuristic::Add),
            Strategy::Greedy(Heuristic::Add),
            Strategy::AStar(Heuristic::GoalCount),
        ] {
            let found = Planner::<4096>::new(strategy)
                .plan::<8>(&actions, f(0), f(3))
                .unwrap();
            let ids: StdVec<usize> = found.body.iter().map(|a| a.index()).collect();
            assert_eq!(ids, at, "{strategy:?}");
            assert!(f(3).is_subset(replay(&actions, &found.body, f(0))));
        }
    }

    #[test]
    fn more_actions_than_an_id_indexes_are_refused() {
        let actions = chain(crate::action::MAX_ACTIONS + 1, &[]);
        let f = |i: usize| FactSet::single(crate::facts::FactId::new(i).unwrap());
        assert_eq!(
            Planner::<16>::default().plan::<4>(&actions, f(0), f(1)),
            Err(PlanningError::TooManyActions {
                limit: crate::action::MAX_ACTIONS as u32
            })
        );
    }

    #[test]
    fn a_search_past_16_bit_node_indices_finds_its_plan() {
        // 17 independent facts, each set by its own action, the goal all of them: breadth-first
        // generates about 2^17 = 131,072 states, past the old 65,534-node cap.
        let f = |i: usize| FactSet::single(crate::facts::FactId::new(i).unwrap());
        let actions: StdVec<ActuatorAction<'static>> = (0..17)
            .map(|i| ActuatorAction::new("set", FactSet::EMPTY, f(i), FactSet::EMPTY))
            .collect();
        let goal = (0..17).fold(FactSet::EMPTY, |g, i| g.union(f(i)));
        // The space is large (about 6 MB): built on a thread with room for it.
        let run = move || {
            let mut search = Search::<200_000>::new();
            let planner = Planner::<200_000>::new(Strategy::BreadthFirst);
            let mut solve = |init: FactSet, goal: FactSet| {
                search.start(&planner, &actions, init, goal);
                loop {
                    if let Some(r) = search.step::<32>(&actions, u32::MAX) {
                        break r;
                    }
                }
            };
            let big = solve(FactSet::EMPTY, goal).unwrap();
            // The same space reused for a small search: cleared, and right.
            let small = solve(f(0), f(0).union(f(1))).unwrap();
            (big, small)
        };
        let (big, small) = std::thread::Builder::new()
            .stack_size(64 << 20)
            .spawn(run)
            .unwrap()
            .join()
            .unwrap();
        assert_eq!(big.body.len(), 17);
        assert!(big.generated > 65_535, "{} nodes", big.generated);
        assert_eq!(small.body.len(), 1);
    }

    #[test]
    fn a_search_space_costs_32_bytes_a_node() {
        // What docs/guide.md states for RAM: nodes 16 B, visited slot 4 B, open entry 12 B.
        assert_eq!(core::mem::size_of::<Search<1024>>(), 32 * 1024 + 64);
    }

    /// Every fact moves a state's slot: 4,096 states differing only in the last 12 facts of
    /// four words, or of one, spread over a table of 2^20 slots as random keys would (about 8
    /// collisions expected); the old hash put each group on one slot.
    #[test]
    fn every_fact_reaches_the_visited_slot() {
        fn spread<const W: usize>(first: usize) -> usize {
            let mut slots: std::vec::Vec<usize> = (0..4096u64)
                .map(|bits| {
                    let facts = (0..12)
                        .filter(|b| bits & (1 << b) != 0)
                        .filter_map(|b| FactId::within(first + b, 64 * W));
                    Visited::<{ 1 << 20 }>::start(facts.collect::<FactSetOf<W>>())
                })
                .collect();
            slots.sort_unstable();
            slots.dedup();
            slots.len()
        }
        assert!(spread::<4>(244) > 4_050, "facts 244-255 of four words");
        assert!(spread::<1>(52) > 4_050, "facts 52-63 of one word");
        assert!(spread::<1>(0) > 4_050, "facts 0-11 of one word");
    }

    /// A planning error reads as words, not as the program's type (`Unsolvable { expanded:
    /// 1 }` reached the runtime's messages).
    #[test]
    fn planning_errors_read_as_words() {
        use std::string::ToString;
        assert_eq!(
            PlanningError::Unsolvable { expanded: 1 }.to_string(),
            "no plan exists (1 states searched)"
        );
        assert_eq!(
            PlanningError::Budget {
                expanded: 3,
                limit: 9
            }
            .to_string(),
            "none found within 9 nodes"
        );
    }
}

//! Primitive behaviours (paper §4.2): sensor-based actions `s = <pre(s), per(s)>` and
//! actuator-based actions `a = <pre(a), add(a), del(a)>`.

use core::fmt;

use embassy_time::Duration;

use crate::facts::FactSetOf;

/// Most sensor-based actions a domain can hold: the width of a [`SensorSet`].
pub const MAX_SENSORS: usize = 32;

/// Index of a sensor-based action in its domain, `0..MAX_SENSORS`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SensorId(u8);

impl SensorId {
    /// The sensor of index `I`, checked when the program is built: an index out of range
    /// fails the build, never a run (the ids of a mission compiled in with `include_mission!`).
    pub const fn of<const I: usize>() -> Self {
        const {
            // Evaluated at compile time only.
            #[allow(clippy::panic)]
            match Self::new(I) {
                Some(id) => id,
                None => panic!("sensor index out of range"),
            }
        }
    }

    /// The sensor with index `index`, or `None` when `index >= MAX_SENSORS`.
    pub const fn new(index: usize) -> Option<Self> {
        if index < MAX_SENSORS {
            Some(Self(index as u8))
        } else {
            None
        }
    }

    /// The index of this sensor in its domain.
    pub const fn index(self) -> usize {
        self.0 as usize
    }
}

/// How many actuator-based actions a domain can index: an [`ActionId`] is 16 bits.
pub const MAX_ACTIONS: usize = 1 << 16;

/// Index of an actuator-based action in its domain, `0..MAX_ACTIONS`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ActionId(u16);

impl ActionId {
    /// The action of index `I`, checked when the program is built: an index out of range
    /// fails the build, never a run (the ids of a mission compiled in with `include_mission!`).
    pub const fn of<const I: usize>() -> Self {
        const {
            // Evaluated at compile time only.
            #[allow(clippy::panic)]
            match Self::new(I) {
                Some(id) => id,
                None => panic!("action index out of range"),
            }
        }
    }

    /// The action with index `index`, or `None` when `index >= MAX_ACTIONS`.
    pub const fn new(index: usize) -> Option<Self> {
        if index < MAX_ACTIONS {
            Some(Self(index as u16))
        } else {
            None
        }
    }

    /// The index of this action in its domain.
    pub const fn index(self) -> usize {
        self.0 as usize
    }
}

/// A set of sensors: the sensors running beside one action state (Algorithm 2).
#[derive(Clone, Copy, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SensorSet(u32);

impl SensorSet {
    /// No sensor.
    pub const EMPTY: Self = Self(0);

    /// The set whose members are the set bits of `bits`.
    pub const fn from_bits(bits: u32) -> Self {
        Self(bits)
    }

    /// The raw bits (bit `i` is sensor `i`).
    pub const fn bits(self) -> u32 {
        self.0
    }

    /// Whether no sensor is in the set.
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// Number of sensors in the set.
    pub const fn len(self) -> usize {
        self.0.count_ones() as usize
    }

    /// Whether `sensor` is in the set.
    pub const fn contains(self, sensor: SensorId) -> bool {
        self.0 & (1u32 << sensor.0) != 0
    }

    /// The set with `sensor` added.
    #[must_use]
    pub const fn with(self, sensor: SensorId) -> Self {
        Self(self.0 | (1u32 << sensor.0))
    }

    /// The set with `sensor` removed.
    #[must_use]
    pub const fn without(self, sensor: SensorId) -> Self {
        Self(self.0 & !(1u32 << sensor.0))
    }

    /// The sensors in either set.
    #[must_use]
    pub const fn union(self, other: Self) -> Self {
        Self(self.0 | other.0)
    }

    /// The sensors in both sets.
    #[must_use]
    pub const fn intersection(self, other: Self) -> Self {
        Self(self.0 & other.0)
    }

    /// Whether the two sets share a sensor.
    pub const fn intersects(self, other: Self) -> bool {
        self.0 & other.0 != 0
    }

    /// The sensors in increasing id order.
    pub fn iter(self) -> impl ExactSizeIterator<Item = SensorId> + Clone {
        SensorIter(self.0)
    }
}

impl fmt::Debug for SensorSet {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_set()
            .entries(self.iter().map(SensorId::index))
            .finish()
    }
}

impl FromIterator<SensorId> for SensorSet {
    fn from_iter<I: IntoIterator<Item = SensorId>>(iter: I) -> Self {
        iter.into_iter().fold(Self::EMPTY, Self::with)
    }
}

#[derive(Clone)]
struct SensorIter(u32);

impl Iterator for SensorIter {
    type Item = SensorId;

    fn next(&mut self) -> Option<SensorId> {
        if self.0 == 0 {
            return None;
        }
        let index = self.0.trailing_zeros();
        self.0 &= self.0.wrapping_sub(1);
        Some(SensorId(index as u8))
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let n = self.0.count_ones() as usize;
        (n, Some(n))
    }
}

impl ExactSizeIterator for SensorIter {}

/// How a sensor runs while it is switched on (paper §4.1, "multi-mode").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SensorMode {
    /// Sampled every `period` (a sonar, a bumper).
    Cyclic {
        /// Time between two samples.
        period: Duration,
    },
    /// Sampled once when switched on (a camera taking one image).
    OneShot,
    /// Sampled only when the running behaviour asks for it
    /// (`ActionIo::request` in psmpa-core).
    OnDemand,
}

/// A sensor-based action `s = <pre(s), per(s)>`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SensorAction<'a, const W: usize = 1> {
    /// Name, as missions and traces call it.
    pub name: &'a str,
    /// `pre(s)`: facts that must hold for the sensor to be switched on.
    pub pre: FactSetOf<W>,
    /// `per(s)`: the facts this sensor's samples decide.
    pub per: FactSetOf<W>,
    /// Cyclic, one-shot or on demand.
    pub mode: SensorMode,
    /// A sample that takes longer than this is a `SensorFault::Timeout` (psmpa-core).
    pub timeout: Duration,
}

impl<'a, const W: usize> SensorAction<'a, W> {
    /// Default time a sample may take before the sensor counts as not answering.
    pub const DEFAULT_TIMEOUT: Duration = Duration::from_millis(500);

    /// A sensor with no precondition and the default timeout.
    pub const fn new(name: &'a str, per: FactSetOf<W>, mode: SensorMode) -> Self {
        Self {
            name,
            pre: FactSetOf::EMPTY,
            per,
            mode,
            timeout: Self::DEFAULT_TIMEOUT,
        }
    }

    /// The same sensor with precondition `pre(s)`.
    #[must_use]
    pub const fn with_pre(mut self, pre: FactSetOf<W>) -> Self {
        self.pre = pre;
        self
    }

    /// The same sensor with another sample timeout.
    #[must_use]
    pub const fn with_timeout(mut self, timeout: Duration) -> Self {
        self.timeout = timeout;
        self
    }

    /// Algorithm 2 line 11: this sensor runs beside an action whose precondition is `pre`
    /// when it perceives something and `per(s) ⊆ pre(a)`.
    pub const fn serves(&self, pre: FactSetOf<W>) -> bool {
        !self.per.is_empty() && self.per.is_subset(pre)
    }
}

/// Algorithm 2 line 11 over a table of sensors by id: the sensors `s` with `per(s) ⊆ pre`
/// (and `per(s) ≠ ∅`). O(NS).
#[inline]
pub fn sensors_serving<const W: usize>(
    sensors: &[SensorAction<'_, W>],
    pre: FactSetOf<W>,
) -> SensorSet {
    sensors
        .iter()
        .enumerate()
        .filter(|(_, s)| s.serves(pre))
        .filter_map(|(i, _)| SensorId::new(i))
        .collect()
}

/// `∪ per(s)` over the sensors `set` of a table of sensors by id: the facts they decide while
/// running. O(NS).
#[inline]
pub fn perception_of<const W: usize>(
    sensors: &[SensorAction<'_, W>],
    set: SensorSet,
) -> FactSetOf<W> {
    set.iter()
        .filter_map(|s| sensors.get(s.index()))
        .fold(FactSetOf::EMPTY, |acc, s| acc.union(s.per))
}

/// An actuator-based action `a = <pre(a), add(a), del(a)>`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ActuatorAction<'a, const W: usize = 1> {
    /// Name, as missions and traces call it.
    pub name: &'a str,
    /// `pre(a)`: facts that must hold while the action runs.
    pub pre: FactSetOf<W>,
    /// `add(a)`: facts the action makes true.
    pub add: FactSetOf<W>,
    /// `del(a)`: facts the action makes false.
    pub del: FactSetOf<W>,
    /// How long `pre(a)` may stay false while the action runs before the runtime stops it;
    /// `None`: the runtime's `Config::max_violation` (psmpa-core).
    /// A robot at a cliff's edge stops at once (zero); one before a box may wait for it.
    /// Zero fails the action at its start when a fact of `pre(a)` that only an on-demand
    /// sensor perceives is still believed false, before the behaviour could ask for it.
    /// A tolerance of its own above zero also lets the action *start* while a fact of
    /// `pre(a)` is known false ([`may_start_violated`](Self::may_start_violated)).
    pub max_violation: Option<Duration>,
}

impl<'a, const W: usize> ActuatorAction<'a, W> {
    /// An action from its STRIPS sets.
    pub const fn new(
        name: &'a str,
        pre: FactSetOf<W>,
        add: FactSetOf<W>,
        del: FactSetOf<W>,
    ) -> Self {
        Self {
            name,
            pre,
            add,
            del,
            max_violation: None,
        }
    }

    /// The same action with its own tolerance for a false precondition.
    #[must_use]
    pub const fn with_max_violation(mut self, max_violation: Duration) -> Self {
        self.max_violation = Some(max_violation);
        self
    }

    /// Whether the action may start while a fact of `pre(a)` is known false: only if it sets
    /// its own `max_violation` above zero. It then rides the violation out from its start as
    /// it would one that arises while it runs (a walk that side-steps a box already in front
    /// of it). An action that relies on the runtime's default is not started on a
    /// precondition known false: selection passes over its plan.
    pub const fn may_start_violated(&self) -> bool {
        match self.max_violation {
            Some(max) => max.as_ticks() > 0,
            None => false,
        }
    }
}

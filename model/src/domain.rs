//! The planning domain `Δ`: the names of facts and events, the sensor-based actions `S` and
//! the actuator-based actions `A` (paper §4.2).
//!
//! Names are resolved to small integer ids once, when the domain is built; everything that
//! runs afterwards works on ids. Lookups by name are linear in the table size and meant for
//! load time only.

use heapless::Vec;

use crate::action::{
    ActionId, ActuatorAction, MAX_SENSORS, SensorAction, SensorId, SensorMode, SensorSet,
};
use crate::facts::{FactId, FactSetOf, MAX_FACTS};

/// Most trigger events a domain can name.
pub const MAX_EVENTS: usize = 16;

/// Index of a trigger event (the invocation `t(p)` of a plan).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EventId(u8);

impl EventId {
    /// The event of index `I`, checked when the program is built: an index out of range
    /// fails the build, never a run (the ids of a mission compiled in with `include_mission!`).
    pub const fn of<const I: usize>() -> Self {
        const {
            // Evaluated at compile time only.
            #[allow(clippy::panic)]
            match Self::new(I) {
                Some(id) => id,
                None => panic!("event index out of range"),
            }
        }
    }

    /// The first event of a domain.
    pub const FIRST: Self = Self(0);

    /// The event with index `index`, or `None` when `index >= MAX_EVENTS`.
    pub const fn new(index: usize) -> Option<Self> {
        if index < MAX_EVENTS {
            Some(Self(index as u8))
        } else {
            None
        }
    }

    /// The index of this event in its domain.
    pub const fn index(self) -> usize {
        self.0 as usize
    }
}

/// Which table of a domain an error is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Table {
    /// Facts.
    Fact,
    /// Trigger events.
    Event,
    /// Sensor-based actions.
    Sensor,
    /// Actuator-based actions.
    Action,
}

/// Why a domain could not be built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum DomainError {
    /// The table already holds `capacity` entries.
    Full {
        /// The table that is full.
        table: Table,
        /// Its capacity.
        capacity: usize,
    },
    /// The name is already in the table.
    Duplicate(Table),
    /// No entry of that name in the table.
    Unknown(Table),
    /// A name is empty, or white space only.
    EmptyName(Table),
    /// A cyclic sensor's period is shorter than one tick: it would sample forever at one
    /// instant.
    ZeroPeriod,
}

impl core::fmt::Display for Table {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::Fact => "facts",
            Self::Event => "events",
            Self::Sensor => "sensors",
            Self::Action => "actions",
        })
    }
}

impl core::fmt::Display for DomainError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Full { table, capacity } => {
                write!(f, "the domain's {table} are full ({capacity})")
            }
            Self::Duplicate(table) => write!(f, "a name already among the domain's {table}"),
            Self::Unknown(table) => write!(f, "no such name among the domain's {table}"),
            Self::EmptyName(table) => write!(f, "an empty name among the domain's {table}"),
            Self::ZeroPeriod => f.write_str("a cyclic sensor's period is shorter than a tick"),
        }
    }
}

impl core::error::Error for DomainError {}

/// The planning domain `Δ` with room for `NS` sensor-based and `NA` actuator-based actions
/// and `NF` facts in fact sets of `W` words (one word and 64 facts by default; `NF` is at
/// most `64 · W`, else the domain does not compile).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Domain<
    'a,
    const NS: usize,
    const NA: usize,
    const W: usize = 1,
    const NF: usize = MAX_FACTS,
> {
    facts: Vec<&'a str, NF>,
    events: Vec<&'a str, MAX_EVENTS>,
    sensors: Vec<SensorAction<'a, W>, NS>,
    actions: Vec<ActuatorAction<'a, W>, NA>,
}

impl<const NS: usize, const NA: usize, const W: usize, const NF: usize> Default
    for Domain<'_, NS, NA, W, NF>
{
    fn default() -> Self {
        Self::new()
    }
}

/// A character a terminal would act on or not show: a control character, or an invisible
/// format or filler character (soft hyphen, zero-width spaces and joiners, bidirectional marks,
/// overrides and isolates, line and paragraph separators, variation selectors, tags, Hangul
/// fillers, the byte order mark), which can make a name read as another.
pub(crate) fn hidden(c: char) -> bool {
    c.is_control()
        || matches!(
            c,
            '\u{00AD}'
                | '\u{034F}'
                | '\u{061C}'
                | '\u{115F}'..='\u{1160}'
                | '\u{17B4}'..='\u{17B5}'
                | '\u{180B}'..='\u{180F}'
                | '\u{200B}'..='\u{200F}'
                | '\u{2028}'..='\u{202E}'
                | '\u{2060}'..='\u{206F}'
                | '\u{3164}'
                | '\u{FE00}'..='\u{FE0F}'
                | '\u{FEFF}'
                | '\u{FFA0}'
                | '\u{FFF9}'..='\u{FFFB}'
                | '\u{1D173}'..='\u{1D17A}'
                | '\u{E0000}'..='\u{E0FFF}'
        )
}

/// White space in a name: Unicode's with `std`; ASCII's and the no-break space without
/// (Unicode's tables would cost a robot's loader 13 KB of flash).
fn space(c: char) -> bool {
    #[cfg(feature = "std")]
    return c.is_whitespace();
    #[cfg(not(feature = "std"))]
    return c.is_ascii_whitespace() || c == '\u{a0}';
}

/// A name that is empty or only white space and invisible characters (`hidden`: zero-width
/// spaces, bidi marks, ...): it could not be told apart in print.
pub fn blank(name: &str) -> bool {
    name.chars().all(|c| space(c) || hidden(c))
}

/// Whether two names read alike, so that one mission (or scenario) may not hold both: equal
/// once invisible characters are dropped, white space (a no-break space too) read as a space
/// and trimmed, and letters lower-cased. With feature `std` (the host's tools, the
/// `include_mission!` macro) the rule is Unicode's: any white space, any letter's case, both
/// names in the composed form (NFC). A robot's run-time loader (no `std`) folds ASCII letters
/// only, to spare the tables' flash: a mission `psmpa-sim check` accepts passes it.
pub fn same_name(a: &str, b: &str) -> bool {
    if a.is_ascii() && b.is_ascii() {
        // The common case, without Unicode's tables: a loader compares every pair of names.
        return ascii_folded(a).eq(ascii_folded(b));
    }
    folded(a).eq(folded(b))
}

fn ascii_folded(name: &str) -> impl Iterator<Item = u8> + '_ {
    name.trim_matches(|c: char| c.is_ascii_whitespace() || c.is_ascii_control())
        .bytes()
        .filter(|b| !b.is_ascii_control())
        .map(|b| {
            if b.is_ascii_whitespace() {
                b' '
            } else {
                b.to_ascii_lowercase()
            }
        })
}

fn folded(name: &str) -> impl Iterator<Item = char> + '_ {
    let trimmed = name.trim_matches(|c: char| space(c) || hidden(c));
    #[cfg(feature = "std")]
    let chars = unicode_normalization::UnicodeNormalization::nfc(trimmed.chars())
        .filter(|c| !hidden(*c))
        .flat_map(char::to_lowercase);
    #[cfg(not(feature = "std"))]
    let chars = trimmed
        .chars()
        .filter(|c| !hidden(*c))
        .map(|c| c.to_ascii_lowercase());
    chars.map(|c| if space(c) { ' ' } else { c })
}

fn push_name<'a, const N: usize>(
    table: &mut Vec<&'a str, N>,
    which: Table,
    name: &'a str,
) -> Result<usize, DomainError> {
    if blank(name) {
        return Err(DomainError::EmptyName(which));
    }
    if table.iter().any(|n| same_name(n, name)) {
        return Err(DomainError::Duplicate(which));
    }
    let index = table.len();
    table.push(name).map_err(|_| DomainError::Full {
        table: which,
        capacity: N,
    })?;
    Ok(index)
}

impl<'a, const NS: usize, const NA: usize, const W: usize, const NF: usize>
    Domain<'a, NS, NA, W, NF>
{
    /// An empty domain. A capacity of more actions than an [`ActionId`] indexes does not
    /// compile.
    pub const fn new() -> Self {
        const {
            assert!(
                NA <= crate::action::MAX_ACTIONS,
                "a domain indexes at most MAX_ACTIONS (65,536) actions"
            );
            assert!(
                NF <= FactSetOf::<W>::CAPACITY,
                "a domain names at most 64 facts a word of its fact sets"
            );
        }
        Self {
            facts: Vec::new(),
            events: Vec::new(),
            sensors: Vec::new(),
            actions: Vec::new(),
        }
    }

    /// A domain from its tables, built at compile time: what `include_mission!` generates for
    /// a mission it has loaded and checked. Nothing is checked here (unique names, ids within
    /// the tables): use [`new`](Self::new) and the `add_` methods, or `mission::load` (feature
    /// `loader`), for a domain built at run time. More entries than a capacity does not compile.
    pub const fn from_tables<const F: usize, const E: usize, const S: usize, const A: usize>(
        facts: [&'a str; F],
        events: [&'a str; E],
        sensors: [SensorAction<'a, W>; S],
        actions: [ActuatorAction<'a, W>; A],
    ) -> Self {
        const {
            assert!(
                NA <= crate::action::MAX_ACTIONS,
                "a domain indexes at most MAX_ACTIONS (65,536) actions"
            );
            assert!(
                NF <= FactSetOf::<W>::CAPACITY,
                "a domain names at most 64 facts a word of its fact sets"
            );
            assert!(E <= MAX_EVENTS, "a domain names at most MAX_EVENTS events");
        }
        Self {
            facts: Vec::from_array(facts),
            events: Vec::from_array(events),
            sensors: Vec::from_array(sensors),
            actions: Vec::from_array(actions),
        }
    }

    /// Empties the domain in place (no copy of it on the stack, as assigning a new one makes).
    pub fn clear(&mut self) {
        self.facts.clear();
        self.events.clear();
        self.sensors.clear();
        self.actions.clear();
    }

    /// Adds a fact and returns its id.
    pub fn add_fact(&mut self, name: &'a str) -> Result<FactId, DomainError> {
        if blank(name) {
            return Err(DomainError::EmptyName(Table::Fact));
        }
        if self.facts.iter().any(|n| same_name(n, name)) {
            return Err(DomainError::Duplicate(Table::Fact));
        }
        let full = DomainError::Full {
            table: Table::Fact,
            capacity: NF,
        };
        let index = self.facts.len();
        let id = FactId::within(index, FactSetOf::<W>::CAPACITY).ok_or(full)?;
        self.facts.push(name).map_err(|_| full)?;
        Ok(id)
    }

    /// Adds a trigger event and returns its id.
    pub fn add_event(&mut self, name: &'a str) -> Result<EventId, DomainError> {
        let index = push_name(&mut self.events, Table::Event, name)?;
        EventId::new(index).ok_or(DomainError::Full {
            table: Table::Event,
            capacity: MAX_EVENTS,
        })
    }

    /// Adds a sensor-based action and returns its id.
    pub fn add_sensor(&mut self, sensor: SensorAction<'a, W>) -> Result<SensorId, DomainError> {
        let full = DomainError::Full {
            table: Table::Sensor,
            capacity: if NS < MAX_SENSORS { NS } else { MAX_SENSORS },
        };
        if blank(sensor.name) {
            return Err(DomainError::EmptyName(Table::Sensor));
        }
        if self.sensors.iter().any(|s| same_name(s.name, sensor.name)) {
            return Err(DomainError::Duplicate(Table::Sensor));
        }
        if let SensorMode::Cyclic { period } = sensor.mode
            && period.as_ticks() == 0
        {
            return Err(DomainError::ZeroPeriod);
        }
        let id = SensorId::new(self.sensors.len()).ok_or(full)?;
        self.sensors.push(sensor).map_err(|_| full)?;
        Ok(id)
    }

    /// Adds an actuator-based action and returns its id.
    pub fn add_action(&mut self, action: ActuatorAction<'a, W>) -> Result<ActionId, DomainError> {
        let full = DomainError::Full {
            table: Table::Action,
            capacity: NA,
        };
        if blank(action.name) {
            return Err(DomainError::EmptyName(Table::Action));
        }
        if self.actions.iter().any(|a| same_name(a.name, action.name)) {
            return Err(DomainError::Duplicate(Table::Action));
        }
        let id = ActionId::new(self.actions.len()).ok_or(full)?;
        self.actions.push(action).map_err(|_| full)?;
        Ok(id)
    }

    /// The id of the fact called `name`.
    #[inline]
    pub fn fact_id(&self, name: &str) -> Option<FactId> {
        self.facts
            .iter()
            .position(|n| *n == name)
            .and_then(|i| FactId::within(i, FactSetOf::<W>::CAPACITY))
    }

    /// The set of the facts called `names`.
    pub fn facts(&self, names: &[&str]) -> Result<FactSetOf<W>, DomainError> {
        names.iter().try_fold(FactSetOf::EMPTY, |set, name| {
            self.fact_id(name)
                .map(|id| set.with(id))
                .ok_or(DomainError::Unknown(Table::Fact))
        })
    }

    /// The id of the event called `name`.
    pub fn event_id(&self, name: &str) -> Option<EventId> {
        self.events
            .iter()
            .position(|n| *n == name)
            .and_then(EventId::new)
    }

    /// The id of the sensor-based action called `name`.
    pub fn sensor_id(&self, name: &str) -> Option<SensorId> {
        self.sensors
            .iter()
            .position(|s| s.name == name)
            .and_then(SensorId::new)
    }

    /// The id of the actuator-based action called `name`.
    #[inline]
    pub fn action_id(&self, name: &str) -> Option<ActionId> {
        self.actions
            .iter()
            .position(|a| a.name == name)
            .and_then(ActionId::new)
    }

    /// The name of a fact.
    pub fn fact_name(&self, fact: FactId) -> Option<&'a str> {
        self.facts.get(fact.index()).copied()
    }

    /// The name of an event.
    pub fn event_name(&self, event: EventId) -> Option<&'a str> {
        self.events.get(event.index()).copied()
    }

    /// A sensor-based action.
    pub fn sensor(&self, id: SensorId) -> Option<&SensorAction<'a, W>> {
        self.sensors.get(id.index())
    }

    /// A sensor-based action, to change its mode or timeout (a simulator applying a
    /// scenario's sampling periods). A zero period is refused, as in [`add_sensor`](Self::add_sensor).
    pub fn set_sensor_mode(&mut self, id: SensorId, mode: SensorMode) -> Result<(), DomainError> {
        if matches!(mode, SensorMode::Cyclic { period } if period.as_ticks() == 0) {
            return Err(DomainError::ZeroPeriod);
        }
        let sensor = self
            .sensors
            .get_mut(id.index())
            .ok_or(DomainError::Unknown(Table::Sensor))?;
        sensor.mode = mode;
        Ok(())
    }

    /// Sets how long an action's precondition may stay false while it runs
    /// ([`ActuatorAction::max_violation`]; `None`: the runtime's default).
    pub fn set_max_violation(
        &mut self,
        id: ActionId,
        max_violation: Option<embassy_time::Duration>,
    ) -> Result<(), DomainError> {
        let action = self
            .actions
            .get_mut(id.index())
            .ok_or(DomainError::Unknown(Table::Action))?;
        action.max_violation = max_violation;
        Ok(())
    }

    /// An actuator-based action.
    pub fn action(&self, id: ActionId) -> Option<&ActuatorAction<'a, W>> {
        self.actions.get(id.index())
    }

    /// All fact names, in id order.
    pub fn fact_names(&self) -> &[&'a str] {
        &self.facts
    }

    /// All event names, in id order.
    pub fn event_names(&self) -> &[&'a str] {
        &self.events
    }

    /// All sensor-based actions, in id order.
    pub fn sensors(&self) -> &[SensorAction<'a, W>] {
        &self.sensors
    }

    /// All actuator-based actions, in id order.
    pub fn actions(&self) -> &[ActuatorAction<'a, W>] {
        &self.actions
    }

    /// Algorithm 2 line 11: the sensors `s` with `per(s) ⊆ pre` (and `per(s) ≠ ∅`).
    ///
    /// O(NS).
    #[inline]
    pub fn sensors_serving(&self, pre: FactSetOf<W>) -> SensorSet {
        crate::action::sensors_serving(&self.sensors, pre)
    }

    /// `∪ per(s)` over a set of sensors: the facts they decide while running.
    ///
    /// O(NS).
    #[inline]
    pub fn perception_of(&self, sensors: SensorSet) -> FactSetOf<W> {
        crate::action::perception_of(&self.sensors, sensors)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::facts::FactSet;

    #[test]
    fn names_are_unique_nonempty_and_bounded() {
        let mut d: Domain<'_, 1, 1> = Domain::new();
        let a = d.add_fact("a").unwrap();
        assert_eq!(d.add_fact("a"), Err(DomainError::Duplicate(Table::Fact)));
        assert_eq!(d.add_fact(""), Err(DomainError::EmptyName(Table::Fact)));
        assert_eq!(d.fact_id("a"), Some(a));
        assert_eq!(d.facts(&["a", "b"]), Err(DomainError::Unknown(Table::Fact)));
        let per = FactSet::single(a);
        d.add_sensor(SensorAction::new("s", per, SensorMode::OneShot))
            .unwrap();
        assert_eq!(
            d.add_sensor(SensorAction::new("t", per, SensorMode::OneShot)),
            Err(DomainError::Full {
                table: Table::Sensor,
                capacity: 1
            })
        );
        d.add_action(ActuatorAction::new("x", per, per, FactSet::EMPTY))
            .unwrap();
        assert_eq!(
            d.add_action(ActuatorAction::new("x", per, per, FactSet::EMPTY)),
            Err(DomainError::Duplicate(Table::Action))
        );
    }

    #[test]
    fn fact_table_holds_exactly_max_facts() {
        let names: std::vec::Vec<std::string::String> =
            (0..=MAX_FACTS).map(|i| std::format!("f{i}")).collect();
        let mut d: Domain<'_, 1, 1> = Domain::new();
        for name in &names[..MAX_FACTS] {
            d.add_fact(name).unwrap();
        }
        assert_eq!(
            d.add_fact(&names[MAX_FACTS]),
            Err(DomainError::Full {
                table: Table::Fact,
                capacity: MAX_FACTS
            })
        );
    }

    /// Names that read alike are one name: case, a trailing or no-break space, a zero-width
    /// space, Unicode composition (with `std`, as tests build); a name of invisible characters
    /// only is blank. Each of these was accepted as a second, different name.
    #[test]
    fn names_that_read_alike_are_duplicates() {
        for (a, b) in [
            ("clear", "Clear"),
            ("clear", "clear "),
            ("path clear", "path\u{a0}clear"),
            ("clear", "cle\u{200b}ar"),
        ] {
            assert!(same_name(a, b), "{a:?} {b:?}");
            let mut d: Domain<'_, 1, 1> = Domain::new();
            d.add_fact(a).unwrap();
            assert_eq!(
                d.add_fact(b),
                Err(DomainError::Duplicate(Table::Fact)),
                "{b:?}"
            );
            assert_eq!(
                d.add_event(a).and_then(|_| d.add_event(b)),
                Err(DomainError::Duplicate(Table::Event))
            );
        }
        #[cfg(feature = "std")]
        assert!(
            same_name("caf\u{e9}", "Cafe\u{301}"),
            "composed and decomposed"
        );
        assert!(!same_name("clear", "clean"));
        assert!(!same_name("a b", "ab"));
        for name in ["", "  ", "\u{200b}\u{200b}", "\u{a0}\u{feff}", "\u{202e}"] {
            assert!(blank(name), "{name:?}");
        }
        assert!(!blank("a\u{200b}"));
    }
}

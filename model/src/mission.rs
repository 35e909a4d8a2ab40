//! A mission: everything the runtime needs to know about a robot's job, `<S, A, P>` and the
//! task `Π`, held in fixed-capacity structures, and its JSON file format.
//!
//! `load` (feature `loader`) reads a mission file with `serde-json-core` in three streaming passes over the same
//! bytes (facts and events; sensors and actions; plans and the task), so that names are
//! resolved to ids as they are read, in any key order, with no intermediate copies: the only
//! memory used is the [`Tables`] itself. Names borrow from the file's bytes. Behaviour names
//! are bound to the platform's behaviours through a [`Registry`]: a name the platform cannot run
//! is an error at load time, not at run time.
//!
//! ```json
//! { "name": "fetch-tea",
//!   "facts": ["path_clear", "at_door", "handle_seen", "door_open", "in_kitchen"],
//!   "events": ["fetch_tea"],
//!   "sensors": [
//!     { "name": "sonar", "per": ["path_clear"], "mode": "cyclic", "period_ms": 100 },
//!     { "name": "camera", "pre": ["at_door"], "per": ["handle_seen"], "mode": "one-shot" } ],
//!   "actions": [
//!     { "name": "go to door", "pre": ["path_clear"], "add": ["at_door"] },
//!     { "name": "open door", "pre": ["at_door", "handle_seen"], "add": ["door_open"] },
//!     { "name": "enter kitchen", "pre": ["door_open"], "add": ["in_kitchen"], "del": ["at_door"] } ],
//!   "plans": [
//!     { "name": "GetIn Kitchen", "trigger": "fetch_tea",
//!       "body": ["go to door", "open door", "enter kitchen"] } ],
//!   "task": { "event": "fetch_tea", "init": [], "goal": ["in_kitchen"] } }
//! ```
//!
//! Sensor `mode` is `cyclic` (with `period_ms`), `one-shot` or `on-demand`; `timeout_ms`
//! (default 500) bounds a sample. An action may have `max_violation_ms`
//! ([`ActuatorAction::max_violation`](crate::action::ActuatorAction::max_violation); absent:
//! the runtime's `Config::max_violation`), a plan `context_not`, facts that must not hold
//! ([`Plan::context_not`](crate::plan::Plan::context_not)), and the file a
//! top-level `description` (any JSON value, skipped). A sensor, an action and a plan may
//! have a `description` too, and the facts a top-level `fact_descriptions` (an object from a
//! fact's name to its description): skipped by the loader; a string one becomes the doc
//! comment of its variant in `include_mission!`'s enums. The `_ms` values are whole numbers of
//! milliseconds: the loader parses integers only, so a microcontroller needs no float
//! parser (`50.0` or `5e1` is an error). `pre`, `add`, `del`, `context`, `context_not` and
//! `init` default to `[]`.

use core::fmt;

#[cfg(feature = "loader")]
use embassy_time::Duration;
use heapless::Vec;
#[cfg(feature = "loader")]
use serde::de::{self, DeserializeSeed, IgnoredAny, MapAccess, SeqAccess, Visitor};

use crate::action::{ActionId, SensorId};
#[cfg(feature = "loader")]
use crate::action::{ActuatorAction, SensorAction, SensorMode};
use crate::domain::{Domain, EventId};
#[cfg(feature = "loader")]
use crate::domain::{DomainError, Table};
#[cfg(feature = "loader")]
use crate::facts::FactId;
use crate::facts::FactSetOf;
use crate::plan::PlanLibrary;
#[cfg(feature = "loader")]
use crate::plan::{Plan, PlanError};
use crate::task::Task;

/// The domain (facts, events, sensor-based and actuator-based actions), the plan library and
/// the task of one robot, with room for `NS` sensors, `NA` actions, `NP` plans of at most `L`
/// actions each.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Tables<
    'a,
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const W: usize = 1,
    const NF: usize = 64,
> {
    /// Name of the mission.
    pub name: &'a str,
    /// `Δ`: facts, events, `S` and `A`.
    pub domain: Domain<'a, NS, NA, W, NF>,
    /// `P`: the plan library.
    pub library: PlanLibrary<'a, NP, L, W>,
    /// `Π`: what to achieve from where.
    pub task: Task<W>,
}

/// Binds the behaviour names of a mission to what the platform can run.
pub trait Registry {
    /// The platform's handle of a sensor behaviour.
    type Sensor: Copy;
    /// The platform's handle of an actuator behaviour.
    type Action: Copy;
    /// The sensor behaviour called `name`, if the platform has one.
    fn sensor(&self, name: &str) -> Option<Self::Sensor>;
    /// The actuator behaviour called `name`, if the platform has one.
    fn action(&self, name: &str) -> Option<Self::Action>;
}

/// Accepts every name and binds nothing: for checking a mission's logic without a platform.
#[derive(Clone, Copy, Debug, Default)]
pub struct AnyBehaviour;

impl Registry for AnyBehaviour {
    type Sensor = ();
    type Action = ();
    fn sensor(&self, _name: &str) -> Option<()> {
        Some(())
    }
    fn action(&self, _name: &str) -> Option<()> {
        Some(())
    }
}

/// The platform behaviour bound to every sensor and action id of a loaded mission.
#[derive(Clone, Debug)]
pub struct Bindings<S, A, const NS: usize, const NA: usize> {
    sensors: Vec<S, NS>,
    actions: Vec<A, NA>,
}

impl<S, A, const NS: usize, const NA: usize> Default for Bindings<S, A, NS, NA> {
    fn default() -> Self {
        Self::new()
    }
}

impl<S, A, const NS: usize, const NA: usize> Bindings<S, A, NS, NA> {
    /// Nothing bound; usable in a `static`.
    pub const fn new() -> Self {
        Self {
            sensors: Vec::new(),
            actions: Vec::new(),
        }
    }
}

impl<S, A, const NS: usize, const NA: usize> Bindings<S, A, NS, NA> {
    /// Unbinds everything, in place.
    pub fn clear(&mut self) {
        self.sensors.clear();
        self.actions.clear();
    }
}

impl<S: Copy, A: Copy, const NS: usize, const NA: usize> Bindings<S, A, NS, NA> {
    /// The behaviour of a sensor. O(1).
    pub fn sensor(&self, id: SensorId) -> Option<S> {
        self.sensors.get(id.index()).copied()
    }

    /// The behaviour of an action. O(1).
    pub fn action(&self, id: ActionId) -> Option<A> {
        self.actions.get(id.index()).copied()
    }
}

impl<S: Copy, A: Copy, const NS: usize, const NA: usize> Bindings<S, A, NS, NA> {
    /// The behaviours of a domain built in Rust, from `registry`: what `load` (feature
    /// `loader`) binds for a mission file. `Err` names the first sensor or action the registry has no behaviour for.
    /// O(NS + NA) registry lookups.
    pub fn resolve<'a, R, const W: usize, const NF: usize>(
        domain: &Domain<'a, NS, NA, W, NF>,
        registry: &R,
    ) -> Result<Self, &'a str>
    where
        R: Registry<Sensor = S, Action = A>,
    {
        let mut bound = Self::new();
        for sensor in domain.sensors() {
            let behaviour = registry.sensor(sensor.name).ok_or(sensor.name)?;
            bound.sensors.push(behaviour).map_err(|_| sensor.name)?;
        }
        for action in domain.actions() {
            let behaviour = registry.action(action.name).ok_or(action.name)?;
            bound.actions.push(behaviour).map_err(|_| action.name)?;
        }
        Ok(bound)
    }
}

impl<S: PartialEq, A: PartialEq, const NS: usize, const NA: usize> Bindings<S, A, NS, NA> {
    /// The sensor a behaviour is bound to (the first, if several): from a device to its id.
    /// O(NS).
    pub fn sensor_id(&self, behaviour: &S) -> Option<SensorId> {
        self.sensors
            .iter()
            .position(|s| s == behaviour)
            .and_then(SensorId::new)
    }

    /// The action a behaviour is bound to (the first, if several). O(NA).
    pub fn action_id(&self, behaviour: &A) -> Option<ActionId> {
        self.actions
            .iter()
            .position(|a| a == behaviour)
            .and_then(ActionId::new)
    }
}

/// Where in a mission file something is wrong.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Location {
    /// Top-level key (`facts`, `sensors`, `plans`, ...), `None` at the top level.
    pub section: Option<&'static str>,
    /// Index in that section's list.
    pub index: Option<u16>,
    /// Field of that entry.
    pub field: Option<&'static str>,
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.section {
            None => f.write_str("top level"),
            Some(s) => {
                f.write_str(s)?;
                if let Some(i) = self.index {
                    write!(f, "[{i}]")?;
                }
                if let Some(field) = self.field {
                    write!(f, ".{field}")?;
                }
                Ok(())
            }
        }
    }
}

/// What is wrong with a mission file.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum Problem<'a> {
    /// Not JSON, or a value of the wrong type.
    Json(JsonError),
    /// A key the format does not have.
    UnknownField(&'a str),
    /// A required key is missing.
    MissingField(&'static str),
    /// A fact name that is not in `facts`.
    UnknownFact(&'a str),
    /// An event name that is not in `events`.
    UnknownEvent(&'a str),
    /// An action name that is not in `actions`.
    UnknownAction(&'a str),
    /// A sensor mode other than `cyclic`, `one-shot`, `on-demand`.
    UnknownMode(&'a str),
    /// The name is already used in its table.
    Duplicate(&'a str),
    /// A name is empty, or white space only.
    EmptyName,
    /// A plan body is empty.
    EmptyBody,
    /// More entries than the runtime was built for.
    Capacity {
        /// What overflowed.
        what: &'static str,
        /// The limit.
        limit: usize,
    },
    /// A cyclic sensor needs a `period_ms` of at least 1.
    Period,
    /// A number of milliseconds past what the runtime counts (2³² − 1).
    Millis,
    /// A `period_ms` on a sensor that is not cyclic: it would be ignored.
    NotCyclic,
    /// A plan's context requires this fact both true (`context`) and false (`context_not`).
    Contradiction(&'a str),
    /// No sequence of actions and percepts can ever make this goal fact true.
    UnreachableGoal(&'a str),
    /// The platform has no behaviour of this name.
    Unbound(&'a str),
    /// Arrays and objects nested deeper than [`MAX_DEPTH`] (the parser recurses once per
    /// level, so the depth bounds its stack).
    TooDeep,
}

/// A JSON error of `serde-json-core`, which carries no message of its own.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum JsonError {
    /// The text is not well-formed JSON.
    Syntax,
    /// A value has the wrong type (a number where a list is expected, ...).
    Type,
    /// A string uses an escape sequence (names must be plain).
    Escape,
    /// A number that is not a whole number in range: negative, or more than 2⁶⁴ − 1. (A
    /// fraction or an exponent ends the whole number early, and what follows it is a
    /// [`Syntax`](Self::Syntax) error, at the same field.)
    Number,
}

/// Why a mission could not be loaded: what and where.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LoadError<'a> {
    /// Where.
    pub at: Location,
    /// What.
    pub problem: Problem<'a>,
}

impl fmt::Display for LoadError<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: ", self.at)?;
        match self.problem {
            // `50.0`: the whole number 50, then a `.` where JSON wants a comma.
            Problem::Json(JsonError::Syntax) if self.at.field.is_some_and(|k| k.ends_with("_ms")) => {
                f.write_str("malformed JSON, or not a whole number of milliseconds (no fraction or exponent)")
            }
            Problem::Json(JsonError::Syntax) => f.write_str("malformed JSON"),
            Problem::Json(JsonError::Type) => f.write_str("a value of the wrong type"),
            Problem::Json(JsonError::Number) => {
                f.write_str("not a whole number of milliseconds up to 4294967295 (no sign, fraction or exponent)")
            }
            Problem::Json(JsonError::Escape) => {
                f.write_str("escape sequences are not allowed in names")
            }
            Problem::UnknownField(k) => write!(f, "unknown field `{k}`"),
            Problem::MissingField(k) => write!(f, "missing field `{k}`"),
            Problem::UnknownFact(n) => write!(f, "unknown fact `{n}` (not in `facts`)"),
            Problem::UnknownEvent(n) => write!(f, "unknown event `{n}` (not in `events`)"),
            Problem::UnknownAction(n) => write!(f, "unknown action `{n}` (not in `actions`)"),
            Problem::UnknownMode(m) => {
                write!(
                    f,
                    "unknown sensor mode `{m}`, expected `cyclic`, `one-shot` or `on-demand`"
                )
            }
            Problem::Duplicate(n) => write!(f, "duplicate name `{n}`"),
            Problem::EmptyName => f.write_str("the name is empty or blank"),
            Problem::EmptyBody => f.write_str("the plan body is empty"),
            Problem::Capacity { what, limit } => {
                write!(f, "more than {limit} {what} (the runtime's capacity)")
            }
            Problem::Period => f.write_str("needs a whole number of milliseconds of at least 1"),
            Problem::Millis => f.write_str("more than 4294967295 milliseconds"),
            Problem::NotCyclic => f.write_str("`period_ms` is only for a `cyclic` sensor"),
            Problem::Contradiction(n) => {
                write!(f, "fact `{n}` is in both `context` and `context_not`")
            }
            Problem::UnreachableGoal(n) => {
                write!(
                    f,
                    "goal fact `{n}` can never hold: no action that adds it can ever start, and no sensor perceives it"
                )
            }
            Problem::Unbound(n) => write!(f, "the platform has no behaviour called `{n}`"),
            Problem::TooDeep => write!(f, "nested deeper than {MAX_DEPTH} levels"),
        }
    }
}

impl core::error::Error for LoadError<'_> {}

/// What the streaming deserializers need from the mission under construction; object safe so
/// they carry no capacity parameters.
#[cfg(feature = "loader")]
trait Build<'a, const W: usize> {
    fn at(&self) -> Location;
    fn set_at(&mut self, at: Location);
    /// Records the first problem, at the current location.
    fn record(&mut self, problem: Problem<'a>);
    fn add_fact(&mut self, name: &'a str) -> Result<(), Problem<'a>>;
    fn add_event(&mut self, name: &'a str) -> Result<(), Problem<'a>>;
    fn fact(&self, name: &'a str) -> Result<FactSetOf<W>, Problem<'a>>;
    fn event(&self, name: &'a str) -> Result<EventId, Problem<'a>>;
    fn add_sensor(&mut self, sensor: SensorAction<'a, W>) -> Result<(), Problem<'a>>;
    fn add_action(&mut self, action: ActuatorAction<'a, W>) -> Result<(), Problem<'a>>;
    fn push_body(&mut self, action: &'a str) -> Result<(), Problem<'a>>;
    fn add_plan(
        &mut self,
        name: &'a str,
        trigger: EventId,
        context: FactSetOf<W>,
        context_not: FactSetOf<W>,
    ) -> Result<(), Problem<'a>>;
    /// The name of a declared fact.
    fn fact_name(&self, fact: FactId) -> &'a str;
    fn set_task(&mut self, task: Task<W>);
    fn set_name(&mut self, name: &'a str);
}

/// Records `problem` and returns the error that stops the parse.
#[cfg(feature = "loader")]
fn fail<'a, E: de::Error, const W: usize>(b: &mut dyn Build<'a, W>, problem: Problem<'a>) -> E {
    b.record(problem);
    E::custom("mission error")
}

#[cfg(feature = "loader")]
fn field<const W: usize>(b: &mut dyn Build<'_, W>, field: Option<&'static str>) {
    let mut at = b.at();
    at.field = field;
    b.set_at(at);
}

/// The mission being built, the current location and the first problem.
#[cfg(feature = "loader")]
struct Builder<
    'a,
    'r,
    R: Registry,
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const W: usize,
    const NF: usize,
> {
    /// Written in place: the mission is never copied while it is built.
    mission: &'r mut Tables<'a, NS, NA, NP, L, W, NF>,
    bindings: &'r mut Bindings<R::Sensor, R::Action, NS, NA>,
    registry: &'r R,
    at: Location,
    error: Option<LoadError<'a>>,
    body: Vec<ActionId, L>,
}

#[cfg(feature = "loader")]
fn domain_problem(e: DomainError, name: &str) -> Problem<'_> {
    match e {
        DomainError::Full { table, capacity } => Problem::Capacity {
            what: match table {
                Table::Fact => "facts",
                Table::Event => "events",
                Table::Sensor => "sensors",
                Table::Action => "actions",
            },
            limit: capacity,
        },
        DomainError::Duplicate(_) => Problem::Duplicate(name),
        DomainError::EmptyName(_) => Problem::EmptyName,
        DomainError::Unknown(_) => Problem::UnknownFact(name),
        DomainError::ZeroPeriod => Problem::Period,
    }
}

#[cfg(feature = "loader")]
impl<
    'a,
    R: Registry,
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const W: usize,
    const NF: usize,
> Build<'a, W> for Builder<'a, '_, R, NS, NA, NP, L, W, NF>
{
    fn at(&self) -> Location {
        self.at
    }

    fn set_at(&mut self, at: Location) {
        self.at = at;
    }

    fn record(&mut self, problem: Problem<'a>) {
        if self.error.is_none() {
            self.error = Some(LoadError {
                at: self.at,
                problem,
            });
        }
    }

    fn add_fact(&mut self, name: &'a str) -> Result<(), Problem<'a>> {
        self.mission
            .domain
            .add_fact(name)
            .map(|_| ())
            .map_err(|e| domain_problem(e, name))
    }

    fn add_event(&mut self, name: &'a str) -> Result<(), Problem<'a>> {
        self.mission
            .domain
            .add_event(name)
            .map(|_| ())
            .map_err(|e| domain_problem(e, name))
    }

    fn fact(&self, name: &'a str) -> Result<FactSetOf<W>, Problem<'a>> {
        self.mission
            .domain
            .fact_id(name)
            .map(FactSetOf::single)
            .ok_or(Problem::UnknownFact(name))
    }

    fn event(&self, name: &'a str) -> Result<EventId, Problem<'a>> {
        self.mission
            .domain
            .event_id(name)
            .ok_or(Problem::UnknownEvent(name))
    }

    fn add_sensor(&mut self, sensor: SensorAction<'a, W>) -> Result<(), Problem<'a>> {
        let behaviour = self
            .registry
            .sensor(sensor.name)
            .ok_or(Problem::Unbound(sensor.name))?;
        self.mission
            .domain
            .add_sensor(sensor)
            .map_err(|e| domain_problem(e, sensor.name))?;
        self.bindings
            .sensors
            .push(behaviour)
            .map_err(|_| Problem::Capacity {
                what: "sensors",
                limit: NS,
            })
    }

    fn add_action(&mut self, action: ActuatorAction<'a, W>) -> Result<(), Problem<'a>> {
        let behaviour = self
            .registry
            .action(action.name)
            .ok_or(Problem::Unbound(action.name))?;
        self.mission
            .domain
            .add_action(action)
            .map_err(|e| domain_problem(e, action.name))?;
        self.bindings
            .actions
            .push(behaviour)
            .map_err(|_| Problem::Capacity {
                what: "actions",
                limit: NA,
            })
    }

    fn push_body(&mut self, action: &'a str) -> Result<(), Problem<'a>> {
        let id = self
            .mission
            .domain
            .action_id(action)
            .ok_or(Problem::UnknownAction(action))?;
        self.body.push(id).map_err(|_| Problem::Capacity {
            what: "actions in a plan body",
            limit: L,
        })
    }

    fn fact_name(&self, fact: FactId) -> &'a str {
        self.mission.domain.fact_name(fact).unwrap_or("")
    }

    fn add_plan(
        &mut self,
        name: &'a str,
        trigger: EventId,
        context: FactSetOf<W>,
        context_not: FactSetOf<W>,
    ) -> Result<(), Problem<'a>> {
        let body = core::mem::take(&mut self.body);
        let plan = Plan::new(name, trigger, context, &body)
            .map_err(|e| match e {
                PlanError::EmptyBody => Problem::EmptyBody,
                PlanError::BodyTooLong { capacity } => Problem::Capacity {
                    what: "actions in a plan body",
                    limit: capacity,
                },
                _ => Problem::EmptyName,
            })?
            .with_context_not(context_not);
        self.mission
            .library
            .add(plan)
            .map(|_| ())
            .map_err(|e| match e {
                PlanError::Duplicate => Problem::Duplicate(name),
                PlanError::LibraryFull { capacity } => Problem::Capacity {
                    what: "plans",
                    limit: capacity,
                },
                _ => Problem::EmptyName,
            })
    }

    fn set_task(&mut self, task: Task<W>) {
        self.mission.task = task;
    }

    fn set_name(&mut self, name: &'a str) {
        self.mission.name = name;
    }
}

/// Which top-level keys a pass reads; it skips the others.
#[cfg(feature = "loader")]
#[derive(Clone, Copy, PartialEq, Eq)]
enum Pass {
    Names,
    Behaviours,
    Plans,
}

/// The top-level keys; all but `sensors`, `description` and `fact_descriptions` are required.
#[cfg(feature = "loader")]
const TOP_KEYS: [&str; 9] = [
    "name",
    "facts",
    "events",
    "sensors",
    "actions",
    "plans",
    "task",
    "description",
    "fact_descriptions",
];
#[cfg(feature = "loader")]
const OPTIONAL_TOP: u16 = 1 << 3 | 1 << 7 | 1 << 8;

/// A JSON string borrowed from the file.
#[cfg(feature = "loader")]
struct Str;

/// A string borrowed as written, escapes and all: the mission's own name, which is only shown
/// (escaped where shown), never compared.
#[cfg(feature = "loader")]
struct Text;

/// The visitor of both: `plain` refuses escapes.
#[cfg(feature = "loader")]
struct StrVisitor {
    plain: bool,
}

#[cfg(feature = "loader")]
impl<'de> Visitor<'de> for StrVisitor {
    type Value = &'de str;
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a string")
    }
    fn visit_borrowed_str<E: de::Error>(self, v: &'de str) -> Result<&'de str, E> {
        // A name is borrowed as written, escapes undecoded: two spellings of one name would be
        // two names. Refused (`load` reports it as `JsonError::Escape`).
        if self.plain && v.bytes().any(|b| b == b'\\') {
            return Err(E::custom("escape"));
        }
        Ok(v)
    }
}

#[cfg(feature = "loader")]
impl<'de> DeserializeSeed<'de> for Str {
    type Value = &'de str;
    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<&'de str, D::Error> {
        d.deserialize_str(StrVisitor { plain: true })
    }
}

#[cfg(feature = "loader")]
impl<'de> DeserializeSeed<'de> for Text {
    type Value = &'de str;
    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<&'de str, D::Error> {
        d.deserialize_str(StrVisitor { plain: false })
    }
}

/// What a [`NameList`] does with each name.
#[cfg(feature = "loader")]
#[derive(Clone, Copy)]
enum ListKind {
    /// Declare facts.
    DeclareFacts,
    /// Declare events.
    DeclareEvents,
    /// A fact set (`pre`, `add`, `goal`, ...).
    Facts,
    /// A plan body.
    Body,
}

/// A list of names: declared, resolved into a fact set, or collected into a plan body.
#[cfg(feature = "loader")]
struct NameList<'s, 'a, const W: usize>(&'s mut dyn Build<'a, W>, ListKind);

#[cfg(feature = "loader")]
impl<'a, const W: usize> DeserializeSeed<'a> for NameList<'_, 'a, W> {
    type Value = FactSetOf<W>;
    fn deserialize<D: de::Deserializer<'a>>(self, d: D) -> Result<FactSetOf<W>, D::Error> {
        d.deserialize_seq(self)
    }
}

#[cfg(feature = "loader")]
impl<'a, const W: usize> Visitor<'a> for NameList<'_, 'a, W> {
    type Value = FactSetOf<W>;
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a list of names")
    }
    fn visit_seq<S: SeqAccess<'a>>(self, mut seq: S) -> Result<FactSetOf<W>, S::Error> {
        let NameList(b, kind) = self;
        let mut set = FactSetOf::EMPTY;
        let mut index = 0usize;
        loop {
            // Set before the element is read: an element of the wrong type is named too.
            if matches!(kind, ListKind::DeclareFacts | ListKind::DeclareEvents) {
                let mut at = b.at();
                at.index = u16::try_from(index).ok();
                b.set_at(at);
            }
            let Some(name) = seq.next_element_seed(Str)? else {
                break;
            };
            let done = match kind {
                ListKind::DeclareFacts => b.add_fact(name),
                ListKind::DeclareEvents => b.add_event(name),
                ListKind::Facts => b.fact(name).map(|f| set = set.union(f)),
                ListKind::Body => b.push_body(name),
            };
            done.map_err(|p| fail::<S::Error, W>(b, p))?;
            index = index.saturating_add(1);
        }
        Ok(set)
    }
}

/// A list of objects of one section, each read by [`Entry`].
#[cfg(feature = "loader")]
struct Entries<'s, 'a, const W: usize>(&'s mut dyn Build<'a, W>, Section);

#[cfg(feature = "loader")]
#[derive(Clone, Copy)]
enum Section {
    Sensors,
    Actions,
    Plans,
    Task,
}

#[cfg(feature = "loader")]
impl<'a, const W: usize> DeserializeSeed<'a> for Entries<'_, 'a, W> {
    type Value = ();
    fn deserialize<D: de::Deserializer<'a>>(self, d: D) -> Result<(), D::Error> {
        match self.1 {
            Section::Task => Entry(self.0, Section::Task).deserialize(d),
            _ => d.deserialize_seq(self),
        }
    }
}

#[cfg(feature = "loader")]
impl<'a, const W: usize> Visitor<'a> for Entries<'_, 'a, W> {
    type Value = ();
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a list of objects")
    }
    fn visit_seq<S: SeqAccess<'a>>(self, mut seq: S) -> Result<(), S::Error> {
        let Entries(b, section) = self;
        let mut index = 0usize;
        loop {
            let mut at = b.at();
            at.index = u16::try_from(index).ok();
            at.field = None;
            b.set_at(at);
            if seq.next_element_seed(Entry(&mut *b, section))?.is_none() {
                return Ok(());
            }
            index = index.saturating_add(1);
        }
    }
}

/// One sensor, action, plan or the task.
#[cfg(feature = "loader")]
struct Entry<'s, 'a, const W: usize>(&'s mut dyn Build<'a, W>, Section);

#[cfg(feature = "loader")]
impl<'a, const W: usize> DeserializeSeed<'a> for Entry<'_, 'a, W> {
    type Value = ();
    fn deserialize<D: de::Deserializer<'a>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_map(self)
    }
}

/// The fields each kind of entry has.
#[cfg(feature = "loader")]
const SENSOR_KEYS: [&str; 8] = [
    "name",
    "pre",
    "per",
    "mode",
    "period_ms",
    "timeout_ms",
    "description",
    "keys",
];
#[cfg(feature = "loader")]
const ACTION_KEYS: [&str; 7] = [
    "name",
    "pre",
    "add",
    "del",
    "max_violation_ms",
    "description",
    "keys",
];

/// The most keys a sensor or an action declares for its data store (`"keys"`).
pub const MAX_DECLARED_KEYS: usize = 16;

/// A behaviour's `"keys"`: names of the keys of its data store, each non-blank and given once,
/// at most [`MAX_DECLARED_KEYS`]. Checked here; a compiled mission makes them types, a mission
/// loaded at run time reads its keys by number.
#[cfg(feature = "loader")]
struct KeyList<'s, 'a, const W: usize>(&'s mut dyn Build<'a, W>);

#[cfg(feature = "loader")]
impl<'a, const W: usize> DeserializeSeed<'a> for KeyList<'_, 'a, W> {
    type Value = ();
    fn deserialize<D: de::Deserializer<'a>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_seq(self)
    }
}

#[cfg(feature = "loader")]
impl<'a, const W: usize> Visitor<'a> for KeyList<'_, 'a, W> {
    type Value = ();
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a list of key names")
    }
    fn visit_seq<S: SeqAccess<'a>>(self, mut seq: S) -> Result<(), S::Error> {
        let KeyList(b) = self;
        let mut seen: [Option<&'a str>; MAX_DECLARED_KEYS] = [None; MAX_DECLARED_KEYS];
        let mut count = 0usize;
        while let Some(name) = seq.next_element_seed(Str)? {
            let problem = if crate::domain::blank(name) {
                Some(Problem::EmptyName)
            } else if seen
                .iter()
                .flatten()
                .any(|k| crate::domain::same_name(k, name))
            {
                Some(Problem::Duplicate(name))
            } else {
                None
            };
            if let Some(problem) = problem {
                return Err(fail(b, problem));
            }
            let Some(slot) = seen.get_mut(count) else {
                return Err(fail(
                    b,
                    Problem::Capacity {
                        what: "keys",
                        limit: MAX_DECLARED_KEYS,
                    },
                ));
            };
            *slot = Some(name);
            count = count.saturating_add(1);
        }
        Ok(())
    }
}
#[cfg(feature = "loader")]
const PLAN_KEYS: [&str; 6] = [
    "name",
    "trigger",
    "context",
    "context_not",
    "body",
    "description",
];
#[cfg(feature = "loader")]
const TASK_KEYS: [&str; 3] = ["event", "init", "goal"];

/// The fields of one entry as read, before they are checked together.
#[cfg(feature = "loader")]
#[derive(Default)]
struct Fields<'a, const W: usize> {
    name: Option<&'a str>,
    mode: Option<&'a str>,
    event: Option<&'a str>,
    number: [Option<u64>; 3],
    sets: [Option<FactSetOf<W>>; 3],
    body: bool,
}

/// A number of milliseconds, at least 1. Integers only: no float parser on a microcontroller.
#[cfg(feature = "loader")]
fn millis<'a>(v: u64) -> Result<Duration, Problem<'a>> {
    if v == 0 {
        return Err(Problem::Period);
    }
    if v > u64::from(u32::MAX) {
        return Err(Problem::Millis);
    }
    Ok(Duration::from_millis(v))
}

#[cfg(feature = "loader")]
impl<'a, const W: usize> Visitor<'a> for Entry<'_, 'a, W> {
    type Value = ();
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("an object")
    }

    fn visit_map<M: MapAccess<'a>>(self, mut map: M) -> Result<(), M::Error> {
        let Entry(b, section) = self;
        let keys: &[&'static str] = match section {
            Section::Sensors => &SENSOR_KEYS,
            Section::Actions => &ACTION_KEYS,
            Section::Plans => &PLAN_KEYS,
            Section::Task => &TASK_KEYS,
        };
        let mut f = Fields::default();
        while let Some(key) = map.next_key_seed(Str)? {
            let Some(&name) = keys.iter().find(|k| **k == key) else {
                field(b, None);
                return Err(fail(b, Problem::UnknownField(key)));
            };
            field(b, Some(name));
            match name {
                "name" => f.name = Some(map.next_value_seed(Str)?),
                "mode" => f.mode = Some(map.next_value_seed(Str)?),
                "trigger" | "event" => f.event = Some(map.next_value_seed(Str)?),
                "period_ms" => f.number[0] = Some(map.next_value()?),
                "timeout_ms" => f.number[1] = Some(map.next_value()?),
                "max_violation_ms" => f.number[2] = Some(map.next_value()?),
                // Prose for people (and, compiled in, the variant's doc comment): skipped.
                "description" => {
                    map.next_value::<IgnoredAny>()?;
                }
                // The data store's keys: checked, then used by `include_mission!` only.
                "keys" => map.next_value_seed(KeyList(&mut *b))?,
                "body" => {
                    f.body = true;
                    map.next_value_seed(NameList(&mut *b, ListKind::Body))?;
                }
                _ => {
                    // A fact set: pre/per/add/del/context/context_not/init/goal, a fixed slot each.
                    let slot = match name {
                        "pre" | "context" | "init" => 0,
                        "per" | "add" | "goal" | "context_not" => 1,
                        _ => 2,
                    };
                    let set = map.next_value_seed(NameList(&mut *b, ListKind::Facts))?;
                    if let Some(s) = f.sets.get_mut(slot) {
                        *s = Some(set);
                    }
                }
            }
        }
        field(b, None);
        let set = |i: usize| f.sets.get(i).copied().flatten();
        let required = |b: &mut dyn Build<'a, W>, v: Option<&'a str>, name: &'static str| {
            v.ok_or_else(|| fail::<M::Error, W>(b, Problem::MissingField(name)))
        };
        let checked = |b: &mut dyn Build<'a, W>, r: Result<(), Problem<'a>>, at: &'static str| {
            field(b, Some(at));
            r.map_err(|p| fail::<M::Error, W>(b, p))
        };
        match section {
            Section::Sensors => {
                let name = required(b, f.name, "name")?;
                let per =
                    set(1).ok_or_else(|| fail::<M::Error, W>(b, Problem::MissingField("per")))?;
                let mode = match required(b, f.mode, "mode")? {
                    "cyclic" => {
                        let p = f.number[0].ok_or_else(|| {
                            fail::<M::Error, W>(b, Problem::MissingField("period_ms"))
                        })?;
                        field(b, Some("period_ms"));
                        SensorMode::Cyclic {
                            period: millis(p).map_err(|e| fail::<M::Error, W>(b, e))?,
                        }
                    }
                    "one-shot" | "on-demand" if f.number[0].is_some() => {
                        field(b, Some("period_ms"));
                        return Err(fail(b, Problem::NotCyclic));
                    }
                    "one-shot" => SensorMode::OneShot,
                    "on-demand" => SensorMode::OnDemand,
                    other => {
                        field(b, Some("mode"));
                        return Err(fail(b, Problem::UnknownMode(other)));
                    }
                };
                let mut sensor =
                    SensorAction::new(name, per, mode).with_pre(set(0).unwrap_or_default());
                if let Some(t) = f.number[1] {
                    field(b, Some("timeout_ms"));
                    sensor = sensor.with_timeout(millis(t).map_err(|e| fail::<M::Error, W>(b, e))?);
                }
                let added = b.add_sensor(sensor);
                checked(b, added, "name")
            }
            Section::Actions => {
                let name = required(b, f.name, "name")?;
                let mut action = ActuatorAction::new(
                    name,
                    set(0).unwrap_or_default(),
                    set(1).unwrap_or_default(),
                    set(2).unwrap_or_default(),
                );
                if let Some(ms) = f.number[2] {
                    // Zero is allowed: the action stops at the first sample that shows pre(a)
                    // false (a cliff).
                    field(b, Some("max_violation_ms"));
                    let ms = millis(ms.max(1))
                        .map(|_| Duration::from_millis(ms))
                        .map_err(|_| fail::<M::Error, W>(b, Problem::Millis))?;
                    action = action.with_max_violation(ms);
                }
                let added = b.add_action(action);
                checked(b, added, "name")
            }
            Section::Plans => {
                let name = required(b, f.name, "name")?;
                let trigger_name = required(b, f.event, "trigger")?;
                if !f.body {
                    return Err(fail(b, Problem::MissingField("body")));
                }
                field(b, Some("trigger"));
                let trigger = b
                    .event(trigger_name)
                    .map_err(|p| fail::<M::Error, W>(b, p))?;
                let (context, context_not) =
                    (set(0).unwrap_or_default(), set(1).unwrap_or_default());
                if let Some(both) = context.intersection(context_not).iter().next() {
                    field(b, Some("context_not"));
                    let name = b.fact_name(both);
                    return Err(fail(b, Problem::Contradiction(name)));
                }
                let added = b.add_plan(name, trigger, context, context_not);
                // Name the part at fault: the name, the whole plan (one too many), or the body.
                let at = match added {
                    Err(Problem::Duplicate(_) | Problem::EmptyName) => Some("name"),
                    Err(Problem::Capacity { what: "plans", .. }) => None,
                    _ => Some("body"),
                };
                field(b, at);
                added.map_err(|p| fail::<M::Error, W>(b, p))
            }
            Section::Task => {
                let event_name = required(b, f.event, "event")?;
                let goal =
                    set(1).ok_or_else(|| fail::<M::Error, W>(b, Problem::MissingField("goal")))?;
                field(b, Some("event"));
                let event = b.event(event_name).map_err(|p| fail::<M::Error, W>(b, p))?;
                b.set_task(Task {
                    event,
                    init: set(0).unwrap_or_default(),
                    goal,
                });
                Ok(())
            }
        }
    }
}

/// One pass over the top-level object.
#[cfg(feature = "loader")]
struct Top<'s, 'a, const W: usize>(&'s mut dyn Build<'a, W>, Pass, &'s mut u16);

#[cfg(feature = "loader")]
impl<'a, const W: usize> DeserializeSeed<'a> for Top<'_, 'a, W> {
    type Value = ();
    fn deserialize<D: de::Deserializer<'a>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_map(self)
    }
}

#[cfg(feature = "loader")]
impl<'a, const W: usize> Visitor<'a> for Top<'_, 'a, W> {
    type Value = ();
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a mission object")
    }

    fn visit_map<M: MapAccess<'a>>(self, mut map: M) -> Result<(), M::Error> {
        let Top(b, pass, seen) = self;
        loop {
            b.set_at(Location::default());
            let Some(key) = map.next_key_seed(Str)? else {
                return Ok(());
            };
            let Some(index) = TOP_KEYS.iter().position(|k| *k == key) else {
                return Err(fail(b, Problem::UnknownField(key)));
            };
            *seen |= 1 << index;
            let section = TOP_KEYS.get(index).copied().unwrap_or_default();
            b.set_at(Location {
                section: Some(section),
                index: None,
                field: None,
            });
            match (pass, section) {
                (Pass::Names, "name") => {
                    let name = map.next_value_seed(Text)?;
                    if crate::domain::blank(name) {
                        return Err(fail(b, Problem::EmptyName));
                    }
                    b.set_name(name);
                }
                (Pass::Names, "facts") => {
                    map.next_value_seed(NameList(&mut *b, ListKind::DeclareFacts))?;
                }
                (Pass::Names, "events") => {
                    map.next_value_seed(NameList(&mut *b, ListKind::DeclareEvents))?;
                }
                (Pass::Behaviours, "sensors") => {
                    map.next_value_seed(Entries(&mut *b, Section::Sensors))?
                }
                (Pass::Behaviours, "actions") => {
                    map.next_value_seed(Entries(&mut *b, Section::Actions))?
                }
                (Pass::Plans, "plans") => map.next_value_seed(Entries(&mut *b, Section::Plans))?,
                (Pass::Plans, "task") => map.next_value_seed(Entries(&mut *b, Section::Task))?,
                _ => {
                    map.next_value::<IgnoredAny>()?;
                }
            }
        }
    }
}

/// Facts that can ever hold, ignoring deletions (relaxed reachability): `init`, everything a
/// sensor perceives, and the `add` of every action whose `pre` can hold. O(NA²).
pub fn reachable<const NS: usize, const NA: usize, const W: usize, const NF: usize>(
    domain: &Domain<'_, NS, NA, W, NF>,
    init: FactSetOf<W>,
) -> FactSetOf<W> {
    let mut facts = domain
        .sensors()
        .iter()
        .fold(init, |acc, s| acc.union(s.per));
    loop {
        let next = domain
            .actions()
            .iter()
            .filter(|a| a.pre.is_subset(facts))
            .fold(facts, |acc, a| acc.union(a.add));
        if next == facts {
            return facts;
        }
        facts = next;
    }
}

/// The deepest nesting of arrays and objects a mission may have. The format itself needs 4
/// (`plans[i].body[j]`); deeper input is refused before parsing, because skipping an unknown
/// value recurses once per level and a microcontroller's stack is small.
pub const MAX_DEPTH: usize = 8;

/// Whether arrays and objects in `json` nest deeper than `limit`, outside strings. O(n).
#[cfg(feature = "loader")]
fn too_deep(json: &[u8], limit: usize) -> Option<Location> {
    let (mut depth, mut in_string, mut escaped) = (0usize, false, false);
    // Where the scan is: the last string read at the top level, the top-level key whose value
    // it is in, and the element of that value's list.
    let (mut string_at, mut key, mut index, mut list) = (0usize, None, 0u16, false);
    let mut last_string: &[u8] = &[];
    for (i, &c) in json.iter().enumerate() {
        if in_string {
            match (escaped, c) {
                (true, _) => escaped = false,
                (false, b'\\') => escaped = true,
                (false, b'"') => {
                    in_string = false;
                    if depth == 1 {
                        last_string = json.get(string_at..i).unwrap_or_default();
                    }
                }
                _ => {}
            }
            continue;
        }
        match c {
            b'"' => {
                in_string = true;
                string_at = i.saturating_add(1);
            }
            b':' if depth == 1 => {
                key = TOP_KEYS
                    .iter()
                    .find(|k| k.as_bytes() == last_string)
                    .copied();
                (index, list) = (0, false);
            }
            b',' if depth == 2 && list => index = index.saturating_add(1),
            b'[' | b'{' => {
                depth = depth.saturating_add(1);
                if depth == 2 {
                    list = c == b'[';
                }
                if depth > limit {
                    return Some(Location {
                        section: key,
                        index: (list && depth > 2).then_some(index),
                        field: None,
                    });
                }
            }
            b']' | b'}' => depth = depth.saturating_sub(1),
            _ => {}
        }
    }
    None
}

/// A mission file's hash, as a flight recording's header names its mission: FNV-1a over its
/// bytes, at compile time or at run time.
#[allow(clippy::indexing_slicing, clippy::arithmetic_side_effects)]
pub const fn mission_hash(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut i = 0;
    // `i < len` keeps the index in range; a `while` because `for` is not `const`.
    while i < bytes.len() {
        h ^= bytes[i] as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
        i += 1;
    }
    h
}

/// Loads a mission file, binding its behaviours through `registry`.
///
/// Errors say what and where ([`LoadError`]): JSON that does not parse, an unknown field or
/// fact or event or action, a duplicate name, a capacity exceeded (naming the limit), an empty
/// plan body, a goal no action can ever add, a behaviour the platform does not have, nesting
/// deeper than [`MAX_DEPTH`].
///
/// ```
/// use psmpa_model::mission::{AnyBehaviour, Loaded, load};
///
/// let json = br#"{ "name": "hello", "facts": ["clear", "there"], "events": ["go"],
///   "sensors": [{ "name": "bumper", "per": ["clear"], "mode": "cyclic", "period_ms": 20 }],
///   "actions": [{ "name": "drive", "pre": ["clear"], "add": ["there"] }],
///   "plans": [{ "name": "go there", "trigger": "go", "context": [], "body": ["drive"] }],
///   "task": { "event": "go", "init": [], "goal": ["there"] } }"#;
/// // 1 sensor, 1 action, 1 plan of at most 1 action; fact sets of one word (64 facts).
/// let loaded: Loaded<'_, (), (), 1, 1, 1, 1> = load(json, &AnyBehaviour).unwrap();
/// let domain = &loaded.mission.domain;
/// assert_eq!(domain.names(loaded.mission.task.goal).to_string(), "{there}");
///
/// // Errors say where: an action that does not exist.
/// let bad = core::str::from_utf8(json).unwrap().replace(r#"["drive"]"#, r#"["fly"]"#);
/// let error = load::<_, 1, 1, 1, 1, 1, 64>(bad.as_bytes(), &AnyBehaviour).unwrap_err();
/// assert!(error.to_string().contains("plans[0].body"), "{error}");
/// ```
#[cfg(feature = "loader")]
pub fn load<
    'a,
    R: Registry,
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const W: usize,
    const NF: usize,
>(
    json: &'a [u8],
    registry: &R,
) -> Result<Loaded<'a, R::Sensor, R::Action, NS, NA, NP, L, W, NF>, LoadError<'a>> {
    let mut out = Loaded::empty();
    load_into(json, registry, &mut out.mission, &mut out.bindings)?;
    Ok(out)
}

/// [`load`] into `mission` and `bindings`, in place: the mission is never copied, which keeps
/// a microcontroller's stack small. Both are emptied first; after an error they hold what was
/// read so far.
#[cfg(feature = "loader")]
pub fn load_into<
    'a,
    R: Registry,
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const W: usize,
    const NF: usize,
>(
    json: &'a [u8],
    registry: &R,
    mission: &mut Tables<'a, NS, NA, NP, L, W, NF>,
    bindings: &mut Bindings<R::Sensor, R::Action, NS, NA>,
) -> Result<(), LoadError<'a>> {
    // Emptied in place: assigning empty ones would build them on the stack first.
    mission.name = "";
    mission.domain.clear();
    mission.library.clear();
    mission.task = Task {
        event: EventId::FIRST,
        init: FactSetOf::EMPTY,
        goal: FactSetOf::EMPTY,
    };
    bindings.clear();
    if let Some(at) = too_deep(json, MAX_DEPTH) {
        return Err(LoadError {
            at,
            problem: Problem::TooDeep,
        });
    }
    let mut b: Builder<'a, '_, R, NS, NA, NP, L, W, NF> = Builder {
        mission,
        bindings,
        registry,
        at: Location::default(),
        error: None,
        body: Vec::new(),
    };
    let mut seen = 0u16;
    for pass in [Pass::Names, Pass::Behaviours, Pass::Plans] {
        let mut de = serde_json_core::de::Deserializer::new(json, None);
        let parsed = Top(&mut b, pass, &mut seen)
            .deserialize(&mut de)
            .and_then(|()| de.end().map(|_| ()));
        if let Err(e) = parsed {
            return Err(b.error.unwrap_or(LoadError {
                at: b.at,
                problem: Problem::Json(match e {
                    serde_json_core::de::Error::InvalidType => JsonError::Type,
                    serde_json_core::de::Error::InvalidNumber => JsonError::Number,
                    // Every other custom error is recorded in `b.error` first: this one is
                    // `Str`'s.
                    serde_json_core::de::Error::InvalidEscapeSequence
                    | serde_json_core::de::Error::EscapedStringIsTooLong
                    | serde_json_core::de::Error::CustomError => JsonError::Escape,
                    _ => JsonError::Syntax,
                }),
            }));
        }
    }
    let missing = TOP_KEYS
        .iter()
        .enumerate()
        .find(|(i, _)| seen & (1 << i) == 0 && OPTIONAL_TOP & (1 << i) == 0);
    if let Some((_, key)) = missing {
        return Err(LoadError {
            at: Location::default(),
            problem: Problem::MissingField(key),
        });
    }
    let m = &*b.mission;
    let possible = reachable(&m.domain, m.task.init);
    if let Some(fact) = m.task.goal.difference(possible).iter().next() {
        return Err(LoadError {
            at: Location {
                section: Some("task"),
                index: None,
                field: Some("goal"),
            },
            problem: Problem::UnreachableGoal(m.domain.fact_name(fact).unwrap_or("?")),
        });
    }
    Ok(())
}

/// A loaded mission and the platform behaviours bound to its sensors and actions.
#[derive(Clone, Debug)]
pub struct Loaded<
    'a,
    S,
    A,
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const W: usize = 1,
    const NF: usize = 64,
> {
    /// The mission.
    pub mission: Tables<'a, NS, NA, NP, L, W, NF>,
    /// The behaviour of every sensor and action id.
    pub bindings: Bindings<S, A, NS, NA>,
}

impl<
    S,
    A,
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const W: usize,
    const NF: usize,
> Loaded<'_, S, A, NS, NA, NP, L, W, NF>
{
    /// Nothing loaded yet; usable in a `static`.
    pub const fn empty() -> Self {
        Self {
            mission: Tables::empty(),
            bindings: Bindings::new(),
        }
    }
}

impl<
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const W: usize,
    const NF: usize,
> Tables<'_, NS, NA, NP, L, W, NF>
{
    /// A mission with nothing in it; usable in a `static`.
    pub const fn empty() -> Self {
        Self {
            name: "",
            domain: Domain::new(),
            library: PlanLibrary::new(),
            task: Task {
                event: EventId::FIRST,
                init: FactSetOf::EMPTY,
                goal: FactSetOf::EMPTY,
            },
        }
    }
}

#[cfg(all(test, feature = "loader"))]
mod tests {
    use super::*;
    use crate::facts::FactSet;
    use std::string::{String, ToString};

    const FETCH_TEA: &[u8] = include_bytes!("../../missions/fetch-tea.json");

    /// The platform of the tests: knows every behaviour of fetch-tea.json except `teleport`.
    struct Platform;
    impl Registry for Platform {
        type Sensor = u8;
        type Action = u8;
        fn sensor(&self, name: &str) -> Option<u8> {
            ["sonar", "bumper", "camera", "handle"]
                .iter()
                .position(|n| *n == name)
                .map(|i| i as u8 + 10)
        }
        fn action(&self, name: &str) -> Option<u8> {
            (name != "teleport").then_some(name.len() as u8)
        }
    }

    type M<'a> = Loaded<'a, u8, u8, 4, 8, 4, 4>;

    fn load_str(json: &str) -> Result<M<'_>, LoadError<'_>> {
        load(json.as_bytes(), &Platform)
    }

    fn error(json: &str) -> String {
        load_str(json).unwrap_err().to_string()
    }

    /// A domain built in Rust binds its behaviours as a loaded file does; a name the platform
    /// lacks is the error.
    #[test]
    fn a_domain_built_in_rust_binds_its_behaviours_through_a_registry() {
        #[derive(Clone, Copy, Debug, PartialEq)]
        enum Dev {
            Bumper,
            Wheels,
        }
        struct Robot;
        impl Registry for Robot {
            type Sensor = Dev;
            type Action = Dev;
            fn sensor(&self, name: &str) -> Option<Dev> {
                (name == "bumper").then_some(Dev::Bumper)
            }
            fn action(&self, name: &str) -> Option<Dev> {
                (name == "drive").then_some(Dev::Wheels)
            }
        }
        let mut d: Domain<'_, 1, 2> = Domain::new();
        let clear = d.add_fact("clear").unwrap();
        let bumper = d
            .add_sensor(SensorAction::new(
                "bumper",
                FactSet::single(clear),
                SensorMode::OneShot,
            ))
            .unwrap();
        let drive = d
            .add_action(ActuatorAction::new(
                "drive",
                FactSet::single(clear),
                FactSet::EMPTY,
                FactSet::EMPTY,
            ))
            .unwrap();
        let b: Bindings<Dev, Dev, 1, 2> = Bindings::resolve(&d, &Robot).unwrap();
        assert_eq!(b.sensor(bumper), Some(Dev::Bumper));
        assert_eq!(b.action(drive), Some(Dev::Wheels));
        assert_eq!(b.sensor_id(&Dev::Bumper), Some(bumper));
        d.add_action(ActuatorAction::new(
            "fly",
            FactSet::EMPTY,
            FactSet::EMPTY,
            FactSet::EMPTY,
        ))
        .unwrap();
        assert_eq!(
            Bindings::<Dev, Dev, 1, 2>::resolve(&d, &Robot).err(),
            Some("fly")
        );
    }

    #[test]
    fn sensors_actions_and_plans_may_have_a_description_of_any_value() {
        let json = r#"{"name": "m", "facts": ["a", "b"], "events": ["go"],
            "sensors": [{"name": "s", "per": ["a"], "mode": "one-shot",
                         "description": "looks ahead"}],
            "actions": [{"name": "x", "pre": ["a"], "add": ["b"],
                         "description": {"why": ["any", 1, true]}}],
            "plans": [{"name": "p", "trigger": "go", "body": ["x"], "description": "the way"}],
            "task": {"event": "go", "goal": ["b"]}}"#;
        let m: Loaded<'_, (), (), 1, 1, 1, 1> = load(json.as_bytes(), &AnyBehaviour).unwrap();
        assert_eq!(m.mission.domain.sensors().len(), 1);
        // Not on the task: it has no name to describe.
        let task = json.replace(r#""goal": ["b"]}"#, r#""goal": ["b"], "description": "t"}"#);
        let error = load::<_, 1, 1, 1, 1, 1, 64>(task.as_bytes(), &AnyBehaviour).unwrap_err();
        assert_eq!(error.to_string(), "task: unknown field `description`");
    }

    #[test]
    fn fetch_tea_loads_with_names_resolved_and_behaviours_bound() {
        let m: M<'_> = load(FETCH_TEA, &Platform).unwrap();
        let d = &m.mission.domain;
        assert_eq!(m.mission.name, "fetch-tea");
        assert_eq!(d.fact_names().len(), 8);
        let sonar = d.sensor_id("sonar").unwrap();
        assert_eq!(
            d.sensor(sonar).unwrap().mode,
            SensorMode::Cyclic {
                period: Duration::from_millis(100)
            }
        );
        let handle = d.sensor_id("handle").unwrap();
        assert_eq!(d.sensor(handle).unwrap().mode, SensorMode::OnDemand);
        assert_eq!(m.bindings.sensor(handle), Some(13));
        let open = d.action_id("open door").unwrap();
        assert_eq!(
            d.action(open).unwrap().pre,
            d.facts(&["at_door", "handle_seen", "door_unlocked"])
                .unwrap()
        );
        assert_eq!(m.bindings.action(open), Some(9));
        // And back, from a behaviour to its id.
        assert_eq!(m.bindings.sensor_id(&13), Some(handle));
        assert_eq!(m.bindings.action_id(&9), Some(open));
        assert_eq!(m.bindings.sensor_id(&99), None);
        let plan = &m.mission.library.plans()[0];
        assert_eq!(plan.name, "GetIn Kitchen");
        assert_eq!(plan.body.len(), 3);
        assert_eq!(m.mission.task.goal, d.facts(&["in_kitchen"]).unwrap());
        assert_eq!(m.mission.task.init, d.facts(&["door_unlocked"]).unwrap());
    }

    const SMALL: &str = r#"{"name": "m", "facts": ["a", "b"], "events": ["go"],
        "sensors": [{"name": "sonar", "per": ["a"], "mode": "cyclic", "period_ms": 50}],
        "actions": [{"name": "x", "pre": ["a"], "add": ["b"]}],
        "plans": [{"name": "p", "trigger": "go", "body": ["x"]}],
        "task": {"event": "go", "goal": ["b"]}}"#;

    #[test]
    fn nesting_deeper_than_the_limit_is_refused_before_parsing() {
        let nested = |depth: usize| {
            let mut json = String::from(SMALL.strip_suffix('}').unwrap());
            json.push_str(", \"description\": ");
            json.extend(core::iter::repeat_n('[', depth));
            json.push_str("\"[[[[[[[[[[ in a string \\\" [[[[[[\"");
            json.extend(core::iter::repeat_n(']', depth));
            json.push('}');
            json
        };
        // The top-level object is one level, the description the rest.
        assert!(load_str(&nested(MAX_DEPTH - 1)).is_ok());
        let deep = nested(MAX_DEPTH);
        assert_eq!(load_str(&deep).unwrap_err().problem, Problem::TooDeep);
        // Named where it is: the key whose value nests too deep.
        assert_eq!(error(&deep), "description[0]: nested deeper than 8 levels");
        let in_plans = SMALL.replace(
            r#""body": ["x"]}]"#,
            r#""body": ["x"]}, {"name": [[[[[[[[[]]]]]]]]]}]"#,
        );
        assert_eq!(error(&in_plans), "plans[1]: nested deeper than 8 levels");
        // What a microcontroller's stack could never parse is refused just as fast.
        let hostile = nested(100_000);
        assert_eq!(load_str(&hostile).unwrap_err().problem, Problem::TooDeep);
    }

    #[test]
    fn key_order_does_not_matter() {
        let reversed = r#"{"task": {"goal": ["b"], "event": "go"},
            "plans": [{"body": ["x"], "trigger": "go", "name": "p"}],
            "actions": [{"add": ["b"], "pre": ["a"], "name": "x"}],
            "sensors": [{"mode": "cyclic", "period_ms": 50, "per": ["a"], "name": "sonar"}],
            "events": ["go"], "facts": ["a", "b"], "name": "m"}"#;
        let a = load_str(SMALL).unwrap();
        let b = load_str(reversed).unwrap();
        assert_eq!(a.mission.domain.actions(), b.mission.domain.actions());
        assert_eq!(a.mission.library.plans(), b.mission.library.plans());
        assert_eq!(a.mission.task, b.mission.task);
    }

    #[test]
    fn an_action_may_set_its_own_max_violation_and_a_plan_facts_that_must_be_false() {
        let json = with(r#""add": ["b"]"#, r#""add": ["b"], "max_violation_ms": 0"#).replacen(
            r#""trigger": "go""#,
            r#""trigger": "go", "context_not": ["b"]"#,
            1,
        );
        let m = load_str(&json).unwrap();
        let d = &m.mission.domain;
        let x = d.action(d.action_id("x").unwrap()).unwrap();
        assert_eq!(x.max_violation, Some(Duration::from_millis(0)));
        let plan = &m.mission.library.plans()[0];
        assert_eq!(plan.context_not, d.facts(&["b"]).unwrap());
        let go = m.mission.task.event;
        assert!(plan.applicable(go, FactSet::EMPTY));
        assert!(!plan.applicable(go, d.facts(&["b"]).unwrap()));
        // Without the keys: the runtime's default, and no negative context.
        let plain = load_str(SMALL).unwrap();
        let d = &plain.mission.domain;
        assert_eq!(
            d.action(d.action_id("x").unwrap()).unwrap().max_violation,
            None
        );
        assert_eq!(plain.mission.library.plans()[0].context_not, FactSet::EMPTY);
    }

    fn with(from: &str, to: &str) -> String {
        assert!(SMALL.contains(from), "{from}");
        SMALL.replacen(from, to, 1)
    }

    #[test]
    fn errors_say_what_and_where() {
        let cases = [
            (
                with(r#""pre": ["a"]"#, r#""pre": ["c"]"#),
                "actions[0].pre: unknown fact `c` (not in `facts`)",
            ),
            (
                with(r#""facts": ["a", "b"]"#, r#""facts": ["a", "a", "b"]"#),
                "facts[1]: duplicate name `a`",
            ),
            (
                with(r#""body": ["x"]"#, r#""body": ["x", "y"]"#),
                "plans[0].body: unknown action `y` (not in `actions`)",
            ),
            (
                with(r#""body": ["x"]"#, r#""body": []"#),
                "plans[0].body: the plan body is empty",
            ),
            (
                with(r#""goal": ["b"]"#, r#""goal": ["a", "c"]"#),
                "task.goal: unknown fact `c` (not in `facts`)",
            ),
            (
                with(r#""trigger": "go""#, r#""trigger": "stop""#),
                "plans[0].trigger: unknown event `stop` (not in `events`)",
            ),
            (
                with(r#""mode": "cyclic""#, r#""mode": "sometimes""#),
                "sensors[0].mode: unknown sensor mode `sometimes`, expected `cyclic`, `one-shot` or `on-demand`",
            ),
            (
                with(r#""period_ms": 50"#, r#""period_ms": 0"#),
                "sensors[0].period_ms: needs a whole number of milliseconds of at least 1",
            ),
            (
                with(r#""name": "x""#, r#""name": "teleport""#),
                "actions[0].name: the platform has no behaviour called `teleport`",
            ),
            (
                with(r#""name": "sonar""#, r#""name": "lidar""#),
                "sensors[0].name: the platform has no behaviour called `lidar`",
            ),
            (
                with(r#""add": ["b"]"#, r#""add": ["b"], "cost": 3"#),
                "actions[0]: unknown field `cost`",
            ),
            (
                with(r#""name": "m","#, r#""name": "m", "owner": "me","#),
                "top level: unknown field `owner`",
            ),
            (
                with(
                    r#""task": {"event": "go", "goal": ["b"]}"#,
                    r#""task": {"event": "go"}"#,
                ),
                "task: missing field `goal`",
            ),
            (
                with(r#""name": "x","#, r#""name": "","#),
                "actions[0].name: the name is empty or blank",
            ),
            (
                with(r#""name": "x","#, r#""name": "  ","#),
                "actions[0].name: the name is empty or blank",
            ),
            (
                with(r#""name": "p","#, r#""name": "","#),
                "plans[0].name: the name is empty or blank",
            ),
            // Names are compared as written: an escape would make two spellings of one name.
            (
                with(
                    r#""facts": ["a", "b"]"#,
                    r#""facts": ["a", "b", "d/e", "d\/e"]"#,
                ),
                "facts[3]: escape sequences are not allowed in names",
            ),
            (
                with(r#""body": ["x"]"#, r#""body": ["x\y"]"#),
                "plans[0].body: escape sequences are not allowed in names",
            ),
            // The element at fault, even when it is not a string.
            (
                with(r#""facts": ["a", "b"]"#, r#""facts": ["a", "b", 1]"#),
                "facts[2]: a value of the wrong type",
            ),
            (
                with(r#""events": ["go"]"#, r#""events": ["go", 5]"#),
                "events[1]: a value of the wrong type",
            ),
            (
                with(r#""period_ms": 50"#, r#""period_ms": 4294967296"#),
                "sensors[0].period_ms: more than 4294967295 milliseconds",
            ),
            (
                with(
                    r#""mode": "cyclic", "period_ms": 50"#,
                    r#""mode": "one-shot", "period_ms": 50"#,
                ),
                "sensors[0].period_ms: `period_ms` is only for a `cyclic` sensor",
            ),
            (
                with(r#""pre": ["a"]"#, r#""pre": "a""#),
                "actions[0].pre: a value of the wrong type",
            ),
            (
                with(r#""add": ["b"]}"#, r#""add": ["b"]"#),
                "actions: malformed JSON",
            ),
            (
                with(
                    r#""trigger": "go""#,
                    r#""trigger": "go", "context": ["a"], "context_not": ["a"]"#,
                ),
                "plans[0].context_not: fact `a` is in both `context` and `context_not`",
            ),
            (
                with(
                    r#""add": ["b"]"#,
                    r#""add": ["b"], "max_violation_ms": 4294967296"#,
                ),
                "actions[0].max_violation_ms: more than 4294967295 milliseconds",
            ),
            // A fraction or an exponent: the whole number ends before it.
            (
                with(r#""period_ms": 50"#, r#""period_ms": 50.0"#),
                "sensors[0].period_ms: malformed JSON, or not a whole number of milliseconds (no fraction or exponent)",
            ),
            (
                with(
                    r#""add": ["b"]"#,
                    r#""add": ["b"], "max_violation_ms": 1e3"#,
                ),
                "actions[0].max_violation_ms: malformed JSON, or not a whole number of milliseconds (no fraction or exponent)",
            ),
            (
                with(r#""add": ["b"]"#, r#""add": ["b"], "max_violation_ms": -1"#),
                "actions[0].max_violation_ms: not a whole number of milliseconds up to 4294967295 (no sign, fraction or exponent)",
            ),
        ];
        for (json, expected) in cases {
            assert_eq!(error(&json), expected, "{json}");
        }
        // No action adds b and no sensor perceives it.
        let unreachable = with(r#""add": ["b"]"#, r#""add": []"#);
        assert_eq!(
            error(&unreachable),
            "task.goal: goal fact `b` can never hold: no action that adds it can ever start, and no sensor perceives it"
        );
        let no_plans = SMALL.replace(
            r#""plans": [{"name": "p", "trigger": "go", "body": ["x"]}],"#,
            "",
        );
        assert_eq!(error(&no_plans), "top level: missing field `plans`");
    }

    #[test]
    fn capacities_are_named() {
        let many_sensors: String = (0..5)
            .map(|i| std::format!(r#"{{"name": "s{i}", "per": ["a"], "mode": "one-shot"}}"#))
            .collect::<std::vec::Vec<_>>()
            .join(",");
        let json = with(
            r#"{"name": "sonar", "per": ["a"], "mode": "cyclic", "period_ms": 50}"#,
            &many_sensors,
        );
        let err = load(json.as_bytes(), &AnyBehaviour)
            .map(|_: Loaded<'_, (), (), 4, 8, 4, 4>| ())
            .unwrap_err();
        assert_eq!(
            err.to_string(),
            "sensors[4].name: more than 4 sensors (the runtime's capacity)"
        );
        let long = with(r#""body": ["x"]"#, r#""body": ["x", "x", "x", "x", "x"]"#);
        assert_eq!(
            error(&long),
            "plans[0].body: more than 4 actions in a plan body (the runtime's capacity)"
        );
    }

    #[test]
    fn relaxed_reachability_ignores_deletes_and_counts_percepts() {
        let m = load_str(SMALL).unwrap().mission;
        let d = &m.domain;
        // a is perceived by the sonar, so x's pre can hold and b is reachable.
        assert_eq!(reachable(d, FactSet::EMPTY), d.facts(&["a", "b"]).unwrap());
    }
}

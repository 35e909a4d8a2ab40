//! Names instead of indices: display adapters that print failures and trace events with the
//! names of a mission ([`Describe`]), as [`FactNames`] prints a fact set with a domain's. No
//! allocation: they write into the formatter.

use core::fmt;

pub use psmpa_model::names::FactNames;

use crate::action::{ActionId, SensorId, SensorSet};
use crate::domain::EventId;
use crate::facts::FactSetOf;
use crate::failure::Failure;
use crate::plan::{MAX_PLANS, PlanId, PlanSet};
use crate::runtime::control::ControlError;
use crate::spec::{ControlErrorOf, FailureOf, Mission, TraceEventOf};
use crate::trace::TraceEvent;

/// A failure, control error or trace event printed with a mission's names ([`Describe`]).
pub struct Described<'m, M, T> {
    mission: &'m M,
    what: T,
}

/// What the runtime says, in words, with a mission's names: `use psmpa_core::Describe;` then
/// `mission.describe(event)` (`fetch_tea::FetchTea.describe(event)`, or `(&tables).describe(..)`
/// for a mission loaded at run time).
pub trait Describe: Mission + Sized {
    /// A trace event in words, with this mission's names: "state entered: go to door with
    /// [sonar bumper]", "precondition of go to door violated: {path_clear}".
    fn describe(&self, event: TraceEventOf<Self>) -> Described<'_, Self, TraceEventOf<Self>> {
        Described {
            mission: self,
            what: event,
        }
    }

    /// Why the control loop stopped, in words, with this mission's names: "no plan for
    /// fetch_tea could start: passed over GetIn Kitchen; known false {path_clear}".
    fn describe_error(
        &self,
        error: ControlErrorOf<Self>,
    ) -> Described<'_, Self, ControlErrorOf<Self>> {
        Described {
            mission: self,
            what: error,
        }
    }

    /// A failure in words, with this mission's names.
    fn describe_failure(&self, failure: FailureOf<Self>) -> Described<'_, Self, FailureOf<Self>> {
        Described {
            mission: self,
            what: failure,
        }
    }
}

impl<M: Mission> Describe for M {}

/// A fact set with the names of facts `names` (by id): `{path_clear, at_door}`, an undeclared
/// fact as `#index`.
pub(crate) fn fact_names<const W: usize>(names: &[&str], set: FactSetOf<W>) -> impl fmt::Display {
    fmt::from_fn(move |f| {
        f.write_str("{")?;
        for (i, fact) in set.iter().enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            match names.get(fact.index()) {
                Some(name) => f.write_str(name)?,
                None => write!(f, "#{}", fact.index())?,
            }
        }
        f.write_str("}")
    })
}

/// What names the ids an error or event holds: a mission (its names, [`Names`]) or nothing
/// (the ids themselves, [`Ids`]: the plain `Display` of an error).
trait Namer<const W: usize> {
    fn action(&self, a: ActionId) -> impl fmt::Display;
    fn sensor(&self, s: SensorId) -> impl fmt::Display;
    fn plan(&self, p: PlanId) -> impl fmt::Display;
    fn event(&self, e: EventId) -> impl fmt::Display;
    fn facts(&self, set: FactSetOf<W>) -> impl fmt::Display;

    fn plans(&self, f: &mut fmt::Formatter<'_>, set: PlanSet) -> fmt::Result {
        let ids = (0..MAX_PLANS)
            .filter_map(PlanId::new)
            .filter(|p| set.contains(*p));
        for (i, p) in ids.enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            write!(f, "{}", self.plan(p))?;
        }
        Ok(())
    }
    /// "; sensors out of service [sonar]" when any is.
    fn out_of_service(&self, f: &mut fmt::Formatter<'_>, faulty: SensorSet) -> fmt::Result {
        if faulty.is_empty() {
            return Ok(());
        }
        f.write_str("; sensors out of service ")?;
        self.sensors(f, faulty)
    }
    fn sensors(&self, f: &mut fmt::Formatter<'_>, set: SensorSet) -> fmt::Result {
        f.write_str("[")?;
        for (i, s) in set.iter().enumerate() {
            if i > 0 {
                f.write_str(" ")?;
            }
            write!(f, "{}", self.sensor(s))?;
        }
        f.write_str("]")
    }
}

/// The names the adapters print: a mission's.
struct Names<'m, M>(&'m M);

impl<M: Mission<Facts = FactSetOf<W>>, const W: usize> Namer<W> for Names<'_, M> {
    fn action(&self, a: ActionId) -> impl fmt::Display {
        self.0.actions().get(a.index()).map_or("?", |a| a.name)
    }
    fn sensor(&self, s: SensorId) -> impl fmt::Display {
        self.0.sensors().get(s.index()).map_or("?", |s| s.name)
    }
    fn plan(&self, p: PlanId) -> impl fmt::Display {
        self.0.plan(p).map_or("generated plan", |p| p.name)
    }
    fn event(&self, e: EventId) -> impl fmt::Display {
        self.0.event_names().get(e.index()).copied().unwrap_or("?")
    }
    fn facts(&self, set: FactSetOf<W>) -> impl fmt::Display {
        fact_names(self.0.fact_names(), set)
    }
}

/// No names: each id as its kind and index ("action #2", facts as `{0, 3}`).
struct Ids;

impl<const W: usize> Namer<W> for Ids {
    fn action(&self, a: ActionId) -> impl fmt::Display {
        fmt::from_fn(move |f| write!(f, "action #{}", a.index()))
    }
    fn sensor(&self, s: SensorId) -> impl fmt::Display {
        fmt::from_fn(move |f| write!(f, "sensor #{}", s.index()))
    }
    fn plan(&self, p: PlanId) -> impl fmt::Display {
        fmt::from_fn(move |f| write!(f, "plan #{}", p.index()))
    }
    fn event(&self, e: EventId) -> impl fmt::Display {
        fmt::from_fn(move |f| write!(f, "event #{}", e.index()))
    }
    fn facts(&self, set: FactSetOf<W>) -> impl fmt::Display {
        fmt::from_fn(move |f| write!(f, "{set:?}"))
    }
}

fn failure<const W: usize>(
    n: &impl Namer<W>,
    what: Failure<W>,
    f: &mut fmt::Formatter<'_>,
) -> fmt::Result {
    match what {
        Failure::ActionFailed { action } => write!(f, "{} failed", n.action(action)),
        Failure::ActionInterrupted { action } => {
            write!(f, "{} was interrupted", n.action(action))
        }
        Failure::PreconditionUnmet { action, missing } => write!(
            f,
            "{} could not start: {} did not hold",
            n.action(action),
            n.facts(missing)
        ),
        Failure::PreconditionViolated { action, missing } => write!(
            f,
            "{} stopped: {} stayed false longer than its max_violation",
            n.action(action),
            n.facts(missing)
        ),
        Failure::SensorUnavailable { sensor } => {
            write!(f, "{} is unavailable", n.sensor(sensor))
        }
        Failure::SensorFault { sensor, fault } => {
            write!(f, "{} failed: {fault:?}", n.sensor(sensor))
        }
        Failure::StoreFull { key } => write!(f, "a data store is full (key {})", key.0),
        Failure::InvalidFsm { state } => write!(f, "the FSM has no state {state}"),
        Failure::SensingStalled => f.write_str("the sensing side does not run"),
    }
}

fn control_error<const W: usize, N: Namer<W>>(
    n: &N,
    what: ControlError<W>,
    f: &mut fmt::Formatter<'_>,
) -> fmt::Result {
    use ControlError as E;
    let failure = |last| fmt::from_fn(move |f| failure(n, last, f));
    match what {
        E::NoApplicablePlan { event, beliefs } => write!(
            f,
            "no plan applies to {} under {}",
            n.event(event),
            n.facts(beliefs)
        ),
        E::Inapplicable {
            event,
            skipped,
            known_false,
            unknown,
            faulty,
        } => {
            write!(
                f,
                "no plan for {} could start: passed over ",
                n.event(event)
            )?;
            n.plans(f, skipped)?;
            if !known_false.is_empty() {
                write!(f, "; known false {}", n.facts(known_false))?;
            }
            if !unknown.is_empty() {
                write!(f, "; never sensed {}", n.facts(unknown))?;
            }
            n.out_of_service(f, faulty)
        }
        E::Exhausted {
            event,
            failed,
            beliefs,
            faulty,
        } => {
            write!(f, "every plan for {} failed: ", n.event(event))?;
            n.plans(f, failed)?;
            write!(f, " (beliefs {})", n.facts(beliefs))?;
            n.out_of_service(f, faulty)
        }
        E::TooManyFailures { failures, last } => {
            write!(f, "{failures} plans failed, the last: {}", failure(last))
        }
        E::PlanLimit { plans } => write!(f, "{plans} plans ran without reaching the goal"),
        E::Compile { plan, error } => {
            write!(f, "{} does not compile: {error}", n.plan(plan))
        }
        E::Planning { error, faulty } => {
            write!(f, "no library plan could run, and the planner: {error}")?;
            n.out_of_service(f, faulty)
        }
        E::InitialModel { failure: first } => write!(
            f,
            "the initial model could not be established: {}",
            failure(first)
        ),
    }
}

fn trace_event<const W: usize>(
    n: &impl Namer<W>,
    what: TraceEvent<W>,
    f: &mut fmt::Formatter<'_>,
) -> fmt::Result {
    use TraceEvent as E;
    match what {
        E::ModelEstablished { beliefs } => write!(f, "model established {}", n.facts(beliefs)),
        E::PlanGenerated { length, expanded } => write!(
            f,
            "no library plan could run: the planner generated {length} actions ({expanded} nodes expanded)"
        ),
        E::PlanSelected { plan, .. } => write!(f, "plan selected: {}", n.plan(plan)),
        E::PlanSucceeded { plan } => write!(f, "plan succeeded: {}", n.plan(plan)),
        E::PlanFailed { plan, reason } => write!(
            f,
            "plan failed: {} ({})",
            n.plan(plan),
            fmt::from_fn(|f| failure(n, reason, f))
        ),
        E::StateEntered {
            action, sensors, ..
        } => {
            write!(f, "state entered: {} with ", n.action(action))?;
            n.sensors(f, sensors)
        }
        E::StateLeft {
            action, outcome, ..
        } => match outcome {
            Some(o) => write!(f, "state left: {} {o:?}", n.action(action)),
            None => write!(f, "state left: {} cut short", n.action(action)),
        },
        E::PhaseStarted { phase, .. } => write!(f, "{phase:?} phase"),
        E::SensorOn { sensor } => write!(f, "{} on", n.sensor(sensor)),
        E::SensorOff { sensor } => write!(f, "{} off", n.sensor(sensor)),
        E::Sample {
            sensor,
            value,
            holds,
        } => write!(
            f,
            "{} sample {value:?}, holds {}",
            n.sensor(sensor),
            n.facts(holds)
        ),
        E::SampleLost { sensor } => write!(f, "{} sample lost", n.sensor(sensor)),
        E::SensorFailed { sensor, fault } => {
            write!(f, "{} fault {fault:?}", n.sensor(sensor))
        }
        E::PreconditionViolated { action, missing } => write!(
            f,
            "precondition of {} violated: {} false",
            n.action(action),
            n.facts(missing)
        ),
        E::PreconditionRestored { action } => {
            write!(f, "precondition of {} restored", n.action(action))
        }
        E::EffectsApplied { action, beliefs } => write!(
            f,
            "effects of {} applied: {}",
            n.action(action),
            n.facts(beliefs)
        ),
        E::GoalReached { beliefs } => write!(f, "goal reached: {}", n.facts(beliefs)),
        E::User { code, value } => write!(f, "user event {code}: {value}"),
    }
}

/// Implements `Display` for an adapter with a mission's names, and for the plain value with ids.
macro_rules! displays {
    ($ty:ident, $with:ident) => {
        impl<M: Mission<Facts = FactSetOf<W>>, const W: usize> fmt::Display
            for Described<'_, M, $ty<W>>
        {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                $with(&Names(self.mission), self.what, f)
            }
        }

        /// In words, with ids for names (`action #2`); [`Describe`] prints a mission's names.
        impl<const W: usize> fmt::Display for $ty<W> {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                $with(&Ids, *self, f)
            }
        }
    };
}

displays!(Failure, failure);
displays!(ControlError, control_error);
displays!(TraceEvent, trace_event);

impl<const W: usize> core::error::Error for Failure<W> {}
impl<const W: usize> core::error::Error for ControlError<W> {}

#[cfg(test)]
mod tests {
    use std::format;

    use crate::mission::{AnyBehaviour, Loaded, load};
    use crate::{Describe, FactSet, Failure, Reading, TraceEvent, Value};

    const MISSION: &str = r#"{"name": "m", "facts": ["clear", "done"], "events": ["go"],
        "sensors": [{"name": "sonar", "per": ["clear"], "mode": "cyclic", "period_ms": 50}],
        "actions": [{"name": "walk", "pre": ["clear"], "add": ["done"]}],
        "plans": [{"name": "p", "trigger": "go", "body": ["walk"]}],
        "task": {"event": "go", "goal": ["done"]}}"#;

    #[test]
    fn events_and_failures_read_with_the_missions_names() {
        let loaded: Loaded<'_, (), (), 1, 1, 1, 1> =
            load(MISSION.as_bytes(), &AnyBehaviour).unwrap();
        let m = &&loaded.mission;
        let d = &m.domain;
        let clear = d.facts(&["clear"]).unwrap();
        let walk = d.action_id("walk").unwrap();
        let violated = TraceEvent::PreconditionViolated {
            action: walk,
            missing: clear,
        };
        assert_eq!(
            format!("{}", m.describe(violated)),
            "precondition of walk violated: {clear} false"
        );
        let failed = Failure::PreconditionViolated {
            action: walk,
            missing: clear,
        };
        assert_eq!(
            format!("{}", m.describe_failure(failed)),
            "walk stopped: {clear} stayed false longer than its max_violation"
        );
        // An undeclared fact prints as its index.
        let odd = clear.with(crate::FactId::new(5).unwrap());
        assert_eq!(format!("{:?}", d.names(odd)), "{clear, #5}");
        // A reading from a bool decides all of per(s) one way.
        assert_eq!(Reading::of(Value::Mm(5), true).holds, FactSet::ALL);
        assert_eq!(Reading::flag(false).holds, FactSet::EMPTY);
        assert_eq!(Reading::<1>::flag(true).value, Value::Bool(true));
    }

    #[test]
    fn errors_print_with_ids_and_go_into_an_application_error() {
        use crate::{ActionId, ControlError, FsmError, Key, PlanId, SensorId, StoreFull};
        use std::boxed::Box;
        use std::string::ToString;
        let walk = ActionId::new(2).unwrap();
        let failed = Failure::<1>::ActionFailed { action: walk };
        assert_eq!(failed.to_string(), "action #2 failed");
        let error = ControlError::<1>::TooManyFailures {
            failures: 3,
            last: Failure::SensorFault {
                sensor: SensorId::new(1).unwrap(),
                fault: crate::SensorFault::Timeout,
            },
        };
        assert_eq!(
            error.to_string(),
            "3 plans failed, the last: sensor #1 failed: Timeout"
        );
        let compile = ControlError::<1>::Compile {
            plan: PlanId::new(0).unwrap(),
            error: FsmError::EmptyBody,
        };
        assert_eq!(
            compile.to_string(),
            "plan #0 does not compile: its body is empty"
        );
        // `?` into an application's error: each is a `core::error::Error`.
        fn app(e: impl core::error::Error + 'static) -> Result<(), Box<dyn core::error::Error>> {
            Err(e)?
        }
        let full = StoreFull {
            key: Key(7),
            value: Value::Bool(true),
            capacity: 4,
        };
        assert_eq!(
            app(full).unwrap_err().to_string(),
            "a data store of 4 keys is full: no room for key 7"
        );
        // The others: that they are errors is what compiles here; their text is checked above
        // or is one fixed string each.
        fn is_error<E: core::error::Error>() {}
        is_error::<ControlError<1>>();
        is_error::<Failure<1>>();
        is_error::<crate::SensorFault>();
        is_error::<crate::DomainError>();
        is_error::<crate::PlanError>();
        is_error::<FsmError>();
        assert_eq!(crate::SensorFault::Device(3).to_string(), "device error 3");
    }

    /// Names, not indices, in a defmt log: the names go out as strings, in the set's order,
    /// and an undeclared fact as its index. `cargo test -p psmpa-core --features
    /// defmt,defmt/unstable-test --lib text::tests` (defmt's host encoder).
    #[cfg(feature = "defmt")]
    #[test]
    fn fact_names_reach_a_defmt_log_as_names() {
        let m: Loaded<'_, (), (), 1, 1, 1, 1> = load(MISSION.as_bytes(), &AnyBehaviour).unwrap();
        let d = &m.mission.domain;
        let set = d.facts(&["clear", "done"]).unwrap();
        let _ = defmt::export::fetch_bytes();
        defmt::Format::format(&d.names(set), defmt::export::make_formatter());
        let bytes = defmt::export::fetch_bytes();
        let at = |bytes: &[u8], name: &[u8]| bytes.windows(name.len()).position(|w| w == name);
        assert!(
            at(&bytes, b"clear").unwrap() < at(&bytes, b"done").unwrap(),
            "{bytes:?}"
        );
        // An undeclared fact: no name, its index (5) encoded as a number.
        let odd = FactSet::single(crate::FactId::new(5).unwrap());
        defmt::Format::format(&d.names(odd), defmt::export::make_formatter());
        let bytes = defmt::export::fetch_bytes();
        assert_eq!(at(&bytes, b"clear"), None, "{bytes:?}");
        assert!(at(&bytes, &5u32.to_le_bytes()).is_some(), "{bytes:?}");
    }
}

//! Names instead of indices: display adapters that print failures and trace events with the
//! names of a mission ([`Describe`]), as [`FactNames`] prints a fact set with a domain's. No
//! allocation: they write into the formatter.

use core::fmt;

pub use psmpa_model::names::FactNames;

use crate::action::SensorSet;
use crate::failure::Failure;
use crate::mission::Mission;
use crate::plan::{MAX_PLANS, PlanId, PlanSet};
use crate::runtime::control::ControlError;
use crate::trace::TraceEvent;

/// A failure or trace event printed with a mission's names ([`Describe`]).
pub struct Described<
    'm,
    'a,
    T,
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const W: usize = 1,
    const NF: usize = 64,
> {
    mission: &'m Mission<'a, NS, NA, NP, L, W, NF>,
    what: T,
}

/// What the runtime says, in words, with a mission's names: `use psmpa_core::Describe;` then
/// `mission.describe(event)`.
pub trait Describe<
    'a,
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const W: usize,
    const NF: usize,
>
{
    /// A trace event in words, with this mission's names: "state entered: go to door with
    /// [sonar bumper]", "precondition of go to door violated: {path_clear}".
    fn describe(
        &self,
        event: TraceEvent<W>,
    ) -> Described<'_, 'a, TraceEvent<W>, NS, NA, NP, L, W, NF>;

    /// Why the control loop stopped, in words, with this mission's names: "no plan for
    /// fetch_tea could start: passed over GetIn Kitchen; known false {path_clear}".
    fn describe_error(
        &self,
        error: ControlError<W>,
    ) -> Described<'_, 'a, ControlError<W>, NS, NA, NP, L, W, NF>;

    /// A failure in words, with this mission's names.
    fn describe_failure(
        &self,
        failure: Failure<W>,
    ) -> Described<'_, 'a, Failure<W>, NS, NA, NP, L, W, NF>;
}

impl<
    'a,
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const W: usize,
    const NF: usize,
> Describe<'a, NS, NA, NP, L, W, NF> for Mission<'a, NS, NA, NP, L, W, NF>
{
    fn describe(
        &self,
        event: TraceEvent<W>,
    ) -> Described<'_, 'a, TraceEvent<W>, NS, NA, NP, L, W, NF> {
        Described {
            mission: self,
            what: event,
        }
    }

    fn describe_error(
        &self,
        error: ControlError<W>,
    ) -> Described<'_, 'a, ControlError<W>, NS, NA, NP, L, W, NF> {
        Described {
            mission: self,
            what: error,
        }
    }

    fn describe_failure(
        &self,
        failure: Failure<W>,
    ) -> Described<'_, 'a, Failure<W>, NS, NA, NP, L, W, NF> {
        Described {
            mission: self,
            what: failure,
        }
    }
}

/// The names the adapters print.
struct Names<
    'm,
    'a,
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const W: usize,
    const NF: usize,
>(&'m Mission<'a, NS, NA, NP, L, W, NF>);

impl<
    'a,
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const W: usize,
    const NF: usize,
> Names<'_, 'a, NS, NA, NP, L, W, NF>
{
    fn action(&self, a: crate::ActionId) -> &'a str {
        self.0.domain.action(a).map_or("?", |a| a.name)
    }
    fn sensor(&self, s: crate::SensorId) -> &'a str {
        self.0.domain.sensor(s).map_or("?", |s| s.name)
    }
    fn plan(&self, p: PlanId) -> &'a str {
        self.0.library.get(p).map_or("generated plan", |p| p.name)
    }
    fn event(&self, e: crate::EventId) -> &'a str {
        self.0.domain.event_name(e).unwrap_or("?")
    }
    fn plans(&self, f: &mut fmt::Formatter<'_>, set: PlanSet) -> fmt::Result {
        let ids = (0..MAX_PLANS)
            .filter_map(PlanId::new)
            .filter(|p| set.contains(*p));
        for (i, p) in ids.enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            f.write_str(self.plan(p))?;
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
            f.write_str(self.sensor(s))?;
        }
        f.write_str("]")
    }
}

impl<
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const W: usize,
    const NF: usize,
> fmt::Display for Described<'_, '_, Failure<W>, NS, NA, NP, L, W, NF>
{
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = Names(self.mission);
        let facts = |set| self.mission.domain.names(set);
        match self.what {
            Failure::ActionFailed { action } => write!(f, "{} failed", n.action(action)),
            Failure::ActionInterrupted { action } => {
                write!(f, "{} was interrupted", n.action(action))
            }
            Failure::PreconditionUnmet { action, missing } => write!(
                f,
                "{} could not start: {} did not hold",
                n.action(action),
                facts(missing)
            ),
            Failure::PreconditionViolated { action, missing } => write!(
                f,
                "{} stopped: {} stayed false longer than its max_violation",
                n.action(action),
                facts(missing)
            ),
            Failure::SensorUnavailable { sensor } => {
                write!(f, "sensor {} is unavailable", n.sensor(sensor))
            }
            Failure::SensorFault { sensor, fault } => {
                write!(f, "sensor {} failed: {fault:?}", n.sensor(sensor))
            }
            Failure::StoreFull { key } => write!(f, "a data store is full (key {})", key.0),
            Failure::InvalidFsm { state } => write!(f, "the FSM has no state {state}"),
            Failure::SensingStalled => f.write_str("the sensing side does not run"),
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
> fmt::Display for Described<'_, '_, ControlError<W>, NS, NA, NP, L, W, NF>
{
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use ControlError as E;
        let n = Names(self.mission);
        let facts = |set| self.mission.domain.names(set);
        match self.what {
            E::NoApplicablePlan { event, beliefs } => write!(
                f,
                "no plan applies to {} under {}",
                n.event(event),
                facts(beliefs)
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
                    write!(f, "; known false {}", facts(known_false))?;
                }
                if !unknown.is_empty() {
                    write!(f, "; never sensed {}", facts(unknown))?;
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
                write!(f, " (beliefs {})", facts(beliefs))?;
                n.out_of_service(f, faulty)
            }
            E::TooManyFailures { failures, last } => write!(
                f,
                "{failures} plans failed, the last: {}",
                self.mission.describe_failure(last)
            ),
            E::PlanLimit { plans } => write!(f, "{plans} plans ran without reaching the goal"),
            E::Compile { plan, error } => {
                write!(f, "plan {} does not compile: {error:?}", n.plan(plan))
            }
            E::Planning { error, faulty } => {
                write!(f, "no library plan could run, and the planner: {error}")?;
                n.out_of_service(f, faulty)
            }
            E::InitialModel { failure } => write!(
                f,
                "the initial model could not be established: {}",
                self.mission.describe_failure(failure)
            ),
            E::Unbound { sensor, action } => {
                f.write_str("the platform is written for another mission: it has no")?;
                if let Some(sensor) = sensor {
                    write!(f, " sensor {}", n.sensor(sensor))?;
                }
                if let Some(action) = action {
                    let and = if sensor.is_some() { " and no" } else { "" };
                    write!(f, "{and} action {}", n.action(action))?;
                }
                Ok(())
            }
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
> fmt::Display for Described<'_, '_, TraceEvent<W>, NS, NA, NP, L, W, NF>
{
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use TraceEvent as E;
        let n = Names(self.mission);
        let facts = |set| self.mission.domain.names(set);
        match self.what {
            E::ModelEstablished { beliefs } => write!(f, "model established {}", facts(beliefs)),
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
                self.mission.describe_failure(reason)
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
                facts(holds)
            ),
            E::SampleLost { sensor } => write!(f, "{} sample lost", n.sensor(sensor)),
            E::SensorFailed { sensor, fault } => {
                write!(f, "{} fault {fault:?}", n.sensor(sensor))
            }
            E::PreconditionViolated { action, missing } => write!(
                f,
                "precondition of {} violated: {} false",
                n.action(action),
                facts(missing)
            ),
            E::PreconditionRestored { action } => {
                write!(f, "precondition of {} restored", n.action(action))
            }
            E::EffectsApplied { action, beliefs } => write!(
                f,
                "effects of {} applied: {}",
                n.action(action),
                facts(beliefs)
            ),
            E::GoalReached { beliefs } => write!(f, "goal reached: {}", facts(beliefs)),
            E::User { code, value } => write!(f, "user event {code}: {value}"),
        }
    }
}

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
        let m: Loaded<'_, (), (), 1, 1, 1, 1> = load(MISSION.as_bytes(), &AnyBehaviour).unwrap();
        let m = &m.mission;
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

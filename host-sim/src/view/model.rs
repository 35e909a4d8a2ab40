//! What the view shows, kept as the events come: the snapshot (`GET /snapshot`), a ring of
//! recent events (the page's timeline), the states run, and the error lines of a bad stream.
//! Memory is bounded whatever the run's length: [`RING`] events, [`RUNS`] states, [`ERRORS`]
//! error lines.

use std::collections::{BTreeMap, VecDeque};

use psmpa_core::record::Frame;
use psmpa_core::{
    FactSet, Fsm, Outcome, PlanId, SensorSet, Target, TraceEvent, Value, trace::Phase,
};
use serde_json::{Value as Json, json};

use crate::robot::FetchTea;

/// Recent events kept for the page's timeline, at most.
pub const RING: usize = 4096;
/// States run kept, at most (the newest).
pub const RUNS: usize = 256;
/// Error lines kept, at most (the newest).
pub const ERRORS: usize = 64;

/// One state run: entered at `entered_ms`, left at `left_ms` with `outcome`.
#[derive(Clone, Debug)]
struct Run {
    plan: String,
    state: u8,
    action: String,
    sensors: Vec<String>,
    entered_ms: u64,
    left_ms: Option<u64>,
    outcome: Option<&'static str>,
}

/// The live state of a run as its events tell it.
pub struct View {
    mission: FetchTea<'static>,
    time_ms: u64,
    plan: Option<PlanId>,
    state: Option<(u8, String)>,
    facts: FactSet,
    sensors: BTreeMap<String, (Json, u64)>,
    on: SensorSet,
    events: u64,
    seq: u64,
    ring: VecDeque<Json>,
    runs: VecDeque<Run>,
    errors: VecDeque<(u64, String)>,
    error_seq: u64,
    ended: Option<String>,
}

fn outcome_name(o: Option<Outcome>) -> Option<&'static str> {
    match o {
        Some(Outcome::Success) => Some("success"),
        Some(Outcome::Failure) => Some("failure"),
        Some(Outcome::Interrupted) => Some("interrupted"),
        None => None,
    }
}

/// A reading as JSON: a distance in mm, a count or a level as an integer, a switch as a
/// boolean, no echo as `null`.
pub fn value_json(v: Value) -> Json {
    match v {
        Value::Bool(b) => json!(b),
        Value::Int(i) | Value::Mm(i) => json!(i),
        Value::Level(l) => json!(l),
        _ => Json::Null,
    }
}

impl View {
    /// An empty view of `mission`.
    pub fn new(mission: FetchTea<'static>) -> Self {
        Self {
            mission,
            time_ms: 0,
            plan: None,
            state: None,
            facts: FactSet::EMPTY,
            sensors: BTreeMap::new(),
            on: SensorSet::EMPTY,
            events: 0,
            seq: 0,
            ring: VecDeque::with_capacity(RING),
            runs: VecDeque::with_capacity(RUNS),
            errors: VecDeque::with_capacity(ERRORS),
            error_seq: 0,
            ended: None,
        }
    }

    fn fact_names(&self, set: FactSet) -> Vec<&'static str> {
        let names = self.mission.domain.fact_names();
        set.iter()
            .filter_map(|f| names.get(f.index()).copied())
            .collect()
    }

    fn sensor_names(&self, set: SensorSet) -> Vec<&'static str> {
        set.iter()
            .filter_map(|s| self.mission.domain.sensor(s).map(|s| s.name))
            .collect()
    }

    fn sensor_name(&self, s: psmpa_core::SensorId) -> String {
        self.mission
            .domain
            .sensor(s)
            .map_or_else(|| format!("sensor {}", s.index()), |s| s.name.to_owned())
    }

    fn action_name(&self, a: psmpa_core::ActionId) -> String {
        self.mission
            .domain
            .action(a)
            .map_or_else(|| format!("action {}", a.index()), |a| a.name.to_owned())
    }

    fn plan_name(&self, p: PlanId) -> String {
        if p == PlanId::GENERATED {
            return "generated plan".to_owned();
        }
        self.mission
            .library
            .plans()
            .get(p.index())
            .map_or_else(|| format!("plan {}", p.index()), |p| p.name.to_owned())
    }

    fn push(&mut self, mut entry: Json) {
        self.seq += 1;
        if let Some(o) = entry.as_object_mut() {
            o.insert("seq".into(), json!(self.seq));
        }
        if self.ring.len() == RING {
            self.ring.pop_front();
        }
        self.ring.push_back(entry);
    }

    /// Takes in a frame at `at_ms`: the event it records, or an error line when it records
    /// none.
    pub fn frame(&mut self, at_ms: u64, frame: &Frame<1>) {
        match super::decode::event_of(frame) {
            Some(e) => self.event(at_ms, &e),
            None => self.error(format!(
                "a frame at {at_ms} ms records no event this view knows (header {:#x}): skipped",
                frame.header
            )),
        }
    }

    /// Takes in one trace event at `at_ms`.
    pub fn event(&mut self, at_ms: u64, e: &TraceEvent) {
        self.events += 1;
        self.time_ms = at_ms;
        let text = crate::cli::outputs::describe(&self.mission, e);
        let before = self.facts;
        let mut entry = json!({ "t": at_ms, "text": text });
        let mut put = |k: &str, v: Json| {
            if let Some(o) = entry.as_object_mut() {
                o.insert(k.to_owned(), v);
            }
        };
        match *e {
            TraceEvent::ModelEstablished { beliefs } => {
                put("kind", json!("model"));
                put("facts", json!(self.fact_names(beliefs)));
                self.facts = beliefs;
            }
            TraceEvent::PlanGenerated { length, expanded } => {
                put("kind", json!("plan_generated"));
                put("length", json!(length));
                put("expanded", json!(expanded));
            }
            TraceEvent::PlanSelected { plan, .. } => {
                put("kind", json!("plan_selected"));
                put("plan", json!(self.plan_name(plan)));
                self.plan = Some(plan);
            }
            TraceEvent::PlanSucceeded { plan } => {
                put("kind", json!("plan_succeeded"));
                put("plan", json!(self.plan_name(plan)));
            }
            TraceEvent::PlanFailed { plan, reason } => {
                put("kind", json!("plan_failed"));
                put("plan", json!(self.plan_name(plan)));
                if let Some(a) = reason.action() {
                    put("action", json!(self.action_name(a)));
                }
            }
            TraceEvent::StateEntered {
                state,
                action,
                sensors,
            } => {
                let name = self.action_name(action);
                let sensors = self.sensor_names(sensors);
                put("kind", json!("state_entered"));
                put("state", json!(state));
                put("action", json!(name));
                put("sensors", json!(sensors));
                if self.runs.len() == RUNS {
                    self.runs.pop_front();
                }
                self.runs.push_back(Run {
                    plan: self.plan.map(|p| self.plan_name(p)).unwrap_or_default(),
                    state,
                    action: name.clone(),
                    sensors: sensors.into_iter().map(str::to_owned).collect(),
                    entered_ms: at_ms,
                    left_ms: None,
                    outcome: None,
                });
                self.state = Some((state, name));
            }
            TraceEvent::StateLeft {
                state,
                action,
                outcome,
            } => {
                let name = self.action_name(action);
                put("kind", json!("state_left"));
                put("state", json!(state));
                put("action", json!(name));
                put("outcome", json!(outcome_name(outcome)));
                if let Some(run) = self
                    .runs
                    .iter_mut()
                    .rev()
                    .find(|r| r.state == state && r.left_ms.is_none())
                {
                    run.left_ms = Some(at_ms);
                    run.outcome = Some(outcome_name(outcome).unwrap_or("cut short"));
                }
                self.state = None;
            }
            TraceEvent::PhaseStarted { action, phase } => {
                put("kind", json!("phase"));
                put("action", json!(self.action_name(action)));
                put(
                    "phase",
                    json!(match phase {
                        Phase::Sense => "sense",
                        Phase::Act => "act",
                    }),
                );
            }
            TraceEvent::SensorOn { sensor } => {
                put("kind", json!("sensor_on"));
                put("sensor", json!(self.sensor_name(sensor)));
                self.on = self.on.with(sensor);
            }
            TraceEvent::SensorOff { sensor } => {
                put("kind", json!("sensor_off"));
                put("sensor", json!(self.sensor_name(sensor)));
                self.on =
                    SensorSet::from_bits(self.on.bits() & !SensorSet::EMPTY.with(sensor).bits());
            }
            TraceEvent::Sample { sensor, value, .. } => {
                let name = self.sensor_name(sensor);
                put("kind", json!("sample"));
                put("sensor", json!(name));
                put("value", value_json(value));
                self.sensors.insert(name, (value_json(value), at_ms));
            }
            TraceEvent::SampleLost { sensor } => {
                put("kind", json!("sample_lost"));
                put("sensor", json!(self.sensor_name(sensor)));
            }
            TraceEvent::SensorFailed { sensor, .. } => {
                put("kind", json!("sensor_failed"));
                put("sensor", json!(self.sensor_name(sensor)));
            }
            TraceEvent::PreconditionViolated { action, missing } => {
                put("kind", json!("violated"));
                put("action", json!(self.action_name(action)));
                put("facts", json!(self.fact_names(missing)));
                self.facts = self.facts.difference(missing);
            }
            TraceEvent::PreconditionRestored { action } => {
                put("kind", json!("restored"));
                put("action", json!(self.action_name(action)));
                if let Some(a) = self.mission.domain.action(action) {
                    self.facts = self.facts.union(a.pre);
                }
            }
            TraceEvent::EffectsApplied { action, beliefs } => {
                put("kind", json!("effects"));
                put("action", json!(self.action_name(action)));
                put("facts", json!(self.fact_names(beliefs)));
                self.facts = beliefs;
            }
            TraceEvent::GoalReached { beliefs } => {
                put("kind", json!("goal"));
                put("facts", json!(self.fact_names(beliefs)));
                self.facts = beliefs;
            }
            TraceEvent::User { code, value } => {
                put("kind", json!("user"));
                put("code", json!(code));
                put("value", json!(value));
            }
            _ => put("kind", json!("other")),
        }
        self.push(entry);
        // A fact that changed, marked as it happens.
        let changed = FactSet::from_bits(before.bits() ^ self.facts.bits());
        for f in changed.iter() {
            let name = self.mission.domain.fact_names().get(f.index()).copied();
            let now = self.facts.contains(f);
            self.push(json!({
                "t": at_ms, "kind": "fact", "fact": name, "value": now,
                "text": format!("{} turned {}", name.unwrap_or("?"), now),
            }));
        }
    }

    /// An error line (a bad or cut frame): kept for the page and said on standard error.
    pub fn error(&mut self, line: String) {
        eprintln!("psmpa-sim: view: {line}");
        self.error_seq += 1;
        if self.errors.len() == ERRORS {
            self.errors.pop_front();
        }
        self.errors.push_back((self.error_seq, line));
    }

    /// A new recording began in the stream: the view starts anew with its mission; the
    /// error lines stay.
    pub fn restart(&mut self, mission: FetchTea<'static>) {
        let errors = std::mem::take(&mut self.errors);
        let (seq, error_seq) = (self.seq, self.error_seq);
        *self = Self::new(mission);
        (self.seq, self.errors, self.error_seq) = (seq, errors, error_seq);
    }

    /// The source has no more events: `why` in words.
    pub fn end(&mut self, why: String) {
        self.ended = Some(why);
    }

    /// Events taken in so far (the snapshot's `events`).
    pub fn events(&self) -> u64 {
        self.events
    }

    /// `GET /snapshot`: `{"time_ms", "plan", "state", "facts", "sensors", "events"}`.
    pub fn snapshot(&self) -> Json {
        let names = self.mission.domain.fact_names();
        let facts: serde_json::Map<String, Json> = names
            .iter()
            .enumerate()
            .map(|(i, n)| {
                let holds = psmpa_core::FactId::new(i).is_some_and(|f| self.facts.contains(f));
                ((*n).to_owned(), json!(holds))
            })
            .collect();
        let sensors: serde_json::Map<String, Json> = self
            .sensors
            .iter()
            .map(|(n, (v, at))| (n.clone(), json!({ "value": v, "at_ms": at })))
            .collect();
        json!({
            "time_ms": self.time_ms,
            "plan": self.plan.map(|p| self.plan_name(p)),
            "state": self.state.as_ref().map(|(_, n)| n.clone()),
            "facts": facts,
            "sensors": sensors,
            "events": self.events,
        })
    }

    /// The mission as the page draws it: facts, sensors, actions, the task, and each plan
    /// with its FSM (Algorithm 2's states and edges).
    pub fn mission(&self) -> Json {
        let m = &self.mission;
        let d = &m.domain;
        let target = |t: Target| match t {
            Target::State(i) => json!(i),
            Target::Done => json!("done"),
            Target::Failed => json!("failed"),
        };
        let plans: Vec<Json> = m
            .library
            .plans()
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let states: Vec<Json> = PlanId::new(i)
                    .and_then(|id| Fsm::compile(id, &p.body, d.actions()).ok())
                    .map(|fsm| {
                        fsm.states(d.actions(), d.sensors())
                            .map(|s| {
                                json!({
                                    "action": d.action(s.action).map(|a| a.name),
                                    "sensors": self.sensor_names(s.sensors),
                                    "parallel": s.is_parallel(),
                                    "success": target(s.on_success),
                                    "failure": target(s.on_failure),
                                })
                            })
                            .collect()
                    })
                    .unwrap_or_default();
                json!({
                    "name": p.name,
                    "trigger": d.event_name(p.trigger),
                    "context": self.fact_names(p.context),
                    "context_not": self.fact_names(p.context_not),
                    "body": p.body.iter().filter_map(|a| d.action(*a).map(|a| a.name)).collect::<Vec<_>>(),
                    "states": states,
                })
            })
            .collect();
        json!({
            "name": m.name,
            "facts": d.fact_names(),
            "sensors": d.sensors().iter().map(|s| json!({
                "name": s.name, "pre": self.fact_names(s.pre), "per": self.fact_names(s.per),
            })).collect::<Vec<_>>(),
            "actions": d.actions().iter().map(|a| json!({
                "name": a.name, "pre": self.fact_names(a.pre),
                "add": self.fact_names(a.add), "del": self.fact_names(a.del),
            })).collect::<Vec<_>>(),
            "plans": plans,
            "task": {
                "event": d.event_name(m.task.event),
                "init": self.fact_names(m.task.init),
                "goal": self.fact_names(m.task.goal),
            },
        })
    }

    /// What changed since event `since` and error `errors_since`: the snapshot, the sensors
    /// switched on, the states run (the newest [`RUNS`]), the new events (at most `max`: past
    /// that, samples are thinned, every other event kept), the new error lines, and whether
    /// the source ended. Returns the update and the newest event and error numbers.
    pub fn update(&self, since: u64, errors_since: u64, max: usize) -> (Json, u64, u64) {
        let first = self
            .ring
            .front()
            .and_then(|e| e["seq"].as_u64())
            .unwrap_or(0);
        let skip = since.saturating_add(1).saturating_sub(first) as usize;
        let new: Vec<&Json> = self.ring.iter().skip(skip).collect();
        let samples = new.iter().filter(|e| e["kind"] == "sample").count();
        let keep_every = if new.len() > max && samples > 0 {
            let room = max.saturating_sub(new.len() - samples).max(1);
            samples.div_ceil(room)
        } else {
            1
        };
        // Thinned sensor by sensor: a sensor that samples rarely keeps its first sample.
        let mut counts: BTreeMap<&str, usize> = BTreeMap::new();
        let events: Vec<&Json> = new
            .into_iter()
            .filter(|e| {
                if e["kind"] != "sample" {
                    return true;
                }
                let n = counts
                    .entry(e["sensor"].as_str().unwrap_or(""))
                    .or_default();
                *n += 1;
                (*n - 1).is_multiple_of(keep_every)
            })
            .collect();
        let errors: Vec<&String> = self
            .errors
            .iter()
            .filter(|(n, _)| *n > errors_since)
            .map(|(_, l)| l)
            .collect();
        let runs: Vec<Json> = self
            .runs
            .iter()
            .map(|r| {
                json!({
                    "plan": r.plan, "state": r.state, "action": r.action, "sensors": r.sensors,
                    "entered_ms": r.entered_ms, "left_ms": r.left_ms, "outcome": r.outcome,
                })
            })
            .collect();
        (
            json!({
                "snapshot": self.snapshot(),
                "on": self.sensor_names(self.on),
                "runs": runs,
                "events": events,
                "coalesced": keep_every > 1,
                "errors": errors,
                "ended": self.ended,
            }),
            self.seq,
            self.error_seq,
        )
    }
}

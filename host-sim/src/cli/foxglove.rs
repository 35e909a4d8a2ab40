//! A run as an MCAP log that opens in Foxglove (`--mcap`): one topic per sensor of the mission
//! (`/sensor/<name>`), the robot's pose (`/robot/pose`) and the runtime's and the world's events
//! (`/events`), each message one JSON object whose channel carries its JSON schema. Log time is
//! the simulated time in nanoseconds. The file is written chunk by chunk while the run goes:
//! memory holds one chunk (1 MiB) and the held runtime events, not the run.

use std::collections::BTreeMap;
use std::io::Write;

use embassy_time::Instant;
use mcap::records::MessageHeader;
use mcap::write::NoSeek;
use mcap::{WriteOptions, Writer};
use psmpa_core::{Phase, TraceEvent};
use serde_json::{Map, Value, json};

use crate::cli::outputs::{Held, describe, world_text};
use crate::robot::FetchTea;
use crate::scenario::{Kind, Scenario};
use crate::world::{Device, Place, WorldEvent};
use psmpa_fetch_tea::codes;

/// The topic of the robot's pose.
pub const POSE: &str = "/robot/pose";
/// The topic of the events.
pub const EVENTS: &str = "/events";
/// The frame the pose is given in: the corridor, x along the robot's walk from its start.
pub const FRAME: &str = "corridor";
/// The devices the world samples, by the name the mission gives their sensors.
const DEVICES: [Device; 4] = [
    Device::Sonar,
    Device::Bumper,
    Device::Camera,
    Device::Handle,
];

/// The topic of one sensor.
pub fn sensor_topic(name: &str) -> String {
    format!("/sensor/{name}")
}

/// The JSON schema of a sensor's messages: the reading as the world gives it.
fn sensor_schema(device: Device) -> Value {
    let int = |d: &str| json!({"type": "integer", "minimum": 0, "description": d});
    let flag = |d: &str| json!({"type": "boolean", "description": d});
    let (properties, required) = match device {
        Device::Sonar => (
            json!({
                "value_mm": int("distance to the nearest box ahead in range, mm; the maximum when nothing is in range"),
                "value_m": {"type": "number", "description": "the same in metres"},
            }),
            json!(["value_mm", "value_m"]),
        ),
        Device::Bumper => (
            json!({
                "value": int("1 no contact, 2 contact"),
                "contact": flag("the foot touches an obstacle"),
            }),
            json!(["value", "contact"]),
        ),
        Device::Camera => (
            json!({
                "value": int("1 when the door handle is seen, else 0"),
                "handle_seen": flag("the door handle is seen"),
            }),
            json!(["value", "handle_seen"]),
        ),
        Device::Handle => (
            json!({
                "value": int("1 when the door gives, else 0"),
                "door_gives": flag("the door handle gives: the door is not locked"),
            }),
            json!(["value", "door_gives"]),
        ),
    };
    json!({
        "title": format!("psmpa.{}Sample", title(device.name())),
        "description": format!("One sample of the {}, as delivered while it is switched on", device.name()),
        "type": "object",
        "properties": properties,
        "required": required,
        "additionalProperties": false,
    })
}

fn title(name: &str) -> String {
    let mut chars = name.chars();
    chars.next().map_or_else(String::new, |c| {
        c.to_uppercase().chain(chars).collect::<String>()
    })
}

/// A sensor message.
fn sensor_message(device: Device, value: u32) -> Value {
    match device {
        Device::Sonar => json!({"value_mm": value, "value_m": f64::from(value) / 1000.0}),
        Device::Bumper => json!({"value": value, "contact": value == 2}),
        Device::Camera => json!({"value": value, "handle_seen": value != 0}),
        Device::Handle => json!({"value": value, "door_gives": value != 0}),
    }
}

/// The JSON schema of the pose: `foxglove.PoseInFrame`'s fields, plus the position in mm.
fn pose_schema() -> Value {
    let num = json!({"type": "number"});
    let xyz = json!({"type": "object", "properties": {"x": num, "y": num, "z": num},
        "required": ["x", "y", "z"], "additionalProperties": false});
    let xyzw = json!({"type": "object", "properties": {"x": num, "y": num, "z": num, "w": num},
        "required": ["x", "y", "z", "w"], "additionalProperties": false});
    let uint = json!({"type": "integer", "minimum": 0});
    json!({
        "title": "foxglove.PoseInFrame",
        "description": "The robot's position on its straight walk (x, metres from the start; y = z = 0; facing +x)",
        "type": "object",
        "properties": {
            "timestamp": {"type": "object", "properties": {"sec": uint, "nsec": uint},
                "required": ["sec", "nsec"], "additionalProperties": false},
            "frame_id": {"type": "string"},
            "pose": {"type": "object", "properties": {"position": xyz, "orientation": xyzw},
                "required": ["position", "orientation"], "additionalProperties": false},
            "position_mm": {"type": "number", "description": "the same position, mm"},
        },
        "required": ["timestamp", "frame_id", "pose", "position_mm"],
        "additionalProperties": false,
    })
}

/// A pose message at `ns` for a position of `pos_um`.
fn pose_message(ns: u64, pos_um: i64) -> Value {
    json!({
        "timestamp": {"sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000},
        "frame_id": FRAME,
        "pose": {
            "position": {"x": pos_um as f64 / 1e6, "y": 0.0, "z": 0.0},
            "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
        },
        "position_mm": pos_um as f64 / 1e3,
    })
}

/// The optional fields of an event, by name.
const EVENT_FIELDS: [(&str, &str, &str); 7] = [
    ("plan", "string", "the plan"),
    ("action", "string", "the action (behaviour state)"),
    ("sensor", "string", "the sensor"),
    (
        "outcome",
        "string",
        "how the state ended: Success, Failure or cut short",
    ),
    ("phase", "string", "SMPA phase: Sense or Act"),
    (
        "obstacle",
        "integer",
        "the interference, from 1 in the scenario's order",
    ),
    (
        "value",
        "integer",
        "a number the event carries (reaction ms, speed in thousandths)",
    ),
];

/// The JSON schema of an event.
fn event_schema() -> Value {
    let mut properties = Map::new();
    properties.insert(
        "source".into(),
        json!({"type": "string", "enum": ["runtime", "world"],
            "description": "runtime: the P-SMPA runtime's trace; world: the simulated world"}),
    );
    properties.insert(
        "kind".into(),
        json!({"type": "string", "description": "what happened, one word (plan_selected, state_entered, detected, ...)"}),
    );
    properties.insert(
        "text".into(),
        json!({"type": "string", "description": "the event in words, with the mission's names"}),
    );
    for (name, ty, description) in EVENT_FIELDS {
        properties.insert(name.into(), json!({"type": ty, "description": description}));
    }
    json!({
        "title": "psmpa.Event",
        "description": "An event of the run (the runtime's own sample events are left out: the readings are on /sensor/*)",
        "type": "object",
        "properties": properties,
        "required": ["source", "kind", "text"],
        "additionalProperties": false,
    })
}

/// An event being built.
struct Event(Map<String, Value>);

impl Event {
    fn new(source: &str, kind: &str, text: String) -> Self {
        let mut m = Map::new();
        m.insert("source".into(), source.into());
        m.insert("kind".into(), kind.into());
        m.insert("text".into(), text.into());
        Self(m)
    }

    fn with(mut self, field: &str, value: impl Into<Value>) -> Self {
        self.0.insert(field.into(), value.into());
        self
    }

    fn with_name(self, field: &str, name: Option<&str>) -> Self {
        match name {
            Some(n) => self.with(field, n),
            None => self,
        }
    }
}

/// The channels of a log.
struct Channels {
    /// `(device, channel)` of each sensor the mission has.
    sensors: Vec<(Device, u16)>,
    pose: u16,
    events: u16,
}

/// The MCAP log of one run, written while the run goes ([`McapLog::world`],
/// [`McapLog::runtime`]). Runtime events wait in a [`Held`] queue as for the trace CSV, so
/// that log times never decrease.
pub struct McapLog<W: Write> {
    writer: Writer<NoSeek<W>>,
    channels: Channels,
    sequence: BTreeMap<u16, u32>,
    mission: Option<FetchTea<'static>>,
    held: Held,
    last_pos: Option<i64>,
    error: Option<String>,
}

fn ns(ms: u64) -> u64 {
    ms.saturating_mul(1_000_000)
}

fn bytes(v: &Value) -> Vec<u8> {
    // A `Value` has string keys only: it always serializes.
    serde_json::to_vec(v).unwrap_or_default()
}

impl<W: Write> McapLog<W> {
    /// Starts the log of a run of `scenario`: its header, schemas and channels.
    pub fn new(out: W, scenario: &Scenario) -> Result<Self, String> {
        let fail = |e: mcap::McapError| format!("cannot write the MCAP log: {e}");
        let options = WriteOptions::new()
            .profile("")
            .compression(None)
            // `Output` does not seek: chunks are put together in memory, one at a time.
            .disable_seeking(true);
        let mut writer = Writer::with_options(NoSeek::new(out), options).map_err(fail)?;
        let mission = crate::robot::fetch_tea(scenario).map(|r| r.mission).ok();
        // One topic per sensor of the mission (all the robot has, if it could not be built).
        let names: Vec<&str> = mission.as_ref().map_or_else(
            || DEVICES.iter().map(|d| d.name()).collect(),
            |m| m.domain.sensors().iter().map(|s| s.name).collect(),
        );
        let none = BTreeMap::new();
        let mut channel = |schema_name: &str, schema: Value, topic: &str| {
            let id = writer.add_schema(schema_name, "jsonschema", &bytes(&schema))?;
            writer.add_channel(id, topic, "json", &none)
        };
        let mut sensors = Vec::new();
        for name in names {
            let Some(&device) = DEVICES.iter().find(|d| d.name() == name) else {
                continue;
            };
            let schema = sensor_schema(device);
            let schema_name = schema["title"]
                .as_str()
                .unwrap_or("psmpa.Sample")
                .to_owned();
            sensors.push((
                device,
                channel(&schema_name, schema, &sensor_topic(name)).map_err(fail)?,
            ));
        }
        let pose = channel("foxglove.PoseInFrame", pose_schema(), POSE).map_err(fail)?;
        let events = channel("psmpa.Event", event_schema(), EVENTS).map_err(fail)?;
        Ok(Self {
            writer,
            channels: Channels {
                sensors,
                pose,
                events,
            },
            sequence: BTreeMap::new(),
            mission,
            held: Held::default(),
            last_pos: None,
            error: None,
        })
    }

    fn message(&mut self, channel: u16, t_ms: u64, v: &Value) {
        if self.error.is_some() {
            return;
        }
        let sequence = self.sequence.entry(channel).or_insert(0);
        let header = MessageHeader {
            channel_id: channel,
            sequence: *sequence,
            log_time: ns(t_ms),
            publish_time: ns(t_ms),
        };
        *sequence = sequence.wrapping_add(1);
        if let Err(e) = self.writer.write_to_known_channel(&header, &bytes(v)) {
            self.error = Some(format!("cannot write the MCAP log: {e}"));
        }
    }

    fn release(&mut self, before: Option<u64>) {
        while let Some((t, e)) = self.held.pop_before(before) {
            if let Some(event) = self.runtime_event(&e) {
                let events = self.channels.events;
                self.message(events, t, &Value::Object(event.0));
            }
        }
    }

    /// A world event at `t` ms, with the robot at `pos_um`.
    pub fn world(&mut self, t: u64, pos_um: i64, e: WorldEvent) {
        self.release(Some(t));
        if self.last_pos != Some(pos_um) {
            self.last_pos = Some(pos_um);
            let pose = self.channels.pose;
            self.message(pose, t, &pose_message(ns(t), pos_um));
        }
        if let WorldEvent::Sample(device, value) = e {
            let channel = self.channels.sensors.iter().find(|(d, _)| *d == device);
            if let Some(&(_, channel)) = channel {
                self.message(channel, t, &sensor_message(device, value));
            }
            return;
        }
        let events = self.channels.events;
        self.message(events, t, &Value::Object(world_event(e).0));
    }

    /// A runtime event.
    pub fn runtime(&mut self, at: Instant, e: &TraceEvent) {
        if let Some(before) = self.held.overflow() {
            self.release(Some(before));
        }
        self.held.push(at.as_millis(), *e);
    }

    /// The `/events` message of a runtime event; `None` for a sample (on `/sensor/*`).
    fn runtime_event(&self, e: &TraceEvent) -> Option<Event> {
        let m = self.mission.as_ref();
        let text = m.map_or_else(|| format!("{e:?}"), |m| describe(m, e));
        let action = |a| m.and_then(|m| m.domain.action(a)).map(|a| a.name);
        let sensor = |s| m.and_then(|m| m.domain.sensor(s)).map(|s| s.name);
        let plan = |p| {
            Some(
                m.and_then(|m| m.library.get(p))
                    .map_or("generated plan", |p| p.name),
            )
        };
        let ev = |kind: &str| Event::new("runtime", kind, text.clone());
        Some(match *e {
            TraceEvent::Sample { .. } => return None,
            TraceEvent::ModelEstablished { .. } => ev("model_established"),
            TraceEvent::PlanGenerated { length, .. } => ev("plan_generated").with("value", length),
            TraceEvent::PlanSelected { plan: p, .. } => {
                ev("plan_selected").with_name("plan", plan(p))
            }
            TraceEvent::PlanSucceeded { plan: p } => {
                ev("plan_succeeded").with_name("plan", plan(p))
            }
            TraceEvent::PlanFailed { plan: p, .. } => ev("plan_failed").with_name("plan", plan(p)),
            TraceEvent::StateEntered { action: a, .. } => {
                ev("state_entered").with_name("action", action(a))
            }
            TraceEvent::StateLeft {
                action: a, outcome, ..
            } => ev("state_left").with_name("action", action(a)).with(
                "outcome",
                outcome.map_or_else(|| "cut short".to_owned(), |o| format!("{o:?}")),
            ),
            TraceEvent::PhaseStarted { action: a, phase } => {
                ev("phase_started").with_name("action", action(a)).with(
                    "phase",
                    match phase {
                        Phase::Sense => "Sense",
                        Phase::Act => "Act",
                    },
                )
            }
            TraceEvent::SensorOn { sensor: s } => ev("sensor_on").with_name("sensor", sensor(s)),
            TraceEvent::SensorOff { sensor: s } => ev("sensor_off").with_name("sensor", sensor(s)),
            TraceEvent::SampleLost { sensor: s } => {
                ev("sample_lost").with_name("sensor", sensor(s))
            }
            TraceEvent::SensorFailed { sensor: s, .. } => {
                ev("sensor_failed").with_name("sensor", sensor(s))
            }
            TraceEvent::PreconditionViolated { action: a, .. } => {
                ev("precondition_violated").with_name("action", action(a))
            }
            TraceEvent::PreconditionRestored { action: a } => {
                ev("precondition_restored").with_name("action", action(a))
            }
            TraceEvent::EffectsApplied { action: a, .. } => {
                ev("effects_applied").with_name("action", action(a))
            }
            TraceEvent::GoalReached { .. } => ev("goal_reached"),
            TraceEvent::User { code, value } => ev(match code {
                codes::AVOID => "avoid",
                codes::RESUME => "resume",
                codes::LOCKED => "locked",
                _ => "user",
            })
            .with("value", value),
            _ => ev("other"),
        })
    }

    /// Writes what is held, the summary and the footer, and gives the writer back; the first
    /// error of the log, if any, as one line.
    pub fn finish(mut self) -> Result<W, String> {
        self.release(None);
        if let Some(e) = self.error.take() {
            return Err(e);
        }
        self.writer
            .finish()
            .map_err(|e| format!("cannot write the MCAP log: {e}"))?;
        Ok(self.writer.into_inner().into_inner())
    }
}

/// The `/events` message of a world event (not a sample: those are on `/sensor/*`).
fn world_event(e: WorldEvent) -> Event {
    let ev = |kind: &str| Event::new("world", kind, world_text(&e));
    let obstacle = |i: u8| u32::from(i) + 1;
    match e {
        WorldEvent::SensorOn(d) => ev("sensor_on").with("sensor", d.name()),
        WorldEvent::SensorOff(d) => ev("sensor_off").with("sensor", d.name()),
        WorldEvent::Sample(d, v) => ev("sample").with("sensor", d.name()).with("value", v),
        WorldEvent::SampleLost(d) => ev("sample_lost").with("sensor", d.name()),
        WorldEvent::Appeared { index, kind, .. } => ev(match kind {
            Kind::Box => "box_put_down",
            Kind::Ball => "ball_put_down",
        })
        .with("obstacle", obstacle(index)),
        WorldEvent::Removed(i) => ev("taken_away").with("obstacle", obstacle(i)),
        WorldEvent::Skipped(i) => ev("not_put_down").with("obstacle", obstacle(i)),
        WorldEvent::Detected(i, d) => ev("detected")
            .with("obstacle", obstacle(i))
            .with("sensor", d.name()),
        WorldEvent::Collided(i) => ev("collision").with("obstacle", obstacle(i)),
        WorldEvent::Reacted(i, ms) => ev("reacted")
            .with("obstacle", obstacle(i))
            .with("value", ms),
        WorldEvent::Walk => ev("walk"),
        WorldEvent::Stop => ev("stop"),
        WorldEvent::AvoidStarted(i) => match i {
            Some(i) => ev("side_step_started").with("obstacle", obstacle(i)),
            None => ev("side_step_started"),
        },
        WorldEvent::AvoidDone(i) => match i {
            Some(i) => ev("side_step_done").with("obstacle", obstacle(i)),
            None => ev("side_step_done"),
        },
        WorldEvent::Held(true) => ev("actuators_held"),
        WorldEvent::Held(false) => ev("actuators_released"),
        WorldEvent::Arrived(Place::KitchenDoor) => ev("arrived_at_door"),
        WorldEvent::Arrived(Place::BackDoor) => ev("arrived_at_back_door"),
        WorldEvent::DoorOpened(_) => ev("door_opened"),
        WorldEvent::Locked => ev("door_locked"),
        WorldEvent::InKitchen => ev("in_kitchen"),
        WorldEvent::Speed(permille) => ev("speed").with("value", permille),
    }
}

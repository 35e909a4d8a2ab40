//! Scenario files (a contract: docs/simulator.md): parsed with `serde-json-core`, validated
//! field by field, converted to integer units (micrometres, milliseconds).
//!
//! `no_std`: the firmware parses the same files at boot with the same code.

use core::fmt;

use heapless::{String, Vec};
use serde::{Deserialize, Serialize};

/// A field that is present must hold a value: `null` is a wrong type, not "use the default".
fn present<'de, D: serde::Deserializer<'de>, T: Deserialize<'de>>(
    d: D,
) -> Result<Option<T>, D::Error> {
    T::deserialize(d).map(Some)
}

/// A number that is present must be finite: serde-json-core reads `null` as NaN, which would
/// slip past every range check.
fn number<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
    let v = f64::deserialize(d)?;
    if v.is_finite() {
        Ok(Some(v))
    } else {
        Err(serde::de::Error::custom("expected a finite number"))
    }
}

/// Most interferences a scenario can hold.
pub const MAX_INTERFERENCES: usize = 32;
/// Longest scenario name, in bytes.
pub const MAX_NAME: usize = 64;

/// What a person puts in front of the robot.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    /// A tall box (0.8 m): the sonar sees it.
    Box,
    /// A small ball (0.1 m), below the sonar cone: only the foot bumper feels it.
    Ball,
}

/// `robot` as written in the file.
#[derive(Clone, Copy, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotFile {
    /// Walking speed, m/s.
    #[serde(default, deserialize_with = "number")]
    pub speed_mps: Option<f64>,
    /// Time a side step around a detected obstacle takes, s.
    #[serde(default, deserialize_with = "number")]
    pub avoid_s: Option<f64>,
    /// Kept for files written before 0.5: the robot walks at `speed_mps` throughout, so only 0
    /// (the default) is accepted.
    #[serde(default, deserialize_with = "number")]
    pub slow_m: Option<f64>,
    /// Extension: processor time the walk spends planning its path each time it starts or
    /// resumes walking, µs; none in the simulator's virtual time, real cycles on a
    /// microcontroller (a long poll of the deciding side).
    #[serde(default, deserialize_with = "number")]
    pub plan_us: Option<f64>,
}

/// `sonar` as written in the file.
#[derive(Clone, Copy, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SonarFile {
    /// Sampling period, ms.
    #[serde(default, deserialize_with = "number")]
    pub period_ms: Option<f64>,
    /// Shortest distance the sonar measures, m.
    #[serde(default, deserialize_with = "number")]
    pub min_m: Option<f64>,
    /// Longest distance; also the reading when nothing is in range, m.
    #[serde(default, deserialize_with = "number")]
    pub max_m: Option<f64>,
    /// An obstacle counts as seen below this distance, m.
    #[serde(default, deserialize_with = "number")]
    pub threshold_m: Option<f64>,
    /// Uniform noise amplitude, m.
    #[serde(default, deserialize_with = "number")]
    pub noise_m: Option<f64>,
    /// Probability that a sample is lost.
    #[serde(default, deserialize_with = "number")]
    pub dropout: Option<f64>,
    /// How long a sample takes, from its start to its result, ms (whole, 0 to 1000).
    #[serde(default, deserialize_with = "number")]
    pub latency_ms: Option<f64>,
    /// Extension: how high the sonar sits, m; 0 (the default) sees every box at any distance.
    #[serde(default, deserialize_with = "number")]
    pub height_m: Option<f64>,
    /// Extension: how far the cone's lower edge drops per metre ahead (0 to 100, default 0.5):
    /// a box lower than the sonar is seen only from `(height_m - box height) / cone_slope` on.
    #[serde(default, deserialize_with = "number")]
    pub cone_slope: Option<f64>,
}

/// `bumper` as written in the file.
#[derive(Clone, Copy, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BumperFile {
    /// Sampling period, ms.
    #[serde(default, deserialize_with = "number")]
    pub period_ms: Option<f64>,
    /// How long a sample takes, from its start to its result, ms (whole, 0 to 1000).
    #[serde(default, deserialize_with = "number")]
    pub latency_ms: Option<f64>,
    /// Extension: how long a contact must last before a sample feels it, ms (whole, 0 to
    /// 1000; default 0).
    #[serde(default, deserialize_with = "number")]
    pub min_contact_ms: Option<f64>,
}

/// `smpa` as written in the file.
#[derive(Clone, Copy, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SmpaFile {
    /// Sense phase length, ms.
    #[serde(default, deserialize_with = "number")]
    pub sense_ms: Option<f64>,
    /// Act phase length, ms.
    #[serde(default, deserialize_with = "number")]
    pub act_ms: Option<f64>,
}

/// `doors` as written in the file (an extension of the contract's format, for re-planning).
#[derive(Clone, Copy, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DoorsFile {
    /// Whether the kitchen door is locked.
    #[serde(default, deserialize_with = "present")]
    pub locked: Option<bool>,
    /// How far beyond the kitchen door the back door is, m.
    #[serde(default, deserialize_with = "number")]
    pub back_door_m: Option<f64>,
}

/// How the sonar fails (extension of the contract's format).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FaultKind {
    /// It stops answering: a sample never completes.
    Silent,
    /// It reports distances beyond its range.
    OutOfRange,
    /// It keeps reporting the same distance.
    Stuck,
}

/// `fault` as written in the file: from `at_s` on, the sonar fails.
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FaultFile {
    /// How it fails.
    pub kind: FaultKind,
    /// When, s.
    #[serde(default, deserialize_with = "number")]
    pub at_s: Option<f64>,
}

/// One interference as written in the file. Every field has a default (the contract's first
/// example: a box put down at 3.0 s, 0.45 m ahead, for 4.0 s).
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InterferenceFile {
    /// Box or ball (default box).
    #[serde(default, deserialize_with = "present")]
    pub kind: Option<Kind>,
    /// When the obstacle is put down, s (default 3.0).
    #[serde(default, deserialize_with = "number")]
    pub at_s: Option<f64>,
    /// How far in front of the robot, m (default 0.45 for a box, 0.05 for a ball).
    #[serde(default, deserialize_with = "number")]
    pub ahead_m: Option<f64>,
    /// After how long the person takes it away again, s (default 4.0).
    #[serde(default, deserialize_with = "number")]
    pub hold_s: Option<f64>,
    /// Extension: the obstacle walks towards the robot along its path at this speed while it
    /// is there, until it touches the robot, m/s (0 to 10, default 0).
    #[serde(default, deserialize_with = "number")]
    pub speed_mps: Option<f64>,
    /// Extension: its height, for the sonar cone, m (0 to 10; default 0.8 for a box, 0.1 for
    /// a ball).
    #[serde(default, deserialize_with = "number")]
    pub height_m: Option<f64>,
}

/// A scenario file as written, before validation.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioFile {
    /// Scenario name (escape sequences decoded).
    pub name: String<MAX_NAME>,
    /// Seed of the noise and dropout generator.
    #[serde(default, deserialize_with = "present")]
    pub seed: Option<u64>,
    /// Distance to the door, m.
    #[serde(default, deserialize_with = "number")]
    pub door_m: Option<f64>,
    /// Longest run, s.
    #[serde(default, deserialize_with = "number")]
    pub max_s: Option<f64>,
    /// The robot.
    #[serde(default, deserialize_with = "present")]
    pub robot: Option<RobotFile>,
    /// The sonar.
    #[serde(default, deserialize_with = "present")]
    pub sonar: Option<SonarFile>,
    /// The foot bumper.
    #[serde(default, deserialize_with = "present")]
    pub bumper: Option<BumperFile>,
    /// The SMPA phases.
    #[serde(default, deserialize_with = "present")]
    pub smpa: Option<SmpaFile>,
    /// The doors (extension: a locked kitchen door makes the robot re-plan).
    #[serde(default, deserialize_with = "present")]
    pub doors: Option<DoorsFile>,
    /// A sonar fault (extension: the robot must notice and stop).
    #[serde(default, deserialize_with = "present")]
    pub fault: Option<FaultFile>,
    /// The interferences, in any order.
    pub interferences: Interferences,
}

/// The `interferences` list: at most [`MAX_INTERFERENCES`], with an error that says so.
#[derive(Clone, Debug, Default)]
pub struct Interferences(pub Vec<InterferenceFile, MAX_INTERFERENCES>);

impl<'de> Deserialize<'de> for Interferences {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Items;
        impl<'de> serde::de::Visitor<'de> for Items {
            type Value = Interferences;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "at most {MAX_INTERFERENCES} interferences")
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                mut seq: A,
            ) -> Result<Self::Value, A::Error> {
                let mut items = Vec::new();
                while let Some(item) = seq.next_element()? {
                    items.push(item).map_err(|_| {
                        serde::de::Error::invalid_length(MAX_INTERFERENCES + 1, &self)
                    })?;
                }
                Ok(Interferences(items))
            }
        }
        deserializer.deserialize_seq(Items)
    }
}

/// The sonar, in integer units.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Sonar {
    /// Sampling period, ms.
    pub period_ms: u64,
    /// Shortest measured distance, µm.
    pub min_um: i64,
    /// Longest measured distance, µm.
    pub max_um: i64,
    /// Detection threshold, µm.
    pub threshold_um: i64,
    /// Noise amplitude, µm.
    pub noise_um: i64,
    /// A sample is lost when a uniform `u32` draw is below this (probability × 2³²).
    pub dropout: u64,
    /// How long a sample takes, ms.
    pub latency_ms: u64,
    /// How high it sits, µm (0: it sees every box).
    pub height_um: i64,
    /// The cone's lower edge drops this many µm per metre ahead (millionths of the slope).
    pub cone_slope_ppm: i64,
}

impl Sonar {
    /// The threshold in whole millimetres, the sonar's resolution.
    pub const fn threshold_mm(&self) -> i64 {
        (self.threshold_um + 500) / 1000
    }

    /// The one rule both the world and the robot apply: a reading of `mm` counts as an
    /// obstacle when it is above 0 (0 is a switched-off sonar) and below the threshold.
    pub const fn registers(&self, mm: i64) -> bool {
        mm > 0 && mm < self.threshold_mm()
    }

    /// From how far the cone takes in a box `height_um` high, µm: 0 for one as high as the
    /// sonar, `i64::MAX` for a lower one under a level cone.
    pub fn seen_from_um(&self, height_um: i64) -> i64 {
        let below = self.height_um - height_um;
        if below <= 0 {
            0
        } else if self.cone_slope_ppm <= 0 {
            i64::MAX
        } else {
            // Whole µm, rounded up: below that the edge still passes above the box.
            // (At most 10 m below, so `below` times a million stays far inside `i64`.)
            (below * 1_000_000 + self.cone_slope_ppm - 1) / self.cone_slope_ppm
        }
    }
}

/// A distance in µm as the sonar reports it: whole millimetres, rounded.
pub const fn to_mm(um: i64) -> i64 {
    (um + 500) / 1000
}

/// One interference, in integer units.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Interference {
    /// Box or ball.
    pub kind: Kind,
    /// When it is put down, ms.
    pub at_ms: u32,
    /// How far in front of the robot, µm (at most 1 km).
    pub ahead_um: i32,
    /// How long until a person takes it away, ms.
    pub hold_ms: u32,
    /// How fast it walks towards the robot while there, µm per ms (= mm/s; at most 10,000).
    pub speed_um_per_ms: u16,
    /// Its height, µm.
    pub height_um: u32,
}

/// A validated scenario in integer units.
///
/// Its serde form is the *canonical* scenario: a JSON array of integers in field order, made
/// at build time from a scenario file ([`to_canonical`](Self::to_canonical)) so that a
/// microcontroller reads it with serde-json-core at boot, with no float parser, no field names
/// to match and little flash ([`from_canonical`](Self::from_canonical)). It is not a file
/// format for people: write scenario files.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Scenario {
    /// Name.
    pub name: String<MAX_NAME>,
    /// PRNG seed.
    pub seed: u64,
    /// Distance to the door, µm.
    pub door_um: i64,
    /// Longest run, ms.
    pub max_ms: u64,
    /// Walking speed, µm per ms (= mm/s).
    pub speed_um_per_ms: i64,
    /// Side step duration, ms.
    pub avoid_ms: u64,
    /// The walk slows down while the sonar reads an obstacle nearer than this, µm; 0: never.
    pub slow_um: i64,
    /// Processor time the walk spends planning whenever it starts or resumes, µs (on a
    /// microcontroller).
    pub plan_us: u32,
    /// The sonar.
    pub sonar: Sonar,
    /// Bumper period, ms.
    pub bumper_period_ms: u64,
    /// How long a bumper sample takes, ms.
    pub bumper_latency_ms: u64,
    /// How long a contact must last before a bumper sample feels it, ms.
    pub bumper_min_contact_ms: u64,
    /// SMPA sense phase, ms.
    pub sense_ms: u64,
    /// SMPA act phase, ms.
    pub act_ms: u64,
    /// Whether the kitchen door is locked.
    pub door_locked: bool,
    /// Distance from the kitchen door on to the back door, µm.
    pub back_door_um: i64,
    /// A sonar fault and when it starts, ms.
    pub fault: Option<(FaultKind, u32)>,
    /// The interferences, in file order.
    pub interferences: Vec<Interference, MAX_INTERFERENCES>,
}

/// The canonical sonar: `[period, min, max, threshold, noise, dropout, latency, height,
/// cone slope]`.
type SonarRow = (u64, i64, i64, i64, i64, u64, u64, i64, i64);
/// A canonical interference: `[kind, at, ahead, hold, speed, height]`, kind 0 for a box, 1
/// for a ball.
type InterferenceRow = (u8, u32, i32, u32, u16, u32);

impl Kind {
    /// The height an interference of this kind has unless its file says otherwise, µm: 0.8 m
    /// for a box, 0.1 m for a ball.
    pub const fn default_height_um(self) -> u32 {
        match self {
            Self::Box => 800_000,
            Self::Ball => 100_000,
        }
    }

    const fn code(self) -> u8 {
        match self {
            Self::Box => 0,
            Self::Ball => 1,
        }
    }
}

impl FaultKind {
    const fn code(self) -> u8 {
        match self {
            Self::Silent => 0,
            Self::OutOfRange => 1,
            Self::Stuck => 2,
        }
    }

    const fn from_code(code: u8) -> Option<Self> {
        match code {
            0 => Some(Self::Silent),
            1 => Some(Self::OutOfRange),
            2 => Some(Self::Stuck),
            _ => None,
        }
    }
}

impl Serialize for Scenario {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeTuple;
        let o = &self.sonar;
        let sonar: SonarRow = (
            o.period_ms,
            o.min_um,
            o.max_um,
            o.threshold_um,
            o.noise_um,
            o.dropout,
            o.latency_ms,
            o.height_um,
            o.cone_slope_ppm,
        );
        let mut t = serializer.serialize_tuple(CANONICAL_FIELDS)?;
        t.serialize_element(self.name.as_str())?;
        t.serialize_element(&self.seed)?;
        t.serialize_element(&self.door_um)?;
        t.serialize_element(&self.max_ms)?;
        t.serialize_element(&self.speed_um_per_ms)?;
        t.serialize_element(&self.avoid_ms)?;
        t.serialize_element(&self.slow_um)?;
        t.serialize_element(&self.plan_us)?;
        t.serialize_element(&sonar)?;
        t.serialize_element(&self.bumper_period_ms)?;
        t.serialize_element(&self.bumper_latency_ms)?;
        t.serialize_element(&self.bumper_min_contact_ms)?;
        t.serialize_element(&self.sense_ms)?;
        t.serialize_element(&self.act_ms)?;
        t.serialize_element(&self.door_locked)?;
        t.serialize_element(&self.back_door_um)?;
        t.serialize_element(&self.fault.map(|(k, at)| (k.code(), at)))?;
        t.serialize_element(&Rows(&self.interferences))?;
        t.end()
    }
}

/// The interferences as canonical rows.
struct Rows<'v>(&'v [Interference]);

impl Serialize for Rows<'_> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_seq(self.0.iter().map(|i| -> InterferenceRow {
            (
                i.kind.code(),
                i.at_ms,
                i.ahead_um,
                i.hold_ms,
                i.speed_um_per_ms,
                i.height_um,
            )
        }))
    }
}

/// Elements of the canonical array.
const CANONICAL_FIELDS: usize = 18;

/// The canonical form's fields, in order: what an error in one is named by.
#[cfg(feature = "std")]
const CANONICAL_NAMES: [&str; CANONICAL_FIELDS] = [
    "name",
    "seed",
    "door_um",
    "max_ms",
    "speed_um_per_ms",
    "avoid_ms",
    "slow_um",
    "plan_us",
    "sonar [period_ms, min_um, max_um, threshold_um, noise_um, dropout, latency_ms, height_um, cone_slope_ppm]",
    "bumper_period_ms",
    "bumper_latency_ms",
    "bumper_min_contact_ms",
    "sense_ms",
    "act_ms",
    "door_locked",
    "back_door_um",
    "fault [kind 0-2, at_ms] or null",
    "interferences [[kind 0-1, at_ms, ahead_um, hold_ms, speed_um_per_ms, height_um], ...]",
];

/// Why `json` is not a canonical scenario, naming the field (its place in the array) and the
/// problem, for a form [`Scenario::read_canonical`] refused (serde-json-core's errors name
/// neither).
#[cfg(feature = "std")]
pub fn canonical_problem(json: &[u8]) -> std::string::String {
    use std::borrow::ToOwned as _;
    use std::format;
    use std::string::ToString as _;
    fn field<T: serde::de::DeserializeOwned>(
        items: &[serde_json::Value],
        i: usize,
    ) -> Result<T, std::string::String> {
        let name = CANONICAL_NAMES.get(i).copied().unwrap_or("?");
        let v = items.get(i).ok_or_else(|| {
            format!(
                "field {i} ({name}): missing: the array ends after {} fields",
                items.len()
            )
        })?;
        serde_json::from_value(v.clone()).map_err(|e| format!("field {i} ({name}): {e}"))
    }
    let value: serde_json::Value = match serde_json::from_slice(json) {
        Ok(v) => v,
        Err(e) => return format!("not JSON: {e}"),
    };
    let Some(items) = value.as_array() else {
        return format!("not an array of its {CANONICAL_FIELDS} fields");
    };
    let checked = (|| -> Result<(), std::string::String> {
        let name: std::string::String = field(items, 0)?;
        if name.len() > MAX_NAME {
            return Err(format!(
                "field 0 (name): {} bytes, more than {MAX_NAME}",
                name.len()
            ));
        }
        field::<u64>(items, 1)?;
        field::<i64>(items, 2)?;
        field::<u64>(items, 3)?;
        field::<i64>(items, 4)?;
        field::<u64>(items, 5)?;
        field::<i64>(items, 6)?;
        field::<u32>(items, 7)?;
        field::<SonarRow>(items, 8)?;
        for i in 9..=13 {
            field::<u64>(items, i)?;
        }
        field::<bool>(items, 14)?;
        field::<i64>(items, 15)?;
        if let Some((code, _)) = field::<Option<(u8, u32)>>(items, 16)?
            && FaultKind::from_code(code).is_none()
        {
            return Err(format!(
                "field 16 ({}): kind {code}: 0, 1 or 2",
                CANONICAL_NAMES[16]
            ));
        }
        let rows: std::vec::Vec<InterferenceRow> = field(items, 17)?;
        if rows.len() > MAX_INTERFERENCES {
            return Err(format!(
                "field 17 (interferences): {}, more than {MAX_INTERFERENCES}",
                rows.len()
            ));
        }
        if let Some(k) = rows.iter().position(|r| r.0 > 1) {
            return Err(format!(
                "field 17 (interferences): interference {k}: kind {}: 0 (a box) or 1 (a ball)",
                rows[k].0
            ));
        }
        if items.len() > CANONICAL_FIELDS {
            return Err(format!(
                "{} fields: a canonical scenario has {CANONICAL_FIELDS}",
                items.len()
            ));
        }
        Ok(())
    })();
    match checked {
        Err(e) => e,
        Ok(()) => "refused by the reader, though each field reads".to_owned(),
    }
    .to_string()
}

/// Fills a scenario from its canonical form, element by element.
struct Fill<'s>(&'s mut Scenario);

impl<'de> serde::de::DeserializeSeed<'de> for Fill<'_> {
    type Value = ();
    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_tuple(CANONICAL_FIELDS, self)
    }
}

/// The next element of a canonical array, which must be there.
fn element<'de, T: Deserialize<'de>, A: serde::de::SeqAccess<'de>>(
    seq: &mut A,
    index: usize,
) -> Result<T, A::Error> {
    seq.next_element()?
        .ok_or_else(|| serde::de::Error::invalid_length(index, &"a canonical scenario"))
}

impl<'de> serde::de::Visitor<'de> for Fill<'_> {
    type Value = ();
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a canonical scenario")
    }
    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        let s = self.0;
        s.name = element(&mut seq, 0)?;
        s.seed = element(&mut seq, 1)?;
        s.door_um = element(&mut seq, 2)?;
        s.max_ms = element(&mut seq, 3)?;
        s.speed_um_per_ms = element(&mut seq, 4)?;
        s.avoid_ms = element(&mut seq, 5)?;
        s.slow_um = element(&mut seq, 6)?;
        s.plan_us = element(&mut seq, 7)?;
        let row: SonarRow = element(&mut seq, 8)?;
        s.sonar = Sonar {
            period_ms: row.0,
            min_um: row.1,
            max_um: row.2,
            threshold_um: row.3,
            noise_um: row.4,
            dropout: row.5,
            latency_ms: row.6,
            height_um: row.7,
            cone_slope_ppm: row.8,
        };
        s.bumper_period_ms = element(&mut seq, 9)?;
        s.bumper_latency_ms = element(&mut seq, 10)?;
        s.bumper_min_contact_ms = element(&mut seq, 11)?;
        s.sense_ms = element(&mut seq, 12)?;
        s.act_ms = element(&mut seq, 13)?;
        s.door_locked = element(&mut seq, 14)?;
        s.back_door_um = element(&mut seq, 15)?;
        let fault: Option<(u8, u32)> = element(&mut seq, 16)?;
        s.fault = match fault {
            Some((code, at)) => Some((
                FaultKind::from_code(code).ok_or_else(|| {
                    serde::de::Error::custom("a canonical fault kind is 0, 1 or 2")
                })?,
                at,
            )),
            None => None,
        };
        s.interferences.clear();
        seq.next_element_seed(Items(&mut s.interferences))?
            .ok_or_else(|| serde::de::Error::invalid_length(17, &"a canonical scenario"))?;
        if seq.next_element::<serde::de::IgnoredAny>()?.is_some() {
            return Err(serde::de::Error::invalid_length(
                CANONICAL_FIELDS + 1,
                &"a canonical scenario",
            ));
        }
        Ok(())
    }
}

/// Pushes interferences one by one into the scenario's list.
struct Items<'v>(&'v mut Vec<Interference, MAX_INTERFERENCES>);

impl<'de> serde::de::DeserializeSeed<'de> for Items<'_> {
    type Value = ();
    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_seq(self)
    }
}

impl<'de> serde::de::Visitor<'de> for Items<'_> {
    type Value = ();
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "at most {MAX_INTERFERENCES} interferences")
    }
    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        while let Some((kind, at_ms, ahead_um, hold_ms, speed_um_per_ms, height_um)) =
            seq.next_element::<InterferenceRow>()?
        {
            let kind = match kind {
                0 => Kind::Box,
                1 => Kind::Ball,
                _ => return Err(serde::de::Error::custom("a canonical kind is 0 or 1")),
            };
            let item = Interference {
                kind,
                at_ms,
                ahead_um,
                hold_ms,
                speed_um_per_ms,
                height_um,
            };
            self.0
                .push(item)
                .map_err(|_| serde::de::Error::invalid_length(MAX_INTERFERENCES + 1, &self))?;
        }
        Ok(())
    }
}

/// Why a scenario has no canonical form.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CanonicalError {
    /// The name holds a quote, backslash or control character.
    NameNeedsEscapes,
    /// The output buffer is too small.
    TooLong,
}

impl fmt::Display for CanonicalError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::NameNeedsEscapes => {
                "the name must not contain quotes, backslashes or control characters"
            }
            Self::TooLong => "the canonical form does not fit the buffer",
        })
    }
}

/// Where in a scenario file something is wrong.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Field {
    /// Section (`robot`, `sonar`, `interferences`, ...) or `None` at the top level.
    pub section: Option<&'static str>,
    /// Index in `interferences`.
    pub index: Option<usize>,
    /// Field name.
    pub name: &'static str,
}

impl Field {
    const fn top(name: &'static str) -> Self {
        Self {
            section: None,
            index: None,
            name,
        }
    }

    const fn of(section: &'static str, name: &'static str) -> Self {
        Self {
            section: Some(section),
            index: None,
            name,
        }
    }
}

impl fmt::Display for Field {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(section) = self.section {
            f.write_str(section)?;
            if let Some(i) = self.index {
                write!(f, "[{i}]")?;
            }
            f.write_str(".")?;
        }
        f.write_str(self.name)
    }
}

/// What is wrong with a value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Problem {
    /// A duration or distance below zero.
    Negative(f64),
    /// Must be above zero.
    NotPositive(f64),
    /// Rounds to zero milliseconds: must be at least 0.001 s.
    BelowOneMillisecond(f64),
    /// Above zero but below the unit the world counts in (`least`: "1 ms", "0.000001 m").
    BelowUnit {
        /// The value.
        value: f64,
        /// The smallest allowed, with its unit.
        least: &'static str,
    },
    /// Must be a whole number of milliseconds.
    NotWhole(f64),
    /// Must be a whole number of `unit`.
    NotWholeUnit {
        /// The value.
        value: f64,
        /// The unit, with its size ("0.001 m/s").
        unit: &'static str,
    },
    /// Outside `[min, max]`.
    OutOfRange {
        /// The value.
        value: f64,
        /// Smallest allowed.
        min: f64,
        /// Largest allowed.
        max: f64,
    },
    /// Above `max` (the least value has a message of its own: not negative, or above 0).
    AboveMax {
        /// The value.
        value: f64,
        /// Largest allowed.
        max: f64,
    },
    /// The name is empty or only spaces.
    Empty,
    /// A slow zone other than 0: the robot walks at one speed.
    NoSlowZone(f64),
    /// Must be a whole number of microseconds from 0 to `max`.
    NotWholeMicros {
        /// The value.
        value: f64,
        /// The largest allowed.
        max: u32,
    },
    /// Must be a whole number of milliseconds from 0 to `max`.
    NotWholeMillis {
        /// The value.
        value: f64,
        /// Largest allowed.
        max: u64,
    },
    /// `threshold_m` must lie in `(min_m, max_m]`.
    ThresholdOutsideRange,
}

/// A value from a file as a message shows it: `1e308` is not written out in 309 digits.
struct Shown(f64);

impl fmt::Display for Shown {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let a = self.0.abs();
        if a >= 1e15 || (a != 0.0 && a < 1e-9) {
            write!(f, "{:e}", self.0)
        } else {
            write!(f, "{}", self.0)
        }
    }
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Negative(v) => write!(f, "must not be negative, got {}", Shown(v)),
            Self::NotPositive(v) => write!(f, "must be greater than 0, got {}", Shown(v)),
            Self::BelowOneMillisecond(v) => write!(f, "must be at least 0.001 s, got {}", Shown(v)),
            Self::BelowUnit { value, least } => {
                write!(f, "must be at least {least}, got {}", Shown(value))
            }
            Self::NotWholeUnit { value, unit } => {
                write!(f, "must be a whole number of {unit}, got {}", Shown(value))
            }
            Self::NotWhole(v) => write!(
                f,
                "must be a whole number of milliseconds, got {}",
                Shown(v)
            ),
            Self::OutOfRange { value, min, max } => {
                write!(f, "must lie between {min} and {max}, got {}", Shown(value))
            }
            Self::AboveMax { value, max } => {
                write!(f, "must be at most {max}, got {}", Shown(value))
            }
            Self::Empty => f.write_str("must not be empty or only spaces"),
            Self::NoSlowZone(v) => write!(
                f,
                "must be 0: the Fetch Tea robot walks at one speed, with no slow zone; got {}",
                Shown(v)
            ),
            Self::NotWholeMicros { value, max } => write!(
                f,
                "must be a whole number of microseconds from 0 to {max}, got {}",
                Shown(value)
            ),
            Self::NotWholeMillis { value, max } => write!(
                f,
                "must be a whole number of milliseconds from 0 to {max}, got {}",
                Shown(value)
            ),
            Self::ThresholdOutsideRange => {
                f.write_str("threshold_m must lie above min_m and at most max_m")
            }
        }
    }
}

/// Why a scenario is invalid.
#[derive(Clone, Debug, PartialEq)]
pub enum ScenarioError {
    /// Not valid JSON, or not the expected shape (a wrong type, an unknown field, a missing
    /// field, an unknown `kind`). `serde-json-core` reports no position; hosts add one.
    Json(serde_json_core::de::Error),
    /// A value out of its range.
    Invalid {
        /// Which field.
        field: Field,
        /// What is wrong.
        problem: Problem,
    },
}

impl fmt::Display for ScenarioError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Json(e) => write!(f, "{e}"),
            Self::Invalid { field, problem } => write!(f, "{field}: {problem}"),
        }
    }
}

fn invalid(field: Field, problem: Problem) -> ScenarioError {
    ScenarioError::Invalid { field, problem }
}

/// Largest duration accepted anywhere (one day), ms.
const MAX_MS: f64 = 86_400_000.0;
/// Largest distance accepted anywhere (1 km), m.
const MAX_M: f64 = 1_000.0;

/// A non-negative number of seconds, rounded to ms.
fn seconds(field: Field, value: f64) -> Result<u64, ScenarioError> {
    let ms = value * 1000.0;
    if !value.is_finite() {
        return Err(invalid(field, Problem::NotPositive(value)));
    }
    if value < 0.0 {
        return Err(invalid(field, Problem::Negative(value)));
    }
    if ms > MAX_MS {
        return Err(invalid(
            field,
            Problem::AboveMax {
                value,
                max: MAX_MS / 1000.0,
            },
        ));
    }
    Ok((ms + 0.5) as u64)
}

/// An obstacle's speed in mm/s (µm a ms) from `um_per_s`, which must be a whole number of
/// them: a slower or finer speed cannot be represented and is refused.
fn mm_per_s(field: Field, um_per_s: i64, value: f64) -> Result<u16, ScenarioError> {
    if um_per_s % 1000 != 0 {
        return Err(invalid(
            field,
            if um_per_s < 1000 {
                Problem::BelowUnit {
                    value,
                    least: "0.001 m/s (or 0, standing)",
                }
            } else {
                Problem::NotWholeUnit {
                    value,
                    unit: "0.001 m/s",
                }
            },
        ));
    }
    u16::try_from(um_per_s / 1000).map_err(|_| {
        invalid(
            field,
            Problem::AboveMax {
                value,
                max: MAX_SPEED_MPS,
            },
        )
    })
}

/// A whole number of milliseconds, at least 1.
fn millis(field: Field, value: f64) -> Result<u64, ScenarioError> {
    if !value.is_finite() {
        return Err(invalid(field, Problem::NotPositive(value)));
    }
    if value < 0.0 {
        return Err(invalid(field, Problem::Negative(value)));
    }
    if value == 0.0 {
        return Err(invalid(field, Problem::NotPositive(value)));
    }
    if value < 1.0 {
        return Err(invalid(
            field,
            Problem::BelowUnit {
                value,
                least: "1 ms",
            },
        ));
    }
    if value > MAX_MS {
        return Err(invalid(
            field,
            Problem::OutOfRange {
                value,
                min: 1.0,
                max: MAX_MS,
            },
        ));
    }
    let whole = value as u64;
    if whole as f64 != value {
        return Err(invalid(field, Problem::NotWhole(value)));
    }
    Ok(whole)
}

/// Most processor time the walk's planning may take, µs (`robot.plan_us`): a tenth of a
/// second.
pub const MAX_PLAN_US: u32 = 100_000;

/// Longest sensor read latency accepted, ms.
pub const MAX_LATENCY_MS: u64 = 1_000;

/// A sensor read latency: a whole number of milliseconds from 0 to [`MAX_LATENCY_MS`].
fn latency(field: Field, value: f64) -> Result<u64, ScenarioError> {
    // `fract` needs std: compare with the whole part instead.
    let whole = value >= 0.0 && value <= MAX_LATENCY_MS as f64 && (value as u64) as f64 == value;
    if !value.is_finite() || !whole {
        let problem = if value < 0.0 {
            Problem::Negative(value)
        } else {
            Problem::NotWholeMillis {
                value,
                max: MAX_LATENCY_MS,
            }
        };
        return Err(invalid(field, problem));
    }
    Ok(value as u64)
}

/// A non-negative distance in metres, rounded to µm.
fn metres(field: Field, value: f64) -> Result<i64, ScenarioError> {
    if !value.is_finite() {
        return Err(invalid(field, Problem::NotPositive(value)));
    }
    if value < 0.0 {
        return Err(invalid(field, Problem::Negative(value)));
    }
    if value > MAX_M {
        return Err(invalid(field, Problem::AboveMax { value, max: MAX_M }));
    }
    Ok((value * 1_000_000.0 + 0.5) as i64)
}

/// Tallest obstacle or highest sonar, m.
const MAX_HEIGHT_M: f64 = 10.0;
/// Steepest sonar cone edge, m per m.
const MAX_CONE_SLOPE: f64 = 100.0;
/// Fastest moving obstacle, m/s.
const MAX_SPEED_MPS: f64 = 10.0;

/// A real number from 0 to `max`, in millionths (µm for metres).
fn up_to(field: Field, value: f64, max: f64) -> Result<i64, ScenarioError> {
    if value < 0.0 {
        return Err(invalid(field, Problem::Negative(value)));
    }
    if !value.is_finite() || value > max {
        let problem = Problem::OutOfRange {
            value,
            min: 0.0,
            max,
        };
        return Err(invalid(field, problem));
    }
    Ok((value * 1_000_000.0 + 0.5) as i64)
}

/// A number of seconds that is at least 1 ms.
fn positive_seconds(field: Field, value: f64) -> Result<u64, ScenarioError> {
    let ms = seconds(field, value)?;
    if ms == 0 {
        return Err(invalid(
            field,
            if value > 0.0 {
                Problem::BelowOneMillisecond(value)
            } else {
                Problem::NotPositive(value)
            },
        ));
    }
    Ok(ms)
}

fn positive_metres(field: Field, value: f64) -> Result<i64, ScenarioError> {
    let um = metres(field, value)?;
    if um == 0 {
        let problem = if value > 0.0 {
            Problem::BelowUnit {
                value,
                least: "0.000001 m",
            }
        } else {
            Problem::NotPositive(value)
        };
        return Err(invalid(field, problem));
    }
    Ok(um)
}

impl Scenario {
    /// The contract's default values (docs/simulator.md): 2 m door, 0.1 m/s, 100 ms sonar with a 0.5 m
    /// threshold, 20 ms bumper, SMPA 1 s sense / 3 s act, at most 600 s.
    pub const DEFAULTS: ScenarioFile = ScenarioFile {
        name: String::new(),
        seed: Some(42),
        door_m: Some(2.0),
        max_s: Some(600.0),
        robot: Some(RobotFile {
            speed_mps: Some(0.1),
            avoid_s: Some(2.0),
            slow_m: Some(0.0),
            plan_us: Some(0.0),
        }),
        sonar: Some(SonarFile {
            period_ms: Some(100.0),
            min_m: Some(0.25),
            max_m: Some(2.55),
            threshold_m: Some(0.5),
            noise_m: Some(0.0),
            dropout: Some(0.0),
            latency_ms: Some(0.0),
            height_m: Some(0.0),
            cone_slope: Some(0.5),
        }),
        bumper: Some(BumperFile {
            period_ms: Some(20.0),
            latency_ms: Some(0.0),
            min_contact_ms: Some(0.0),
        }),
        smpa: Some(SmpaFile {
            sense_ms: Some(1000.0),
            act_ms: Some(3000.0),
        }),
        doors: Some(DoorsFile {
            locked: Some(false),
            back_door_m: Some(3.0),
        }),
        fault: None,
        interferences: Interferences(Vec::new()),
    };

    /// Writes the canonical form into `out` and returns its length. The name must be plain
    /// (no quote, backslash or control character): the canonical reader does not unescape,
    /// which keeps the unescaping code, and the panic paths it brings, out of firmware.
    pub fn to_canonical(&self, out: &mut [u8]) -> Result<usize, CanonicalError> {
        if self
            .name
            .chars()
            .any(|c| c == '"' || c == '\\' || c.is_control())
        {
            return Err(CanonicalError::NameNeedsEscapes);
        }
        serde_json_core::to_slice(self, out).map_err(|_| CanonicalError::TooLong)
    }

    /// An empty scenario, to be filled by [`read_canonical`](Self::read_canonical).
    pub const fn empty() -> Self {
        Self {
            name: String::new(),
            seed: 0,
            door_um: 0,
            max_ms: 0,
            speed_um_per_ms: 0,
            avoid_ms: 0,
            slow_um: 0,
            plan_us: 0,
            sonar: Sonar {
                period_ms: 0,
                min_um: 0,
                max_um: 0,
                threshold_um: 0,
                noise_um: 0,
                dropout: 0,
                latency_ms: 0,
                height_um: 0,
                cone_slope_ppm: 0,
            },
            bumper_period_ms: 0,
            bumper_latency_ms: 0,
            bumper_min_contact_ms: 0,
            sense_ms: 0,
            act_ms: 0,
            door_locked: false,
            back_door_um: 0,
            fault: None,
            interferences: Vec::new(),
        }
    }

    /// Reads the canonical form into `self`, in place: no copy of the scenario is ever on the
    /// stack (a microcontroller reads it at boot with a few hundred bytes of stack).
    pub fn read_canonical(&mut self, json: &[u8]) -> Result<(), serde_json_core::de::Error> {
        let mut de = serde_json_core::de::Deserializer::new(json, None);
        serde::de::DeserializeSeed::deserialize(Fill(self), &mut de)?;
        de.end().map(|_| ())
    }

    /// Reads the canonical form (integers only, already validated when it was made).
    pub fn from_canonical(json: &[u8]) -> Result<Self, serde_json_core::de::Error> {
        let mut s = Self::empty();
        s.read_canonical(json)?;
        Ok(s)
    }

    /// The file this scenario comes from, in its own units: what a canonical form read from
    /// outside (a recording's prologue) is checked against, since one made from a validated
    /// file comes back from [`validate`](Self::validate) unchanged.
    pub fn to_file(&self) -> ScenarioFile {
        let m = |um: i64| um as f64 / 1e6;
        let s = |ms: u64| ms as f64 / 1e3;
        let ms = |ms: u64| Some(ms as f64);
        let o = &self.sonar;
        let mut interferences = Vec::new();
        for i in &self.interferences {
            // As many as the scenario holds: the same capacity.
            let _ = interferences.push(InterferenceFile {
                kind: Some(i.kind),
                at_s: Some(f64::from(i.at_ms) / 1e3),
                ahead_m: Some(f64::from(i.ahead_um) / 1e6),
                hold_s: Some(f64::from(i.hold_ms) / 1e3),
                speed_mps: Some(f64::from(i.speed_um_per_ms) / 1e3),
                height_m: Some(f64::from(i.height_um) / 1e6),
            });
        }
        ScenarioFile {
            name: self.name.clone(),
            seed: Some(self.seed),
            door_m: Some(m(self.door_um)),
            max_s: Some(s(self.max_ms)),
            robot: Some(RobotFile {
                speed_mps: Some(self.speed_um_per_ms as f64 / 1e3),
                avoid_s: Some(s(self.avoid_ms)),
                slow_m: Some(m(self.slow_um)),
                plan_us: Some(f64::from(self.plan_us)),
            }),
            sonar: Some(SonarFile {
                period_ms: ms(o.period_ms),
                min_m: Some(m(o.min_um)),
                max_m: Some(m(o.max_um)),
                threshold_m: Some(m(o.threshold_um)),
                noise_m: Some(m(o.noise_um)),
                dropout: Some(o.dropout as f64 / 4_294_967_296.0),
                latency_ms: ms(o.latency_ms),
                height_m: Some(m(o.height_um)),
                cone_slope: Some(o.cone_slope_ppm as f64 / 1e6),
            }),
            bumper: Some(BumperFile {
                period_ms: ms(self.bumper_period_ms),
                latency_ms: ms(self.bumper_latency_ms),
                min_contact_ms: ms(self.bumper_min_contact_ms),
            }),
            smpa: Some(SmpaFile {
                sense_ms: ms(self.sense_ms),
                act_ms: ms(self.act_ms),
            }),
            doors: Some(DoorsFile {
                locked: Some(self.door_locked),
                back_door_m: Some(m(self.back_door_um)),
            }),
            fault: self.fault.map(|(kind, at)| FaultFile {
                kind,
                at_s: Some(f64::from(at) / 1e3),
            }),
            interferences: Interferences(interferences),
        }
    }

    /// Parses and validates a scenario file.
    pub fn parse(json: &[u8]) -> Result<Self, ScenarioError> {
        // Room to decode the longest string with escape sequences (a name).
        let mut unescape = [0u8; 4 * MAX_NAME];
        let (file, _) = serde_json_core::from_slice_escaped::<ScenarioFile>(json, &mut unescape)
            .map_err(ScenarioError::Json)?;
        Self::validate(&file)
    }

    /// Validates a parsed file and converts it to integer units.
    pub fn validate(file: &ScenarioFile) -> Result<Self, ScenarioError> {
        // Every default is `Some` in DEFAULTS; `or` keeps the file's value when present.
        let d = Self::DEFAULTS;
        let dr = d.robot.unwrap_or_default();
        let ds = d.sonar.unwrap_or_default();
        let db = d.bumper.unwrap_or_default();
        let dp = d.smpa.unwrap_or_default();
        let r = file.robot.unwrap_or_default();
        let s = file.sonar.unwrap_or_default();
        let b = file.bumper.unwrap_or_default();
        let p = file.smpa.unwrap_or_default();
        let pick = |v: Option<f64>, default: Option<f64>| v.or(default).unwrap_or(0.0);

        // One rule for blank names, the missions' (white space and invisible characters).
        if psmpa_core::domain::blank(&file.name) {
            return Err(invalid(Field::top("name"), Problem::Empty));
        }
        let name = file.name.clone();
        let door_m = pick(file.door_m, d.door_m);
        let door_um = positive_metres(Field::top("door_m"), door_m)?;
        let max_ms = positive_seconds(Field::top("max_s"), pick(file.max_s, d.max_s))?;
        let speed = pick(r.speed_mps, dr.speed_mps);
        let speed_field = Field::of("robot", "speed_mps");
        if !speed.is_finite() || speed < 0.0 {
            return Err(invalid(speed_field, Problem::Negative(speed)));
        }
        if !(0.001..=10.0).contains(&speed) {
            return Err(invalid(
                speed_field,
                Problem::OutOfRange {
                    value: speed,
                    min: 0.001,
                    max: 10.0,
                },
            ));
        }
        let speed_um_per_ms = (speed * 1000.0 + 0.5) as i64;
        // A side step takes time: one of no time could repeat forever at one instant.
        let avoid_ms =
            positive_seconds(Field::of("robot", "avoid_s"), pick(r.avoid_s, dr.avoid_s))?;

        let sonar = Sonar {
            period_ms: millis(
                Field::of("sonar", "period_ms"),
                pick(s.period_ms, ds.period_ms),
            )?,
            min_um: metres(Field::of("sonar", "min_m"), pick(s.min_m, ds.min_m))?,
            max_um: positive_metres(Field::of("sonar", "max_m"), pick(s.max_m, ds.max_m))?,
            threshold_um: positive_metres(
                Field::of("sonar", "threshold_m"),
                pick(s.threshold_m, ds.threshold_m),
            )?,
            noise_um: metres(Field::of("sonar", "noise_m"), pick(s.noise_m, ds.noise_m))?,
            dropout: {
                let p = pick(s.dropout, ds.dropout);
                let field = Field::of("sonar", "dropout");
                if !p.is_finite() || p < 0.0 {
                    return Err(invalid(field, Problem::Negative(p)));
                }
                if p > 1.0 {
                    return Err(invalid(
                        field,
                        Problem::OutOfRange {
                            value: p,
                            min: 0.0,
                            max: 1.0,
                        },
                    ));
                }
                (p * 4_294_967_296.0 + 0.5) as u64
            },
            latency_ms: latency(
                Field::of("sonar", "latency_ms"),
                pick(s.latency_ms, ds.latency_ms),
            )?,
            height_um: up_to(
                Field::of("sonar", "height_m"),
                pick(s.height_m, ds.height_m),
                MAX_HEIGHT_M,
            )?,
            cone_slope_ppm: up_to(
                Field::of("sonar", "cone_slope"),
                pick(s.cone_slope, ds.cone_slope),
                MAX_CONE_SLOPE,
            )?,
        };
        if sonar.max_um <= sonar.min_um {
            // Name the field the file gave: a `min_m` above the default `max_m` is min's fault.
            let (field, problem) = match s.max_m {
                None => (
                    Field::of("sonar", "min_m"),
                    Problem::OutOfRange {
                        value: pick(s.min_m, ds.min_m),
                        min: 0.0,
                        max: pick(s.max_m, ds.max_m),
                    },
                ),
                Some(max_m) => (
                    Field::of("sonar", "max_m"),
                    Problem::OutOfRange {
                        value: max_m,
                        min: pick(s.min_m, ds.min_m),
                        max: MAX_M,
                    },
                ),
            };
            return Err(invalid(field, problem));
        }
        if sonar.threshold_um <= sonar.min_um || sonar.threshold_um > sonar.max_um {
            return Err(invalid(
                Field::of("sonar", "threshold_m"),
                Problem::ThresholdOutsideRange,
            ));
        }
        let bumper_period_ms = millis(
            Field::of("bumper", "period_ms"),
            pick(b.period_ms, db.period_ms),
        )?;
        let bumper_latency_ms = latency(
            Field::of("bumper", "latency_ms"),
            pick(b.latency_ms, db.latency_ms),
        )?;
        let bumper_min_contact_ms = latency(
            Field::of("bumper", "min_contact_ms"),
            pick(b.min_contact_ms, db.min_contact_ms),
        )?;
        let slow_m = pick(r.slow_m, dr.slow_m);
        let slow_um = metres(Field::of("robot", "slow_m"), slow_m)?;
        if slow_um != 0 {
            return Err(invalid(
                Field::of("robot", "slow_m"),
                Problem::NoSlowZone(slow_m),
            ));
        }
        let plan_us = {
            let us = pick(r.plan_us, dr.plan_us);
            if !(0.0..=f64::from(MAX_PLAN_US)).contains(&us) || f64::from(us as u32) != us {
                let problem = Problem::NotWholeMicros {
                    value: us,
                    max: MAX_PLAN_US,
                };
                return Err(invalid(Field::of("robot", "plan_us"), problem));
            }
            us as u32
        };
        let sense_ms = millis(Field::of("smpa", "sense_ms"), pick(p.sense_ms, dp.sense_ms))?;
        let act_ms = millis(Field::of("smpa", "act_ms"), pick(p.act_ms, dp.act_ms))?;
        let doors = file.doors.unwrap_or_default();
        let default_doors = d.doors.unwrap_or_default();
        let door_locked = doors.locked.or(default_doors.locked).unwrap_or(false);
        let back_door_um = positive_metres(
            Field::of("doors", "back_door_m"),
            pick(doors.back_door_m, default_doors.back_door_m),
        )?;

        let mut interferences = Vec::new();
        for (index, i) in file.interferences.0.iter().enumerate() {
            let at = |name| Field {
                section: Some("interferences"),
                index: Some(index),
                name,
            };
            let kind = i.kind.unwrap_or(Kind::Box);
            let default_ahead = match kind {
                Kind::Box => 0.45,
                Kind::Ball => 0.05,
            };
            // Within range of 32 bits: times are at most a day, distances at most 1 km.
            let item = Interference {
                kind,
                at_ms: seconds(at("at_s"), i.at_s.unwrap_or(3.0))? as u32,
                ahead_um: metres(at("ahead_m"), i.ahead_m.unwrap_or(default_ahead))? as i32,
                // Held for no time, it is never there: refused, not "detected".
                hold_ms: positive_seconds(at("hold_s"), i.hold_s.unwrap_or(4.0))? as u32,
                // µm per ms is mm/s: up_to's µm / 1000, whole (0.0005 m/s was 0).
                speed_um_per_ms: mm_per_s(
                    at("speed_mps"),
                    up_to(at("speed_mps"), i.speed_mps.unwrap_or(0.0), MAX_SPEED_MPS)?,
                    i.speed_mps.unwrap_or(0.0),
                )?,
                height_um: up_to(
                    at("height_m"),
                    i.height_m
                        .unwrap_or(f64::from(kind.default_height_um()) / 1e6),
                    MAX_HEIGHT_M,
                )? as u32,
            };
            // Cannot overflow: the file held at most MAX_INTERFERENCES.
            let _ = interferences.push(item);
        }
        Ok(Self {
            name,
            seed: file.seed.or(d.seed).unwrap_or(0),
            door_um,
            max_ms,
            speed_um_per_ms,
            avoid_ms,
            slow_um,
            plan_us,
            sonar,
            bumper_period_ms,
            bumper_latency_ms,
            bumper_min_contact_ms,
            sense_ms,
            act_ms,
            door_locked,
            back_door_um,
            fault: match file.fault {
                Some(f) => Some((
                    f.kind,
                    seconds(Field::of("fault", "at_s"), f.at_s.unwrap_or(0.0))? as u32,
                )),
                None => None,
            },
            interferences,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(json: &str) -> ScenarioError {
        Scenario::parse(json.as_bytes()).unwrap_err()
    }

    #[test]
    fn the_contract_example_parses_to_integer_units() {
        let json = br#"{
          "name": "sonar-6", "seed": 42, "door_m": 2.0, "max_s": 600,
          "robot":  { "speed_mps": 0.1, "avoid_s": 2.0 },
          "sonar":  { "period_ms": 100, "min_m": 0.25, "max_m": 2.55, "threshold_m": 0.5,
                      "noise_m": 0.0, "dropout": 0.0 },
          "bumper": { "period_ms": 20 },
          "smpa":   { "sense_ms": 1000, "act_ms": 3000 },
          "interferences": [
            { "kind": "box",  "at_s": 3.0,  "ahead_m": 0.45, "hold_s": 4.0 },
            { "kind": "ball", "at_s": 11.0, "ahead_m": 0.05, "hold_s": 4.0 }
          ]
        }"#;
        let s = Scenario::parse(json).unwrap();
        assert_eq!(s.name.as_str(), "sonar-6");
        assert_eq!(s.door_um, 2_000_000);
        assert_eq!(s.speed_um_per_ms, 100);
        assert_eq!(s.sonar.max_um, 2_550_000);
        assert_eq!(s.sonar.threshold_um, 500_000);
        assert_eq!(s.interferences[1].at_ms, 11_000);
        assert_eq!(s.interferences[0].ahead_um, 450_000);
        // Only the required fields: the same scenario, with the shown defaults.
        let minimal = Scenario::parse(
            br#"{"name":"sonar-6","interferences":[
            {"kind":"box","at_s":3.0},{"kind":"ball","at_s":11.0}]}"#,
        )
        .unwrap();
        assert_eq!(minimal, s);
    }

    #[test]
    fn bad_values_name_their_field() {
        let e = err(
            r#"{"name":"x","interferences":[{"kind":"box","at_s":1},{"kind":"ball","at_s":-2}]}"#,
        );
        assert_eq!(
            e.to_string(),
            "interferences[1].at_s: must not be negative, got -2"
        );
        let e = err(r#"{"name":"","interferences":[]}"#);
        assert_eq!(e.to_string(), "name: must not be empty or only spaces");
        let e = err(r#"{"name":"   ","interferences":[]}"#);
        assert_eq!(e.to_string(), "name: must not be empty or only spaces");
        // The field the file gave is the one named.
        let e = err(r#"{"name":"x","sonar":{"min_m":3.0},"interferences":[]}"#);
        assert_eq!(
            e.to_string(),
            "sonar.min_m: must lie between 0 and 2.55, got 3"
        );
        let e = err(r#"{"name":"x","sonar":{"min_m":1,"max_m":0.5},"interferences":[]}"#);
        assert_eq!(
            e.to_string(),
            "sonar.max_m: must lie between 1 and 1000, got 0.5"
        );
        let e = err(r#"{"name":"x","sonar":{"max_m":1e-9},"interferences":[]}"#);
        assert_eq!(
            e.to_string(),
            "sonar.max_m: must be at least 0.000001 m, got 0.000000001"
        );
        let e = err(r#"{"name":"x","bumper":{"period_ms":0.5},"interferences":[]}"#);
        assert_eq!(
            e.to_string(),
            "bumper.period_ms: must be at least 1 ms, got 0.5"
        );
        let e = err(r#"{"name":"x","sonar":{"period_ms":0},"interferences":[]}"#);
        assert_eq!(
            e.to_string(),
            "sonar.period_ms: must be greater than 0, got 0"
        );
        let e = err(r#"{"name":"x","bumper":{"period_ms":2.5},"interferences":[]}"#);
        assert_eq!(
            e.to_string(),
            "bumper.period_ms: must be a whole number of milliseconds, got 2.5"
        );
        let e = err(r#"{"name":"x","sonar":{"threshold_m":3.0},"interferences":[]}"#);
        assert!(e.to_string().starts_with("sonar.threshold_m:"));
        let e = err(r#"{"name":"x","sonar":{"dropout":1.5},"interferences":[]}"#);
        assert_eq!(
            e.to_string(),
            "sonar.dropout: must lie between 0 and 1, got 1.5"
        );
        let e = err(r#"{"name":"x","robot":{"speed_mps":0},"interferences":[]}"#);
        assert!(e.to_string().starts_with("robot.speed_mps:"));
        // A field above 0 says so on its own; past its largest, only the largest is named.
        let e = err(r#"{"name":"x","door_m":1000.001,"interferences":[]}"#);
        assert_eq!(e.to_string(), "door_m: must be at most 1000, got 1000.001");
        let e = err(r#"{"name":"x","door_m":0,"interferences":[]}"#);
        assert_eq!(e.to_string(), "door_m: must be greater than 0, got 0");
        for (latency, problem) in [
            ("-1", "must not be negative, got -1"),
            (
                "2.5",
                "must be a whole number of milliseconds from 0 to 1000, got 2.5",
            ),
            (
                "1001",
                "must be a whole number of milliseconds from 0 to 1000, got 1001",
            ),
        ] {
            let json = std::format!(
                r#"{{"name":"x","sonar":{{"latency_ms":{latency}}},"interferences":[]}}"#
            );
            assert_eq!(
                err(&json).to_string(),
                std::format!("sonar.latency_ms: {problem}")
            );
            let json = std::format!(
                r#"{{"name":"x","bumper":{{"latency_ms":{latency}}},"interferences":[]}}"#
            );
            assert_eq!(
                err(&json).to_string(),
                std::format!("bumper.latency_ms: {problem}")
            );
        }
        let e = err(r#"{"name":"x","robot":{"slow_m":-0.5},"interferences":[]}"#);
        assert_eq!(
            e.to_string(),
            "robot.slow_m: must not be negative, got -0.5"
        );
        for us in ["-1", "0.5", "100001", "1e300"] {
            let json =
                std::format!(r#"{{"name":"x","robot":{{"plan_us":{us}}},"interferences":[]}}"#);
            // As written in the file, `1e300` too (not in 301 digits).
            let shown = us;
            assert_eq!(
                err(&json).to_string(),
                std::format!(
                    "robot.plan_us: must be a whole number of microseconds from 0 to 100000, \
                     got {shown}"
                )
            );
        }
    }

    #[test]
    fn read_latencies_default_to_none_and_take_whole_milliseconds() {
        let s = Scenario::parse(br#"{"name":"x","interferences":[]}"#).unwrap();
        assert_eq!(
            (
                s.sonar.latency_ms,
                s.bumper_latency_ms,
                s.slow_um,
                s.plan_us
            ),
            (0, 0, 0, 0)
        );
        let e = Scenario::parse(br#"{"name":"x","robot":{"slow_m":1.2},"interferences":[]}"#);
        assert_eq!(
            e.unwrap_err().to_string(),
            "robot.slow_m: must be 0: the Fetch Tea robot walks at one speed, with no slow zone; \
             got 1.2"
        );
        let s = Scenario::parse(
            br#"{"name":"x","sonar":{"latency_ms":40},"bumper":{"latency_ms":1000},
                "robot":{"slow_m":0,"plan_us":100000},"interferences":[]}"#,
        )
        .unwrap();
        assert_eq!(
            (
                s.sonar.latency_ms,
                s.bumper_latency_ms,
                s.slow_um,
                s.plan_us
            ),
            (40, 1000, 0, 100_000)
        );
        let mut buf = [0u8; 4096];
        let len = s.to_canonical(&mut buf).unwrap();
        assert_eq!(Scenario::from_canonical(&buf[..len]).unwrap(), s);
    }

    #[test]
    fn a_canonical_form_that_does_not_read_is_named_by_field_and_problem() {
        let s = Scenario::parse(br#"{"name": "c", "interferences": [{"kind": "box", "at_s": 1, "ahead_m": 0.4, "hold_s": 1}]}"#)
            .unwrap();
        let mut buf = [0u8; 4096];
        let len = s.to_canonical(&mut buf).unwrap();
        let good = core::str::from_utf8(&buf[..len]).unwrap().to_owned();
        assert_eq!(
            canonical_problem(good.as_bytes()),
            "refused by the reader, though each field reads"
        );
        let fields: std::vec::Vec<serde_json::Value> = serde_json::from_str(&good).unwrap();
        let with = |i: usize, v: serde_json::Value| {
            let mut f = fields.clone();
            f[i] = v;
            serde_json::to_string(&f).unwrap()
        };
        for (text, says) in [
            (
                with(3, serde_json::json!("far")),
                "field 3 (max_ms): invalid type: string \"far\", expected u64",
            ),
            (
                with(14, serde_json::json!(2)),
                // serde_json says "integer `2`" or, with arbitrary_precision on in the
                // build (as beside xtask), "number": the field and the problem either way.
                "field 14 (door_locked): invalid type: ",
            ),
            (
                with(16, serde_json::json!([7, 1])),
                "field 16 (fault [kind 0-2, at_ms] or null): kind 7: 0, 1 or 2",
            ),
            (
                with(17, serde_json::json!([[2, 1, 1, 1, 0, 0]])),
                "field 17 (interferences): interference 0: kind 2",
            ),
            (
                serde_json::to_string(&fields[..5]).unwrap(),
                "field 5 (avoid_ms): missing: the array ends after 5 fields",
            ),
            ("{}".to_owned(), "not an array of its 18 fields"),
            ("[1,".to_owned(), "not JSON: EOF while parsing"),
        ] {
            let mut scratch = Scenario::empty();
            // serde-json-core's own error names neither the field nor its place.
            let theirs = scratch
                .read_canonical(text.as_bytes())
                .unwrap_err()
                .to_string();
            assert!(!theirs.contains("field"), "{theirs}");
            let problem = canonical_problem(text.as_bytes());
            assert!(problem.starts_with(says), "{text}: {problem}");
        }
    }

    #[test]
    fn shape_errors_come_from_the_json_parser() {
        assert!(matches!(err(r#"{"name":"x"}"#), ScenarioError::Json(_)));
        assert!(matches!(
            err(r#"{"name":"x","interferences":[],"colour":1}"#),
            ScenarioError::Json(_)
        ));
        assert!(matches!(
            err(r#"{"name":"x","interferences":[{"kind":"chair","at_s":1}]}"#),
            ScenarioError::Json(_)
        ));
        assert!(matches!(
            err(r#"{"name":"x","door_m":"far","interferences":[]}"#),
            ScenarioError::Json(_)
        ));
        assert!(matches!(
            err(r#"{"name":"x","interferences":["#),
            ScenarioError::Json(_)
        ));
    }

    #[test]
    fn null_is_a_wrong_type_and_escapes_are_decoded() {
        assert!(matches!(
            err(r#"{"name":"x","door_m":null,"interferences":[]}"#),
            ScenarioError::Json(_)
        ));
        assert!(matches!(
            err(r#"{"name":"x","sonar":{"noise_m":null},"interferences":[]}"#),
            ScenarioError::Json(_)
        ));
        assert!(matches!(
            err(r#"{"name":"x","interferences":[{"at_s":null}]}"#),
            ScenarioError::Json(_)
        ));
        assert!(matches!(
            err(r#"{"name":"x","robot":null,"interferences":[]}"#),
            ScenarioError::Json(_)
        ));
        let s = Scenario::parse(br#"{"name":"caf\u00e9 \"one\"","interferences":[]}"#).unwrap();
        assert_eq!(s.name.as_str(), "caf\u{e9} \"one\"");
        let long = std::format!(
            r#"{{"name":"{}","interferences":[]}}"#,
            "n".repeat(MAX_NAME + 1)
        );
        assert!(matches!(err(&long), ScenarioError::Json(_)));
    }

    #[test]
    fn interference_fields_default_to_the_contract_example() {
        let s = Scenario::parse(br#"{"name":"x","interferences":[{}, {"kind":"ball"}]}"#).unwrap();
        let [a, b] = [s.interferences[0], s.interferences[1]];
        assert_eq!(
            (a.kind, a.at_ms, a.ahead_um, a.hold_ms),
            (Kind::Box, 3_000, 450_000, 4_000)
        );
        assert_eq!((b.kind, b.ahead_um), (Kind::Ball, 50_000));
    }

    #[test]
    fn durations_that_cannot_take_time_are_rejected() {
        let e = err(r#"{"name":"x","robot":{"avoid_s":0},"interferences":[]}"#);
        assert_eq!(
            e.to_string(),
            "robot.avoid_s: must be greater than 0, got 0"
        );
        let e = err(r#"{"name":"x","max_s":0.0004,"interferences":[]}"#);
        assert_eq!(e.to_string(), "max_s: must be at least 0.001 s, got 0.0004");
    }

    #[test]
    fn every_shipped_scenario_survives_the_canonical_form_unchanged() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
        let mut n = 0;
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_none_or(|x| x != "json") {
                continue; // the expected traces' folder
            }
            let s = Scenario::parse(&std::fs::read(&path).unwrap()).unwrap();
            let mut buf = [0u8; 4096];
            let len = s.to_canonical(&mut buf).unwrap();
            let text = core::str::from_utf8(&buf[..len]).unwrap();
            assert!(!text.contains('.'), "integers only: {text}");
            assert_eq!(
                Scenario::from_canonical(&buf[..len]).unwrap(),
                s,
                "{}",
                path.display()
            );
            // With a fault, too.
            let mut faulty = s.clone();
            faulty.fault = Some((FaultKind::Stuck, 1234));
            let len = faulty.to_canonical(&mut buf).unwrap();
            assert_eq!(Scenario::from_canonical(&buf[..len]).unwrap(), faulty);
            n += 1;
        }
        assert!(n >= 12);
        // Names that need escapes have no canonical form (it is read without unescaping).
        let s = Scenario::parse(br#"{"name":"a \"b\"","interferences":[]}"#).unwrap();
        let mut buf = [0u8; 4096];
        assert_eq!(
            s.to_canonical(&mut buf),
            Err(CanonicalError::NameNeedsEscapes)
        );
    }

    /// Values the world cannot represent are refused, not truncated: an obstacle held for no
    /// time (it was "detected" and side-stepped), a speed below or between whole mm/s (0.0005
    /// m/s stood still).
    #[test]
    fn unrepresentable_interferences_are_refused() {
        let one = |field: &str| {
            err(&format!(
                r#"{{"name":"x","interferences":[{{"kind":"box",{field}}}]}}"#
            ))
            .to_string()
        };
        assert_eq!(
            one(r#""hold_s":0"#),
            "interferences[0].hold_s: must be greater than 0, got 0"
        );
        assert_eq!(
            one(r#""speed_mps":0.0005"#),
            "interferences[0].speed_mps: must be at least 0.001 m/s (or 0, standing), got 0.0005"
        );
        assert_eq!(
            one(r#""speed_mps":0.0015"#),
            "interferences[0].speed_mps: must be a whole number of 0.001 m/s, got 0.0015"
        );
        let ok = Scenario::parse(
            br#"{"name":"x","interferences":[{"kind":"box","speed_mps":0.15,"hold_s":0.001}]}"#,
        )
        .unwrap();
        assert_eq!(ok.interferences[0].speed_um_per_ms, 150);
    }
}

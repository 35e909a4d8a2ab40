//! The bench's fault scenarios (`boards/faults/*.json`): a scenario of `scenarios/`, a fault
//! and what must come of it.
//!
//! ```json
//! { "name": "hang", "scenario": "../../scenarios/quiet.json",
//!   "fault": { "kind": "hang", "at_s": 4.0 },
//!   "expect": { "watchdog_resets": 1, "still": true, "reached_door": false,
//!               "log": ["the watchdog reset the board"] } }
//! ```
//!
//! Faults (`kind`): on the pins, played by the world, `no-echo` (the sonar never answers from
//! `at_s`), `echo-stuck-high` (its echo line sticks high at the next trigger), `too-near`
//! (from `at_s` every echo is narrower than the ranger's 20 mm minimum takes), `marker-gone`
//! (from `at_s` the marker sensor sees nothing, even at a door: it leaves its line open),
//! `bumper-chatter` (the bumper's wire makes an edge every `every_us` for `for_s`); in the
//! firmware, through its test points, `hang` (thread mode loops for ever, as a behaviour
//! stuck in a loop) and `panic` (thread mode panics, as a bug would).
//!
//! Expectations (`expect`, each optional): `reached_door`, `collisions`, `watchdog_resets`;
//! `still`: once the fault has struck (the firmware fails a sensor, resets or panics) the
//! motors stop, within `stops_within_ms` or else 20 ms, and never drive again; `motors_off_first`: after a panic the motors are off before the
//! firmware's log says a word; `stops_within_ms`: the motors drive when the fault is
//! injected and stop within that many ms after it (for a hang: the watchdog's timeout and a
//! sensor period), not before it; `log`: lines the log must hold (substrings);
//! `sample_gap_max_ms`: the most each sensor's samples may lie apart.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;

/// A fault on the bench.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Fault {
    /// The sonar never answers.
    NoEcho {
        /// From when, s.
        at_s: f64,
    },
    /// The echo line sticks high.
    EchoStuckHigh {
        /// From when, s.
        at_s: f64,
    },
    /// Something inside the sonar's minimum range: every echo is narrower than 20 mm takes.
    TooNear {
        /// From when, s.
        at_s: f64,
    },
    /// The marker sensor sees nothing, even at a door.
    MarkerGone {
        /// From when, s.
        at_s: f64,
    },
    /// The bumper's wire chatters.
    BumperChatter {
        /// From when, s.
        at_s: f64,
        /// For how long, s.
        for_s: f64,
        /// Between edges, µs.
        every_us: u64,
    },
    /// Thread mode hangs.
    Hang {
        /// When, s.
        at_s: f64,
    },
    /// Thread mode panics.
    Panic {
        /// When, s.
        at_s: f64,
    },
}

impl Fault {
    /// When it strikes, s.
    pub fn at_s(&self) -> f64 {
        match *self {
            Self::NoEcho { at_s }
            | Self::EchoStuckHigh { at_s }
            | Self::TooNear { at_s }
            | Self::MarkerGone { at_s }
            | Self::BumperChatter { at_s, .. }
            | Self::Hang { at_s }
            | Self::Panic { at_s } => at_s,
        }
    }

    /// When it strikes, ns.
    pub fn at_ns(&self) -> u64 {
        (self.at_s().max(0.0) * 1e9) as u64
    }

    /// Its name in the file.
    pub fn name(&self) -> &'static str {
        match self {
            Self::NoEcho { .. } => "no-echo",
            Self::EchoStuckHigh { .. } => "echo-stuck-high",
            Self::TooNear { .. } => "too-near",
            Self::MarkerGone { .. } => "marker-gone",
            Self::BumperChatter { .. } => "bumper-chatter",
            Self::Hang { .. } => "hang",
            Self::Panic { .. } => "panic",
        }
    }
}

/// `fault` as written (serde's tagged enums read numbers through a buffer that serde_json's
/// `arbitrary_precision`, which another crate here turns on, breaks: fields are read flat).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FaultSpec {
    kind: String,
    at_s: f64,
    for_s: Option<f64>,
    every_us: Option<u64>,
}

impl FaultSpec {
    fn fault(&self) -> Result<Fault, String> {
        let at_s = self.at_s;
        let only_at = |f: Fault| match (self.for_s, self.every_us) {
            (None, None) => Ok(f),
            _ => Err(format!("fault {}: only at_s", self.kind)),
        };
        match self.kind.as_str() {
            "no-echo" => only_at(Fault::NoEcho { at_s }),
            "echo-stuck-high" => only_at(Fault::EchoStuckHigh { at_s }),
            "too-near" => only_at(Fault::TooNear { at_s }),
            "marker-gone" => only_at(Fault::MarkerGone { at_s }),
            "hang" => only_at(Fault::Hang { at_s }),
            "panic" => only_at(Fault::Panic { at_s }),
            "bumper-chatter" => match (self.for_s, self.every_us) {
                (Some(for_s), Some(every_us)) => Ok(Fault::BumperChatter {
                    at_s,
                    for_s,
                    every_us,
                }),
                _ => Err("fault bumper-chatter: at_s, for_s and every_us".to_owned()),
            },
            other => Err(format!(
                "unknown fault kind {other:?}: no-echo, echo-stuck-high, too-near, marker-gone, bumper-chatter, hang or panic"
            )),
        }
    }
}

/// What must come of a fault.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Expect {
    /// Whether the robot reaches the kitchen door.
    pub reached_door: Option<bool>,
    /// Collisions.
    pub collisions: Option<u32>,
    /// Resets by the watchdog.
    pub watchdog_resets: Option<u32>,
    /// The motors stop once the fault has struck (within `stops_within_ms`, or 20 ms) and
    /// never drive again.
    #[serde(default)]
    pub still: bool,
    /// After a panic, the motors are off before the log says a word.
    #[serde(default)]
    pub motors_off_first: bool,
    /// The motors drive when the fault is injected through a test point and stop this many
    /// ms after it at most (and not before it).
    pub stops_within_ms: Option<u64>,
    /// Lines the log must hold (substrings).
    #[serde(default)]
    pub log: Vec<String>,
    /// The most each sensor's samples may lie apart, ms.
    #[serde(default)]
    pub sample_gap_max_ms: BTreeMap<String, f64>,
}

/// A fault scenario file.
#[derive(Clone, Debug)]
pub struct FaultFile {
    /// Its name.
    pub name: String,
    /// The scenario it plays.
    pub scenario: PathBuf,
    /// The fault.
    pub fault: Fault,
    /// What must come of it.
    pub expect: Expect,
}

/// A fault scenario file as written.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    name: String,
    scenario: PathBuf,
    fault: FaultSpec,
    expect: Expect,
}

/// Whether `bytes` are meant as a fault scenario rather than a scenario: an object with
/// `expect` or `scenario`, which no scenario has (one without `expect` is then refused as a
/// fault scenario missing it, not read as a scenario; a scenario's own `fault` is its
/// sonar's).
pub fn is_fault_file(bytes: &[u8]) -> bool {
    serde_json::from_slice::<serde_json::Value>(bytes)
        .is_ok_and(|v| ["expect", "scenario"].iter().any(|k| v.get(k).is_some()))
}

/// Reads a fault scenario; its scenario's path made relative to the file's folder.
pub fn load(path: &Path, bytes: &[u8]) -> Result<FaultFile, String> {
    let bad = |e: String| format!("{}: not a fault scenario: {e}", path.display());
    // Strict JSON first: a byte order mark, bad UTF-8 or a duplicate key named as such.
    let bytes = psmpa_sim::json::strict_file(path, bytes)?;
    let raw: File = serde_json::from_slice(&bytes).map_err(|e| bad(e.to_string()))?;
    let base = path.parent().unwrap_or(Path::new("."));
    let file = FaultFile {
        name: raw.name,
        scenario: base.join(&raw.scenario),
        fault: raw.fault.fault().map_err(bad)?,
        expect: raw.expect,
    };
    let at = |e: String| format!("{}: {e}", path.display());
    if file.name.trim().is_empty() {
        return Err(at("name: empty".to_owned()));
    }
    let at_s = file.fault.at_s();
    if !(0.0..=MAX_AT_S).contains(&at_s) {
        return Err(at(format!(
            "fault.at_s {at_s}: from 0 to {MAX_AT_S} s (a day)"
        )));
    }
    if file.fault.at_ns() == 0 && !matches!(file.fault, Fault::NoEcho { .. }) {
        return Err(at("fault.at_s must be above 0".to_owned()));
    }
    if let Fault::BumperChatter {
        for_s, every_us, ..
    } = file.fault
    {
        if !(0.0..=60.0).contains(&for_s) || !(MIN_CHATTER_US..=MAX_CHATTER_US).contains(&every_us)
        {
            return Err(at(format!(
                "a chatter lasts 0 to 60 s with at least {MIN_CHATTER_US} us between edges and at most {MAX_CHATTER_US} (its longest)"
            )));
        }
        let edges = for_s * 1e6 / every_us as f64;
        if edges > MAX_CHATTER_EDGES as f64 {
            return Err(at(format!(
                "a chatter of {edges:.0} edges: the bench plays at most {MAX_CHATTER_EDGES} (each is a pin change the emulator plays)"
            )));
        }
    }
    for (sensor, gap) in &file.expect.sample_gap_max_ms {
        if !["sonar", "bumper"].contains(&sensor.as_str()) {
            return Err(at(format!(
                "expect.sample_gap_max_ms: no sensor {sensor:?} on the bench's robot: sonar or bumper"
            )));
        }
        if !(gap.is_finite() && *gap > 0.0) {
            return Err(at(format!(
                "expect.sample_gap_max_ms.{sensor}: {gap}: a gap is more than 0 ms"
            )));
        }
    }
    let through_test_point = matches!(file.fault, Fault::Hang { .. } | Fault::Panic { .. });
    if let Some(within) = file.expect.stops_within_ms {
        if !through_test_point {
            return Err(at(format!(
                "expect.stops_within_ms: a {} fault is played on the pins, not injected through a test point: only hang and panic have it (still says the motors stay stopped)",
                file.fault.name()
            )));
        }
        if within > MAX_STOPS_WITHIN_MS {
            return Err(at(format!(
                "expect.stops_within_ms {within}: at most {MAX_STOPS_WITHIN_MS} ms (a minute)"
            )));
        }
    }
    if file.expect.motors_off_first && !matches!(file.fault, Fault::Panic { .. }) {
        return Err(at(format!(
            "expect.motors_off_first: only a panic logs its message as it stops the motors, not a {} fault",
            file.fault.name()
        )));
    }
    if file.expect.log.iter().any(|l| l.trim().is_empty()) {
        return Err(at(
            "expect.log: an empty line is in every log: name what the log must say".to_owned(),
        ));
    }
    Ok(file)
}

/// The latest a fault may strike, s: a day, as a scenario's longest run.
pub const MAX_AT_S: f64 = 86_400.0;
/// The shortest time between two edges of a chattering bumper, µs: faster than the chip's
/// GPIO interrupt and the sensing poll it wakes can take them, every edge is one more pending
/// interrupt.
pub const MIN_CHATTER_US: u64 = 20;
/// The longest time between two edges of a chattering bumper, µs: a chatter's longest
/// duration (60 s).
pub const MAX_CHATTER_US: u64 = 60_000_000;
/// The most `expect.stops_within_ms` may be, ms: a minute.
pub const MAX_STOPS_WITHIN_MS: u64 = 60_000;
/// The most edges a chatter may make: each is a pin change the harness plays and logs.
pub const MAX_CHATTER_EDGES: u64 = 200_000;

impl FaultFile {
    /// Whether the fault strikes within `sc`'s run: one later than its `max_s` never does.
    pub fn fits(&self, sc: &psmpa_sim::scenario::Scenario) -> Result<(), String> {
        let at_ms = (self.fault.at_s() * 1e3) as u64;
        if at_ms >= sc.max_ms {
            return Err(format!(
                "fault.at_s {}: after its scenario's run ends (max_s {})",
                self.fault.at_s(),
                sc.max_ms as f64 / 1e3
            ));
        }
        Ok(())
    }
}

//! The result of one run, as the contract's JSON object and as text.

use std::fmt::Write as _;

use serde::Serialize;

use crate::robot::Arch;
use crate::run::{Ending, Summary};
use crate::scenario::Scenario;
use crate::world::{Device, Fate};
use psmpa_core::Describe;

/// Sensor on-time, seconds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SensorOn {
    /// Sonar.
    pub sonar: f64,
    /// Foot bumper.
    pub bumper: f64,
}

/// The largest interval between two delivered samples of each sensor while it stayed on, ms;
/// `null` for a sensor with fewer than two such samples.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SampleGaps {
    /// Sonar.
    pub sonar: Option<u64>,
    /// Foot bumper.
    pub bumper: Option<u64>,
}

/// The JSON object `psmpa-sim run --json` prints (the contract: docs/simulator.md),
/// field for field.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunJson {
    /// Scenario name.
    pub scenario: String,
    /// `psmpa` or `smpa`.
    pub arch: &'static str,
    /// Interferences that were put down.
    pub interferences: u32,
    /// Of which detected.
    pub detected: u32,
    /// `detected / interferences` (1.0 when there were none).
    pub detection_rate: f64,
    /// Collisions.
    pub collisions: u32,
    /// Whether the robot reached the door.
    pub reached_door: bool,
    /// When the run ended, s.
    pub time_cost_s: f64,
    /// Longest reaction latency, ms; `null` when nothing was detected.
    pub max_reaction_ms: Option<u64>,
    /// Sensor on-time.
    pub sensor_on_s: SensorOn,
    /// The largest gap between delivered samples, per sensor.
    pub sample_gap_max_ms: SampleGaps,
    /// Trace hash, 16 lower-case hex digits.
    pub trace_hash: String,
}

/// `detected / interferences`, 1.0 when nothing was put down (nothing was missed).
pub fn rate(detected: u32, interferences: u32) -> f64 {
    if interferences == 0 {
        1.0
    } else {
        f64::from(detected) / f64::from(interferences)
    }
}

fn seconds(ms: u64) -> f64 {
    ms as f64 / 1000.0
}

impl RunJson {
    /// The contract object of a run.
    pub fn new(scenario: &Scenario, summary: &Summary) -> Self {
        let t = &summary.tally;
        Self {
            scenario: scenario.name.as_str().to_owned(),
            arch: summary.arch.name(),
            interferences: t.placed,
            detected: t.detected,
            detection_rate: rate(t.detected, t.placed),
            collisions: t.collisions,
            reached_door: t.reached_door,
            time_cost_s: seconds(summary.time_cost_ms),
            max_reaction_ms: t.max_reaction_ms,
            sensor_on_s: SensorOn {
                sonar: seconds(t.on_ms[0]),
                bumper: seconds(t.on_ms[1]),
            },
            sample_gap_max_ms: SampleGaps {
                sonar: t.sample_gap_max_ms[0],
                bumper: t.sample_gap_max_ms[1],
            },
            trace_hash: format!("{:016x}", summary.trace_hash),
        }
    }
}

/// The architecture as the paper writes it.
pub fn arch_title(arch: Arch) -> &'static str {
    match arch {
        Arch::PSmpa => "P-SMPA",
        Arch::Smpa => "SMPA",
    }
}

/// How the run of `scenario` ended, in words (the mission's names, not indices).
pub fn ending(e: &Ending, scenario: &Scenario) -> String {
    match e {
        Ending::Goal(r) => format!(
            "goal reached: in the kitchen ({} plan{} started, {} failed)",
            r.plans_started,
            if r.plans_started == 1 { "" } else { "s" },
            r.plans_failed
        ),
        Ending::Error(e) => match crate::robot::fetch_tea(scenario) {
            Ok(robot) => format!(
                "the control loop gave up: {}",
                (&robot.mission).describe_error(*e)
            ),
            Err(_) => format!("the control loop gave up: {e:?}"),
        },
        Ending::TimeLimit => "stopped at max_s".to_owned(),
    }
}

/// The human-readable report of one run.
pub fn human(scenario: &Scenario, summary: &Summary) -> String {
    let j = RunJson::new(scenario, summary);
    let mut out = String::new();
    let _ = writeln!(
        out,
        "scenario {} under {}",
        // An escaped control character in the name (`\u001b`) is valid JSON: never print it raw.
        crate::json::printable(&j.scenario),
        arch_title(summary.arch)
    );
    let _ = writeln!(out, "  interferences    {}", j.interferences);
    let _ = writeln!(
        out,
        "  detected         {} ({:.1} %)",
        j.detected,
        100.0 * j.detection_rate
    );
    let _ = writeln!(out, "  collisions       {}", j.collisions);
    let _ = writeln!(
        out,
        "  reached door     {}",
        if j.reached_door { "yes" } else { "no" }
    );
    let _ = writeln!(out, "  time cost        {:.1} s", j.time_cost_s);
    let _ = writeln!(
        out,
        "  max reaction     {}",
        j.max_reaction_ms
            .map_or("-".to_owned(), |ms| format!("{ms} ms"))
    );
    // The contract's `sensor_on_s` (sonar and bumper, the sensors of the walk the paper
    // measures), and no more: the JSON object has exactly the contract's fields, and the text
    // says what the JSON says. The camera's second at the door is in `--trace`.
    let _ = writeln!(
        out,
        "  sensor on-time   sonar {:.1} s, bumper {:.1} s",
        j.sensor_on_s.sonar, j.sensor_on_s.bumper
    );
    let gap = |g: Option<u64>| g.map_or("-".to_owned(), |ms| format!("{ms} ms"));
    let _ = writeln!(
        out,
        "  longest gap      sonar {}, bumper {} (between delivered samples)",
        gap(j.sample_gap_max_ms.sonar),
        gap(j.sample_gap_max_ms.bumper)
    );
    let _ = writeln!(
        out,
        "  outcome          {}",
        ending(&summary.ending, scenario)
    );
    let _ = writeln!(out, "  trace hash       {}", j.trace_hash);
    for (i, (item, report)) in scenario
        .interferences
        .iter()
        .zip(summary.obstacles.iter())
        .enumerate()
    {
        let what = match report.fate {
            _ if report.skipped => "not put down (due after the robot reached the door)".to_owned(),
            _ if !report.placed => "not put down (the run ended before it was due)".to_owned(),
            Fate::Unmet
                if u64::from(item.at_ms) + u64::from(item.hold_ms) > summary.time_cost_ms =>
            {
                "not met (still there when the run ended)".to_owned()
            }
            Fate::Unmet => "not met (taken away before the robot came near)".to_owned(),
            Fate::Detected(d) => format!(
                "detected by the {}{}",
                device(d),
                report
                    .reaction_ms
                    .map_or(String::new(), |r| format!(", reaction {r} ms"))
            ),
            Fate::Collided => "collision".to_owned(),
        };
        // From the integer milliseconds: a float would round 3.55 down and 18.55 up.
        let _ = writeln!(
            out,
            "  #{:<2} {:<4} at {:>4}.{:03} s: {what}",
            i + 1,
            match item.kind {
                crate::scenario::Kind::Box => "box",
                crate::scenario::Kind::Ball => "ball",
            },
            item.at_ms / 1000,
            item.at_ms % 1000,
        );
    }
    out
}

fn device(d: Device) -> &'static str {
    d.name()
}

//! Outputs a user can look at: the trace as CSV, the sensor readings as an SVG plot (like the
//! paper's Figs. 5 and 6), and the behaviours as a Chrome trace-event timeline (Perfetto).

use std::fmt::Write as _;
use std::path::Path;

use plotters::prelude::*;
use psmpa_core::{Phase, TraceEvent};
use serde_json::json;

use crate::cli::report::arch_title;
use crate::robot::{FetchTea, codes};
use crate::scenario::{Kind, Scenario};
use crate::sim::Recorded;
use crate::world::{Device, WorldEvent};

fn secs(ms: u64) -> f64 {
    ms as f64 / 1000.0
}

/// A core trace event in words, with the mission's names (the core's [`psmpa_core::Mission::describe`]),
/// and the robot's own events spelled out.
pub fn describe(mission: &FetchTea<'_>, e: &TraceEvent) -> String {
    match *e {
        TraceEvent::User { code, .. } if code == codes::AVOID => {
            "walk: stop and side-step".to_owned()
        }
        TraceEvent::User { code, .. } if code == codes::RESUME => "walk: resume".to_owned(),
        TraceEvent::User { code, .. } if code == codes::LOCKED => {
            "open door: the handle does not give, the door is locked".to_owned()
        }
        other => mission.describe(other).to_string(),
    }
}

fn world_text(e: &WorldEvent) -> String {
    match *e {
        WorldEvent::Appeared { index, kind, at_um } => format!(
            "#{} {} put down at {:.3} m",
            index + 1,
            match kind {
                Kind::Box => "box",
                Kind::Ball => "ball",
            },
            at_um as f64 / 1e6
        ),
        WorldEvent::Removed(i) => format!("#{} taken away", i + 1),
        WorldEvent::Skipped(i) => format!("#{} not put down (robot at the door)", i + 1),
        WorldEvent::Detected(i, d) => format!("#{} detected by {}", i + 1, d.name()),
        WorldEvent::Collided(i) => format!("#{} collision", i + 1),
        WorldEvent::Reacted(i, ms) => format!("#{} reaction {ms} ms", i + 1),
        other => format!("{other:?}"),
    }
}

/// The trace as CSV: `time_s,sonar_m,bumper,position_m,source,event`. World events and runtime
/// events are merged in time order; readings show 0 while a sensor is off, as on the robot.
pub fn trace_csv(scenario: &Scenario, rec: &Recorded) -> String {
    let mission = crate::robot::fetch_tea(scenario).map(|r| r.mission).ok();
    let mut out = String::from("time_s,sonar_m,bumper,position_m,source,event\n");
    let (mut sonar, mut bumper, mut pos) = (0.0f64, 0u32, 0i64);
    let mut world = rec.world.0.iter().peekable();
    let mut core = rec.trace.0.iter().peekable();
    loop {
        let next_world = world.peek().map(|w| w.0);
        let next_core = core.peek().map(|c| c.0.as_millis());
        let (t, source, text) = match (next_world, next_core) {
            (None, None) => break,
            (Some(w), c) if c.is_none_or(|c| w <= c) => {
                let Some(&(t, p, e)) = world.next() else {
                    break;
                };
                pos = p;
                match e {
                    WorldEvent::Sample(Device::Sonar, mm) => sonar = f64::from(mm) / 1000.0,
                    WorldEvent::Sample(Device::Bumper, level) => bumper = level,
                    WorldEvent::SensorOff(Device::Sonar) => sonar = 0.0,
                    WorldEvent::SensorOff(Device::Bumper) => bumper = 0,
                    _ => {}
                }
                (t, "world", world_text(&e))
            }
            _ => {
                let Some((t, e)) = core.next() else { break };
                let text = mission
                    .as_ref()
                    .map_or_else(|| format!("{e:?}"), |m| describe(m, e));
                (t.as_millis(), "runtime", text)
            }
        };
        let _ = writeln!(
            out,
            "{:.3},{:.3},{},{:.4},{},\"{}\"",
            secs(t),
            sonar,
            bumper,
            pos as f64 / 1e6,
            source,
            text.replace('"', "'")
        );
    }
    out
}

/// Step series of one device's readings (0 while off), in seconds and reading units.
fn readings(rec: &Recorded, device: Device, scale: f64) -> Vec<(f64, f64)> {
    let mut points = vec![(0.0, 0.0)];
    let mut last = 0.0;
    for &(t, _, e) in &rec.world.0 {
        let value = match e {
            WorldEvent::Sample(d, v) if d == device => f64::from(v) * scale,
            WorldEvent::SensorOff(d) if d == device => 0.0,
            _ => continue,
        };
        points.push((secs(t), last));
        points.push((secs(t), value));
        last = value;
    }
    points.push((secs(rec.summary.time_cost_ms), last));
    points
}

/// Plots sonar and bumper readings over time for both architectures (the paper's Figs. 5 and
/// 6): the threshold line, the instants obstacles were put down (box blue, ball orange),
/// detections (green) and collisions (red).
pub fn plot(path: &Path, scenario: &Scenario, runs: &[Recorded]) -> Result<(), String> {
    let root = SVGBackend::new(path, (1200, 330 * runs.len() as u32)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let rows = root.split_evenly((runs.len(), 2));
    let end = runs
        .iter()
        .map(|r| secs(r.summary.time_cost_ms))
        .fold(1.0, f64::max);
    let threshold = scenario.sonar.threshold_um as f64 / 1e6;
    let sonar_max = scenario.sonar.max_um as f64 / 1e6 * 1.05;
    for (i, rec) in runs.iter().enumerate() {
        let title = arch_title(rec.summary.arch);
        for (j, device) in [Device::Sonar, Device::Bumper].into_iter().enumerate() {
            let Some(area) = rows.get(i * 2 + j) else {
                continue;
            };
            let (y_max, scale, unit) = match device {
                Device::Sonar => (sonar_max, 0.001, "distance (m)"),
                _ => (2.3, 1.0, "value (0 off, 1 free, 2 contact)"),
            };
            let mut chart = ChartBuilder::on(area)
                .caption(
                    format!(
                        "{} under {title}: {} readings",
                        printable(scenario.name.as_str()),
                        device.name()
                    ),
                    ("sans-serif", 16),
                )
                .margin(8)
                .x_label_area_size(30)
                .y_label_area_size(45)
                .build_cartesian_2d(0.0..end, 0.0..y_max)
                .map_err(|e| e.to_string())?;
            chart
                .configure_mesh()
                .x_desc("time (s)")
                .y_desc(unit)
                .light_line_style(WHITE)
                .draw()
                .map_err(|e| e.to_string())?;
            let legend = i == 0;
            let mut first = [true; 2];
            for &(t, _, e) in &rec.world.0 {
                let (color, y, k, label) = match e {
                    WorldEvent::Appeared {
                        kind: Kind::Box, ..
                    } => (BLUE.mix(0.35), y_max, 0, "box put down"),
                    WorldEvent::Appeared {
                        kind: Kind::Ball, ..
                    } => (RGBColor(230, 120, 0).mix(0.45), y_max, 1, "ball put down"),
                    _ => continue,
                };
                let series = chart
                    .draw_series(LineSeries::new(
                        [(secs(t), 0.0), (secs(t), y)],
                        color.stroke_width(1),
                    ))
                    .map_err(|e| e.to_string())?;
                if legend && std::mem::take(&mut first[k]) {
                    series.label(label).legend(move |(x, y)| {
                        PathElement::new([(x, y), (x + 16, y)], color.stroke_width(2))
                    });
                }
            }
            let series = chart
                .draw_series(LineSeries::new(
                    readings(rec, device, scale),
                    BLACK.stroke_width(1),
                ))
                .map_err(|e| e.to_string())?;
            if legend {
                series
                    .label("reading (0 while the sensor is off)")
                    .legend(|(x, y)| {
                        PathElement::new([(x, y), (x + 16, y)], BLACK.stroke_width(2))
                    });
            }
            if device == Device::Sonar {
                let series = chart
                    .draw_series(LineSeries::new(
                        [(0.0, threshold), (end, threshold)],
                        RED.mix(0.6).stroke_width(1),
                    ))
                    .map_err(|e| e.to_string())?;
                if legend {
                    series.label("detection threshold").legend(|(x, y)| {
                        PathElement::new([(x, y), (x + 16, y)], RED.mix(0.6).stroke_width(2))
                    });
                }
            }
            let marks = rec.world.0.iter().filter_map(|&(t, _, e)| match e {
                WorldEvent::Detected(_, d) if d == device => Some((secs(t), GREEN.filled())),
                WorldEvent::Collided(_) => Some((secs(t), RED.filled())),
                _ => None,
            });
            chart
                .draw_series(marks.map(|(t, style)| Circle::new((t, y_max * 0.93), 4, style)))
                .map_err(|e| e.to_string())?;
            if legend {
                chart
                    .draw_series(std::iter::once(Circle::new(
                        (-1.0, -1.0),
                        0,
                        GREEN.filled(),
                    )))
                    .map_err(|e| e.to_string())?
                    .label("detected (this sensor)")
                    .legend(|(x, y)| Circle::new((x + 8, y), 4, GREEN.filled()));
                chart
                    .draw_series(std::iter::once(Circle::new((-1.0, -1.0), 0, RED.filled())))
                    .map_err(|e| e.to_string())?
                    .label("collision")
                    .legend(|(x, y)| Circle::new((x + 8, y), 4, RED.filled()));
                chart
                    .configure_series_labels()
                    .position(SeriesLabelPosition::UpperRight)
                    .background_style(WHITE.mix(0.9))
                    .border_style(BLACK.mix(0.3))
                    .label_font(("sans-serif", 12))
                    .draw()
                    .map_err(|e| e.to_string())?;
            }
        }
    }
    root.present().map_err(|e| e.to_string())
}

/// The run as a Chrome trace-event JSON document: one track per behaviour (plan, action
/// state, each sensor, SMPA phase, the robot's legs) plus instants for obstacles.
pub fn timeline(scenario: &Scenario, rec: &Recorded) -> serde_json::Value {
    let mission = crate::robot::fetch_tea(scenario).map(|r| r.mission).ok();
    let name = |e: &TraceEvent| {
        mission
            .as_ref()
            .map_or_else(|| format!("{e:?}"), |m| describe(m, e))
    };
    let us = |ms: u64| ms * 1000;
    let mut events = vec![
        json!({"ph": "M", "pid": 1, "name": "process_name", "args": {"name": format!("{} under {}", scenario.name.as_str(), arch_title(rec.summary.arch))}}),
    ];
    let tracks = [
        "plan",
        "action state",
        "sonar",
        "bumper",
        "camera",
        "SMPA phase",
        "legs",
        "obstacles",
    ];
    for (tid, track) in tracks.iter().enumerate() {
        events.push(json!({"ph": "M", "pid": 1, "tid": tid + 1, "name": "thread_name", "args": {"name": track}}));
    }
    let mut open: std::collections::HashMap<(usize, String), u64> =
        std::collections::HashMap::new();
    let mut span = |events: &mut Vec<serde_json::Value>,
                    tid: usize,
                    label: String,
                    t: u64,
                    begin: bool| {
        if begin {
            open.insert((tid, label), t);
        } else if let Some(start) = open.remove(&(tid, label.clone())) {
            events.push(json!({"ph": "X", "pid": 1, "tid": tid, "name": label, "ts": us(start), "dur": us(t - start)}));
        }
    };
    let mut phase: Option<(String, u64)> = None;
    for (at, e) in &rec.trace.0 {
        let t = at.as_millis();
        let d = mission.as_ref().map(|m| &m.domain);
        match *e {
            TraceEvent::PlanSelected { plan, .. } => {
                let label = mission
                    .as_ref()
                    .and_then(|m| m.library.get(plan))
                    .map_or("plan".to_owned(), |p| p.name.to_owned());
                span(&mut events, 1, label, t, true);
            }
            TraceEvent::PlanSucceeded { plan } | TraceEvent::PlanFailed { plan, .. } => {
                if matches!(e, TraceEvent::PlanFailed { .. }) {
                    events.push(json!({"ph": "i", "s": "t", "pid": 1, "tid": 1, "name": name(e), "ts": us(t)}));
                }
                let label = mission
                    .as_ref()
                    .and_then(|m| m.library.get(plan))
                    .map_or("plan".to_owned(), |p| p.name.to_owned());
                span(&mut events, 1, label, t, false);
            }
            TraceEvent::StateEntered { action, .. } | TraceEvent::StateLeft { action, .. } => {
                let label = d
                    .and_then(|d| d.action(action))
                    .map_or("action".to_owned(), |a| a.name.to_owned());
                span(
                    &mut events,
                    2,
                    label,
                    t,
                    matches!(e, TraceEvent::StateEntered { .. }),
                );
            }
            TraceEvent::SensorOn { sensor } | TraceEvent::SensorOff { sensor } => {
                let tid = 3 + sensor.index().min(2);
                let label = d
                    .and_then(|d| d.sensor(sensor))
                    .map_or("sensor".to_owned(), |s| format!("{} on", s.name));
                span(
                    &mut events,
                    tid,
                    label,
                    t,
                    matches!(e, TraceEvent::SensorOn { .. }),
                );
            }
            TraceEvent::PhaseStarted { phase: p, .. } => {
                if let Some((label, start)) = phase.take() {
                    events.push(json!({"ph": "X", "pid": 1, "tid": 6, "name": label, "ts": us(start), "dur": us(t - start)}));
                }
                phase = Some((
                    match p {
                        Phase::Sense => "sense",
                        Phase::Act => "act",
                    }
                    .to_owned(),
                    t,
                ));
            }
            TraceEvent::PreconditionViolated { .. } | TraceEvent::PreconditionRestored { .. } => {
                events.push(
                    json!({"ph": "i", "s": "t", "pid": 1, "tid": 2, "name": name(e), "ts": us(t)}),
                );
            }
            _ => {}
        }
        if let (TraceEvent::StateLeft { .. }, Some((label, start))) = (e, phase.clone()) {
            events.push(json!({"ph": "X", "pid": 1, "tid": 6, "name": label, "ts": us(start), "dur": us(t - start)}));
            phase = None;
        }
    }
    let mut legs: Option<(&'static str, u64)> = None;
    for &(t, _, e) in &rec.world.0 {
        let next = match e {
            WorldEvent::Walk => Some("walking"),
            WorldEvent::AvoidStarted(_) => Some("side step"),
            WorldEvent::Stop | WorldEvent::AvoidDone(_) | WorldEvent::Arrived(_) => None,
            WorldEvent::Appeared { .. }
            | WorldEvent::Removed(_)
            | WorldEvent::Detected(..)
            | WorldEvent::Collided(_) => {
                events.push(json!({"ph": "i", "s": "t", "pid": 1, "tid": 8, "name": world_text(&e), "ts": us(t)}));
                continue;
            }
            _ => continue,
        };
        if let Some((label, start)) = legs.take() {
            if t > start {
                events.push(json!({"ph": "X", "pid": 1, "tid": 7, "name": label, "ts": us(start), "dur": us(t - start)}));
            }
        }
        legs = next.map(|l| (l, t));
    }
    // Close what was still running when the run ended (at max_s, or on an error).
    let end = rec.summary.time_cost_ms;
    let mut still_open: Vec<((usize, String), u64)> = open.into_iter().collect();
    still_open.sort();
    for ((tid, label), start) in still_open {
        events.push(json!({"ph": "X", "pid": 1, "tid": tid, "name": label, "ts": us(start), "dur": us(end.saturating_sub(start))}));
    }
    if let Some((label, start)) = phase {
        events.push(json!({"ph": "X", "pid": 1, "tid": 6, "name": label, "ts": us(start), "dur": us(end.saturating_sub(start))}));
    }
    if let Some((label, start)) = legs {
        events.push(json!({"ph": "X", "pid": 1, "tid": 7, "name": label, "ts": us(start), "dur": us(end.saturating_sub(start))}));
    }
    json!({"traceEvents": events, "displayTimeUnit": "ms"})
}

/// `text` with control characters replaced: XML 1.0 allows none but tab and line breaks, even
/// escaped, and a scenario name may hold any (`"\u0001"`).
fn printable(text: &str) -> String {
    text.chars()
        .map(|c| if c.is_control() { '\u{fffd}' } else { c })
        .collect()
}

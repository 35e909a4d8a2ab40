//! Outputs a user can look at: the trace as CSV, the sensor readings as an SVG plot (like the
//! paper's Figs. 5 and 6), and the behaviours as a Chrome trace-event timeline (Perfetto).

use std::cell::RefCell;
use std::collections::{HashMap, VecDeque};
use std::fmt::Write as _;
use std::io::{self, Write};
use std::path::PathBuf;

use embassy_time::Instant;

use plotters::prelude::*;
use psmpa_core::{Describe, Phase, TraceEvent, TraceSink};
use serde_json::json;

use crate::cli::files::Output;
use crate::cli::foxglove::McapLog;
use crate::cli::report::arch_title;
use crate::robot::{Arch, FetchTea};
use crate::scenario::{Kind, Scenario};
use crate::sim::{Recorded, WorldRecord};
use crate::world::{Device, WorldEvent, WorldLog};
use psmpa_fetch_tea::codes;

fn secs(ms: u64) -> f64 {
    ms as f64 / 1000.0
}

/// A core trace event in words, with the mission's names (the core's [`psmpa_core::Describe::describe`]),
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

/// A world event in words, as the trace CSV and the expected traces (`scenarios/traces/`)
/// show it; `cargo xtask qemu` rebuilds the firmware's trace with it.
pub fn world_text(e: &WorldEvent) -> String {
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

/// Runtime events held back by [`TraceCsv`] and the MCAP log at most: the world logs what
/// happened since it was last looked at only when it is next looked at, so a runtime event may
/// be followed by world events from before it. Past this many the oldest is written anyway
/// (memory stays bounded; the rows may then be out of time order by that much).
const HOLD: usize = 1 << 16;

/// Runtime events (time in ms) waiting for the world's log to pass their instant, so that an
/// output merges the two in time order, the world's first at the same millisecond.
#[derive(Default)]
pub struct Held(VecDeque<(u64, TraceEvent)>);

impl Held {
    /// When `HOLD` (65,536) events wait, the instant before which the caller lets them out
    /// ([`Held::pop_before`]) before it holds another.
    pub fn overflow(&self) -> Option<u64> {
        match self.0.front() {
            Some(&(first, _)) if self.0.len() >= HOLD => Some(first.saturating_add(1)),
            _ => None,
        }
    }

    /// Holds a runtime event at `t` ms.
    pub fn push(&mut self, t: u64, e: TraceEvent) {
        self.0.push_back((t, e));
    }

    /// The oldest held event from before `before` (any, with `None`).
    pub fn pop_before(&mut self, before: Option<u64>) -> Option<(u64, TraceEvent)> {
        let &(t, _) = self.0.front()?;
        if before.is_some_and(|b| t >= b) {
            return None;
        }
        self.0.pop_front()
    }
}

/// The trace as CSV, written row by row while the run goes (memory does not grow with the
/// run): `time_s,sonar_m,bumper,position_m,source,event`. World and runtime events are merged
/// in time order (the world's first at the same millisecond); readings show 0 while a sensor
/// is off, as on the robot.
pub struct TraceCsv<W: Write> {
    out: W,
    mission: Option<FetchTea<'static>>,
    sonar: f64,
    bumper: u32,
    pos: i64,
    held: Held,
    error: Option<io::Error>,
}

impl<W: Write> TraceCsv<W> {
    /// Starts the CSV of a run of `scenario` with its header.
    pub fn new(out: W, scenario: &Scenario) -> Self {
        let mut csv = Self {
            out,
            mission: crate::robot::fetch_tea(scenario).map(|r| r.mission).ok(),
            sonar: 0.0,
            bumper: 0,
            pos: 0,
            held: Held::default(),
            error: None,
        };
        let header = csv
            .out
            .write_all(b"time_s,sonar_m,bumper,position_m,source,event\n");
        csv.keep(header);
        csv
    }

    fn keep(&mut self, result: io::Result<()>) {
        if let Err(e) = result {
            self.error.get_or_insert(e);
        }
    }

    fn row(&mut self, t: u64, source: &str, text: &str) {
        let written = writeln!(
            self.out,
            "{:.3},{:.3},{},{:.4},{},\"{}\"",
            secs(t),
            self.sonar,
            self.bumper,
            self.pos as f64 / 1e6,
            source,
            text.replace('"', "'")
        );
        self.keep(written);
    }

    fn release(&mut self, before: Option<u64>) {
        while let Some((t, e)) = self.held.pop_before(before) {
            let text = self
                .mission
                .as_ref()
                .map_or_else(|| format!("{e:?}"), |m| describe(m, &e));
            self.row(t, "runtime", &text);
        }
    }

    /// A world event.
    pub fn world(&mut self, t: u64, pos: i64, e: WorldEvent) {
        self.release(Some(t));
        self.pos = pos;
        match e {
            WorldEvent::Sample(Device::Sonar, mm) => self.sonar = f64::from(mm) / 1000.0,
            WorldEvent::Sample(Device::Bumper, level) => self.bumper = level,
            WorldEvent::SensorOff(Device::Sonar) => self.sonar = 0.0,
            WorldEvent::SensorOff(Device::Bumper) => self.bumper = 0,
            _ => {}
        }
        self.row(t, "world", &world_text(&e));
    }

    /// A runtime event.
    pub fn runtime(&mut self, at: Instant, e: &TraceEvent) {
        if let Some(before) = self.held.overflow() {
            self.release(Some(before));
        }
        self.held.push(at.as_millis(), *e);
    }

    /// Writes what is held and gives the writer back, or the first write error.
    pub fn finish(mut self) -> io::Result<W> {
        self.release(None);
        match self.error {
            Some(e) => Err(e),
            None => Ok(self.out),
        }
    }
}

/// A recorded run as text, the form of the expected traces in `scenarios/traces/`: a first
/// line naming the run and its trace hash, then one line per event, `MS w TEXT` for the
/// world and `MS r TEXT` for the runtime, merged in time order with the world's first at the
/// same millisecond (as the CSV). Integer milliseconds and the mission's names only, so
/// the text is the same on every machine.
pub fn trace_text(scenario: &Scenario, arch: Arch, rec: &Recorded) -> String {
    let mission = crate::robot::fetch_tea(scenario).map(|r| r.mission).ok();
    let runtime = |e: &TraceEvent| {
        mission
            .as_ref()
            .map_or_else(|| format!("{e:?}"), |m| describe(m, e))
    };
    let mut out = format!(
        "# {} {} trace_hash {:016x}\n",
        scenario.name,
        arch.name(),
        rec.summary.trace_hash
    );
    let mut line = |t: u64, source: char, text: &str| {
        let _ = writeln!(out, "{t} {source} {text}");
    };
    let mut trace = rec.trace.0.iter().peekable();
    for &(t, _, e) in &rec.world.0 {
        while let Some((at, e)) = trace.next_if(|(at, _)| at.as_millis() < t) {
            line(at.as_millis(), 'r', &runtime(e));
        }
        line(t, 'w', &world_text(&e));
    }
    for (at, e) in trace {
        line(at.as_millis(), 'r', &runtime(e));
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
/// 6), as an SVG document: the threshold line, the instants obstacles were put down (box blue, ball orange),
/// detections (green) and collisions (red).
pub fn plot(scenario: &Scenario, runs: &[Recorded]) -> Result<String, String> {
    let mut svg = String::new();
    draw(
        SVGBackend::with_string(&mut svg, (1200, 330 * runs.len() as u32)).into_drawing_area(),
        scenario,
        runs,
    )?;
    Ok(svg)
}

fn draw(
    root: DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    scenario: &Scenario,
    runs: &[Recorded],
) -> Result<(), String> {
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
            let with_legend = i == 0;
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
                if with_legend && std::mem::take(&mut first[k]) {
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
            if with_legend {
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
                if with_legend {
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
            if with_legend {
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
                legend(&mut chart, SeriesLabelPosition::UpperRight)?;
            }
        }
    }
    root.present().map_err(|e| e.to_string())
}

/// Draws a chart's legend at `position`, in the style of every plot here.
pub(crate) fn legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
) -> Result<(), String> {
    chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK.mix(0.3))
        .label_font(("sans-serif", 12))
        .draw()
        .map_err(|e| e.to_string())
}

/// Tracks of the timeline, by thread id from 1.
const TRACKS: [&str; 8] = [
    "plan",
    "action state",
    "sonar",
    "bumper",
    "camera",
    "SMPA phase",
    "legs",
    "obstacles",
];

/// The run as a Chrome trace-event JSON document (open in Perfetto), written event by event
/// while the run goes: one track per behaviour (plan, action state, each sensor, SMPA phase,
/// the robot's legs) plus instants for obstacles. Memory holds only the spans still open.
pub struct Timeline<W: Write> {
    out: W,
    mission: Option<FetchTea<'static>>,
    open: HashMap<(usize, String), u64>,
    phase: Option<(&'static str, u64)>,
    legs: Option<(&'static str, u64)>,
    error: Option<io::Error>,
}

fn us(ms: u64) -> u64 {
    ms.saturating_mul(1000)
}

impl<W: Write> Timeline<W> {
    /// Starts the timeline of a run of `scenario` under `arch`.
    pub fn new(out: W, scenario: &Scenario, arch: Arch) -> Self {
        let mut t = Self {
            out,
            mission: crate::robot::fetch_tea(scenario).map(|r| r.mission).ok(),
            open: HashMap::new(),
            phase: None,
            legs: None,
            error: None,
        };
        let head = t.out.write_all(b"{\"traceEvents\": [\n");
        t.keep(head);
        let process = format!("{} under {}", scenario.name.as_str(), arch_title(arch));
        t.event(&json!({"ph": "M", "pid": 1, "name": "process_name", "args": {"name": process}}));
        for (tid, track) in TRACKS.iter().enumerate() {
            t.event(&json!({"ph": "M", "pid": 1, "tid": tid + 1, "name": "thread_name", "args": {"name": track}}));
        }
        t
    }

    fn keep(&mut self, result: io::Result<()>) {
        if let Err(e) = result {
            self.error.get_or_insert(e);
        }
    }

    fn event(&mut self, e: &serde_json::Value) {
        // Every event ends with a comma; `finish` closes the list with one more event.
        let written = serde_json::to_writer(&mut self.out, e)
            .map_err(io::Error::from)
            .and_then(|()| self.out.write_all(b",\n"));
        self.keep(written);
    }

    fn span(&mut self, tid: usize, label: String, t: u64, begin: bool) {
        if begin {
            self.open.insert((tid, label), t);
        } else if let Some(start) = self.open.remove(&(tid, label.clone())) {
            self.complete(tid, &label, start, t);
        }
    }

    fn complete(&mut self, tid: usize, label: &str, start: u64, end: u64) {
        self.event(&json!({"ph": "X", "pid": 1, "tid": tid, "name": label, "ts": us(start), "dur": us(end.saturating_sub(start))}));
    }

    fn instant(&mut self, tid: usize, label: String, t: u64) {
        self.event(&json!({"ph": "i", "s": "t", "pid": 1, "tid": tid, "name": label, "ts": us(t)}));
    }

    fn plan_name(&self, plan: psmpa_core::PlanId) -> String {
        self.mission
            .as_ref()
            .and_then(|m| m.library.get(plan))
            .map_or("plan".to_owned(), |p| p.name.to_owned())
    }

    /// A runtime event.
    pub fn runtime(&mut self, at: Instant, e: &TraceEvent) {
        let t = at.as_millis();
        let name = |e: &TraceEvent| {
            self.mission
                .as_ref()
                .map_or_else(|| format!("{e:?}"), |m| describe(m, e))
        };
        let d = self.mission.as_ref().map(|m| &m.domain);
        match *e {
            TraceEvent::PlanSelected { plan, .. } => {
                let label = self.plan_name(plan);
                self.span(1, label, t, true);
            }
            TraceEvent::PlanSucceeded { plan } | TraceEvent::PlanFailed { plan, .. } => {
                if matches!(e, TraceEvent::PlanFailed { .. }) {
                    let text = name(e);
                    self.instant(1, text, t);
                }
                let label = self.plan_name(plan);
                self.span(1, label, t, false);
            }
            TraceEvent::StateEntered { action, .. } | TraceEvent::StateLeft { action, .. } => {
                let label = d
                    .and_then(|d| d.action(action))
                    .map_or("action".to_owned(), |a| a.name.to_owned());
                self.span(2, label, t, matches!(e, TraceEvent::StateEntered { .. }));
            }
            TraceEvent::SensorOn { sensor } | TraceEvent::SensorOff { sensor } => {
                let tid = 3 + sensor.index().min(2);
                let label = d
                    .and_then(|d| d.sensor(sensor))
                    .map_or("sensor".to_owned(), |s| format!("{} on", s.name));
                self.span(tid, label, t, matches!(e, TraceEvent::SensorOn { .. }));
            }
            TraceEvent::PhaseStarted { phase: p, .. } => {
                if let Some((label, start)) = self.phase.take() {
                    self.complete(6, label, start, t);
                }
                let label = match p {
                    Phase::Sense => "sense",
                    Phase::Act => "act",
                };
                self.phase = Some((label, t));
            }
            TraceEvent::PreconditionViolated { .. } | TraceEvent::PreconditionRestored { .. } => {
                let text = name(e);
                self.instant(2, text, t);
            }
            _ => {}
        }
        if matches!(e, TraceEvent::StateLeft { .. })
            && let Some((label, start)) = self.phase.take()
        {
            self.complete(6, label, start, t);
        }
    }

    /// A world event.
    pub fn world(&mut self, t: u64, e: WorldEvent) {
        let next = match e {
            WorldEvent::Walk => Some("walking"),
            WorldEvent::AvoidStarted(_) => Some("side step"),
            WorldEvent::Stop | WorldEvent::AvoidDone(_) | WorldEvent::Arrived(_) => None,
            WorldEvent::Appeared { .. }
            | WorldEvent::Removed(_)
            | WorldEvent::Detected(..)
            | WorldEvent::Collided(_) => {
                self.instant(8, world_text(&e), t);
                return;
            }
            _ => return,
        };
        if let Some((label, start)) = self.legs.take()
            && t > start
        {
            self.complete(7, label, start, t);
        }
        self.legs = next.map(|l| (l, t));
    }

    /// Closes what was still running when the run ended at `end_ms` (at `max_s`, or on an
    /// error), ends the document and gives the writer back, or the first write error.
    pub fn finish(mut self, end_ms: u64) -> io::Result<W> {
        let mut still_open: Vec<((usize, String), u64)> = self.open.drain().collect();
        still_open.sort();
        for ((tid, label), start) in still_open {
            self.complete(tid, &label, start, end_ms);
        }
        if let Some((label, start)) = self.phase.take() {
            self.complete(6, label, start, end_ms);
        }
        if let Some((label, start)) = self.legs.take() {
            self.complete(7, label, start, end_ms);
        }
        // A last event so that the list needs no comma bookkeeping: the run's end.
        let end =
            json!({"ph": "i", "s": "g", "pid": 1, "tid": 1, "name": "run ended", "ts": us(end_ms)});
        let tail = serde_json::to_writer(&mut self.out, &end)
            .map_err(io::Error::from)
            .and_then(|()| self.out.write_all(b"\n], \"displayTimeUnit\": \"ms\"}\n"));
        self.keep(tail);
        match self.error {
            Some(e) => Err(e),
            None => Ok(self.out),
        }
    }
}

/// `text` with control characters replaced: XML 1.0 allows none but tab and line breaks, even
/// escaped, and a scenario name may hold any (`"\u0001"`).
fn printable(text: &str) -> String {
    text.chars()
        .map(|c| if c.is_control() { '\u{fffd}' } else { c })
        .collect()
}

/// The most sensor samples a run may take, up to `max_s`, for `--plot`: every sample is kept
/// for the plot and drawn (two runs, a few hundred bytes a sample in all).
pub const PLOT_SAMPLES: u64 = 1_000_000;

/// `ms` as seconds, to the millisecond it was given: 500001 is "500.001", 600000 "600".
pub fn seconds_text(ms: u64) -> String {
    match ms % 1000 {
        0 => (ms / 1000).to_string(),
        frac => format!(
            "{}.{}",
            ms / 1000,
            format!("{frac:03}").trim_end_matches('0')
        ),
    }
}

/// Refuses `--plot` up front for a scenario whose runs may take more than [`PLOT_SAMPLES`]
/// samples.
pub fn plot_fits(scenario: &Scenario) -> Result<(), String> {
    let per = |period_ms: u64| scenario.max_ms / period_ms.max(1);
    let samples = per(scenario.sonar.period_ms).saturating_add(per(scenario.bumper_period_ms));
    if samples > PLOT_SAMPLES {
        return Err(format!(
            "--plot: up to {samples} sensor samples in {} s, more than the {PLOT_SAMPLES} a \
             plot holds: shorten max_s, lengthen the sensor periods, or leave out --plot \
             (--trace and --timeline have no limit)",
            seconds_text(scenario.max_ms)
        ));
    }
    Ok(())
}

/// The outputs a run writes while it goes (trace CSV, timeline, MCAP log), shared by the world's log and the runtime's
/// trace sink ([`WorldStream`], [`TraceStream`]).
pub struct Streams {
    csv: Option<TraceCsv<Output>>,
    timeline: Option<Timeline<Output>>,
    /// The MCAP log and the path it is for (its errors name it).
    mcap: Option<(McapLog<Output>, PathBuf)>,
    /// The flight recording (`--record`).
    record: Option<psmpa_core::record::Recorder<crate::replay::RecordFile>>,
    world: Option<WorldRecord>,
}

impl Streams {
    /// Streams a run of `scenario` under `arch` into the trace CSV and the timeline given,
    /// and keeps the world's events when `keep_world` (for a plot).
    pub fn new(
        scenario: &Scenario,
        arch: Arch,
        csv: Option<Output>,
        timeline: Option<Output>,
        keep_world: bool,
    ) -> Self {
        Self {
            csv: csv.map(|o| TraceCsv::new(o, scenario)),
            timeline: timeline.map(|o| Timeline::new(o, scenario, arch)),
            mcap: None,
            record: None,
            world: keep_world.then(WorldRecord::default),
        }
    }

    /// Also streams the run of `scenario` into an MCAP log (`--mcap`).
    pub fn with_mcap(mut self, out: Output, scenario: &Scenario) -> Result<Self, String> {
        let path = out.path().to_path_buf();
        let log = McapLog::new(out, scenario).map_err(|e| format!("{}: {e}", path.display()))?;
        self.mcap = Some((log, path));
        Ok(self)
    }

    /// Also records the run into `out` (`--record`): the scenario's bytes and the architecture
    /// go in the recording.
    pub fn with_record(mut self, out: Output, scenario_json: &[u8], arch: Arch) -> Self {
        self.record = Some(crate::replay::recorder(out, scenario_json, arch));
        self
    }

    /// Ends the outputs of a run that ended at `end_ms`; gives back the outputs to commit
    /// and the world's events if kept.
    pub fn finish(self, end_ms: u64) -> Result<(Vec<Output>, Option<WorldRecord>), String> {
        let fail = |e: io::Error| format!("cannot write: {e}");
        let mut outputs = Vec::new();
        if let Some(csv) = self.csv {
            outputs.push(csv.finish().map_err(fail)?);
        }
        if let Some(timeline) = self.timeline {
            outputs.push(timeline.finish(end_ms).map_err(fail)?);
        }
        if let Some((log, path)) = self.mcap {
            outputs.push(
                log.finish()
                    .map_err(|e| format!("{}: {e}", path.display()))?,
            );
        }
        if let Some(record) = self.record {
            outputs.push(record.into_inner().0);
        }
        Ok((outputs, self.world))
    }
}

/// The world's side of [`Streams`].
pub struct WorldStream<'a>(pub &'a RefCell<Streams>);

impl WorldLog for WorldStream<'_> {
    fn log(&mut self, at_ms: u64, pos_um: i64, event: WorldEvent) {
        let mut s = self.0.borrow_mut();
        if let Some(csv) = &mut s.csv {
            csv.world(at_ms, pos_um, event);
        }
        if let Some(timeline) = &mut s.timeline {
            timeline.world(at_ms, event);
        }
        if let Some((log, _)) = &mut s.mcap {
            log.world(at_ms, pos_um, event);
        }
        if let Some(world) = &mut s.world {
            world.log(at_ms, pos_um, event);
        }
    }
}

/// The runtime's side of [`Streams`].
pub struct TraceStream<'a>(pub &'a RefCell<Streams>);

impl<Ms: psmpa_core::Mission<Facts = psmpa_core::FactSet>> TraceSink<Ms> for TraceStream<'_> {
    fn record(&mut self, at: Instant, event: &TraceEvent) {
        let mut s = self.0.borrow_mut();
        if let Some(csv) = &mut s.csv {
            csv.runtime(at, event);
        }
        if let Some(timeline) = &mut s.timeline {
            timeline.runtime(at, event);
        }
        if let Some((log, _)) = &mut s.mcap {
            log.runtime(at, event);
        }
        if let Some(record) = &mut s.record {
            TraceSink::<Ms>::record(record, at, event);
        }
    }
}

//! The firmware's world trace against the expected traces of `scenarios/traces/`.
//!
//! The firmware logs every world event as numbers (`psmpa_firmware::world_trace`); this
//! module rebuilds the host's text from them (`world_text`) and compares it with the `w`
//! lines of the expected trace. On the target computing takes real time, none in virtual
//! time, so its instants come later. What must hold, and what may differ (the allowances were
//! set from the shifts measured in all 30 runs on both machines):
//!
//! * Events (every line but a sample): the same ones, in the same order. An event may lag
//!   the host's, never lead it, by [`TICKS_PER_WALK`] ms for the start and for each walk
//!   started so far, plus the scenario's planning time (`plan_us`) per walk: the robot starts
//!   each walk that much later. Obstacles are put down, taken away and skipped at the scenario's
//!   instants: no lag at all. Measured: at most 8 ms (16 allowed, `bumper-6`), and 356 ms in
//!   `replan` (366 allowed: 7 walks planning 50 ms each).
//! * Quantities that derive from instants: where an obstacle is put down (ahead of the
//!   robot, which lags) within the walking speed times the lag, and 1 mm of the text's
//!   rounding; a reaction longer by at most its line's own lag (the sample that detected the
//!   obstacle came that much later, the obstacle did not), or [`REACTION_MS`] if more.
//! * An obstacle taken away as a side step around it ends is logged only where the removal
//!   comes first: on one side only, it is accepted when its instant lies between the two
//!   sides' ends of that side step.
//! * Where the sonar drops samples: the target's sonar takes one more sample at the start
//!   (its sensors come on a tick later), so its draws run one ahead of the host's until a
//!   loss the host does not have realigns them. Such losses are accepted, as many as its
//!   extra reads; its readings may be the host's one period later; every lag and reaction
//!   may be one period longer (a reaction also one shorter).
//! * Samples: each firmware reading must be one the host read within the lag before it (the
//!   sonar's within how far the robot and the fastest walking obstacle close in that lag, and
//!   twice its noise; a reading of "nothing in range" also where the host's lay that close to
//!   an edge of what the sonar sees: its minimum or maximum range, or where a low box leaves
//!   its cone); per device the counts may differ by one, and one more per period the run lasts
//!   longer.

use std::collections::BTreeMap;
use std::path::PathBuf;

use psmpa_firmware::world_trace::{Fields, decode};
use psmpa_sim::cli::outputs::world_text;
use psmpa_sim::scenario::Scenario;
use similar::{Algorithm, DiffTag, capture_diff_slices};

use crate::firmware::root;

/// The lag a walk adds at most, ms. Measured on both machines: one tick per walk and one at the
/// start (the sensors come on a tick later); two per walk while a logged line cost 1,400
/// cycles instead of 1,150. The second tick is that margin: a step that grows by a fifth may
/// cross one more tick boundary per walk.
pub const TICKS_PER_WALK: u64 = 2;

/// The lag a phase that switches sensors on adds at most, ms: on the target the sampling that
/// starts it takes a tick (SMPA's sense phases: measured 1 ms each).
pub const TICKS_PER_PHASE: u64 = 1;

/// The lag a side step adds at most, ms: the robot brakes for what it saw, then starts the
/// step a tick later (measured 1 ms each, `bumper-4`; the walk it resumes counts as a walk).
pub const TICKS_PER_SIDE_STEP: u64 = 1;

/// How much earlier the target may read a bump switch's change, ms: the switch settles after
/// sub-millisecond bounces (the body's), played at instants within a tick that differ on the
/// target, so the debounced read lands on either side of a tick (measured: 1 ms, `person`).
pub const SWITCH_LEAD_MS: u64 = 1;

/// What has begun by a line's instant: walks, phases that switched sensors on, side steps.
#[derive(Clone, Copy, Default)]
struct Begun {
    walks: u64,
    phases: u64,
    steps: u64,
}

/// How much longer a reaction may take on the target, ms: its stop comes in the poll after
/// the sample's tick, and the robot's devices answer on the tick their edge is played in
/// (measured: 0 to 2 ms in every reaction but one after a lost sample).
pub const REACTION_MS: u64 = 2;

/// Lines of a diff shown per run: enough to read the first differences, not a flood.
const SHOWN: usize = 40;

/// One world event: its instant (ms) and its text, as the host writes it.
pub type Line = (u64, String);

/// Runs' world events by (scenario, arch).
pub type Traces = BTreeMap<(String, String), Vec<Line>>;

/// One device's readings in order: instant (ms) and reading (`None`: lost).
type Reads = Vec<(u64, Option<u64>)>;

/// The world events of every run in a firmware log, by (scenario, arch), rebuilt into the
/// host's text; and the lines that could not be read. A run's `w` lines come before its
/// `result` line.
pub fn firmware_traces(log: &str) -> (Traces, Vec<String>) {
    let (mut runs, mut errors, mut current) = (BTreeMap::new(), Vec::new(), Vec::new());
    for line in log.lines() {
        let mut words = line.split_whitespace().skip(2);
        match words.next() {
            Some("w") => {
                let n: Vec<&str> = words.collect();
                match world_line(&n) {
                    Some(l) => current.push(l),
                    None => errors.push(format!("unreadable world event: {line}")),
                }
            }
            Some("result") => {
                let fields: BTreeMap<&str, &str> =
                    words.filter_map(|kv| kv.split_once('=')).collect();
                let get = |k| fields.get(k).copied().unwrap_or("?").to_owned();
                runs.insert((get("scenario"), get("arch")), std::mem::take(&mut current));
            }
            _ => {}
        }
    }
    if !current.is_empty() {
        errors.push(format!(
            "{} world events after the last run's result",
            current.len()
        ));
    }
    (runs, errors)
}

/// `MS KIND A B VALUE` as an instant and the event's text.
fn world_line(n: &[&str]) -> Option<Line> {
    let [ms, kind, a, b, value] = n else {
        return None;
    };
    let event = decode(Fields {
        kind: kind.parse().ok()?,
        a: a.parse().ok()?,
        b: b.parse().ok()?,
        value: value.parse().ok()?,
    })?;
    Some((ms.parse().ok()?, world_text(&event)))
}

/// The expected trace of `scenario` under `arch`.
pub fn expected_path(scenario: &str, arch: &str) -> PathBuf {
    root().join(format!("scenarios/traces/{scenario}.{arch}.trace"))
}

/// The world lines (`MS w TEXT`) of an expected trace.
pub fn world_lines(text: &str) -> Vec<Line> {
    text.lines()
        .filter_map(|l| {
            let (ms, rest) = l.split_once(' ')?;
            Some((ms.parse().ok()?, rest.strip_prefix("w ")?.to_owned()))
        })
        .collect()
}

/// Lines as the expected traces write them (`MS w TEXT`).
pub fn as_text(lines: &[Line]) -> String {
    lines
        .iter()
        .map(|(ms, t)| format!("{ms} w {t}\n"))
        .collect()
}

/// What a scenario lets its firmware trace differ by (see the module doc).
#[derive(Clone, Debug, Default)]
pub struct Allowance {
    /// Processor time a walk plans for when it starts or resumes, ms.
    pub plan_ms: u64,
    /// The sonar's period if it drops samples, else 0, ms.
    pub lossy_ms: u64,
    /// Walking speed, µm per ms.
    pub speed_um_per_ms: u64,
    /// How fast the robot and the fastest walking obstacle close in, µm per ms.
    pub closing_um_per_ms: u64,
    /// Where what the sonar sees begins or ends, mm: its range's ends and each low box's cone
    /// edge. Its reading of nothing in range is `max_mm`.
    pub edges_mm: Vec<u64>,
    /// The sonar's reading of nothing in range, mm.
    pub max_mm: u64,
    /// The sonar's noise amplitude, µm.
    pub noise_um: u64,
    /// Sampling periods of the sonar and the bumper, ms (the camera and the handle read once
    /// when asked: their counts must be equal).
    pub periods_ms: [u64; 2],
}

impl Allowance {
    /// What `sc` allows.
    pub fn of(sc: &Scenario) -> Self {
        Self {
            plan_ms: u64::from(sc.plan_us).div_ceil(1000),
            lossy_ms: if sc.sonar.dropout > 0 {
                sc.sonar.period_ms
            } else {
                0
            },
            speed_um_per_ms: sc.speed_um_per_ms.unsigned_abs(),
            closing_um_per_ms: sc.speed_um_per_ms.unsigned_abs()
                + sc.interferences
                    .iter()
                    .map(|i| u64::from(i.speed_um_per_ms))
                    .max()
                    .unwrap_or(0),
            edges_mm: [sc.sonar.min_um, sc.sonar.max_um]
                .into_iter()
                .chain(
                    sc.interferences
                        .iter()
                        .map(|i| sc.sonar.seen_from_um(i64::from(i.height_um)))
                        .filter(|&e| e > 0 && e < i64::MAX),
                )
                .map(|um| psmpa_sim::scenario::to_mm(um).unsigned_abs())
                .collect(),
            max_mm: psmpa_sim::scenario::to_mm(sc.sonar.max_um).unsigned_abs(),
            noise_um: sc.sonar.noise_um.unsigned_abs(),
            periods_ms: [sc.sonar.period_ms, sc.bumper_period_ms],
        }
    }

    /// The largest lag after what has `begun`, ms.
    fn lag_ms(&self, begun: Begun) -> u64 {
        TICKS_PER_WALK * (begun.walks + 1)
            + self.plan_ms * begun.walks
            + begun.phases * TICKS_PER_PHASE
            + begun.steps * TICKS_PER_SIDE_STEP
            + self.lossy_ms
    }
}

/// What one run's comparison found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Stats {
    /// Lines compared (the firmware's).
    pub lines: usize,
    /// Of which samples.
    pub samples: usize,
    /// The largest lag of an event, ms.
    pub max_shift_ms: u64,
    /// The lag allowed where the largest was measured, ms.
    pub bound_ms: u64,
    /// Lines on one side only, accepted for their cause: obstacles taken away as a side step
    /// ended, sonar losses where the draws realign.
    pub accepted: usize,
}

/// An event line as the comparison sees it: what must be equal, and the quantity that may
/// differ (µm for a position, ms for a reaction).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
struct Key(String);

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Quantity {
    None,
    /// Where an obstacle is put down, µm.
    Position(u64),
    /// A reaction, ms.
    Reaction(u64),
}

/// The key and quantity of an event's text.
fn key(text: &str) -> (Key, Quantity) {
    if let Some((head, tail)) = text.split_once(" put down at ")
        && let Some(m) = tail.strip_suffix(" m")
        && let Some(um) = micrometres(m)
    {
        return (
            Key(format!("{head} put down at … m")),
            Quantity::Position(um),
        );
    }
    if let Some((head, tail)) = text.split_once(" reaction ")
        && let Some(ms) = tail.strip_suffix(" ms").and_then(|v| v.parse().ok())
    {
        return (Key(format!("{head} reaction … ms")), Quantity::Reaction(ms));
    }
    (Key(text.to_owned()), Quantity::None)
}

/// `1.234` (metres, 3 decimals) in µm.
fn micrometres(m: &str) -> Option<u64> {
    let (whole, frac) = m.split_once('.')?;
    if frac.len() != 3 {
        return None;
    }
    Some(whole.parse::<u64>().ok()? * 1_000_000 + frac.parse::<u64>().ok()? * 1000)
}

/// Obstacles are put down, taken away and skipped at the scenario's instants.
fn fixed(text: &str) -> bool {
    text.contains(" put down at ")
        || text.ends_with(" taken away")
        || text.contains(" not put down")
}

/// A sample's device (`Sonar`, `Bumper`, ...) and reading (`None`: lost), or `None` for an
/// event.
fn sample(text: &str) -> Option<(&str, Option<u64>)> {
    if let Some(d) = text
        .strip_prefix("SampleLost(")
        .and_then(|r| r.strip_suffix(')'))
    {
        return Some((d, None));
    }
    let (d, v) = text
        .strip_prefix("Sample(")?
        .strip_suffix(')')?
        .split_once(", ")?;
    Some((d, Some(v.parse().ok()?)))
}

/// One row of the comparison: an event on both sides, or on one.
#[derive(Clone, Copy, Debug)]
enum Row {
    Both(usize, usize),
    Host(usize),
    Firmware(usize),
}

/// Compares the firmware's world lines `got` with the expected ones `want` under `allow`.
/// `Err` names the first difference, then shows a unified-style diff of the events that
/// differ (`-` the expected line, `+` the firmware's, with what was allowed; headed by the
/// two `names`), then the samples that differ.
pub fn compare(
    want: &[Line],
    got: &[Line],
    allow: &Allowance,
    names: (&str, &str),
) -> Result<Stats, String> {
    let events = |lines: &[Line]| -> Vec<(u64, String)> {
        lines
            .iter()
            .filter(|(_, t)| sample(t).is_none())
            .cloned()
            .collect()
    };
    let (we, ge) = (events(want), events(got));
    let wk: Vec<(Key, Quantity)> = we.iter().map(|(_, t)| key(t)).collect();
    let gk: Vec<(Key, Quantity)> = ge.iter().map(|(_, t)| key(t)).collect();
    // What has begun by each line's instant (one begun at the same instant counts: the
    // wheels' first write comes before the world logs the walk).
    let begun: Vec<Begun> = we
        .iter()
        .scan((Begun::default(), None), |(b, last_on), (at, t)| {
            b.walks += u64::from(t == "Walk");
            b.steps += u64::from(t.starts_with("AvoidStarted("));
            if t.starts_with("SensorOn(") && *last_on != Some(*at) {
                b.phases += 1;
                *last_on = Some(*at);
            }
            Some(*b)
        })
        .collect();
    let walks: Vec<Begun> = we
        .iter()
        .map(|(at, _)| {
            let n = we.partition_point(|(u, _)| u <= at);
            n.checked_sub(1).map_or(Begun::default(), |k| begun[k])
        })
        .collect();
    let (wkeys, gkeys): (Vec<&Key>, Vec<&Key>) = (
        wk.iter().map(|(k, _)| k).collect(),
        gk.iter().map(|(k, _)| k).collect(),
    );
    let mut rows = Vec::new();
    for op in capture_diff_slices(Algorithm::Myers, &wkeys, &gkeys) {
        let (tag, w, g) = op.as_tag_tuple();
        match tag {
            DiffTag::Equal => rows.extend(w.zip(g).map(|(i, j)| Row::Both(i, j))),
            _ => {
                rows.extend(w.map(Row::Host));
                rows.extend(g.map(Row::Firmware));
            }
        }
    }
    // An event on one side only that the other has elsewhere: the order differs; compared
    // as a pair, its lag checked like any other's.
    let mut partner: BTreeMap<usize, usize> = BTreeMap::new();
    for a in 0..rows.len() {
        let Row::Host(i) = rows[a] else { continue };
        let found = (0..rows.len()).find(|&b| {
            !partner.contains_key(&b) && matches!(rows[b], Row::Firmware(j) if gk[j].0 == wk[i].0)
        });
        if let Some(b) = found {
            partner.insert(a, b);
            partner.insert(b, a);
        }
    }
    let shift_bound = |i: usize| {
        if fixed(&we[i].1) {
            0
        } else {
            allow.lag_ms(walks[i])
        }
    };
    let (mut stats, mut measured) = (Stats::default(), false);
    let mut issues: Vec<Option<String>> = vec![None; rows.len()];
    let mut check = |i: usize, j: usize| -> Option<String> {
        let (t, u) = (we[i].0, ge[j].0);
        let bound = shift_bound(i);
        if u < t {
            return Some(format!("{} ms early: never allowed", t - u));
        }
        let lag = u - t;
        if lag > stats.max_shift_ms || !measured {
            (stats.max_shift_ms, stats.bound_ms, measured) = (lag, bound, true);
        }
        if lag > bound {
            return Some(format!("{lag} ms late, allowed 0 to {bound}"));
        }
        match (wk[i].1, gk[j].1) {
            (Quantity::Position(p), Quantity::Position(q)) => {
                let room = allow.speed_um_per_ms * allow.lag_ms(walks[i]) + 1000;
                (p.abs_diff(q) > room).then(|| {
                    format!(
                        "put down {} µm away, allowed {room} (the walk in {} ms, and 1 mm)",
                        p.abs_diff(q),
                        allow.lag_ms(walks[i])
                    )
                })
            }
            (Quantity::Reaction(a), Quantity::Reaction(b)) => {
                // The obstacle appears at the scenario's instant on both sides; the reaction
                // ends at this line, which lags by `lag` (within the lag allowed above).
                let (low, high) = (
                    a.saturating_sub(allow.lossy_ms),
                    a + lag.max(REACTION_MS) + allow.lossy_ms,
                );
                (!(low..=high).contains(&b))
                    .then(|| format!("reaction {b} ms, allowed {low} to {high}"))
            }
            _ => None,
        }
    };
    let mut accepted = 0;
    for (a, row) in rows.iter().enumerate() {
        issues[a] = match (*row, partner.get(&a).map(|&b| rows[b])) {
            (Row::Both(i, j), _) | (Row::Host(i), Some(Row::Firmware(j))) => check(i, j),
            (Row::Firmware(_), Some(_)) => None,
            (Row::Host(i), _) if removal_race(&we[i], &we, &ge, &rows) => {
                accepted += 1;
                None
            }
            (Row::Firmware(j), _) if removal_race(&ge[j], &we, &ge, &rows) => {
                accepted += 1;
                None
            }
            (Row::Host(_), _) => Some("missing on the firmware".to_owned()),
            (Row::Firmware(_), _) => Some("not in the expected trace".to_owned()),
        };
    }
    let report = diff(&we, &ge, &rows, &issues, &partner);
    let (samples, realigned) = sample_issues(want, got, &we, &walks, allow);
    stats.lines = got.len();
    stats.samples = got.len() - ge.len();
    stats.accepted = accepted + realigned;
    if report.is_empty() && samples.is_empty() {
        return Ok(stats);
    }
    let first = rows
        .iter()
        .zip(&issues)
        .find_map(|(r, e)| {
            let e = e.as_ref()?;
            Some(match *r {
                Row::Both(_, j) | Row::Firmware(j) => {
                    format!("`{}` at {} ms: {e}", ge[j].1, ge[j].0)
                }
                Row::Host(i) => format!("`{}` at {} ms: {e}", we[i].1, we[i].0),
            })
        })
        .or_else(|| {
            samples.first().map(|(l, e)| match l {
                Some((t, text)) => format!("`{text}` at {t} ms: {e}"),
                None => e.clone(),
            })
        })
        .unwrap_or_default();
    let count = issues.iter().flatten().count() + samples.len();
    let mut lines = vec![format!("--- {}", names.0), format!("+++ {}", names.1)];
    lines.extend(report);
    if !samples.is_empty() {
        lines.push("samples:".to_owned());
        lines.extend(samples.iter().map(|(l, e)| match l {
            Some((t, text)) => format!("+{t} w {text}   <- {e}"),
            None => format!(" {e}"),
        }));
    }
    let total = lines.len();
    lines.truncate(SHOWN);
    if total > SHOWN {
        lines.push(format!("... {} more lines", total - SHOWN));
    }
    Err(format!(
        "{count} difference{}, first {first}\n{}",
        if count == 1 { "" } else { "s" },
        lines.join("\n")
    ))
}

/// Whether `line`, on one side only, is an obstacle taken away at an instant between the
/// ends of the side step around it on the two sides (inclusive): where the side step ended
/// first, the obstacle was passed and its removal is not logged.
fn removal_race(line: &Line, we: &[Line], ge: &[Line], rows: &[Row]) -> bool {
    let Some(n) = line
        .1
        .strip_suffix(" taken away")
        .and_then(|h| h.strip_prefix('#'))
        .and_then(|n| n.parse::<u64>().ok())
    else {
        return false;
    };
    let done = format!("AvoidDone(Some({}))", n.saturating_sub(1));
    rows.iter().any(|r| match *r {
        Row::Both(i, j) if we[i].1 == done => {
            let (a, b) = (we[i].0.min(ge[j].0), we[i].0.max(ge[j].0));
            (a..=b).contains(&line.0)
        }
        _ => false,
    })
}

/// The rows as a unified-style diff: each row with an issue, two rows of context around.
fn diff(
    we: &[Line],
    ge: &[Line],
    rows: &[Row],
    issues: &[Option<String>],
    partner: &BTreeMap<usize, usize>,
) -> Vec<String> {
    const CONTEXT: usize = 2;
    let shown: Vec<bool> = (0..rows.len())
        .map(|a| {
            let lo = a.saturating_sub(CONTEXT);
            let hi = (a + CONTEXT + 1).min(rows.len());
            issues[lo..hi].iter().any(Option::is_some)
        })
        .collect();
    let mut out = Vec::new();
    let mut last = None;
    for (a, row) in rows.iter().enumerate() {
        if !shown[a] {
            continue;
        }
        if last != Some(a.wrapping_sub(1)) {
            let (i, j) = rows[a..].iter().fold((None, None), |(i, j), r| match *r {
                Row::Both(x, y) => (i.or(Some(x)), j.or(Some(y))),
                Row::Host(x) => (i.or(Some(x)), j),
                Row::Firmware(y) => (i, j.or(Some(y))),
            });
            out.push(format!(
                "@@ expected event {}, firmware event {} @@",
                i.map_or(0, |i| i + 1),
                j.map_or(0, |j| j + 1)
            ));
        }
        last = Some(a);
        let note = |e: &Option<String>| e.as_ref().map_or(String::new(), |e| format!("   <- {e}"));
        let moved = partner.contains_key(&a);
        match (*row, &issues[a]) {
            (Row::Both(i, _), None) => out.push(format!(" {} w {}", we[i].0, we[i].1)),
            (Row::Both(i, j), e) => {
                out.push(format!("-{} w {}", we[i].0, we[i].1));
                out.push(format!("+{} w {}{}", ge[j].0, ge[j].1, note(e)));
            }
            (Row::Host(i), e) if moved => {
                out.push(format!(
                    "-{} w {}   (order differs){}",
                    we[i].0,
                    we[i].1,
                    note(e)
                ));
            }
            (Row::Firmware(j), _) if moved => {
                out.push(format!("+{} w {}   (order differs)", ge[j].0, ge[j].1));
            }
            (Row::Host(i), None) => out.push(format!(
                " {} w {}   (expected only: the removal raced the side step's end)",
                we[i].0, we[i].1
            )),
            (Row::Firmware(j), None) => out.push(format!(
                " {} w {}   (firmware only: the removal raced the side step's end)",
                ge[j].0, ge[j].1
            )),
            (Row::Host(i), e) => out.push(format!("-{} w {}{}", we[i].0, we[i].1, note(e))),
            (Row::Firmware(j), e) => out.push(format!("+{} w {}{}", ge[j].0, ge[j].1, note(e))),
        }
    }
    out
}

/// The samples that differ more than allowed: each firmware reading against the host's in
/// the lag before it; then the counts per device. Also how many losses were accepted where
/// the sonar's draws realign.
fn sample_issues(
    want: &[Line],
    got: &[Line],
    we: &[Line],
    walks: &[Begun],
    allow: &Allowance,
) -> (Vec<(Option<Line>, String)>, usize) {
    let walks_at = |t: u64| {
        let n = we.partition_point(|(u, _)| *u <= t);
        n.checked_sub(1).map_or(Begun::default(), |k| walks[k])
    };
    let mut by_device: BTreeMap<&str, (Reads, usize)> = BTreeMap::new();
    for (t, text) in want {
        if let Some((d, v)) = sample(text) {
            by_device.entry(d).or_default().0.push((*t, v));
        }
    }
    let mut issues = Vec::new();
    // How many draws the firmware's sonar may run ahead: one per extra read.
    let sonar_reads = |lines: &[Line]| {
        lines
            .iter()
            .filter(|(_, t)| sample(t).is_some_and(|(d, _)| d == "Sonar"))
            .count()
    };
    let ahead = sonar_reads(got).saturating_sub(sonar_reads(want));
    let mut realigned = 0;
    for (t, text) in got {
        let Some((d, v)) = sample(text) else {
            continue;
        };
        let entry = by_device.entry(d).or_default();
        entry.1 += 1;
        let lag = allow.lag_ms(walks_at(*t));
        // A sonar whose draws run ahead reads what the host read a sample later. The bump
        // switch, switched off up to the lag later, may read once more what the host read last,
        // a period before.
        let (period, lead) = match d {
            "Bumper" => (allow.periods_ms[1], SWITCH_LEAD_MS),
            _ => (0, 0),
        };
        let (from, to) = (t.saturating_sub(lag + period), t + lead + allow.lossy_ms);
        let (room, allowed) = match (d, v) {
            ("Sonar", Some(_)) => {
                let mm = allow.closing_um_per_ms * lag / 1000 + 2 * allow.noise_um / 1000 + 1;
                (mm, format!("within {mm} mm"))
            }
            (_, Some(_)) => (0, "the same reading".to_owned()),
            (_, None) => (0, "a loss".to_owned()),
        };
        let window = {
            let a = entry.0.partition_point(|(u, _)| *u < from);
            let b = entry.0.partition_point(|(u, _)| *u <= to);
            entry.0.get(a..b).unwrap_or_default()
        };
        // One side read an edge of what the sonar sees, the other nothing in range.
        let at_edge = |r: u64| allow.edges_mm.iter().any(|e| e.abs_diff(r) <= room);
        let near = |w: &Option<u64>| match (w, v) {
            (Some(a), Some(b))
                if d == "Sonar" && room > 0 && (*a == allow.max_mm) != (b == allow.max_mm) =>
            {
                let other = if *a == allow.max_mm { b } else { *a };
                a.abs_diff(b) <= room || at_edge(other)
            }
            (Some(a), Some(b)) => a.abs_diff(b) <= room,
            (None, None) => true,
            _ => false,
        };
        if !window.iter().any(|(_, w)| near(w)) {
            if v.is_none() && allow.lossy_ms > 0 && realigned < ahead {
                // The draws realign on a loss the host does not have (module doc).
                realigned += 1;
                continue;
            }
            let seen: Vec<String> = window
                .iter()
                .map(|(u, w)| {
                    let w = w.map_or("a loss".to_owned(), |w| w.to_string());
                    format!("{w} at {u}")
                })
                .collect();
            let seen = if seen.is_empty() {
                "nothing".to_owned()
            } else {
                seen.join(", ")
            };
            issues.push((
                Some((*t, text.clone())),
                format!("the host read {seen} from {from} to {to} ms (allowed: {allowed})"),
            ));
        }
    }
    let longer = got
        .last()
        .map_or(0, |l| l.0)
        .abs_diff(want.last().map_or(0, |l| l.0));
    for (d, (host, count)) in &by_device {
        let period = match *d {
            "Sonar" => allow.periods_ms[0],
            "Bumper" => allow.periods_ms[1],
            _ => 0,
        };
        let room = if period == 0 {
            0
        } else {
            1 + longer.div_ceil(period)
        };
        if host.len().abs_diff(*count) > room as usize {
            issues.push((
                None,
                format!(
                    "{d}: {count} reads on the firmware, {} on the host (allowed: {room} apart)",
                    host.len()
                ),
            ));
        }
    }
    (issues, realigned)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lines(text: &str) -> Vec<Line> {
        world_lines(text)
    }

    const HOST: &str = "\
0 w SensorOn(Sonar)
0 w Sample(Sonar, 2550)
0 w Walk
100 w Sample(Sonar, 2550)
1800 w #1 box put down at 0.530 m
1800 w Sample(Sonar, 400)
1800 w #1 detected by sonar
1800 w #1 reaction 0 ms
1800 w Stop
1800 w AvoidStarted(Some(0))
2800 w AvoidDone(Some(0))
2800 w Walk
";

    const NAMES: (&str, &str) = ("expected", "firmware");

    fn allow() -> Allowance {
        Allowance {
            speed_um_per_ms: 100,
            closing_um_per_ms: 100,
            edges_mm: vec![250, 2550],
            max_mm: 2550,
            periods_ms: [100, 20],
            ..Allowance::default()
        }
    }

    #[test]
    fn equal_traces_pass() {
        let stats = compare(&lines(HOST), &lines(HOST), &allow(), NAMES);
        assert_eq!(
            stats,
            Ok(Stats {
                lines: 12,
                samples: 3,
                max_shift_ms: 0,
                bound_ms: 5,
                accepted: 0,
            })
        );
    }

    /// [`HOST`] as the target runs it: later by a tick or two, one more sample, and the
    /// obstacle's removal logged before the side step's end.
    const TARGET: &str = "\
0 w SensorOn(Sonar)
0 w Sample(Sonar, 2550)
1 w Sample(Sonar, 2550)
2 w Walk
101 w Sample(Sonar, 2550)
1800 w #1 box put down at 0.530 m
1801 w #1 detected by sonar
1801 w Sample(Sonar, 400)
1801 w #1 reaction 1 ms
1801 w Stop
1801 w AvoidStarted(Some(0))
2800 w #1 taken away
2801 w AvoidDone(Some(0))
2802 w Walk
";

    #[test]
    fn instants_shifted_within_the_lag_pass() {
        let stats = compare(&lines(HOST), &lines(TARGET), &allow(), NAMES);
        assert_eq!(
            stats,
            Ok(Stats {
                lines: 14,
                samples: 4,
                max_shift_ms: 2,
                bound_ms: 5,
                accepted: 1,
            })
        );
    }

    #[test]
    fn a_lag_past_the_bound_fails_naming_the_event() {
        // By 1800 ms: a walk (2 ticks, and 2 for the start), a phase and a side step.
        let got = HOST.replace("1800 w Stop", "1807 w Stop");
        let err = compare(&lines(HOST), &lines(&got), &allow(), NAMES).unwrap_err();
        assert!(
            err.contains("first `Stop` at 1807 ms: 7 ms late, allowed 0 to 6"),
            "{err}"
        );
        assert!(err.contains("\n--- expected\n+++ firmware\n@@ "), "{err}");
        assert!(err.contains("-1800 w Stop\n+1807 w Stop"), "{err}");
    }

    #[test]
    fn a_missing_or_changed_event_fails_naming_it() {
        let missing = HOST.replace("1800 w #1 detected by sonar\n", "");
        let err = compare(&lines(HOST), &lines(&missing), &allow(), NAMES).unwrap_err();
        assert!(
            err.contains("`#1 detected by sonar` at 1800 ms: missing on the firmware"),
            "{err}"
        );
        let changed = HOST.replace("detected by sonar", "detected by bumper");
        let err = compare(&lines(HOST), &lines(&changed), &allow(), NAMES).unwrap_err();
        assert!(err.contains("-1800 w #1 detected by sonar"), "{err}");
        assert!(
            err.contains("+1800 w #1 detected by bumper   <- not in the expected trace"),
            "{err}"
        );
        // An obstacle put down elsewhere than the lag allows.
        let moved = HOST.replace("0.530 m", "0.600 m");
        let err = compare(&lines(HOST), &lines(&moved), &allow(), NAMES).unwrap_err();
        assert!(
            err.contains("put down 70000 µm away, allowed 1600"),
            "{err}"
        );
    }

    /// A bump switch's change may come a tick earlier on the target (its bounces settle
    /// within the tick), not two.
    #[test]
    fn a_contact_may_lead_by_a_tick_not_two() {
        let host =
            "0 w SensorOn(Bumper)\n0 w Walk\n480 w Sample(Bumper, 1)\n500 w Sample(Bumper, 2)\n";
        let early = |at: u64| {
            let got = format!(
                "0 w SensorOn(Bumper)\n0 w Walk\n481 w Sample(Bumper, 1)\n{at} w Sample(Bumper, 2)\n"
            );
            compare(&lines(host), &lines(&got), &allow(), NAMES)
        };
        assert!(early(499).is_ok(), "{:?}", early(499));
        let err = early(498).unwrap_err();
        assert!(
            err.contains("+498 w Sample(Bumper, 2)   <- the host read 1 at 480"),
            "{err}"
        );
    }

    /// A reaction may be longer by its own line's lag (the detecting sample came that much
    /// later), no more.
    #[test]
    fn a_reaction_may_grow_by_its_lines_lag_only() {
        let late = |reaction: u64| {
            let got = HOST
                .replace("1800 w Sample(Sonar, 400)", "1803 w Sample(Sonar, 400)")
                .replace("1800 w #1 detected", "1803 w #1 detected")
                .replace(
                    "1800 w #1 reaction 0 ms",
                    &format!("1803 w #1 reaction {reaction} ms"),
                )
                .replace("1800 w Stop", "1803 w Stop")
                .replace("1800 w AvoidStarted", "1803 w AvoidStarted");
            compare(&lines(HOST), &lines(&got), &allow(), NAMES)
        };
        assert!(late(3).is_ok(), "{:?}", late(3));
        let err = late(4).unwrap_err();
        assert!(err.contains("reaction 4 ms, allowed 0 to 3"), "{err}");
    }

    #[test]
    fn a_sample_the_host_did_not_read_fails() {
        let got = HOST.replace("Sample(Sonar, 400)", "Sample(Sonar, 900)");
        let err = compare(&lines(HOST), &lines(&got), &allow(), NAMES).unwrap_err();
        assert!(
            err.contains(
                "+1800 w Sample(Sonar, 900)   <- the host read 400 at 1800 from 1794 to 1800 ms (allowed: within 1 mm)"
            ),
            "{err}"
        );
    }

    /// A walking obstacle closes 8 mm a millisecond: a reading late by the lag may differ by
    /// that much, and one side may read nothing in range (2550) where the other read the box
    /// at the edge of the sonar's range, but not in the middle of it.
    #[test]
    fn a_walking_obstacle_widens_the_readings_allowed_and_edges_may_read_nothing() {
        let fast = Allowance {
            closing_um_per_ms: 8_100,
            ..allow()
        };
        let host = HOST.replace("Sample(Sonar, 400)", "Sample(Sonar, 252)");
        let edge = HOST.replace("Sample(Sonar, 400)", "Sample(Sonar, 2550)");
        assert!(compare(&lines(&host), &lines(&edge), &fast, NAMES).is_ok());
        let closer = HOST.replace("Sample(Sonar, 400)", "Sample(Sonar, 370)");
        assert!(compare(&lines(HOST), &lines(&closer), &fast, NAMES).is_ok());
        // Not with the robot's own speed only, and not in the middle of the range.
        assert!(compare(&lines(HOST), &lines(&closer), &allow(), NAMES).is_err());
        let err = compare(&lines(HOST), &lines(&edge), &fast, NAMES).unwrap_err();
        assert!(err.contains("the host read 400 at 1800"), "{err}");
    }

    #[test]
    fn every_world_event_survives_the_firmware_s_numbers() {
        use psmpa_firmware::world_trace::encode;
        use psmpa_sim::scenario::Kind;
        use psmpa_sim::world::{Device, Place, WorldEvent as E};
        let devices = [
            Device::Sonar,
            Device::Bumper,
            Device::Camera,
            Device::Handle,
        ];
        let mut all = vec![
            E::Appeared {
                index: 31,
                kind: Kind::Ball,
                at_um: 12_345_678,
            },
            E::Removed(3),
            E::Skipped(4),
            E::Collided(5),
            E::Reacted(6, 190),
            E::Walk,
            E::Stop,
            E::AvoidStarted(None),
            E::AvoidStarted(Some(0)),
            E::AvoidDone(Some(255)),
            E::Held(true),
            E::Held(false),
            E::Arrived(Place::BackDoor),
            E::DoorOpened(Place::KitchenDoor),
            E::Locked,
            E::InKitchen,
            E::Speed(750),
        ];
        for d in devices {
            all.extend([
                E::SensorOn(d),
                E::SensorOff(d),
                E::Sample(d, 2550),
                E::SampleLost(d),
                E::Detected(2, d),
            ]);
        }
        for e in all {
            assert_eq!(decode(encode(&e)), Some(e));
        }
    }

    #[test]
    fn a_run_s_world_lines_are_read_from_the_log() {
        let log = "\
0.000 INFO  psmpa firmware: 15 scenarios
0.000 INFO  w 0 0 0 0 0
1.800 INFO  w 1800 4 0 0 530000
1.800 INFO  w 1800 99 0 0 0
19.020 INFO  result scenario=quiet arch=psmpa detected=0
";
        let (runs, errors) = firmware_traces(log);
        let quiet = runs.get(&("quiet".to_owned(), "psmpa".to_owned()));
        assert_eq!(
            quiet.map(|l| as_text(l)).as_deref(),
            Some("0 w SensorOn(Sonar)\n1800 w #1 box put down at 0.530 m\n")
        );
        assert_eq!(
            errors,
            ["unreadable world event: 1.800 INFO  w 1800 99 0 0 0"]
        );
    }
}

//! Table I of the paper, reproduced: the six scenario files of `scenarios/` (embedded at build
//! time) under both architectures, printed beside the paper's own numbers.

use std::fmt::Write as _;
use std::path::Path;

use rand_core::Rng;
use rand_pcg::Pcg32;
use rayon::prelude::*;
use serde::Serialize;

use crate::cli::report::rate;
use crate::cli::sensitivity::{Interval, Moments};
use crate::load::{LoadError, parse};
use crate::robot::Arch;
use crate::scenario::Scenario;
use crate::sim::{RunError, run_summary};

/// One row of the paper's Table I.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PaperRow {
    /// `sonar` or `bumper`.
    pub sensor: &'static str,
    /// Interferences.
    pub interferences: u32,
    /// P-SMPA detected.
    pub psmpa_detected: u32,
    /// P-SMPA performance, % (as printed).
    pub psmpa_percent: f64,
    /// P-SMPA time cost, s.
    pub psmpa_time_s: f64,
    /// SMPA detected.
    pub smpa_detected: u32,
    /// SMPA performance, % (as printed).
    pub smpa_percent: f64,
    /// SMPA time cost, s.
    pub smpa_time_s: f64,
}

/// A row from `(detected, percent, time)` of each architecture.
const fn row(
    sensor: &'static str,
    n: u32,
    psmpa: (u32, f64, f64),
    smpa: (u32, f64, f64),
) -> PaperRow {
    PaperRow {
        sensor,
        interferences: n,
        psmpa_detected: psmpa.0,
        psmpa_percent: psmpa.1,
        psmpa_time_s: psmpa.2,
        smpa_detected: smpa.0,
        smpa_percent: smpa.1,
        smpa_time_s: smpa.2,
    }
}

/// The paper's Table I. (The last row prints 66.7 % for SMPA's 2 of 6, as in the paper.)
pub const PAPER: [PaperRow; 6] = [
    row("sonar", 6, (6, 100.0, 23.0), (2, 33.3, 53.0)),
    row("sonar", 7, (7, 100.0, 42.0), (4, 57.1, 87.0)),
    row("sonar", 8, (7, 87.5, 63.0), (4, 50.0, 101.0)),
    row("bumper", 4, (4, 100.0, 20.0), (2, 50.0, 59.0)),
    row("bumper", 5, (5, 100.0, 35.0), (3, 60.0, 98.0)),
    row("bumper", 6, (4, 66.7, 58.0), (2, 66.7, 117.0)),
];

/// The scenario files of the six rows, by name and content.
pub const SCENARIOS: [(&str, &str); 6] = [
    (
        "scenarios/sonar-6.json",
        include_str!("../../../scenarios/sonar-6.json"),
    ),
    (
        "scenarios/sonar-7.json",
        include_str!("../../../scenarios/sonar-7.json"),
    ),
    (
        "scenarios/sonar-8.json",
        include_str!("../../../scenarios/sonar-8.json"),
    ),
    (
        "scenarios/bumper-4.json",
        include_str!("../../../scenarios/bumper-4.json"),
    ),
    (
        "scenarios/bumper-5.json",
        include_str!("../../../scenarios/bumper-5.json"),
    ),
    (
        "scenarios/bumper-6.json",
        include_str!("../../../scenarios/bumper-6.json"),
    ),
];

/// Our result for one architecture on one row.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Ours {
    /// Interferences put down.
    pub interferences: u32,
    /// Detected.
    pub detected: u32,
    /// `detected / interferences`, %.
    pub percent: f64,
    /// Collisions.
    pub collisions: u32,
    /// Time cost, s.
    pub time_s: f64,
    /// Trace hash; in JSON a 16-digit hex string, as `run --json` prints it (a JSON number
    /// above 2⁵³ loses digits in many readers).
    #[serde(serialize_with = "hex")]
    pub trace_hash: u64,
}

fn hex<S: serde::Serializer>(hash: &u64, s: S) -> Result<S::Ok, S::Error> {
    s.collect_str(&format_args!("{hash:016x}"))
}

/// One row: the paper's numbers and ours.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// The scenario's name.
    pub scenario: String,
    /// The paper's row.
    pub paper: PaperRow,
    /// P-SMPA.
    pub psmpa: Ours,
    /// SMPA.
    pub smpa: Ours,
    /// The same row with its interference instants shifted at random.
    pub shifted: Shifted,
}

/// A row run again with every interference instant moved by one offset drawn uniformly from
/// one SMPA cycle (`[0, sense + act)`), so that nobody chose where the instants fall in SMPA's
/// phases; means over the shifts.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Shifted {
    /// How many shifts.
    pub shifts: u32,
    /// P-SMPA: interferences detected, % of those put down (a late shift may put one
    /// down after the robot is through the door).
    pub psmpa_percent: Interval,
    /// P-SMPA: collisions.
    pub psmpa_collisions: Interval,
    /// SMPA: interferences detected, % of those put down.
    pub smpa_percent: Interval,
    /// SMPA: collisions.
    pub smpa_collisions: Interval,
    /// SMPA's time cost over P-SMPA's, run by run.
    pub time_ratio: Interval,
}

/// Shifts per row by default.
pub const SHIFTS: u32 = 1000;

/// The seed of the shifts: row `r`'s shift `i` draws from PCG stream `r * 2^32 + i`, so the
/// table is the same on any number of threads.
const SHIFT_SEED: u64 = 0x7ab1e1;

fn shifted(scenario: &Scenario, row: u64, shifts: u32) -> Result<Shifted, RunError> {
    let cycle = (scenario.sense_ms + scenario.act_ms).max(1);
    let runs: Vec<[f64; 5]> = (0..shifts)
        .into_par_iter()
        .map(|i| {
            let mut rng = Pcg32::new(SHIFT_SEED, row << 32 | u64::from(i));
            let offset = u64::from(rng.next_u32()) % cycle;
            let mut sc = scenario.clone();
            for it in sc.interferences.iter_mut() {
                it.at_ms = it.at_ms.saturating_add(offset as u32);
            }
            let p = run_summary(&sc, Arch::PSmpa)?;
            let s = run_summary(&sc, Arch::Smpa)?;
            Ok([
                100.0 * rate(p.tally.detected, p.tally.placed),
                f64::from(p.tally.collisions),
                100.0 * rate(s.tally.detected, s.tally.placed),
                f64::from(s.tally.collisions),
                s.time_cost_ms as f64 / p.time_cost_ms.max(1) as f64,
            ])
        })
        .collect::<Result<_, RunError>>()?;
    // Mean ± 1.96 standard errors, within each quantity's range (as the sensitivity study).
    let column = |k: usize, hi: f64| {
        let mut m = Moments::default();
        runs.iter().for_each(|r| m.add(r[k]));
        m.interval(0.0, hi).unwrap_or(Interval {
            mean: 0.0,
            lo: 0.0,
            hi: 0.0,
            n: 0,
        })
    };
    Ok(Shifted {
        shifts,
        psmpa_percent: column(0, 100.0),
        psmpa_collisions: column(1, f64::INFINITY),
        smpa_percent: column(2, 100.0),
        smpa_collisions: column(3, f64::INFINITY),
        time_ratio: column(4, f64::INFINITY),
    })
}

/// Why Table I could not be computed.
#[derive(Debug)]
pub enum TableError {
    /// An embedded scenario is invalid (a build with a broken file).
    Load(LoadError),
    /// A run failed.
    Run(RunError),
}

impl std::fmt::Display for TableError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Load(e) => e.fmt(f),
            Self::Run(e) => e.fmt(f),
        }
    }
}

/// The six embedded scenarios.
pub fn scenarios() -> Result<Vec<Scenario>, LoadError> {
    SCENARIOS
        .iter()
        .map(|(name, json)| parse(Path::new(name), json.as_bytes()))
        .collect()
}

fn ours(scenario: &Scenario, arch: Arch) -> Result<Ours, RunError> {
    let s = run_summary(scenario, arch)?;
    let t = s.tally;
    Ok(Ours {
        interferences: t.placed,
        detected: t.detected,
        percent: 100.0 * rate(t.detected, t.placed),
        collisions: t.collisions,
        time_s: s.time_cost_ms as f64 / 1000.0,
        trace_hash: s.trace_hash,
    })
}

/// Runs the six rows under both architectures, as built and with `shifts` random shifts.
pub fn compute(shifts: u32) -> Result<Vec<Row>, TableError> {
    let scenarios = scenarios().map_err(TableError::Load)?;
    scenarios
        .iter()
        .zip(PAPER)
        .enumerate()
        .map(|(i, (sc, paper))| {
            Ok(Row {
                scenario: sc.name.as_str().to_owned(),
                paper,
                psmpa: ours(sc, Arch::PSmpa).map_err(TableError::Run)?,
                smpa: ours(sc, Arch::Smpa).map_err(TableError::Run)?,
                shifted: shifted(sc, i as u64, shifts).map_err(TableError::Run)?,
            })
        })
        .collect()
}

/// The table as text: ours, with the paper's value in brackets.
pub fn render(rows: &[Row]) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "Table I, rows built to mirror the paper: \"go to door\" under interference, ours [paper]\n"
    );
    let half = |title: &str| format!("{title:^41}");
    let _ = writeln!(
        out,
        "{:<15}|{}|{}",
        "",
        half("P-SMPA (sensing while acting)"),
        half("SMPA (sense and act alternate)")
    );
    let head = format!(
        " {:>9} {:>13} {:>4} {:>11} ",
        "detected", "%", "coll", "time s"
    );
    let _ = writeln!(out, "{:<7} {:>6} |{head}|{head}", "sensor", "interf");
    let _ = writeln!(out, "{}", "-".repeat(15 + 2 * 42));
    for r in rows {
        let p = &r.paper;
        let cell = |o: &Ours, d: u32, pct: f64, t: f64| {
            format!(
                " {:>9} {:>13} {:>4} {:>11} ",
                format!("{} [{}]", o.detected, d),
                format!("{:.1} [{:.1}]", o.percent, pct),
                o.collisions,
                format!("{:.1} [{:.0}]", o.time_s, t),
            )
        };
        let _ = writeln!(
            out,
            "{:<7} {:>6} |{}|{}",
            p.sensor,
            r.psmpa.interferences,
            cell(&r.psmpa, p.psmpa_detected, p.psmpa_percent, p.psmpa_time_s),
            cell(&r.smpa, p.smpa_detected, p.smpa_percent, p.smpa_time_s),
        );
    }
    let (pt, st): (f64, f64) = rows.iter().fold((0.0, 0.0), |(a, b), r| {
        (a + r.psmpa.time_s, b + r.smpa.time_s)
    });
    let (ppt, pst): (f64, f64) = rows.iter().fold((0.0, 0.0), |(a, b), r| {
        (a + r.paper.psmpa_time_s, b + r.paper.smpa_time_s)
    });
    let _ = writeln!(
        out,
        "\ntime cost SMPA / P-SMPA over the six rows: {:.2} [paper {:.2}]",
        st / pt,
        pst / ppt
    );
    let shifts = rows.first().map_or(0, |r| r.shifted.shifts);
    let _ = writeln!(
        out,
        "\nThe same rows, every interference instant shifted by one offset drawn from one SMPA \
         cycle,\n{shifts} shifts a row: mean [95 % interval]\n"
    );
    let _ = writeln!(
        out,
        "{:<7} {:>6} | {:^20} | {:^17} | {:^20} | {:^17} | {:^17}",
        "sensor",
        "interf",
        "P-SMPA detected %",
        "P-SMPA collisions",
        "SMPA detected %",
        "SMPA collisions",
        "time SMPA/P-SMPA"
    );
    let _ = writeln!(out, "{}", "-".repeat(15 + 2 * 23 + 3 * 20));
    let iv = |i: Interval| format!("{:.2} [{:.2}, {:.2}]", i.mean, i.lo, i.hi);
    let pc = |i: Interval| format!("{:.1} [{:.1}, {:.1}]", i.mean, i.lo, i.hi);
    for r in rows {
        let h = &r.shifted;
        let _ = writeln!(
            out,
            "{:<7} {:>6} | {:>20} | {:>17} | {:>20} | {:>17} | {:>17}",
            r.paper.sensor,
            r.psmpa.interferences,
            pc(h.psmpa_percent),
            iv(h.psmpa_collisions),
            pc(h.smpa_percent),
            iv(h.smpa_collisions),
            iv(h.time_ratio),
        );
    }
    out
}

//! Table I of the paper, reproduced: the six scenario files of `scenarios/` (embedded at build
//! time) under both architectures, printed beside the paper's own numbers.

use std::fmt::Write as _;
use std::path::Path;

use serde::Serialize;

use crate::cli::report::rate;
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
        interferences: t.interferences,
        detected: t.detected,
        percent: 100.0 * rate(t.detected, t.interferences),
        collisions: t.collisions,
        time_s: s.time_cost_ms as f64 / 1000.0,
        trace_hash: s.trace_hash,
    })
}

/// Runs the six rows under both architectures.
pub fn compute() -> Result<Vec<Row>, TableError> {
    let scenarios = scenarios().map_err(TableError::Load)?;
    scenarios
        .iter()
        .zip(PAPER)
        .map(|(sc, paper)| {
            Ok(Row {
                scenario: sc.name.as_str().to_owned(),
                paper,
                psmpa: ours(sc, Arch::PSmpa).map_err(TableError::Run)?,
                smpa: ours(sc, Arch::Smpa).map_err(TableError::Run)?,
            })
        })
        .collect()
}

/// The table as text: ours, with the paper's value in brackets.
pub fn render(rows: &[Row]) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "Table I reproduced: \"go to door\" under interference, ours [paper]\n"
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
    out
}

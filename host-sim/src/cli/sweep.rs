//! Randomized scenarios under both architectures, with summary statistics.
//!
//! Scenario `i` of a sweep depends only on the seed and `i` (its own PCG stream), so a sweep
//! gives the same numbers on any number of threads.

use indicatif::{ProgressBar, ProgressState, ProgressStyle};
use rand_core::Rng;
use rand_pcg::Pcg32;
use rayon::prelude::*;
use serde::Serialize;

use crate::robot::Arch;
use crate::run::Summary;
use crate::scenario::{Interference, Kind, MAX_INTERFERENCES, Scenario, Sonar};
use crate::sim::{RunError, run_summary};

/// A whole number drawn uniformly from `lo..=hi`.
pub(crate) fn uniform(rng: &mut Pcg32, lo: u64, hi: u64) -> u64 {
    lo + u64::from(rng.next_u32()) % (hi - lo + 1)
}

/// The sweep's sonar faults: noise up to 30 mm and dropout up to 10 % (a threshold on a `u32`
/// draw: probability v / 1000), each in half the worlds. Returns `(noise_um, dropout)`.
pub(crate) fn sonar_faults(r: &mut Pcg32) -> (i64, u64) {
    let noise_um = if uniform(r, 0, 1) == 0 {
        0
    } else {
        uniform(r, 0, 30) as i64 * 1_000
    };
    let dropout = if uniform(r, 0, 1) == 0 {
        0
    } else {
        (uniform(r, 0, 100) << 32) / 1000
    };
    (noise_um, dropout)
}

/// The NAO's sonar (0.25 to 2.55 m, a 0.5 m threshold, a cone that sees every box) with the
/// drawn period, noise (µm), dropout and read latency (ms).
pub(crate) fn sonar(period_ms: u64, noise_um: i64, dropout: u64, latency_ms: u64) -> Sonar {
    Sonar {
        period_ms,
        min_um: 250_000,
        max_um: 2_550_000,
        threshold_um: 500_000,
        noise_um,
        dropout,
        latency_ms,
        height_um: 0,
        cone_slope_ppm: 500_000,
    }
}

/// `n` interferences put down uniformly over a walk of `walk_ms`: a box 0.15 to 1 m ahead or
/// a ball 0 to 0.3 m ahead, held 0.5 to 10 s (the sweep's and the sensitivity study's draws).
pub(crate) fn obstacles(
    r: &mut Pcg32,
    n: u64,
    walk_ms: u64,
) -> heapless::Vec<Interference, MAX_INTERFERENCES> {
    let mut interferences = heapless::Vec::new();
    for _ in 0..n {
        let kind = if uniform(r, 0, 1) == 0 {
            Kind::Box
        } else {
            Kind::Ball
        };
        let ahead_um = match kind {
            Kind::Box => uniform(r, 150, 1_000),
            Kind::Ball => uniform(r, 0, 300),
        } as i64
            * 1_000;
        let _ = interferences.push(Interference {
            kind,
            at_ms: uniform(r, 0, walk_ms) as u32,
            ahead_um: ahead_um as i32,
            hold_ms: uniform(r, 500, 10_000) as u32,
            speed_um_per_ms: 0,
            height_um: kind.default_height_um(),
        });
    }
    interferences
}

/// Scenario `index` of the sweep with `seed`.
pub fn scenario(seed: u64, index: u64) -> Scenario {
    let mut rng = Pcg32::new(seed, index);
    let r = &mut rng;
    let speed_um_per_ms = uniform(r, 50, 200) as i64;
    let door_um = uniform(r, 1_000, 3_000) as i64 * 1_000;
    let walk_ms = (door_um / speed_um_per_ms) as u64;
    let (noise_um, dropout) = sonar_faults(r);
    let n = uniform(r, 0, 8);
    let interferences = obstacles(r, n, walk_ms);
    let mut name = heapless::String::new();
    let _ = core::fmt::write(&mut name, format_args!("sweep-{seed}-{index}"));
    let avoid_ms = uniform(r, 1_000, 3_000);
    let sonar_period_ms = [50, 100, 200][uniform(r, 0, 2) as usize];
    let bumper_period_ms = [10, 20, 50][uniform(r, 0, 2) as usize];
    let sense_ms = uniform(r, 5, 20) * 100;
    let act_ms = uniform(r, 10, 40) * 100;
    // Drawn last, so every other draw is what it was before read latencies existed: an echo
    // of up to 40 ms, a bumper debounce of up to 5 ms (within the mission's timeouts).
    let sonar_latency_ms = uniform(r, 0, 40);
    let bumper_latency_ms = uniform(r, 0, 5);
    Scenario {
        name,
        seed: seed ^ index.rotate_left(17),
        door_um,
        max_ms: 600_000,
        speed_um_per_ms,
        avoid_ms,
        slow_um: 0,
        plan_us: 0,
        sonar: sonar(sonar_period_ms, noise_um, dropout, sonar_latency_ms),
        bumper_period_ms,
        bumper_latency_ms,
        bumper_min_contact_ms: 0,
        sense_ms,
        act_ms,
        door_locked: false,
        back_door_um: 3_000_000,
        fault: None,
        interferences,
    }
}

/// Totals of one architecture over a sweep.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct ArchStats {
    /// Scenarios run.
    pub scenarios: u64,
    /// Interferences put down.
    pub interferences: u64,
    /// Detected.
    pub detected: u64,
    /// Physically detectable (certain to register in a P-SMPA sample; see `world`); `None`
    /// when the sweep ran no P-SMPA, which is what tells.
    pub detectable: Option<u64>,
    /// Detectable obstacles this architecture did not detect, counted obstacle by obstacle;
    /// `None` without P-SMPA runs.
    pub missed_detectable: Option<u64>,
    /// Collisions.
    pub collisions: u64,
    /// Runs that reached the door.
    pub reached_door: u64,
    /// Runs that reached the goal.
    pub goal: u64,
    /// Sum of time costs, ms.
    pub time_ms: u64,
    /// Worst reaction latency, ms.
    pub max_reaction_ms: Option<u64>,
    /// Sum of sonar and bumper on-time, ms.
    pub sensor_on_ms: u64,
}

impl ArchStats {
    fn add(&mut self, s: &Summary, detectable: Option<&[bool]>) {
        if let Some(detectable) = detectable {
            let count = detectable.iter().filter(|d| **d).count() as u64;
            // Obstacle by obstacle: detectable (in the P-SMPA run) but not detected here.
            let missed = s
                .obstacles
                .iter()
                .zip(detectable)
                .filter(|(o, d)| **d && !matches!(o.fate, crate::world::Fate::Detected(_)))
                .count() as u64;
            self.detectable = Some(self.detectable.unwrap_or(0) + count);
            self.missed_detectable = Some(self.missed_detectable.unwrap_or(0) + missed);
        }
        let t = &s.tally;
        self.scenarios += 1;
        self.interferences += u64::from(t.placed);
        self.detected += u64::from(t.detected);
        self.collisions += u64::from(t.collisions);
        self.reached_door += u64::from(t.reached_door);
        self.goal += u64::from(matches!(s.ending, crate::run::Ending::Goal(_)));
        self.time_ms += s.time_cost_ms;
        self.max_reaction_ms = self.max_reaction_ms.max(t.max_reaction_ms);
        self.sensor_on_ms += t.on_ms[0] + t.on_ms[1];
    }

    /// Adds the totals of `other`.
    fn merge(&mut self, other: &Self) {
        let sum = |a: Option<u64>, b: Option<u64>| match (a, b) {
            (None, None) => None,
            (a, b) => Some(a.unwrap_or(0) + b.unwrap_or(0)),
        };
        self.scenarios += other.scenarios;
        self.interferences += other.interferences;
        self.detected += other.detected;
        self.detectable = sum(self.detectable, other.detectable);
        self.missed_detectable = sum(self.missed_detectable, other.missed_detectable);
        self.collisions += other.collisions;
        self.reached_door += other.reached_door;
        self.goal += other.goal;
        self.time_ms += other.time_ms;
        self.max_reaction_ms = self.max_reaction_ms.max(other.max_reaction_ms);
        self.sensor_on_ms += other.sensor_on_ms;
    }

    /// Detected / interferences.
    pub fn detection_rate(&self) -> f64 {
        crate::cli::report::rate(self.detected as u32, self.interferences as u32)
    }
}

/// A sweep's statistics.
#[derive(Debug, Clone, Default, Serialize)]
pub struct SweepStats {
    /// Seed.
    pub seed: u64,
    /// Runs per architecture.
    pub runs: u64,
    /// P-SMPA, when run.
    pub psmpa: Option<ArchStats>,
    /// SMPA, when run.
    pub smpa: Option<ArchStats>,
    /// Median over scenarios of SMPA time / P-SMPA time (both run).
    pub time_ratio_median: Option<f64>,
    /// Total SMPA time / total P-SMPA time (both run).
    pub time_ratio_total: Option<f64>,
}

/// The most scenarios one sweep runs. A sweep keeps its totals and one time ratio a scenario
/// (8 bytes, for the median): 8 MB at this bound.
pub const MAX_RUNS: u64 = 1_000_000;

/// Which architectures a sweep runs.
pub fn arches(only: Option<Arch>) -> Vec<Arch> {
    only.map_or_else(|| Arch::ALL.to_vec(), |a| vec![a])
}

/// The architecture of the run `sweep --mcap` writes: `chosen` (`--mcap-arch`), else the one
/// the sweep runs, else P-SMPA; refused when the sweep does not run it, or `run` is not one
/// of the sweep's `runs` scenarios.
pub fn mcap_arch(
    arches: &[Arch],
    chosen: Option<Arch>,
    run: u64,
    runs: u64,
) -> Result<Arch, String> {
    if run >= runs {
        return Err(format!(
            "--mcap-run {run}: the sweep runs scenarios 0 to {} (--runs {runs})",
            runs.saturating_sub(1)
        ));
    }
    let arch = chosen.unwrap_or(match arches {
        [only] => *only,
        _ => Arch::PSmpa,
    });
    if !arches.contains(&arch) {
        return Err(format!(
            "--mcap-arch {}: the sweep runs only {} (--arch)",
            arch_flag(arch),
            arches
                .iter()
                .map(|&a| arch_flag(a))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    Ok(arch)
}

/// An architecture as the command line spells it.
fn arch_flag(arch: Arch) -> &'static str {
    match arch {
        Arch::PSmpa => "psmpa",
        Arch::Smpa => "smpa",
    }
}

/// What a sweep keeps of the scenarios run so far (on one thread, then merged).
#[derive(Default)]
struct Partial {
    psmpa: Option<ArchStats>,
    smpa: Option<ArchStats>,
    ratios: Vec<f64>,
}

impl Partial {
    /// Adds the runs of one scenario.
    fn add(mut self, summaries: &[Summary]) -> Self {
        // Detectability is a property of each obstacle of the scenario, measured on the
        // P-SMPA run (whose sensors run for the whole walk).
        let detectable: Option<Vec<bool>> = summaries
            .iter()
            .find(|s| s.arch == Arch::PSmpa)
            .map(|s| s.obstacles.iter().map(|o| o.detectable).collect());
        let mut times = [None, None];
        for s in summaries {
            let slot = match s.arch {
                Arch::PSmpa => &mut self.psmpa,
                Arch::Smpa => &mut self.smpa,
            };
            slot.get_or_insert_with(ArchStats::default)
                .add(s, detectable.as_deref());
            times[usize::from(s.arch == Arch::Smpa)] = Some(s.time_cost_ms);
        }
        if let [Some(p), Some(s)] = times {
            self.ratios.push(s as f64 / p.max(1) as f64);
        }
        self
    }

    fn merge(mut self, other: Self) -> Self {
        for (mine, theirs) in [(&mut self.psmpa, other.psmpa), (&mut self.smpa, other.smpa)] {
            match (mine.as_mut(), theirs) {
                (Some(m), Some(t)) => m.merge(&t),
                (None, t) => *mine = t,
                (Some(_), None) => {}
            }
        }
        self.ratios.extend(other.ratios);
        self
    }
}

/// A progress bar over `len` items called `unit`, with a whole-number rate.
pub(crate) fn progress_bar(len: u64, unit: &str) -> ProgressBar {
    let bar = ProgressBar::new(len);
    let template = format!(
        "{{spinner}} [{{elapsed_precise}}] {{wide_bar}} {{pos}}/{{len}} {unit} ({{rate}}/s, eta {{eta}})"
    );
    if let Ok(style) = ProgressStyle::with_template(&template) {
        // indicatif's `{per_sec}` prints every digit it has (`658.6149/s`): a whole number.
        bar.set_style(style.with_key(
            "rate",
            |state: &ProgressState, w: &mut dyn std::fmt::Write| {
                let _ = write!(w, "{:.0}", state.per_sec());
            },
        ));
    }
    bar
}

/// Runs `runs` scenarios from `seed` under `arches` (in parallel), with a progress bar when
/// `progress`. Memory holds the totals and one ratio a scenario, not the runs.
pub fn sweep(
    seed: u64,
    runs: u64,
    arches: &[Arch],
    progress: bool,
) -> Result<SweepStats, RunError> {
    let bar = if progress {
        progress_bar(runs, "scenarios")
    } else {
        ProgressBar::hidden()
    };
    let kept = (0..runs)
        .into_par_iter()
        .map(|i| {
            let sc = scenario(seed, i);
            let out: Result<Vec<Summary>, RunError> =
                arches.iter().map(|&a| run_summary(&sc, a)).collect();
            bar.inc(1);
            out
        })
        .try_fold(Partial::default, |kept, summaries| {
            summaries.map(|s| kept.add(&s))
        })
        .try_reduce(Partial::default, |a, b| Ok(a.merge(b)));
    bar.finish_and_clear();
    let mut kept = kept?;

    let mut stats = SweepStats {
        seed,
        runs,
        psmpa: kept.psmpa,
        smpa: kept.smpa,
        ..SweepStats::default()
    };
    if !kept.ratios.is_empty() {
        kept.ratios.sort_by(f64::total_cmp);
        stats.time_ratio_median = kept.ratios.get(kept.ratios.len() / 2).copied();
    }
    if let (Some(p), Some(s)) = (stats.psmpa, stats.smpa) {
        stats.time_ratio_total = Some(s.time_ms as f64 / p.time_ms.max(1) as f64);
    }
    Ok(stats)
}

/// The statistics as text.
pub fn render(stats: &SweepStats) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "sweep: {} random scenarios, seed {}",
        stats.runs, stats.seed
    );
    let _ = writeln!(
        out,
        "{:<8} {:>10} {:>9} {:>8} {:>11} {:>9} {:>11} {:>10} {:>13} {:>13}",
        "arch",
        "interf",
        "detected",
        "rate %",
        "detectable",
        "missed",
        "collisions",
        "at door",
        "max react ms",
        "sensor on s"
    );
    for (name, s) in [("P-SMPA", stats.psmpa), ("SMPA", stats.smpa)] {
        let Some(s) = s else { continue };
        let _ = writeln!(
            out,
            "{:<8} {:>10} {:>9} {:>8.1} {:>11} {:>9} {:>11} {:>10} {:>13} {:>13.0}",
            name,
            s.interferences,
            s.detected,
            100.0 * s.detection_rate(),
            s.detectable.map_or("-".to_owned(), |d| d.to_string()),
            s.missed_detectable
                .map_or("-".to_owned(), |m| m.to_string()),
            s.collisions,
            s.reached_door,
            s.max_reaction_ms.map_or("-".to_owned(), |m| m.to_string()),
            s.sensor_on_ms as f64 / 1000.0,
        );
    }
    if let (Some(m), Some(t)) = (stats.time_ratio_median, stats.time_ratio_total) {
        let _ = writeln!(out, "time cost SMPA / P-SMPA: median {m:.2}, total {t:.2}");
    }
    let _ = writeln!(
        out,
        "detectable: present while a delivered P-SMPA sample was certain to register it \
         (box within [min + noise, threshold - noise) of the sonar, or touching the bumper)"
    );
    out
}

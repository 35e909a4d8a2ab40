//! How much of the paper's claim survives other SMPA settings: a grid of sense fractions and
//! cycle lengths, each cell run on the same random worlds (common random numbers), once with
//! clean sensors and once with sensor faults and read latencies drawn at random.
//!
//! A third part runs the clean worlds again with the hazards under which P-SMPA can fail
//! (docs/experiment.md, "The harder world"): people who walk into the robot's path, boxes too low for the
//! sonar's cone close by, and a bumper that feels a contact only after one of its periods.
//!
//! World `i` depends only on the seed and `i` (its own PCG stream), and the statistics are
//! summed in world order, so the results do not depend on the number of threads.

use std::fmt::Write as _;

use indicatif::ProgressBar;
use plotters::prelude::*;
use rand_pcg::Pcg32;
use rayon::prelude::*;
use serde::Serialize;

use crate::cli::outputs::legend;
use crate::cli::sweep::{self, obstacles, uniform};
use crate::cli::table1::PAPER;
use crate::robot::Arch;
use crate::run::Summary;
use crate::scenario::{Kind, Scenario};
use crate::sim::{RunError, run_summary};
use crate::world::Fate;

/// Sense fractions of the grid, % of a cycle: sense_ms / (sense_ms + act_ms).
pub const FRACTIONS_PCT: [u64; 9] = [10, 20, 30, 40, 50, 60, 70, 80, 90];

/// Cycle lengths of the grid, ms: sense_ms + act_ms.
pub const CYCLES_MS: [u64; 6] = [500, 1_000, 2_000, 3_000, 4_000, 6_000];

/// Cells of the grid.
const CELLS: usize = FRACTIONS_PCT.len() * CYCLES_MS.len();

/// The most worlds a cell may run: at this bound a study runs 11 million simulations.
pub const MAX_RUNS: u64 = 100_000;

/// The longest simulated run, ms. SMPA at 90 % sense walks a tenth of the time: the slowest
/// world (3 m at 50 mm/s, eight obstacles held 10 s) needs about 700 s there.
const MAX_MS: u64 = 1_200_000;

/// Worlds simulated between two sequential merges: bounds memory whatever `--runs`.
const CHUNK: u64 = 4_096;

/// The 95 % normal quantile.
const Z95: f64 = 1.96;

/// World `index` of the study with `seed`; with `faults`, the same world with sonar noise,
/// dropout and read latencies drawn at random. Its SMPA phases are left at 1 s / 3 s: each
/// cell sets its own ([`with_phases`]).
///
/// As the sweep draws them: speed 50 to 200 mm/s, door 1 to 3 m, side step 1 to 3 s, sonar
/// period 50/100/200 ms, bumper period 10/20/50 ms, and 1 to 8 interferences (box or ball),
/// each put down at an instant uniform over the unhindered walk (door / speed), whatever the
/// SMPA phase, a box 0.15 to 1 m ahead, a ball 0 to 0.3 m ahead, held 0.5 to 10 s. The faults
/// are drawn last, so the clean world and its faulty twin differ only in them.
pub fn world(seed: u64, index: u64, faults: bool) -> Scenario {
    let mut rng = Pcg32::new(seed, index);
    let r = &mut rng;
    let speed_um_per_ms = uniform(r, 50, 200) as i64;
    let door_um = uniform(r, 1_000, 3_000) as i64 * 1_000;
    let walk_ms = (door_um / speed_um_per_ms) as u64;
    let avoid_ms = uniform(r, 1_000, 3_000);
    let sonar_period_ms = [50, 100, 200][uniform(r, 0, 2) as usize];
    let bumper_period_ms = [10, 20, 50][uniform(r, 0, 2) as usize];
    // At least one: a world without obstacles says nothing about detection.
    let n = uniform(r, 1, 8);
    let interferences = obstacles(r, n, walk_ms);
    // The sweep's faults; a sonar echo of up to 40 ms and a bumper debounce of up to 5 ms.
    let (noise_um, dropout) = sweep::sonar_faults(r);
    let sonar_latency_ms = uniform(r, 0, 40);
    let bumper_latency_ms = uniform(r, 0, 5);
    let mut name = heapless::String::new();
    let _ = core::fmt::write(
        &mut name,
        format_args!(
            "sensitivity-{seed}-{index}{}",
            if faults { "-faults" } else { "" }
        ),
    );
    let on = |v: u64| if faults { v } else { 0 };
    Scenario {
        name,
        seed: seed ^ index.rotate_left(17),
        door_um,
        max_ms: MAX_MS,
        speed_um_per_ms,
        avoid_ms,
        slow_um: 0,
        plan_us: 0,
        sonar: sweep::sonar(
            sonar_period_ms,
            if faults { noise_um } else { 0 },
            on(dropout),
            on(sonar_latency_ms),
        ),
        bumper_period_ms,
        bumper_latency_ms: on(bumper_latency_ms),
        bumper_min_contact_ms: 0,
        sense_ms: 1_000,
        act_ms: 3_000,
        door_locked: false,
        back_door_um: 3_000_000,
        fault: None,
        interferences,
    }
}

/// `sc` with the SMPA phases of a sense fraction (%) and a cycle length (ms).
pub fn with_phases(sc: &Scenario, fraction_pct: u64, cycle_ms: u64) -> Scenario {
    let mut sc = sc.clone();
    sc.sense_ms = cycle_ms * fraction_pct / 100;
    sc.act_ms = cycle_ms - sc.sense_ms;
    sc
}

/// The speeds at which the people of the harder world walk towards the robot, mm/s: standing
/// boxes, a slow walk, a walk, a brisk walk, a run.
pub const PERSON_SPEEDS_MM_S: [u16; 5] = [0, 500, 1_000, 1_500, 3_000];

/// The harder world's sonar height, µm: a NAO's chest sonars sit about 0.35 m high.
pub const HARDER_SONAR_HEIGHT_UM: i64 = 350_000;

/// The harder world's cone: its lower edge drops 0.577 m a metre (a 60° cone on a level axis).
pub const HARDER_CONE_SLOPE_PPM: i64 = 577_000;

/// The heights of the harder world's standing boxes, uniform, mm.
pub const HARDER_BOX_HEIGHT_MM: (u64, u64) = (50, 800);

/// The height of the harder world's people, µm: taller than the sonar, so in its cone at any
/// distance.
pub const PERSON_HEIGHT_UM: u32 = 1_700_000;

/// World `index` of the study with the hazards, its people walking at `speed_mm_s`: the clean
/// world ([`world`]) with the sonar [`HARDER_SONAR_HEIGHT_UM`] high under a cone that drops
/// [`HARDER_CONE_SLOPE_PPM`] and a bumper that feels a contact once it has lasted one
/// bumper period. Each box is, with even odds, a person walking towards the robot or a
/// standing box of a height drawn uniformly in [`HARDER_BOX_HEIGHT_MM`] (drawn from their own
/// stream: the same at every speed). Balls lie still.
pub fn harder_world(seed: u64, index: u64, speed_mm_s: u16) -> Scenario {
    let mut sc = world(seed, index, false);
    let mut rng = Pcg32::new(seed ^ 0x6861_7264_6572, index);
    sc.sonar.height_um = HARDER_SONAR_HEIGHT_UM;
    sc.sonar.cone_slope_ppm = HARDER_CONE_SLOPE_PPM;
    sc.bumper_min_contact_ms = sc.bumper_period_ms;
    for i in &mut sc.interferences {
        let person = uniform(&mut rng, 0, 1) == 0;
        let (lo, hi) = HARDER_BOX_HEIGHT_MM;
        let height_um = uniform(&mut rng, lo, hi) * 1_000;
        if i.kind == Kind::Box {
            if person {
                i.height_um = PERSON_HEIGHT_UM;
                i.speed_um_per_ms = speed_mm_s;
            } else {
                i.height_um = height_um as u32;
            }
        }
    }
    sc
}

/// What one run contributes.
#[derive(Clone, Copy, Debug)]
struct RunVals {
    /// Detected / detectable, over the obstacles detectable in the world's P-SMPA run;
    /// `None` when none was.
    detection: Option<f64>,
    /// Detected / (detected + collided), over the same obstacles; `None` when the robot met
    /// none of them (each was taken away first).
    met: Option<f64>,
    collisions: u32,
    time_ms: u64,
    reached: bool,
}

impl RunVals {
    fn new(s: &Summary, detectable: &[bool]) -> Self {
        let (mut of, mut hit, mut met) = (0u32, 0u32, 0u32);
        for (o, &d) in s.obstacles.iter().zip(detectable) {
            if d {
                of += 1;
                hit += u32::from(matches!(o.fate, Fate::Detected(_)));
                met += u32::from(!matches!(o.fate, Fate::Unmet));
            }
        }
        Self {
            detection: (of > 0).then(|| f64::from(hit) / f64::from(of)),
            met: (met > 0).then(|| f64::from(hit) / f64::from(met)),
            collisions: s.tally.collisions,
            time_ms: s.time_cost_ms,
            reached: s.tally.reached_door,
        }
    }
}

/// One world under P-SMPA and under every cell's SMPA.
struct WorldVals {
    psmpa: RunVals,
    smpa: Vec<RunVals>,
}

fn run_world(sc: &Scenario) -> Result<WorldVals, RunError> {
    let p = run_summary(sc, Arch::PSmpa)?;
    // Detectable is a property of each obstacle, measured where the sensors never sleep.
    let detectable: Vec<bool> = p.obstacles.iter().map(|o| o.detectable).collect();
    let mut smpa = Vec::with_capacity(CELLS);
    for &f in &FRACTIONS_PCT {
        for &c in &CYCLES_MS {
            let s = run_summary(&with_phases(sc, f, c), Arch::Smpa)?;
            smpa.push(RunVals::new(&s, &detectable));
        }
    }
    Ok(WorldVals {
        psmpa: RunVals::new(&p, &detectable),
        smpa,
    })
}

/// One world of the harder part: per person speed, P-SMPA and SMPA at Table I's setting.
fn run_harder(seed: u64, index: u64) -> Result<Vec<[RunVals; 2]>, RunError> {
    PERSON_SPEEDS_MM_S
        .iter()
        .map(|&v| {
            let sc = harder_world(seed, index, v);
            let p = run_summary(&sc, Arch::PSmpa)?;
            let detectable: Vec<bool> = p.obstacles.iter().map(|o| o.detectable).collect();
            let table1 = with_phases(&sc, PAPER_FRACTION_PCT, TABLE1_CYCLE_MS);
            let s = run_summary(&table1, Arch::Smpa)?;
            Ok([RunVals::new(&p, &detectable), RunVals::new(&s, &detectable)])
        })
        .collect()
}

/// Running sums of one quantity, added in world order.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Moments {
    n: u64,
    sum: f64,
    sum_sq: f64,
}

impl Moments {
    pub(crate) fn add(&mut self, x: f64) {
        self.n += 1;
        self.sum += x;
        self.sum_sq += x * x;
    }

    /// Mean ± 1.96 sd/√n, clamped to `[lo_bound, hi_bound]`; `None` without data.
    pub(crate) fn interval(&self, lo_bound: f64, hi_bound: f64) -> Option<Interval> {
        if self.n == 0 {
            return None;
        }
        let n = self.n as f64;
        let mean = self.sum / n;
        let var = if self.n > 1 {
            ((self.sum_sq - n * mean * mean) / (n - 1.0)).max(0.0)
        } else {
            0.0
        };
        let half = Z95 * (var / n).sqrt();
        let mean = mean.clamp(lo_bound, hi_bound);
        Some(Interval {
            mean,
            lo: (mean - half).clamp(lo_bound, mean),
            hi: (mean + half).clamp(mean, hi_bound),
            n: self.n,
        })
    }
}

/// A mean with its 95 % confidence interval. In JSON, `lo` and `hi` are `null` for a mean of
/// one run: one run shows no spread, so there is no interval.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Interval {
    /// The mean over the runs.
    pub mean: f64,
    /// Lower bound: mean − 1.96·sd/√n (not below the quantity's least value).
    pub lo: f64,
    /// Upper bound: mean + 1.96·sd/√n (not above the quantity's greatest value).
    pub hi: f64,
    /// Runs the mean is over.
    pub n: u64,
}

impl Interval {
    /// Its bounds; `None` for a mean of one run, which has no interval.
    pub fn bounds(&self) -> Option<(f64, f64)> {
        (self.n > 1).then_some((self.lo, self.hi))
    }
}

impl Serialize for Interval {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct as _;
        let bounds = self.bounds();
        let mut st = s.serialize_struct("Interval", 4)?;
        st.serialize_field("mean", &self.mean)?;
        st.serialize_field("lo", &bounds.map(|b| b.0))?;
        st.serialize_field("hi", &bounds.map(|b| b.1))?;
        st.serialize_field("n", &self.n)?;
        st.end()
    }
}

/// What one architecture amounted to in one cell (or, for P-SMPA, in every cell).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ArchCell {
    /// Fraction of the detectable obstacles detected, per run (runs with at least one).
    pub detection_rate: Option<Interval>,
    /// Of those detectable obstacles the robot met (detected or collided with; not those taken
    /// away before it came near), the fraction detected, per run that met at least one.
    pub met_detection_rate: Option<Interval>,
    /// Collisions per run.
    pub collisions: Option<Interval>,
    /// Runs that did not reach the door within the time limit.
    pub not_reached: u64,
}

#[derive(Clone, Copy, Default)]
struct ArchSums {
    detection: Moments,
    met: Moments,
    collisions: Moments,
    not_reached: u64,
}

impl ArchSums {
    fn add(&mut self, v: &RunVals) {
        if let Some(d) = v.detection {
            self.detection.add(d);
        }
        if let Some(m) = v.met {
            self.met.add(m);
        }
        self.collisions.add(f64::from(v.collisions));
        self.not_reached += u64::from(!v.reached);
    }

    fn cell(&self) -> ArchCell {
        ArchCell {
            detection_rate: self.detection.interval(0.0, 1.0),
            met_detection_rate: self.met.interval(0.0, 1.0),
            collisions: self.collisions.interval(0.0, f64::INFINITY),
            not_reached: self.not_reached,
        }
    }
}

/// One SMPA setting and what it amounted to.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Cell {
    /// Sense fraction, %.
    pub sense_fraction_pct: u64,
    /// Cycle length, ms.
    pub cycle_ms: u64,
    /// Sense phase, ms.
    pub sense_ms: u64,
    /// Act phase, ms.
    pub act_ms: u64,
    /// SMPA.
    pub smpa: ArchCell,
    /// SMPA time / P-SMPA time of the same world, over the worlds where both reached the
    /// door.
    pub time_ratio: Option<Interval>,
}

/// One pass over the grid.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Pass {
    /// `clean` or `faults`.
    pub name: &'static str,
    /// P-SMPA (the SMPA settings do not affect it: one run per world).
    pub psmpa: ArchCell,
    /// The cells, sense fraction major, cycle length minor.
    pub cells: Vec<Cell>,
}

impl Pass {
    /// The cell where SMPA's detection rate is highest (the shorter time ratio on a tie).
    pub fn closest(&self) -> Option<&Cell> {
        let key = |c: &Cell| c.smpa.detection_rate.map_or(f64::NEG_INFINITY, |d| d.mean);
        self.cells.iter().max_by(|a, b| {
            key(a).total_cmp(&key(b)).then_with(|| {
                let r = |c: &Cell| c.time_ratio.map_or(f64::INFINITY, |t| t.mean);
                r(b).total_cmp(&r(a))
            })
        })
    }

    /// The cell of a setting.
    pub fn cell(&self, fraction_pct: u64, cycle_ms: u64) -> Option<&Cell> {
        self.cells
            .iter()
            .find(|c| c.sense_fraction_pct == fraction_pct && c.cycle_ms == cycle_ms)
    }
}

/// One person speed of the harder world.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct HarderRow {
    /// How fast the boxes walk towards the robot, m/s.
    pub person_speed_mps: f64,
    /// P-SMPA.
    pub psmpa: ArchCell,
    /// SMPA at Table I's setting (sense 50 %, cycle 3 s).
    pub smpa: ArchCell,
}

/// The harder world: the clean worlds with the hazards under which P-SMPA can fail.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Harder {
    /// The sonar's height, m.
    pub sonar_height_m: f64,
    /// How far the sonar cone's lower edge drops per metre ahead.
    pub cone_slope: f64,
    /// The standing boxes' heights are uniform in this range, m.
    pub box_height_m: [f64; 2],
    /// The people's height, m.
    pub person_height_m: f64,
    /// How long a contact must last before the bumper feels it.
    pub bumper_min_contact: &'static str,
    /// One row per person speed.
    pub rows: Vec<HarderRow>,
}

/// The grid.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Settings {
    /// Sense fractions, %.
    pub sense_fraction_pct: Vec<u64>,
    /// Cycle lengths, ms.
    pub cycle_ms: Vec<u64>,
    /// Longest simulated run, ms.
    pub max_run_ms: u64,
    /// How the intervals are computed.
    pub interval: &'static str,
}

/// The whole study.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Study {
    /// The grid.
    pub settings: Settings,
    /// Worlds per cell.
    pub runs: u64,
    /// Seed of the world generator.
    pub seed: u64,
    /// Clean sensors.
    pub clean: Pass,
    /// Sensor faults and read latencies drawn at random.
    pub faults: Pass,
    /// The clean worlds with the hazards under which P-SMPA can fail.
    pub harder: Harder,
}

#[derive(Clone)]
struct PassSums {
    psmpa: ArchSums,
    smpa: Vec<ArchSums>,
    ratio: Vec<Moments>,
}

impl PassSums {
    fn new() -> Self {
        Self {
            psmpa: ArchSums::default(),
            smpa: vec![ArchSums::default(); CELLS],
            ratio: vec![Moments::default(); CELLS],
        }
    }

    fn add(&mut self, w: &WorldVals) {
        self.psmpa.add(&w.psmpa);
        for (k, s) in w.smpa.iter().enumerate() {
            if let (Some(sums), Some(ratio)) = (self.smpa.get_mut(k), self.ratio.get_mut(k)) {
                sums.add(s);
                if s.reached && w.psmpa.reached {
                    ratio.add(s.time_ms as f64 / w.psmpa.time_ms.max(1) as f64);
                }
            }
        }
    }

    fn pass(&self, name: &'static str) -> Pass {
        let mut cells = Vec::with_capacity(CELLS);
        let grid = FRACTIONS_PCT
            .iter()
            .flat_map(|&f| CYCLES_MS.iter().map(move |&c| (f, c)));
        for ((f, c), (s, r)) in grid.zip(self.smpa.iter().zip(&self.ratio)) {
            let sense_ms = c * f / 100;
            cells.push(Cell {
                sense_fraction_pct: f,
                cycle_ms: c,
                sense_ms,
                act_ms: c - sense_ms,
                smpa: s.cell(),
                time_ratio: r.interval(0.0, f64::INFINITY),
            });
        }
        Pass {
            name,
            psmpa: self.psmpa.cell(),
            cells,
        }
    }
}

/// Runs the study: `runs` worlds, each under P-SMPA once and under SMPA in every cell, clean
/// and with faults, in parallel; a progress bar on stderr when `progress` (indicatif hides it
/// when stderr is not a terminal).
pub fn study(seed: u64, runs: u64, progress: bool) -> Result<Study, RunError> {
    let per_world = 1 + CELLS as u64;
    let per_harder = 2 * PERSON_SPEEDS_MM_S.len() as u64;
    let bar = if progress {
        sweep::progress_bar(runs * (2 * per_world + per_harder), "runs")
    } else {
        ProgressBar::hidden()
    };
    let mut sums = [PassSums::new(), PassSums::new()];
    let mut start = 0;
    while start < runs {
        let end = (start + CHUNK).min(runs);
        // Collected in order and summed sequentially: the same sums on any number of threads.
        let chunk: Vec<WorldVals> = (2 * start..2 * end)
            .into_par_iter()
            .map(|j| {
                let out = run_world(&world(seed, j / 2, j % 2 == 1));
                bar.inc(per_world);
                out
            })
            .collect::<Result<_, _>>()?;
        for pair in chunk.chunks(2) {
            for (s, w) in sums.iter_mut().zip(pair) {
                s.add(w);
            }
        }
        start = end;
    }
    let mut harder = vec![[ArchSums::default(); 2]; PERSON_SPEEDS_MM_S.len()];
    start = 0;
    while start < runs {
        let end = (start + CHUNK).min(runs);
        let chunk: Vec<Vec<[RunVals; 2]>> = (start..end)
            .into_par_iter()
            .map(|i| {
                let out = run_harder(seed, i);
                bar.inc(per_harder);
                out
            })
            .collect::<Result<_, _>>()?;
        for rows in &chunk {
            for (sums, vals) in harder.iter_mut().zip(rows) {
                for (s, v) in sums.iter_mut().zip(vals) {
                    s.add(v);
                }
            }
        }
        start = end;
    }
    bar.finish_and_clear();
    let [clean, faults] = sums;
    let (lo, hi) = HARDER_BOX_HEIGHT_MM;
    Ok(Study {
        settings: Settings {
            sense_fraction_pct: FRACTIONS_PCT.to_vec(),
            cycle_ms: CYCLES_MS.to_vec(),
            max_run_ms: MAX_MS,
            interval: "95 %: mean ± 1.96·sd/√n over the runs, clamped to the quantity's range",
        },
        runs,
        seed,
        clean: clean.pass("clean"),
        faults: faults.pass("faults"),
        harder: Harder {
            sonar_height_m: HARDER_SONAR_HEIGHT_UM as f64 / 1e6,
            cone_slope: HARDER_CONE_SLOPE_PPM as f64 / 1e6,
            box_height_m: [lo as f64 / 1e3, hi as f64 / 1e3],
            person_height_m: f64::from(PERSON_HEIGHT_UM) / 1e6,
            bumper_min_contact: "one bumper period",
            rows: PERSON_SPEEDS_MM_S
                .iter()
                .zip(&harder)
                .map(|(&v, [p, s])| HarderRow {
                    person_speed_mps: f64::from(v) / 1e3,
                    psmpa: p.cell(),
                    smpa: s.cell(),
                })
                .collect(),
        },
    })
}

/// The paper's pooled SMPA detection rates, sonar and bumper rows (10/21 and 7/15).
pub fn paper_detection() -> [(&'static str, f64); 2] {
    ["sonar", "bumper"].map(|sensor| {
        let (hit, of) = PAPER
            .iter()
            .filter(|r| r.sensor == sensor)
            .fold((0, 0), |(h, n), r| {
                (h + r.smpa_detected, n + r.interferences)
            });
        (sensor, f64::from(hit) / f64::from(of.max(1)))
    })
}

/// The paper's time ratio: the sum of its SMPA times over the sum of its P-SMPA times.
pub fn paper_time_ratio() -> f64 {
    let (s, p) = PAPER.iter().fold((0.0, 0.0), |(s, p), r| {
        (s + r.smpa_time_s, p + r.psmpa_time_s)
    });
    s / p
}

/// The sense fraction at which the paper's points are drawn (the paper does not say).
pub const PAPER_FRACTION_PCT: u64 = 50;

/// The cycle length of the Table I scenario files (1.5 s sense, 1.5 s act).
pub const TABLE1_CYCLE_MS: u64 = 3_000;

fn pct(i: Option<Interval>) -> String {
    i.map_or("-".to_owned(), |i| match i.bounds() {
        Some((lo, hi)) => format!(
            "{:.1} [{:.1}, {:.1}]",
            100.0 * i.mean,
            100.0 * lo,
            100.0 * hi
        ),
        None => format!("{:.1} [1 run]", 100.0 * i.mean),
    })
}

fn num(i: Option<Interval>) -> String {
    i.map_or("-".to_owned(), |i| match i.bounds() {
        Some((lo, hi)) => format!("{:.2} [{:.2}, {:.2}]", i.mean, lo, hi),
        None => format!("{:.2} [1 run]", i.mean),
    })
}

fn cycle_name(ms: u64) -> String {
    format!("{} s", ms as f64 / 1000.0)
}

fn grid(out: &mut String, title: &str, pass: &Pass, value: impl Fn(&Cell) -> String) {
    let _ = writeln!(out, "{title}");
    let _ = write!(out, "{:>6}", "sense");
    for c in CYCLES_MS {
        let _ = write!(out, " {:>20}", format!("cycle {}", cycle_name(c)));
    }
    let _ = writeln!(out);
    for f in FRACTIONS_PCT {
        let _ = write!(out, "{:>6}", format!("{f} %"));
        for c in CYCLES_MS {
            let v = pass.cell(f, c).map_or("-".to_owned(), &value);
            let _ = write!(out, " {v:>20}");
        }
        let _ = writeln!(out);
    }
}

fn render_pass(out: &mut String, pass: &Pass, heading: &str, full: bool) {
    let _ = writeln!(out, "\n== {heading} ==");
    let p = &pass.psmpa;
    let _ = writeln!(
        out,
        "P-SMPA: detection rate {} % over {} runs, collisions per run {}, {} runs not at the door",
        pct(p.detection_rate),
        p.detection_rate.map_or(0, |d| d.n),
        num(p.collisions),
        p.not_reached
    );
    grid(
        out,
        "SMPA detection rate of detectable obstacles, % [95 % interval]",
        pass,
        |c| pct(c.smpa.detection_rate),
    );
    grid(
        out,
        "SMPA time / P-SMPA time, per world where both reached the door [95 % interval]",
        pass,
        |c| num(c.time_ratio),
    );
    if full {
        grid(
            out,
            "SMPA detection rate of the detectable obstacles it met (detected or collided \
             with), % [95 % interval]",
            pass,
            |c| pct(c.smpa.met_detection_rate),
        );
        grid(out, "SMPA collisions per run [95 % interval]", pass, |c| {
            num(c.smpa.collisions)
        });
    }
    let not_reached: u64 = pass.cells.iter().map(|c| c.smpa.not_reached).sum();
    let _ = writeln!(
        out,
        "SMPA runs that did not reach the door (left out of the time ratio): {not_reached} of {}",
        pass.cells.len() as u64 * pass.psmpa.collisions.map_or(0, |c| c.n)
    );
    if let Some(c) = pass.cell(PAPER_FRACTION_PCT, TABLE1_CYCLE_MS) {
        let _ = writeln!(
            out,
            "SMPA at the setting of the Table I scenarios (sense 50 %, cycle 3 s): detection \
             rate {} %, collisions per run {}, time ratio {}",
            pct(c.smpa.detection_rate),
            num(c.smpa.collisions),
            num(c.time_ratio)
        );
    }
    if let Some(c) = pass.closest() {
        let _ = writeln!(
            out,
            "SMPA comes closest to P-SMPA at sense {} %, cycle {} ({} ms sense, {} ms act): \
             detection rate {} % against P-SMPA's {} %, at a time ratio of {}",
            c.sense_fraction_pct,
            cycle_name(c.cycle_ms),
            c.sense_ms,
            c.act_ms,
            pct(c.smpa.detection_rate),
            pct(pass.psmpa.detection_rate),
            num(c.time_ratio)
        );
    }
}

fn render_harder(out: &mut String, h: &Harder) {
    let _ = writeln!(
        out,
        "\n== the harder world: the clean worlds with a sonar {2} m high whose cone drops {3} m \
         a metre, a bumper that feels a contact after one period, and each box either a \
         standing box {0}-{1} m high or a person walking towards the robot ==",
        h.box_height_m[0], h.box_height_m[1], h.sonar_height_m, h.cone_slope
    );
    let _ = writeln!(
        out,
        "{:>8}  {:>20} {:>20} {:>20}  {:>20} {:>20}",
        "person",
        "P-SMPA detection %",
        "P-SMPA of met %",
        "P-SMPA collisions",
        "SMPA detection %",
        "SMPA collisions"
    );
    for r in &h.rows {
        let _ = writeln!(
            out,
            "{:>8}  {:>20} {:>20} {:>20}  {:>20} {:>20}",
            format!("{} m/s", r.person_speed_mps),
            pct(r.psmpa.detection_rate),
            pct(r.psmpa.met_detection_rate),
            num(r.psmpa.collisions),
            pct(r.smpa.detection_rate),
            num(r.smpa.collisions)
        );
    }
    let _ = writeln!(
        out,
        "(SMPA at the Table I setting, sense 50 %, cycle 3 s; detection: of the obstacles \
         detectable in the world's P-SMPA run; of met: of those detected or collided with)"
    );
}

/// The study as text.
pub fn render(study: &Study) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "sensitivity: SMPA's sense fraction x cycle length, {} random worlds a cell (the same \
         worlds in every cell), seed {}",
        study.runs, study.seed
    );
    let _ = writeln!(
        out,
        "intervals: 95 %, mean ± 1.96·sd/√n over the runs; detection rate: of the obstacles \
         detectable in the world's P-SMPA run, per run with at least one"
    );
    render_pass(
        &mut out,
        &study.clean,
        "clean sensors (no noise, dropout or read latency)",
        true,
    );
    render_pass(
        &mut out,
        &study.faults,
        "with sensor faults and latencies drawn at random (sonar noise 0-30 mm and dropout \
         0-10 % each in half the worlds, sonar latency 0-40 ms, bumper 0-5 ms)",
        false,
    );
    render_harder(&mut out, &study.harder);
    let [(_, sonar), (_, bumper)] = paper_detection();
    let _ = writeln!(
        out,
        "\npaper (NAO, phases not stated): SMPA detected {:.1} % (sonar rows) and {:.1} % \
         (bumper rows) at a time ratio of {:.2}",
        100.0 * sonar,
        100.0 * bumper,
        paper_time_ratio()
    );
    out
}

/// Colours of the cycle lengths.
const COLORS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

/// The legend's label of the paper's points.
pub const PAPER_LABEL: &str = "paper (NAO; sense fraction assumed 50 %)";

type Chart<'a, 'b> = ChartContext<
    'a,
    SVGBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// One line per cycle length of `value` (`None` points left out): solid for the clean pass,
/// dashed for the faults pass.
fn lines(
    chart: &mut Chart<'_, '_>,
    study: &Study,
    value: impl Fn(&Cell) -> Option<f64>,
    legend: bool,
) -> Result<(), String> {
    for (k, &c) in CYCLES_MS.iter().enumerate() {
        let color = COLORS.get(k).copied().unwrap_or(BLACK);
        for (pass, dashed) in [(&study.clean, false), (&study.faults, true)] {
            let points: Vec<(f64, f64)> = FRACTIONS_PCT
                .iter()
                .filter_map(|&f| Some((f as f64, value(pass.cell(f, c)?)?)))
                .collect();
            if dashed {
                chart
                    .draw_series(DashedLineSeries::new(
                        points,
                        6,
                        4,
                        color.mix(0.6).stroke_width(1),
                    ))
                    .map_err(|e| e.to_string())?;
            } else {
                let series = chart
                    .draw_series(LineSeries::new(points.clone(), color.stroke_width(2)))
                    .map_err(|e| e.to_string())?;
                if legend {
                    series
                        .label(format!("cycle {}", cycle_name(c)))
                        .legend(move |(x, y)| {
                            PathElement::new([(x, y), (x + 16, y)], color.stroke_width(2))
                        });
                }
                chart
                    .draw_series(points.iter().map(|&p| Circle::new(p, 3, color.filled())))
                    .map_err(|e| e.to_string())?;
            }
        }
    }
    Ok(())
}

/// The study as an SVG document: detection rate and time ratio against the sense fraction,
/// one line per cycle length (dashed: with faults), P-SMPA's detection rate as a reference and
/// the paper's points at an assumed 50 %.
pub fn plot(study: &Study) -> Result<String, String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1400, 560)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let root = root
            .titled(
                &format!(
                    "SMPA against P-SMPA over SMPA's settings: {} random worlds a point (seed {}); \
                     solid clean sensors, dashed with faults and latencies",
                    study.runs, study.seed
                ),
                ("sans-serif", 18),
            )
            .map_err(|e| e.to_string())?;
        let panels = root.split_evenly((1, 2));
        let (Some(left), Some(right)) = (panels.first(), panels.get(1)) else {
            return Err("the plot could not be laid out".to_owned());
        };
        let x = 5.0..95.0;

        let mut chart = ChartBuilder::on(left)
            .caption("Detection rate of detectable obstacles", ("sans-serif", 16))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(55)
            .build_cartesian_2d(x.clone(), 0.0..105.0)
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc("SMPA sense fraction, sense / (sense + act) (%)")
            .y_desc("detection rate (%)")
            .light_line_style(WHITE)
            .x_label_formatter(&|x| format!("{x:.0}"))
            .y_label_formatter(&|y| format!("{y:.0}"))
            .draw()
            .map_err(|e| e.to_string())?;
        lines(
            &mut chart,
            study,
            |c| c.smpa.detection_rate.map(|d| 100.0 * d.mean),
            true,
        )?;
        if let Some(p) = study.clean.psmpa.detection_rate {
            let y = 100.0 * p.mean;
            chart
                .draw_series(LineSeries::new(
                    [(5.0, y), (95.0, y)],
                    BLACK.stroke_width(2),
                ))
                .map_err(|e| e.to_string())?
                .label(format!("P-SMPA ({y:.1} %)"))
                .legend(|(x, y)| PathElement::new([(x, y), (x + 16, y)], BLACK.stroke_width(2)));
        }
        let paper_x = PAPER_FRACTION_PCT as f64;
        let paper_points: Vec<(f64, f64)> = paper_detection()
            .iter()
            .map(|&(_, d)| (paper_x, 100.0 * d))
            .collect();
        chart
            .draw_series(
                paper_points
                    .iter()
                    .map(|&p| Cross::new(p, 7, BLACK.stroke_width(2))),
            )
            .map_err(|e| e.to_string())?
            .label(PAPER_LABEL)
            .legend(|(x, y)| Cross::new((x + 8, y), 5, BLACK.stroke_width(2)));
        chart
            .draw_series(paper_detection().iter().zip(&paper_points).enumerate().map(
                |(k, (&(sensor, _), &(px, py)))| {
                    // Sonar's label above its mark, bumper's below: the two nearly coincide.
                    let dy = if k == 0 { 5.0 } else { -1.0 };
                    Text::new(sensor, (px + 1.5, py + dy), ("sans-serif", 11))
                },
            ))
            .map_err(|e| e.to_string())?;
        legend(&mut chart, SeriesLabelPosition::UpperRight)?;

        let ratios = [&study.clean, &study.faults]
            .iter()
            .flat_map(|p| p.cells.iter().filter_map(|c| c.time_ratio.map(|t| t.mean)))
            .chain([paper_time_ratio()])
            .fold(1.0, f64::max);
        let mut chart = ChartBuilder::on(right)
            .caption(
                "Time cost, SMPA / P-SMPA (same world, both at the door)",
                ("sans-serif", 16),
            )
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(55)
            .build_cartesian_2d(x, 0.0..ratios * 1.05)
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc("SMPA sense fraction, sense / (sense + act) (%)")
            .y_desc("time ratio (SMPA s / P-SMPA s)")
            .light_line_style(WHITE)
            .x_label_formatter(&|x| format!("{x:.0}"))
            .draw()
            .map_err(|e| e.to_string())?;
        lines(&mut chart, study, |c| c.time_ratio.map(|t| t.mean), true)?;
        let paper = (paper_x, paper_time_ratio());
        chart
            .draw_series(std::iter::once(Cross::new(paper, 7, BLACK.stroke_width(2))))
            .map_err(|e| e.to_string())?
            .label(PAPER_LABEL)
            .legend(|(x, y)| Cross::new((x + 8, y), 5, BLACK.stroke_width(2)));
        legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(svg)
}

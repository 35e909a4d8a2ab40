//! `cargo xtask experiment`: the sensitivity study (`psmpa-sim sensitivity --json`, its
//! defaults: seeded, the same bytes on any machine) and the figures the pages show of it, written
//! between markers in README.md and docs/experiment.md.

use std::process::Command;

use serde::Deserialize;

use crate::firmware;

/// A mean with its 95 % interval.
#[derive(Clone, Copy, Debug, Deserialize)]
struct Interval {
    mean: f64,
    lo: f64,
    hi: f64,
}

/// An architecture's figures over the worlds of a cell or a row.
#[derive(Clone, Copy, Debug, Deserialize)]
struct Figures {
    detection_rate: Interval,
    met_detection_rate: Interval,
    collisions: Interval,
    /// Runs that did not reach the door in time.
    not_reached: u64,
}

#[derive(Debug, Deserialize)]
struct Cell {
    sense_fraction_pct: u64,
    cycle_ms: u64,
    sense_ms: u64,
    act_ms: u64,
    smpa: Figures,
    time_ratio: Interval,
}

#[derive(Debug, Deserialize)]
struct Pass {
    psmpa: Figures,
    cells: Vec<Cell>,
}

#[derive(Debug, Deserialize)]
struct Row {
    person_speed_mps: f64,
    psmpa: Figures,
    smpa: Figures,
}

#[derive(Debug, Deserialize)]
struct Harder {
    rows: Vec<Row>,
}

#[derive(Debug, Deserialize)]
struct Study {
    runs: u64,
    clean: Pass,
    faults: Pass,
    harder: Harder,
}

/// A rate as a percentage to a tenth.
fn pct(x: f64) -> String {
    format!("{:.1}", x * 100.0)
}

fn two(x: f64) -> String {
    format!("{x:.2}")
}

/// `mean (lo to hi)` of a rate, in per cent.
fn pct_interval(i: Interval) -> String {
    format!("{} ({} to {})", pct(i.mean), pct(i.lo), pct(i.hi))
}

fn two_interval(i: Interval) -> String {
    format!("{} ({} to {})", two(i.mean), two(i.lo), two(i.hi))
}

/// The cells the pages name: Table I's setting (50 %, 3 s), the highest detection rate, the
/// highest rate of those met, the fewest collisions.
fn named(pass: &Pass) -> Result<[&Cell; 4], String> {
    let table1 = pass
        .cells
        .iter()
        .find(|c| c.sense_fraction_pct == 50 && c.cycle_ms == 3_000)
        .ok_or("no cell at Table I's setting (50 %, 3 s)")?;
    let by = |f: fn(&Cell) -> f64| {
        pass.cells
            .iter()
            .max_by(|a, b| f(a).total_cmp(&f(b)))
            .ok_or("no cells")
    };
    Ok([
        table1,
        by(|c| c.smpa.detection_rate.mean)?,
        by(|c| c.smpa.met_detection_rate.mean)?,
        by(|c| -c.smpa.collisions.mean)?,
    ])
}

/// What the pages show of `study`: `(file, marker, text)`.
fn pages(study: &Study) -> Result<Vec<(&'static str, &'static str, String)>, String> {
    let [table1, detects, met, least] = named(&study.clean)?;
    let [f_table1, f_detects, f_met, _] = named(&study.faults)?;
    let p = &study.clean.psmpa;
    // The README's short table.
    let mut readme = format!(
        "\n| | detection rate | collisions per run | time, SMPA / P-SMPA |\n|---|---|---|---|\n| P-SMPA | {} % | {:.3} | 1 |\n",
        pct(p.detection_rate.mean),
        p.collisions.mean
    );
    for (what, c) in [
        ("at Table I's setting", table1),
        ("where it detects most", detects),
        ("where it collides least", least),
    ] {
        readme += &format!(
            "| SMPA {what} (sense {} ms, act {} ms) | {} % | {} | {} |\n",
            c.sense_ms,
            c.act_ms,
            pct(c.smpa.detection_rate.mean),
            two(c.smpa.collisions.mean),
            two(c.time_ratio.mean)
        );
    }
    // docs/experiment.md: each with its interval, the faults pass in brackets.
    let fp = &study.faults.psmpa;
    let mut table = format!(
        "\n| | detection rate, % | of those met, % | collisions per run | time ratio |\n|---|---|---|---|---|\n| P-SMPA | {} [{}] | {} [{}] | {:.3} [{:.3}] | 1 |\n",
        pct(p.detection_rate.mean),
        pct(fp.detection_rate.mean),
        pct(p.met_detection_rate.mean),
        pct(fp.met_detection_rate.mean),
        p.collisions.mean,
        fp.collisions.mean
    );
    for (what, c, f) in [
        ("Table I's setting", table1, f_table1),
        ("highest detection rate", detects, f_detects),
        ("highest of those met", met, f_met),
    ] {
        table += &format!(
            "| SMPA, {} %, {} s ({what}) | {} [{}] | {} [{}] | {} [{}] | {} [{}] |\n",
            c.sense_fraction_pct,
            c.cycle_ms as f64 / 1e3,
            pct_interval(c.smpa.detection_rate),
            pct(f.smpa.detection_rate.mean),
            pct_interval(c.smpa.met_detection_rate),
            pct(f.smpa.met_detection_rate.mean),
            two_interval(c.smpa.collisions),
            two(f.smpa.collisions.mean),
            two_interval(c.time_ratio),
            two(f.time_ratio.mean)
        );
    }
    table += "| paper (NAO, phases not stated) | 47.6 sonar, 46.7 bumper | | | 2.14 |\n";
    let mut harder = String::from(
        "\n| people walk at | P-SMPA detection rate, % | P-SMPA collisions per run | SMPA detection rate, % | SMPA collisions per run |\n|---|---|---|---|---|\n",
    );
    for r in &study.harder.rows {
        harder += &format!(
            "| {} m/s | {} | {} | {} | {} |\n",
            r.person_speed_mps,
            pct_interval(r.psmpa.detection_rate),
            two_interval(r.psmpa.collisions),
            pct_interval(r.smpa.detection_rate),
            two_interval(r.smpa.collisions)
        );
    }
    let range = |f: fn(&Row) -> f64, show: fn(f64) -> String| {
        let values: Vec<f64> = study.harder.rows.iter().map(f).collect();
        let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        format!("{} to {}", show(lo), show(hi))
    };
    let summary = format!(
        "it detects {} % and collides {} times a run, against SMPA's {} % and {}",
        range(|r| r.psmpa.detection_rate.mean, pct),
        range(|r| r.psmpa.collisions.mean, two),
        range(|r| r.smpa.detection_rate.mean, pct),
        range(|r| r.smpa.collisions.mean, two)
    );
    let late = |pass: &Pass| pass.cells.iter().map(|c| c.smpa.not_reached).sum::<u64>();
    let not_reached = format!(
        "{} of {} in the clean pass, {} in the faults pass",
        crate::hil::thousands(late(&study.clean)),
        crate::hil::thousands(study.runs * study.clean.cells.len() as u64),
        crate::hil::thousands(late(&study.faults))
    );
    Ok(vec![
        ("docs/experiment.md", "not-reached", not_reached),
        ("README.md", "experiment", readme),
        ("README.md", "experiment-harder", summary),
        ("docs/experiment.md", "sensitivity-table", table),
        ("docs/experiment.md", "harder-table", harder),
    ])
}

/// Runs the study with its defaults and writes its figures into the pages.
pub fn run() -> Result<(), String> {
    let sim = firmware::build_host_sim()?;
    let out = Command::new(&sim)
        .args(["sensitivity", "--json"])
        .output()
        .map_err(|e| format!("{}: {e}", sim.display()))?;
    if !out.status.success() {
        return Err(format!(
            "psmpa-sim sensitivity failed: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    let study: Study = serde_json::from_slice(&out.stdout)
        .map_err(|e| format!("psmpa-sim sensitivity --json: {e}"))?;
    let root = firmware::root();
    let regions: Vec<_> = pages(&study)?
        .into_iter()
        .map(|(page, marker, text)| (root.join(page), marker, text))
        .collect();
    crate::pages::write_pages(&regions)?;
    println!("the sensitivity study's figures written into README.md and docs/experiment.md");
    Ok(())
}

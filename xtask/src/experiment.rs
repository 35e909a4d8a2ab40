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

/// The markers this command writes between: (page, name).
const REGIONS: [(&str, &str); 7] = [
    ("docs/experiment.md", "not-reached"),
    ("README.md", "experiment"),
    ("README.md", "experiment-harder"),
    ("docs/experiment.md", "sensitivity-table"),
    ("docs/experiment.md", "harder-table"),
    ("docs/experiment.md", "table1"),
    ("docs/experiment.md", "table1-shifted"),
];

/// A row of `psmpa-sim table1`'s second table (the shifted instants): sensor, P-SMPA's and
/// SMPA's detected % and the time ratio, each a mean.
struct Shifted {
    sensor: String,
    scenario: String,
    psmpa_pct: f64,
    smpa_pct: f64,
    ratio: f64,
}

/// The shifted rows of `table1`'s text: those after its second header whose first cell is a
/// sensor and a count.
fn shifted_rows(table1: &str) -> Result<Vec<Shifted>, String> {
    let second = table1
        .find("P-SMPA detected %")
        .ok_or("psmpa-sim table1: no table of shifted instants")?;
    let mean = |cell: &str| -> Result<f64, String> {
        cell.split_whitespace()
            .next()
            .and_then(|m| m.parse().ok())
            .ok_or_else(|| format!("psmpa-sim table1: not a mean: {cell:?}"))
    };
    let mut rows = Vec::new();
    for line in table1[second..].lines() {
        let cells: Vec<&str> = line.split('|').collect();
        let Some(&[sensor, count]) = cells
            .first()
            .map(|c| c.split_whitespace().collect::<Vec<_>>())
            .as_deref()
        else {
            continue;
        };
        if cells.len() != 6 || count.parse::<u32>().is_err() {
            continue;
        }
        rows.push(Shifted {
            sensor: sensor.to_owned(),
            scenario: format!("{sensor}-{count}"),
            psmpa_pct: mean(cells[1])?,
            smpa_pct: mean(cells[3])?,
            ratio: mean(cells[5])?,
        });
    }
    if rows.is_empty() {
        return Err("psmpa-sim table1: no shifted rows".to_owned());
    }
    Ok(rows)
}

/// What docs/experiment.md says of the shifted rows: SMPA's detections of the boxes and of
/// the balls, the time ratios, and what P-SMPA misses.
fn shifted_summary(rows: &[Shifted]) -> String {
    let range = |of: &dyn Fn(&Shifted) -> bool, f: fn(&Shifted) -> f64, digits: usize| {
        let values: Vec<f64> = rows.iter().filter(|r| of(r)).map(f).collect();
        let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let (lo, hi) = (format!("{lo:.digits$}"), format!("{hi:.digits$}"));
        if lo == hi {
            lo
        } else {
            format!("{lo} to {hi}")
        }
    };
    let sonar = |r: &Shifted| r.sensor == "sonar";
    let bumper = |r: &Shifted| r.sensor == "bumper";
    // What P-SMPA misses of one kind of obstacle, row by row.
    let misses = |of: &dyn Fn(&Shifted) -> bool, kind: &str| {
        let missed: Vec<String> = rows
            .iter()
            .filter(|r| of(r) && r.psmpa_pct < 100.0)
            .map(|r| format!("{:.1} % in `{}`", 100.0 - r.psmpa_pct, r.scenario))
            .collect();
        if missed.is_empty() {
            format!("detects every {kind}")
        } else {
            format!("misses {} of the {kind}s", missed.join(", "))
        }
    };
    format!(
        "SMPA then sees {} % of the boxes and {} % of the balls, and the time ratio is {}. P-SMPA {} and {}",
        range(&sonar, |r| r.smpa_pct, 0),
        range(&bumper, |r| r.smpa_pct, 0),
        range(&|_| true, |r| r.ratio, 2),
        misses(&sonar, "box"),
        misses(&bumper, "ball"),
    )
}

/// Runs `psmpa-sim ARGS` and returns its standard output.
fn sim_output(sim: &std::path::Path, args: &[&str]) -> Result<Vec<u8>, String> {
    let out = Command::new(sim)
        .args(args)
        .output()
        .map_err(|e| format!("{}: {e}", sim.display()))?;
    if !out.status.success() {
        return Err(format!(
            "psmpa-sim {} failed: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    Ok(out.stdout)
}

/// Runs the study with its defaults and Table I, and writes their figures into the pages.
pub fn run() -> Result<(), String> {
    let root = firmware::root();
    let at = |page: &str| root.join(page);
    let marked: Vec<_> = REGIONS.iter().map(|(p, m)| (at(p), *m)).collect();
    crate::pages::check_pages(&marked)?;
    let sim = firmware::build_host_sim()?;
    let study: Study = serde_json::from_slice(&sim_output(&sim, &["sensitivity", "--json"])?)
        .map_err(|e| format!("psmpa-sim sensitivity --json: {e}"))?;
    let table1 = String::from_utf8(sim_output(&sim, &["table1"])?)
        .map_err(|e| format!("psmpa-sim table1: {e}"))?;
    let mut regions: Vec<_> = pages(&study)?
        .into_iter()
        .map(|(page, marker, text)| (at(page), marker, text))
        .collect();
    regions.push((
        at("docs/experiment.md"),
        "table1",
        format!("\n```text\n{table1}```\n"),
    ));
    regions.push((
        at("docs/experiment.md"),
        "table1-shifted",
        shifted_summary(&shifted_rows(&table1)?),
    ));
    crate::pages::write_pages(&regions)?;
    println!(
        "the sensitivity study's and Table I's figures written into README.md and docs/experiment.md"
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shifted rows as `psmpa-sim table1` prints them, and what the page says of them.
    #[test]
    fn the_shifted_rows_are_read_and_summed_up() {
        let text = "Table I ...\nsonar        6 |     6 [6] 100.0 [100.0]    0   23.1 [23] |     2 [2]   33.3 [33.3]    0   41.5 [53] \n\
            sensor  interf |  P-SMPA detected %   | P-SMPA collisions |   SMPA detected %    |  SMPA collisions  | time SMPA/P-SMPA \n\
            ------------------\n\
            sonar        6 | 100.0 [100.0, 100.0] | 0.00 [0.00, 0.00] |    80.4 [78.7, 82.0] | 0.00 [0.00, 0.00] | 1.86 [1.85, 1.87]\n\
            sonar        7 | 100.0 [100.0, 100.0] | 0.00 [0.00, 0.00] |    81.2 [79.1, 82.1] | 0.22 [0.19, 0.25] | 1.98 [1.97, 1.98]\n\
            bumper       4 |    98.6 [98.2, 98.9] | 0.00 [0.00, 0.00] |    24.0 [22.5, 25.5] | 3.04 [2.98, 3.10] | 2.37 [2.35, 2.38]\n";
        let rows = shifted_rows(text).unwrap();
        assert_eq!(
            rows.len(),
            3,
            "the first table's rows are not the shifted ones"
        );
        assert_eq!(
            shifted_summary(&rows),
            "SMPA then sees 80 to 81 % of the boxes and 24 % of the balls, and the time ratio is 1.86 to 2.37. P-SMPA detects every box and misses 1.4 % in `bumper-4` of the balls"
        );
        assert!(shifted_rows("no table").is_err());
    }
}

//! Expected traces: every shipped scenario under both architectures, event by event, against
//! the text checked in under `scenarios/traces/` (`NAME.ARCH.trace`). A change of behaviour
//! fails with a diff that names the events; bless intended changes with
//! `PSMPA_BLESS=1 cargo test -p psmpa-sim --test traces`.

mod common;

use std::path::{Path, PathBuf};

use psmpa_sim::cli::outputs::trace_text;
use psmpa_sim::load::load;
use psmpa_sim::robot::Arch;
use psmpa_sim::sim::run_recorded;
use rayon::prelude::*;
use similar::TextDiff;

/// Lines of a diff shown per trace: enough to read the first changes, not a flood.
const SHOWN: usize = 40;

fn traces() -> PathBuf {
    common::repo("scenarios/traces")
}

fn expected_path(name: &str, arch: Arch) -> PathBuf {
    traces().join(format!("{name}.{}.trace", arch.name()))
}

/// What differs between the expected trace and the run's, as a unified diff cut to [`SHOWN`]
/// lines; `None` when they are equal.
fn difference(file: &Path, expected: &str, got: &str) -> Option<String> {
    if expected == got {
        return None;
    }
    let diff = TextDiff::from_lines(expected, got)
        .unified_diff()
        .context_radius(2)
        .header(&file.display().to_string(), "this run")
        .to_string();
    let total = diff.lines().count();
    let mut shown: Vec<&str> = diff.lines().take(SHOWN).collect();
    let more = format!("... {} more lines of diff", total.saturating_sub(SHOWN));
    if total > SHOWN {
        shown.push(&more);
    }
    Some(shown.join("\n"))
}

#[test]
fn every_shipped_scenario_runs_as_its_expected_trace() {
    let bless = std::env::var_os("PSMPA_BLESS").is_some();
    let scenarios: Vec<PathBuf> = common::names_in(&common::repo("scenarios"))
        .into_iter()
        .filter(|n| n.ends_with(".json"))
        .map(|n| common::repo("scenarios").join(n))
        .collect();
    assert!(scenarios.len() >= 15, "the shipped scenarios are missing");
    let runs: Vec<(PathBuf, Arch)> = scenarios
        .iter()
        .flat_map(|p| Arch::ALL.map(|a| (p.clone(), a)))
        .collect();
    let mut failures: Vec<String> = runs
        .par_iter()
        .filter_map(|(path, arch)| {
            let scenario = load(path).unwrap();
            let rec = run_recorded(&scenario, *arch).unwrap();
            let got = trace_text(&scenario, *arch, &rec);
            let file = expected_path(scenario.name.as_str(), *arch);
            if bless {
                std::fs::write(&file, &got).unwrap();
                return None;
            }
            match std::fs::read_to_string(&file) {
                Ok(expected) => difference(&file, &expected, &got),
                Err(e) => Some(format!("{}: {e}", file.display())),
            }
        })
        .collect();
    failures.sort();
    assert!(
        failures.is_empty(),
        "{} of {} runs differ from their expected traces:\n\n{}\n\nIf the change is intended: \
         PSMPA_BLESS=1 cargo test -p psmpa-sim --test traces",
        failures.len(),
        runs.len(),
        failures.join("\n\n")
    );
    // No expected trace is left without its scenario.
    let mut names: Vec<String> = common::names_in(&traces());
    let mut wanted: Vec<String> = runs
        .iter()
        .map(|(p, a)| {
            let name = load(p).unwrap().name.as_str().to_owned();
            format!("{name}.{}.trace", a.name())
        })
        .collect();
    names.sort();
    wanted.sort();
    assert_eq!(names, wanted, "an expected trace without its scenario");
}

/// One event changed in a run's trace makes the comparison fail, and the message shows that
/// event, the one expected in its place, and the time it happened.
#[test]
fn a_changed_event_shows_in_the_diff() {
    let path = common::repo("scenarios/sonar-6.json");
    let scenario = load(&path).unwrap();
    let rec = run_recorded(&scenario, Arch::PSmpa).unwrap();
    let expected = trace_text(&scenario, Arch::PSmpa, &rec);
    let line = expected
        .lines()
        .find(|l| l.contains(" r walk: stop and side-step"))
        .unwrap()
        .to_owned();
    let changed_line = line.replace("walk: stop", "walk: keep going");
    let changed = expected.replacen(&line, &changed_line, 1);
    let file = expected_path("sonar-6", Arch::PSmpa);
    let diff = difference(&file, &expected, &changed).unwrap();
    assert!(diff.contains(&format!("-{line}")), "{diff}");
    assert!(diff.contains(&format!("+{changed_line}")), "{diff}");
    assert!(diff.contains("sonar-6.psmpa.trace"), "{diff}");
    assert_eq!(difference(&file, &expected, &expected), None);
}

/// The text is the trace, not a summary: every runtime event and every world event of the
/// run is one line, in time order, and the first line carries the trace hash.
#[test]
fn the_text_has_one_line_per_event() {
    let scenario = load(&common::repo("scenarios/bumper-4.json")).unwrap();
    let rec = run_recorded(&scenario, Arch::Smpa).unwrap();
    let text = trace_text(&scenario, Arch::Smpa, &rec);
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some(format!("# bumper-4 smpa trace_hash {:016x}", rec.summary.trace_hash).as_str())
    );
    let events: Vec<(u64, &str)> = lines
        .map(|l| {
            let mut parts = l.splitn(3, ' ');
            let t = parts.next().unwrap().parse().unwrap();
            (t, parts.next().unwrap())
        })
        .collect();
    assert_eq!(
        events.iter().filter(|(_, s)| *s == "w").count(),
        rec.world.0.len()
    );
    assert_eq!(
        events.iter().filter(|(_, s)| *s == "r").count(),
        rec.trace.0.len()
    );
    assert!(events.windows(2).all(|w| w[0].0 <= w[1].0));
}

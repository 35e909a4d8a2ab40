//! Algorithm 2 at build time against Algorithm 2 at run time: every shipped scenario, and a
//! hundred random ones (`psmpa-sim sweep`'s), under both architectures, along the two paths
//! of the compiled Fetch Tea mission (its plans' states as constants, and its plans through
//! the run-time FSM), the one robot on its simulated devices: the same trace, event by event
//! (its hash), and the same outcome.

mod common;

use psmpa_sim::cli::sweep;
use psmpa_sim::load::load;
use psmpa_sim::robot::Arch;
use psmpa_sim::sim::{PlanPath, run_on};
use rayon::prelude::*;

fn same_on_every_path(name: &str, scenario: &psmpa_sim::scenario::Scenario) {
    for arch in Arch::ALL {
        let built = run_on(scenario, arch, PlanPath::Compiled).unwrap();
        let other = run_on(scenario, arch, PlanPath::CompiledRunTime).unwrap();
        assert_eq!(
            (other.trace_hash, other.trace_events),
            (built.trace_hash, built.trace_events),
            "{name} {}: the run-time FSM gives another trace than the built one",
            arch.name()
        );
        assert_eq!(other, built, "{name} {}", arch.name());
    }
}

#[test]
fn every_shipped_scenario_runs_alike_on_both_paths() {
    let names: Vec<String> = common::names_in(&common::repo("scenarios"))
        .into_iter()
        .filter(|n| n.ends_with(".json"))
        .collect();
    assert!(names.len() >= 15, "the shipped scenarios are missing");
    names.par_iter().for_each(|name| {
        let scenario = load(&common::repo("scenarios").join(name)).unwrap();
        same_on_every_path(name, &scenario);
    });
}

#[test]
fn random_scenarios_run_alike_on_the_three_paths() {
    (0..100u64).into_par_iter().for_each(|i| {
        let scenario = sweep::scenario(55, i);
        same_on_every_path(&format!("sweep scenario {i}"), &scenario);
    });
}

/// The comparison can fail: another run (the sonar's period 50 ms longer) along the compiled
/// path gives another trace.
#[test]
fn another_run_gives_another_trace() {
    let mut scenario = load(&common::repo("scenarios/sonar-6.json")).unwrap();
    let built = run_on(&scenario, Arch::PSmpa, PlanPath::Compiled).unwrap();
    scenario.sonar.period_ms += 50;
    let other = run_on(&scenario, Arch::PSmpa, PlanPath::CompiledRunTime).unwrap();
    assert_ne!(other.trace_hash, built.trace_hash);
}

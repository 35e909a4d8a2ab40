//! Any bytes given to the scenario parser: a scenario or an error naming the field, never a
//! panic. A valid scenario survives its canonical form unchanged and simulates to the end under
//! both architectures (no panic, no overflow, no deadlock, no time-limit error).
#![no_main]

use libfuzzer_sys::fuzz_target;
use psmpa_sim::robot::Arch;
use psmpa_sim::scenario::Scenario;
use psmpa_sim::sim::run_summary;

fuzz_target!(|data: &[u8]| {
    // The host's loader also re-reads bad files with serde_json to say where.
    let loaded = psmpa_sim::load::parse(std::path::Path::new("fuzz.json"), data);
    let Ok(mut scenario) = loaded.map_err(|e| assert!(!e.message.is_empty())) else {
        return;
    };
    let mut buf = vec![0u8; 16 * 1024];
    if let Ok(len) = scenario.to_canonical(&mut buf) {
        assert_eq!(Scenario::from_canonical(&buf[..len]).unwrap(), scenario);
    }
    // Keep each run short: the physics, not the length of the walk, is under test.
    scenario.max_ms = scenario.max_ms.min(30_000);
    for arch in Arch::ALL {
        let summary = run_summary(&scenario, arch).expect("the simulation runs to its end");
        assert!(summary.time_cost_ms <= scenario.max_ms);
        assert!(summary.tally.detected + summary.tally.collisions <= summary.tally.interferences);
    }
});

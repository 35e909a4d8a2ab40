//! The simulated experiment: Table I, the world's physics on cases with known answers,
//! determinism, and the sweep.

use std::path::PathBuf;

use psmpa_core::{TraceEvent, Value};
use psmpa_sim::cli::{sweep, table1};
use psmpa_sim::load::load;
use psmpa_sim::robot::Arch;
use psmpa_sim::run::Ending;
use psmpa_sim::scenario::Scenario;
use psmpa_sim::sim::{run_recorded, run_summary};
use psmpa_sim::world::{Device, Fate};

fn scenario(name: &str) -> Scenario {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("../scenarios/{name}.json"));
    load(&path).unwrap()
}

#[test]
fn table1_psmpa_detects_every_interference_and_smpa_fewer_and_slower() {
    let rows = table1::compute().unwrap();
    assert_eq!(rows.len(), 6);
    for r in &rows {
        let (p, s) = (&r.psmpa, &r.smpa);
        assert_eq!(p.interferences, r.paper.interferences, "{}", r.scenario);
        assert_eq!(
            p.detected, p.interferences,
            "{}: P-SMPA detects all",
            r.scenario
        );
        assert_eq!(p.collisions, 0, "{}", r.scenario);
        assert!(
            s.detected < p.detected,
            "{}: SMPA detects fewer",
            r.scenario
        );
        assert!(s.time_s > p.time_s, "{}: SMPA takes longer", r.scenario);
        // The rows were built to mirror the paper's SMPA counts and P-SMPA times.
        assert_eq!(s.detected, r.paper.smpa_detected, "{}", r.scenario);
        // A touch registers within one bumper period (20 ms) after contact.
        assert!(
            (p.time_s - r.paper.psmpa_time_s).abs() < 0.5,
            "{}: {}",
            r.scenario,
            p.time_s
        );
    }
    let ratio = rows.iter().map(|r| r.smpa.time_s).sum::<f64>()
        / rows.iter().map(|r| r.psmpa.time_s).sum::<f64>();
    assert!(
        ratio > 1.8,
        "SMPA about twice as slow as P-SMPA, got {ratio:.2}"
    );
}

/// With nothing in the way the times follow from distance, speed and the phases alone.
#[test]
fn a_quiet_walk_takes_exactly_what_distance_speed_and_phases_say() {
    let sc = scenario("quiet"); // 2 m at 0.1 m/s, SMPA 1 s sense / 3 s act
    let p = run_summary(&sc, Arch::PSmpa).unwrap();
    // 20 s walk, 1 s to open the door, 1 s to enter.
    assert_eq!(p.time_cost_ms, 22_000);
    assert!(matches!(p.ending, Ending::Goal(_)));
    // Least commitment: sonar and bumper on exactly while walking, the camera while opening.
    assert_eq!(p.tally.on_ms, [20_000, 20_000, 1_000]);
    let s = run_summary(&sc, Arch::Smpa).unwrap();
    // 20 s of walking needs 7 act phases (the last one 2 s), each after a 1 s sense phase:
    // 27 s; then "open door" senses 1 s and acts 1 s; "enter kitchen" runs 1 s.
    assert_eq!(s.time_cost_ms, 30_000);
    assert_eq!(s.tally.on_ms, [7_000, 7_000, 1_000]);
}

#[test]
fn a_box_inside_the_sonar_blind_zone_is_felt_by_the_bumper_under_psmpa_only() {
    let sc = scenario("blind-box");
    let p = run_summary(&sc, Arch::PSmpa).unwrap();
    assert!(
        p.fates.iter().all(|f| *f == Fate::Detected(Device::Bumper)),
        "{:?}",
        p.fates
    );
    let s = run_summary(&sc, Arch::Smpa).unwrap();
    assert!(
        s.fates.iter().all(|f| *f == Fate::Collided),
        "{:?}",
        s.fates
    );
}

#[test]
fn a_far_box_is_seen_once_it_comes_within_the_threshold() {
    let sc = scenario("far-box");
    let rec = run_recorded(&sc, Arch::PSmpa).unwrap();
    assert!(
        rec.summary
            .fates
            .iter()
            .all(|f| *f == Fate::Detected(Device::Sonar))
    );
    // The sonar reports it every sample, but it counts only below the threshold.
    let readings: Vec<u32> = rec
        .trace
        .0
        .iter()
        .filter_map(|(_, e)| match e {
            TraceEvent::Sample {
                value: Value::Mm(mm),
                ..
            } => Some(*mm),
            _ => None,
        })
        .collect();
    assert!(
        readings.iter().any(|&mm| mm > 500 && mm < 2_550),
        "sees the box beyond the threshold"
    );
    assert!(rec.summary.tally.max_reaction_ms.unwrap() < 100);
}

#[test]
fn obstacles_that_come_and_go_inside_act_phases_are_missed_by_smpa() {
    let sc = scenario("transient");
    assert_eq!(run_summary(&sc, Arch::PSmpa).unwrap().tally.detected, 5);
    let s = run_summary(&sc, Arch::Smpa).unwrap().tally;
    assert_eq!((s.detected, s.collisions), (0, 0));
}

/// Reaction latency without noise or dropout is below one sampling period of the sensor that
/// detected the obstacle.
#[test]
fn noise_free_reactions_take_less_than_one_sensor_period() {
    for name in [
        "sonar-6",
        "sonar-7",
        "sonar-8",
        "bumper-4",
        "bumper-5",
        "bumper-6",
        "far-box",
        "blind-box",
        "mixed",
    ] {
        let sc = scenario(name);
        let period = sc.sonar.period_ms.max(sc.bumper_period_ms);
        for arch in Arch::ALL {
            let t = run_summary(&sc, arch).unwrap().tally;
            if let Some(r) = t.max_reaction_ms {
                assert!(r < period, "{name} {arch:?}: {r} ms");
            }
        }
    }
}

/// Sonar and bumper both perceive `path_clear`: a bumper sample saying "free" must not clear a
/// violation the sonar raised (the conjunction of the two decides).
#[test]
fn a_bumper_saying_free_does_not_clear_what_the_sonar_saw() {
    let sc = scenario("sonar-6");
    let rec = run_recorded(&sc, Arch::PSmpa).unwrap();
    let (mut sonar_blocked, mut bumper_samples_while_blocked) = (false, 0);
    let mut events = rec.trace.0.iter().map(|(_, e)| *e).peekable();
    while let Some(e) = events.next() {
        match e {
            TraceEvent::Sample {
                value: Value::Mm(mm),
                ..
            } => sonar_blocked = mm < 500,
            TraceEvent::Sample {
                value: Value::Level(1),
                ..
            } if sonar_blocked => {
                bumper_samples_while_blocked += 1;
                assert!(
                    !matches!(events.peek(), Some(TraceEvent::PreconditionRestored { .. })),
                    "a free bumper restored path_clear while the sonar saw a box"
                );
            }
            _ => {}
        }
    }
    assert!(bumper_samples_while_blocked > 50);
}

#[test]
fn the_run_stops_at_max_s() {
    let mut sc = scenario("quiet");
    sc.max_ms = 5_000;
    let s = run_summary(&sc, Arch::PSmpa).unwrap();
    assert_eq!(s.ending, Ending::TimeLimit);
    assert_eq!(s.time_cost_ms, 5_000);
    assert!(!s.tally.reached_door);
}

/// The trace hash of every shipped scenario under both architectures. A change here is a
/// change of behaviour: update the pins only on purpose.
#[test]
fn trace_hashes_are_pinned() {
    let pins: &[(&str, u64, u64)] = &PINS;
    let mut got = Vec::new();
    for (name, _, _) in pins {
        let sc = scenario(name);
        let p = run_summary(&sc, Arch::PSmpa).unwrap().trace_hash;
        let s = run_summary(&sc, Arch::Smpa).unwrap().trace_hash;
        got.push((*name, p, s));
    }
    let report: Vec<String> = got
        .iter()
        .map(|(n, p, s)| format!("    (\"{n}\", 0x{p:016x}, 0x{s:016x}),"))
        .collect();
    assert_eq!(got.as_slice(), pins, "new hashes:\n{}", report.join("\n"));
}

const PINS: [(&str, u64, u64); 12] = [
    ("sonar-6", 0x447d9c0c11e0c346, 0x33f861fefc906104),
    ("sonar-7", 0x8a41be738c335bb3, 0x48e83dbd143b111c),
    ("sonar-8", 0xec275f30d9403d9c, 0x2f1b77b71b82787f),
    ("bumper-4", 0x4ec6e7001db3fde4, 0xa2521db1a2f5082e),
    ("bumper-5", 0x03b0b5a3625437c8, 0xf9da2d580b784328),
    ("bumper-6", 0x804562c9122ac8ee, 0x4a4c0840cd8673c4),
    ("quiet", 0x1d90bb81e4347192, 0xef7d8c5fb6a48335),
    ("blind-box", 0xa1b4170f48a1f33b, 0x5bb3f2e38c41e3cb),
    ("far-box", 0xa826e5d036d92df9, 0x6152ecd7dfc4a7fe),
    ("transient", 0x5be63e20368da769, 0xc1f3d1e6979d38f5),
    ("noisy-sonar", 0xabd3b3939f3aea65, 0x37e58a17f3afba76),
    ("mixed", 0xa3d588766550fcb4, 0x1e5558a153104b97),
];

#[test]
fn the_same_scenario_gives_the_same_hash_on_parallel_threads() {
    let sc = scenario("noisy-sonar");
    let reference = run_summary(&sc, Arch::PSmpa).unwrap().trace_hash;
    let handles: Vec<_> = (0..8)
        .map(|_| {
            let sc = sc.clone();
            std::thread::spawn(move || run_summary(&sc, Arch::PSmpa).unwrap().trace_hash)
        })
        .collect();
    for h in handles {
        assert_eq!(h.join().unwrap(), reference);
    }
    // The seed matters: another seed, other noise, another trace.
    let mut other = sc;
    other.seed += 1;
    assert_ne!(
        run_summary(&other, Arch::PSmpa).unwrap().trace_hash,
        reference
    );
}

#[test]
fn the_sweep_psmpa_misses_nothing_detectable_and_smpa_misses_much() {
    let stats = sweep::sweep(7, 300, &Arch::ALL, false).unwrap();
    let p = stats.psmpa.unwrap();
    let s = stats.smpa.unwrap();
    assert_eq!(p.scenarios, 300);
    assert!(
        p.detectable > 500,
        "enough detectable obstacles: {}",
        p.detectable
    );
    assert_eq!(p.missed_detectable, 0);
    assert_eq!(p.collisions, 0);
    assert!(
        s.detection_rate() < 0.5 * p.detection_rate(),
        "SMPA {:.2} P-SMPA {:.2}",
        s.detection_rate(),
        p.detection_rate()
    );
    assert!(s.collisions > 100);
    assert!(stats.time_ratio_total.unwrap() > 1.2);
    // Deterministic whatever the thread count.
    let again = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| sweep::sweep(7, 300, &Arch::ALL, false).unwrap());
    assert_eq!(again.psmpa, stats.psmpa);
    assert_eq!(again.smpa, stats.smpa);
}

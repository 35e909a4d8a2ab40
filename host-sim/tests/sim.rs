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
    // Least commitment: sonar and bumper on exactly while walking; camera and handle while
    // opening the door (the handle sample is taken on request, at once).
    assert_eq!(p.tally.on_ms, [20_000, 20_000, 1_000, 1_000]);
    let s = run_summary(&sc, Arch::Smpa).unwrap();
    // 20 s of walking needs 7 act phases (the last one 2 s), each after a 1 s sense phase:
    // 27 s. "open door": sense 1 s (camera), act 3 s (the handle request waits: the sensors are
    // off), sense 1 s (handle sampled), act 1 s (push): 6 s. "enter kitchen" runs 1 s.
    assert_eq!(s.time_cost_ms, 34_000);
    assert_eq!(s.tally.on_ms, [7_000, 7_000, 2_000, 2_000]);
}

#[test]
fn a_box_inside_the_sonar_blind_zone_is_felt_by_the_bumper_under_psmpa_only() {
    let sc = scenario("blind-box");
    let p = run_summary(&sc, Arch::PSmpa).unwrap();
    assert!(
        p.obstacles
            .iter()
            .all(|o| o.fate == Fate::Detected(Device::Bumper)),
        "{:?}",
        p.obstacles
    );
    let s = run_summary(&sc, Arch::Smpa).unwrap();
    assert!(
        s.obstacles.iter().all(|o| o.fate == Fate::Collided),
        "{:?}",
        s.obstacles
    );
}

#[test]
fn a_far_box_is_seen_once_it_comes_within_the_threshold() {
    let sc = scenario("far-box");
    let rec = run_recorded(&sc, Arch::PSmpa).unwrap();
    assert!(
        rec.summary
            .obstacles
            .iter()
            .all(|o| o.fate == Fate::Detected(Device::Sonar))
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
fn noise_free_reactions_take_less_than_one_period_of_the_detecting_sensor() {
    let mut checked = 0;
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
        for arch in Arch::ALL {
            for o in run_summary(&sc, arch).unwrap().obstacles {
                let (Fate::Detected(device), Some(r)) = (o.fate, o.reaction_ms) else {
                    continue;
                };
                let period = match device {
                    Device::Sonar => sc.sonar.period_ms,
                    _ => sc.bumper_period_ms,
                };
                assert!(r < period, "{name} {arch:?} {device:?}: {r} ms");
                checked += 1;
            }
        }
    }
    assert!(checked > 40);
}

/// Every reaction P-SMPA shows, on every shipped scenario and 300 random ones (noise, dropout,
/// obstacles that come and go), is within the bound `psmpa_core::timing` promises: with a
/// response time of 0, as computing takes no virtual time. The bound must also be tight enough
/// to mean something: some reaction comes within 2 periods of it.
#[test]
fn every_psmpa_reaction_is_within_the_latency_bound() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
    let mut scenarios: Vec<Scenario> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| load(&e.unwrap().path()).unwrap())
        .collect();
    scenarios.extend((0..300).map(|i| sweep::scenario(7, i)));
    let (mut checked, mut worst_slack_ns) = (0, u64::MAX);
    for sc in &scenarios {
        let robot = psmpa_sim::robot::fetch_tea(sc).unwrap();
        let bounds = psmpa_sim::robot::latency_bounds(&robot, sc, |_| 0);
        assert_eq!(bounds.len(), 2, "sonar and bumper are cyclic");
        // A box is perceived by both, and the slower one's bound holds for either.
        let bound_ns = bounds.iter().map(|b| b.bound_ns).max().unwrap();
        for o in run_summary(sc, Arch::PSmpa).unwrap().obstacles {
            let (Fate::Detected(_), Some(r)) = (o.fate, o.reaction_ms) else {
                continue;
            };
            let r_ns = r * 1_000_000;
            assert!(r_ns <= bound_ns, "{}: {r} ms > {bound_ns} ns", sc.name);
            worst_slack_ns = worst_slack_ns.min(bound_ns - r_ns);
            checked += 1;
        }
    }
    eprintln!("{checked} reactions, least slack {worst_slack_ns} ns");
    assert!(checked > 500, "{checked}");
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

const PINS: [(&str, u64, u64); 13] = [
    ("sonar-6", 0xb0ddef01d8c25214, 0xdd540fd836957b39),
    ("sonar-7", 0x9f676d516f8319b3, 0x90d3292f5f341c72),
    ("sonar-8", 0xdb9f2dcb255fa40a, 0xb96b354b182e6138),
    ("bumper-4", 0x3edb0ef43ece770c, 0x88b3e0dd273688e3),
    ("bumper-5", 0xccfe2c2abee442a0, 0x01868c71766d1316),
    ("bumper-6", 0x3716d6cd3161204d, 0xef386f7a17e1aca6),
    ("quiet", 0x2b6f443f43a3d9b1, 0xad7d394011a805b6),
    ("blind-box", 0x5a5fd63a87c35dfe, 0xc13eba0ce78a0899),
    ("far-box", 0x61c7ffc7292b90fa, 0x7059694187fe4e51),
    ("transient", 0xcb01099d217d47bf, 0x7236ae7e462dd25e),
    ("noisy-sonar", 0x4b4980071df710c6, 0x0d74c84c1ad3fe0b),
    ("locked-door", 0x6bb16381538a1d62, 0x9b55392e4f7132d3),
    ("mixed", 0x05353d56e803afaf, 0xd66518f0df79d463),
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

/// The kitchen door is locked: "open door" presses the handle (an on-demand sample), the
/// precondition `door_unlocked` fails, the plan fails, and the control loop plans again from
/// the current beliefs: the back door. Run with `--nocapture` to read the trace.
#[test]
fn a_locked_kitchen_door_makes_the_robot_replan_through_the_back_door() {
    use psmpa_core::{Failure, PlanId};
    let sc = scenario("locked-door");
    let robot = psmpa_sim::robot::fetch_tea(&sc).unwrap();
    let d = &robot.mission.domain;
    let open_door = d.action_id("open door").unwrap();
    for arch in Arch::ALL {
        let rec = run_recorded(&sc, arch).unwrap();
        let Ending::Goal(report) = rec.summary.ending else {
            panic!("{arch:?}: {:?}", rec.summary.ending)
        };
        assert_eq!((report.plans_started, report.plans_failed), (2, 1));
        println!("{arch:?}:");
        for (t, e) in &rec.trace.0 {
            if !matches!(
                e,
                TraceEvent::Sample { .. }
                    | TraceEvent::SensorOn { .. }
                    | TraceEvent::SensorOff { .. }
            ) {
                println!(
                    "  {:>8.3} s  {}",
                    t.as_millis() as f64 / 1000.0,
                    psmpa_sim::cli::outputs::describe(&robot.mission, e)
                );
            }
        }
        let plan_events: Vec<TraceEvent> = rec
            .trace
            .0
            .iter()
            .map(|(_, e)| *e)
            .filter(|e| {
                matches!(
                    e,
                    TraceEvent::PlanSelected { .. }
                        | TraceEvent::PlanFailed { .. }
                        | TraceEvent::PlanGenerated { .. }
                        | TraceEvent::PlanSucceeded { .. }
                )
            })
            .collect();
        let first = PlanId::new(0).unwrap();
        assert!(matches!(plan_events[0], TraceEvent::PlanSelected { plan, .. } if plan == first));
        assert_eq!(
            plan_events[1],
            TraceEvent::PlanFailed {
                plan: first,
                reason: Failure::ActionInterrupted { action: open_door }
            }
        );
        assert!(matches!(
            plan_events[2],
            TraceEvent::PlanGenerated { length: 3, .. }
        ));
        assert!(matches!(
            plan_events[3],
            TraceEvent::PlanSelected {
                plan: PlanId::GENERATED,
                ..
            }
        ));
        assert_eq!(
            plan_events[4],
            TraceEvent::PlanSucceeded {
                plan: PlanId::GENERATED
            }
        );
        let states: Vec<&str> = rec
            .trace
            .0
            .iter()
            .filter_map(|(_, e)| match e {
                TraceEvent::StateEntered { action, .. } => Some(d.action(*action).unwrap().name),
                _ => None,
            })
            .collect();
        assert_eq!(
            states,
            [
                "go to door",
                "open door",
                "go to back door",
                "open back door",
                "enter by back door"
            ]
        );
    }
}

#[test]
fn the_simulator_runs_the_mission_from_its_json_file() {
    let robot = psmpa_sim::robot::fetch_tea(&scenario("sonar-6")).unwrap();
    assert_eq!(robot.mission.name, "fetch-tea");
    let d = &robot.mission.domain;
    assert_eq!(d.actions().len(), 6);
    assert_eq!(d.sensors().len(), 4);
    for (i, a) in d.actions().iter().enumerate() {
        assert!(
            robot
                .bindings
                .action(psmpa_core::ActionId::new(i).unwrap())
                .is_some(),
            "{}",
            a.name
        );
    }
    // The scenario's sampling periods replace the file's.
    let mut sc = scenario("sonar-6");
    sc.sonar.period_ms = 37;
    let robot = psmpa_sim::robot::fetch_tea(&sc).unwrap();
    let sonar = robot.mission.domain.sensor_id("sonar").unwrap();
    assert_eq!(
        robot.mission.domain.sensor(sonar).unwrap().mode,
        psmpa_core::SensorMode::Cyclic {
            period: embassy_time::Duration::from_millis(37)
        }
    );
}

fn inline(json: &str) -> Scenario {
    Scenario::parse(json.as_bytes()).unwrap()
}

/// Review findings, kept as regressions.
#[test]
fn a_box_just_below_the_threshold_is_seen_alike_by_world_and_robot() {
    // 0.4996 m rounds to a 500 mm reading: not below the 500 mm threshold, for both.
    let sc = inline(
        r#"{"name":"r","interferences":[{"kind":"box","at_s":4.5,"ahead_m":0.4996,"hold_s":20}]}"#,
    );
    for arch in Arch::ALL {
        let s = run_summary(&sc, arch).unwrap();
        let o = s.obstacles[0];
        // Never registered by a reading the robot takes for clear: either both say "box"
        // (detected) or the robot walks into it with the bumper off (a collision), never a
        // detection the robot did not act on.
        assert!(
            matches!(o.fate, Fate::Detected(_) | Fate::Collided),
            "{arch:?}: {o:?}"
        );
        if let Fate::Detected(Device::Sonar) = o.fate {
            assert!(
                o.reaction_ms.is_some(),
                "{arch:?}: detected but never reacted to"
            );
        }
    }
}

#[test]
fn boxes_put_down_together_are_all_registered_by_one_echo() {
    let items: Vec<String> = (0..8)
        .map(|_| r#"{"kind":"box","at_s":3}"#.to_owned())
        .collect();
    let sc = inline(&format!(
        r#"{{"name":"pile","interferences":[{}]}}"#,
        items.join(",")
    ));
    let s = run_summary(&sc, Arch::PSmpa).unwrap();
    assert_eq!(s.tally.detected, 8);
    assert!(s.tally.max_reaction_ms.unwrap() < sc.sonar.period_ms);
}

#[test]
fn a_ball_lying_at_the_door_is_no_collision_for_psmpa() {
    let sc = inline(
        r#"{"name":"ball-at-door","door_m":2.0,"interferences":[{"kind":"ball","at_s":17,"ahead_m":0.3,"hold_s":30}]}"#,
    );
    let s = run_summary(&sc, Arch::PSmpa).unwrap();
    assert_eq!(s.tally.collisions, 0);
}

#[test]
fn interferences_count_the_scenario_list_even_when_not_all_are_put_down() {
    // The second is due long after the robot reached the door.
    let sc = inline(
        r#"{"name":"late","interferences":[{"kind":"box","at_s":3},{"kind":"box","at_s":500}]}"#,
    );
    let s = run_summary(&sc, Arch::PSmpa).unwrap();
    assert_eq!(
        (s.tally.interferences, s.tally.placed, s.tally.detected),
        (2, 1, 1)
    );
    assert!(!s.obstacles[1].placed);
}

/// A walk towards a box 1.2 m ahead (in the sonar's range, beyond its threshold) during which
/// the sonar fails at 3 s.
fn with_sonar_fault(kind: &str) -> psmpa_sim::sim::Recorded {
    let sc = inline(&format!(
        r#"{{"name":"fault","door_m":3.0,"fault":{{"kind":"{kind}","at_s":3.0}},
            "interferences":[{{"kind":"box","at_s":2.0,"ahead_m":1.2,"hold_s":60}}]}}"#
    ));
    run_recorded(&sc, Arch::PSmpa).unwrap()
}

/// The sonar fault was detected, the action failed safe (the robot never moved again), no plan
/// could run without the sonar, and nothing was hit. Returns when the fault was detected.
fn assert_fails_safe(rec: &psmpa_sim::sim::Recorded, expected: psmpa_core::SensorFault) -> u64 {
    use psmpa_core::Failure;
    use psmpa_sim::world::WorldEvent;
    let detected = rec
        .trace
        .0
        .iter()
        .find_map(|(t, e)| match *e {
            TraceEvent::SensorFailed { fault, .. } => Some((t.as_millis(), fault)),
            _ => None,
        })
        .expect("the fault is noticed");
    assert_eq!(detected.1, expected);
    assert!(rec.trace.0.iter().any(|(_, e)| matches!(
        e,
        TraceEvent::PlanFailed {
            reason: Failure::SensorFault { fault, .. },
            ..
        } if *fault == expected
    )));
    // Fail safe: from the fault on, the robot stands still.
    let positions: Vec<i64> = rec
        .world
        .0
        .iter()
        .filter(|(t, _, _)| *t >= detected.0)
        .map(|(_, p, _)| *p)
        .collect();
    assert!(!positions.is_empty());
    assert!(
        positions.iter().all(|p| *p == positions[0]),
        "moved after the fault"
    );
    assert!(
        rec.world
            .0
            .iter()
            .any(|(t, _, e)| *t == detected.0 && *e == WorldEvent::Stop)
    );
    assert_eq!(rec.summary.tally.collisions, 0);
    // Without a working sonar no plan can monitor path_clear: a clear error, not a hang.
    assert!(
        matches!(
            rec.summary.ending,
            Ending::Error(psmpa_core::ControlError::Planning { .. })
        ),
        "{:?}",
        rec.summary.ending
    );
    detected.0
}

#[test]
fn a_sonar_that_stops_answering_times_out_and_the_robot_stops() {
    let at = assert_fails_safe(
        &with_sonar_fault("silent"),
        psmpa_core::SensorFault::Timeout,
    );
    // The first sample due at or after 3 s never completes; its 50 ms timeout expires.
    assert_eq!(at, 3_050);
}

#[test]
fn a_sonar_reading_beyond_its_range_is_a_fault_and_the_robot_stops() {
    let at = assert_fails_safe(
        &with_sonar_fault("out-of-range"),
        psmpa_core::SensorFault::OutOfRange,
    );
    assert_eq!(at, 3_000);
}

#[test]
fn a_stuck_sonar_is_caught_by_odometry_and_the_robot_stops() {
    let at = assert_fails_safe(&with_sonar_fault("stuck"), psmpa_core::SensorFault::Stuck);
    // The echo stays at one distance while the robot walks 5 cm (0.5 s at 0.1 m/s).
    assert_eq!(at, 3_500);
}

#[test]
fn a_sonar_stuck_while_the_robot_stands_is_not_a_false_alarm() {
    // Standing before a box (side-stepping it), readings repeat: that is no fault.
    let sc = scenario("sonar-6");
    let s = run_summary(&sc, Arch::PSmpa).unwrap();
    assert!(matches!(s.ending, Ending::Goal(_)));
}

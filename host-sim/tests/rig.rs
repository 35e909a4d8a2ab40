//! The one Fetch Tea robot (`psmpa-fetch-tea`) on psmpa-sim's simulated devices: its body in
//! the world moves by its motor pins, its sonar's echo is timed in the world, its switches
//! debounce through the drivers, and SMPA's sense phases hold its wheels.

use std::path::PathBuf;

use psmpa_core::{TraceEvent, Value};
use psmpa_sim::load::{load, parse};
use psmpa_sim::rig::{Chassis, settings_for};
use psmpa_sim::robot::Arch;
use psmpa_sim::run::{Ending, Summary};
use psmpa_sim::scenario::Scenario;
use psmpa_sim::sim::{Setup, TraceRecord, WorldRecord, run_chassis, run_with};
use psmpa_sim::world::{Fate, WorldEvent};

fn scenario(name: &str) -> Scenario {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("../scenarios/{name}.json"));
    load(&path).unwrap()
}

/// `sc` under `setup` to its end, its world's events and its trace recorded.
fn recorded(sc: &Scenario, setup: Setup) -> (Summary, WorldRecord, TraceRecord) {
    run_with(
        sc,
        setup,
        WorldRecord::default(),
        TraceRecord::default(),
        || false,
    )
    .unwrap()
}

/// `arch` on the boards' chassis.
fn wheeled(arch: Arch) -> Setup {
    Setup {
        chassis: Chassis::Wheeled,
        ..Setup::new(arch)
    }
}

fn inline(json: &str) -> Scenario {
    parse(std::path::Path::new("inline.json"), json.as_bytes()).unwrap()
}

#[test]
fn on_an_empty_path_the_robot_drives_its_calibrated_time_pushes_and_enters() {
    let sc = inline(
        r#"{"name": "empty", "door_m": 1.0, "robot": {"speed_mps": 0.1}, "interferences": []}"#,
    );
    let settings = settings_for(&sc, Chassis::Wheeled);
    let (s, world, _) = recorded(&sc, wheeled(Arch::PSmpa));
    assert!(matches!(s.ending, Ending::Goal(_)), "{:?}", s.ending);
    assert!(s.tally.reached_door);
    let at = |want: WorldEvent| {
        world
            .0
            .iter()
            .find(|(_, _, e)| *e == want)
            .map(|(ms, pos, _)| (*ms, *pos))
            .unwrap()
    };
    // 1,000 mm at 100 mm/s less the 2 mm a walk may end short by: 9.98 s of driving from the
    // walk's start; the door within 20 mm.
    let (walked, _) = at(WorldEvent::Walk);
    let (arrived, pos) = at(WorldEvent::Arrived(psmpa_sim::world::Place::KitchenDoor));
    assert_eq!(arrived - walked, 10_000 - 20);
    assert!((pos - 1_000_000).abs() <= 20_000, "{pos}");
    // The handle's switch settles (its debounce time), then the push and the entry are the
    // robot's calibrated drives.
    let (opened, _) = at(WorldEvent::DoorOpened(psmpa_sim::world::Place::KitchenDoor));
    let (entered, _) = at(WorldEvent::InKitchen);
    let settle = psmpa_drivers::switch::DEBOUNCE.as_millis();
    assert_eq!(opened - arrived, settle + settings.push.as_millis());
    assert_eq!(entered - opened, settings.enter.as_millis());
}

#[test]
fn smpa_sense_phases_hold_the_wheels_and_do_not_count_as_driven() {
    // Sensing 1 s in every 4: a robot that counted held time as driven would stop a quarter
    // short of the door and fail to open it.
    let sc = inline(
        r#"{"name": "held", "door_m": 1.0, "robot": {"speed_mps": 0.1}, "interferences": []}"#,
    );
    let (s, world, _) = recorded(&sc, wheeled(Arch::Smpa));
    assert!(s.tally.reached_door, "{:?}", s.ending);
    assert!(
        matches!(s.ending, Ending::Goal(r) if r.plans_failed == 0),
        "{:?}",
        s.ending
    );
    // The wheels stop at every sense phase: the walk is cut into stretches.
    let stops = world
        .0
        .iter()
        .filter(|(_, _, e)| *e == WorldEvent::Stop)
        .count();
    assert!(stops >= 3, "{stops} stops");
}

#[test]
fn the_sonar_reads_the_box_at_its_distance_through_the_drivers_conversion() {
    // A box 0.45 m ahead from the start; the robot's first reading of it.
    let sc = inline(
        r#"{"name": "box", "door_m": 3.0, "robot": {"speed_mps": 0.1},
            "interferences": [{"kind": "box", "at_s": 0.0, "ahead_m": 0.45, "hold_s": 30.0}]}"#,
    );
    let (_, _, trace) = run_with(
        &sc,
        wheeled(Arch::PSmpa),
        (),
        TraceRecord::default(),
        || false,
    )
    .unwrap();
    let sonar = psmpa_fetch_tea::fetch_tea::Sensor::Sonar.id();
    let first = trace
        .0
        .iter()
        .find_map(|(_, e)| match e {
            TraceEvent::Sample { sensor, value, .. } if *sensor == sonar => Some(*value),
            _ => None,
        })
        .unwrap();
    // Before the walk starts: the box is 450 mm away; the echo's width reads back its mm.
    assert_eq!(first, Value::Mm(450));
}

#[test]
fn under_psmpa_every_obstacle_of_the_paper_scenarios_is_detected_without_a_collision() {
    for name in [
        "sonar-6", "sonar-7", "sonar-8", "bumper-4", "bumper-5", "bumper-6",
    ] {
        let s = run_chassis(&scenario(name), Arch::PSmpa, Chassis::Wheeled).unwrap();
        assert!(
            matches!(s.ending, Ending::Goal(_)),
            "{name}: {:?}",
            s.ending
        );
        assert_eq!(s.tally.collisions, 0, "{name}");
        assert!(
            s.obstacles
                .iter()
                .all(|o| matches!(o.fate, Fate::Detected(_))),
            "{name}: {:?}",
            s.obstacles
        );
    }
}

#[test]
fn a_run_is_deterministic() {
    let sc = scenario("mixed");
    for arch in Arch::ALL {
        let a = run_chassis(&sc, arch, Chassis::Wheeled).unwrap();
        let b = run_chassis(&sc, arch, Chassis::Wheeled).unwrap();
        assert_eq!(a, b);
    }
}

/// The body plays the scenario's bumper latency (the bench's world is this body): a contact
/// shows on the switch's pin that much later, and the robot reacts that much later.
#[test]
fn the_bumpers_latency_delays_its_contact_on_the_pin() {
    let with = |latency_ms: u32| {
        inline(&format!(
            r#"{{"name": "late", "door_m": 3.0, "robot": {{"speed_mps": 0.1}},
                "bumper": {{"latency_ms": {latency_ms}}},
                "interferences": [{{"kind": "ball", "at_s": 1.0, "ahead_m": 0.05, "hold_s": 5.0}}]}}"#
        ))
    };
    let reaction = |latency_ms| {
        let s = run_chassis(&with(latency_ms), Arch::PSmpa, Chassis::Wheeled).unwrap();
        let o = s.obstacles[0];
        assert_eq!(o.fate, Fate::Detected(psmpa_sim::world::Device::Bumper));
        o.reaction_ms.unwrap()
    };
    assert_eq!(reaction(30), reaction(0) + 30);
}

/// The sonar switched off mid-echo (the door turned out locked) and on again 5 ms later: its
/// module's 38 ms no-echo pulse is still running. The read waits it out and measures, as the
/// driver does; it does not lose the sample (and the walk does not start on the last belief).
#[test]
fn a_sonar_switched_on_during_its_last_pulse_waits_it_out_and_reads() {
    let (_, _, trace) = recorded(&scenario("locked-door"), Setup::new(Arch::PSmpa));
    let sonar = psmpa_fetch_tea::fetch_tea::Sensor::Sonar.id();
    let lost = trace
        .0
        .iter()
        .filter(|(_, e)| matches!(e, TraceEvent::SampleLost { sensor } if *sensor == sonar))
        .count();
    assert_eq!(lost, 0);
}

/// The NAO's body counts its way by what it rolled (an encoder, `Motor::rolled_um`): pushed
/// against balls through SMPA's blind act phases (`bumper-4`, 2 collisions), its walk still
/// ends at the door, and the one plan succeeds. Counted by wheel time instead, the pushing
/// would count as way made: the walk would stop short and the plan fail at the door.
#[test]
fn the_naos_walk_counts_what_it_rolled_not_what_it_pushed() {
    let sc = scenario("bumper-4");
    let (s, world, trace) = recorded(&sc, Setup::new(Arch::Smpa));
    assert!(s.tally.collisions > 0, "the robot pushed against something");
    let (_, pos, _) = world
        .0
        .iter()
        .find(|(_, _, e)| *e == WorldEvent::Arrived(psmpa_sim::world::Place::KitchenDoor))
        .expect("the walk reached the door");
    assert!(
        (pos - sc.door_um).abs() <= 20_000,
        "{pos} against {}",
        sc.door_um
    );
    let failed = trace
        .0
        .iter()
        .filter(|(_, e)| matches!(e, TraceEvent::PlanFailed { .. }))
        .count();
    assert_eq!(failed, 0);
    assert!(s.tally.reached_door);
}

//! The world's optional hazards, each on a case with a known answer: a person walking into the
//! robot's path, a sonar cone that misses low boxes close by, and a bumper that needs a
//! minimum contact. With them P-SMPA can fail, so its detections are measured, not given.

use psmpa_sim::robot::Arch;
use psmpa_sim::scenario::Scenario;
use psmpa_sim::sim::{run_recorded, run_summary};
use psmpa_sim::world::{Device, Fate, WorldEvent};

fn inline(json: &str) -> Scenario {
    Scenario::parse(json.as_bytes()).unwrap()
}

/// The instant of the first world event `e`.
fn when(rec: &psmpa_sim::sim::Recorded, e: WorldEvent) -> Option<u64> {
    rec.world
        .0
        .iter()
        .find(|(_, _, x)| *x == e)
        .map(|(t, _, _)| *t)
}

/// A person walking at 8 m/s towards a robot walking at 0.1 m/s closes 8.1 mm a millisecond:
/// the sonar's band from 0.5 m down to its 0.25 m minimum takes 31 ms, a third of its
/// 100 ms period. The person sets off as the sonar triggers, at 10.042 s; it triggers again at
/// 10.142 s and 10.242 s.
fn runner(ahead_m: f64) -> Scenario {
    inline(&format!(
        r#"{{"name":"runner","door_m":3.0,"interferences":[
             {{"kind":"box","at_s":10.042,"ahead_m":{ahead_m},"hold_s":4.0,"speed_mps":8.0}}]}}"#
    ))
}

#[test]
fn a_person_is_seen_when_a_sample_falls_in_the_band_and_hits_the_robot_when_none_does() {
    // 2.0 m ahead: 1,190 mm at 10.142 s, 380 mm at 10.242 s, in the band.
    let seen = run_recorded(&runner(2.0), Arch::PSmpa).unwrap();
    assert_eq!(
        seen.summary.obstacles[0].fate,
        Fate::Detected(Device::Sonar)
    );
    assert_eq!(seen.summary.tally.collisions, 0);
    // 1.7 m ahead: 890 mm at 10.142 s, then it reaches the robot within ⌈890 / 8.1⌉ = 110 ms,
    // the next read finding it below the band: the bumper is on, but the person hit the robot.
    let hit = run_recorded(&runner(1.7), Arch::PSmpa).unwrap();
    assert_eq!(hit.summary.obstacles[0].fate, Fate::Collided);
    assert_eq!(when(&hit, WorldEvent::Collided(0)), Some(10_252));
    // The person stands against the robot: the bump switch feels them once it settles, and
    // the robot steps aside.
    let settle = psmpa_drivers::switch::DEBOUNCE.as_millis();
    assert_eq!(
        when(&hit, WorldEvent::AvoidStarted(Some(0))),
        Some(10_252 + settle)
    );
    assert!(hit.summary.tally.reached_door);
}

#[test]
fn a_slow_person_is_seen_by_the_sonar_whatever_the_phase() {
    // 0.6 mm a millisecond: 417 ms in the band, four samples at least.
    for at_s in [2.0, 2.03, 2.05, 2.07] {
        let sc = inline(&format!(
            r#"{{"name":"walker","door_m":3.0,"interferences":[
                 {{"kind":"box","at_s":{at_s},"ahead_m":1.5,"hold_s":6.0,"speed_mps":0.5}}]}}"#
        ));
        let s = run_summary(&sc, Arch::PSmpa).unwrap();
        assert_eq!(s.obstacles[0].fate, Fate::Detected(Device::Sonar), "{at_s}");
    }
}

/// A sonar 0.5 m high whose cone drops 0.5 m a metre sees a box `height_m` high from
/// `(0.5 - height_m) / 0.5` m on: 0.3 m high from 0.4 m, 0.1 m high from 0.8 m.
fn low_box(height_m: f64, ahead_m: f64) -> Fate {
    let sc = inline(&format!(
        r#"{{"name":"low","sonar":{{"height_m":0.5,"cone_slope":0.5}},"interferences":[
             {{"kind":"box","at_s":3.0,"ahead_m":{ahead_m},"hold_s":20.0,"height_m":{height_m}}}]}}"#
    ));
    run_summary(&sc, Arch::PSmpa).unwrap().obstacles[0].fate
}

#[test]
fn a_low_box_close_by_is_below_the_cone_and_left_to_the_bumper() {
    // As high as the sonar: seen anywhere in its range.
    assert_eq!(low_box(0.5, 0.35), Fate::Detected(Device::Sonar));
    // 0.3 m high: seen from 0.4 m, so 0.45 m ahead it is seen; 0.35 m ahead it is not.
    assert_eq!(low_box(0.3, 0.45), Fate::Detected(Device::Sonar));
    assert_eq!(low_box(0.3, 0.35), Fate::Detected(Device::Bumper));
    // 0.1 m high: seen from 0.8 m, beyond the 0.5 m threshold: never registered by the sonar.
    assert_eq!(low_box(0.1, 0.45), Fate::Detected(Device::Bumper));
    // Under SMPA the walk runs with the bumper off: the same box is walked into.
    let sc = inline(
        r#"{"name":"low","sonar":{"height_m":0.5,"cone_slope":0.5},"interferences":[
             {"kind":"box","at_s":3.0,"ahead_m":0.35,"hold_s":20.0,"height_m":0.1}]}"#,
    );
    let s = run_summary(&sc, Arch::Smpa).unwrap();
    assert_eq!(s.obstacles[0].fate, Fate::Collided);
}

#[test]
fn the_cone_slope_is_kept_to_the_millionth() {
    // A sonar 0.5 m high sees a box on the floor from 0.5 m / slope on, in whole µm rounded
    // up: with a slope of 0.0019 from 263.157895 m; it was kept as 0.001, seen from 500 m.
    let seen_from = |slope: &str| {
        let sc = inline(&format!(
            r#"{{"name":"c","sonar":{{"height_m":0.5,"cone_slope":{slope}}},"interferences":[]}}"#
        ));
        sc.sonar.seen_from_um(0)
    };
    assert_eq!(seen_from("0.0019"), 263_157_895);
    assert_eq!(seen_from("0.001"), 500_000_000);
    // tan 30°, to six decimals: the harder world's kind of cone.
    assert_eq!(seen_from("0.57735"), 866_026);
    // Three decimals or fewer, as before.
    assert_eq!(seen_from("0.5"), 1_000_000);
}

/// A ball put down under the walking robot's foot at 3.0 s and taken away `hold_s` later,
/// with a 20 ms bumper that feels a contact once it lasted `min_contact_ms`.
fn ball_underfoot(hold_s: f64, min_contact_ms: u32) -> psmpa_sim::sim::Recorded {
    let sc = inline(&format!(
        r#"{{"name":"underfoot","bumper":{{"min_contact_ms":{min_contact_ms}}},"interferences":[
             {{"kind":"ball","at_s":3.0,"ahead_m":0.0,"hold_s":{hold_s}}}]}}"#
    ));
    run_recorded(&sc, Arch::PSmpa).unwrap()
}

#[test]
fn a_touch_shorter_than_the_bumpers_minimum_contact_is_a_collision() {
    // 30 ms of contact: a 20 ms bumper samples it at least once.
    let felt = ball_underfoot(0.03, 0);
    assert_eq!(
        felt.summary.obstacles[0].fate,
        Fate::Detected(Device::Bumper)
    );
    // Needing 50 ms of contact, it never feels those 30 ms: touched and gone unregistered.
    let missed = ball_underfoot(0.03, 50);
    assert_eq!(missed.summary.obstacles[0].fate, Fate::Collided);
    assert_eq!(when(&missed, WorldEvent::Collided(0)), Some(3_030));
    // Held long enough, it is felt once the contact has lasted 50 ms, at the next sample.
    let held = ball_underfoot(1.0, 50);
    let t = when(&held, WorldEvent::Detected(0, Device::Bumper)).unwrap();
    assert!((3_050..3_070).contains(&t), "{t}");
}

#[test]
fn the_hazards_are_rejected_out_of_range_with_their_field_named() {
    for (json, message) in [
        (
            r#"{"name":"x","interferences":[{"speed_mps":11}]}"#,
            "interferences[0].speed_mps: must lie between 0 and 10, got 11",
        ),
        (
            r#"{"name":"x","interferences":[{},{"height_m":-0.1}]}"#,
            "interferences[1].height_m: must not be negative, got -0.1",
        ),
        (
            r#"{"name":"x","sonar":{"cone_slope":101},"interferences":[]}"#,
            "sonar.cone_slope: must lie between 0 and 100, got 101",
        ),
        (
            r#"{"name":"x","sonar":{"height_m":10.5},"interferences":[]}"#,
            "sonar.height_m: must lie between 0 and 10, got 10.5",
        ),
        (
            r#"{"name":"x","bumper":{"min_contact_ms":2.5},"interferences":[]}"#,
            "bumper.min_contact_ms: must be a whole number of milliseconds from 0 to 1000, got 2.5",
        ),
    ] {
        let e = Scenario::parse(json.as_bytes()).unwrap_err();
        assert_eq!(e.to_string(), message, "{json}");
    }
}

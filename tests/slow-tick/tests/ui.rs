//! At 10 Hz a mission's milliseconds must be whole tenths of a second (within 1 %).

use std::path::Path;

#[test]
fn a_period_the_tick_rate_cannot_represent_fails_the_build() {
    assert_eq!(embassy_time_driver::TICK_HZ, 10);
    // trybuild builds each case in `<target>/tests/trybuild/slow-tick`, where a mission path
    // is resolved: its mission goes there.
    let project = Path::new(env!("CARGO_TARGET_TMPDIR")).join("../tests/trybuild/slow-tick");
    std::fs::create_dir_all(&project).unwrap();
    std::fs::copy("ui/fast-bumper.json", project.join("fast-bumper.json")).unwrap();
    trybuild::TestCases::new().compile_fail("ui/*.rs");
}

#[test]
fn a_mission_of_whole_ticks_compiles() {
    assert_eq!(slow_tick::slow::Sensor::Bumper.name(), "bumper");
}

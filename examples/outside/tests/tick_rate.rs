//! The dock robot's mission at this crate's tick rate, in virtual time.

use embassy_time::Duration;
use psmpa_core::{Config, TraceEvent};
use psmpa_dock::{Dock, DockRuntime, Yard};
use psmpa_testkit::{Recorder, simulate};

#[test]
fn the_kit_runs_a_mission_at_the_crates_own_tick_rate() {
    assert_eq!(embassy_time_driver::TICK_HZ, 32_768);
    let yard = Yard::new().with_box(2_000, 3_000);
    let dock = Dock { yard: &yard };
    let mut rt = DockRuntime::new(
        psmpa_dock::dock::Dock,
        &dock,
        Recorder::default(),
        Config::default(),
    );
    let done = simulate(rt.run_with_sensing(), Duration::from_secs(60)).unwrap();
    assert!(done.output.is_ok(), "{:?}", done.output);
    let trace = rt.into_sink();
    let seen = trace
        .first(|e| matches!(e, TraceEvent::PreconditionViolated { .. }))
        .unwrap();
    // The box is seen within a ranger period and read (130 ms), in ticks of 1/32,768 s.
    assert!(
        seen.as_ticks() >= 2 * 32_768 && seen.as_millis() <= 2_130,
        "{seen:?}"
    );
}

#[test]
fn a_mission_compiled_in_is_the_loaded_one_at_this_tick_rate() {
    use outside::dock;
    // Durations are ticks of 1/32,768 s here: the compiled periods and timeouts round as the
    // loader's do.
    use psmpa_core::mission::{AnyBehaviour, Loaded, load};
    let loaded: Loaded<
        '_,
        (),
        (),
        { dock::NS },
        { dock::NA },
        { dock::NP },
        { dock::L },
        { dock::W },
        { dock::NF },
    > = load(include_bytes!("../../dock/mission.json"), &AnyBehaviour).unwrap();
    assert_eq!(loaded.mission, dock::TABLES);
    let tof = dock::Sensor::Tof;
    let spec = dock::TABLES.domain.sensor(tof.id()).unwrap();
    assert_eq!(spec.name, "tof");
}

//! The dock robot in virtual time, with the test kit.

use embassy_time::Duration;
use psmpa_core::{Config, ControlError, Report, SensorSet, TraceEvent};
use psmpa_dock::dock::{Action, Plan, Sensor};
use psmpa_dock::{DOCK_MM, Dock, DockRuntime, NEAR_MM, TOF_LATENCY, Yard};
use psmpa_testkit::{Recorder, simulate};

const LIMIT: Duration = Duration::from_secs(120);
const TOF_PERIOD_MS: u64 = 100;

/// Runs the mission in `yard`: how it ended, and the trace.
fn run(
    yard: &Yard,
) -> (
    Result<Report, ControlError>,
    Recorder<psmpa_dock::dock::Dock>,
) {
    let dock = Dock { yard };
    let mut rt = DockRuntime::new(
        psmpa_dock::dock::Dock,
        &dock,
        Recorder::default(),
        Config::default(),
    );
    let done = simulate(rt.run_with_sensing(), LIMIT).unwrap();
    (done.output, rt.into_sink())
}

#[test]
fn docks_driving_with_a_good_battery_and_creeping_with_a_low_one() {
    for (battery, plan, mm_s) in [(90, Plan::DriveIn, 300), (20, Plan::CreepIn, 100)] {
        let yard = Yard::new().with_battery(battery);
        let (result, trace) = run(&yard);
        assert!(result.is_ok(), "{result:?}");
        assert_eq!(trace.plans_selected::<Plan>(), [plan]);
        // The approach takes its distance at its speed; aligning 0.5 s, connecting 0.3 s.
        let goal = trace.first(|e| matches!(e, TraceEvent::GoalReached { .. }));
        let approach_ms = ((DOCK_MM - NEAR_MM) as u64 * 1_000).div_ceil(mm_s);
        let at = goal.unwrap().as_millis();
        assert!(
            (approach_ms + 800..approach_ms + 800 + 200).contains(&at),
            "battery {battery}: docked at {at} ms"
        );
        assert_eq!(yard.position_mm(), DOCK_MM - NEAR_MM);
    }
}

#[test]
fn a_box_stops_the_drive_within_one_ranger_period_and_the_robot_docks_after_it() {
    let (from, to) = (2_000, 4_000);
    let yard = Yard::new().with_box(from, to);
    let (result, trace) = run(&yard);
    assert!(result.is_ok(), "{result:?}");
    let violated = trace
        .first(|e| {
            matches!(e, TraceEvent::PreconditionViolated { .. })
                && e.action() == Some(Action::Drive.id())
        })
        .unwrap()
        .as_millis();
    let restored = trace
        .first(|e| matches!(e, TraceEvent::PreconditionRestored { .. }))
        .unwrap()
        .as_millis();
    // The first read that starts after the box appears sees it; it takes the ranger's latency.
    let within = TOF_PERIOD_MS + TOF_LATENCY.as_millis();
    assert!((from..=from + within).contains(&violated), "{violated}");
    assert!((to..=to + within).contains(&restored), "{restored}");
    // Stopped while the box stood there: the whole approach is late by about as long.
    let goal = trace
        .first(|e| matches!(e, TraceEvent::GoalReached { .. }))
        .unwrap()
        .as_millis();
    assert!(goal >= 9_334 + 800 + (restored - violated), "{goal}");
}

#[test]
fn a_cliff_stops_the_robot_at_the_edge_and_ends_the_mission_with_an_error() {
    let yard = Yard::new().with_cliff(1_500);
    let (result, trace) = run(&yard);
    // The drive failed after its 3 s of tolerance; the only other plan needs a low battery.
    assert!(
        matches!(result, Err(ControlError::Exhausted { .. })),
        "{result:?}"
    );
    // Braked within one cliff period (20 ms at 300 mm/s: 6 mm) of the edge.
    let pos = yard.position_mm();
    assert!((1_500..=1_506).contains(&pos), "stopped at {pos} mm");
    // The drive starts once the ranger's first read is in; it reaches the edge 5 s later, and
    // the next cliff sample (20 ms) sees it.
    let entered = trace
        .first(|e| matches!(e, TraceEvent::StateEntered { .. }))
        .unwrap();
    let seen = trace
        .first(|e| matches!(e, TraceEvent::PreconditionViolated { .. }))
        .unwrap();
    let edge = entered + TOF_LATENCY + Duration::from_millis(5_000);
    assert!(
        seen >= edge && seen <= edge + Duration::from_millis(20),
        "{seen:?}"
    );
}

#[test]
fn each_state_runs_exactly_the_sensors_its_precondition_needs() {
    let (result, trace) = run(&Yard::new());
    assert!(result.is_ok());
    assert_eq!(
        trace.states_entered::<Action, Sensor>(),
        [
            (Action::Drive, vec![Sensor::Tof, Sensor::Cliff]),
            (Action::Align, vec![Sensor::Camera]),
            (Action::Connect, vec![]),
        ]
    );
    // After the initial model, a sensor is on only inside a state that needs it.
    let mut on = SensorSet::EMPTY;
    let mut needed = SensorSet::EMPTY;
    let model = trace
        .events
        .iter()
        .position(|(_, e)| matches!(e, TraceEvent::ModelEstablished { .. }))
        .unwrap();
    for (at, e) in &trace.events[model..] {
        match *e {
            TraceEvent::StateEntered { sensors, .. } => needed = sensors,
            TraceEvent::StateLeft { .. } => needed = SensorSet::EMPTY,
            TraceEvent::SensorOn { sensor } => on = on.with(sensor),
            TraceEvent::SensorOff { sensor } => on = on.without(sensor),
            TraceEvent::Sample { sensor, .. } => {
                assert!(
                    needed.contains(sensor),
                    "{sensor:?} sampled at {at:?} outside its state"
                )
            }
            _ => {}
        }
        assert_eq!(
            on.bits() & !needed.bits(),
            0,
            "a sensor on at {at:?} that no state needs"
        );
    }
}

/// Algorithm 2 at build time against Algorithm 2 at run time: the mission's plans from their
/// constant states and through the run-time FSM give the same run, event by event, in every yard of these tests.
#[test]
fn the_constant_states_and_the_run_time_fsm_run_alike() {
    let yards: [fn() -> Yard; 4] = [
        Yard::new,
        || Yard::new().with_battery(20),
        || Yard::new().with_box(2_000, 4_000),
        || Yard::new().with_cliff(1_500),
    ];
    for (i, yard) in yards.iter().enumerate() {
        let with = |plans| {
            let yard = yard();
            let dock = Dock { yard: &yard };
            let mut config = Config::default();
            config.plans = plans;
            let mut rt =
                DockRuntime::new(psmpa_dock::dock::Dock, &dock, Recorder::default(), config);
            let done = simulate(rt.run_with_sensing(), LIMIT).unwrap();
            (done.output, rt.into_sink().events)
        };
        let compiled = with(psmpa_core::Plans::Compiled);
        assert!(compiled.1.len() > 10, "yard {i}: a run");
        assert_eq!(compiled, with(psmpa_core::Plans::RunTime), "yard {i}");
    }
}

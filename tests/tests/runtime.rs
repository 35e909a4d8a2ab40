//! End-to-end behaviour of the core runtime on the tiny world, in virtual time.

use embassy_time::{Duration, Instant};
use psmpa_core::{
    ControlError, DataStore, Describe, Failure, Policy, SensorSet, StoreAccess, TraceEvent, Value,
};
use psmpa_testkit::simulate_split;
use psmpa_tests::tiny::{self, Ids, Note, SMPA, TinyWorld};

const LIMIT: Duration = Duration::from_secs(600);

struct Run {
    result: Result<psmpa_core::Report, ControlError>,
    trace: Vec<(Instant, TraceEvent)>,
    hash: u64,
    notes: Vec<Note>,
    elapsed: Duration,
}

fn run_with(
    policy: Policy,
    windows: &[(u64, u64)],
    failing_plan: bool,
    tweak: impl FnOnce(&mut TinyWorld),
) -> Run {
    let (mission, ids) = tiny::mission(failing_plan);
    let mut world = TinyWorld::new(ids, windows);
    tweak(&mut world);
    run_on(&mission, &world, policy)
}

/// Runs `mission` on `world` under `policy` to its end.
fn run_on(mission: &tiny::TinyMission, world: &TinyWorld, policy: Policy) -> Run {
    let mut rt: tiny::TinyRuntime<'_> = tiny::runtime(mission, world, tiny::config(policy));
    let (mut sensing, mut deciding) = rt.split();
    let done = simulate_split(sensing.run(), deciding.run(), LIMIT).expect("simulation completes");
    let hash = rt.trace_hash().value();
    Run {
        result: done.output,
        trace: rt.into_sink().events,
        hash,
        notes: world.notes(),
        elapsed: done.elapsed,
    }
}

fn run(policy: Policy, windows: &[(u64, u64)]) -> Run {
    run_with(policy, windows, false, |_| {})
}

fn ids() -> Ids {
    tiny::mission(false).1
}

#[test]
fn mission_reaches_the_goal_in_the_expected_virtual_time() {
    let r = run(Policy::PSmpa, &[]);
    let report = r.result.unwrap();
    assert_eq!(report.plans_started, 1);
    assert_eq!(report.plans_failed, 0);
    // 2 m at 0.2 m/s, then 0.5 s to open the door.
    assert_eq!(r.elapsed, Duration::from_millis(10_500));
    assert!(matches!(
        r.trace.last(),
        Some((_, TraceEvent::GoalReached { .. }))
    ));
}

/// Least commitment: a sensor is on only inside a state whose action needs it (`per(s) ⊆
/// pre(a)`), apart from the one sample of each sensor that establishes the initial model.
#[test]
fn sensors_are_on_only_during_the_actions_that_need_them() {
    let ids = ids();
    for policy in [Policy::PSmpa, SMPA] {
        let r = run(policy, &[(3_000, 4_000)]);
        r.result.unwrap();
        let mut established = false;
        let mut state_sensors: Option<SensorSet> = None;
        let mut on = SensorSet::EMPTY;
        let mut on_per_action = [SensorSet::EMPTY; 4];
        let mut current_action = None;
        for (_, e) in &r.trace {
            match *e {
                TraceEvent::ModelEstablished { .. } => {
                    assert!(on.is_empty());
                    established = true;
                }
                TraceEvent::StateEntered {
                    action, sensors, ..
                } => {
                    state_sensors = Some(sensors);
                    current_action = Some(action);
                }
                TraceEvent::StateLeft { .. } => {
                    assert!(
                        on.is_empty(),
                        "{policy:?}: sensors still on when the action ended"
                    );
                    state_sensors = None;
                }
                TraceEvent::SensorOn { sensor } => {
                    if established {
                        let allowed = state_sensors.expect("sensor on outside a state");
                        assert!(
                            allowed.contains(sensor),
                            "{policy:?}: sensor {sensor:?} on for a state that does not need it"
                        );
                        let a = current_action.unwrap().index();
                        on_per_action[a] = on_per_action[a].with(sensor);
                    }
                    on = on.with(sensor);
                }
                TraceEvent::SensorOff { sensor } => on = on.without(sensor),
                _ => {}
            }
        }
        assert_eq!(
            on_per_action[ids.walk.index()],
            SensorSet::EMPTY.with(ids.range)
        );
        assert_eq!(
            on_per_action[ids.open.index()],
            SensorSet::EMPTY.with(ids.camera)
        );
    }
}

/// Algorithm 3: every value the walking behaviour read from its mutual store is the latest
/// sample its range sensor wrote before that instant.
#[test]
fn the_actuator_reads_what_its_sensor_wrote_through_the_mutual_store() {
    let ids = ids();
    let r = run(Policy::PSmpa, &[(2_050, 2_730), (6_000, 6_400)]);
    r.result.unwrap();
    let samples: Vec<(Instant, Value)> = r
        .trace
        .iter()
        .filter_map(|(t, e)| match *e {
            TraceEvent::Sample { sensor, value, .. } if sensor == ids.range => Some((*t, value)),
            _ => None,
        })
        .collect();
    let reads: Vec<(Instant, Option<Value>)> = r
        .notes
        .iter()
        .filter_map(|n| match *n {
            Note::ReadRange(t, v) => Some((t, v)),
            _ => None,
        })
        .collect();
    assert!(
        reads.len() > 20,
        "the behaviour woke on samples: {} reads",
        reads.len()
    );
    let mut saw_obstacle = false;
    for (t, v) in reads {
        let latest = samples
            .iter()
            .rev()
            .find(|(st, _)| *st <= t)
            .map(|(_, v)| *v);
        assert_eq!(v, latest, "read at {t:?}");
        saw_obstacle |= v == Some(Value::Mm(300));
    }
    assert!(saw_obstacle);
}

/// The behaviour learns of a violated precondition within one sensor period.
#[test]
fn a_precondition_violation_reaches_the_behaviour_within_one_sensor_period() {
    for appear in [1_234u64, 3_000, 5_001, 7_099] {
        let r = run(Policy::PSmpa, &[(appear, appear + 1_000)]);
        r.result.unwrap();
        let stopped: Vec<Instant> = r
            .notes
            .iter()
            .filter_map(|n| match *n {
                Note::Stopped(t) => Some(t),
                _ => None,
            })
            .collect();
        assert_eq!(stopped.len(), 1, "obstacle at {appear} ms");
        let latency = stopped[0] - Instant::from_millis(appear);
        assert!(
            latency <= tiny::RANGE_PERIOD,
            "obstacle at {appear} ms seen after {} ms",
            latency.as_millis()
        );
        let violated_at = r
            .trace
            .iter()
            .find(|(_, e)| matches!(e, TraceEvent::PreconditionViolated { .. }))
            .map(|(t, _)| *t)
            .unwrap();
        assert_eq!(violated_at, stopped[0], "told at the instant of the sample");
    }
}

/// An obstacle that comes and goes inside an SMPA act phase (1-4 s, sensors off) is never
/// seen by SMPA; P-SMPA, sensing while walking, sees it and stops.
#[test]
fn a_transient_event_during_an_act_phase_is_missed_by_smpa_and_caught_by_psmpa() {
    let window = [(1_500, 2_500)];
    let violations = |r: &Run| {
        r.trace
            .iter()
            .filter(|(_, e)| matches!(e, TraceEvent::PreconditionViolated { .. }))
            .count()
    };
    let p = run(Policy::PSmpa, &window);
    let s = run(SMPA, &window);
    p.result.unwrap();
    s.result.unwrap();
    assert_eq!(violations(&p), 1);
    assert!(p.notes.iter().any(|n| matches!(n, Note::Stopped(_))));
    assert_eq!(violations(&s), 0);
    assert!(!s.notes.iter().any(|n| matches!(n, Note::Stopped(_))));
    // SMPA stands still a quarter of the time: it takes longer than P-SMPA even though
    // P-SMPA stopped for the obstacle.
    assert!(
        s.elapsed > p.elapsed,
        "smpa {:?} psmpa {:?}",
        s.elapsed,
        p.elapsed
    );
}

/// Under SMPA the sensors are on exactly during sense phases and the robot is held then.
#[test]
fn smpa_alternates_sense_and_act_phases_of_the_configured_lengths() {
    let ids = ids();
    let s = run(SMPA, &[]);
    s.result.unwrap();
    let walk_phases: Vec<(Instant, psmpa_core::Phase)> = s
        .trace
        .iter()
        .filter_map(|(t, e)| match *e {
            TraceEvent::PhaseStarted { action, phase } if action == ids.walk => Some((*t, phase)),
            _ => None,
        })
        .collect();
    assert!(walk_phases.len() >= 6);
    for pair in walk_phases.windows(2) {
        let dt = pair[1].0 - pair[0].0;
        match pair[0].1 {
            psmpa_core::Phase::Sense => assert_eq!(dt, Duration::from_secs(1)),
            psmpa_core::Phase::Act => assert_eq!(dt, Duration::from_secs(3)),
        }
    }
    // 10 s of walking in 3 s act phases needs 4 sense phases: 14 s, then the door.
    assert_eq!(s.elapsed, Duration::from_millis(14_000 + 1_000 + 500));
}

#[test]
fn a_failed_plan_leads_to_reselection_of_another_plan() {
    let r = run_with(Policy::PSmpa, &[], true, |_| {});
    let report = r.result.unwrap();
    assert_eq!((report.plans_started, report.plans_failed), (2, 1));
    let plan_events: Vec<TraceEvent> = r
        .trace
        .iter()
        .map(|(_, e)| *e)
        .filter(|e| {
            matches!(
                e,
                TraceEvent::PlanSelected { .. }
                    | TraceEvent::PlanFailed { .. }
                    | TraceEvent::PlanSucceeded { .. }
            )
        })
        .collect();
    let ids = ids();
    let p0 = psmpa_core::PlanId::new(0).unwrap();
    let p1 = psmpa_core::PlanId::new(1).unwrap();
    let ev = psmpa_core::EventId::new(0).unwrap();
    assert_eq!(
        plan_events,
        [
            TraceEvent::PlanSelected {
                plan: p0,
                event: ev
            },
            TraceEvent::PlanFailed {
                plan: p0,
                reason: Failure::ActionFailed {
                    action: ids.stumble
                }
            },
            TraceEvent::PlanSelected {
                plan: p1,
                event: ev
            },
            TraceEvent::PlanSucceeded { plan: p1 },
        ]
    );
}

#[test]
fn no_applicable_plan_is_a_clear_error_not_a_hang() {
    let (mut mission, ids) = tiny::mission(false);
    // The only plan now needs a fact that never holds.
    let mut library = psmpa_core::PlanLibrary::new();
    let never = mission.domain.fact_id("door_open").unwrap();
    library
        .add(
            psmpa_core::Plan::new(
                "get-in",
                mission.task.event,
                psmpa_core::FactSet::single(never),
                &[ids.walk],
            )
            .unwrap(),
        )
        .unwrap();
    mission.library = library;
    let world = TinyWorld::new(ids, &[]);
    let mut rt: tiny::TinyRuntime<'_> =
        tiny::runtime(&mission, &world, tiny::config(Policy::PSmpa));
    let (mut sensing, mut deciding) = rt.split();
    let out = simulate_split(sensing.run(), deciding.run(), LIMIT)
        .unwrap()
        .output;
    assert!(
        matches!(out, Err(ControlError::NoApplicablePlan { .. })),
        "{out:?}"
    );
}

#[test]
fn repeated_failure_ends_with_exhausted_not_a_loop() {
    let (mut mission, ids) = tiny::mission(true);
    let mut library = psmpa_core::PlanLibrary::new();
    library
        .add(
            psmpa_core::Plan::new(
                "only",
                mission.task.event,
                psmpa_core::FactSet::EMPTY,
                &[ids.stumble],
            )
            .unwrap(),
        )
        .unwrap();
    mission.library = library;
    let world = TinyWorld::new(ids, &[]);
    let mut rt: tiny::TinyRuntime<'_> =
        tiny::runtime(&mission, &world, tiny::config(Policy::PSmpa));
    let (mut sensing, mut deciding) = rt.split();
    let out = simulate_split(sensing.run(), deciding.run(), LIMIT)
        .unwrap()
        .output;
    assert!(
        matches!(out, Err(ControlError::Exhausted { .. })),
        "{out:?}"
    );
}

/// A sensor that stops answering is a fault after its timeout: the state fails, the behaviour
/// is not left running, and the control loop ends with an error instead of hanging.
#[test]
fn a_sensor_that_stops_answering_fails_the_action_after_its_timeout() {
    let ids = ids();
    let r = run_with(Policy::PSmpa, &[], false, |w| w.camera_answers.set(false));
    assert!(r.result.is_err());
    let fault_at = r
        .trace
        .iter()
        .find_map(|(t, e)| match *e {
            TraceEvent::SensorFailed { sensor, fault } if sensor == ids.camera => Some((*t, fault)),
            _ => None,
        })
        .unwrap();
    assert_eq!(fault_at.1, psmpa_core::SensorFault::Timeout);
    // The camera was switched on when "open" started (10 s) and timed out 500 ms later.
    assert_eq!(fault_at.0, Instant::from_millis(10_500));
    assert!(r.trace.iter().any(|(_, e)| matches!(
        e,
        TraceEvent::PlanFailed {
            reason: Failure::SensorFault { .. },
            ..
        }
    )));
}

/// A sensor that failed is out of service: a library plan with an action that needs it is
/// passed over, not started (the robot does not walk to a door it could not open), the run
/// ends with an error naming the sensor, the planner leaves those actions out as well, and
/// `clear_faults` puts the sensor back into service.
#[test]
fn a_state_that_needs_a_faulty_sensor_fails_at_once_until_the_faults_are_cleared() {
    let (mut mission, ids) = tiny::mission(false);
    // Two library plans with the same body: when the first fails, the second is tried.
    let mut library = psmpa_core::PlanLibrary::new();
    for name in ["first", "second"] {
        let plan = psmpa_core::Plan::new(
            name,
            mission.task.event,
            psmpa_core::FactSet::EMPTY,
            &[ids.walk, ids.open],
        );
        library.add(plan.unwrap()).unwrap();
    }
    mission.library = library;
    let world = TinyWorld::new(ids, &[]);
    world.camera_answers.set(false);
    let mut rt: tiny::TinyRuntime<'_> =
        tiny::runtime(&mission, &world, tiny::config(Policy::PSmpa));
    let planner =
        psmpa_core::planner::Planner::<64>::new(psmpa_core::planner::Strategy::BreadthFirst);
    let mut space = psmpa_core::planner::Search::<64>::new();
    let (mut sensing, mut deciding) = rt.split();
    let (broken, planned, repaired) = simulate_split(
        sensing.run(),
        async {
            let broken = (
                deciding.run().await,
                deciding.faulty_sensors(),
                Instant::now(),
            );
            // The planner cannot count on the camera either: no action needing it applies.
            let planned = deciding.run_planning(&planner, &mut space).await;
            // The camera is repaired.
            world.camera_answers.set(true);
            deciding.clear_faults();
            (broken, planned, deciding.run().await)
        },
        LIMIT,
    )
    .unwrap()
    .output;
    // The planner finds nothing either; the error keeps the library's reason, the camera.
    if let Err(e) = planned {
        assert_eq!(
            (&mission).describe_error(e).to_string(),
            "no plan for get_in could start: passed over first, second; sensors out of service [camera]"
        );
    }
    assert!(
        matches!(
            planned,
            Err(ControlError::Inapplicable { faulty, .. }) if faulty == SensorSet::EMPTY.with(ids.camera)
        ),
        "{planned:?}"
    );
    let (result, faulty, ended) = broken;
    assert_eq!(faulty, SensorSet::EMPTY.with(ids.camera));
    // "second" needs the camera for "open": passed over, and the error says why.
    match result {
        Err(ControlError::Inapplicable {
            skipped,
            faulty,
            known_false,
            unknown,
            ..
        }) => {
            assert_eq!(skipped.bits(), 0b10, "the second plan passed over");
            assert_eq!(faulty, SensorSet::EMPTY.with(ids.camera));
            assert!(known_false.is_empty() && unknown.is_empty());
        }
        other => panic!("expected Inapplicable, got {other:?}"),
    }
    let trace = rt.into_sink().events;
    let failures: Vec<(Instant, Failure)> = trace
        .iter()
        .filter_map(|(t, e)| match e {
            TraceEvent::PlanFailed { reason, .. } => Some((*t, *reason)),
            _ => None,
        })
        .collect();
    // The first plan: the camera timed out 500 ms into "open", and the run ended there.
    assert_eq!(
        failures,
        [(
            ended,
            Failure::SensorFault {
                sensor: ids.camera,
                fault: psmpa_core::SensorFault::Timeout
            }
        )]
    );
    let selected = trace
        .iter()
        .filter(|(_, e)| matches!(e, TraceEvent::PlanSelected { .. }))
        .count();
    assert_eq!(
        selected, 2,
        "\"first\" before the fault and after the repair; \"second\" never started"
    );
    let camera_on: Vec<Instant> = trace
        .iter()
        .filter(|(_, e)| *e == TraceEvent::SensorOn { sensor: ids.camera })
        .map(|(t, _)| *t)
        .collect();
    assert_eq!(
        camera_on.len(),
        2,
        "once before the fault, once after the repair, never while it is out of service"
    );
    assert!(camera_on[0] < ended && camera_on[1] >= ended);
    // After the repair the same library plan runs to the goal.
    assert_eq!(repaired.unwrap().plans_failed, 0);
}

/// The precondition of "open" on the camera's percept, with the camera's frame `lost` or
/// showing no handle, under `policy`, "open" working `open_ms`: the trace.
fn open_with_camera(policy: Policy, lost: bool, open_ms: u64) -> Vec<(Instant, TraceEvent)> {
    let (mission, ids) = tiny::mission(false);
    let world = TinyWorld::new(ids, &[]);
    world.camera_loses.set(lost);
    world.handle_visible.set(false);
    world.open_ms.set(open_ms);
    run_on(&mission, &world, policy).trace
}

/// Whether "open" was traced violated on `handle_seen`, and whether it was traced restored.
fn open_violated(trace: &[(Instant, TraceEvent)]) -> (bool, bool) {
    let open = tiny::mission(false).1.open;
    let handle = psmpa_core::FactSet::single(psmpa_core::FactId::new(2).unwrap());
    let violated = trace.iter().any(|(_, e)| {
        matches!(e, TraceEvent::PreconditionViolated { action, missing }
            if *action == open && missing.intersects(handle))
    });
    let restored = trace
        .iter()
        .any(|(_, e)| matches!(e, TraceEvent::PreconditionRestored { action } if *action == open));
    (violated, restored)
}

/// A one-shot camera whose only frame is lost leaves `handle_seen` unshown: "open" runs with
/// its precondition violated, and the trace says so (a lost sample hides nothing).
#[test]
fn a_lost_one_shot_sample_leaves_the_precondition_violated() {
    let trace = open_with_camera(Policy::PSmpa, true, 500);
    assert!(
        trace
            .iter()
            .any(|(_, e)| matches!(e, TraceEvent::SampleLost { .. })),
        "the camera's frame was lost"
    );
    assert_eq!(open_violated(&trace), (true, false));
}

/// Under SMPA a one-shot camera samples in the first sense phase only: its "no handle" stands
/// in every later phase, and the violation is not cleared when a phase starts without a frame.
#[test]
fn under_smpa_a_one_shot_percept_stands_in_later_phases() {
    let trace = open_with_camera(tiny::SMPA, false, 6_000);
    let phases = trace
        .iter()
        .filter(|(_, e)| {
            matches!(
                e,
                TraceEvent::PhaseStarted {
                    phase: psmpa_core::Phase::Sense,
                    ..
                }
            )
        })
        .count();
    assert!(phases >= 3, "open spans several sense phases: {phases}");
    assert_eq!(open_violated(&trace), (true, false));
}

/// A precondition that stays false longer than `max_violation` takes the failure edge.
#[test]
fn a_precondition_that_stays_violated_fails_the_state() {
    let (mission, ids) = tiny::mission(false);
    let world = TinyWorld::new(ids, &[(2_000, 60_000)]);
    let mut config = tiny::config(Policy::PSmpa);
    config.max_violation = Duration::from_secs(3);
    config.max_failures = 0;
    let mut rt: tiny::TinyRuntime<'_> = tiny::runtime(&mission, &world, config);
    let (mut sensing, mut deciding) = rt.split();
    let out = simulate_split(sensing.run(), deciding.run(), LIMIT).unwrap();
    assert!(matches!(
        out.output,
        Err(ControlError::TooManyFailures {
            last: Failure::PreconditionViolated { .. },
            ..
        })
    ));
    // Seen at 2.0 s, given up 3 s later.
    assert_eq!(out.elapsed, Duration::from_secs(5));
}

#[test]
fn the_same_run_gives_the_same_trace_hash_twice_and_on_8_parallel_threads() {
    let window = [(1_500, 2_500), (4_200, 5_000)];
    let reference: Vec<u64> = [Policy::PSmpa, SMPA]
        .iter()
        .map(|p| run(*p, &window).hash)
        .collect();
    assert_ne!(
        reference[0], reference[1],
        "the policies leave different traces"
    );
    let again: Vec<u64> = [Policy::PSmpa, SMPA]
        .iter()
        .map(|p| run(*p, &window).hash)
        .collect();
    assert_eq!(reference, again);
    let threads: Vec<_> = (0..8)
        .map(|i| {
            std::thread::spawn(move || {
                let policy = if i % 2 == 0 { Policy::PSmpa } else { SMPA };
                (i % 2, run(policy, &window).hash)
            })
        })
        .collect();
    for t in threads {
        let (which, hash) = t.join().unwrap();
        assert_eq!(hash, reference[which]);
    }
}

/// Stores are the runtime's: after a run the sensor's store holds its last sample.
#[test]
fn sensor_stores_keep_the_latest_sample_with_its_time() {
    let (mission, ids) = tiny::mission(false);
    let world = TinyWorld::new(ids, &[]);
    let mut rt: tiny::TinyRuntime<'_> =
        tiny::runtime(&mission, &world, tiny::config(Policy::PSmpa));
    let (mut sensing, mut deciding) = rt.split();
    simulate_split(sensing.run(), deciding.run(), LIMIT)
        .unwrap()
        .output
        .unwrap();
    let store: &DataStore<_, 5> = rt.sensor_store(ids.range).unwrap();
    let last = store.get(psmpa_core::store::SAMPLE_KEY).unwrap();
    assert_eq!(last.value, Value::Mm(2550));
    // Sampled every 100 ms from 0 while walking. The walk ends at 10.0 s, the instant the next
    // sample is due: sensing comes first at an instant, so that sample is taken before the
    // walk, and the sensor with it, ends.
    assert_eq!(last.at, Instant::from_millis(10_000));
    let model = rt.model::<2>();
    assert!(model.goal_holds());
    assert_eq!(model.percept(ids.range), Some(last));
}

/// SMPA phases of no time are taken as one tick each: the run ends instead of alternating
/// forever at one instant.
#[test]
fn zero_length_smpa_phases_do_not_livelock() {
    let zero = Policy::Smpa {
        sense: Duration::from_ticks(0),
        act: Duration::from_ticks(0),
    };
    let r = run(zero, &[]);
    r.result.unwrap();
    // 10 s of walking in 1-tick act phases alternating with 1-tick sense phases.
    assert!(
        r.elapsed >= Duration::from_secs(20) && r.elapsed < Duration::from_secs(22),
        "{:?}",
        r.elapsed
    );
}

/// Runs `mission` on the tiny world with obstacles in `windows`, P-SMPA.
fn run_mission(mission: &tiny::TinyMission, ids: Ids, windows: &[(u64, u64)]) -> Run {
    run_on(mission, &TinyWorld::new(ids, windows), Policy::PSmpa)
}

/// The plans selected, in order, by index.
fn selected_plans(trace: &[(Instant, TraceEvent)]) -> Vec<usize> {
    trace
        .iter()
        .filter_map(|(_, e)| match e {
            TraceEvent::PlanSelected { plan, .. } => Some(plan.index()),
            _ => None,
        })
        .collect()
}

fn plan_failures(trace: &[(Instant, TraceEvent)]) -> Vec<(Instant, Failure)> {
    trace
        .iter()
        .filter_map(|(t, e)| match e {
            TraceEvent::PlanFailed { reason, .. } => Some((*t, *reason)),
            _ => None,
        })
        .collect()
}

/// Per-action monitoring: the same box in the walk's path from 3 s to 4 s. A walk that may wait
/// (the runtime's default, 30 s here) waits and arrives; the same walk with a tolerance of zero,
/// as at a cliff's edge, fails at the first sample that shows its path blocked.
#[test]
fn an_action_without_tolerance_fails_at_once_while_another_may_wait() {
    let box_at = [(3_000, 4_000)];
    let (mission, ids) = tiny::mission(false);
    let waits = run_mission(&mission, ids, &box_at);
    assert_eq!(waits.result.unwrap().plans_failed, 0);
    assert!(plan_failures(&waits.trace).is_empty());

    let (mut cliff, ids) = tiny::mission(false);
    cliff
        .domain
        .set_max_violation(ids.walk, Some(Duration::from_ticks(0)))
        .unwrap();
    let stops = run_mission(&cliff, ids, &box_at);
    assert!(stops.result.is_err(), "{:?}", stops.result);
    let failures = plan_failures(&stops.trace);
    // The range samples every 100 ms from the walk's start at 0: the 3 s sample sees the box.
    assert_eq!(
        failures.first(),
        Some(&(
            Instant::from_millis(3_000),
            Failure::PreconditionViolated {
                action: ids.walk,
                missing: psmpa_core::FactSet::single(psmpa_core::FactId::new(0).unwrap()),
            }
        ))
    );
    // The same walk with 2 s of tolerance: the 1 s box is waited out.
    let (mut patient, ids) = tiny::mission(false);
    patient
        .domain
        .set_max_violation(ids.walk, Some(Duration::from_secs(2)))
        .unwrap();
    assert_eq!(
        run_mission(&patient, ids, &box_at)
            .result
            .unwrap()
            .plans_failed,
        0
    );
}

/// A plan context may require a fact to be false: a plan for when the path is *not* clear is
/// passed over while it is clear, and the next plan is chosen; with the path blocked at the
/// start it is the one chosen.
#[test]
fn a_negative_context_chooses_the_other_plan() {
    let (mut mission, ids) = tiny::mission(false);
    let event = mission.task.event;
    let clear = psmpa_core::FactSet::single(psmpa_core::FactId::new(0).unwrap());
    let mut library = psmpa_core::PlanLibrary::new();
    // "detour" (first in priority) applies only while the path is known not clear: its first
    // action, "open", does not need a clear path.
    let detour = psmpa_core::Plan::new("detour", event, psmpa_core::FactSet::EMPTY, &[ids.open])
        .unwrap()
        .with_context_not(clear);
    library.add(detour).unwrap();
    library
        .add(
            psmpa_core::Plan::new(
                "get-in",
                event,
                psmpa_core::FactSet::EMPTY,
                &[ids.walk, ids.open],
            )
            .unwrap(),
        )
        .unwrap();
    mission.library = library;
    // The path is clear at the start: "detour" does not apply, "get-in" runs to the goal.
    let clear_path = run_mission(&mission, ids, &[]);
    assert_eq!(clear_path.result.unwrap().plans_failed, 0);
    assert_eq!(selected_plans(&clear_path.trace), [1]);
    // A box at the start: the initial model shows the path blocked, "detour" applies.
    let blocked = run_mission(&mission, ids, &[(0, 60_000)]);
    assert_eq!(selected_plans(&blocked.trace).first(), Some(&0));
}

/// A negative context on a fact that a sensor perceives but no sample has shown is unknown, not
/// satisfied: the camera (one-shot, at the door) has not looked at the start, so a plan for
/// "no handle seen" is passed over and the next plan runs; alone in the library, it gives an
/// error naming the unknown fact, and nothing moves.
#[test]
fn a_negative_context_on_a_fact_never_sensed_does_not_apply() {
    let (mut mission, ids) = tiny::mission(false);
    let event = mission.task.event;
    let handle = psmpa_core::FactSet::single(psmpa_core::FactId::new(2).unwrap());
    let blind = psmpa_core::Plan::new("no handle", event, psmpa_core::FactSet::EMPTY, &[ids.walk])
        .unwrap()
        .with_context_not(handle);
    let get_in = psmpa_core::Plan::new(
        "get-in",
        event,
        psmpa_core::FactSet::EMPTY,
        &[ids.walk, ids.open],
    )
    .unwrap();
    let mut library = psmpa_core::PlanLibrary::new();
    library.add(blind.clone()).unwrap();
    library.add(get_in).unwrap();
    mission.library = library;
    let both = run_mission(&mission, ids, &[]);
    assert_eq!(both.result.unwrap().plans_failed, 0);
    assert_eq!(selected_plans(&both.trace), [1]);

    let mut alone = psmpa_core::PlanLibrary::new();
    alone.add(blind).unwrap();
    mission.library = alone;
    let r = run_mission(&mission, ids, &[]);
    match r.result {
        Err(ControlError::Inapplicable {
            skipped, unknown, ..
        }) => {
            assert_eq!(skipped.bits(), 0b1);
            assert_eq!(unknown, handle);
        }
        other => panic!("expected Inapplicable, got {other:?}"),
    }
    assert!(selected_plans(&r.trace).is_empty());
}

/// What is known starts again with each run's initial model: the camera's "handle seen" of one
/// run does not make a "no handle" plan's negative context hold in the next run, which has
/// not looked yet. Both runs pass it over.
#[test]
fn a_new_run_does_not_know_what_an_earlier_run_sensed() {
    let (mut mission, ids) = tiny::mission(false);
    let event = mission.task.event;
    let handle = psmpa_core::FactSet::single(psmpa_core::FactId::new(2).unwrap());
    let mut library = psmpa_core::PlanLibrary::new();
    let blind = psmpa_core::Plan::new("no handle", event, psmpa_core::FactSet::EMPTY, &[ids.walk]);
    library
        .add(blind.unwrap().with_context_not(handle))
        .unwrap();
    let get_in = psmpa_core::Plan::new(
        "get-in",
        event,
        psmpa_core::FactSet::EMPTY,
        &[ids.walk, ids.open],
    );
    library.add(get_in.unwrap()).unwrap();
    mission.library = library;
    let world = TinyWorld::new(ids, &[]);
    let mut rt: tiny::TinyRuntime<'_> =
        tiny::runtime(&mission, &world, tiny::config(Policy::PSmpa));
    let (mut sensing, mut deciding) = rt.split();
    let (first, second) = simulate_split(
        sensing.run(),
        async { (deciding.run().await, deciding.run().await) },
        LIMIT,
    )
    .unwrap()
    .output;
    assert!(first.is_ok() && second.is_ok(), "{first:?} {second:?}");
    assert_eq!(selected_plans(&rt.into_sink().events), [1, 1]);
}

/// An action's effects are known as a percept is: a fact a sensor perceives, deleted by an
/// action, is known false, and a plan that needs it false applies.
#[test]
fn a_percept_fact_an_action_deleted_is_known_false() {
    let (mut mission, ids) = tiny::mission(false);
    let event = mission.task.event;
    let handle = psmpa_core::FactSet::single(psmpa_core::FactId::new(2).unwrap());
    let drop = mission
        .domain
        .add_action(psmpa_core::ActuatorAction::new(
            "forget the handle",
            psmpa_core::FactSet::EMPTY,
            psmpa_core::FactSet::EMPTY,
            handle,
        ))
        .unwrap();
    mission.task.init = handle;
    let mut library = psmpa_core::PlanLibrary::new();
    library
        .add(psmpa_core::Plan::new("forget", event, handle, &[drop]).unwrap())
        .unwrap();
    let express = psmpa_core::Plan::new(
        "express",
        event,
        psmpa_core::FactSet::EMPTY,
        &[ids.walk, ids.open],
    );
    library
        .add(express.unwrap().with_context_not(handle))
        .unwrap();
    mission.library = library;
    let r = run_mission(&mission, ids, &[]);
    assert!(r.result.is_ok(), "{:?}", r.result);
    assert_eq!(selected_plans(&r.trace), [0, 1]);
}

/// A plan whose first action needs a fact a percept has already shown false is not started:
/// the next applicable plan is tried, and when there is none, a clear error names the plans
/// passed over and the facts known false. Nothing moved.
#[test]
fn a_plan_known_to_be_inapplicable_is_skipped() {
    let (mission, ids) = tiny::mission(true);
    // A box in front from the start for a minute: both plans start with a walk on a clear path.
    let r = run_mission(&mission, ids, &[(0, 60_000)]);
    let clear = psmpa_core::FactSet::single(psmpa_core::FactId::new(0).unwrap());
    match r.result {
        Err(
            e @ ControlError::Inapplicable {
                skipped,
                known_false,
                ..
            },
        ) => {
            assert_eq!(skipped.bits(), 0b11, "both plans passed over");
            assert_eq!(known_false, clear);
            // In words, with the mission's names.
            assert_eq!(
                (&mission).describe_error(e).to_string(),
                "no plan for get_in could start: passed over stumble-first, get-in; \
                 known false {path_clear}"
            );
        }
        other => panic!("expected Inapplicable, got {other:?}"),
    }
    assert!(
        !r.trace.iter().any(|(_, e)| matches!(
            e,
            TraceEvent::PlanSelected { .. } | TraceEvent::StateEntered { .. }
        )),
        "no plan started, no state entered"
    );
    // Once the first plan is out of the way, the second still needs the clear path; a third,
    // whose first action does not, is the one started.
    let (mut mission, ids) = tiny::mission(true);
    let event = mission.task.event;
    mission
        .library
        .add(
            psmpa_core::Plan::new("open-first", event, psmpa_core::FactSet::EMPTY, &[ids.open])
                .unwrap(),
        )
        .unwrap();
    let r = run_mission(&mission, ids, &[(0, 60_000)]);
    assert_eq!(selected_plans(&r.trace).first(), Some(&2));
}

/// With a planner to fall back on, the library's reason is kept: when every plan was passed
/// over and the planner finds nothing either (the walk needs the path a sample showed
/// blocked), the error names the plans and the fact, not just "unsolvable".
#[test]
fn a_planner_that_finds_nothing_keeps_the_reason_plans_were_passed_over() {
    let (mission, ids) = tiny::mission(true);
    let world = TinyWorld::new(ids, &[(0, 60_000)]);
    let mut rt: tiny::TinyRuntime<'_> =
        tiny::runtime(&mission, &world, tiny::config(Policy::PSmpa));
    let planner =
        psmpa_core::planner::Planner::<64>::new(psmpa_core::planner::Strategy::BreadthFirst);
    let mut space = psmpa_core::planner::Search::<64>::new();
    let (mut sensing, mut deciding) = rt.split();
    let out = simulate_split(
        sensing.run(),
        deciding.run_planning(&planner, &mut space),
        LIMIT,
    )
    .unwrap()
    .output;
    let clear = psmpa_core::FactSet::single(psmpa_core::FactId::new(0).unwrap());
    match out {
        Err(ControlError::Inapplicable {
            skipped,
            known_false,
            ..
        }) => {
            assert_eq!(skipped.bits(), 0b11);
            assert_eq!(known_false, clear);
        }
        other => panic!("expected Inapplicable, got {other:?}"),
    }
    // A search that ran out of its budget proved nothing: it says so itself (a larger budget
    // may find a plan). One more action gives the search somewhere to go.
    let mut mission = mission;
    let at_door = psmpa_core::FactSet::single(psmpa_core::FactId::new(1).unwrap());
    mission
        .domain
        .add_action(psmpa_core::ActuatorAction::new(
            "sidle to the door",
            psmpa_core::FactSet::EMPTY,
            at_door,
            psmpa_core::FactSet::EMPTY,
        ))
        .unwrap();
    let world = TinyWorld::new(ids, &[(0, 60_000)]);
    let mut rt: tiny::TinyRuntime<'_> =
        tiny::runtime(&mission, &world, tiny::config(Policy::PSmpa));
    let mut small =
        psmpa_core::planner::Planner::<64>::new(psmpa_core::planner::Strategy::BreadthFirst);
    small.budget = 1;
    let (mut sensing, mut deciding) = rt.split();
    let out = simulate_split(
        sensing.run(),
        deciding.run_planning(&small, &mut space),
        LIMIT,
    )
    .unwrap()
    .output;
    assert!(
        matches!(
            out,
            Err(ControlError::Planning {
                error: psmpa_core::planner::PlanningError::Budget { .. },
                ..
            })
        ),
        "{out:?}"
    );
}

/// An action with a tolerance of its own was written to ride a violation out: it is started
/// on a precondition a sample has already shown false, and waits as it would had the
/// violation arisen while it ran. The same box at the start stops the same mission whose walk
/// relies on the runtime's default (the test above).
#[test]
fn an_action_with_a_tolerance_of_its_own_starts_on_a_blocked_path_and_waits() {
    let (mut mission, ids) = tiny::mission(true);
    for walk in [ids.stumble, ids.walk] {
        mission
            .domain
            .set_max_violation(walk, Some(Duration::from_secs(30)))
            .unwrap();
    }
    // The box stands in front from the start until 2 s.
    let r = run_mission(&mission, ids, &[(0, 2_000)]);
    let report = r.result.unwrap();
    // "stumble-first" starts at once (it fails, as it always does), then "get-in" waits.
    assert_eq!(selected_plans(&r.trace), [0, 1]);
    assert_eq!(report.plans_failed, 1);
    assert!(
        matches!(
            plan_failures(&r.trace).as_slice(),
            [(_, Failure::ActionFailed { action })] if *action == ids.stumble
        ),
        "{:?}",
        plan_failures(&r.trace)
    );
    // 2 m at 0.2 m/s from the box's removal at 2 s (the next 100 ms sample), then 0.5 s for the
    // door: more than the 10.5 s of a clear path, by the wait.
    assert!(
        r.elapsed >= Duration::from_millis(12_500),
        "{:?}",
        r.elapsed
    );
    assert!(r.elapsed < Duration::from_millis(13_000), "{:?}", r.elapsed);
}

#[test]
fn with_no_sink_nothing_is_traced_and_hashing_keeps_the_recorders_hash() {
    use psmpa_core::{Hashing, Runtime, TraceHash};
    let (mission, ids) = tiny::mission(false);
    let recorded = run_with(Policy::PSmpa, &[], false, |_| {});
    // Each run on a world of its own, from the same start.
    let hash_and_count = |traced: bool| {
        let world = TinyWorld::new(ids, &[]);
        let config = tiny::config(Policy::PSmpa);
        if traced {
            let mut rt = Runtime::<'_, tiny::Tiny<'_>, TinyWorld, Hashing>::new(
                &mission, &world, Hashing, config,
            );
            let (mut s, mut d) = rt.split();
            simulate_split(s.run(), d.run(), LIMIT).unwrap();
            (rt.trace_hash(), rt.trace_events())
        } else {
            let mut rt =
                Runtime::<'_, tiny::Tiny<'_>, TinyWorld, ()>::new(&mission, &world, (), config);
            let (mut s, mut d) = rt.split();
            simulate_split(s.run(), d.run(), LIMIT).unwrap();
            (rt.trace_hash(), rt.trace_events())
        }
    };
    let (hash, events) = hash_and_count(true);
    assert_eq!(hash.value(), recorded.hash);
    assert_eq!(events as usize, recorded.trace.len());
    assert_eq!(hash_and_count(false), (TraceHash::new(), 0));
}

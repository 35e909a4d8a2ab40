//! The whole Fetch Tea mission on the robot of `psmpa_fetch_tea`, its drivers on scripted
//! and recorded pins, sensing beside deciding in virtual time (`simulate_split`).
//!
//! 1 kHz ticks: echo widths and edges are whole milliseconds; a 6 ms echo is 1,029 mm.

mod common;

use common::{
    Run, Wheeling, World, action, echo_ms, far_echo_ms, run, run_config, run_with, sensor,
};
use embassy_time::{Duration, Instant};
use psmpa_core::{Config, ControlError, Outcome, SensorFault, TraceEvent, Value};
use psmpa_drivers::hcsr04::{Hcsr04Error, PULSE_LIMIT, RISE_TIMEOUT, Range, TRIGGER_PULSE};
use psmpa_drivers::switch::DEBOUNCE;
use psmpa_fetch_tea::{ARRIVE_WITHIN_MM, PIN_FAULT, Settings, sonar_reading};

const BUMPER_PERIOD_MS: u64 = 20;
const SONAR_PERIOD_MS: u64 = 100;

/// The walk's driving at the default settings: 2,000 mm at 250 mm/s, less the 2 mm it may
/// end short by (`ARRIVE_WITHIN_MM`: 8 ms).
fn walk_ms() -> u64 {
    let s = Settings::DEFAULT;
    let within = u64::from(ARRIVE_WITHIN_MM) * 1_000 / u64::from(s.walk_mm_s);
    s.walk_time().unwrap().as_millis() - within
}

/// The walking duty on the rig's PWM: 600 ‰ of 4,000.
fn walking() -> Wheeling {
    let duty = u32::from(Settings::DEFAULT.walk_permille.unsigned_abs());
    Wheeling::Forward((duty * u32::from(common::MAX_DUTY) / 1_000) as u16)
}

/// When the walk started driving: once the first readings of its sensors were in (the
/// state's first sonar read takes its echo's time).
fn drove(run: &Run) -> Instant {
    let writes = run.left.writes();
    let first = writes.iter().find(|t| run.left.at(**t) == walking());
    *first.expect("the walk drove")
}

/// How each state ended, in order.
fn outcomes(run: &Run) -> Vec<(psmpa_core::ActionId, Option<Outcome>)> {
    run.trace
        .find(|e| matches!(e, TraceEvent::StateLeft { .. }))
        .into_iter()
        .filter_map(|(_, e)| match e {
            TraceEvent::StateLeft {
                action, outcome, ..
            } => Some((action, outcome)),
            _ => None,
        })
        .collect()
}

#[test]
fn the_mission_completes_with_the_door_unlocked_the_marker_seen_and_the_path_clear() {
    let run = run(World::clear());
    assert!(run.result.is_ok(), "{:?}", run.result);
    assert_eq!(
        outcomes(&run),
        [
            (action("go to door"), Some(Outcome::Success)),
            (action("open door"), Some(Outcome::Success)),
            (action("enter kitchen"), Some(Outcome::Success)),
        ]
    );
    // The sonar measured the far wall's 6 and 7 ms echoes: 1,029 and 1,200 mm, clear of the
    // 300 mm clearance.
    let sonar = run.samples(sensor("sonar"));
    assert!(sonar.len() > 10, "{sonar:?}");
    assert!(
        sonar
            .iter()
            .all(|(_, v)| [Value::Mm(1_029), Value::Mm(1_200)].contains(v)),
        "{sonar:?}"
    );
    // The bumper was never pressed; the marker was seen; the handle gave.
    let bumper = run.samples(sensor("bumper"));
    assert!(bumper.iter().all(|(_, v)| *v == Value::Bool(false)));
    assert_eq!(
        run.samples(sensor("camera"))
            .iter()
            .map(|(_, v)| *v)
            .collect::<Vec<_>>(),
        [Value::Bool(true)]
    );
    assert_eq!(
        run.samples(sensor("handle"))
            .iter()
            .map(|(_, v)| *v)
            .collect::<Vec<_>>(),
        [Value::Bool(true)]
    );
    // Dead reckoning: the walk drove both wheels at the walking duty for the walk's time and
    // braked at its end. It started once the sonar's first reading was in (8 ms: the trigger,
    // the echo's delay, its 6 ms).
    let (entered, left) = run.state(action("go to door"));
    let started = drove(&run);
    assert_eq!(started, entered + Duration::from_millis(8));
    assert_eq!((left - started).as_millis(), walk_ms());
    for wheel in [&run.left, &run.right] {
        assert_eq!(
            wheel.at(started - Duration::from_millis(1)),
            Wheeling::Other
        );
        assert_eq!(wheel.at(started), walking());
        assert_eq!(wheel.at(left - Duration::from_millis(1)), walking());
        assert_eq!(wheel.at(left), Wheeling::Brake);
    }
    // Pushing the door and entering are timed drives; the robot ends braked.
    let (pushed, opened) = run.state(action("open door"));
    let (entering, inside) = run.state(action("enter kitchen"));
    let s = Settings::DEFAULT;
    // The handle's read debounces its press before the push starts.
    assert_eq!(
        (opened - pushed).as_millis(),
        DEBOUNCE.as_millis() + s.push.as_millis()
    );
    assert_eq!((inside - entering).as_millis(), s.enter.as_millis());
    assert_eq!(run.left.at(inside), Wheeling::Brake);
    assert_eq!(run.right.at(inside), Wheeling::Brake);
    // The chip was woken before the first command.
    assert_eq!(run.standby.log().first().map(|(_, l)| *l), Some(true));
}

#[test]
fn a_slow_echo_does_not_delay_the_bumper() {
    // Nothing in front: every ping comes back as the module's 38 ms "no echo" pulse.
    let run = run(World {
        echo: echo_ms(38),
        ..World::clear()
    });
    assert!(run.result.is_ok(), "{:?}", run.result);
    let (entered, left) = run.state(action("go to door"));
    let during = |t: &Instant| (entered..=left).contains(t);
    let ms = |t: Instant| (t - entered).as_millis();
    // The sonar's reads take 40 ms (trigger, delay, 38 ms pulse) every 100 ms: nothing in
    // range, a clear path. (The sample delivered at the state's start is the initial model's.)
    let sonar: Vec<_> = run
        .samples(sensor("sonar"))
        .into_iter()
        .filter(|(t, _)| during(t) && *t > entered)
        .collect();
    assert!(sonar.len() as u64 > walk_ms() / SONAR_PERIOD_MS);
    for (i, (at, value)) in sonar.iter().enumerate() {
        assert_eq!(*value, Value::NoEcho);
        assert_eq!(ms(*at), i as u64 * SONAR_PERIOD_MS + 40);
    }
    // The bumper's samples stay on their 20 ms grid while the sonar's reads are under way:
    // every instant of the grid has its sample, at that instant, none waits for the sonar.
    let bumper: Vec<Instant> = run
        .samples(sensor("bumper"))
        .into_iter()
        .map(|(t, _)| t)
        .filter(during)
        .collect();
    let grid: Vec<u64> = (0..=ms(left)).step_by(BUMPER_PERIOD_MS as usize).collect();
    assert_eq!(bumper.iter().map(|t| ms(*t)).collect::<Vec<_>>(), grid);
    // The bumper's pin was read at those instants too (the trace could stamp a late read
    // early; the pin cannot).
    let reads: Vec<Instant> = run.bumper.reads().into_iter().filter(during).collect();
    assert_eq!(reads, bumper);
}

/// Edges every 3 ms from `from` for `n` edges, starting at `first` and alternating.
fn chatter(from: u64, n: u64, first: bool) -> Vec<(u64, bool)> {
    (0..n)
        .map(|i| (from + 3 * i, first ^ (i % 2 == 1)))
        .collect()
}

#[test]
fn a_bump_during_the_walk_brakes_once_and_the_walk_resumes_after_it() {
    // The bumper (to ground, pressed low) is hit at 3 s and chatters for 30 ms as the robot
    // rocks against the obstacle; it is freed at 4 s and chatters for 12 ms.
    let mut bumper = chatter(3_000, 11, false);
    bumper.extend(chatter(4_000, 5, true));
    let run = run(World {
        bumper,
        ..World::clear()
    });
    assert!(run.result.is_ok(), "{:?}", run.result);
    let walk = action("go to door");
    // The edges wake the bumper between its periods (`Sensor::wake`): a read at the first
    // edge, whose debounce window the next edge ends; a read at the edge after that; and so
    // on, until a read at the last edge sees the level hold. Undebounced, those reads would
    // see contact, release, contact, ...
    let reads = run.bumper.reads();
    for edge in (3_000..=3_030).step_by(6).chain((4_000..=4_012).step_by(6)) {
        assert!(
            reads.contains(&Instant::from_millis(edge)),
            "no read at {edge}"
        );
    }
    // One contact: one violation of `path_clear`, one restoration, each the debounce time
    // after the last edge, not at the next period's read (3,048 and 4,028 ms).
    let violated = run
        .trace
        .find(|e| matches!(e, TraceEvent::PreconditionViolated { action, .. } if *action == walk));
    let restored = run
        .trace
        .find(|e| matches!(e, TraceEvent::PreconditionRestored { action } if *action == walk));
    let d = DEBOUNCE.as_millis();
    let at = |ms| Instant::from_millis(ms);
    assert_eq!(
        violated.iter().map(|(t, _)| *t).collect::<Vec<_>>(),
        [at(3_030 + d)]
    );
    assert_eq!(
        restored.iter().map(|(t, _)| *t).collect::<Vec<_>>(),
        [at(4_012 + d)]
    );
    let (violated, restored) = (violated[0].0, restored[0].0);
    // The wheels braked at once, stayed braked, and drove on when the bumper was freed.
    for wheel in [&run.left, &run.right] {
        assert_eq!(wheel.at(violated - Duration::from_millis(1)), walking());
        assert_eq!(wheel.at(violated), Wheeling::Brake);
        assert_eq!(
            wheel.at(restored - Duration::from_millis(1)),
            Wheeling::Brake
        );
        assert_eq!(wheel.at(restored), walking());
    }
    // Braked time does not count as walking, nor the time the bumper held the wheels from the
    // read that found the contact (it began at the last edge, 3,030 ms) to the brake: the walk
    // lasts that much longer.
    let (_, left) = run.state(walk);
    let held = d;
    assert_eq!(
        (left - drove(&run)).as_millis(),
        walk_ms() + held + (restored - violated).as_millis()
    );
}

#[test]
fn with_a_side_step_the_walk_goes_around_a_bump_and_drives_on() {
    // The bumper is hit at 3 s and freed at 4 s; the robot steps around for a second.
    let mut bumper = chatter(3_000, 1, false);
    bumper.extend(chatter(4_000, 1, true));
    let avoid = Duration::from_millis(1_000);
    let settings = Settings {
        avoid,
        ..Settings::DEFAULT
    };
    let run = run_with(
        World {
            bumper,
            ..World::clear()
        },
        settings,
    );
    assert!(run.result.is_ok(), "{:?}", run.result);
    let walk = action("go to door");
    let violated = run
        .trace
        .first(|e| matches!(e, TraceEvent::PreconditionViolated { action, .. } if *action == walk))
        .unwrap();
    assert_eq!(violated, Instant::from_millis(3_000 + DEBOUNCE.as_millis()));
    let ms = Duration::from_millis;
    // Turning away (the left wheel backwards), passing, turning back (the right backwards).
    assert_eq!(run.left.at(violated), Wheeling::Other);
    assert_eq!(run.right.at(violated), walking());
    for wheel in [&run.left, &run.right] {
        assert_eq!(wheel.at(violated + ms(250)), walking());
        assert_eq!(wheel.at(violated + ms(749)), walking());
    }
    assert_eq!(run.left.at(violated + ms(750)), walking());
    assert_eq!(run.right.at(violated + ms(750)), Wheeling::Other);
    // Then it drives on: the violation it saw was the obstacle it went around, and the
    // bumper was freed meanwhile. The step does not count as walking, nor the debounce time
    // the bumper held the wheels before the brake.
    for wheel in [&run.left, &run.right] {
        assert_eq!(wheel.at(violated + avoid), walking());
    }
    let (_, left) = run.state(walk);
    assert_eq!(
        (left - drove(&run)).as_millis(),
        walk_ms() + DEBOUNCE.as_millis() + avoid.as_millis()
    );
    // Once: one violation.
    let violations = run
        .trace
        .find(|e| matches!(e, TraceEvent::PreconditionViolated { action, .. } if *action == walk));
    assert_eq!(violations.len(), 1);
}

#[test]
fn an_obstacle_nearer_than_the_clearance_stops_the_walk_until_it_goes() {
    // From 2 s to 3 s something stands 171 mm ahead (a 1 ms echo); the far wall otherwise.
    let run = run(World {
        echo: std::sync::Arc::new(|at: Instant| {
            let near = (2_000..3_000).contains(&at.as_millis());
            Some(if near {
                Duration::from_millis(1)
            } else {
                far_echo_ms(at)
            })
        }),
        ..World::clear()
    });
    assert!(run.result.is_ok(), "{:?}", run.result);
    let walk = action("go to door");
    // 171 mm only while the obstacle stood there (a read takes 3 or 4 ms), the far wall
    // before and after.
    let sonar = run.samples(sensor("sonar"));
    let near = |t: &Instant| (2_000..3_000 + 3).contains(&t.as_millis());
    assert!(sonar.iter().any(|(t, _)| near(t)));
    for (t, v) in &sonar {
        let far = [Value::Mm(1_029), Value::Mm(1_200)];
        assert!(
            if near(t) {
                *v == Value::Mm(171)
            } else {
                far.contains(v)
            },
            "{v:?} at {t:?}"
        );
    }
    assert!(sonar.iter().any(|(t, _)| t.as_millis() > 3_100));
    let violated = run
        .trace
        .first(|e| matches!(e, TraceEvent::PreconditionViolated { action, .. } if *action == walk))
        .unwrap();
    let restored = run
        .trace
        .first(|e| matches!(e, TraceEvent::PreconditionRestored { action } if *action == walk))
        .unwrap();
    // Within a sonar period (and its read) of the obstacle's coming and going.
    let latency = Duration::from_millis(SONAR_PERIOD_MS + 10);
    assert!(violated >= Instant::from_millis(2_000), "{violated:?}");
    assert!(
        violated <= Instant::from_millis(2_000) + latency,
        "{violated:?}"
    );
    assert!(restored >= Instant::from_millis(3_000), "{restored:?}");
    assert!(
        restored <= Instant::from_millis(3_000) + latency,
        "{restored:?}"
    );
    assert_eq!(run.left.at(violated), Wheeling::Brake);
    assert_eq!(run.left.at(restored), walking());
}

#[test]
fn a_locked_door_is_not_pushed() {
    let run = run(World {
        unlocked: false,
        ..World::clear()
    });
    assert!(run.result.is_err(), "{:?}", run.result);
    assert_eq!(
        outcomes(&run).get(..2),
        Some(
            &[
                (action("go to door"), Some(Outcome::Success)),
                (action("open door"), Some(Outcome::Interrupted)),
            ][..]
        )
    );
    assert_eq!(
        run.samples(sensor("handle"))
            .iter()
            .map(|(_, v)| *v)
            .collect::<Vec<_>>(),
        [Value::Bool(false)]
    );
    // After the walk braked, the wheels were never driven again.
    let (_, walked) = run.state(action("go to door"));
    for wheel in [&run.left, &run.right] {
        assert!(
            wheel
                .writes()
                .iter()
                .all(|t| *t <= walked || wheel.at(*t) == Wheeling::Brake)
        );
    }
}

#[test]
fn a_sonar_that_never_answers_loses_its_samples_then_faults_and_the_robot_brakes() {
    let run = run(World {
        echo: std::sync::Arc::new(|_| None),
        ..World::clear()
    });
    let sonar = sensor("sonar");
    // The only plan failed and no other applies.
    assert!(
        matches!(run.result, Err(ControlError::Exhausted { .. })),
        "{:?}",
        run.result
    );
    // Each read gives up RISE_TIMEOUT after its trigger: a lost sample, counted by the
    // runtime, until `max_lost` in a row make the sonar silent.
    let lost = run
        .trace
        .find(|e| matches!(e, TraceEvent::SampleLost { sensor } if *sensor == sonar));
    let failed = run
        .trace
        .first(|e| {
            matches!(e, TraceEvent::SensorFailed { sensor, fault: SensorFault::Silent } if *sensor == sonar)
        })
        .expect("the sonar failed");
    assert_eq!(lost.len(), usize::from(Config::default().max_lost));
    assert_eq!(lost.last().map(|(t, _)| *t), Some(failed));
    let first_read = 1 + RISE_TIMEOUT.as_millis();
    assert_eq!(lost[0].0, Instant::from_millis(first_read));
    assert!(run.samples(sonar).is_empty());
    // The walk had set off on the bumper's word; the runtime's halt braked it at the fault.
    for wheel in [&run.left, &run.right] {
        assert_eq!(wheel.at(failed - Duration::from_millis(1)), walking());
        assert_eq!(wheel.at(failed), Wheeling::Brake);
        assert_eq!(wheel.writes().last(), Some(&failed));
    }
}

#[test]
fn a_stuck_echo_line_is_the_drivers_stuck_fault_within_the_sonars_timeout() {
    // The echo rises and never falls. The driver gives up PULSE_LIMIT after the rise, before
    // the runtime's timeout of the read: the fault says what happened (`Stuck`), not only that
    // the read took too long (`Timeout`).
    let run = run(World {
        echo: std::sync::Arc::new(|_| Some(Duration::from_secs(3_600))),
        ..World::clear()
    });
    let sonar = sensor("sonar");
    let faults: Vec<SensorFault> = run
        .trace
        .find(|e| matches!(e, TraceEvent::SensorFailed { sensor, .. } if *sensor == sonar))
        .into_iter()
        .filter_map(|(_, e)| match e {
            TraceEvent::SensorFailed { fault, .. } => Some(fault),
            _ => None,
        })
        .collect();
    assert_eq!(faults.first(), Some(&SensorFault::Stuck), "{faults:?}");
    // Trigger (one 1 ms tick here), the module's delay, the pulse limit: inside the timeout.
    let timeout = psmpa_fetch_tea::fetch_tea::TABLES
        .domain
        .sensor(sonar)
        .map(|s| s.timeout);
    let read = Duration::from_millis(1) + common::ECHO_DELAY + PULSE_LIMIT;
    assert!(
        timeout.is_some_and(|t| read < t),
        "{read:?} against {timeout:?}"
    );
    assert!(run.result.is_err(), "{:?}", run.result);
}

#[test]
fn the_sonars_timeout_holds_a_read_that_first_waits_out_a_running_pulse() {
    // A state that ends while its sonar read waits for the echo leaves the module's pulse
    // running (it ends it by itself, up to 38 ms later); the next state's first read waits it
    // out (at most PULSE_LIMIT), then triggers and times a whole pulse. Within the mission's
    // timeout, or the sonar fails (`Timeout`) where nothing is wrong with it: a re-plan at the
    // kitchen door whose marker is not in view did so on the bench (50 ms).
    let timeout = psmpa_fetch_tea::fetch_tea::TABLES
        .domain
        .sensor(sensor("sonar"))
        .map(|s| s.timeout);
    let worst = PULSE_LIMIT + TRIGGER_PULSE + RISE_TIMEOUT + PULSE_LIMIT;
    assert!(
        timeout.is_some_and(|t| worst < t),
        "{worst:?} against {timeout:?}"
    );
}

#[test]
fn a_noisy_bumper_wire_cannot_flood_the_sensing_side() {
    // Motor noise on the bumper's line during the walk: an edge every millisecond from 1 s to
    // 2 s, too short for a contact. Each edge would make a sample due; the switch lets one
    // through a debounce time, so the bumper's reads stay within one a debounce time plus its
    // periodic ones, and no contact is seen.
    let noise: Vec<(u64, bool)> = (1_000..2_000).map(|ms| (ms, ms % 2 == 1)).collect();
    let run = run(World {
        bumper: noise,
        ..World::clear()
    });
    assert!(run.result.is_ok(), "{:?}", run.result);
    let walk = action("go to door");
    assert!(
        run.trace
            .first(
                |e| matches!(e, TraceEvent::PreconditionViolated { action, .. } if *action == walk)
            )
            .is_none()
    );
    let during = |t: &Instant| (1_000..2_000).contains(&t.as_millis());
    let reads = run.bumper.reads().into_iter().filter(during).count() as u64;
    let most = 1_000 / DEBOUNCE.as_millis() + 1_000 / BUMPER_PERIOD_MS + 1;
    assert!(reads <= most, "{reads} reads in the noise, at most {most}");
    // The edges did wake it: more reads than its period alone gives.
    assert!(reads > 1_000 / BUMPER_PERIOD_MS + 1, "{reads} reads");
}

#[test]
fn each_outcome_of_a_sonar_read_becomes_a_sample_a_lost_sample_or_a_fault() {
    let clear = Settings::DEFAULT.clearance_mm;
    let reading = |r| sonar_reading(r, clear).map(|s| s.map(|s| (s.value, !s.holds.is_empty())));
    assert_eq!(
        reading(Ok(Range::Mm(1_029))),
        Ok(Some((Value::Mm(1_029), true)))
    );
    assert_eq!(
        reading(Ok(Range::Mm(clear + 1))),
        Ok(Some((Value::Mm(301), true)))
    );
    // At the clearance or nearer: not clear.
    assert_eq!(
        reading(Ok(Range::Mm(clear))),
        Ok(Some((Value::Mm(300), false)))
    );
    assert_eq!(
        reading(Ok(Range::NothingInRange)),
        Ok(Some((Value::NoEcho, true)))
    );
    assert_eq!(reading(Err(Hcsr04Error::NoEcho)), Ok(None));
    assert_eq!(reading(Err(Hcsr04Error::Busy)), Ok(None));
    assert_eq!(
        reading(Err(Hcsr04Error::OutOfRange)),
        Err(SensorFault::OutOfRange)
    );
    assert_eq!(reading(Err(Hcsr04Error::Stuck)), Err(SensorFault::Stuck));
    assert_eq!(
        reading(Err(Hcsr04Error::Pin)),
        Err(SensorFault::Device(PIN_FAULT))
    );
}

#[test]
fn the_robot_is_sync_so_its_runtime_can_serve_two_priorities() {
    fn sync<T: Sync>() {}
    sync::<common::TestRobot>();
}

/// Algorithm 2 at build time against Algorithm 2 at run time: the mission's plan from its
/// constant states and through the run-time FSM give the robot the same run, event by event, in worlds that take
/// each of its edges (a clear path, a bump, a near obstacle, a silent sonar, a locked door).
#[test]
fn the_constant_states_and_the_run_time_fsm_run_alike() {
    let worlds: [fn() -> World; 5] = [
        World::clear,
        || World {
            bumper: [chatter(3_000, 11, false), chatter(4_000, 5, true)].concat(),
            ..World::clear()
        },
        || World {
            // Something within the clearance from 2 s to 3 s.
            echo: std::sync::Arc::new(|at: Instant| {
                let near = (2_000..3_000).contains(&at.as_millis());
                Some(Duration::from_millis(if near { 1 } else { 6 }))
            }),
            ..World::clear()
        },
        || World {
            echo: std::sync::Arc::new(|_| None),
            ..World::clear()
        },
        || World {
            unlocked: false,
            ..World::clear()
        },
    ];
    for (i, world) in worlds.iter().enumerate() {
        let with = |plans| {
            let mut config = psmpa_core::Config::default();
            config.plans = plans;
            let run = run_config(world(), Settings::DEFAULT, config);
            (run.result, run.trace.events)
        };
        let compiled = with(psmpa_core::Plans::Compiled);
        assert!(compiled.1.len() > 10, "world {i}: a run");
        assert_eq!(compiled, with(psmpa_core::Plans::RunTime), "world {i}");
    }
}

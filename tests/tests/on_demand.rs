//! A precondition fact that only an on-demand sensor perceives, as `ActionIo::violation` and
//! docs/guide.md's `max_violation_ms` describe it: at the action's start it keeps its belief from
//! before (here never sensed, so false) until the behaviour asks for a sample.

use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_time::{Duration, Instant, Timer};
use psmpa_core::mission::{AnyBehaviour, load};
use psmpa_core::{
    Act, ActionId, Actuator, Config, ControlError, Failure, Loaded, Outcome, Platform, Reading,
    Report, Runtime, Sensor, SensorFault, SensorId, Tables,
};
use psmpa_testkit::{Recorder, simulate_split};

/// "pick" needs `item_seen`, which only the on-demand camera perceives; nothing senses it
/// before "pick" starts. `TOLERANCE` stands for the action's `max_violation_ms`.
const MISSION: &str = r#"{ "name": "pick", "facts": ["item_seen", "picked"], "events": ["go"],
  "sensors": [{ "name": "camera", "per": ["item_seen"], "mode": "on-demand", "timeout_ms": 100 }],
  "actions": [{ "name": "pick", "pre": ["item_seen"], "add": ["picked"], "max_violation_ms": TOLERANCE }],
  "plans": [{ "name": "p", "trigger": "go", "body": ["pick"] }],
  "task": { "event": "go", "init": [], "goal": ["picked"] } }"#;

/// The mission, loaded at run time: its tables.
type Pick<'a> = &'a Tables<'a, 1, 1, 1, 1>;

/// The camera sees the item (a read takes 20 ms); "pick" asks for it, then picks once the
/// precondition holds.
struct Picker;

impl Sensor<Pick<'_>> for Picker {
    async fn switch_on(&self, _: SensorId) -> Result<(), SensorFault> {
        Ok(())
    }

    async fn switch_off(&self, _: SensorId) {}

    async fn sample(&self, _: SensorId) -> Result<Option<Reading>, SensorFault> {
        Timer::after_millis(20).await;
        Ok(Some(Reading::flag(true)))
    }
}

impl Actuator<Pick<'_>> for Picker {
    fn halt(&self, _: ActionId) {} // nothing to stop

    async fn run(&self, act: Act<'_, Pick<'_>>) -> Outcome {
        let io = act.untyped();
        let Some(camera) = SensorId::new(0) else {
            return Outcome::Failure;
        };
        io.request(camera);
        let mut version = io.version();
        while io.violation().is_some() {
            match io.changed_within(version, Duration::from_millis(200)).await {
                Some(v) => version = v,
                None => return Outcome::Failure,
            }
        }
        Outcome::Success
    }
}

impl Platform for Picker {
    type Mutex = NoopRawMutex;
}

/// Runs the mission with "pick"'s `max_violation_ms` set to `tolerance_ms`: its result and
/// the instants and reasons of the plans that failed.
fn run(tolerance_ms: u32) -> (Result<Report, ControlError>, Vec<(Instant, Failure)>) {
    let json = MISSION.replace("TOLERANCE", &tolerance_ms.to_string());
    let loaded: Loaded<'_, (), (), 1, 1, 1, 1> =
        load(json.as_bytes(), &AnyBehaviour).unwrap_or_else(|e| panic!("the mission loads: {e}"));
    let mut rt = Runtime::<'_, Pick<'_>, Picker, Recorder<Pick<'_>>>::new(
        &loaded.mission,
        &Picker,
        Recorder::default(),
        Config::default(),
    );
    let (mut sensing, mut deciding) = rt.split();
    let done = simulate_split(sensing.run(), deciding.run(), Duration::from_secs(10))
        .expect("the run ends");
    let failures = rt
        .into_sink()
        .plan_failures::<psmpa_core::PlanId>()
        .into_iter()
        .map(|(t, _, reason)| (t, reason))
        .collect();
    (done.output, failures)
}

#[test]
fn an_on_demand_fact_is_violated_until_asked_for() {
    // With a tolerance longer than the request takes, the camera's sample restores it.
    let (picked, failures) = run(100);
    assert_eq!(picked.map(|r| r.plans_failed), Ok(0));
    assert!(failures.is_empty(), "{failures:?}");
    // With none, the action fails at its start, before the behaviour could ask.
    let (failed, failures) = run(0);
    assert!(
        matches!(failed, Err(ControlError::Exhausted { .. })),
        "{failed:?}"
    );
    assert!(
        matches!(
            failures.as_slice(),
            [(at, Failure::PreconditionViolated { .. })] if *at == Instant::from_ticks(0)
        ),
        "{failures:?}"
    );
}

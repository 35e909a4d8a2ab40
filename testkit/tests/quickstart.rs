use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_time::{Duration, Timer};
use psmpa_core::mission::{AnyBehaviour, load};
use psmpa_core::{ActionId, ActionIo, Actuator, Caps, Config, LoadedOf, Outcome, Platform};
use psmpa_core::{Reading, Runtime, Sensor, SensorFault, SensorId, TraceEvent};
use psmpa_testkit::{Recorder, simulate_split};

// One sensor (a bumper, every 20 ms), one action that needs what it senses, one plan.
const MISSION: &str = r#"{ "name": "hello", "facts": ["clear", "there"], "events": ["go"],
  "sensors": [{ "name": "bumper", "per": ["clear"], "mode": "cyclic", "period_ms": 20 }],
  "actions": [{ "name": "drive", "pre": ["clear"], "add": ["there"] }],
  "plans": [{ "name": "go there", "trigger": "go", "context": [], "body": ["drive"] }],
  "task": { "event": "go", "init": [], "goal": ["there"] } }"#;

struct Robot;

impl Sensor for Robot {
    async fn switch_on(&self, _: SensorId) -> Result<(), SensorFault> {
        Ok(())
    }
    async fn switch_off(&self, _: SensorId) {}
    async fn sample(&self, _: SensorId) -> Result<Option<Reading>, SensorFault> {
        Ok(Some(Reading::flag(true))) // the bumper feels nothing: the way is clear
    }
}

impl Actuator for Robot {
    async fn run(&self, _: ActionId, _: &ActionIo<'_>) -> Outcome {
        Timer::after(Duration::from_secs(2)).await; // drive for 2 s
        Outcome::Success
    }
    fn halt(&self, _: ActionId) {
        // The runtime cancelled the drive (a sensor failed, the way stayed blocked): a real
        // robot stops its motors here; the default does nothing.
    }
}

impl Platform for Robot {
    type Mutex = NoopRawMutex; // sensing and deciding on one executor
}

/// 1 sensor, 1 action, 1 plan of at most 1 action, 4 keys per data store.
type Hello = Caps<1, 1, 1, 1, 4>;

#[test]
fn the_robot_gets_there_in_virtual_time() {
    let loaded: LoadedOf<'_, AnyBehaviour, Hello> =
        load(MISSION.as_bytes(), &AnyBehaviour).unwrap();
    let rt = Runtime::<Robot, Hello, Recorder>::new(
        &loaded.mission,
        &Robot,
        Recorder::default(),
        Config::default(),
    );
    let done = simulate_split(rt.sensing(), rt.run(), Duration::from_secs(10)).unwrap();
    assert!(done.output.is_ok());
    let trace = rt.into_sink();
    assert_eq!(
        trace.find(|e| matches!(e, TraceEvent::Sample { .. })).len(),
        101
    ); // 0, 20, ... 2000 ms
    assert_eq!(done.elapsed, Duration::from_secs(2));
}

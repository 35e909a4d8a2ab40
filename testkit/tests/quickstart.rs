use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_time::{Duration, Timer};
use psmpa_core::{Act, Actuator, Config, Outcome, Platform};
use psmpa_core::{Reading, Sensor, SensorFault, TraceEvent};
use psmpa_testkit::{Recorder, simulate};

// One sensor (a bumper, every 20 ms), one action that needs what it senses, one plan: checked
// when this file compiles, and turned into a mission type (`hello::Hello`), its names, its
// plan's states as constants and the bumper's sampler.
psmpa_core::include_mission!(mod hello = "tests/hello.json");

struct Robot;

impl Sensor<hello::Hello> for Robot {
    async fn switch_on(&self, _: hello::Sensor) -> Result<(), SensorFault> {
        Ok(())
    }
    async fn switch_off(&self, _: hello::Sensor) {}
    async fn sample(&self, sensor: hello::Sensor) -> Result<Option<Reading>, SensorFault> {
        match sensor {
            // The bumper feels nothing: the way is clear.
            hello::Sensor::Bumper => Ok(Some(Reading::flag(true))),
        }
    }
}

impl Actuator<hello::Hello> for Robot {
    async fn run(&self, act: Act<'_, hello::Hello>) -> Outcome {
        match act.typed() {
            // Drive for 2 s (`io` reads the bumper, which runs beside the drive).
            hello::Run::Drive(_io) => Timer::after(Duration::from_secs(2)).await,
        }
        Outcome::Success
    }
    fn halt(&self, _: hello::Action) {
        // The safety stop, required: the runtime cancelled the drive (a sensor failed, the
        // way stayed blocked). A real robot stops its motors here.
    }
}

impl Platform for Robot {
    type Mutex = NoopRawMutex; // sensing and deciding on one executor
}

#[test]
fn the_robot_gets_there_in_virtual_time() {
    let mut rt = hello::Runtime::new(hello::Hello, &Robot, Recorder::default(), Config::default());
    // Both sides on one executor, sensing first; ends with the control loop's result.
    let done = simulate(rt.run_with_sensing(), Duration::from_secs(10)).unwrap();
    assert!(done.output.is_ok());
    let trace = rt.into_sink();
    assert_eq!(
        trace.find(|e| matches!(e, TraceEvent::Sample { .. })).len(),
        101
    ); // 0, 20, ... 2000 ms
    assert_eq!(done.elapsed, Duration::from_secs(2));
}

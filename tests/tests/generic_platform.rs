//! A robot generic over its hardware: the compiled mission's runtime takes `Robot<H>` with `H`
//! generic, `compile_runtime!` type-checks it for every `H` its bounds admit, and a test runs
//! it with one.

use core::cell::Cell;

use embassy_time::Duration;
use psmpa_core::{Act, Actuator, Config, Outcome, Platform, Reading, Sensor, SensorFault};
use psmpa_testkit::simulate;

psmpa_core::include_mission!(mod hello = "../testkit/tests/hello.json");

/// What the robot's hardware must do: feel the bumper, stop the wheels.
trait Hardware {
    fn bumped(&self) -> bool;
    fn stop(&self);
}

struct Robot<H> {
    hw: H,
}

impl<H: Hardware> Sensor<hello::Hello> for Robot<H> {
    async fn switch_on(&self, _: hello::Sensor) -> Result<(), SensorFault> {
        Ok(())
    }
    async fn switch_off(&self, _: hello::Sensor) {}
    async fn sample(&self, _: hello::Sensor) -> Result<Option<Reading>, SensorFault> {
        Ok(Some(Reading::flag(!self.hw.bumped())))
    }
}

impl<H: Hardware> Actuator<hello::Hello> for Robot<H> {
    async fn run(&self, _: Act<'_, hello::Hello>) -> Outcome {
        embassy_time::Timer::after(Duration::from_millis(500)).await;
        Outcome::Success
    }
    fn halt(&self, _: hello::Action) {
        self.hw.stop();
    }
}

impl<H> Platform for Robot<H> {
    type Mutex = embassy_sync::blocking_mutex::raw::NoopRawMutex;
}

type RobotRuntime<'r, H> = hello::Runtime<'r, Robot<H>>;

psmpa_core::compile_runtime!(<H> RobotRuntime<'_, H> where H: Hardware);

/// The simulated hardware: a clear way.
struct Simulated {
    stops: Cell<u32>,
}

impl Hardware for Simulated {
    fn bumped(&self) -> bool {
        false
    }
    fn stop(&self) {
        self.stops.set(self.stops.get() + 1);
    }
}

#[test]
fn a_runtime_generic_over_the_hardware_runs_with_one() {
    let robot = Robot {
        hw: Simulated {
            stops: Cell::new(0),
        },
    };
    let mut rt: RobotRuntime<'_, Simulated> =
        hello::Runtime::new(hello::Hello, &robot, (), Config::default());
    let done = simulate(rt.run_with_sensing(), Duration::from_secs(10)).unwrap();
    assert!(done.output.is_ok(), "{:?}", done.output);
    assert_eq!(robot.hw.stops.get(), 0, "a clear way: no safety stop");
}

//! The workload ([`crate::workload`]) on psmpa itself: the real core (Algorithm 1's control
//! loop, Algorithm 2's states, Algorithm 3's stores) on the real embassy executor, in the host's
//! virtual time, under the P-SMPA policy.
//!
//! The mission (`bench/missions/bench.json`, compiled in): one cyclic sensor (`sonar`, every
//! tick) perceiving `path_clear`; three actions whose precondition needs `path_clear`, so each
//! runs in a parallel state beside the sonar; one plan with the three in sequence. An action
//! step is one sonar sample (the runtime stores it, updates the beliefs and checks the running
//! action's precondition) and one step of the behaviour: it reads the sample through the
//! mutual store and writes its progress into its own store.

use core::cell::{Cell, RefCell};

use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_time::Duration;
use psmpa_core::{
    Act, Actuator, Beside, Config, Outcome, OwnKey, Plans, Reading, Sensor, SensorFault, Value,
};

use crate::workload::{STEPS_PER_ACTION, Sonar, path_clear};

psmpa_core::include_mission!(
    /// The workload's mission.
    pub mod bench = "missions/bench.json"
);

/// The mission of the workload.
pub fn mission() -> bench::Bench {
    bench::Bench
}

/// The platform: the sonar and the three behaviours.
#[derive(Debug, Default)]
pub struct Platform {
    sonar: RefCell<Sonar>,
    /// Action steps run.
    pub steps: Cell<u32>,
}

impl Sensor<bench::Bench> for Platform {
    // The workload's sonar never makes a sample due early, as the peers' have no such hook.
    const WAKES: bool = false;

    async fn switch_on(&self, _: bench::Sensor) -> Result<(), SensorFault> {
        Ok(())
    }

    async fn switch_off(&self, _: bench::Sensor) {}

    async fn sample(&self, _: bench::Sensor) -> Result<Option<Reading>, SensorFault> {
        let mm = self.sonar.borrow_mut().sample();
        // The condition, decided on this sample: `path_clear` holds or not.
        Ok(Some(Reading::of(Value::Mm(mm), path_clear(mm))))
    }
}

impl psmpa_core::Platform for Platform {
    type Mutex = NoopRawMutex;
}

impl Platform {
    /// One action of the plan: ten steps, each on the sonar's next sample.
    async fn act<A>(&self, io: &bench::Io<'_, A>) -> Outcome
    where
        A: Beside<bench::sensor::Sonar>,
        bench::key::Progress: OwnKey<A>,
    {
        let mut version = io.version();
        for step in 0..STEPS_PER_ACTION {
            if step > 0 {
                // The next sample: the runtime has checked the precondition on it.
                version = io.changed(version).await;
            }
            if io.violation().is_some() {
                return Outcome::Interrupted;
            }
            let Some(reading) = io.sample(bench::sensor::Sonar) else {
                return Outcome::Failure;
            };
            let Value::Mm(mm) = reading.value else {
                return Outcome::Failure;
            };
            let progress = Value::Int(mm.wrapping_add(step as i32));
            if io.put(bench::key::Progress, progress).is_err() {
                return Outcome::Failure;
            }
            self.steps.set(self.steps.get() + 1);
        }
        Outcome::Success
    }
}

impl Actuator<bench::Bench> for Platform {
    fn halt(&self, _: bench::Action) {} // nothing to stop

    async fn run(&self, act: Act<'_, bench::Bench>) -> Outcome {
        match act.typed() {
            bench::Run::A0(io) => self.act(&io).await,
            bench::Run::A1(io) => self.act(&io).await,
            bench::Run::A2(io) => self.act(&io).await,
        }
    }
}

/// The runtime of the workload.
pub type BenchRuntime<'r> = bench::Runtime<'r, Platform>;

/// Runs the plan once on `platform`, its plans as `plans` says (compiled: from its constant
/// states; run-time: through the run-time FSM); returns the action steps it ran.
pub fn run_plan_with(mission: &bench::Bench, platform: &Platform, plans: Plans) -> u32 {
    let mut config = Config::default();
    config.max_violation = Duration::from_ticks(0);
    config.plans = plans;
    let mut runtime = BenchRuntime::new(*mission, platform, (), config);
    let before = platform.steps.get();
    let (mut sensing, mut deciding) = runtime.split();
    let done =
        psmpa_sim::backend::simulate_split(sensing.run(), deciding.run(), Duration::from_secs(60));
    match done {
        Ok(done) if done.output.is_ok() => platform.steps.get() - before,
        _ => 0,
    }
}

/// Runs the plan once on `platform`, from `mission`, from its constant states; returns the
/// action steps it ran.
pub fn run_plan_on(mission: &bench::Bench, platform: &Platform) -> u32 {
    run_plan_with(mission, platform, Plans::Compiled)
}

/// Runs the plan once, mission and platform included; returns the action steps it ran.
pub fn run_plan() -> u32 {
    run_plan_on(&mission(), &Platform::default())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::workload::EXPECTED_STEPS;

    #[test]
    fn the_plan_runs_thirty_action_steps() {
        assert_eq!(run_plan(), EXPECTED_STEPS);
        // Again on the same mission and platform: nothing carries over.
        let (m, p) = (mission(), Platform::default());
        assert_eq!(run_plan_on(&m, &p), EXPECTED_STEPS);
        assert_eq!(run_plan_on(&m, &p), EXPECTED_STEPS);
        // Through the run-time FSM: the same steps.
        assert_eq!(run_plan_with(&m, &p, Plans::RunTime), EXPECTED_STEPS);
    }
}

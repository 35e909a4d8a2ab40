//! The workload ([`crate::workload`]) on psmpa itself: the real core (Algorithm 1's control
//! loop, Algorithm 2's FSM, Algorithm 3's stores) on the real embassy executor, in the host's
//! virtual time, under the P-SMPA policy.
//!
//! The mission: one cyclic sensor (`sonar`, every tick) perceiving `path_clear`; three
//! actions whose precondition needs `path_clear`, so each runs in a parallel state beside the
//! sonar; one plan with the three in sequence. An action step is one sonar sample (the runtime
//! stores it, updates the beliefs and checks the running action's precondition) and one step
//! of the behaviour: it reads the sample through the mutual store and writes its progress into
//! its own store.

use core::cell::{Cell, RefCell};

use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_time::Duration;
use psmpa_core::{
    ActionId, ActionIo, Actions, Actuator, ActuatorAction, Body, Caps, Config, Domain, FactSet,
    Key, Keys, Mission, Outcome, Plan, PlanLibrary, Plans, Reading, Runtime, Sensor, SensorAction,
    SensorFault, SensorId, SensorMode, Sensors, Task, Value,
};

use crate::workload::{STEPS_PER_ACTION, Sonar, path_clear};

/// The mission's capacities: 1 sensor, 3 actions, 1 plan of 3 actions.
pub type BenchMission = Mission<'static, 1, 3, 1, 3>;

/// Where a behaviour writes its progress in its own store.
const PROGRESS: Key = Key(1);

/// The mission of the workload.
pub fn mission() -> BenchMission {
    let mut d: Domain<'static, 1, 3> = Domain::new();
    let clear = d.add_fact("path_clear").expect("room for a fact");
    let go = d.add_event("go").expect("room for an event");
    let every_tick = SensorMode::Cyclic {
        period: Duration::from_ticks(1),
    };
    d.add_sensor(SensorAction::new(
        "sonar",
        FactSet::single(clear),
        every_tick,
    ))
    .expect("room for a sensor");
    let mut body: heapless::Vec<ActionId, 3> = heapless::Vec::new();
    let mut goal = FactSet::EMPTY;
    for (name, done) in [("a0", "done0"), ("a1", "done1"), ("a2", "done2")] {
        let done = d.add_fact(done).expect("room for the facts");
        let pre = FactSet::single(clear);
        let action = ActuatorAction::new(name, pre, FactSet::single(done), FactSet::EMPTY);
        let id = d.add_action(action).expect("room for three actions");
        body.push(id).expect("three actions");
        goal = goal.with(done);
    }
    let mut library: PlanLibrary<'static, 1, 3> = PlanLibrary::new();
    let plan = Plan::new("three actions", go, FactSet::EMPTY, &body).expect("a plan of three");
    library.add(plan).expect("room for a plan");
    Mission {
        name: "bench",
        domain: d,
        library,
        task: Task {
            event: go,
            init: FactSet::EMPTY,
            goal,
        },
    }
}

/// The platform: the sonar and the three behaviours.
#[derive(Debug, Default)]
pub struct Platform {
    sonar: RefCell<Sonar>,
    /// Action steps run.
    pub steps: Cell<u32>,
}

impl Sensor for Platform {
    type Id = SensorId;
    // The workload's sonar never makes a sample due early, as the peers' have no such hook.
    const WAKES: bool = false;

    async fn switch_on(&self, _: SensorId) -> Result<(), SensorFault> {
        Ok(())
    }

    async fn switch_off(&self, _: SensorId) {}

    async fn sample(&self, _: SensorId) -> Result<Option<Reading>, SensorFault> {
        let mm = self.sonar.borrow_mut().sample();
        // The condition, decided on this sample: `path_clear` holds or not.
        Ok(Some(Reading::of(Value::Mm(mm), path_clear(mm))))
    }
}

impl psmpa_core::Platform for Platform {
    type Mutex = NoopRawMutex;
}

impl Actuator for Platform {
    type Id = ActionId;
    fn halt(&self, _: ActionId) {} // nothing to stop

    async fn run(&self, _: ActionId, io: &ActionIo<'_>) -> Outcome {
        let Some(sonar) = SensorId::new(0) else {
            return Outcome::Failure;
        };
        let mut version = io.version();
        for step in 0..STEPS_PER_ACTION {
            if step > 0 {
                // The next sample: the runtime has checked the precondition on it.
                version = io.changed(version).await;
            }
            if io.violation().is_some() {
                return Outcome::Interrupted;
            }
            let Some(reading) = io.sample(sonar) else {
                return Outcome::Failure;
            };
            let Value::Mm(mm) = reading.value else {
                return Outcome::Failure;
            };
            let progress = Value::Int(mm.wrapping_add(step as i32));
            if io.put(PROGRESS, progress).is_err() {
                return Outcome::Failure;
            }
            self.steps.set(self.steps.get() + 1);
        }
        Outcome::Success
    }
}

/// The runtime of the workload: 4 keys per store.
pub type BenchRuntime<'r> =
    Runtime<'r, Platform, Caps<Sensors<1>, Actions<3>, Plans<1>, Body<3>, Keys<4>>>;

/// Runs the plan once on `platform`, from `mission`; returns the action steps it ran.
pub fn run_plan_on(mission: &BenchMission, platform: &Platform) -> u32 {
    let mut config = Config::default();
    config.max_violation = Duration::from_ticks(0);
    let mut runtime = BenchRuntime::new(mission, platform, (), config);
    let before = platform.steps.get();
    let (mut sensing, mut deciding) = runtime.split();
    let done =
        psmpa_sim::backend::simulate_split(sensing.run(), deciding.run(), Duration::from_secs(60));
    match done {
        Ok(done) if done.output.is_ok() => platform.steps.get() - before,
        _ => 0,
    }
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
    }
}

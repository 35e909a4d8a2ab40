//! The robot of the paper's experiment, written against `psmpa-core` the way an application
//! would: the "Fetch Tea" task with the "GetIn Kitchen" plan (go to door, open door, enter
//! kitchen), the sensors behind its sensor-based actions and the behaviours behind its
//! actuator-based actions, all acting on a simulated [`World`].
//!
//! * "go to door" needs `path_clear`, which the sonar and the foot bumper perceive (cyclic):
//!   Algorithm 2 runs both beside the walk.
//! * "open door" needs `handle_seen`, which the camera perceives in one shot once the robot is
//!   at the door.

use embassy_futures::select::{Either, select};
use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_time::{Duration, Instant, Timer};
use psmpa_core::{
    ActionId, ActionIo, Actuator, ActuatorAction, Config, Domain, DomainError, FactId, FactSet,
    Mission, Outcome, Plan, PlanError, PlanLibrary, Policy, Reading, Runtime, Sensor, SensorAction,
    SensorFault, SensorId, SensorMode, Task, Value,
};

use crate::scenario::Scenario;
use crate::world::{Device, Motion, World, WorldLog};

/// Time to open the door once the handle is seen.
pub const OPEN_DOOR: Duration = Duration::from_millis(1_000);
/// Time to walk through the open door.
pub const ENTER_KITCHEN: Duration = Duration::from_millis(1_000);

/// The Fetch Tea mission: 3 sensors, 3 actions, 2 plans of up to 4 actions.
pub type FetchTea = Mission<'static, 3, 3, 2, 4>;

/// Ids of the Fetch Tea mission.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Ids {
    /// `path_clear`: no obstacle right in front.
    pub path_clear: FactId,
    /// `at_door`.
    pub at_door: FactId,
    /// `handle_seen`: the camera sees the door handle.
    pub handle_seen: FactId,
    /// `door_open`.
    pub door_open: FactId,
    /// `in_kitchen`: the goal.
    pub in_kitchen: FactId,
    /// Sonar: cyclic, perceives `path_clear`.
    pub sonar: SensorId,
    /// Foot bumper: cyclic, perceives `path_clear`.
    pub bumper: SensorId,
    /// Camera: one-shot, needs `at_door`, perceives `handle_seen`.
    pub camera: SensorId,
    /// Go to door: pre `path_clear`, add `at_door`.
    pub go_to_door: ActionId,
    /// Open door: pre `at_door, handle_seen`, add `door_open`.
    pub open_door: ActionId,
    /// Enter kitchen: pre `door_open`, add `in_kitchen`, del `at_door`.
    pub enter_kitchen: ActionId,
}

/// Why the mission could not be built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MissionError {
    /// A domain table.
    Domain(DomainError),
    /// The plan library.
    Plan(PlanError),
}

impl From<DomainError> for MissionError {
    fn from(e: DomainError) -> Self {
        Self::Domain(e)
    }
}

impl From<PlanError> for MissionError {
    fn from(e: PlanError) -> Self {
        Self::Plan(e)
    }
}

/// Builds the Fetch Tea mission with the scenario's sensor periods.
pub fn fetch_tea(scenario: &Scenario) -> Result<(FetchTea, Ids), MissionError> {
    let mut d: Domain<'static, 3, 3> = Domain::new();
    let path_clear = d.add_fact("path_clear")?;
    let at_door = d.add_fact("at_door")?;
    let handle_seen = d.add_fact("handle_seen")?;
    let door_open = d.add_fact("door_open")?;
    let in_kitchen = d.add_fact("in_kitchen")?;
    let fetch = d.add_event("fetch_tea")?;
    let cyclic = |ms| SensorMode::Cyclic {
        period: Duration::from_millis(ms),
    };
    let one = FactSet::single;
    let sonar = d.add_sensor(SensorAction::new(
        "sonar",
        one(path_clear),
        cyclic(scenario.sonar.period_ms),
    ))?;
    let bumper = d.add_sensor(SensorAction::new(
        "bumper",
        one(path_clear),
        cyclic(scenario.bumper_period_ms),
    ))?;
    let camera = d.add_sensor(
        SensorAction::new("camera", one(handle_seen), SensorMode::OneShot).with_pre(one(at_door)),
    )?;
    let go_to_door = d.add_action(ActuatorAction::new(
        "go to door",
        one(path_clear),
        one(at_door),
        FactSet::EMPTY,
    ))?;
    let open_door = d.add_action(ActuatorAction::new(
        "open door",
        one(at_door).with(handle_seen),
        one(door_open),
        FactSet::EMPTY,
    ))?;
    let enter_kitchen = d.add_action(ActuatorAction::new(
        "enter kitchen",
        one(door_open),
        one(in_kitchen),
        one(at_door),
    ))?;
    let mut library = PlanLibrary::new();
    library.add(Plan::new(
        "GetIn Kitchen",
        fetch,
        FactSet::EMPTY,
        &[go_to_door, open_door, enter_kitchen],
    )?)?;
    let mission = Mission {
        name: "fetch-tea",
        domain: d,
        library,
        task: Task {
            event: fetch,
            init: FactSet::EMPTY,
            goal: one(in_kitchen),
        },
    };
    let ids = Ids {
        path_clear,
        at_door,
        handle_seen,
        door_open,
        in_kitchen,
        sonar,
        bumper,
        camera,
        go_to_door,
        open_door,
        enter_kitchen,
    };
    Ok((mission, ids))
}

/// The architecture a run uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Arch {
    /// Sensors run in parallel with acting.
    PSmpa,
    /// Sensing and acting alternate.
    Smpa,
}

impl Arch {
    /// `psmpa` or `smpa`.
    pub const fn name(self) -> &'static str {
        match self {
            Self::PSmpa => "psmpa",
            Self::Smpa => "smpa",
        }
    }

    /// Both, P-SMPA first.
    pub const ALL: [Self; 2] = [Self::PSmpa, Self::Smpa];
}

/// The runtime settings of a run: only the policy differs between the architectures.
pub fn config(scenario: &Scenario, arch: Arch) -> Config {
    Config {
        policy: match arch {
            Arch::PSmpa => Policy::PSmpa,
            Arch::Smpa => Policy::Smpa {
                sense: Duration::from_millis(scenario.sense_ms),
                act: Duration::from_millis(scenario.act_ms),
            },
        },
        // The robot waits for an obstacle to be avoided or taken away; give up only if the
        // path stays blocked for a minute.
        max_violation: Duration::from_secs(60),
        max_failures: 3,
        max_plans: 8,
        max_lost: 10,
    }
}

/// Application-defined trace codes of the robot's behaviours.
pub mod codes {
    /// The walk stopped for an obstacle and started a side step.
    pub const AVOID: u16 = 1;
    /// The side step ended and the walk resumed.
    pub const RESUME: u16 = 2;
}

/// The robot: the platform implementation of the mission's sensors and behaviours.
pub struct Nao<'w, 's, L: WorldLog> {
    world: &'w World<'s, L>,
    ids: Ids,
}

impl<'w, 's, L: WorldLog> Nao<'w, 's, L> {
    /// The robot in `world`.
    pub fn new(world: &'w World<'s, L>, ids: Ids) -> Self {
        Self { world, ids }
    }

    fn device(&self, sensor: SensorId) -> Option<Device> {
        [
            (self.ids.sonar, Device::Sonar),
            (self.ids.bumper, Device::Bumper),
            (self.ids.camera, Device::Camera),
        ]
        .into_iter()
        .find(|(id, _)| *id == sensor)
        .map(|(_, d)| d)
    }

    /// "go to door": walk; when a percept says the path is not clear, stop and side-step, then
    /// walk on. A violation counts as new evidence only if a sample showed it at or after the
    /// end of the last side step (the world settles the step before a sample at that instant;
    /// under SMPA the flag stays up, stale, until the next sense phase).
    async fn go_to_door(&self, io: &ActionIo<'_>) -> Outcome {
        let world = self.world;
        let mut handled: Option<Instant> = None;
        let mut stepping = false;
        let mut version = io.version();
        loop {
            let motion = world.motion();
            if !matches!(motion, Motion::Avoiding { .. }) {
                if stepping {
                    // The side step ended.
                    stepping = false;
                    handled = Some(Instant::now());
                    io.trace(codes::RESUME, 0);
                }
                if world.at_door() {
                    world.stop();
                    world.arrived();
                    return Outcome::Success;
                }
                let fresh = io
                    .violation()
                    .is_some_and(|v| handled.is_none_or(|h| v.last_seen >= h));
                if fresh {
                    world.stop();
                    world.begin_avoid();
                    stepping = true;
                    handled = Some(Instant::now());
                    io.trace(codes::AVOID, 0);
                    continue;
                }
                if motion != Motion::Walking {
                    world.walk();
                }
            }
            let wake = world.next_event();
            let sleep = async {
                match wake {
                    Some(at) => Timer::at(at).await,
                    None => core::future::pending().await,
                }
            };
            if let Either::First(v) = select(io.changed(version), sleep).await {
                version = v;
            }
        }
    }
}

impl<L: WorldLog> Sensor for Nao<'_, '_, L> {
    async fn switch_on(&self, sensor: SensorId) -> Result<(), SensorFault> {
        let device = self.device(sensor).ok_or(SensorFault::Device(1))?;
        self.world.power(device, true);
        Ok(())
    }

    async fn switch_off(&self, sensor: SensorId) {
        if let Some(device) = self.device(sensor) {
            self.world.power(device, false);
        }
    }

    async fn sample(&self, sensor: SensorId) -> Result<Option<Reading>, SensorFault> {
        let clear = FactSet::single(self.ids.path_clear);
        Ok(match self.device(sensor).ok_or(SensorFault::Device(1))? {
            Device::Sonar => self.world.sonar().map(|mm| {
                let threshold_mm = (self.world.scenario().sonar.threshold_um / 1000) as u32;
                Reading {
                    value: Value::Mm(mm),
                    holds: if mm > 0 && mm < threshold_mm {
                        FactSet::EMPTY
                    } else {
                        clear
                    },
                }
            }),
            Device::Bumper => {
                let level = self.world.bumper();
                Some(Reading {
                    value: Value::Level(level),
                    holds: if level == 2 { FactSet::EMPTY } else { clear },
                })
            }
            Device::Camera => {
                let seen = self.world.camera();
                Some(Reading {
                    value: Value::Bool(seen),
                    holds: if seen {
                        FactSet::single(self.ids.handle_seen)
                    } else {
                        FactSet::EMPTY
                    },
                })
            }
        })
    }
}

impl<L: WorldLog> Actuator for Nao<'_, '_, L> {
    async fn run(&self, action: ActionId, io: &ActionIo<'_>) -> Outcome {
        if action == self.ids.go_to_door {
            self.go_to_door(io).await
        } else if action == self.ids.open_door {
            Timer::after(OPEN_DOOR).await;
            self.world.open_door();
            Outcome::Success
        } else if action == self.ids.enter_kitchen {
            Timer::after(ENTER_KITCHEN).await;
            self.world.enter_kitchen();
            Outcome::Success
        } else {
            Outcome::Failure
        }
    }

    fn hold(&self, _action: ActionId, held: bool) {
        self.world.hold(held);
    }

    fn halt(&self, _action: ActionId) {
        self.world.halt();
    }
}

/// The runtime type of a Fetch Tea run.
pub type NaoRuntime<'r, 'w, 's, L, T> =
    Runtime<'r, 'static, NoopRawMutex, Nao<'w, 's, L>, Nao<'w, 's, L>, T, 3, 3, 2, 4, 4>;

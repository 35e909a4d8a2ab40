//! The Fetch Tea mission as the experiment's tools read it, and how a run is set up. The robot
//! that runs it is `psmpa-fetch-tea`'s, the boards' own, on simulated devices
//! ([`crate::rig`]); this module loads `missions/fetch-tea.json` at run time for what reads the
//! mission without running it (its names in the outputs, the response-time bounds, `check
//! --platform nao`'s requirements), and holds the runtime's settings of a run ([`config`]),
//! its planner ([`PLANNER`]) and a recording's start ([`record_start`]).

use embassy_time::Duration;
use psmpa_core::mission::{self, Bindings, LoadError, Registry};
use psmpa_core::planner::{Planner, Search, Strategy};
use psmpa_core::timing::{Blocking, Job, Response, TimingError};
use psmpa_core::{Config, DomainError, FactId, FactSet, Policy, SensorId, SensorMode, Tables};

use crate::body;
use crate::scenario::Scenario;

/// The Fetch Tea mission file.
pub const FETCH_TEA: &[u8] = include_bytes!("../../missions/fetch-tea.json");

/// A mission of the robot, loaded at run time: its tables, with room for 4 sensors, 8
/// actions, 4 plans of up to 6 actions.
pub type FetchTea<'a> = Tables<'a, 4, 8, 4, 6>;

/// A mission of the robot as the runtime's mission type: its tables (a mission loaded at run
/// time is its tables).
pub type Loaded<'r> = &'r FetchTea<'static>;

/// The bindings of a mission's sensors and actions to the robot's behaviours.
pub type NaoBindings = Bindings<NaoSensor, NaoAction, 4, 8>;

/// The robot's sensor behaviours.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NaoSensor {
    /// Ultrasonic sonar.
    Sonar,
    /// Foot bumper.
    Bumper,
    /// Head camera.
    Camera,
    /// Hand on the door handle.
    Handle,
}

/// The robot's actuator behaviours.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NaoAction {
    /// Walk to the kitchen door.
    GoToDoor,
    /// Press the handle and push the kitchen door.
    OpenDoor,
    /// Walk through the kitchen door.
    EnterKitchen,
    /// Walk on to the back door.
    GoToBackDoor,
    /// Open the back door.
    OpenBackDoor,
    /// Walk through the back door into the kitchen.
    EnterByBackDoor,
}

/// What this robot can run, by the names missions use.
#[derive(Clone, Copy, Debug, Default)]
pub struct NaoRegistry;

impl Registry for NaoRegistry {
    type Sensor = NaoSensor;
    type Action = NaoAction;

    fn sensor(&self, name: &str) -> Option<NaoSensor> {
        Some(match name {
            "sonar" => NaoSensor::Sonar,
            "bumper" => NaoSensor::Bumper,
            "camera" => NaoSensor::Camera,
            "handle" => NaoSensor::Handle,
            _ => return None,
        })
    }

    fn action(&self, name: &str) -> Option<NaoAction> {
        Some(match name {
            "go to door" => NaoAction::GoToDoor,
            "open door" => NaoAction::OpenDoor,
            "enter kitchen" => NaoAction::EnterKitchen,
            "go to back door" => NaoAction::GoToBackDoor,
            "open back door" => NaoAction::OpenBackDoor,
            "enter by back door" => NaoAction::EnterByBackDoor,
            _ => return None,
        })
    }
}

/// Why the robot's mission could not be set up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MissionError {
    /// The mission file is invalid.
    Load(LoadError<'static>),
    /// The mission lacks a fact the robot's sensors decide.
    MissingFact(&'static str),
    /// A sensor the scenario gives a period to is not declared cyclic in the mission.
    NotCyclic(&'static str),
    /// A sensor perceives nothing (`empty`), or a fact other than the one its device gives.
    Perceives {
        /// The sensor.
        sensor: &'static str,
        /// The fact its device gives.
        gives: &'static str,
        /// Its `per` is empty.
        empty: bool,
    },
    /// A scenario period could not be applied.
    Domain(DomainError),
}

impl core::fmt::Display for MissionError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Load(e) => write!(f, "{e}"),
            Self::MissingFact(name) => write!(
                f,
                "the mission has no fact `{name}`, which the robot's sensors decide"
            ),
            Self::NotCyclic(name) => write!(
                f,
                "sensor `{name}` must be `cyclic`: the robot samples it on the scenario's period"
            ),
            Self::Perceives {
                sensor,
                gives,
                empty: true,
            } => write!(
                f,
                "sensor `{sensor}` perceives nothing (its `per` is empty): the robot's {sensor} gives `{gives}`"
            ),
            Self::Perceives { sensor, gives, .. } => write!(
                f,
                "sensor `{sensor}` perceives a fact its device cannot give: the robot's {sensor} gives only `{gives}`"
            ),
            Self::Domain(e) => write!(f, "{e:?}"),
        }
    }
}

/// The facts the robot's sensors decide.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Percepts {
    /// Sonar and bumper.
    pub path_clear: FactId,
    /// Camera.
    pub handle_seen: FactId,
    /// Handle.
    pub door_unlocked: FactId,
}

/// A mission set up for this robot: the mission, its behaviour bindings and percept facts.
#[derive(Clone, Debug)]
pub struct Robot<'a> {
    /// The mission, with the scenario's sampling periods.
    pub mission: FetchTea<'a>,
    /// The behaviour of every sensor and action id.
    pub bindings: NaoBindings,
    /// Percept fact ids.
    pub percepts: Percepts,
}

/// Loads a mission for this robot and gives its cyclic sensors the scenario's periods.
pub fn robot(json: &'static [u8], scenario: &Scenario) -> Result<Robot<'static>, MissionError> {
    let mut robot = Robot::load(json)?;
    robot.apply(scenario)?;
    Ok(robot)
}

impl Robot<'static> {
    /// Loads a mission for this robot, binding its behaviours.
    pub fn load(json: &'static [u8]) -> Result<Self, MissionError> {
        let mut robot = Self::empty();
        robot.load_into(json)?;
        Ok(robot)
    }

    /// [`load`](Self::load) in place: no copy of the mission on the stack (firmware).
    pub fn load_into(&mut self, json: &'static [u8]) -> Result<(), MissionError> {
        mission::load_into(json, &NaoRegistry, &mut self.mission, &mut self.bindings)
            .map_err(MissionError::Load)?;
        self.percepts = requirements(&self.mission.domain, &self.bindings)?;
        Ok(())
    }
}

/// What the robot needs of a mission beyond the names of its behaviours: the facts its sensors
/// decide, and a sonar and a bumper that sample cyclically (the scenario gives them their
/// periods, which would otherwise override a mode the mission declared). `check --platform
/// nao` checks the same.
pub fn requirements<const NS: usize, const NA: usize>(
    d: &psmpa_core::Domain<'_, NS, NA>,
    bindings: &Bindings<NaoSensor, NaoAction, NS, NA>,
) -> Result<Percepts, MissionError> {
    let fact = |name: &'static str| d.fact_id(name).ok_or(MissionError::MissingFact(name));
    let percepts = Percepts {
        path_clear: fact("path_clear")?,
        handle_seen: fact("handle_seen")?,
        door_unlocked: fact("door_unlocked")?,
    };
    for (i, sensor) in d.sensors().iter().enumerate() {
        let bound = SensorId::new(i).and_then(|id| bindings.sensor(id));
        // What each device decides (its `sample`): nothing else may be in its `per`.
        let (name, gives, fact) = match bound {
            Some(NaoSensor::Sonar) => ("sonar", "path_clear", percepts.path_clear),
            Some(NaoSensor::Bumper) => ("bumper", "path_clear", percepts.path_clear),
            Some(NaoSensor::Camera) => ("camera", "handle_seen", percepts.handle_seen),
            Some(NaoSensor::Handle) => ("handle", "door_unlocked", percepts.door_unlocked),
            None => continue,
        };
        if sensor.per.is_empty() || !sensor.per.is_subset(FactSet::single(fact)) {
            return Err(MissionError::Perceives {
                sensor: name,
                gives,
                empty: sensor.per.is_empty(),
            });
        }
        let name = match bound {
            Some(NaoSensor::Sonar) => "sonar",
            Some(NaoSensor::Bumper) => "bumper",
            _ => continue,
        };
        if !matches!(sensor.mode, SensorMode::Cyclic { .. }) {
            return Err(MissionError::NotCyclic(name));
        }
    }
    Ok(percepts)
}

impl Robot<'_> {
    /// No mission yet; usable in a `static`.
    pub const fn empty() -> Self {
        let none = FactId::FIRST;
        Self {
            mission: FetchTea::empty(),
            bindings: Bindings::new(),
            percepts: Percepts {
                path_clear: none,
                handle_seen: none,
                door_unlocked: none,
            },
        }
    }
}

impl Robot<'_> {
    /// Gives the sonar and the bumper the scenario's sampling periods.
    pub fn apply(&mut self, scenario: &Scenario) -> Result<(), MissionError> {
        for i in 0..self.mission.domain.sensors().len() {
            let Some(id) = SensorId::new(i) else { break };
            let period_ms = match self.bindings.sensor(id) {
                Some(NaoSensor::Sonar) => scenario.sonar.period_ms,
                Some(NaoSensor::Bumper) => scenario.bumper_period_ms,
                _ => continue,
            };
            self.mission
                .domain
                .set_sensor_mode(
                    id,
                    SensorMode::Cyclic {
                        period: Duration::from_millis(period_ms),
                    },
                )
                .map_err(MissionError::Domain)?;
        }
        Ok(())
    }
}

/// The Fetch Tea mission for `scenario`.
pub fn fetch_tea(scenario: &Scenario) -> Result<Robot<'static>, MissionError> {
    robot(FETCH_TEA, scenario)
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

/// What a recording's decisions depend on: the mission, the scenario's bytes (a file's, or
/// the canonical form a firmware embeds), the architecture. Its header carries it, so that a
/// replay against another mission is refused.
pub fn mission_hash(scenario: &[u8], arch: Arch) -> u64 {
    let mut h = psmpa_core::TraceHash::new();
    h.write(FETCH_TEA);
    h.write(scenario);
    h.write(&[arch.byte()]);
    h.value()
}

impl Arch {
    /// Its byte in a recording's prologue.
    pub const fn byte(self) -> u8 {
        match self {
            Self::PSmpa => 0,
            Self::Smpa => 1,
        }
    }
}

/// Writes a recording's start to `out`: the core's header (`mission`, from [`mission_hash`])
/// and the prologue, the scenario's bytes with the architecture's byte as its kind
/// ([`psmpa_core::record::write_start`]). The frames follow.
pub fn record_start(
    out: &mut impl psmpa_core::record::RecordOut,
    mission: u64,
    scenario: &[u8],
    arch: Arch,
) {
    use psmpa_core::record::{self, Header};
    record::write_start(out, &Header::new(1, mission), scenario, arch.byte());
}

/// The runtime settings of a run: only the policy differs between the architectures.
pub fn config(scenario: &Scenario, arch: Arch) -> Config {
    let mut config = Config::default();
    config.policy = match arch {
        Arch::PSmpa => Policy::PSmpa,
        Arch::Smpa => Policy::Smpa {
            sense: Duration::from_millis(scenario.sense_ms),
            act: Duration::from_millis(scenario.act_ms),
        },
    };
    // The robot waits for an obstacle to be avoided or taken away; give up only if the path
    // stays blocked for a minute.
    config.max_violation = Duration::from_secs(60);
    config.max_failures = 3;
    config.max_plans = 8;
    config.max_lost = 10;
    config
}

/// The reaction latency the runtime promises for one cyclic sensor
/// ([`psmpa_core::timing::latency_bound`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LatencyBound {
    /// The sensor.
    pub sensor: SensorId,
    /// Its sampling job.
    pub job: Job,
    /// Its worst response.
    pub response: Response,
    /// The bound, ns.
    pub bound_ns: u64,
}

impl Robot<'_> {
    /// How long a read of `sensor` that registers an obstacle takes in `scenario` at most, ns
    /// (the camera and the handle: none). The sonar is an HC-SR04 on the rig: its trigger,
    /// then the echo of the farthest distance that registers (the scenario's read latency if
    /// that is later), and the tick its read ends on (the rig's reads end on a tick).
    pub fn read_latency_ns(&self, sensor: SensorId, scenario: &Scenario) -> u64 {
        let ms = |ms: u64| ms.saturating_mul(1_000_000);
        match self.bindings.sensor(sensor) {
            Some(NaoSensor::Sonar) => {
                let farthest = u32::try_from(scenario.sonar.threshold_mm()).unwrap_or(u32::MAX);
                let echo = body::ECHO_DELAY_NS.saturating_add(body::echo_ns(farthest));
                let tick = 1_000_000_000 / embassy_time::TICK_HZ;
                body::TRIGGER_NS
                    .saturating_add(echo.max(ms(scenario.sonar.latency_ms)))
                    .saturating_add(tick)
            }
            Some(NaoSensor::Bumper) => ms(scenario.bumper_latency_ms),
            _ => 0,
        }
    }
}

/// The reaction-latency bound of every cyclic sensor of `robot`'s mission (after
/// [`Robot::apply`]) under P-SMPA: the response-time analysis of [`psmpa_core::timing`] with
/// the read latencies ([`Robot::read_latency_ns`]), the sample step `cost_ns` of each sensor, the behaviour step
/// `reaction_ns`, the `blocking` of the platform and its `interrupts` (jobs that only
/// interfere: a timer's alarm). In virtual time, where computing takes no time, costs and
/// blocking are 0 and only the read latencies remain. Latencies count from the instant a
/// sensor is certain to register the obstacle (see [`crate::world`]), so no margin for noise
/// is needed.
pub fn latency_bounds(
    robot: &Robot<'_>,
    scenario: &Scenario,
    blocking: Blocking,
    reaction_ns: u64,
    cost_ns: impl Fn(SensorId) -> u64,
    interrupts: &[Job],
) -> Result<heapless::Vec<LatencyBound, 4>, TimingError> {
    let max_lost = config(scenario, Arch::PSmpa).max_lost;
    let domain = &robot.mission.domain;
    let sensors: heapless::Vec<(SensorId, Job), 4> = (0..domain.sensors().len())
        .filter_map(SensorId::new)
        .filter_map(|id| match domain.sensor(id)?.mode {
            SensorMode::Cyclic { period } => Some((
                id,
                Job {
                    period_ns: period.as_micros().saturating_mul(1_000),
                    cost_ns: cost_ns(id),
                    latency_ns: robot.read_latency_ns(id, scenario),
                },
            )),
            _ => None,
        })
        .collect();
    // The sensors first, then the interrupts: at most 4 of each count.
    let jobs: heapless::Vec<Job, 8> = sensors
        .iter()
        .map(|(_, j)| *j)
        .chain(interrupts.iter().take(4).copied())
        .collect();
    let mut bounds = heapless::Vec::new();
    for (i, (sensor, job)) in sensors.iter().enumerate() {
        let response = psmpa_core::timing::response(&jobs, i, blocking, reaction_ns)?;
        // At most 4 cyclic sensors: room for each.
        let _ = bounds.push(LatencyBound {
            sensor: *sensor,
            job: *job,
            response,
            bound_ns: psmpa_core::timing::latency_bound(response, max_lost, 0),
        });
    }
    Ok(bounds)
}

/// The planner the robot uses when no library plan applies: shortest plans, 32 nodes. The
/// Fetch Tea actions add and delete five facts (`at_door`, `door_open`, `at_back_door`,
/// `back_door_open`, `in_kitchen`; what the sensors perceive no action changes), so at most
/// 2⁵ = 32 states are reachable and a breadth-first search, which stores each state once,
/// cannot run out.
pub const PLANNER: Planner<32> = Planner::new(Strategy::BreadthFirst);

/// The space [`PLANNER`] searches in (about 1 KiB).
pub type PlannerSpace = Search<32>;

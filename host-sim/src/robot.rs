//! The robot of the paper's experiment, written against `psmpa-core` the way an application
//! would: the "Fetch Tea" mission is the JSON file `missions/fetch-tea.json` (embedded at build
//! time), whose sensor and action names are bound to this robot's behaviours through a
//! [`Registry`]; the behaviours act on a simulated [`World`].
//!
//! * "go to door" needs `path_clear`, which the sonar and the foot bumper perceive (cyclic):
//!   Algorithm 2 runs both beside the walk. The walk reads their samples from the mutual store
//!   (Algorithm 3): it stops for a sonar echo below the threshold or a pressed bumper, and, in
//!   scenarios with a slow zone, slows down as the sonar distance falls.
//! * A sample takes the scenario's `latency_ms` of that sensor (an echo, a debounce): only
//!   that sensor waits; it reports the world as it was when the read started.
//! * "open door" needs `handle_seen` (camera, one shot) and `door_unlocked` (the hand on the
//!   handle, on demand): the behaviour presses the handle before pushing the door.
//! * A locked kitchen door fails "open door"; the control loop then plans again from what the
//!   robot now believes and takes the back door.

use embassy_futures::select::{Either, select};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::{NoopRawMutex, RawMutex};
use embassy_time::{Duration, Instant, Timer};
use psmpa_core::mission::{self, Bindings, LoadError, Registry};
use psmpa_core::planner::{Planner, Search, Strategy};
use psmpa_core::timing::{Blocking, Job, Response, TimingError};
use psmpa_core::{
    Act, ActionIo, ActionOf, Actuator, Config, DomainError, Entry, FactId, FactSet, Key, Mission,
    Outcome, Platform, Policy, Reading, Runtime, Sensor, SensorAction, SensorFault, SensorId,
    SensorMode, SensorOf, Tables, Value,
};

use crate::scenario::Scenario;
use crate::world::{Device, Motion, Place, World, WorldLog};

/// The Fetch Tea mission file.
pub const FETCH_TEA: &[u8] = include_bytes!("../../missions/fetch-tea.json");

/// Time to push a door open once it gives.
pub const OPEN_DOOR: Duration = Duration::from_millis(1_000);
/// Time to walk through an open door.
pub const ENTER_KITCHEN: Duration = Duration::from_millis(1_000);

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
    /// How long a read of `sensor` takes in `scenario`, ms (the camera and the handle: none).
    pub fn read_latency_ms(&self, sensor: SensorId, scenario: &Scenario) -> u64 {
        match self.bindings.sensor(sensor) {
            Some(NaoSensor::Sonar) => scenario.sonar.latency_ms,
            Some(NaoSensor::Bumper) => scenario.bumper_latency_ms,
            _ => 0,
        }
    }
}

/// The reaction-latency bound of every cyclic sensor of `robot`'s mission (after
/// [`Robot::apply`]) under P-SMPA: the response-time analysis of [`psmpa_core::timing`] with
/// the scenario's read latencies, the sample step `cost_ns` of each sensor, the behaviour step
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
                    latency_ns: robot
                        .read_latency_ms(id, scenario)
                        .saturating_mul(1_000_000),
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

/// Application-defined trace codes of the robot's behaviours.
pub mod codes {
    /// The walk stopped for an obstacle and started a side step.
    pub const AVOID: u16 = 1;
    /// The side step ended and the walk resumed.
    pub const RESUME: u16 = 2;
    /// The door handle did not give: the door is locked.
    pub const LOCKED: u16 = 3;
    /// The walk changed its speed (value: thousandths of full speed).
    pub const SPEED: u16 = 4;
}

/// Where the sonar puts the round-trip time of its echo, µs, beside the distance (Algorithm 3:
/// a sensor's own `(k', v')` pairs).
pub const ECHO_US: Key = Key(1);

/// The slowest the walk goes in the slow zone, thousandths of full speed.
pub const SLOWEST_PERMILLE: u16 = 250;

/// How far the robot must walk, by odometry, while an echo in range keeps the same distance,
/// before the sonar counts as stuck: walking towards an object must bring its echo closer.
pub const STUCK_AFTER_UM: i64 = 50_000;

/// The robot: the platform implementation of the mission's sensors and behaviours. Its
/// sensors and its behaviours run on the two sides of the runtime; what they share sits behind
/// the mutex `M`, as the world's state does.
pub struct Nao<'w, 's, L: WorldLog, M: RawMutex = NoopRawMutex> {
    world: &'w World<'s, L, M>,
    bindings: NaoBindings,
    percepts: Percepts,
    /// The sonar's last echo in range and the odometry when it was first read.
    echo: Mutex<M, core::cell::Cell<Option<(u32, i64)>>>,
    /// The sonar and the bumper of the mission, if it has them.
    sonar: Option<SensorId>,
    bumper: Option<SensorId>,
    /// Their sample timeouts: a read at least this long never answers.
    timeouts: [Duration; 2],
    /// Spends processor time: nothing on the host, busy cycles on a microcontroller.
    compute: fn(u32),
}

impl<'w, 's, L: WorldLog, M: RawMutex> Nao<'w, 's, L, M> {
    /// The robot in `world`, running `robot`'s behaviours.
    pub fn new(world: &'w World<'s, L, M>, robot: &Robot<'_>) -> Self {
        let find = |which: NaoSensor| robot.bindings.sensor_id(&which);
        let timeout = |id: Option<SensorId>| {
            id.and_then(|id| robot.mission.domain.sensor(id))
                .map_or(SensorAction::<'_, 1>::DEFAULT_TIMEOUT, |s| s.timeout)
        };
        let (sonar, bumper) = (find(NaoSensor::Sonar), find(NaoSensor::Bumper));
        Self {
            world,
            bindings: robot.bindings.clone(),
            percepts: robot.percepts,
            echo: Mutex::new(core::cell::Cell::new(None)),
            sonar,
            bumper,
            timeouts: [timeout(sonar), timeout(bumper)],
            compute: |_| {},
        }
    }

    /// The robot, spending the scenario's `plan_us` of processor time through `compute` each
    /// time its walk starts or resumes.
    #[must_use]
    pub fn with_compute(mut self, compute: fn(u32)) -> Self {
        self.compute = compute;
        self
    }

    /// Whether a sample read from the mutual store shows an obstacle in the way: a sonar echo
    /// below the threshold, or the bumper pressed.
    fn shows_obstacle(&self, sensor: Option<SensorId>, entry: Entry) -> bool {
        let sonar = self.world.scenario().sonar;
        match entry.value {
            Value::Mm(mm) => sensor == self.sonar && sonar.registers(i64::from(mm)),
            Value::Level(level) => sensor == self.bumper && level == 2,
            _ => false,
        }
    }

    /// The walking speed the latest sonar reading calls for, thousandths of full speed: full
    /// outside the scenario's slow zone, falling linearly to [`SLOWEST_PERMILLE`] at the
    /// threshold.
    fn speed_for(&self, reading: Option<Entry>) -> u16 {
        let sc = self.world.scenario();
        let threshold_mm = sc.sonar.threshold_mm();
        let slow_mm = crate::scenario::to_mm(sc.slow_um);
        let Some(Value::Mm(mm)) = reading.map(|e| e.value) else {
            return 1000;
        };
        let mm = i64::from(mm);
        if slow_mm <= threshold_mm || mm >= slow_mm {
            return 1000;
        }
        let slowest = i64::from(SLOWEST_PERMILLE);
        let span = slow_mm - threshold_mm;
        let permille = slowest + (1000 - slowest) * (mm - threshold_mm).max(0) / span;
        u16::try_from(permille.clamp(slowest, 1000)).unwrap_or(1000)
    }

    /// Walk to `place`, deciding from the samples of the sonar and the bumper in the mutual
    /// store: an echo below the threshold or a pressed bumper stops the walk for a side step;
    /// in a slow zone the walk slows down as the echo comes nearer. A sample counts only if it
    /// was taken at or after the end of the last side step (or the start of the walk): the
    /// world settles a step before a sample at that instant, and under SMPA the store keeps
    /// the sense phase's samples, stale, through the act phase. A violation of the
    /// precondition seen since then stops it too (a sensor this walk does not read). Each time
    /// it starts or resumes, it first plans its path: the scenario's `plan_us` of processor
    /// time on a microcontroller, none in virtual time.
    async fn walk<Ms: Mission<Facts = FactSet>>(
        &self,
        place: Place,
        io: &ActionIo<'_, Ms>,
    ) -> Outcome {
        let world = self.world;
        let mut handled = Instant::now();
        let mut stepping = false;
        let mut version = io.version();
        // Planning the path takes processor time: on a microcontroller this poll of the
        // deciding side is that long, and sensing goes on meanwhile.
        let plan = || {
            let us = world.scenario().plan_us;
            if us > 0 {
                (self.compute)(us);
            }
        };
        plan();
        loop {
            // One look at the world for the loop's questions.
            let (motion, arrived, speed_now) = world.legs(place);
            if !matches!(motion, Motion::Avoiding { .. }) {
                if stepping {
                    // The side step ended: samples from now on count; plan the way on.
                    stepping = false;
                    handled = Instant::now();
                    io.trace(codes::RESUME, 0);
                    plan();
                }
                if arrived {
                    world.stop();
                    world.arrived(place);
                    return Outcome::Success;
                }
                let fresh = |e: &Entry| e.at >= handled;
                let latest = self.sonar.and_then(|s| io.sample(s));
                let sonar = latest.filter(fresh);
                let bumper = self.bumper.and_then(|s| io.sample(s)).filter(fresh);
                let seen = sonar.filter(|e| self.shows_obstacle(self.sonar, *e));
                let felt = bumper.filter(|e| self.shows_obstacle(self.bumper, *e));
                // The runtime's verdict too, for sensors this walk does not read.
                let other = io.violation().is_some_and(|v| v.last_seen >= handled);
                if seen.is_some() || felt.is_some() || other {
                    world.stop();
                    world.begin_avoid();
                    stepping = true;
                    handled = Instant::now();
                    let mm = match seen.map(|e| e.value) {
                        Some(Value::Mm(mm)) => mm,
                        _ => 0,
                    };
                    io.trace(codes::AVOID, mm);
                    continue;
                }
                let speed = self.speed_for(latest);
                if speed != speed_now {
                    world.set_speed(speed);
                    io.trace(codes::SPEED, i32::from(speed));
                }
                if motion != Motion::Walking {
                    world.walk_to(place);
                }
            }
            // The change-or-deadline wait written out: `ActionIo::changed_until` costs 156 B more
            // flash here, and the simulator firmware has little to spare.
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

    /// "open door": press the handle (an on-demand sample), then push the door if it gives.
    async fn open_door<Ms: Mission<Facts = FactSet>>(&self, io: &ActionIo<'_, Ms>) -> Outcome {
        let handle = self.bindings.sensor_id(&NaoSensor::Handle);
        if let Some(handle) = handle {
            let asked = Instant::now();
            io.request(handle);
            let mut version = io.version();
            // Under SMPA the request is served in the next sense phase.
            while io.sample(handle).is_none_or(|e| e.at < asked) {
                version = io.changed(version).await;
            }
            if io.violation().is_some() {
                io.trace(codes::LOCKED, 0);
                return Outcome::Interrupted;
            }
        }
        Timer::after(OPEN_DOOR).await;
        self.world.open_door(Place::KitchenDoor);
        Outcome::Success
    }
}

/// The robot runs any mission of one word of facts whose sensors and actions its bindings name
/// (the mission loaded at run time, or the same file compiled in): it reads them by id.
impl<Ms: Mission<Facts = FactSet>, L: WorldLog, M: RawMutex> Sensor<Ms> for Nao<'_, '_, L, M> {
    async fn switch_on(&self, sensor: Ms::Sensor) -> Result<(), SensorFault> {
        let device = self.device(sensor.id()).ok_or(SensorFault::Device(1))?;
        if device == Device::Sonar {
            // What the echo did before the sonar was off says nothing about it now: under SMPA
            // the robot walks between sense phases, and the next box, put down as far ahead
            // as the last, echoes at the same distance.
            self.echo.lock(|e| e.set(None));
        }
        self.world.power(device, true);
        Ok(())
    }

    async fn switch_off(&self, sensor: Ms::Sensor) {
        if let Some(device) = self.device(sensor.id()) {
            self.world.power(device, false);
        }
    }

    async fn sample(&self, sensor: Ms::Sensor) -> Result<Option<Reading>, SensorFault> {
        let sensor = sensor.id();
        let p = self.percepts;
        let clear = FactSet::single(p.path_clear);
        let when = |yes: bool, fact: FactId| {
            if yes {
                FactSet::single(fact)
            } else {
                FactSet::EMPTY
            }
        };
        let sc = self.world.scenario();
        Ok(match self.device(sensor).ok_or(SensorFault::Device(1))? {
            Device::Sonar => {
                let Some(echo) = self.world.sonar_start() else {
                    // Silent: the echo never comes, and the runtime's sample timeout notices.
                    return core::future::pending().await;
                };
                // The ping's round trip: only this sensor waits.
                read_latency(read_time(sc.sonar.latency_ms, self.timeouts[0])).await;
                let Some(mm) = self.world.sonar_deliver(echo) else {
                    return Ok(None);
                };
                self.check_sonar(mm, echo.pos_um)?;
                self.world.sample_delivered(Device::Sonar);
                let max_mm = crate::scenario::to_mm(sc.sonar.max_um);
                let mm = i32::try_from(mm).map_err(|_| SensorFault::OutOfRange)?;
                // The rule the world registers obstacles by.
                let holds = if sc.sonar.registers(i64::from(mm)) {
                    FactSet::EMPTY
                } else {
                    clear
                };
                // Sound at about 343 m/s: 5.83 µs per mm, there and back. No echo, no time:
                // the pair is put either way, so the store never keeps an earlier echo's.
                let (value, echo_us) = if i64::from(mm) == max_mm {
                    (Value::NoEcho, Value::NoEcho)
                } else {
                    (Value::Mm(mm), Value::Int(mm.saturating_mul(583) / 100))
                };
                let reading = Reading::new(value, holds).with(ECHO_US, echo_us);
                Some(reading.map_err(|_| SensorFault::Device(2))?)
            }
            Device::Bumper => {
                let touch = self.world.bumper_read();
                read_latency(read_time(sc.bumper_latency_ms, self.timeouts[1])).await;
                let level = self.world.bumper_deliver(touch);
                self.world.sample_delivered(Device::Bumper);
                let holds = if level == 2 { FactSet::EMPTY } else { clear };
                Some(Reading::new(Value::Level(level), holds))
            }
            Device::Camera => {
                let seen = self.world.camera();
                Some(Reading::new(Value::Bool(seen), when(seen, p.handle_seen)))
            }
            Device::Handle => {
                let gives = self.world.handle();
                Some(Reading::new(
                    Value::Bool(gives),
                    when(gives, p.door_unlocked),
                ))
            }
        })
    }
}

/// How long a read takes: `None` when it never answers, as a read at least as long as the
/// sensor's timeout must not (the contract: every such sample times out; an answer due on the
/// very tick of the timeout would otherwise win).
fn read_time(latency_ms: u64, timeout: Duration) -> Option<Duration> {
    let latency = Duration::from_millis(latency_ms);
    (latency < timeout).then_some(latency)
}

/// Waits out a read of `read_time`; no await at all for an instant one. Only the timer lives
/// across the await: this future is in every sampler's.
async fn read_latency(read: Option<Duration>) {
    match read {
        Some(d) if d.as_ticks() == 0 => {}
        Some(d) => Timer::after(d).await,
        None => core::future::pending().await,
    }
}

impl<L: WorldLog, M: RawMutex> Nao<'_, '_, L, M> {
    /// The sonar driver's plausibility checks: a reading outside the sonar's range is a device
    /// fault; an echo in range that keeps the same distance while the robot walks on, the sonar
    /// on all along, is stuck. (A sonar stuck at its maximum, "nothing in range", cannot be told
    /// from an empty path; nor, under SMPA, a stuck one, as the robot never walks while it is
    /// on.)
    fn check_sonar(&self, mm: u32, at: i64) -> Result<(), SensorFault> {
        let sonar = self.world.scenario().sonar;
        let (min, max) = (
            crate::scenario::to_mm(sonar.min_um),
            crate::scenario::to_mm(sonar.max_um),
        );
        if !(min..=max).contains(&i64::from(mm)) {
            return Err(SensorFault::OutOfRange);
        }
        if i64::from(mm) == max {
            self.echo.lock(|e| e.set(None));
            return Ok(());
        }
        match self.echo.lock(core::cell::Cell::get) {
            Some((last, since)) if last == mm => {
                if at - since >= STUCK_AFTER_UM {
                    return Err(SensorFault::Stuck);
                }
            }
            _ => self.echo.lock(|e| e.set(Some((mm, at)))),
        }
        Ok(())
    }

    fn device(&self, sensor: SensorId) -> Option<Device> {
        Some(match self.bindings.sensor(sensor)? {
            NaoSensor::Sonar => Device::Sonar,
            NaoSensor::Bumper => Device::Bumper,
            NaoSensor::Camera => Device::Camera,
            NaoSensor::Handle => Device::Handle,
        })
    }
}

impl<Ms: Mission<Facts = FactSet>, L: WorldLog, M: RawMutex> Actuator<Ms> for Nao<'_, '_, L, M> {
    async fn run(&self, act: Act<'_, Ms>) -> Outcome {
        let io = act.untyped();
        let Some(behaviour) = self.bindings.action(io.action().id()) else {
            return Outcome::Failure;
        };
        match behaviour {
            NaoAction::GoToDoor => self.walk(Place::KitchenDoor, &io).await,
            NaoAction::GoToBackDoor => self.walk(Place::BackDoor, &io).await,
            NaoAction::OpenDoor => self.open_door(&io).await,
            NaoAction::OpenBackDoor => {
                Timer::after(OPEN_DOOR).await;
                self.world.open_door(Place::BackDoor);
                Outcome::Success
            }
            NaoAction::EnterKitchen | NaoAction::EnterByBackDoor => {
                Timer::after(ENTER_KITCHEN).await;
                self.world.enter_kitchen();
                Outcome::Success
            }
        }
    }

    fn hold(&self, _action: Ms::Action, held: bool) {
        self.world.hold(held);
    }

    fn halt(&self, _action: Ms::Action) {
        self.world.halt();
    }
}

impl<L: WorldLog, M: RawMutex> Platform for Nao<'_, '_, L, M> {
    type Mutex = M;
}

/// The runtime type of a Fetch Tea run, its two sides sharing state through `M`.
pub type NaoRuntime<'r, 'w, 's, L, T, M = NoopRawMutex> =
    Runtime<'r, Loaded<'r>, Nao<'w, 's, L, M>, T>;

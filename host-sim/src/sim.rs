//! Host runs of a scenario in virtual time, with everything recorded for the outputs.

use embassy_time::{Duration, Instant};
use psmpa_core::{TraceEvent, TraceSink};

use crate::backend::{SimError, simulate_split};
use crate::rig::{self, Chassis, Observed, Rig};
use crate::robot::{self, Arch, MissionError};
use crate::run::{Summary, decide_on, summary};
use crate::scenario::Scenario;
use crate::world::{WorldEvent, WorldLog};
use psmpa_fetch_tea::fetch_tea;

/// Every world event with its time (ms) and the robot's position (µm).
#[derive(Debug, Default, Clone)]
pub struct WorldRecord(pub Vec<(u64, i64, WorldEvent)>);

impl WorldLog for WorldRecord {
    fn log(&mut self, at_ms: u64, pos_um: i64, event: WorldEvent) {
        self.0.push((at_ms, pos_um, event));
    }
}

/// Every runtime trace event with its time.
#[derive(Debug, Default, Clone)]
pub struct TraceRecord(pub Vec<(Instant, TraceEvent)>);

impl<Ms: psmpa_core::Mission<Facts = psmpa_core::FactSet>> TraceSink<Ms> for TraceRecord {
    fn record(&mut self, at: Instant, event: &TraceEvent) {
        self.0.push((at, *event));
    }
}

/// Why a host run failed (never because of the scenario's outcome).
#[derive(Debug)]
pub enum RunError {
    /// The mission could not be built.
    Mission(MissionError),
    /// The simulation deadlocked or ran past its limit.
    Sim(SimError),
    /// The caller's `stop` said so ([`run_logged_until`]): an output failed.
    Stopped,
    /// The simulated devices were asked to schedule more input changes than they hold.
    Rig,
}

impl std::fmt::Display for RunError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Mission(e) => write!(f, "the mission could not be built: {e:?}"),
            Self::Sim(e) => write!(f, "simulation failed: {e}"),
            Self::Stopped => write!(f, "the run was stopped"),
            Self::Rig => write!(
                f,
                "the simulated devices scheduled more than {} input changes at once",
                rig::PENDING
            ),
        }
    }
}

impl std::error::Error for RunError {}

/// A recorded run.
#[derive(Debug, Clone)]
pub struct Recorded {
    /// The summary.
    pub summary: Summary,
    /// The world's events.
    pub world: WorldRecord,
    /// The runtime's trace.
    pub trace: TraceRecord,
}

/// Virtual time allowed beyond `max_s`: the run stops itself at `max_s`.
const SLACK: Duration = Duration::from_secs(1);

/// Runs `scenario` under `arch` with nothing recorded (fast path for sweeps and benchmarks).
pub fn run_summary(scenario: &Scenario, arch: Arch) -> Result<Summary, RunError> {
    run_logged(scenario, arch, (), psmpa_core::Hashing).map(|(s, (), _)| s)
}

/// Runs `scenario` under `arch`, logging the world into `log` and tracing the runtime into
/// `sink` as the run goes; gives both back with the summary.
pub fn run_logged<L: WorldLog, T: TraceSink<fetch_tea::FetchTea>>(
    scenario: &Scenario,
    arch: Arch,
    log: L,
    sink: T,
) -> Result<(Summary, L, T), RunError> {
    run_logged_until(scenario, arch, log, sink, || false)
}

/// [`run_logged`], asking `stop` at every step of the run (every wake of its sensing or
/// deciding side): when it answers `true` the run ends at once with [`RunError::Stopped`]. A
/// command whose output failed (`--trace /dev/full`) stops there instead of simulating on.
pub fn run_logged_until<L: WorldLog, T: TraceSink<fetch_tea::FetchTea>>(
    scenario: &Scenario,
    arch: Arch,
    log: L,
    sink: T,
    stop: impl Fn() -> bool,
) -> Result<(Summary, L, T), RunError> {
    run_with(scenario, Setup::new(arch), log, sink, stop)
}

/// Runs `scenario` under `arch` recording the world and the trace in memory.
pub fn run_recorded(scenario: &Scenario, arch: Arch) -> Result<Recorded, RunError> {
    let (summary, world, trace) = run_logged(
        scenario,
        arch,
        WorldRecord::default(),
        TraceRecord::default(),
    )?;
    Ok(Recorded {
        summary,
        world,
        trace,
    })
}

/// Which of the runtime's paths a run takes through its plans ([`run_on`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PlanPath {
    /// The plans' states as constants: Algorithm 2 at build time, each sensor's own sampler
    /// (what every command runs).
    #[default]
    Compiled,
    /// The same plans through the run-time FSM.
    CompiledRunTime,
}

/// How a run is set up beyond its scenario.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Setup {
    /// The architecture.
    pub arch: Arch,
    /// The body the robot drives.
    pub chassis: Chassis,
    /// The runtime's path through the plans.
    pub plans: PlanPath,
}

impl Setup {
    /// `arch` on the paper's NAO along the compiled plans: what psmpa-sim's commands run.
    pub const fn new(arch: Arch) -> Self {
        Self {
            arch,
            chassis: Chassis::Nao,
            plans: PlanPath::Compiled,
        }
    }
}

/// Runs `scenario` under `arch` along `path`, with nothing recorded but the trace's hash: the
/// two paths of one mission give one trace (`host-sim/tests/differential.rs`).
pub fn run_on(scenario: &Scenario, arch: Arch, path: PlanPath) -> Result<Summary, RunError> {
    let setup = Setup {
        plans: path,
        ..Setup::new(arch)
    };
    run_with(scenario, setup, (), psmpa_core::Hashing, || false).map(|(s, (), _)| s)
}

/// Runs `scenario` on `chassis` under `arch`, with nothing recorded: the one robot's outcome
/// on that body (the bench compares the chip's with it on [`Chassis::Wheeled`]).
pub fn run_chassis(scenario: &Scenario, arch: Arch, chassis: Chassis) -> Result<Summary, RunError> {
    let setup = Setup {
        chassis,
        ..Setup::new(arch)
    };
    run_with(scenario, setup, (), psmpa_core::Hashing, || false).map(|(s, (), _)| s)
}

/// Runs `scenario` as `setup` says: the Fetch Tea robot of `psmpa-fetch-tea`, calibrated for
/// the scenario and its chassis ([`rig::settings_for`]), on the simulated devices of its body
/// in the world ([`rig::Rig`]), logging the world into `log` and tracing the runtime into
/// `sink`; `stop` as [`run_logged_until`]'s.
pub fn run_with<L: WorldLog, T: TraceSink<fetch_tea::FetchTea>>(
    scenario: &Scenario,
    setup: Setup,
    log: L,
    sink: T,
    stop: impl Fn() -> bool,
) -> Result<(Summary, L, T), RunError> {
    use embassy_futures::join::join;
    let limit = Duration::from_millis(scenario.max_ms) + SLACK;
    let settings = rig::settings_for(scenario, setup.chassis);
    let rig: Rig<'_, L> = Rig::new(
        scenario,
        log,
        settings.walk_permille.unsigned_abs(),
        rig::sensor_ids(),
    );
    let robot = rig.robot(settings, setup.chassis);
    let mut space = robot::PlannerSpace::new();
    let mut config = robot::config(scenario, setup.arch);
    config.plans = match setup.plans {
        PlanPath::Compiled => psmpa_core::Plans::Compiled,
        PlanPath::CompiledRunTime => psmpa_core::Plans::RunTime,
    };
    let mut runtime = fetch_tea::Runtime::new(
        fetch_tea::FetchTea,
        &robot,
        Observed::new(&rig, sink),
        config,
    );
    for (sensor, period) in [
        (fetch_tea::Sensor::Sonar, settings.sonar_period),
        (fetch_tea::Sensor::Bumper, settings.bumper_period),
    ] {
        runtime.set_period(sensor, period);
    }
    let (mut sensing, mut deciding) = runtime.split();
    let decided = async {
        let mut run = core::pin::pin!(decide_on(&mut deciding, scenario, &mut space, || {
            rig.halt()
        }));
        core::future::poll_fn(|cx| {
            if stop() {
                return core::task::Poll::Ready(None);
            }
            run.as_mut().poll(cx).map(Some)
        })
        .await
    };
    let done =
        simulate_split(join(sensing.run(), rig.pump()), decided, limit).map_err(RunError::Sim)?;
    let ended = done.output.ok_or(RunError::Stopped)?;
    if rig.overflowed() {
        return Err(RunError::Rig);
    }
    let summary = rig.world(|w| summary(setup.arch, w, &runtime, ended));
    let sink = runtime.into_sink().into_inner();
    drop(robot);
    Ok((summary, rig.into_world().into_log(), sink))
}

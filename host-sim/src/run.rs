//! One run of a scenario under one architecture: the Fetch Tea mission on the simulated world
//! until the goal holds, the control loop gives up, or `max_s` passes.
//!
//! `no_std`: the firmware awaits [`run`] inside an embassy task, the host inside
//! [`backend::simulate`](crate::backend::simulate).

use embassy_futures::select::{Either, select};
use embassy_time::{Instant, Timer};
use psmpa_core::{ControlError, Report, Runtime, TraceSink};

use crate::robot::{self, Arch, MissionError, Nao, Robot};
use crate::scenario::Scenario;
use crate::world::{ObstacleReport, Tally, World, WorldLog};

/// How the control loop ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ending {
    /// The goal holds.
    Goal(Report),
    /// The control loop stopped with an error.
    Error(ControlError),
    /// `max_s` passed first.
    TimeLimit,
}

/// The result of one run: the contract's summary fields and a little more.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Summary {
    /// The architecture.
    pub arch: Arch,
    /// What the world counted.
    pub tally: Tally,
    /// How each interference ended, in scenario order.
    pub obstacles: heapless::Vec<ObstacleReport, { crate::scenario::MAX_INTERFERENCES }>,
    /// When the run ended, ms: the time cost.
    pub time_cost_ms: u64,
    /// How the control loop ended.
    pub ending: Ending,
    /// Hash of the run: the runtime's trace followed by the world's events.
    pub trace_hash: u64,
    /// Events in the runtime's trace.
    pub trace_events: u32,
}

/// Runs `scenario` under `arch`, logging the world into `log` and tracing the runtime into
/// `sink`; returns the summary and gives the log and the sink back.
pub async fn run<L: WorldLog, T: TraceSink>(
    scenario: &Scenario,
    arch: Arch,
    log: L,
    sink: T,
) -> Result<(Summary, L, T), MissionError> {
    let robot = robot::fetch_tea(scenario)?;
    Ok(run_robot(&robot, scenario, arch, log, sink).await)
}

/// Runs a mission already loaded for `scenario` ([`robot::fetch_tea`]). The run starts at the
/// current instant; the host and the firmware start it at tick 0 so their traces agree.
pub async fn run_robot<L: WorldLog, T: TraceSink>(
    robot: &Robot<'_>,
    scenario: &Scenario,
    arch: Arch,
    log: L,
    sink: T,
) -> (Summary, L, T) {
    let world = World::new(scenario, log);
    let nao = Nao::new(&world, robot);
    let runtime: robot::NaoRuntime<'_, '_, '_, '_, L, T> = Runtime::new(
        &robot.mission,
        &nao,
        &nao,
        sink,
        robot::config(scenario, arch),
    );
    let deadline = Timer::at(Instant::from_millis(scenario.max_ms));
    let ending = match select(runtime.run_planning(&robot::PLANNER), deadline).await {
        Either::First(Ok(report)) => Ending::Goal(report),
        Either::First(Err(error)) => Ending::Error(error),
        Either::Second(()) => {
            world.halt();
            Ending::TimeLimit
        }
    };
    let summary = Summary {
        arch,
        tally: world.tally(),
        obstacles: world.obstacles(),
        time_cost_ms: Instant::now().as_millis(),
        ending,
        trace_hash: {
            let mut h = runtime.trace_hash();
            h.write(&world.hash().value().to_le_bytes());
            h.value()
        },
        trace_events: runtime.trace_events(),
    };
    let sink = runtime.into_sink();
    (summary, world.into_log(), sink)
}

//! One run of a scenario under one architecture: the Fetch Tea mission on the simulated world
//! until the goal holds, the control loop gives up, or `max_s` passes.
//!
//! `no_std`: the pieces of a run, which the host and the firmware put together each in its own
//! way. The rig (the robot's body in the world, [`crate::rig::Rig::new`]), the robot on it
//! and the runtime are built where they stay; the runtime is split; the sensing side runs at a
//! higher priority (the host's poll loop, through `simulate_split`; a task on the firmware's
//! interrupt executor) beside [`decide_on`]; and [`summary`] reads the outcome.

use embassy_futures::select::{Either, select};
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_time::{Instant, Timer};
use psmpa_core::{
    Actuator, ControlError, DecidingSide, FactSet, Mission, Platform, Report, Runtime, Sensor,
    TraceSink,
};

use crate::robot::{self, Arch};
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

/// The deciding side of a run of `scenario`: Algorithm 1, planning in `space` when it must,
/// until the goal holds, the control loop gives up, or `max_ms` passes (then `halt` stops the
/// robot).
/// Returns how it ended and when, ms. The sensing side runs beside it at a higher priority:
/// the host's poll loop (`simulate_split`), or a task on the firmware's interrupt executor.
/// The run starts at the current instant; the host and the firmware start it at tick 0 so
/// their traces agree.
pub async fn decide_on<Ms, P, T>(
    deciding: &mut DecidingSide<'_, Runtime<'_, Ms, P, T>>,
    scenario: &Scenario,
    space: &mut robot::PlannerSpace,
    halt: impl FnOnce(),
) -> (Ending, u64)
where
    Ms: Mission<Facts = FactSet>,
    P: Platform + Sensor<Ms> + Actuator<Ms>,
    T: TraceSink<Ms>,
{
    let deadline = Timer::at(Instant::from_millis(scenario.max_ms));
    let ending = match select(deciding.run_planning(&robot::PLANNER, space), deadline).await {
        Either::First(Ok(report)) => Ending::Goal(report),
        Either::First(Err(error)) => Ending::Error(error),
        Either::Second(()) => {
            halt();
            Ending::TimeLimit
        }
    };
    (ending, Instant::now().as_millis())
}

/// The summary of a run under `arch` that ended with `ending` at `time_cost_ms`
/// ([`decide_on`]), from its world and its runtime.
pub fn summary<Ms, L, P, T, M>(
    arch: Arch,
    world: &World<'_, L, M>,
    runtime: &Runtime<'_, Ms, P, T>,
    (ending, time_cost_ms): (Ending, u64),
) -> Summary
where
    Ms: Mission<Facts = FactSet>,
    L: WorldLog,
    P: Platform + Sensor<Ms> + Actuator<Ms>,
    T: TraceSink<Ms>,
    M: RawMutex,
{
    Summary {
        arch,
        tally: world.tally(),
        obstacles: world.obstacles(),
        time_cost_ms,
        ending,
        trace_hash: {
            let mut h = runtime.trace_hash();
            h.write(&world.hash().value().to_le_bytes());
            h.value()
        },
        trace_events: runtime.trace_events(),
    }
}

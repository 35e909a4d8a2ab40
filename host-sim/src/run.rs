//! One run of a scenario under one architecture: the Fetch Tea mission on the simulated world
//! until the goal holds, the control loop gives up, or `max_s` passes.
//!
//! `no_std`: the firmware awaits [`run_robot`] inside an embassy task, the host inside
//! [`backend::simulate`](crate::backend::simulate) (through `sim`, with the mission loaded once
//! per thread). Each places the runtime's sensing side
//! through [`Sides`]: the host at its poll loop's higher priority, the firmware on its own
//! interrupt executor.

use core::future::Future;
use core::pin::{Pin, pin};

use embassy_futures::select::{Either, select};
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_time::{Instant, Timer};
use psmpa_core::{ControlError, Report, TraceSink};

pub use psmpa_testkit::beside::{Beside, Erased, HighSlot, PreemptingSlot};

use crate::robot::{self, Arch, Nao, Robot};
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

/// Where the two sides of a runtime run: the platform's choice.
#[allow(async_fn_in_trait)] // Single-threaded executors: no `Send` bound wanted.
pub trait Sides {
    /// The mutex through which the two sides share state: a `NoopRawMutex` where they take
    /// turns on one thread, a `CriticalSectionRawMutex` where sensing preempts deciding.
    type Mutex: RawMutex;

    /// Runs `sensing` at a higher priority than `deciding` for as long as `deciding` runs, and
    /// returns what `deciding` returns; `sensing` is not polled afterwards. Both are pinned
    /// where the caller built them: nothing moves them (a run's futures are large, and every
    /// move is a copy on the stack of the task that makes it).
    ///
    /// # Safety
    ///
    /// An implementation may hand `sensing` to a task that polls it from elsewhere, so the
    /// returned future must not be leaked (`mem::forget`) while `sensing` is alive, and must be
    /// dropped on the thread that polled it: run it to completion, or drop it. Where that task
    /// preempts this one, `sensing` must be safe to poll from there: `Send`, its shared state
    /// behind [`Mutex`](Self::Mutex).
    async unsafe fn beside<S: Future, D: Future>(
        &self,
        sensing: Pin<&mut S>,
        deciding: Pin<&mut D>,
    ) -> D::Output;

    /// Spends `us` microseconds of processor time (a behaviour's computation): nothing in
    /// virtual time, where computing takes none; busy cycles on a microcontroller.
    fn compute(us: u32) {
        let _ = us;
    }
}

/// Runs a mission already loaded for `scenario` ([`robot::fetch_tea`]), planning in `space`
/// when it must. The run starts at the current instant; the host and the firmware start it at
/// tick 0 so their traces agree.
///
/// # Safety
///
/// As [`Sides::beside`]: the future must not be leaked, and must be dropped where it was
/// polled.
pub async unsafe fn run_robot<P: Sides, L: WorldLog, T: TraceSink>(
    sides: &P,
    robot: &Robot<'_>,
    scenario: &Scenario,
    arch: Arch,
    space: &mut robot::PlannerSpace,
    log: L,
    sink: T,
) -> (Summary, L, T) {
    let world: World<'_, L, P::Mutex> = World::new(scenario, log);
    let nao = Nao::new(&world, robot).with_compute(P::compute);
    let mut runtime = robot::NaoRuntime::<'_, '_, '_, L, T, P::Mutex>::new(
        &robot.mission,
        &nao,
        sink,
        robot::config(scenario, arch),
    );
    let ending = {
        let deadline = Timer::at(Instant::from_millis(scenario.max_ms));
        let (mut sensing, mut deciding) = runtime.split();
        // Built where they stay: neither side is ever copied.
        let sensing = pin!(sensing.run());
        let deciding = pin!(select(
            deciding.run_planning(&robot::PLANNER, space),
            deadline
        ));
        // SAFETY: this future is not leaked and stays where it is polled: the caller's
        // contract.
        match unsafe { sides.beside(sensing, deciding) }.await {
            Either::First(Ok(report)) => Ending::Goal(report),
            Either::First(Err(error)) => Ending::Error(error),
            Either::Second(()) => {
                world.halt();
                Ending::TimeLimit
            }
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

//! One run of a scenario under one architecture: the Fetch Tea mission on the simulated world
//! until the goal holds, the control loop gives up, or `max_s` passes.
//!
//! `no_std`: the firmware awaits [`run`] inside an embassy task, the host inside
//! [`backend::simulate`](crate::backend::simulate). Each places the runtime's sensing side
//! through [`Sides`]: the host at its poll loop's higher priority, the firmware on its own
//! interrupt executor.

use core::future::Future;
use core::marker::PhantomData;
use core::pin::{Pin, pin};
use core::task::{Context, Poll};

use embassy_futures::select::{Either, select};
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_time::{Instant, Timer};
use psmpa_core::{ControlError, Report, TraceSink};

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

/// A pinned future with its type and lifetime erased: its address and the function that polls
/// it (dropping its output). Valid only while installed in a [`HighSlot`].
#[derive(Clone, Copy, Debug)]
pub struct Erased {
    data: *mut (),
    poll: unsafe fn(*mut (), &mut Context<'_>) -> Poll<()>,
}

/// Polls the `F` at `data`, dropping its output.
///
/// # Safety
///
/// `data` points to a live, pinned `F` that nothing else uses during the call.
unsafe fn poll_erased<F: Future>(data: *mut (), cx: &mut Context<'_>) -> Poll<()> {
    // SAFETY: the caller's contract.
    unsafe { Pin::new_unchecked(&mut *data.cast::<F>()) }
        .poll(cx)
        .map(|_| ())
}

impl Erased {
    /// Polls the future.
    ///
    /// # Safety
    ///
    /// Only while it is installed in a [`HighSlot`] (the future is alive and pinned), and not
    /// re-entrantly.
    pub unsafe fn poll(self, cx: &mut Context<'_>) -> Poll<()> {
        // SAFETY: the caller's contract.
        unsafe { (self.poll)(self.data, cx) }
    }
}

/// The slot a higher-priority task polls: where [`Beside`] puts a sensing side.
///
/// # Safety
///
/// The task that polls the slot polls the future only between [`install`](Self::install)
/// and [`uninstall`](Self::uninstall), never re-entrantly, and never while the code that
/// uninstalls is running in the middle of a poll of it: the poller runs on the same thread
/// and is not re-entered. (A poller that preempts from an interrupt polls the future from
/// another context: it would need the future to be `Send`, which this slot does not ask.)
pub unsafe trait HighSlot {
    /// Makes `future` the one the higher-priority task polls and wakes that task; `false` when
    /// another future is installed.
    fn install(&self, future: Erased) -> bool;
    /// Removes the installed future: it is not polled again.
    fn uninstall(&self);
}

/// Runs `sensing` from `slot` for as long as `deciding` runs: the future of
/// [`Sides::beside`] on a platform with a higher-priority task polling `slot`. One at a time:
/// while the slot holds another sensing side, this one is not run (a runtime's deciding side
/// then fails with [`Failure::SensingStalled`](psmpa_core::Failure::SensingStalled)). Neither
/// `Send` nor `Sync`: it must be dropped where it was polled.
pub struct Beside<'h, 'p, H: HighSlot, S, D> {
    slot: &'h H,
    sensing: Pin<&'p mut S>,
    deciding: Pin<&'p mut D>,
    /// Not yet offered to the slot.
    first: bool,
    installed: bool,
    _here: PhantomData<*const ()>,
}

impl<'h, 'p, H: HighSlot, S: Future, D: Future> Beside<'h, 'p, H, S, D> {
    /// `sensing` beside `deciding`, through `slot`.
    ///
    /// # Safety
    ///
    /// Once polled, the future hands a pointer to `sensing` to `slot`'s poller, taken back only
    /// when it ends or is dropped: it must not be leaked (`mem::forget`) while `sensing` is
    /// alive. Run it to completion, or drop it.
    pub unsafe fn new(slot: &'h H, sensing: Pin<&'p mut S>, deciding: Pin<&'p mut D>) -> Self {
        Self {
            slot,
            sensing,
            deciding,
            first: true,
            installed: false,
            _here: PhantomData,
        }
    }
}

/// A [`HighSlot`] whose poller preempts the code that installs into it (an interrupt
/// executor): what it polls is touched from another context, so it must be `Send`.
///
/// # Safety
///
/// As [`HighSlot`], and the poller runs only at a priority that preempts the installing code.
pub unsafe trait PreemptingSlot: HighSlot {}

impl<'h, 'p, H: PreemptingSlot, S: Future + Send, D: Future> Beside<'h, 'p, H, S, D> {
    /// `sensing` beside `deciding`, through a slot whose poller preempts this one: `sensing`
    /// must be `Send`.
    ///
    /// # Safety
    ///
    /// As [`Beside::new`].
    pub unsafe fn preempting(
        slot: &'h H,
        sensing: Pin<&'p mut S>,
        deciding: Pin<&'p mut D>,
    ) -> Self {
        // SAFETY: the caller's contract; `Send` is what the preempting poller needs besides.
        unsafe { Self::new(slot, sensing, deciding) }
    }
}

impl<H: HighSlot, S: Future, D: Future> Future for Beside<'_, '_, H, S, D> {
    type Output = D::Output;

    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<D::Output> {
        let this = self.get_mut();
        if core::mem::take(&mut this.first) {
            // `Drop` uninstalls before `sensing` can end, and `HighSlot`'s contract keeps the
            // poller from using it afterwards. From here on only the poller touches `sensing`.
            let erased = Erased {
                // SAFETY: the pointer is only polled, in place: `sensing` stays pinned.
                data: core::ptr::from_mut(unsafe { this.sensing.as_mut().get_unchecked_mut() })
                    .cast(),
                poll: poll_erased::<S>,
            };
            this.installed = this.slot.install(erased);
        }
        let out = this.deciding.as_mut().poll(cx);
        if out.is_ready() && core::mem::take(&mut this.installed) {
            this.slot.uninstall();
        }
        out
    }
}

impl<H: HighSlot, S, D> Drop for Beside<'_, '_, H, S, D> {
    fn drop(&mut self) {
        if core::mem::take(&mut self.installed) {
            self.slot.uninstall();
        }
    }
}

/// Runs `scenario` under `arch`, logging the world into `log` and tracing the runtime into
/// `sink`; returns the summary and gives the log and the sink back.
///
/// # Safety
///
/// As [`Sides::beside`]: the future must not be leaked, and must be dropped where it was
/// polled. [`crate::sim`] runs it safely.
pub async unsafe fn run<P: Sides, L: WorldLog, T: TraceSink>(
    sides: &P,
    scenario: &Scenario,
    arch: Arch,
    log: L,
    sink: T,
) -> Result<(Summary, L, T), MissionError> {
    let robot = robot::fetch_tea(scenario)?;
    let mut space = robot::PlannerSpace::new();
    // SAFETY: this future is not leaked and stays where it is polled: the caller's contract.
    Ok(unsafe { run_robot(sides, &robot, scenario, arch, &mut space, log, sink) }.await)
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
    let runtime = robot::NaoRuntime::<'_, '_, '_, L, T, P::Mutex>::new(
        &robot.mission,
        &nao,
        sink,
        robot::config(scenario, arch),
    );
    let ending = {
        let deadline = Timer::at(Instant::from_millis(scenario.max_ms));
        // Built where they stay: neither side is ever copied.
        let sensing = pin!(runtime.sensing());
        let deciding = pin!(select(
            runtime.run_planning(&robot::PLANNER, space),
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

//! The host backend: a virtual-time `embassy-time` driver and two hand-driven embassy
//! executors, one per priority.
//!
//! [`simulate`] polls a future on an `embassy_executor::raw::Executor` until nothing is ready,
//! then jumps the virtual clock to the earliest timer deadline, and so on until the future
//! completes. Time only moves when every task waits, so a minute of robot time takes
//! milliseconds, and the same future gives the same result every time.
//!
//! Inside a simulation, [`beside`] runs a second future (a runtime's sensing side) on a
//! second executor of *higher priority*: whenever it has work, it is polled before the next
//! poll of the simulated future, so at every instant ready sensing work comes before deciding
//! work, as on a microcontroller where sensing runs on an interrupt executor (there it can
//! even preempt a poll; here polls take no time, so preempting at poll boundaries is the same).
//! [`simulate_split`] is the two together.
//!
//! The clock, the timer queue and the executor are per thread: independent simulations run on
//! parallel test threads without seeing each other. A simulation must stay on its thread.
//!
//! Errors instead of hangs: a future that waits with no timer pending is a
//! [`SimError::Deadlock`]; one still running at the time limit is a [`SimError::TimeLimit`].

use std::cell::{Cell, RefCell};
use std::fmt;
use std::future::Future;
use std::pin::{Pin, pin};
use std::task::{Context, Poll, Waker};

use embassy_executor::raw::{Executor, TaskStorage};
use embassy_time::{Duration, Instant};

use crate::run::{Beside, Erased, HighSlot};

/// Why a simulation did not complete.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SimError {
    /// The future waits for something, but no timer is pending: it would wait forever.
    Deadlock {
        /// Virtual time at which everything stopped.
        at: Instant,
    },
    /// The next timer lies beyond the time limit.
    TimeLimit {
        /// The limit.
        limit: Duration,
    },
    /// [`simulate`] was called from inside a simulation on the same thread.
    Nested,
}

impl fmt::Display for SimError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Deadlock { at } => write!(
                f,
                "deadlock at {} ms of virtual time: the simulation waits with no timer pending",
                at.as_millis()
            ),
            Self::TimeLimit { limit } => write!(
                f,
                "time limit of {} ms of virtual time reached",
                limit.as_millis()
            ),
            Self::Nested => write!(f, "simulate() called inside a running simulation"),
        }
    }
}

impl std::error::Error for SimError {}

/// A completed simulation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Completed<T> {
    /// What the future returned.
    pub output: T,
    /// Virtual time when it returned.
    pub elapsed: Duration,
    /// Times the clock jumped to a timer deadline.
    pub clock_jumps: u64,
}

/// A timer registration: wake `waker` at tick `at`; `seq` orders equal deadlines by arrival.
struct Alarm {
    at: u64,
    seq: u64,
    waker: Waker,
}

#[derive(Default)]
struct Clock {
    now: u64,
    seq: u64,
    alarms: Vec<Alarm>,
}

/// The running simulation's future, pinned on `simulate`'s stack (no allocation); the
/// lifetime is erased, and [`Cleanup`] takes the pointer back before that frame ends.
type TaskPtr = *mut (dyn Future<Output = ()> + 'static);

/// The pender context of the higher-priority executor (the lower one's is null).
const HIGH_CONTEXT: *mut () = std::ptr::without_provenance_mut(1);

/// Both executors of a thread and their task slots.
struct Executors {
    low: Executor,
    low_task: TaskStorage<Trampoline>,
    high: Executor,
    high_task: TaskStorage<HighTrampoline>,
}

thread_local! {
    static CLOCK: RefCell<Clock> = RefCell::new(Clock::default());
    /// The future of the running simulation, polled by the trampoline task.
    static CURRENT: Cell<Option<TaskPtr>> = const { Cell::new(None) };
    /// The future running at the higher priority, if [`beside`] placed one.
    static HIGH: Cell<Option<Erased>> = const { Cell::new(None) };
    /// Alarms due at the current instant, reused so that advancing the clock allocates nothing.
    static DUE: RefCell<Vec<Alarm>> = const { RefCell::new(Vec::new()) };
    static TRAMPOLINE_WAKER: RefCell<Option<Waker>> = const { RefCell::new(None) };
    static HIGH_WAKER: RefCell<Option<Waker>> = const { RefCell::new(None) };
    static PENDING: Cell<bool> = const { Cell::new(false) };
    static PENDING_HIGH: Cell<bool> = const { Cell::new(false) };
    /// Tells the higher-priority trampoline to end: the simulation is over.
    static STOPPING: Cell<bool> = const { Cell::new(false) };
    static RUNNING: Cell<bool> = const { Cell::new(false) };
    /// Two executors and their task slots per thread, made once and kept for the thread's life.
    static EXECUTORS: &'static Executors = Box::leak(Box::new(Executors {
        low: Executor::new(std::ptr::null_mut()),
        low_task: TaskStorage::new(),
        high: Executor::new(HIGH_CONTEXT),
        high_task: TaskStorage::new(),
    }));
}

struct VirtualClock;

impl embassy_time_driver::Driver for VirtualClock {
    fn now(&self) -> u64 {
        CLOCK.with(|c| c.borrow().now)
    }

    fn schedule_wake(&self, at: u64, waker: &Waker) {
        // A deadline that has come is due now: wake at once, as a hardware driver does, so the
        // task is polled again at this instant, in its priority's turn.
        if at <= CLOCK.with(|c| c.borrow().now) {
            waker.wake_by_ref();
            return;
        }
        CLOCK.with(|c| {
            let mut c = c.borrow_mut();
            // One alarm per task: keep the earliest deadline (the driver contract allows an
            // early wake; the woken future re-registers what it still needs).
            if let Some(alarm) = c.alarms.iter_mut().find(|a| a.waker.will_wake(waker)) {
                alarm.at = alarm.at.min(at);
                return;
            }
            let seq = c.seq;
            c.seq += 1;
            c.alarms.push(Alarm {
                at,
                seq,
                waker: waker.clone(),
            });
        });
    }
}

embassy_time_driver::time_driver_impl!(static DRIVER: VirtualClock = VirtualClock);

// An executor calls this when one of its tasks was woken: note which, the run loop polls.
#[unsafe(export_name = "__pender")]
fn pender(context: *mut ()) {
    if context == HIGH_CONTEXT {
        PENDING_HIGH.with(|p| p.set(true));
    } else {
        PENDING.with(|p| p.set(true));
    }
}

/// The one task of a thread's executor: polls whatever future [`simulate`] put in `CURRENT`.
struct Trampoline;

impl Future for Trampoline {
    type Output = ();

    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<()> {
        TRAMPOLINE_WAKER.with(|w| *w.borrow_mut() = Some(cx.waker().clone()));
        // Take the future out while polling it, so that it may use the thread-locals freely.
        let Some(future) = CURRENT.with(Cell::take) else {
            return Poll::Ready(());
        };
        // SAFETY: the pointer is to the future `simulate` pinned on its stack, alive until its
        // `Cleanup` has cleared `CURRENT`; taking it out first means nothing else aliases it.
        let pinned = unsafe { Pin::new_unchecked(&mut *future) };
        match pinned.poll(cx) {
            Poll::Ready(()) => Poll::Ready(()),
            Poll::Pending => {
                CURRENT.with(|c| c.set(Some(future)));
                Poll::Pending
            }
        }
    }
}

/// The task of the higher-priority executor: polls whatever future [`beside`] put in `HIGH`,
/// until the simulation ends.
struct HighTrampoline;

impl Future for HighTrampoline {
    type Output = ();

    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<()> {
        HIGH_WAKER.with(|w| *w.borrow_mut() = Some(cx.waker().clone()));
        if STOPPING.with(Cell::get) {
            return Poll::Ready(());
        }
        // Taken out while polled, like the simulation's own future.
        if let Some(future) = HIGH.with(Cell::take) {
            // SAFETY: installed by a live `Beside`, whose `Drop` clears `HIGH` first; taken out
            // while polled, so nothing else uses it.
            // A future that ends is polled no more; the `Beside` keeps it until dropped.
            if unsafe { future.poll(cx) }.is_pending() {
                HIGH.with(|h| h.set(Some(future)));
            }
        }
        Poll::Pending
    }
}

/// Polls until no task is ready: the higher-priority executor whenever it has work, the
/// simulation's own executor only when it has none.
fn poll_ready(executors: &'static Executors) {
    loop {
        // SAFETY (both): `poll` is never re-entered: the pender only sets a flag, and this
        // thread is the only one that polls its executors.
        if PENDING_HIGH.with(|p| p.replace(false)) {
            unsafe { executors.high.poll() };
        } else if PENDING.with(|p| p.replace(false)) {
            unsafe { executors.low.poll() };
        } else {
            return;
        }
    }
}

/// The higher-priority task's slot on this thread.
#[derive(Clone, Copy, Debug, Default)]
pub struct ThreadSlot;

// SAFETY: the slot is polled only by `HighTrampoline`, which takes the pointer out for the
// duration of its poll, on this thread, from `poll_ready`, which is never re-entered; a
// `Beside` runs on the same thread, so it never uninstalls in the middle of that poll.
unsafe impl HighSlot for ThreadSlot {
    fn install(&self, future: Erased) -> bool {
        if HIGH.with(Cell::get).is_some() {
            return false;
        }
        HIGH.with(|h| h.set(Some(future)));
        if let Some(w) = HIGH_WAKER.with(|w| w.borrow().clone()) {
            w.wake();
        }
        true
    }

    fn uninstall(&self) {
        HIGH.with(|h| h.set(None));
    }
}

/// Runs `sensing` at the higher priority for as long as `deciding` runs, inside a
/// [`simulate`]d future, and returns what `deciding` returns: whenever `sensing` has work it
/// is polled before `deciding` (see the module doc). `sensing` is dropped with the returned
/// future. One at a time: while another `beside` runs, `sensing` is not run (see [`Beside`]).
/// [`simulate_split`] is the safe way to use it.
///
/// # Safety
///
/// As [`Beside::new`]: the returned future must not be leaked while anything `sensing` borrows
/// is alive.
pub unsafe fn beside<'p, S: Future, D: Future>(
    sensing: Pin<&'p mut S>,
    deciding: Pin<&'p mut D>,
) -> Beside<'static, 'p, ThreadSlot, S, D> {
    // SAFETY: the caller's contract.
    unsafe { Beside::new(&ThreadSlot, sensing, deciding) }
}

/// [`simulate`] with `sensing` at the higher priority beside `deciding` ([`beside`]).
pub fn simulate_split<S: Future, D: Future>(
    sensing: S,
    deciding: D,
    limit: Duration,
) -> Result<Completed<D::Output>, SimError> {
    let (sensing, deciding) = (pin!(sensing), pin!(deciding));
    // SAFETY: `simulate` pins the future on its own stack and drops it, on this thread, before
    // it returns (and on unwind): it cannot be leaked.
    simulate(unsafe { beside(sensing, deciding) }, limit)
}

/// Moves the clock to the earliest alarm and wakes every alarm due by then, in
/// (deadline, arrival) order. Returns `false` when no alarm is pending.
fn advance(limit: u64) -> Result<bool, SimError> {
    let due = CLOCK.with(|c| {
        let mut c = c.borrow_mut();
        let Some(next) = c.alarms.iter().map(|a| a.at).min() else {
            return Ok(None);
        };
        if next > limit {
            return Err(SimError::TimeLimit {
                limit: Duration::from_ticks(limit),
            });
        }
        c.now = c.now.max(next);
        let now = c.now;
        DUE.with(|d| {
            let mut due = d.borrow_mut();
            let mut i = 0;
            while i < c.alarms.len() {
                if c.alarms[i].at <= now {
                    due.push(c.alarms.remove(i));
                } else {
                    i += 1;
                }
            }
            // (deadline, arrival) is unique: the unstable sort gives the stable order.
            due.sort_unstable_by_key(|a| (a.at, a.seq));
        });
        Ok(Some(()))
    })?;
    // Wake outside the clock's borrow: a woken task may schedule a new alarm when polled.
    match due {
        Some(()) => {
            DUE.with(|d| {
                for alarm in d.borrow_mut().drain(..) {
                    alarm.waker.wake();
                }
            });
            Ok(true)
        }
        None => Ok(false),
    }
}

/// Drops the running future and lets both trampoline tasks finish, so the thread's task slots
/// are free for the next simulation.
struct Cleanup(&'static Executors);

impl Drop for Cleanup {
    fn drop(&mut self) {
        CURRENT.with(|c| c.set(None));
        HIGH.with(|h| h.set(None));
        STOPPING.with(|s| s.set(true));
        for waker in [&TRAMPOLINE_WAKER, &HIGH_WAKER] {
            if let Some(waker) = waker.with(|w| w.borrow_mut().take()) {
                waker.wake();
            }
        }
        poll_ready(self.0);
        STOPPING.with(|s| s.set(false));
        CLOCK.with(|c| c.borrow_mut().alarms.clear());
        RUNNING.with(|r| r.set(false));
    }
}

/// Runs `future` to completion in virtual time starting at 0, on this thread's embassy
/// executor. Fails when the future deadlocks or is still running at `limit`.
pub fn simulate<F: Future>(future: F, limit: Duration) -> Result<Completed<F::Output>, SimError> {
    if RUNNING.with(|r| r.replace(true)) {
        return Err(SimError::Nested);
    }
    let executors = EXECUTORS.with(|e| *e);
    CLOCK.with(|c| {
        // Keep the alarm list's capacity: a simulation after the first allocates nothing.
        let mut c = c.borrow_mut();
        c.now = 0;
        c.seq = 0;
        c.alarms.clear();
    });
    PENDING.with(|p| p.set(false));
    PENDING_HIGH.with(|p| p.set(false));

    let mut output: Option<F::Output> = None;
    let slot: *mut Option<F::Output> = &mut output;
    let wrapped = async move {
        let value = future.await;
        // SAFETY: `output` outlives the wrapped future: the future is dropped by `Cleanup`
        // before `simulate` returns, and `output` is only read after that.
        unsafe { *slot = Some(value) };
    };
    let mut pinned = std::pin::pin!(wrapped);
    // SAFETY: the future stays pinned in this frame; the pointer is only dereferenced by the
    // trampoline, which never moves it.
    let raw: *mut (dyn Future<Output = ()> + '_) = unsafe { pinned.as_mut().get_unchecked_mut() };
    // SAFETY: lifetime erasure only. `cleanup`, declared after `pinned` and so dropped before
    // it (on return and on unwind), clears the thread-local before the future and its borrows
    // of the caller's frame end.
    let raw: TaskPtr =
        unsafe { std::mem::transmute::<*mut (dyn Future<Output = ()> + '_), TaskPtr>(raw) };
    CURRENT.with(|c| c.set(Some(raw)));
    let cleanup = Cleanup(executors);

    let token = executors
        .low_task
        .spawn(|| Trampoline)
        .map_err(|_| SimError::Nested)?;
    executors.low.spawner().spawn(token);
    let token = executors
        .high_task
        .spawn(|| HighTrampoline)
        .map_err(|_| SimError::Nested)?;
    executors.high.spawner().spawn(token);
    PENDING.with(|p| p.set(true));

    let limit = limit.as_ticks();
    let mut clock_jumps = 0u64;
    let result = loop {
        poll_ready(executors);
        if CURRENT.with(|c| c.get().is_none()) {
            break Ok(());
        }
        match advance(limit) {
            Ok(true) => clock_jumps += 1,
            Ok(false) => {
                break Err(SimError::Deadlock {
                    at: Instant::from_ticks(CLOCK.with(|c| c.borrow().now)),
                });
            }
            Err(e) => break Err(e),
        }
    };
    let elapsed = Duration::from_ticks(CLOCK.with(|c| c.borrow().now));
    drop(cleanup);
    result?;
    output
        .take()
        .map(|output| Completed {
            output,
            elapsed,
            clock_jumps,
        })
        .ok_or(SimError::Deadlock {
            at: Instant::from_ticks(elapsed.as_ticks()),
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use embassy_time::Timer;

    #[test]
    fn time_is_virtual_and_exact() {
        let local = [7u64];
        let done = simulate(
            async {
                for _ in 0..600 {
                    Timer::after(Duration::from_millis(100)).await;
                }
                (Instant::now().as_millis(), local[0])
            },
            Duration::from_secs(3600),
        )
        .unwrap();
        assert_eq!(done.output, (60_000, 7));
        assert_eq!(done.elapsed, Duration::from_secs(60));
        assert_eq!(done.clock_jumps, 600);
    }

    #[test]
    fn waiting_forever_is_a_deadlock_and_the_thread_stays_usable() {
        let err = simulate(
            async {
                Timer::after_secs(2).await;
                std::future::pending::<()>().await
            },
            Duration::from_secs(10),
        )
        .unwrap_err();
        assert_eq!(
            err,
            SimError::Deadlock {
                at: Instant::from_secs(2)
            }
        );
        // The slot was released: the next simulation on this thread runs, from time 0.
        let ok = simulate(async { Instant::now() }, Duration::from_secs(1)).unwrap();
        assert_eq!(ok.output, Instant::from_ticks(0));
    }

    #[test]
    fn time_limit_stops_a_long_run() {
        let err = simulate(Timer::after_secs(100), Duration::from_secs(10)).unwrap_err();
        assert_eq!(
            err,
            SimError::TimeLimit {
                limit: Duration::from_secs(10)
            }
        );
    }

    #[test]
    fn nested_simulation_is_an_error() {
        let inner = simulate(
            async { simulate(async {}, Duration::from_secs(1)).map(|_| ()) },
            Duration::from_secs(1),
        )
        .unwrap();
        assert_eq!(inner.output, Err(SimError::Nested));
    }

    #[test]
    fn threads_have_independent_clocks() {
        let handles: Vec<_> = (1..=4u64)
            .map(|n| {
                std::thread::spawn(move || {
                    simulate(
                        async move {
                            Timer::after_secs(n).await;
                            Instant::now().as_secs()
                        },
                        Duration::from_secs(60),
                    )
                    .unwrap()
                    .output
                })
            })
            .collect();
        let got: Vec<u64> = handles.into_iter().map(|h| h.join().unwrap()).collect();
        assert_eq!(got, [1, 2, 3, 4]);
    }
}

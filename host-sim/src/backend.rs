//! The host backend: a virtual-time `embassy-time` driver and a hand-driven embassy executor.
//!
//! [`simulate`] polls a future on an `embassy_executor::raw::Executor` until nothing is ready,
//! then jumps the virtual clock to the earliest timer deadline, and so on until the future
//! completes. Time only moves when every task waits, so a minute of robot time takes
//! milliseconds, and the same future gives the same result every time.
//!
//! The clock, the timer queue and the executor are per thread: independent simulations run on
//! parallel test threads without seeing each other. A simulation must stay on its thread.
//!
//! Errors instead of hangs: a future that waits with no timer pending is a
//! [`SimError::Deadlock`]; one still running at the time limit is a [`SimError::TimeLimit`].

use std::cell::{Cell, RefCell};
use std::fmt;
use std::future::Future;
use std::pin::Pin;
use std::task::{Context, Poll, Waker};

use embassy_executor::raw::{Executor, TaskStorage};
use embassy_time::{Duration, Instant};

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

thread_local! {
    static CLOCK: RefCell<Clock> = RefCell::new(Clock::default());
    /// The future of the running simulation, polled by the trampoline task.
    static CURRENT: Cell<Option<TaskPtr>> = const { Cell::new(None) };
    /// Alarms due at the current instant, reused so that advancing the clock allocates nothing.
    static DUE: RefCell<Vec<Alarm>> = const { RefCell::new(Vec::new()) };
    static TRAMPOLINE_WAKER: RefCell<Option<Waker>> = const { RefCell::new(None) };
    static PENDING: Cell<bool> = const { Cell::new(false) };
    static RUNNING: Cell<bool> = const { Cell::new(false) };
    /// One executor and one task slot per thread, made once and kept for the thread's life.
    static EXECUTOR: &'static (Executor, TaskStorage<Trampoline>) =
        Box::leak(Box::new((Executor::new(std::ptr::null_mut()), TaskStorage::new())));
}

struct VirtualClock;

impl embassy_time_driver::Driver for VirtualClock {
    fn now(&self) -> u64 {
        CLOCK.with(|c| c.borrow().now)
    }

    fn schedule_wake(&self, at: u64, waker: &Waker) {
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

// The executor calls this when a task was woken: note it, the run loop polls.
#[unsafe(export_name = "__pender")]
fn pender(_context: *mut ()) {
    PENDING.with(|p| p.set(true));
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

/// Polls until no task is ready.
fn poll_ready(executor: &'static Executor) {
    while PENDING.with(|p| p.replace(false)) {
        // SAFETY: `poll` is never re-entered: the pender only sets a flag, and this thread is
        // the only one that polls its executor.
        unsafe { executor.poll() };
    }
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

/// Drops the running future and lets the trampoline task finish, so the thread's task slot is
/// free for the next simulation.
struct Cleanup(&'static Executor);

impl Drop for Cleanup {
    fn drop(&mut self) {
        CURRENT.with(|c| c.set(None));
        if let Some(waker) = TRAMPOLINE_WAKER.with(|w| w.borrow_mut().take()) {
            waker.wake();
        }
        poll_ready(self.0);
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
    let (executor, storage) = EXECUTOR.with(|e| *e);
    CLOCK.with(|c| {
        // Keep the alarm list's capacity: a simulation after the first allocates nothing.
        let mut c = c.borrow_mut();
        c.now = 0;
        c.seq = 0;
        c.alarms.clear();
    });
    PENDING.with(|p| p.set(false));

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
    let cleanup = Cleanup(executor);

    let token = storage.spawn(|| Trampoline).map_err(|_| SimError::Nested)?;
    executor.spawner().spawn(token);
    PENDING.with(|p| p.set(true));

    let limit = limit.as_ticks();
    let mut clock_jumps = 0u64;
    let result = loop {
        poll_ready(executor);
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

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

type BoxedTask = Pin<Box<dyn Future<Output = ()>>>;

thread_local! {
    static CLOCK: RefCell<Clock> = RefCell::new(Clock::default());
    /// The future of the running simulation, polled by the trampoline task.
    static CURRENT: RefCell<Option<BoxedTask>> = const { RefCell::new(None) };
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
        let Some(mut future) = CURRENT.with(|c| c.borrow_mut().take()) else {
            return Poll::Ready(());
        };
        match future.as_mut().poll(cx) {
            Poll::Ready(()) => Poll::Ready(()),
            Poll::Pending => {
                CURRENT.with(|c| *c.borrow_mut() = Some(future));
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
        let (mut due, rest): (Vec<Alarm>, Vec<Alarm>) =
            c.alarms.drain(..).partition(|a| a.at <= now);
        c.alarms = rest;
        due.sort_by_key(|a| (a.at, a.seq));
        Ok(Some(due))
    })?;
    // Wake outside the borrow: a waker may schedule a new alarm.
    match due {
        Some(due) => {
            for alarm in due {
                alarm.waker.wake();
            }
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
        drop(CURRENT.with(|c| c.borrow_mut().take()));
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
    CLOCK.with(|c| *c.borrow_mut() = Clock::default());
    PENDING.with(|p| p.set(false));

    let mut output: Option<F::Output> = None;
    let slot: *mut Option<F::Output> = &mut output;
    let wrapped = async move {
        let value = future.await;
        // SAFETY: `output` outlives the wrapped future: the future is dropped by `Cleanup`
        // before `simulate` returns, and `output` is only read after that.
        unsafe { *slot = Some(value) };
    };
    let boxed: Pin<Box<dyn Future<Output = ()> + '_>> = Box::pin(wrapped);
    // SAFETY: lifetime erasure only. The boxed future borrows from the caller's frame; it is
    // stored in a thread-local that `Cleanup` empties (on return and on unwind) before this
    // function's borrows end, and the trampoline never moves it anywhere else.
    let boxed: BoxedTask =
        unsafe { std::mem::transmute::<Pin<Box<dyn Future<Output = ()> + '_>>, BoxedTask>(boxed) };
    CURRENT.with(|c| *c.borrow_mut() = Some(boxed));
    let cleanup = Cleanup(executor);

    let token = storage.spawn(|| Trampoline).map_err(|_| SimError::Nested)?;
    executor.spawner().spawn(token);
    PENDING.with(|p| p.set(true));

    let limit = limit.as_ticks();
    let mut clock_jumps = 0u64;
    let result = loop {
        poll_ready(executor);
        if CURRENT.with(|c| c.borrow().is_none()) {
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

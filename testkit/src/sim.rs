//! The host backend: a virtual-time `embassy-time` driver and a two-priority poll loop.
//!
//! [`simulate`] polls a future until nothing is ready, then jumps the virtual clock to the
//! earliest timer deadline, and so on until the future completes. Time only moves when
//! everything waits, so a minute of robot time takes milliseconds, and the same future gives
//! the same result every time.
//!
//! [`simulate_split`] runs a second future (a runtime's sensing side) at a *higher priority*
//! beside the simulated one (its deciding side): whenever it has work, it is polled before the
//! next poll of the deciding future, so at every instant ready sensing work comes before
//! deciding work, as on a microcontroller where sensing runs on an interrupt executor (there it
//! can even preempt a poll; here polls take no time, so preempting at poll boundaries is the
//! same).
//!
//! No executor: the core spawns no tasks, so the loop polls its two futures itself, each with
//! its priority's waker, whose wake only sets that priority's "pending" flag. Timers sit in one
//! alarm slot per priority waker; a future that polls with a waker of its own gets a list.
//!
//! The clock, the timers and the flags are per thread: independent simulations run on parallel
//! test threads without seeing each other. A simulation must stay on its thread (its wakers set
//! the flags of the thread that wakes them).
//!
//! Errors instead of hangs: a future that waits with no timer pending is a
//! [`SimError::Deadlock`]; one still running at the time limit is a [`SimError::TimeLimit`].

use std::cell::{Cell, RefCell};
use std::fmt;
use std::future::Future;
use std::pin::{Pin, pin};
use std::sync::Arc;
use std::task::{Context, Poll, Wake, Waker};

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

/// The simulated future's priority: the index of its flag and alarm slot.
const LOW: usize = 0;
/// The sensing side's priority ([`simulate_split`]).
const HIGH: usize = 1;

/// A priority waker's timer: wake at tick `at`; `seq` orders equal deadlines by arrival.
#[derive(Clone, Copy)]
struct Slot {
    at: u64,
    seq: u64,
}

/// The end of time: no alarm is later, so a jump takes plain minimums of deadlines (with
/// `Option`s, the plan benchmark took 17 more instructions a step). An alarm may be set for
/// then too: `seq` tells it from an empty slot.
const NEVER: u64 = u64::MAX;

/// An empty slot: due at the end of time, with an arrival number never reached.
const EMPTY: Slot = Slot {
    at: NEVER,
    seq: u64::MAX,
};

impl Slot {
    fn is_set(self) -> bool {
        self.seq != EMPTY.seq
    }
}

/// A timer of a waker that is not one of the two priority wakers.
struct Alarm {
    at: u64,
    seq: u64,
    waker: Waker,
}

/// What a due alarm wakes.
enum Target {
    Priority(usize),
    Foreign(Waker),
}

/// A thread's simulation state. Cells only: no borrow flags, no destructor, so each access is
/// a plain thread-local load (wakes and timer registrations come several times per step).
struct State {
    now: Cell<u64>,
    /// Arrival counter of alarms.
    seq: Cell<u64>,
    /// Per priority: woken since its last poll.
    pending: [Cell<bool>; 2],
    /// Per priority waker: its one alarm.
    alarms: [Cell<Slot>; 2],
    /// The earliest deadline in `FOREIGN` ([`NEVER`] when empty), so that jumps need not look
    /// there.
    foreign_next: Cell<u64>,
    /// Whether `FOREIGN` may hold alarms: most simulations never touch it.
    foreign_used: Cell<bool>,
    /// Per priority: the data pointer of its waker in the running simulation (null outside
    /// one), which tells a priority waker from any other by one comparison.
    wakers: [Cell<*const ()>; 2],
    running: Cell<bool>,
}

thread_local! {
    static STATE: State = const {
        State {
            now: Cell::new(0),
            seq: Cell::new(0),
            pending: [Cell::new(false), Cell::new(false)],
            alarms: [Cell::new(EMPTY), Cell::new(EMPTY)],
            foreign_next: Cell::new(NEVER),
            foreign_used: Cell::new(false),
            wakers: [Cell::new(std::ptr::null()), Cell::new(std::ptr::null())],
            running: Cell::new(false),
        }
    };
    /// The two priorities' wakers, made once per thread. Clones of the wakers made, so that
    /// every waker in use has the vtable of a clone: `Waker::will_wake` compares vtables, and
    /// a registration (embassy's `WakerRegistration`) then keeps the waker it has.
    static WAKERS: [Waker; 2] = [LOW, HIGH].map(|p| Waker::from(Arc::new(Priority(p))).clone());
    /// Alarms of other wakers, one per waker; rare, so a list. Kept with its capacity.
    static FOREIGN: RefCell<Vec<Alarm>> = const { RefCell::new(Vec::new()) };
    /// Alarms due at a jump that involves `FOREIGN`, being sorted; kept with its capacity.
    static DUE: RefCell<Vec<(u64, u64, Target)>> = const { RefCell::new(Vec::new()) };
}

impl State {
    /// The next arrival number.
    fn arrival(&self) -> u64 {
        let seq = self.seq.get();
        self.seq.set(seq + 1);
        seq
    }

    /// Sets the alarm of priority `p`'s waker. One alarm per waker: the earliest deadline wins
    /// (the driver contract allows an early wake; the woken future re-registers what it still
    /// needs), with its first arrival.
    fn arm(&self, p: usize, at: u64) {
        let slot = self.alarms[p].get();
        if !slot.is_set() {
            self.alarms[p].set(Slot {
                at,
                seq: self.arrival(),
            });
        } else if at < slot.at {
            self.alarms[p].set(Slot { at, ..slot });
        }
    }

    /// Forgets every timer, flag and sensing side, keeping the lists' capacity.
    fn clear(&self) {
        self.pending.iter().for_each(|p| p.set(false));
        self.alarms.iter().for_each(|a| a.set(EMPTY));
        self.wakers.iter().for_each(|w| w.set(std::ptr::null()));
        self.foreign_next.set(NEVER);
        if self.foreign_used.replace(false) {
            // Taken out first: dropping a waker may run arbitrary code.
            let mut foreign = FOREIGN.with(RefCell::take);
            foreign.clear();
            FOREIGN.with(|f| f.replace(foreign));
        }
    }
}

/// A priority's waker: its wake only sets the priority's flag on the thread that wakes it, so
/// it belongs to its simulation's thread.
struct Priority(usize);

impl Wake for Priority {
    fn wake(self: Arc<Self>) {
        self.wake_by_ref();
    }

    fn wake_by_ref(self: &Arc<Self>) {
        STATE.with(|s| {
            if let Some(p) = s.pending.get(self.0) {
                p.set(true);
            }
        });
    }
}

/// A priority waker's priority, `None` for any other waker: a pointer comparison. (Data
/// pointers only: `Waker::will_wake` compares vtables too, which the compiler may duplicate.)
fn priority_of(s: &State, waker: &Waker) -> Option<usize> {
    let data = waker.data();
    s.wakers.iter().position(|w| std::ptr::eq(w.get(), data))
}

struct VirtualClock;

impl embassy_time_driver::Driver for VirtualClock {
    fn now(&self) -> u64 {
        STATE.with(|s| s.now.get())
    }

    fn schedule_wake(&self, at: u64, waker: &Waker) {
        STATE.with(|s| {
            // A deadline that has come is due now: wake at once, as a hardware driver does, so
            // the task is polled again at this instant, in its priority's turn.
            if at <= s.now.get() {
                waker.wake_by_ref();
                return;
            }
            match priority_of(s, waker) {
                Some(p) => s.arm(p, at),
                None => schedule_foreign(s, at, waker),
            }
        });
    }
}

/// `schedule_wake` for a waker of a future's own: kept out of the common path.
#[cold]
#[inline(never)]
fn schedule_foreign(s: &State, at: u64, waker: &Waker) {
    FOREIGN.with(|f| {
        let mut foreign = f.borrow_mut();
        if let Some(alarm) = foreign.iter_mut().find(|a| a.waker.will_wake(waker)) {
            alarm.at = alarm.at.min(at);
        } else {
            foreign.push(Alarm {
                at,
                seq: s.arrival(),
                waker: waker.clone(),
            });
        }
    });
    s.foreign_next.set(s.foreign_next.get().min(at));
    s.foreign_used.set(true);
}

embassy_time_driver::time_driver_impl!(static DRIVER: VirtualClock = VirtualClock);

/// Moves the clock to the earliest alarm and wakes every alarm due by then, in
/// (deadline, arrival) order. Returns `false` when no alarm is pending.
fn advance(s: &State, limit: u64) -> Result<bool, SimError> {
    let (low, high) = (s.alarms[LOW].get(), s.alarms[HIGH].get());
    let next = low.at.min(high.at).min(s.foreign_next.get());
    if next == NEVER && !set_at_the_end(s) {
        return Ok(false);
    }
    if next > limit {
        return Err(SimError::TimeLimit {
            limit: Duration::from_ticks(limit),
        });
    }
    let now = s.now.get().max(next);
    s.now.set(now);
    // (At the end of time, an empty slot is "due" too: the careful path tells them apart.)
    if s.foreign_next.get() <= now {
        wake_with_foreign(s, now);
    } else {
        // A priority wake only sets a flag: the order of the two cannot be observed.
        for (p, slot) in [(LOW, low), (HIGH, high)] {
            if slot.at <= now {
                s.alarms[p].set(EMPTY);
                s.pending[p].set(true);
            }
        }
    }
    Ok(true)
}

/// Whether an alarm is set for the end of time, when every deadline is [`NEVER`].
#[cold]
fn set_at_the_end(s: &State) -> bool {
    s.alarms.iter().any(|a| a.get().is_set())
        || s.foreign_used.get() && FOREIGN.with(|f| !f.borrow().is_empty())
}

/// [`advance`]'s wakes when a foreign waker is due: those may run code that observes the order.
#[cold]
#[inline(never)]
fn wake_with_foreign(s: &State, now: u64) {
    // Taken out of its thread-local while waking: a wake may register a new alarm.
    let mut due = DUE.with(RefCell::take);
    FOREIGN.with(|f| {
        let mut foreign = f.borrow_mut();
        let mut i = 0;
        while i < foreign.len() {
            if foreign[i].at <= now {
                let alarm = foreign.swap_remove(i);
                due.push((alarm.at, alarm.seq, Target::Foreign(alarm.waker)));
            } else {
                i += 1;
            }
        }
        s.foreign_next
            .set(foreign.iter().map(|a| a.at).min().unwrap_or(NEVER));
    });
    for p in [LOW, HIGH] {
        let slot = s.alarms[p].get();
        if slot.is_set() && slot.at <= now {
            s.alarms[p].set(EMPTY);
            due.push((slot.at, slot.seq, Target::Priority(p)));
        }
    }
    // (deadline, arrival) is unique: the unstable sort gives the stable order.
    due.sort_unstable_by_key(|&(at, seq, _)| (at, seq));
    for (_, _, target) in due.drain(..) {
        match target {
            Target::Priority(p) => s.pending[p].set(true),
            Target::Foreign(waker) => waker.wake(),
        }
    }
    DUE.with(|d| d.replace(due));
}

/// Runs `deciding` as [`simulate`] does, with `sensing` at the higher priority beside it:
/// whenever `sensing` has work it is polled before `deciding` (see the module doc), from the
/// first poll of `deciding` on. Returns what `deciding` returns; `sensing` is not polled after
/// that (nor after it ends), and both are dropped before this returns.
pub fn simulate_split<S: Future, D: Future>(
    sensing: S,
    deciding: D,
    limit: Duration,
) -> Result<Completed<D::Output>, SimError> {
    run(pin!(deciding), Some(pin!(sensing)), limit)
}

/// Ends the thread's simulation, on return and on unwind: nothing outlives it.
struct Running<'s>(&'s State);

impl Drop for Running<'_> {
    fn drop(&mut self) {
        self.0.clear();
        self.0.running.set(false);
    }
}

/// Moves this thread's virtual clock forward to `at` (never back) from inside a poll, as the
/// processor time a computation spends moves a chip's clock: for replaying a recording made
/// where computing takes time. Timers due by then fire when the poll returns.
pub fn advance_to(at: Instant) {
    STATE.with(|s| s.now.set(s.now.get().max(at.as_ticks())));
}

/// Runs `future` to completion in virtual time starting at 0, on this thread. Fails when the
/// future deadlocks or is still running at `limit`.
pub fn simulate<F: Future>(future: F, limit: Duration) -> Result<Completed<F::Output>, SimError> {
    run(
        pin!(future),
        None::<Pin<&mut std::future::Pending<()>>>,
        limit,
    )
}

/// One poll of the sensing side; whether it ended. Out of line, so that a profile of the host
/// shows a sensing step as one function (`cargo xtask timing`).
#[inline(never)]
fn poll_sensing<S: Future>(sensing: Pin<&mut S>, cx: &mut Context<'_>) -> bool {
    sensing.poll(cx).is_ready()
}

/// The poll loop: `future` at the lower priority, `high` (if any) at the higher. Both are
/// pinned by the caller and polled in place: never moved, never type-erased.
fn run<F: Future, S: Future>(
    mut future: Pin<&mut F>,
    mut high: Option<Pin<&mut S>>,
    limit: Duration,
) -> Result<Completed<F::Output>, SimError> {
    STATE.with(|s| {
        if s.running.replace(true) {
            return Err(SimError::Nested);
        }
        let _running = Running(s);
        // Whatever a waker outside any simulation left here is not this simulation's.
        s.clear();
        s.now.set(0);
        s.seq.set(0);
        let [low, high_waker] = WAKERS.with(Clone::clone);
        for (slot, waker) in s.wakers.iter().zip([&low, &high_waker]) {
            slot.set(waker.data());
        }
        let (mut low_cx, mut high_cx) =
            (Context::from_waker(&low), Context::from_waker(&high_waker));
        let limit = limit.as_ticks();
        let mut clock_jumps = 0u64;
        s.pending[LOW].set(true);
        // The deciding side is polled first; the sensing side has work from then on. (One
        // call site for each poll, so that the compiler may inline them into the loop.)
        let mut starting = high.is_some();
        let output = loop {
            if s.pending[HIGH].replace(false) {
                // One that ends is polled no more.
                if let Some(sensing) = high.as_mut()
                    && poll_sensing(sensing.as_mut(), &mut high_cx)
                {
                    high = None;
                }
            } else if s.pending[LOW].replace(false) {
                if starting {
                    starting = false;
                    s.pending[HIGH].set(true);
                }
                if let Poll::Ready(output) = future.as_mut().poll(&mut low_cx) {
                    break output;
                }
            } else if advance(s, limit)? {
                clock_jumps += 1;
            } else {
                return Err(SimError::Deadlock {
                    at: Instant::from_ticks(s.now.get()),
                });
            }
        };
        Ok(Completed {
            output,
            elapsed: Duration::from_ticks(s.now.get()),
            clock_jumps,
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::{Arc, Mutex};
    use std::task::Wake;

    use embassy_sync::blocking_mutex::raw::NoopRawMutex;
    use embassy_sync::signal::Signal;
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
    fn a_panicking_future_leaves_the_thread_usable() {
        let log = RefCell::new(Vec::new());
        let panicked = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            simulate_split(
                std::future::pending::<()>(),
                async {
                    Timer::after_secs(1).await;
                    panic!("on purpose")
                },
                Duration::from_secs(10),
            )
        }));
        assert!(panicked.is_err());
        let ok = simulate_split(
            async { log.borrow_mut().push(Instant::now()) },
            // Made inside: `Timer::after` reads the clock when made.
            async { Timer::after_secs(2).await },
            Duration::from_secs(10),
        )
        .unwrap();
        // From time 0, with the sensing slot free again.
        assert_eq!(ok.elapsed, Duration::from_secs(2));
        assert_eq!(*log.borrow(), [Instant::from_ticks(0)]);
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
        // A timer at the end of time is a timer too, not a deadlock.
        let err = simulate(Timer::at(Instant::MAX), Duration::from_secs(10)).unwrap_err();
        assert!(matches!(err, SimError::TimeLimit { .. }));
        let end = simulate(Timer::at(Instant::MAX), Duration::MAX).unwrap();
        assert_eq!((end.elapsed, end.clock_jumps), (Duration::MAX, 1));
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

    /// A foreign waker: logs its name when woken, then wakes `then`, if set.
    struct Logger {
        name: &'static str,
        log: Arc<Mutex<Vec<(&'static str, u64)>>>,
        then: Mutex<Option<Waker>>,
    }

    impl Wake for Logger {
        fn wake(self: Arc<Self>) {
            self.wake_by_ref();
        }

        fn wake_by_ref(self: &Arc<Self>) {
            let now = Instant::now().as_millis();
            self.log.lock().unwrap().push((self.name, now));
            if let Some(w) = self.then.lock().unwrap().take() {
                w.wake();
            }
        }
    }

    fn logger(name: &'static str, log: &Arc<Mutex<Vec<(&'static str, u64)>>>) -> Arc<Logger> {
        Arc::new(Logger {
            name,
            log: log.clone(),
            then: Mutex::new(None),
        })
    }

    #[test]
    fn equal_deadlines_wake_in_arrival_order() {
        let log = Arc::new(Mutex::new(Vec::new()));
        let [a, b, c, d] = ["a", "b", "c", "d"].map(|n| Waker::from(logger(n, &log)));
        let done = simulate(
            async {
                let at = |ms| Instant::from_millis(ms).as_ticks();
                embassy_time_driver::schedule_wake(at(10), &a);
                embassy_time_driver::schedule_wake(at(5), &b);
                embassy_time_driver::schedule_wake(at(10), &c);
                embassy_time_driver::schedule_wake(at(5), &d);
                // Earlier: `a` moves to 5 ms and keeps its arrival, first; later: ignored.
                embassy_time_driver::schedule_wake(at(5), &a);
                embassy_time_driver::schedule_wake(at(20), &c);
                // The simulated future's own timer, between foreign ones at 10 ms.
                Timer::at(Instant::from_millis(10)).await;
                Timer::at(Instant::from_millis(30)).await;
            },
            Duration::from_secs(1),
        )
        .unwrap();
        assert_eq!(
            *log.lock().unwrap(),
            [("a", 5), ("b", 5), ("d", 5), ("c", 10)]
        );
        assert_eq!(done.clock_jumps, 3);
        assert_eq!(done.elapsed, Duration::from_millis(30));
    }

    #[test]
    fn sensing_is_polled_before_deciding_at_one_instant() {
        let log = RefCell::new(Vec::new());
        let work = Signal::<NoopRawMutex, u32>::new();
        let done = simulate_split(
            async {
                loop {
                    let n = work.wait().await;
                    log.borrow_mut().push(("sensing", n));
                }
            },
            async {
                // Deciding registers its timer first, yet sensing runs first at 10 ms.
                Timer::at(Instant::from_millis(10)).await;
                log.borrow_mut().push(("deciding", 0));
                for n in 1..=3 {
                    // Sensing gets work, and runs before deciding's next poll, at this instant.
                    work.signal(n);
                    embassy_futures::yield_now().await;
                    log.borrow_mut().push(("deciding", n));
                }
                Instant::now().as_millis()
            },
            Duration::from_secs(1),
        );
        assert_eq!(done.unwrap().output, 10);
        assert_eq!(
            *log.borrow(),
            [
                ("deciding", 0),
                ("sensing", 1),
                ("deciding", 1),
                ("sensing", 2),
                ("deciding", 2),
                ("sensing", 3),
                ("deciding", 3),
            ]
        );
    }

    #[test]
    fn sensing_wakes_before_deciding_at_an_equal_deadline() {
        let log = RefCell::new(Vec::new());
        let done = simulate_split(
            async {
                Timer::at(Instant::from_millis(10)).await;
                log.borrow_mut().push("sensing");
                std::future::pending::<()>().await
            },
            async {
                // Polled first, so its timer arrives first.
                Timer::at(Instant::from_millis(10)).await;
                log.borrow_mut().push("deciding");
            },
            Duration::from_secs(1),
        )
        .unwrap();
        assert_eq!(*log.borrow(), ["sensing", "deciding"]);
        assert_eq!(done.clock_jumps, 1);
    }

    #[test]
    fn a_foreign_waker_gets_its_timer() {
        let log = Arc::new(Mutex::new(Vec::new()));
        let inner = logger("inner", &log);
        let foreign = Waker::from(inner.clone());
        let done = simulate(
            async {
                // A timer polled with a waker of its own, which wakes this future in turn.
                let mut timer = pin!(Timer::after_millis(5));
                let mut own = pin!(Timer::after_millis(8));
                let mut own_done = false;
                std::future::poll_fn(|cx| {
                    *inner.then.lock().unwrap() = Some(cx.waker().clone());
                    own_done |= own.as_mut().poll(cx).is_ready();
                    let timer_done = timer
                        .as_mut()
                        .poll(&mut Context::from_waker(&foreign))
                        .is_ready();
                    if own_done && timer_done {
                        Poll::Ready(Instant::now().as_millis())
                    } else {
                        Poll::Pending
                    }
                })
                .await
            },
            Duration::from_secs(1),
        )
        .unwrap();
        assert_eq!(done.output, 8);
        assert_eq!(done.clock_jumps, 2);
        assert_eq!(*log.lock().unwrap(), [("inner", 5)]);

        // A foreign timer left pending does not outlive its simulation.
        let err = simulate(
            async {
                let at = Instant::from_millis(50).as_ticks();
                embassy_time_driver::schedule_wake(at, &Waker::from(logger("left", &log)));
            },
            Duration::from_secs(1),
        );
        assert!(err.is_ok());
        let err = simulate(std::future::pending::<()>(), Duration::from_secs(1)).unwrap_err();
        assert_eq!(
            err,
            SimError::Deadlock {
                at: Instant::from_ticks(0)
            }
        );
        assert_eq!(log.lock().unwrap().len(), 1);
    }
}

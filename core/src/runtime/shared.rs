//! The state the sensing and deciding sides share, behind one mutex: the command the
//! deciding side gives (which sensors run, and how), the beliefs' version, the violation,
//! and each side's waker.

use core::cell::{Cell, RefCell};
use core::future::Future;
use core::pin::Pin;
use core::task::{Context, Poll, Waker};

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_time::{Duration, Instant, Timer};

use crate::action::{ActionId, SensorId, SensorSet};
use crate::facts::FactSetOf;
use crate::failure::{Failure, Violation};
use crate::store::Entry;

/// What the deciding side asks of the sensing side: the sensors to run and how.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Command<const W: usize> {
    /// Moves on with every command; a sampler serves one epoch at a time.
    pub(crate) epoch: u32,
    pub(crate) sensors: SensorSet,
    pub(crate) mode: Mode,
    /// The running action and its precondition, checked after every sample.
    pub(crate) watch: Option<(ActionId, FactSetOf<W>)>,
    /// Cyclic sensors are due at this instant first.
    pub(crate) start: Instant,
}

/// How the commanded sensors sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Mode {
    /// Beside an action: cyclic sensors every period, one-shot ones once at the start,
    /// on-demand ones on request.
    Parallel,
    /// An SMPA sense phase: as `Parallel`, with one-shot sensors only in the first phase.
    Phase { first: bool },
    /// The initial model: every commanded sensor samples once.
    Once,
}

/// State the two sides share. Only `Cell`s, so reads and writes cannot fail; the waker lists
/// are the `RefCell`s, never borrowed across a call out.
pub(crate) struct Shared<const NS: usize, const W: usize> {
    pub(crate) beliefs: Cell<FactSetOf<W>>,
    pub(crate) percepts: [Cell<Option<Entry>>; NS],
    /// What each sensor's latest sample says of its `per(s)`.
    pub(crate) holds: [Cell<FactSetOf<W>>; NS],
    /// The sensors switched on.
    pub(crate) running: Cell<SensorSet>,
    /// The running sensors that have sampled since they were switched on.
    pub(crate) fresh: Cell<SensorSet>,
    /// Samples lost in a row, per sensor.
    pub(crate) lost: [Cell<u8>; NS],
    /// When each sensor's latest read started.
    pub(crate) last_read: [Cell<Option<Instant>>; NS],
    /// Facts some sample has decided (true or false) since the start.
    pub(crate) sensed: Cell<FactSetOf<W>>,
    /// Sensors that failed: out of service until [`Engine::clear_faults`].
    pub(crate) faulty: Cell<SensorSet>,
    pub(crate) violation: Cell<Option<Violation<W>>>,
    pub(crate) requests: Cell<SensorSet>,
    pub(crate) version: Cell<u32>,
    pub(crate) command: Cell<Command<W>>,
    /// The command's epoch, apart: samplers read it at every await.
    pub(crate) epoch: Cell<u32>,
    /// Sensors of the current command that are on and have taken the samples due at its start.
    pub(crate) ready: Cell<SensorSet>,
    /// Sensors whose sampler is between switching on and having switched off.
    pub(crate) active: Cell<SensorSet>,
    /// The first failure under the command of that epoch.
    pub(crate) failure: Cell<Option<(u32, Failure<W>)>>,
    /// The deciding side's task (behaviours, the precondition watch and the control loop).
    /// One task per side: a registration of another waker wakes the one it replaces.
    pub(crate) deciding: Waiter,
    /// The sensing side's task (the samplers).
    pub(crate) sensing: Waiter,
}

impl<const NS: usize, const W: usize> Shared<NS, W> {
    /// Something the deciding side may wait for changed: bump the version and wake it.
    pub(crate) fn notify(&self) {
        self.version.set(self.version.get().wrapping_add(1));
        self.deciding.wake();
    }

    /// A read of `sensor` started at `at`.
    pub(crate) fn record_read(&self, sensor: SensorId, at: Instant) {
        if let Some(r) = self.last_read.get(sensor.index()) {
            r.set(Some(at));
        }
    }
}

/// The waker of one side's task. Unlike embassy-sync's `WakerRegistration` it keeps the waker
/// when it wakes it: a side registers again at nearly every poll, and a kept waker makes that a
/// comparison instead of a clone. A later wake of a task that waits for something else is a
/// spurious wake, which futures allow.
pub(crate) struct Waiter(RefCell<Option<Waker>>);

impl Waiter {
    pub(crate) const fn new() -> Self {
        Self(RefCell::new(None))
    }

    /// Makes `waker` the one woken. One task per side: a different waker replaces the one
    /// registered, which is woken so that it can register again.
    pub(crate) fn register(&self, waker: &Waker) {
        let replaced = match self.0.try_borrow_mut() {
            Ok(mut slot) => match &*slot {
                Some(kept) if kept.will_wake(waker) => None,
                _ => slot.replace(waker.clone()),
            },
            Err(_) => None,
        };
        if let Some(replaced) = replaced {
            replaced.wake();
        }
    }

    /// Wakes the registered task, if any.
    pub(crate) fn wake(&self) {
        if let Ok(slot) = self.0.try_borrow()
            && let Some(waker) = &*slot
        {
            waker.wake_by_ref();
        }
    }
}

/// A wait on the shared state `shared`: `done` decides, and when it says not yet the waker is
/// registered with the side's wakers (`wakers`), in the same lock, so that a side that preempts
/// in between cannot wake nobody.
pub(crate) fn poll_shared<M: RawMutex, const NS: usize, const W: usize, R>(
    shared: &Mutex<M, Shared<NS, W>>,
    cx: &Context<'_>,
    wakers: impl FnOnce(&Shared<NS, W>) -> &Waiter,
    done: impl FnOnce(&Shared<NS, W>) -> Option<R>,
) -> Poll<R> {
    shared.lock(|s| match done(s) {
        Some(r) => Poll::Ready(r),
        None => {
            wakers(s).register(cx.waker());
            Poll::Pending
        }
    })
}

/// The future of [`Engine::watch`]: polled before the behaviour at every step of it, so a
/// future of its own rather than an `async fn` around a `poll_fn`.
pub(crate) struct Watch<'s, M: RawMutex, const NS: usize, const W: usize> {
    pub(crate) shared: &'s Mutex<M, Shared<NS, W>>,
    pub(crate) epoch: u32,
    pub(crate) action: ActionId,
    pub(crate) max: Duration,
    /// The timer of the current violation's deadline.
    pub(crate) alarm: Option<(Instant, Timer)>,
    /// Whether this task's waker is registered with the deciding side's: once it is, it stays
    /// (a `Waiter` keeps its waker until another replaces it, and every waker that could
    /// replace it wakes this same task, which polls this watch with the rest).
    pub(crate) registered: bool,
}

impl<M: RawMutex, const NS: usize, const W: usize> Future for Watch<'_, M, NS, W> {
    type Output = Failure<W>;

    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Failure<W>> {
        let this = self.get_mut();
        let epoch = this.epoch;
        // Registered in the same lock as the check: a delivery in between cannot be missed.
        let register = !core::mem::replace(&mut this.registered, true);
        let seen = this.shared.lock(|s| {
            if register {
                s.deciding.register(cx.waker());
            }
            match s.failure.get() {
                Some((e, failure)) if e == epoch => Err(failure),
                _ => Ok(s.violation.get()),
            }
        });
        let violation = match seen {
            Err(failure) => return Poll::Ready(failure),
            Ok(None) => {
                this.alarm = None;
                return Poll::Pending;
            }
            Ok(Some(v)) => v,
        };
        let deadline = violation.since.saturating_add(this.max);
        if Instant::now() >= deadline {
            return Poll::Ready(Failure::PreconditionViolated {
                action: this.action,
                missing: violation.missing,
            });
        }
        let timer = match &mut this.alarm {
            Some((at, timer)) if *at == deadline => timer,
            slot => &mut slot.insert((deadline, Timer::at(deadline))).1,
        };
        // Pending: the timer wakes this task at the deadline.
        let _ = Pin::new(timer).poll(cx);
        Poll::Pending
    }
}

//! The watch of a running action, polled by the deciding side in the same lock as its check.

use core::future::Future;
use core::pin::Pin;
use core::task::{Context, Poll};

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_time::{Duration, Instant, Timer};

use crate::action::ActionId;
use crate::facts::FactSetOf;
use crate::failure::Failure;
use crate::spec::storage::Shared;

/// The watch of a running action: the first failure the sensing side reports under command
/// `epoch`, or the violation of `pre(a)` once it has lasted `max`. Polled by the parallel
/// state before its behaviour at every step, in the same lock as its check.
pub(crate) struct Watch<F> {
    pub(crate) epoch: u32,
    pub(crate) action: ActionId,
    pub(crate) max: Duration,
    /// The timer of the current violation's deadline.
    pub(crate) alarm: Option<(Instant, Timer)>,
    /// Whether this task's waker is registered with the deciding side's: once it is, it stays
    /// (a `Waiter` keeps its waker until another replaces it, and every waker that could
    /// replace it wakes this same task, which polls this watch with the rest).
    pub(crate) registered: bool,
    pub(crate) _facts: core::marker::PhantomData<F>,
}

impl<const W: usize> Watch<FactSetOf<W>> {
    /// One look: `Ready` with the failure that ends the state, else `Pending` with the task
    /// woken by the next delivery or the violation's deadline.
    pub(crate) fn poll<M: RawMutex, S>(
        &mut self,
        shared: &Mutex<M, Shared<FactSetOf<W>, S>>,
        cx: &mut Context<'_>,
    ) -> Poll<Failure<W>> {
        let epoch = self.epoch;
        // Registered in the same lock as the check: a delivery in between cannot be missed.
        let register = !core::mem::replace(&mut self.registered, true);
        let seen = shared.lock(|s| {
            if register {
                s.deciding.register(cx.waker());
            }
            // Nearly every step: nothing wrong.
            if !s.alert.get() {
                return Ok(None);
            }
            match s.failure.get() {
                Some((e, failure)) if e == epoch => Err(failure),
                _ => Ok(s.violation.get()),
            }
        });
        let violation = match seen {
            Err(failure) => return Poll::Ready(failure),
            Ok(None) => {
                if self.alarm.is_some() {
                    self.alarm = None;
                }
                return Poll::Pending;
            }
            Ok(Some(v)) => v,
        };
        let deadline = violation.since.saturating_add(self.max);
        if Instant::now() >= deadline {
            return Poll::Ready(Failure::PreconditionViolated {
                action: self.action,
                missing: violation.missing,
            });
        }
        let timer = match &mut self.alarm {
            Some((at, timer)) if *at == deadline => timer,
            slot => &mut slot.insert((deadline, Timer::at(deadline))).1,
        };
        // Pending: the timer wakes this task at the deadline.
        let _ = Pin::new(timer).poll(cx);
        Poll::Pending
    }
}

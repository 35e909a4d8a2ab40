//! A sensing side beside a deciding side, at a higher priority: [`Beside`] hands the sensing
//! future to a [`HighSlot`] that a higher-priority task polls (the virtual-time backend's
//! loop on a host, an interrupt executor's task on a microcontroller) for as long as the
//! deciding future runs. `no_std`; the firmware uses it as the host does.

use core::marker::PhantomData;
use core::pin::Pin;
use core::task::{Context, Poll};

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
/// a platform's `beside` on a platform with a higher-priority task polling `slot`. One at a time:
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

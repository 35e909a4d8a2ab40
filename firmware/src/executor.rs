//! A thread-mode embassy executor that sleeps with WFI between polls (QEMU treats WFE as a
//! no-op, so an executor waiting with WFE would spin). No `platform-*` feature of
//! embassy-executor: this module provides `__pender`.

use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicBool, Ordering};

use embassy_executor::{Spawner, raw};

static PENDING: AtomicBool = AtomicBool::new(false);

#[unsafe(export_name = "__pender")]
fn pender(_context: *mut ()) {
    PENDING.store(true, Ordering::Release);
}

/// Creates the executor in `slot`, lets `init` spawn, then polls whenever something is
/// pending and sleeps otherwise. Never returns: the firmware ends with a semihosting exit.
pub fn run(slot: &'static mut MaybeUninit<raw::Executor>, init: impl FnOnce(Spawner)) -> ! {
    let executor: &'static raw::Executor = slot.write(raw::Executor::new(core::ptr::null_mut()));
    init(executor.spawner());
    PENDING.store(true, Ordering::Release);
    loop {
        if PENDING.swap(false, Ordering::AcqRel) {
            // SAFETY: only this loop polls the executor; the pender never calls `poll`.
            unsafe { executor.poll() };
            continue;
        }
        // Interrupts off between the check and WFI, so a wake cannot slip in unseen; a pending
        // interrupt still ends WFI.
        cortex_m::interrupt::disable();
        if !PENDING.load(Ordering::Acquire) {
            cortex_m::asm::wfi();
        }
        // SAFETY: not inside a critical section.
        unsafe { cortex_m::interrupt::enable() };
    }
}

//! A thread-mode embassy executor that sleeps with WFI between polls (QEMU treats WFE as a
//! no-op, so an executor waiting with WFE would spin). No `platform-*` feature of
//! embassy-executor: this module provides `__pender`.

use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicBool, Ordering};

use embassy_executor::{Spawner, raw};

static PENDING: AtomicBool = AtomicBool::new(false);

/// How long polls took, in core cycles.
#[derive(Clone, Copy, Debug, Default)]
pub struct Polls {
    /// Polls run.
    pub count: u32,
    /// The longest.
    pub max_cycles: u32,
    /// The tick at which the longest one began.
    pub max_at: u64,
    /// All of them together.
    pub total_cycles: u64,
}

static POLLS: critical_section::Mutex<core::cell::Cell<Polls>> =
    critical_section::Mutex::new(core::cell::Cell::new(Polls {
        count: 0,
        max_cycles: 0,
        max_at: 0,
        total_cycles: 0,
    }));

/// The poll statistics since the last call, which starts them again.
pub fn take_polls() -> Polls {
    critical_section::with(|cs| POLLS.borrow(cs).replace(Polls::default()))
}

fn record(begin: u64, end: u64, tick: u64) {
    let cycles = u32::try_from(end.saturating_sub(begin)).unwrap_or(u32::MAX);
    critical_section::with(|cs| {
        let cell = POLLS.borrow(cs);
        let mut p = cell.get();
        p.count = p.count.saturating_add(1);
        p.total_cycles = p.total_cycles.saturating_add(u64::from(cycles));
        if cycles > p.max_cycles {
            p.max_cycles = cycles;
            p.max_at = tick;
        }
        cell.set(p);
    });
}

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
            crate::time_driver::latch();
            let (begin, tick) = (
                crate::time_driver::cycles(),
                embassy_time::Instant::now().as_ticks(),
            );
            // SAFETY: only this loop polls the executor; the pender never calls `poll`.
            unsafe { executor.poll() };
            record(begin, crate::time_driver::cycles(), tick);
            crate::time_driver::release();
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

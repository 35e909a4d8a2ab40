//! A thread-mode embassy executor that sleeps with WFI between polls (QEMU treats WFE as a
//! no-op, so an executor waiting with WFE would spin). No `platform-*` feature of
//! embassy-executor: this module provides `__pender`.

use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

use embassy_executor::{Spawner, raw};

static PENDING: AtomicBool = AtomicBool::new(false);

/// What a poll did, from the trace events it emitted ([`note`]): a sample of sensor `i` sets
/// bit `i`; planning, plan and state changes set [`CONTROL`]; a poll that emits nothing is a
/// behaviour step.
pub const CONTROL: u32 = 1 << 8;

/// Sensors whose sample steps are told apart.
pub const SENSORS: usize = 4;

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
    /// The longest poll that sampled sensor `i` (and maybe others), without control work.
    pub max_sample: [u32; SENSORS],
    /// The longest poll that planned, selected a plan or moved the FSM.
    pub max_control: u32,
    /// The longest poll that did none of that: a behaviour step.
    pub max_behaviour: u32,
}

static POLLS: critical_section::Mutex<core::cell::Cell<Polls>> =
    critical_section::Mutex::new(core::cell::Cell::new(Polls {
        count: 0,
        max_cycles: 0,
        max_at: 0,
        total_cycles: 0,
        max_sample: [0; SENSORS],
        max_control: 0,
        max_behaviour: 0,
    }));

/// Steps of the running poll.
static STEPS: AtomicU32 = AtomicU32::new(0);

/// Records that the running poll did `steps`.
pub fn note(steps: u32) {
    STEPS.fetch_or(steps, Ordering::Relaxed);
}

/// The poll statistics since the last call, which starts them again.
pub fn take_polls() -> Polls {
    critical_section::with(|cs| POLLS.borrow(cs).replace(Polls::default()))
}

fn record(begin: u64, end: u64, tick: u64) {
    let cycles = u32::try_from(end.saturating_sub(begin)).unwrap_or(u32::MAX);
    let steps = STEPS.swap(0, Ordering::Relaxed);
    critical_section::with(|cs| {
        let cell = POLLS.borrow(cs);
        let mut p = cell.get();
        p.count = p.count.saturating_add(1);
        p.total_cycles = p.total_cycles.saturating_add(u64::from(cycles));
        if cycles > p.max_cycles {
            p.max_cycles = cycles;
            p.max_at = tick;
        }
        // A poll that also planned or moved the FSM counts as control only: control is
        // sporadic and bounded as blocking; sample steps are the periodic jobs.
        if steps & CONTROL != 0 {
            p.max_control = p.max_control.max(cycles);
        } else {
            for (i, max) in p.max_sample.iter_mut().enumerate() {
                if steps & (1 << i) != 0 {
                    *max = (*max).max(cycles);
                }
            }
        }
        if steps == 0 {
            p.max_behaviour = p.max_behaviour.max(cycles);
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

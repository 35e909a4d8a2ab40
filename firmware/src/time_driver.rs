//! The embassy-time driver on SysTick, tickless: a SysTick period runs from the current tick to
//! the next deadline, in whole ticks of the tick rate (1 kHz, the host's, so that `Duration`
//! rounding and therefore traces agree). The interrupt comes at the deadline tick itself, and
//! only then: a run with a sample every 20 ms takes 50 interrupts a second, not 1000.
//!
//! `now = base + elapsed cycles / cycles per tick`. Starting a new period at the current tick
//! keeps time continuous and monotonic; the fraction of the tick in progress is stretched,
//! which shifts the tick grid against the core clock by less than a tick and is not observable
//! by the program. Under QEMU's `-icount` all of it is deterministic.
//!
//! Logical time: `now()` answers the instant of the deadline the executors last woke for, and
//! moves on only when both executors are idle ([`advance`], called from the executor loop):
//! the SysTick interrupt just ends the WFI at a deadline, and the loop then wakes the timers
//! due. This is the host simulator's rule (time jumps to the next deadline once every task
//! waits), so a burst of work at one instant is stamped with that instant however many polls
//! it takes, and the firmware's trace equals the host's. What a task observes depends on what
//! happened, not on how fast the core ran it; how long polls take is measured in cycles
//! ([`cycles`]). A burst that outlasts the time to the next deadline delays that deadline's
//! work in real time, not in the trace: `cargo xtask timing` bounds the bursts.

use core::cell::{Cell, RefCell};
use core::sync::atomic::{AtomicU32, Ordering};
use core::task::Waker;

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::{SCB, SYST};
use cortex_m_rt::exception;
use critical_section::{CriticalSection, Mutex};
use embassy_time_driver::Driver;
use embassy_time_queue_utils::Queue;

/// Core clock of mps2-an386 in QEMU; SysTick counts it.
pub const CORE_HZ: u32 = 25_000_000;
/// Core cycles per tick.
pub const CYCLES_PER_TICK: u32 = CORE_HZ / embassy_time_driver::TICK_HZ as u32;
/// The longest SysTick period in whole ticks (the reload value has 24 bits).
const MAX_PERIOD: u32 = 0x00FF_FFFF / CYCLES_PER_TICK;

struct SysTickDriver {
    /// The tick at which the current SysTick period started.
    base: Mutex<Cell<u64>>,
    /// Core cycles counted before the current SysTick period (for measuring, not timing).
    cycles_before: Mutex<Cell<u64>>,
    /// Its length in ticks.
    period: Mutex<Cell<u32>>,
    /// The logical instant: the deadline the executors last woke for.
    logical: Mutex<Cell<u64>>,
    /// The earliest deadline in `queue`, `u64::MAX` when there is none.
    alarm: Mutex<Cell<u64>>,
    queue: Mutex<RefCell<Queue>>,
}

/// SysTick's registers (the driver is their only user).
fn syst() -> &'static cortex_m::peripheral::syst::RegisterBlock {
    // SAFETY: a fixed, always-mapped system peripheral; only this module touches it.
    unsafe { &*SYST::PTR }
}

impl SysTickDriver {
    /// Core cycles since the current period started (a wrap not yet handled included).
    fn elapsed(&self) -> u32 {
        let reload = syst().rvr.read();
        let before = syst().cvr.read();
        if SCB::is_pendst_pending() {
            reload + 1 + (reload - syst().cvr.read())
        } else {
            reload - before
        }
    }

    fn now_in(&self, cs: CriticalSection<'_>) -> u64 {
        let (base, period) = (self.base.borrow(cs).get(), self.period.borrow(cs).get());
        let reload = syst().rvr.read();
        let before = syst().cvr.read();
        // Interrupts are masked here, but the counter runs: it may have wrapped.
        if SCB::is_pendst_pending() {
            let after = syst().cvr.read();
            base + u64::from(period) + u64::from((reload - after) / CYCLES_PER_TICK)
        } else {
            base + u64::from((reload - before) / CYCLES_PER_TICK)
        }
    }

    /// Starts a SysTick period at tick `now` that ends at the earliest deadline.
    fn program(&self, cs: CriticalSection<'_>, now: u64) {
        let alarm = self.alarm.borrow(cs).get();
        let ticks = alarm.saturating_sub(now).clamp(1, u64::from(MAX_PERIOD)) as u32;
        let counted = self.cycles_before.borrow(cs);
        counted.set(counted.get() + u64::from(self.elapsed()));
        let s = syst();
        // SAFETY: SysTick is only driven from here; writing CVR makes the counter reload from
        // RVR at the next clock (no interrupt: it did not count down to 0).
        unsafe {
            s.rvr.write(ticks * CYCLES_PER_TICK - 1);
            s.cvr.write(0);
        }
        SCB::clear_pendst();
        self.base.borrow(cs).set(now);
        self.period.borrow(cs).set(ticks);
    }

    /// Wakes what is due at `now` and remembers the next deadline.
    fn expire(&self, cs: CriticalSection<'_>, now: u64) {
        let next = self.queue.borrow_ref_mut(cs).next_expiration(now);
        self.alarm.borrow(cs).set(next);
    }
}

impl Driver for SysTickDriver {
    fn now(&self) -> u64 {
        critical_section::with(|cs| self.logical.borrow(cs).get())
    }

    fn schedule_wake(&self, at: u64, waker: &Waker) {
        critical_section::with(|cs| {
            // A deadline that has come is due now: the task is polled again at this instant.
            if at <= self.logical.borrow(cs).get() {
                waker.wake_by_ref();
                return;
            }
            if self.queue.borrow_ref_mut(cs).schedule_wake(at, waker) {
                let alarm = self.alarm.borrow(cs);
                alarm.set(alarm.get().min(at));
                let end = self.base.borrow(cs).get() + u64::from(self.period.borrow(cs).get());
                if at < end {
                    let now = self.now_in(cs);
                    self.program(cs, now);
                }
            }
        });
    }
}

embassy_time_driver::time_driver_impl!(static DRIVER: SysTickDriver = SysTickDriver {
    base: Mutex::new(Cell::new(0)),
    cycles_before: Mutex::new(Cell::new(0)),
    period: Mutex::new(Cell::new(MAX_PERIOD)),
    logical: Mutex::new(Cell::new(0)),
    alarm: Mutex::new(Cell::new(u64::MAX)),
    queue: Mutex::new(RefCell::new(Queue::new())),
});

#[exception]
fn SysTick() {
    let begin = critical_section::with(|cs| {
        // The period ran out and the counter reloaded (taking the exception cleared the pending
        // flag, so `elapsed` now counts from the reload): count the whole period.
        let counted = DRIVER.cycles_before.borrow(cs);
        counted.set(counted.get() + u64::from(syst().rvr.read()) + 1);
        counted.get() + u64::from(DRIVER.elapsed())
    });
    critical_section::with(|cs| {
        // The period ended: this is its last tick. The executor loop, woken from WFI, wakes
        // the timers due.
        let now = DRIVER.base.borrow(cs).get() + u64::from(DRIVER.period.borrow(cs).get());
        DRIVER.program(cs, now);
    });
    let cycles = cycles().saturating_sub(begin);
    ISR_MAX_CYCLES.fetch_max(u32::try_from(cycles).unwrap_or(u32::MAX), Ordering::Relaxed);
}

/// The longest SysTick handler so far, in cycles from its first statement to its last
/// (exception entry and exit, 12 cycles each on a Cortex-M4, come on top).
static ISR_MAX_CYCLES: AtomicU32 = AtomicU32::new(0);

/// The longest SysTick handler since the last call, which starts again.
pub fn take_isr_max_cycles() -> u32 {
    ISR_MAX_CYCLES.swap(0, Ordering::Relaxed)
}

/// Starts the clock at tick 0: SysTick from the core clock, interrupting at deadlines.
pub fn start(syst: &mut SYST) {
    syst.set_clock_source(SystClkSource::Core);
    critical_section::with(|cs| DRIVER.program(cs, 0));
    syst.enable_interrupt();
    syst.enable_counter();
}

/// Puts the clock back to tick 0 with no timer pending: every run starts at 0, as every host
/// simulation does. Wakers of the previous run are dropped (their futures are gone).
pub fn restart() {
    critical_section::with(|cs| {
        *DRIVER.queue.borrow_ref_mut(cs) = Queue::new();
        DRIVER.alarm.borrow(cs).set(u64::MAX);
        DRIVER.program(cs, 0);
        DRIVER.logical.borrow(cs).set(0);
    });
}

/// Called when both executors are idle: if the earliest deadline has come on the counter, moves
/// the logical instant to it and wakes the timers due then; `true` when it did (there is work
/// again), `false` when the loop may sleep until the next interrupt.
pub fn advance() -> bool {
    critical_section::with(|cs| {
        let next = DRIVER.alarm.borrow(cs).get();
        if next == u64::MAX || next > DRIVER.now_in(cs) {
            return false;
        }
        let logical = DRIVER.logical.borrow(cs);
        logical.set(logical.get().max(next));
        DRIVER.expire(cs, logical.get());
        true
    })
}

/// Core cycles since the clock started, from SysTick's counter: a cycle stamp for measuring
/// how long code runs (exact under QEMU's `-icount`, where each instruction is one cycle).
pub fn cycles() -> u64 {
    critical_section::with(|cs| DRIVER.cycles_before.borrow(cs).get() + u64::from(DRIVER.elapsed()))
}

//! The embassy-time driver: SysTick interrupts at the tick rate (1 kHz, the same as the host,
//! so that `Duration` rounding and therefore traces agree). Each tick compares the count with
//! the earliest deadline and wakes what is due at that very tick, as the host's virtual clock
//! does when it jumps to a deadline.

use core::cell::{Cell, RefCell};
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

struct SysTickDriver {
    ticks: Mutex<Cell<u64>>,
    /// The earliest deadline in `queue`, `u64::MAX` when there is none.
    alarm: Mutex<Cell<u64>>,
    queue: Mutex<RefCell<Queue>>,
}

impl SysTickDriver {
    /// Wakes what is due at `now` and arms the next deadline.
    fn expire(&self, cs: CriticalSection<'_>, now: u64) {
        let next = self.queue.borrow_ref_mut(cs).next_expiration(now);
        self.alarm.borrow(cs).set(next);
    }
}

impl Driver for SysTickDriver {
    fn now(&self) -> u64 {
        // Two words on this core: read them in one critical section.
        critical_section::with(|cs| self.ticks.borrow(cs).get())
    }

    fn schedule_wake(&self, at: u64, waker: &Waker) {
        critical_section::with(|cs| {
            if self.queue.borrow_ref_mut(cs).schedule_wake(at, waker) {
                // A deadline already past is woken at once.
                let now = self.ticks.borrow(cs).get();
                self.expire(cs, now);
            }
        });
    }
}

embassy_time_driver::time_driver_impl!(static DRIVER: SysTickDriver = SysTickDriver {
    ticks: Mutex::new(Cell::new(0)),
    alarm: Mutex::new(Cell::new(u64::MAX)),
    queue: Mutex::new(RefCell::new(Queue::new())),
});

#[exception]
fn SysTick() {
    critical_section::with(|cs| {
        let now = DRIVER.ticks.borrow(cs).get().wrapping_add(1);
        DRIVER.ticks.borrow(cs).set(now);
        if now >= DRIVER.alarm.borrow(cs).get() {
            DRIVER.expire(cs, now);
        }
    });
}

/// Starts the clock: SysTick from the core clock, one interrupt per tick.
pub fn start(syst: &mut SYST) {
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(CYCLES_PER_TICK - 1);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
}

/// Puts the clock back to tick 0 with no timer pending, and a full tick before the next
/// interrupt: every run starts at 0, as every host simulation does. Wakers of the previous
/// run are dropped (their futures are gone).
pub fn restart() {
    critical_section::with(|cs| {
        DRIVER.ticks.borrow(cs).set(0);
        DRIVER.alarm.borrow(cs).set(u64::MAX);
        *DRIVER.queue.borrow_ref_mut(cs) = Queue::new();
        // SAFETY: only this module uses SysTick; writing CVR reloads the counter.
        unsafe { (*SYST::PTR).cvr.write(0) };
        SCB::clear_pendst();
    });
}

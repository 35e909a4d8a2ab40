//! The embassy-time driver: a free-running timer is the clock, a second one the alarm.
//!
//! * Clock: the CMSDK APB TIMER0 of the board ([`crate::board`]) counts down at the core clock,
//!   reloading 2³² − 1 when it reaches 0, and nothing writes it after [`start`]: no cycle is
//!   ever lost. Each read adds the cycles since the value read last (under a critical
//!   section) to a count of whole ticks and the cycles into the current one
//!   ([`crate::clock`]: no 64-bit division); the alarm fires at least every 0.84 s and reads
//!   it, far more often than it wraps (171.8 s at 25 MHz, 214.7 s at 20 MHz). `now()` is the
//!   whole ticks: `CYCLES_PER_TICK` is 25,000 on mps2-an386, 20,000 on mps2-an505, so 1 kHz
//!   ticks, the host's rate, and `Duration` rounding agrees.
//!   Monotonic by construction.
//! * Alarm: TIMER1 is loaded with the exact number of cycles left to the earliest deadline
//!   (at most 2²⁴: 0.67 s at 25 MHz, 0.84 s at 20 MHz) and interrupts when it reaches 0; the handler wakes what is due and
//!   loads the next. An alarm that comes before a far deadline only loads the next one.
//!   (SysTick would do on silicon, but QEMU 7.2 restarts it a whole period late after a write
//!   of its current value, so its alarms came twice as late as asked.)
//! * Reference: the dual timer, 32 bits counting every 256 cycles from [`start`], is never
//!   read by the driver: [`reference_cycles`] lets `cargo xtask qemu` check every run's ticks
//!   against a count the driver's arithmetic does not touch.
//!
//! TIMER0 starts 2²⁴ cycles before a wrap, so every run longer than 0.84 s crosses one and the
//! check covers the extension.

use core::cell::{Cell, RefCell};
use core::sync::atomic::{AtomicU32, Ordering};
use core::task::Waker;

use crate::board;
use crate::executor::Irq;

use cortex_m::peripheral::NVIC;
use critical_section::{CriticalSection, Mutex};
use embassy_time_driver::Driver;
use embassy_time_queue_utils::Queue;

/// The board's core clock in QEMU; the timers count it.
pub const CORE_HZ: u32 = board::CORE_HZ;
/// Core cycles per tick.
pub const CYCLES_PER_TICK: u64 = CORE_HZ as u64 / embassy_time_driver::TICK_HZ;
/// The longest alarm, cycles.
const MAX_ALARM: u64 = 1 << 24;
/// TIMER0's value at [`start`]: it wraps 2²⁴ cycles later.
const FIRST_VALUE: u32 = 1 << 24;
/// The dual timer's prescaler: it counts every 256 cycles.
pub const REFERENCE_PRESCALE: u64 = 256;

/// CMSDK APB timers: CTRL, VALUE, RELOAD, INTSTATUS/INTCLEAR. TIMER0 is the clock, TIMER1
/// the alarm.
const TIMER0: usize = board::TIMER0;
const TIMER1: usize = board::TIMER1;
/// CMSDK dual timer, timer 1: LOAD, VALUE, CONTROL.
const DUALTIMER: usize = board::DUALTIMER;

fn write(address: usize, value: u32) {
    // SAFETY: a register of a timer only this module touches, always mapped on the board (on
    // mps2-an505 at its Secure alias, which the core, running Secure, may use).
    unsafe { (address as *mut u32).write_volatile(value) }
}

fn read(address: usize) -> u32 {
    // SAFETY: as `write`.
    unsafe { (address as *const u32).read_volatile() }
}

/// TIMER0's count: falls by one every cycle, wrapping. A single load: usable anywhere, also
/// inside the critical-section implementation, to time spans shorter than 171 s.
#[inline(always)]
pub fn counter() -> u32 {
    read(TIMER0 + 4)
}

/// The clock's arithmetic, at this board's rate.
type Clock = crate::clock::Clock<{ CYCLES_PER_TICK as u32 }>;

struct TimerDriver {
    clock: Mutex<Cell<Clock>>,
    /// The tick the alarm is set for; 0 when none.
    alarm: Mutex<Cell<u64>>,
    queue: Mutex<RefCell<Queue>>,
}

impl TimerDriver {
    /// Reads the clock.
    fn clock_in(&self, cs: CriticalSection<'_>) -> Clock {
        let cell = self.clock.borrow(cs);
        let clock = cell.get().advance(counter());
        cell.set(clock);
        clock
    }

    /// Sets the alarm to interrupt at tick `at` (or within 0.67 s, whichever is first); pends
    /// it at once when `at` has come.
    fn arm(&self, cs: CriticalSection<'_>, at: u64) {
        self.alarm.borrow(cs).set(at);
        let now = self.clock_in(cs).cycles();
        let target = at.saturating_mul(CYCLES_PER_TICK);
        if target <= now {
            NVIC::pend(Irq::Alarm);
            return;
        }
        // At least 1: a value of 0 would wait for a whole reload period.
        let cycles = (target - now).clamp(1, MAX_ALARM) as u32;
        // An earlier alarm's interrupt, not yet taken, is stale: the handler recomputes anyway.
        write(TIMER1 + 0xC, 1);
        NVIC::unpend(Irq::Alarm);
        // The timer interrupts when it counts down from `cycles` to 0: `cycles` from now.
        write(TIMER1 + 4, cycles);
    }
}

impl Driver for TimerDriver {
    fn now(&self) -> u64 {
        ticks()
    }

    fn schedule_wake(&self, at: u64, waker: &Waker) {
        critical_section::with(|cs| {
            if self.queue.borrow_ref_mut(cs).schedule_wake(at, waker) {
                let alarm = self.alarm.borrow(cs).get();
                if alarm == 0 || at < alarm {
                    self.arm(cs, at);
                }
            }
        });
    }
}

embassy_time_driver::time_driver_impl!(static DRIVER: TimerDriver = TimerDriver {
    clock: Mutex::new(Cell::new(Clock::start(FIRST_VALUE))),
    alarm: Mutex::new(Cell::new(0)),
    queue: Mutex::new(RefCell::new(Queue::new())),
});

/// TIMER1's interrupt: wakes what is due and sets the next alarm.
///
/// # Safety
///
/// Only the vector table calls it, as TIMER1's interrupt handler ([`Irq::Alarm`]).
pub unsafe extern "C" fn alarm_interrupt() {
    let begin = counter();
    write(TIMER1 + 0xC, 1);
    critical_section::with(|cs| {
        let now = DRIVER.clock_in(cs).ticks();
        let next = DRIVER.queue.borrow_ref_mut(cs).next_expiration(now);
        // Nothing to wake: come back anyway, to keep reading the clock.
        let keep_reading = now + MAX_ALARM / CYCLES_PER_TICK;
        DRIVER.arm(cs, next.min(keep_reading));
    });
    let cycles = begin.wrapping_sub(counter());
    crate::executor::handler_ran(cycles);
    ISR_MAX_CYCLES.fetch_max(cycles, Ordering::Relaxed);
}

/// The longest alarm handler so far, in cycles from its first statement to its last
/// (exception entry and exit, 12 cycles each on a Cortex-M4 or a Cortex-M33, come on top).
static ISR_MAX_CYCLES: AtomicU32 = AtomicU32::new(0);

/// The longest alarm handler since the last call, which starts again.
pub fn take_isr_max_cycles() -> u32 {
    ISR_MAX_CYCLES.swap(0, Ordering::Relaxed)
}

/// Starts the clock at tick 0, the reference beside it, and the alarm. Call once, before the
/// executors start.
pub fn start() {
    // The reference first, then the clock: they start a few cycles apart, which the check's
    // tolerance of a tick covers many times over.
    write(DUALTIMER, u32::MAX);
    // Enabled, free-running, prescaler 256, 32 bits, no interrupt.
    write(DUALTIMER + 8, 0x80 | 0b10 << 2 | 0x2);
    // QEMU's CMSDK timer takes a RELOAD write as a VALUE write too: RELOAD first.
    write(TIMER0 + 8, u32::MAX);
    write(TIMER0 + 4, FIRST_VALUE);
    critical_section::with(|cs| DRIVER.clock.borrow(cs).set(Clock::start(FIRST_VALUE)));
    write(TIMER0, 1);
    // The alarm: enabled with its interrupt, reloading 2³² − 1 after it fires (the handler
    // loads the next value long before that comes).
    write(TIMER1 + 8, u32::MAX);
    write(TIMER1, 1 | 1 << 3);
    critical_section::with(|cs| DRIVER.arm(cs, MAX_ALARM / CYCLES_PER_TICK));
    // SAFETY: set once, before the interrupt is unmasked; the alarm is the most urgent.
    unsafe {
        let mut nvic = cortex_m::Peripherals::steal().NVIC;
        nvic.set_priority(Irq::Alarm, 0);
        NVIC::unmask(Irq::Alarm);
    }
}

/// Core cycles since [`start`]: the clock's count, for measuring how long code runs.
pub fn cycles() -> u64 {
    critical_section::with(|cs| DRIVER.clock_in(cs).cycles())
}

/// Whole ticks since [`start`]: `embassy_time`'s `now()`.
pub fn ticks() -> u64 {
    critical_section::with(|cs| DRIVER.clock_in(cs).ticks())
}

/// Core cycles since [`start`] by the reference timer, to within its prescaler (256 cycles).
pub fn reference_cycles() -> u64 {
    u64::from(u32::MAX - read(DUALTIMER + 4)) * REFERENCE_PRESCALE
}

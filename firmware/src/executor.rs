//! Two priorities: the runtime's sensing side on an embassy `InterruptExecutor`, the deciding
//! side on a raw executor polled in thread mode.
//!
//! * Sensing: interrupt 14 (wired to nothing on either board) at priority
//!   [`SENSING_PRIORITY`], below the clock's alarm only. A sample preempts whatever the
//!   deciding side is computing.
//! * Deciding: the executor's pender pends interrupt 15 (lowest priority), whose handler only
//!   sets a flag; thread mode polls when the flag is set and sleeps with WFI otherwise (QEMU
//!   treats WFE as a no-op, so embassy's thread executor would spin). embassy's
//!   `platform-cortex-m` `__pender` serves both.
//!
//! Polls are timed in cycles of the clock, without the time of the handlers that preempted
//! them: a deciding poll's cost is its own processor time. Critical sections entered below the
//! sensing priority are timed too: they are the one way the deciding side can delay a sample.
//! Neither counts the firmware's trace log ([`uncounted`]): a product would not carry it.

use core::cell::Cell;
use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

use cortex_m::interrupt::InterruptNumber;
use critical_section::Mutex;
use embassy_executor::{InterruptExecutor, SendSpawner, Spawner, raw};

use crate::time_driver::counter;

/// The interrupts the firmware uses.
#[derive(Clone, Copy)]
#[repr(u16)]
pub enum Irq {
    /// The clock's alarm: TIMER1 reaching 0 (9 on mps2-an386, 4 on mps2-an505).
    Alarm = crate::board::TIMER1_IRQ,
    /// Runs the sensing executor.
    Sensing = 14,
    /// Wakes thread mode for the deciding executor.
    Deciding = 15,
}

// SAFETY: `Alarm` is TIMER1's interrupt on the board; 14 and 15 are interrupts that nothing
// else raises on either board (`crate::board`).
unsafe impl InterruptNumber for Irq {
    fn number(self) -> u16 {
        self as u16
    }
}

/// NVIC priorities (upper bits of a byte; lower is more urgent). The alarm has 0.
const SENSING_PRIORITY: u8 = 0x40;
const DECIDING_PRIORITY: u8 = 0xE0;

static SENSING: InterruptExecutor = InterruptExecutor::new();
/// Set by interrupt 15: the deciding executor has work.
static WOKEN: AtomicBool = AtomicBool::new(false);
/// Set while the sensing executor polls: the trace events it emits are sensing steps.
static IN_SENSING: AtomicBool = AtomicBool::new(false);

/// What a poll did, from the trace events it emitted ([`note`]): a sample, a switch or a fault
/// of sensor `i` sets bit `i`; planning, plan and state changes set [`CONTROL`]; a deciding
/// poll that emits neither is a behaviour step.
pub const CONTROL: u32 = 1 << 8;

/// Sensors whose sample steps are told apart.
pub const SENSORS: usize = 4;

/// How long polls took, in core cycles of their own (preempting handlers excluded).
#[derive(Clone, Copy, Debug)]
pub struct Polls {
    /// Polls run, of both executors.
    pub count: u32,
    /// The longest poll of either.
    pub max_cycles: u32,
    /// The tick at which the longest one began.
    pub max_at: u64,
    /// All of them together.
    pub total_cycles: u64,
    /// The longest sensing poll that worked for sensor `i` (and maybe others).
    pub max_sample: [u32; SENSORS],
    /// The longest deciding poll that planned, selected a plan or moved the FSM.
    pub max_control: u32,
    /// The longest deciding poll that did none of that: a behaviour step.
    pub max_behaviour: u32,
    /// The longest deciding poll of any kind: what a reaction may wait for.
    pub max_deciding: u32,
    /// The longest critical section entered below the sensing priority: what a sample may
    /// wait for.
    pub max_critical: u32,
}

impl Polls {
    /// No poll yet.
    pub const NONE: Self = Self {
        count: 0,
        max_cycles: 0,
        max_at: 0,
        total_cycles: 0,
        max_sample: [0; SENSORS],
        max_control: 0,
        max_behaviour: 0,
        max_deciding: 0,
        max_critical: 0,
    };
}

static POLLS: Mutex<Cell<Polls>> = Mutex::new(Cell::new(Polls::NONE));

/// Steps of the running sensing poll, and of the running deciding poll.
static SENSING_STEPS: AtomicU32 = AtomicU32::new(0);
static DECIDING_STEPS: AtomicU32 = AtomicU32::new(0);

/// Cycles spent in preempting handlers so far (wrapping): a poll subtracts what grew while it
/// ran.
static PREEMPTED: AtomicU32 = AtomicU32::new(0);

/// The longest critical section entered below the sensing priority, cycles.
static MAX_CRITICAL: AtomicU32 = AtomicU32::new(0);

/// Records that the running poll did `steps`.
pub fn note(steps: u32) {
    if IN_SENSING.load(Ordering::Relaxed) {
        SENSING_STEPS.fetch_or(steps, Ordering::Relaxed);
    } else {
        DECIDING_STEPS.fetch_or(steps, Ordering::Relaxed);
    }
}

/// A handler that preempted whatever ran took `cycles` of its own.
pub fn handler_ran(cycles: u32) {
    PREEMPTED.fetch_add(cycles, Ordering::Relaxed);
}

/// The firmware's own instrumentation (the trace log) took `cycles`: counted like a
/// preempting handler's, and the critical section it ran in starts that much later, so that
/// no poll or section includes them. Call it inside a critical section, so that no handler
/// ran in those cycles.
pub fn uncounted(cycles: u32) {
    PREEMPTED.fetch_add(cycles, Ordering::Relaxed);
    // The clock counts down: a later start is a smaller count.
    SECTION_BEGIN.fetch_sub(cycles, Ordering::Relaxed);
}

/// The poll statistics since the last call, which starts them again.
pub fn take_polls() -> Polls {
    let critical = MAX_CRITICAL.swap(0, Ordering::Relaxed);
    let mut p = critical_section::with(|cs| POLLS.borrow(cs).replace(Polls::NONE));
    p.max_critical = critical;
    p
}

fn record(sensing: bool, cycles: u32, tick: u64) {
    let steps = if sensing {
        SENSING_STEPS.swap(0, Ordering::Relaxed)
    } else {
        DECIDING_STEPS.swap(0, Ordering::Relaxed)
    };
    critical_section::with(|cs| {
        let cell = POLLS.borrow(cs);
        let mut p = cell.get();
        p.count = p.count.saturating_add(1);
        p.total_cycles = p.total_cycles.saturating_add(u64::from(cycles));
        if cycles > p.max_cycles {
            p.max_cycles = cycles;
            p.max_at = tick;
        }
        if sensing {
            for (i, max) in p.max_sample.iter_mut().enumerate() {
                if steps & (1 << i) != 0 {
                    *max = (*max).max(cycles);
                }
            }
        } else {
            p.max_deciding = p.max_deciding.max(cycles);
            if steps & CONTROL != 0 {
                p.max_control = p.max_control.max(cycles);
            } else {
                p.max_behaviour = p.max_behaviour.max(cycles);
            }
        }
        cell.set(p);
    });
}

/// The clock and the handlers' total read together: no handler ran between the two reads, so
/// a handler's cycles are either in both or in neither.
fn snapshot() -> (u32, u32) {
    loop {
        let preempted = PREEMPTED.load(Ordering::Relaxed);
        let now = counter();
        if PREEMPTED.load(Ordering::Relaxed) == preempted {
            return (now, preempted);
        }
    }
}

/// The cycles of its own spent since `begin` (a [`snapshot`]): the span less the handlers
/// that ran in it.
fn own_since((begin, preempted): (u32, u32)) -> u32 {
    let (now, total) = snapshot();
    // The counter counts down.
    let span = begin.wrapping_sub(now);
    span.saturating_sub(total.wrapping_sub(preempted))
}

/// Runs `poll`, returning the cycles it took of its own: its span less the handlers that
/// preempted it (whose own entry and exit, a dozen cycles each, stay in the span).
fn timed(poll: impl FnOnce()) -> u32 {
    let begin = snapshot();
    poll();
    own_since(begin)
}

/// Spends `cycles` of processor time of its own (what preempts it does not count): a
/// behaviour's computation.
pub fn compute(cycles: u32) {
    let begin = snapshot();
    while own_since(begin) < cycles {}
}

/// Interrupt 14: polls the sensing executor.
///
/// # Safety
///
/// Only the vector table calls it, as interrupt 14's handler.
pub unsafe extern "C" fn sensing_interrupt() {
    let tick = embassy_time::Instant::now().as_ticks();
    let begin = snapshot();
    IN_SENSING.store(true, Ordering::Relaxed);
    // SAFETY: the handler of the interrupt `SENSING` was started on, called from nowhere else.
    let own = timed(|| unsafe { SENSING.on_interrupt() });
    IN_SENSING.store(false, Ordering::Relaxed);
    // What the code below sees: this whole span, nested handlers included. Those added their
    // own share already: add this handler's.
    PREEMPTED.fetch_add(own_since(begin), Ordering::Relaxed);
    record(true, own, tick);
}

/// Interrupt 15: the deciding executor has work; thread mode polls it.
///
/// # Safety
///
/// Only the vector table calls it, as interrupt 15's handler.
pub unsafe extern "C" fn deciding_interrupt() {
    WOKEN.store(true, Ordering::Release);
}

/// Where the deciding executor lives.
pub type Slot = MaybeUninit<raw::Executor>;

/// Starts the sensing executor, creates the deciding one in `slot`, lets `init` spawn on them
/// (deciding, sensing), then polls the deciding side whenever it has work and sleeps
/// otherwise. Never returns: the firmware ends with a semihosting exit or a reset.
pub fn run(slot: &'static mut Slot, init: impl FnOnce(Spawner, SendSpawner)) -> ! {
    run_idle(slot, init, || false)
}

/// [`run`], with `idle` called while the deciding side has no work, before sleeping: one
/// short piece of background work a call (the flight recorder's encoding), `true` while more
/// remains. The deciding side's wakes are seen between calls; the sensing side preempts them.
pub fn run_idle(
    slot: &'static mut Slot,
    init: impl FnOnce(Spawner, SendSpawner),
    mut idle: impl FnMut() -> bool,
) -> ! {
    // SAFETY: priorities are set once, before either interrupt is unmasked; nothing else
    // writes them.
    unsafe {
        let mut core = cortex_m::Peripherals::steal();
        core.NVIC.set_priority(Irq::Sensing, SENSING_PRIORITY);
        core.NVIC.set_priority(Irq::Deciding, DECIDING_PRIORITY);
    }
    let sensing = SENSING.start(Irq::Sensing);
    let deciding: &'static raw::Executor =
        slot.write(raw::Executor::new(Irq::Deciding as usize as *mut ()));
    // SAFETY: its handler only sets a flag.
    unsafe { cortex_m::peripheral::NVIC::unmask(Irq::Deciding) };
    init(deciding.spawner(), sensing);
    WOKEN.store(true, Ordering::Release);
    loop {
        if WOKEN.swap(false, Ordering::AcqRel) {
            let tick = embassy_time::Instant::now().as_ticks();
            // SAFETY: only this loop polls the deciding executor; its pender never does.
            let own = timed(|| unsafe { deciding.poll() });
            record(false, own, tick);
            continue;
        }
        if idle() {
            continue;
        }
        // Interrupts off between the check and WFI, so a wake cannot slip in unseen; a pending
        // interrupt still ends WFI, and is taken when they are back on.
        cortex_m::interrupt::disable();
        if !WOKEN.load(Ordering::Acquire) {
            cortex_m::asm::wfi();
        }
        // SAFETY: not inside a critical section.
        unsafe { cortex_m::interrupt::enable() };
    }
}

/// The critical-section implementation: cortex-m's single-core one (mask interrupts), which
/// also times each outermost section entered below the sensing priority.
struct Timed;
critical_section::set_impl!(Timed);

/// When the current outermost critical section began (TIMER0's count), less [`uncounted`]
/// time in it.
static SECTION_BEGIN: AtomicU32 = AtomicU32::new(0);

/// Whether the code running is below the sensing priority: thread mode or interrupt 15.
fn below_sensing() -> bool {
    // ICSR.VECTACTIVE: 0 in thread mode, 16 + n in interrupt n.
    // SAFETY: a read of a system register that is always there.
    let active = unsafe { (*cortex_m::peripheral::SCB::PTR).icsr.read() } & 0x1FF;
    active == 0 || active == 16 + Irq::Deciding as u32
}

// SAFETY: masks interrupts for the section and restores the previous state: single core.
unsafe impl critical_section::Impl for Timed {
    unsafe fn acquire() -> bool {
        let was_enabled = cortex_m::register::primask::read().is_active();
        cortex_m::interrupt::disable();
        if was_enabled {
            SECTION_BEGIN.store(counter(), Ordering::Relaxed);
        }
        was_enabled
    }

    unsafe fn release(was_enabled: bool) {
        if was_enabled {
            if below_sensing() {
                let cycles = SECTION_BEGIN
                    .load(Ordering::Relaxed)
                    .wrapping_sub(counter());
                MAX_CRITICAL.fetch_max(cycles, Ordering::Relaxed);
            }
            // SAFETY: interrupts were enabled when the section began.
            unsafe { cortex_m::interrupt::enable() };
        }
    }
}

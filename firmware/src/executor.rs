//! Two thread-mode embassy executors, one per side of the runtime, that sleep with WFI between
//! polls (QEMU treats WFE as a no-op, so an executor waiting with WFE would spin). No
//! `platform-*` feature of embassy-executor: this module provides `__pender`.
//!
//! The sensing executor has the higher priority: whenever it has work it is polled before the
//! next poll of the deciding executor, the rule the host simulator follows, so both give the
//! same trace. Polls are not preempted (one thread); a sample can wait for the deciding poll in
//! progress, which `cargo xtask timing` measures and the response-time analysis charges.

use core::cell::{Cell, RefCell};
use core::future::poll_fn;
use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use core::task::{Poll, Waker};

use critical_section::Mutex;
use embassy_executor::{Spawner, raw};
use psmpa_sim::run::{Erased, HighSlot};

static PENDING: AtomicBool = AtomicBool::new(false);
static PENDING_SENSING: AtomicBool = AtomicBool::new(false);

/// The pender context of the sensing executor (the deciding one's is null).
const SENSING: *mut () = core::ptr::without_provenance_mut(1);

/// What a poll did, from the trace events it emitted ([`note`]): a sample, a switch or a fault
/// of sensor `i` sets bit `i`; planning, plan and state changes set [`CONTROL`]; a deciding
/// poll that emits neither is a behaviour step.
pub const CONTROL: u32 = 1 << 8;

/// Sensors whose sample steps are told apart.
pub const SENSORS: usize = 4;

/// How long polls took, in core cycles.
#[derive(Clone, Copy, Debug, Default)]
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
    /// The longest deciding poll of any kind: what a released sample may wait for.
    pub max_deciding: u32,
}

static POLLS: Mutex<Cell<Polls>> = Mutex::new(Cell::new(Polls {
    count: 0,
    max_cycles: 0,
    max_at: 0,
    total_cycles: 0,
    max_sample: [0; SENSORS],
    max_control: 0,
    max_behaviour: 0,
    max_deciding: 0,
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

fn record(sensing: bool, begin: u64, end: u64, tick: u64) {
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

#[unsafe(export_name = "__pender")]
fn pender(context: *mut ()) {
    if context == SENSING {
        PENDING_SENSING.store(true, Ordering::Release);
    } else {
        PENDING.store(true, Ordering::Release);
    }
}

/// Where the two executors live.
pub struct Slots {
    deciding: MaybeUninit<raw::Executor>,
    sensing: MaybeUninit<raw::Executor>,
}

impl Slots {
    /// Room for both executors.
    pub const fn new() -> Self {
        Self {
            deciding: MaybeUninit::uninit(),
            sensing: MaybeUninit::uninit(),
        }
    }
}

/// Polls `executor` once, timed.
fn poll(executor: &'static raw::Executor, sensing: bool) {
    let (begin, tick) = (
        crate::time_driver::cycles(),
        embassy_time::Instant::now().as_ticks(),
    );
    // SAFETY: only the loop of `run` polls the executors; the pender never calls `poll`.
    unsafe { executor.poll() };
    record(sensing, begin, crate::time_driver::cycles(), tick);
}

/// Creates both executors in `slots`, lets `init` spawn on them (deciding, sensing), then polls
/// whatever is pending, sensing first, and sleeps otherwise. Never returns: the firmware ends
/// with a semihosting exit.
pub fn run(slots: &'static mut Slots, init: impl FnOnce(Spawner, Spawner)) -> ! {
    let deciding: &'static raw::Executor = slots
        .deciding
        .write(raw::Executor::new(core::ptr::null_mut()));
    let sensing: &'static raw::Executor = slots.sensing.write(raw::Executor::new(SENSING));
    init(deciding.spawner(), sensing.spawner());
    PENDING.store(true, Ordering::Release);
    PENDING_SENSING.store(true, Ordering::Release);
    loop {
        if PENDING_SENSING.swap(false, Ordering::AcqRel) {
            poll(sensing, true);
            continue;
        }
        if PENDING.swap(false, Ordering::AcqRel) {
            poll(deciding, false);
            continue;
        }
        // Both idle: time moves on to the next deadline, if it has come.
        if crate::time_driver::advance() {
            continue;
        }
        // Interrupts off between the check and WFI, so a wake cannot slip in unseen; a pending
        // interrupt still ends WFI.
        cortex_m::interrupt::disable();
        let idle = !PENDING.load(Ordering::Acquire) && !PENDING_SENSING.load(Ordering::Acquire);
        if idle && !crate::time_driver::advance() {
            cortex_m::asm::wfi();
        }
        // SAFETY: not inside a critical section.
        unsafe { cortex_m::interrupt::enable() };
    }
}

/// The installed sensing side, with its type and lifetime erased ([`HighSlot`]).
struct Installed(Erased);

// SAFETY: the pointer is only used in thread mode, by the sensing trampoline.
unsafe impl Send for Installed {}

static INSTALLED: Mutex<Cell<Option<Installed>>> = Mutex::new(Cell::new(None));
static TRAMPOLINE: Mutex<RefCell<Option<Waker>>> = Mutex::new(RefCell::new(None));

/// The sensing executor's slot: a run's sensing side is installed here while it runs.
pub struct SensingSlot;

// SAFETY: `trampoline` takes the pointer out for the duration of its poll; it runs in thread
// mode from `run`'s loop, never re-entered, and a `Beside` uninstalls from a deciding poll of
// the same loop, so never in the middle of that poll.
unsafe impl HighSlot for SensingSlot {
    fn install(&self, future: Erased) -> bool {
        critical_section::with(|cs| {
            let slot = INSTALLED.borrow(cs);
            let current = slot.take();
            if current.is_some() {
                slot.set(current);
                return false;
            }
            slot.set(Some(Installed(future)));
            if let Some(w) = TRAMPOLINE.borrow_ref(cs).as_ref() {
                w.wake_by_ref();
            }
            true
        })
    }

    fn uninstall(&self) {
        critical_section::with(|cs| INSTALLED.borrow(cs).set(None));
    }
}

/// The one task of the sensing executor: polls the installed sensing side, forever.
#[embassy_executor::task]
pub async fn trampoline() {
    poll_fn(|cx| {
        let installed = critical_section::with(|cs| {
            TRAMPOLINE.borrow_ref_mut(cs).replace(cx.waker().clone());
            INSTALLED.borrow(cs).take()
        });
        if let Some(Installed(future)) = installed {
            // SAFETY: installed by a live `Beside`, which uninstalls before the future ends;
            // taken out while polled, so nothing else uses it.
            if unsafe { future.poll(cx) }.is_pending() {
                critical_section::with(|cs| INSTALLED.borrow(cs).set(Some(Installed(future))));
            }
        }
        Poll::<()>::Pending
    })
    .await;
}

//! The flight recorder: every event of the runtime's trace, recorded (`psmpa_core::record`)
//! so that `psmpa-sim replay` runs the robot's decisions again on a desk.
//!
//! * On the runtime's path ([`take`], from the trace sink, inside its lock) an event is only
//!   copied into a queue: its instant and words, a few dozen cycles, so a sample's instant
//!   does not move. When the queue is full the oldest is encoded there and then: nothing is
//!   dropped.
//! * The [`drain`] task, in thread mode beside the control loop, encodes each frame (CRC-32)
//!   and sends it over RTT as a defmt message `rec [bytes]`, and keeps it in [`RING`]: the
//!   last 4 KiB of the recording (about 140 frames, seconds of sensing) in `.uninit`, which
//!   a reset leaves as it was.
//! * After a watchdog reset, [`after_reset`] sends what the ring kept, as a recording of its
//!   own, so that what the robot sensed and decided before a hang or a fault can be read. A
//!   debug probe reads it too: `PSMPA_RECORDING` (a magic word, the write position, the
//!   bytes held, then the bytes).
//!
//! A recording starts with the core's header (`fetch_tea::HASH` names the mission) and a
//! prologue: the calibration record (the sensors' periods come from it), kind byte 2 ("a
//! board"), a CRC-32. `psmpa-sim replay` reads both.

use core::cell::RefCell;
use core::mem::MaybeUninit;

use defmt::info;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::signal::Signal;
use embassy_time::Instant;
use heapless::Deque;
use portable_atomic::Ordering;
use psmpa_core::TraceEvent;
use psmpa_core::record::{self, Frame, Header, MAX_FRAME, RecordOut, Recorder, Ring};
use psmpa_fetch_tea::{Settings, fetch_tea};

/// Bytes of the ring: about 140 one-word frames.
pub const RING_BYTES: usize = 4096;

/// Frames queued for the drain task: a second of the busiest sensing (the bumper every 20 ms,
/// the sonar every 100 ms) while thread mode computes a plan.
const QUEUE: usize = 64;

/// The kind byte of a board's prologue (`psmpa_sim::replay::BOARD`).
const BOARD: u8 = 2;

/// The last [`RING_BYTES`] of the recording, kept across a reset (not initialised at boot).
#[unsafe(link_section = ".uninit.PSMPA_RECORDING")]
#[unsafe(export_name = "PSMPA_RECORDING")]
static mut RING: MaybeUninit<Ring<RING_BYTES>> = MaybeUninit::uninit();

/// The defmt log over RTT: one message a piece of the recording.
struct Rtt;

impl RecordOut for Rtt {
    fn write(&mut self, bytes: &[u8]) {
        info!("rec {=[u8]}", bytes);
    }
}

struct State {
    queue: Deque<Frame<1>, QUEUE>,
    /// The frame the drain task took and is encoding: sent first if the runtime's path must
    /// send one itself, so that frames go out in their order.
    in_flight: Option<Frame<1>>,
    /// `None` until the recording starts (and after a watchdog reset, when it does not).
    ring: Option<&'static mut Ring<RING_BYTES>>,
    /// Frames taken, the most queued at once, and those sent on the runtime's path because
    /// the queue was full: counted under the lock the path holds anyway.
    taken: u32,
    queued_max: u32,
    inline: u32,
}

/// All zeros at first: in `.bss`, no initial values in flash.
static STATE: Mutex<CriticalSectionRawMutex, RefCell<State>> = Mutex::new(RefCell::new(State {
    queue: Deque::new(),
    in_flight: None,
    ring: None,
    taken: 0,
    queued_max: 0,
    inline: 0,
}));

/// Frames are queued.
static QUEUED: Signal<CriticalSectionRawMutex, ()> = Signal::new();

/// Encodes `frame` and sends it (RTT, and the ring).
fn send(frame: &Frame<1>, ring: &mut Ring<RING_BYTES>) {
    Recorder::frames_only((Rtt, ring)).write_frame(frame);
}

/// The ring, taken once at boot; `None` on a second call.
fn ring() -> Option<&'static mut Ring<RING_BYTES>> {
    static TAKEN: portable_atomic::AtomicBool = portable_atomic::AtomicBool::new(false);
    if TAKEN.swap(true, Ordering::AcqRel) {
        return None;
    }
    // SAFETY: the question is the `&mut` made here. It is the only reference to `RING` for
    // the rest of the program: `TAKEN` lets this line run once, and no other code names `RING`
    // (its exported name is for a debugger, which reads the halted chip). The pointer is
    // `RING`'s own, cast from `MaybeUninit<Ring>` to `Ring`, which has the same layout: aligned
    // and in bounds. And the `Ring` it points at is initialised, as a reference requires,
    // although nothing wrote it this boot: its fields are integers, for which every bit
    // pattern a reset or power-on leaves is a value (`Ring` checks its magic and bounds before
    // it trusts one).
    Some(unsafe { &mut *(&raw mut RING).cast::<Ring<RING_BYTES>>() })
}

/// Starts the recording of this run: its header and prologue ([`Settings::to_record`] of
/// `settings`). At boot after a watchdog reset instead: sends what the ring kept from before
/// it, as a recording of its own (header, prologue, frames), and says how much; the board
/// then stays still and records nothing.
pub fn start(settings: &Settings, after_reset: bool) {
    let Some(ring) = ring() else {
        return;
    };
    if after_reset {
        let mut frames = 0u32;
        let (mut first, mut last) = (0, 0);
        begin(&mut Rtt, settings);
        let mut rtt = Recorder::frames_only(Rtt);
        for frame in ring.recovered::<1>() {
            rtt.write_frame(&frame);
            if frames == 0 {
                first = frame.ticks;
            }
            last = frame.ticks;
            frames += 1;
        }
        info!(
            "flight recorder: {=u32} frames from before the reset, {=u64} ms to {=u64} ms",
            frames,
            Instant::from_ticks(first).as_millis(),
            Instant::from_ticks(last).as_millis()
        );
        // The board stays still: nothing more to record, and the ring keeps what it had.
        return;
    }
    ring.clear();
    begin(&mut Rtt, settings);
    begin(ring, settings);
    critical_section::with(|cs| STATE.borrow(cs).borrow_mut().ring = Some(ring));
}

/// A recording's header and prologue into `out`: the calibration record's bytes, kind
/// [`BOARD`].
fn begin(out: &mut impl RecordOut, settings: &Settings) {
    let mut body = [0u8; 4 * psmpa_fetch_tea::RECORD_WORDS];
    for (slot, byte) in body
        .iter_mut()
        .zip(settings.to_record().iter().flat_map(|w| w.to_le_bytes()))
    {
        *slot = byte;
    }
    record::write_start(out, &Header::new(1, fetch_tea::HASH), &body, BOARD);
}

/// The runtime's path: queues the event's frame (the trace sink calls it inside its lock).
pub fn take(at: Instant, event: &TraceEvent) {
    let frame = Frame::of(at, event);
    critical_section::with(|cs| {
        let mut state = STATE.borrow(cs).borrow_mut();
        let State {
            queue,
            in_flight,
            ring: Some(ring),
            taken,
            queued_max,
            inline,
        } = &mut *state
        else {
            return;
        };
        if queue.is_full() {
            for frame in [in_flight.take(), queue.pop_front()].into_iter().flatten() {
                *inline += 1;
                send(&frame, ring);
            }
        }
        let _ = queue.push_back(frame);
        *taken += 1;
        *queued_max = (*queued_max).max(queue.len() as u32);
    });
    QUEUED.signal(());
}

/// Encodes and sends the queued frames, one a poll, whenever some are queued.
#[embassy_executor::task]
pub async fn drain() {
    loop {
        QUEUED.wait().await;
        loop {
            // Whatever the same event woke (the control loop, reacting to a sample) runs
            // first: the recorder only takes the time left over.
            embassy_futures::yield_now().await;
            let frame = critical_section::with(|cs| {
                let mut s = STATE.borrow(cs).borrow_mut();
                s.in_flight = s.queue.pop_front();
                s.in_flight
            });
            let Some(frame) = frame else {
                break;
            };
            // Encoded outside the lock: an interrupt waits only for the copies.
            let mut buf = [0u8; MAX_FRAME];
            let n = frame.encode(&mut buf).unwrap_or(0);
            let bytes = buf.get(..n).unwrap_or(&[]);
            critical_section::with(|cs| {
                let mut s = STATE.borrow(cs).borrow_mut();
                if let State {
                    in_flight: in_flight @ Some(_),
                    ring: Some(ring),
                    ..
                } = &mut *s
                    && *in_flight == Some(frame)
                {
                    // Not sent by the runtime's path meanwhile.
                    *in_flight = None;
                    Rtt.write(bytes);
                    ring.write(bytes);
                }
            });
        }
    }
}

/// Sends whatever is queued at once, and says what the recorder did: before the board stops
/// (the task's end).
pub fn flush() {
    let (taken, queued_max, inline) = critical_section::with(|cs| {
        let s = STATE.borrow(cs).borrow();
        (s.taken, s.queued_max, s.inline)
    });
    info!(
        "flight recorder: {=u32} frames, at most {=u32} queued, {=u32} sent on the runtime's path for a full queue",
        taken, queued_max, inline
    );
    // A frame a critical section, as the drain task sends them.
    while critical_section::with(|cs| {
        let mut state = STATE.borrow(cs).borrow_mut();
        let State {
            queue,
            in_flight,
            ring: Some(ring),
            ..
        } = &mut *state
        else {
            return false;
        };
        match in_flight.take().or_else(|| queue.pop_front()) {
            Some(frame) => {
                send(&frame, ring);
                true
            }
            None => false,
        }
    }) {}
}

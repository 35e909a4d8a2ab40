//! defmt's global logger: the host's standard output through semihosting, one host call per
//! frame.
//!
//! defmt-semihosting, used before, handed every encoded byte to the host on its own: about 15
//! host calls a world event, most of a line's 1,400 cycles, and as much wall time in QEMU
//! as the runs themselves. Here a frame is gathered in a buffer and written at once (a frame
//! longer than the buffer goes in pieces). A frame is encoded inside a critical section, as
//! defmt requires; a fault handler's frame begun inside another ends that one first.

use core::cell::UnsafeCell;

use cortex_m_semihosting::hio::{self, HostStream};
use critical_section::RestoreState;

/// Bytes gathered before a host call: a world event's line takes about 15.
const BUFFER: usize = 64;

struct State {
    /// Frames begun and not ended: 2 only when a fault handler logs inside a frame.
    depth: u8,
    /// What each of them found when it entered its critical section.
    restore: [RestoreState; 2],
    encoder: defmt::Encoder,
    buf: [u8; BUFFER],
    len: usize,
    /// The host's standard output, opened with the first frame.
    out: Option<HostStream>,
}

struct Shared(UnsafeCell<State>);

// SAFETY: the state is used only inside the critical section a frame holds.
unsafe impl Sync for Shared {}

static STATE: Shared = Shared(UnsafeCell::new(State {
    depth: 0,
    restore: [RestoreState::invalid(); 2],
    encoder: defmt::Encoder::new(),
    buf: [0; BUFFER],
    len: 0,
    out: None,
}));

/// Writes what is gathered to the host (a failed write is lost: there is nowhere to say so).
fn flush(buf: &[u8; BUFFER], len: &mut usize, out: &mut Option<HostStream>) {
    if let (Some(out), Some(bytes)) = (out.as_mut(), buf.get(..*len)) {
        let _ = out.write_all(bytes);
    }
    *len = 0;
}

/// Gathers encoded bytes, writing to the host when the buffer is full.
fn put(buf: &mut [u8; BUFFER], len: &mut usize, out: &mut Option<HostStream>, bytes: &[u8]) {
    for &b in bytes {
        if *len >= BUFFER {
            flush(buf, len, out);
        }
        if let Some(slot) = buf.get_mut(*len) {
            *slot = b;
            *len += 1;
        }
    }
}

impl State {
    // Closures borrow `buf`, `len` and `out` apart from `encoder` (disjoint captures).
    fn start_frame(&mut self) {
        self.encoder
            .start_frame(|b| put(&mut self.buf, &mut self.len, &mut self.out, b));
    }

    fn write(&mut self, bytes: &[u8]) {
        self.encoder.write(bytes, |b| {
            put(&mut self.buf, &mut self.len, &mut self.out, b)
        });
    }

    fn end_frame(&mut self) {
        self.encoder
            .end_frame(|b| put(&mut self.buf, &mut self.len, &mut self.out, b));
        flush(&self.buf, &mut self.len, &mut self.out);
    }
}

#[defmt::global_logger]
struct Logger;

// SAFETY: defmt's contract: frames are begun, written and ended in order, inside a critical
// section held from `acquire` to `release`.
unsafe impl defmt::Logger for Logger {
    fn acquire() {
        // SAFETY: released in `release`, which defmt calls after every `acquire`.
        let restore = unsafe { critical_section::acquire() };
        // SAFETY: inside the critical section; no other reference to the state is live (a
        // nested frame comes from a fault handler, which does not return into this one).
        let s = unsafe { &mut *STATE.0.get() };
        if s.depth > 0 {
            // A fault handler logs inside a frame: end that one, so this one decodes.
            s.end_frame();
        }
        if let Some(r) = s.restore.get_mut(usize::from(s.depth)) {
            *r = restore;
        }
        s.depth = s.depth.saturating_add(1);
        if s.out.is_none() {
            s.out = hio::hstdout().ok();
        }
        s.start_frame();
    }

    unsafe fn flush() {}

    unsafe fn release() {
        // SAFETY: inside the critical section `acquire` entered.
        let s = unsafe { &mut *STATE.0.get() };
        s.end_frame();
        s.depth = s.depth.saturating_sub(1);
        if let Some(&restore) = s.restore.get(usize::from(s.depth)) {
            // SAFETY: the state `acquire` saved for this frame, restored once.
            unsafe { critical_section::release(restore) };
        }
    }

    unsafe fn write(bytes: &[u8]) {
        // SAFETY: inside the critical section `acquire` entered.
        let s = unsafe { &mut *STATE.0.get() };
        s.write(bytes);
    }
}

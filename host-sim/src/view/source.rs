//! Where the view's events come from, each as the recorder's frames ([`Frame`]): the simulator
//! running a scenario (paced to real time times the speed), a recording played at its
//! instants (paced the same way), and a frame stream on standard input (a board's, as it
//! comes). The first two can be paused, stepped and sped up ([`Pace`]); nothing here drives
//! the robot.

use std::io::Read;
use std::path::Path;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant as Wall};

use embassy_time::Instant;
use psmpa_core::record::{self, Frame, Header, RecordError, kind};
use psmpa_core::{FactSet, Mission, TraceEvent, TraceSink};

use super::model::View;
use crate::replay::{Recording, Source};
use crate::robot::{self, Arch, FetchTea};
use crate::scenario::Scenario;

/// Locks `m`, a poisoned lock taken as it is (a panicking thread left the view readable).
pub fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The pacing of a source that can be paused: virtual time runs at `speed` times real time.
pub struct Pace {
    state: Mutex<PaceState>,
    changed: Condvar,
}

struct PaceState {
    paused: bool,
    speed: f64,
    steps: u32,
    anchor_wall: Wall,
    anchor_ms: u64,
    last_ms: u64,
    lag_ms: u64,
    late_ms: u64,
}

/// A command of the page's controls.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Control {
    /// Stop at the next event.
    Pause,
    /// Go on at the speed set.
    Resume,
    /// While paused: on to the next decision (an event other than a sample, a lost sample or
    /// a sensor switched).
    Step,
    /// Virtual time at this many times real time.
    Speed(f64),
}

/// The slowest and fastest speeds, times real time.
pub const SPEEDS: (f64, f64) = (0.01, 10_000.0);

/// Whether a frame of this kind is a decision (what a step stops after).
fn decision(kind: u8) -> bool {
    !matches!(
        kind,
        kind::SAMPLE | kind::SAMPLE_LOST | kind::SENSOR_ON | kind::SENSOR_OFF
    )
}

impl Pace {
    /// A pace of `speed`, paused or not.
    pub fn new(speed: f64, paused: bool) -> Self {
        Self {
            state: Mutex::new(PaceState {
                paused,
                speed,
                steps: 0,
                anchor_wall: Wall::now(),
                anchor_ms: 0,
                last_ms: 0,
                lag_ms: 0,
                late_ms: 0,
            }),
            changed: Condvar::new(),
        }
    }

    /// Waits until the event of a frame of `kind` at `t_ms` is due: its virtual instant at
    /// the speed set, and not paused (a step lets it through).
    pub fn wait(&self, t_ms: u64, kind: u8) {
        let mut s = lock(&self.state);
        loop {
            if s.paused {
                if s.steps > 0 {
                    if decision(kind) {
                        s.steps -= 1;
                    }
                    break;
                }
                s = self
                    .changed
                    .wait(s)
                    .unwrap_or_else(std::sync::PoisonError::into_inner);
                continue;
            }
            let ahead = t_ms.saturating_sub(s.anchor_ms) as f64 / 1000.0 / s.speed;
            let due = s.anchor_wall + Duration::from_secs_f64(ahead.min(1e9));
            let now = Wall::now();
            if now >= due {
                s.late_ms = (now - due).as_millis() as u64;
                s.lag_ms = s.lag_ms.max(s.late_ms);
                break;
            }
            s = self
                .changed
                .wait_timeout(s, due - now)
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .0;
        }
        s.last_ms = t_ms;
        if s.paused {
            s.anchor_wall = Wall::now();
            s.anchor_ms = t_ms;
        }
    }

    /// Carries out a command of the page.
    pub fn control(&self, c: Control) {
        let mut s = lock(&self.state);
        match c {
            Control::Pause => s.paused = true,
            Control::Resume => s.paused = false,
            Control::Step => s.steps = s.steps.saturating_add(1),
            Control::Speed(x) => s.speed = x.clamp(SPEEDS.0, SPEEDS.1),
        }
        s.anchor_wall = Wall::now();
        s.anchor_ms = s.last_ms;
        self.changed.notify_all();
    }

    /// Paused, the speed, the most an event came later than due and how late the last one
    /// came, ms (the view falling behind; the time paused is not lag).
    pub fn status(&self) -> (bool, f64, u64, u64) {
        let s = lock(&self.state);
        (s.paused, s.speed, s.lag_ms, s.late_ms)
    }
}

/// What the view shares between its source and its server.
pub struct Shared {
    /// The live state.
    pub view: Mutex<View>,
    /// The pacing, for a source that can be paused.
    pub pace: Option<Pace>,
    /// The source in words.
    pub source: String,
}

/// The runtime's trace events of a live run, as frames into the view, each when it is due:
/// `offset_ms` later than traced (the runs before it, with `--repeat`).
struct Sink {
    shared: Arc<Shared>,
    offset_ms: u64,
    last_ms: u64,
}

impl<Ms: Mission<Facts = FactSet>> TraceSink<Ms> for Sink {
    fn record(&mut self, at: Instant, event: &TraceEvent) {
        let frame = Frame::of(at, event);
        let ms = at.as_millis().saturating_add(self.offset_ms);
        self.last_ms = ms;
        if let Some(p) = &self.shared.pace {
            p.wait(ms, frame.kind());
        }
        lock(&self.shared.view).frame(ms, &frame);
    }
}

/// Runs `scenario` under `arch` into the view, paced, `repeat` times back to back (virtual
/// time going on from one run to the next); says how each run ended. Each run is the one
/// `psmpa-sim run` makes: the view only waits between its events, in real time, while virtual
/// time stands still.
pub fn simulate(scenario: &Scenario, arch: Arch, repeat: u64, shared: &Arc<Shared>) {
    let started = Wall::now();
    let mut offset_ms = 0;
    for run in 1..=repeat.max(1) {
        let sink = Sink {
            shared: Arc::clone(shared),
            offset_ms,
            last_ms: offset_ms,
        };
        let ended = crate::sim::run_logged(scenario, arch, (), sink);
        let lag = shared.pace.as_ref().map_or(0, |p| p.status().2);
        let mut view = lock(&shared.view);
        match ended {
            Ok((summary, (), sink)) => {
                let which = if repeat > 1 {
                    format!("run {run} of {repeat}")
                } else {
                    "the run".to_owned()
                };
                let line = format!(
                    "{which} ended at {:.3} s after {:.3} s of real time ({} events, trace_hash {:016x}, the view at most {lag} ms behind)",
                    summary.time_cost_ms as f64 / 1000.0,
                    started.elapsed().as_secs_f64(),
                    summary.trace_events,
                    summary.trace_hash,
                );
                eprintln!("psmpa-sim: view: {line}");
                view.end(line);
                // The next run starts a virtual second after this one's end.
                let end = offset_ms.saturating_add(summary.time_cost_ms);
                offset_ms = end.max(sink.last_ms).saturating_add(1000);
            }
            Err(e) => {
                view.error(format!("the run failed: {e}"));
                view.end("the run failed".to_owned());
                return;
            }
        }
    }
}

/// Plays a recording's frames into the view at their instants, paced.
pub fn play(recording: &Recording, shared: &Arc<Shared>) {
    for frame in &recording.frames {
        let ms = Instant::from_ticks(frame.ticks).as_millis();
        if let Some(p) = &shared.pace {
            p.wait(ms, frame.kind());
        }
        lock(&shared.view).frame(ms, frame);
    }
    let line = format!("the recording ended: {} frames", recording.frames.len());
    eprintln!("psmpa-sim: view: {line}");
    lock(&shared.view).end(line);
}

/// The mission whose names a recording's events use.
pub fn mission_of(recording: &Recording) -> Result<FetchTea<'static>, String> {
    match &recording.source {
        Source::Simulator { scenario, .. } => robot::fetch_tea(scenario).map(|r| r.mission),
        Source::Board { .. } => fetch_tea_names(),
    }
    .map_err(|e| format!("the mission could not be built: {e:?}"))
}

/// The Fetch Tea mission as its file has it (the names a board's frames use).
pub fn fetch_tea_names() -> Result<FetchTea<'static>, robot::MissionError> {
    robot::Robot::load(robot::FETCH_TEA).map(|r| r.mission)
}

/// A frame stream read as it comes: recordings (header, prologue, frames) back to back,
/// binary or as the `rec [..]` lines of a decoded defmt log. A bad frame, a bad line or a cut
/// stream is an error line on the view; the reading goes on.
pub struct FrameStream {
    buf: Vec<u8>,
    /// Bytes dropped or taken before `buf[0]`.
    offset: usize,
    tick_hz: Option<u32>,
    skipping: bool,
    text: Option<bool>,
    line: Vec<u8>,
    /// Frames taken in.
    pub frames: u64,
}

/// The longest line of a decoded log kept while it comes, bytes; past it the line is dropped.
const MAX_LINE: usize = 1 << 16;

impl Default for FrameStream {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameStream {
    /// A stream before its first byte.
    pub fn new() -> Self {
        Self {
            buf: Vec::new(),
            offset: 0,
            tick_hz: None,
            skipping: false,
            text: None,
            line: Vec::new(),
            frames: 0,
        }
    }

    /// Takes in the next bytes of standard input.
    pub fn feed(&mut self, bytes: &[u8], shared: &Shared) {
        let text = *self.text.get_or_insert_with(|| {
            // A recording starts with its magic; anything else is read as a log.
            !record::MAGIC.starts_with(&bytes[..bytes.len().min(record::MAGIC.len())])
        });
        if !text {
            self.bytes(bytes, shared);
            return;
        }
        for &b in bytes {
            if b != b'\n' {
                if self.line.len() < MAX_LINE {
                    self.line.push(b);
                }
                continue;
            }
            let line = String::from_utf8_lossy(&self.line).into_owned();
            self.line.clear();
            match crate::replay::rec_bytes(line.trim_end()) {
                Some(Ok(rec)) => self.bytes(&rec, shared),
                Some(Err(e)) => lock(&shared.view).error(format!("a bad line: {e}")),
                None => {}
            }
        }
    }

    fn drop_front(&mut self, n: usize) {
        let n = n.min(self.buf.len());
        self.buf.drain(..n);
        self.offset += n;
    }

    fn bytes(&mut self, bytes: &[u8], shared: &Shared) {
        self.buf.extend_from_slice(bytes);
        loop {
            if self.buf.starts_with(&record::MAGIC) || self.tick_hz.is_none() {
                match self.start(shared) {
                    Some(true) => continue,
                    Some(false) => return,
                    None => {
                        // Not a recording's start: skip to the next magic.
                        let next = self
                            .buf
                            .windows(record::MAGIC.len())
                            .skip(1)
                            .position(|w| w == record::MAGIC)
                            .map_or(self.buf.len().saturating_sub(record::MAGIC.len()), |p| {
                                p + 1
                            });
                        self.drop_front(next.max(1));
                        if self.buf.is_empty() {
                            return;
                        }
                        continue;
                    }
                }
            }
            let Some(tick_hz) = self.tick_hz else { return };
            match Frame::<1>::decode(&self.buf, self.offset) {
                Ok((frame, used)) => {
                    self.skipping = false;
                    self.frames += 1;
                    let ms = (u128::from(frame.ticks) * 1000 / u128::from(tick_hz)) as u64;
                    lock(&shared.view).frame(ms, &frame);
                    self.drop_front(used);
                }
                Err(RecordError::Cut { .. }) => return,
                Err(e) => {
                    if !self.skipping {
                        lock(&shared.view).error(format!("{e}: skipped to the next whole frame"));
                    }
                    self.skipping = true;
                    self.drop_front(1);
                }
            }
        }
    }

    /// Reads a recording's header and prologue at the front: `Some(true)` when read (the view
    /// starts anew with its mission), `Some(false)` when more bytes are needed, `None` when
    /// the front is not one (an error line said why).
    fn start(&mut self, shared: &Shared) -> Option<bool> {
        let at = record::HEADER_LEN;
        if self.buf.len() < at + 4 {
            return record::MAGIC
                .starts_with(&self.buf[..self.buf.len().min(8)])
                .then_some(false)
                .or_else(|| {
                    if !self.skipping {
                        lock(&shared.view).error(format!(
                            "byte {}: not a recording's header: skipped to the next one",
                            self.offset
                        ));
                    }
                    self.skipping = true;
                    None
                });
        }
        let len = u32::from_le_bytes([
            self.buf[at],
            self.buf[at + 1],
            self.buf[at + 2],
            self.buf[at + 3],
        ]) as usize;
        let fail = |me: &mut Self, why: String| {
            lock(&shared.view).error(format!("byte {}: {why}", me.offset));
            me.skipping = true;
            None
        };
        if len as u64 > crate::cli::files::MAX_INPUT {
            return fail(
                self,
                format!("a prologue of {len} bytes: not a recording's"),
            );
        }
        let end = at + 4 + len + 1 + 4;
        if self.buf.len() < end {
            return Some(false);
        }
        let header = match Header::decode(&self.buf) {
            Ok(h) => h,
            Err(e) => return fail(self, e.to_string()),
        };
        let recording = match crate::replay::read(Path::new("-"), &self.buf[..end]) {
            Ok(r) => r,
            Err(e) => return fail(self, e),
        };
        let mission = match mission_of(&recording) {
            Ok(m) => m,
            Err(e) => return fail(self, e),
        };
        lock(&shared.view).restart(mission);
        self.tick_hz = Some(header.tick_hz);
        self.skipping = false;
        self.drop_front(end);
        Some(true)
    }

    /// The stream ended (`what` says how: "standard input closed"): a partial frame or line
    /// left over is said.
    pub fn close(&mut self, shared: &Shared, what: &str) {
        if !self.line.is_empty() {
            // The last line of a log, without its newline.
            self.feed(b"\n", shared);
        }
        let mut view = lock(&shared.view);
        if !self.buf.is_empty() {
            view.error(format!(
                "the stream was cut at byte {}: {} bytes of a frame left",
                self.offset + self.buf.len(),
                self.buf.len()
            ));
        }
        view.end(format!("{what} after {} frames", self.frames));
    }
}

/// Reads frames from standard input into the view until it closes.
pub fn stdin_frames(shared: &Arc<Shared>) {
    let mut stream = FrameStream::new();
    let mut input = std::io::stdin().lock();
    let mut chunk = vec![0u8; 1 << 16];
    loop {
        match input.read(&mut chunk) {
            Ok(0) => break,
            Ok(n) => stream.feed(&chunk[..n], shared),
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => {
                lock(&shared.view).error(format!("standard input: {e}"));
                break;
            }
        }
    }
    stream.close(shared, "standard input closed");
}

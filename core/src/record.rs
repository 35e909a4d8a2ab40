//! The flight recorder's format: what the deciding side consumed and decided, as compact
//! binary frames a robot can stream (RTT, a RAM ring) and a host can check and replay.
//!
//! A recording is a [`Header`] (magic, version, fact-set width, the mission's hash) and then
//! one [`Frame`] an event of the runtime's trace: the event's instant in ticks and the words
//! [`TraceHash`] mixes for it ([`TraceHash::words`]), so a recording holds every delivered
//! sample (sensor, value, the facts it decides), every lost sample and sensor fault, every
//! behaviour's outcome, the plans selected and the states entered, bit for bit. Each frame
//! carries its length and a CRC-32 of its bytes: a corrupted or cut recording is detected
//! ([`RecordError`]), never read as events.
//!
//! Layout, little-endian: header `"PSMPAREC"`, version `u16`, width `u8` (fact-set words),
//! mission `u64`, tick rate `u32` (Hz, the unit of the frames' instants); frame: length `u8` (of what follows, checksum excluded), ticks `u64`,
//! header word `u64`, `W` fact-set words `u64`, CRC-32 (IEEE) `u32` of the length byte and
//! what follows it.
//!
//! ```
//! use embassy_time::Instant;
//! use psmpa_core::record::{self, Frame};
//! use psmpa_core::{SensorId, TraceEvent};
//!
//! let event: TraceEvent = TraceEvent::SensorOn { sensor: SensorId::new(1).unwrap() };
//! let mut buf = [0u8; record::MAX_FRAME];
//! let n = Frame::of(Instant::from_ticks(42), &event).encode(&mut buf).unwrap();
//! let (back, used) = Frame::<1>::decode(&buf[..n], 0).unwrap();
//! assert_eq!((back.ticks, used), (42, n));
//! assert_eq!(back, Frame::of(Instant::from_ticks(42), &event));
//! ```

use embassy_time::Instant;

use crate::action::{ActionId, SensorId};
use crate::facts::FactSetOf;
use crate::failure::SensorFault;
use crate::platform::Outcome;
use crate::spec::Mission;
use crate::store::Value;
use crate::trace::{Phase, TraceEvent, TraceHash, TraceSink};

/// The first bytes of every recording.
pub const MAGIC: [u8; 8] = *b"PSMPAREC";
/// The format's version; a recording of another is refused ([`RecordError::Version`]).
/// Version 2 added the tick rate to the header.
pub const VERSION: u16 = 2;
/// Bytes of a [`Header`].
pub const HEADER_LEN: usize = 8 + 2 + 1 + 8 + 4;
/// The widest fact sets a frame holds: 4 words, 256 facts (the loader's most).
pub const MAX_WORDS: usize = 4;
/// Bytes of the largest frame.
pub const MAX_FRAME: usize = frame_len(MAX_WORDS);

/// Bytes of a frame of a `words`-word runtime: 29 for one word.
pub const fn frame_len(words: usize) -> usize {
    words.saturating_mul(8).saturating_add(21)
}

/// Why bytes are not a recording, or not this one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RecordError {
    /// It does not start with [`MAGIC`].
    NotARecording,
    /// Written by another version of the format.
    Version {
        /// The version it was written in.
        found: u16,
    },
    /// Its fact sets are of another width than the reader's (or wider than [`MAX_WORDS`]).
    Width {
        /// Its width, words.
        found: u8,
    },
    /// The frame at byte `at` fails its checksum, or its length is not a frame's.
    Corrupt {
        /// Where the frame starts.
        at: usize,
    },
    /// The bytes end inside the header or the frame at byte `at`.
    Cut {
        /// Where the cut item starts.
        at: usize,
    },
    /// A buffer too small for a frame was given to [`Frame::encode`].
    Buffer,
    /// Its header gives a tick rate of 0: its frames' instants have no unit.
    TickRate,
}

impl core::fmt::Display for RecordError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NotARecording => f.write_str("not a recording (no PSMPAREC at its start)"),
            Self::Version { found } => write!(
                f,
                "a recording of format version {found}, this reads version {VERSION}"
            ),
            Self::Width { found } => write!(f, "a recording of {found}-word fact sets"),
            Self::Corrupt { at } => write!(f, "the frame at byte {at} fails its checksum"),
            Self::Cut { at } => write!(f, "cut short in the item at byte {at}"),
            Self::Buffer => f.write_str("the buffer is smaller than a frame"),
            Self::TickRate => f.write_str("its header gives a tick rate of 0 Hz"),
        }
    }
}

impl core::error::Error for RecordError {}

/// What a recording says of itself.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Header {
    /// Fact-set words of the runtime that wrote it.
    pub width: u8,
    /// The recorded mission's hash (the writer's choice of what it covers; `psmpa-sim` hashes
    /// the mission and the scenario), so that a replay against another mission is refused.
    pub mission: u64,
    /// The writer's embassy-time tick rate, Hz: the unit of every frame's instant (a board's
    /// 1 MHz, the host's 1 kHz).
    pub tick_hz: u32,
}

impl Header {
    /// The header of a `width`-word runtime's recording of `mission`, at this build's tick
    /// rate.
    pub const fn new(width: u8, mission: u64) -> Self {
        Self {
            width,
            mission,
            tick_hz: embassy_time::TICK_HZ as u32,
        }
    }

    /// The header's bytes.
    pub fn encode(&self) -> [u8; HEADER_LEN] {
        let mut out = [0u8; HEADER_LEN];
        let (magic, rest) = out.split_at_mut(8);
        magic.copy_from_slice(&MAGIC);
        let (version, rest) = rest.split_at_mut(2);
        version.copy_from_slice(&VERSION.to_le_bytes());
        let (width, rest) = rest.split_at_mut(1);
        width.copy_from_slice(&[self.width]);
        let (mission, tick_hz) = rest.split_at_mut(8);
        mission.copy_from_slice(&self.mission.to_le_bytes());
        tick_hz.copy_from_slice(&self.tick_hz.to_le_bytes());
        out
    }

    /// Reads the header at the start of `bytes`.
    pub fn decode(bytes: &[u8]) -> Result<Self, RecordError> {
        if bytes.get(..MAGIC.len()).is_some_and(|m| m != MAGIC) {
            return Err(RecordError::NotARecording);
        }
        if bytes.len() < MAGIC.len() && !MAGIC.starts_with(bytes) {
            return Err(RecordError::NotARecording);
        }
        // The version first: another version's header may be of another length.
        if bytes.len() >= 10 {
            let version = u16::from_le_bytes([byte(bytes, 8), byte(bytes, 9)]);
            if version != VERSION {
                return Err(RecordError::Version { found: version });
            }
        }
        let Some(header) = bytes.get(..HEADER_LEN) else {
            return Err(RecordError::Cut { at: 0 });
        };
        let tick_hz = (u64_at(header, 19) & 0xFFFF_FFFF) as u32;
        if tick_hz == 0 {
            return Err(RecordError::TickRate);
        }
        Ok(Self {
            width: byte(header, 10),
            mission: u64_at(header, 11),
            tick_hz,
        })
    }
}

/// One recorded event: its instant and the words of [`TraceHash::words`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Frame<const W: usize> {
    /// The event's instant, ticks.
    pub ticks: u64,
    /// The event's header word.
    pub header: u64,
    /// The event's fact set.
    pub payload: FactSetOf<W>,
}

impl<const W: usize> Frame<W> {
    /// The frame of `event` at `at`. O(W).
    pub fn of(at: Instant, event: &TraceEvent<W>) -> Self {
        let (header, payload) = TraceHash::words(event);
        Self {
            ticks: at.as_ticks(),
            header,
            payload,
        }
    }

    /// The event's kind, as the header word encodes it (a `TraceEvent` variant's number).
    pub fn kind(&self) -> u8 {
        (self.header & 0xFF) as u8
    }

    /// Writes the frame into `buf`; its length. O(W).
    pub fn encode(&self, buf: &mut [u8]) -> Result<usize, RecordError> {
        let len = frame_len(W);
        if W > MAX_WORDS {
            return Err(RecordError::Width { found: W as u8 });
        }
        let out = buf.get_mut(..len).ok_or(RecordError::Buffer)?;
        let body = len.saturating_sub(4);
        let mut at = 0usize;
        let mut put = |bytes: &[u8]| {
            let end = at.saturating_add(bytes.len());
            if let Some(dst) = out.get_mut(at..end) {
                dst.copy_from_slice(bytes);
            }
            at = end;
        };
        put(&[body.saturating_sub(1) as u8]);
        put(&self.ticks.to_le_bytes());
        put(&self.header.to_le_bytes());
        for w in self.payload.words() {
            put(&w.to_le_bytes());
        }
        let crc = crc32(out.get(..body).unwrap_or(&[]));
        if let Some(dst) = out.get_mut(body..len) {
            dst.copy_from_slice(&crc.to_le_bytes());
        }
        Ok(len)
    }

    /// Reads the frame that starts at `bytes[0]`, which is byte `at` of the recording (for
    /// errors); the frame and its length in bytes.
    pub fn decode(bytes: &[u8], at: usize) -> Result<(Self, usize), RecordError> {
        let len = frame_len(W);
        let Some(&first) = bytes.first() else {
            return Err(RecordError::Cut { at });
        };
        if usize::from(first) != len.saturating_sub(5) {
            return Err(RecordError::Corrupt { at });
        }
        let frame = bytes.get(..len).ok_or(RecordError::Cut { at })?;
        let body = len.saturating_sub(4);
        let crc = (u64_at(frame, body) & 0xFFFF_FFFF) as u32;
        if crc != crc32(frame.get(..body).unwrap_or(&[])) {
            return Err(RecordError::Corrupt { at });
        }
        let mut words = [0u64; W];
        for (i, w) in words.iter_mut().enumerate() {
            *w = u64_at(frame, i.saturating_mul(8).saturating_add(17));
        }
        Ok((
            Self {
                ticks: u64_at(frame, 1),
                header: u64_at(frame, 9),
                payload: FactSetOf::from_words(words),
            },
            len,
        ))
    }
}

/// The kind numbers of [`TraceHash::words`]' header word ([`Frame::kind`]) that a reader
/// tells apart.
pub mod kind {
    /// `StateEntered`.
    pub const STATE_ENTERED: u8 = 4;
    /// `StateLeft`.
    pub const STATE_LEFT: u8 = 5;
    /// `PhaseStarted`.
    pub const PHASE_STARTED: u8 = 6;
    /// `SensorOn`.
    pub const SENSOR_ON: u8 = 7;
    /// `SensorOff`.
    pub const SENSOR_OFF: u8 = 8;
    /// `Sample`.
    pub const SAMPLE: u8 = 9;
    /// `SensorFailed`.
    pub const SENSOR_FAILED: u8 = 10;
    /// `EffectsApplied`.
    pub const EFFECTS_APPLIED: u8 = 13;
    /// `User`.
    pub const USER: u8 = 16;
    /// `SampleLost`.
    pub const SAMPLE_LOST: u8 = 17;
    /// `PlanGenerated`.
    pub const PLAN_GENERATED: u8 = 18;
}

/// What a replay feeds the runtime, read back from a frame: the platform's side of the trace
/// (readings, faults, a behaviour's outcome and its own events) and the states it runs in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Input<const W: usize> {
    /// A sensor delivered a sample.
    Sample {
        /// The sensor.
        sensor: SensorId,
        /// Its main value.
        value: Value,
        /// The facts it decided true.
        holds: FactSetOf<W>,
    },
    /// A sensor answered without a value.
    Lost {
        /// The sensor.
        sensor: SensorId,
    },
    /// A sensor failed.
    Fault {
        /// The sensor.
        sensor: SensorId,
        /// How.
        fault: SensorFault,
    },
    /// A behaviour state started.
    Entered {
        /// The state's index.
        state: u8,
        /// Its action.
        action: ActionId,
    },
    /// A behaviour state ended; `None`: the runtime cut it short.
    Left {
        /// The state's index.
        state: u8,
        /// Its action.
        action: ActionId,
        /// How the behaviour ended.
        outcome: Option<Outcome>,
    },
    /// A behaviour's own event (`ActionIo::trace`).
    User {
        /// Its code.
        code: u16,
        /// Its value.
        value: i32,
    },
}

impl<const W: usize> Frame<W> {
    fn field(&self, i: u32) -> u8 {
        (self.header.checked_shr(i.saturating_mul(8)).unwrap_or(0) & 0xFF) as u8
    }

    fn action(&self) -> Option<ActionId> {
        ActionId::new(usize::from(self.field(2)) | usize::from(self.field(5)) << 8)
    }

    /// The phase a `PhaseStarted` frame starts (SMPA), `None` for any other frame.
    pub fn phase(&self) -> Option<Phase> {
        match (self.kind(), self.field(2)) {
            (kind::PHASE_STARTED, 0) => Some(Phase::Sense),
            (kind::PHASE_STARTED, 1) => Some(Phase::Act),
            _ => None,
        }
    }

    /// The nodes a `PlanGenerated` frame's search expanded, `None` for any other frame.
    pub fn expanded(&self) -> Option<u32> {
        (self.kind() == kind::PLAN_GENERATED)
            .then(|| self.payload.words().first().map(|w| *w as u32))
            .flatten()
    }

    /// The sensor a `SensorOn` (`true`) or `SensorOff` (`false`) frame switches, `None` for
    /// any other frame: when a sensor was on, as the robot itself recorded it.
    pub fn power(&self) -> Option<(SensorId, bool)> {
        let on = match self.kind() {
            kind::SENSOR_ON => true,
            kind::SENSOR_OFF => false,
            _ => return None,
        };
        Some((SensorId::new(usize::from(self.field(1)))?, on))
    }

    /// The input this frame records, if it is one ([`Input`]); `None` for the runtime's own
    /// decisions (plans, beliefs, violations, sensors switched) and for fields out of range.
    pub fn input(&self) -> Option<Input<W>> {
        let sensor = || SensorId::new(usize::from(self.field(1)));
        let low = self.payload.words().first().copied().unwrap_or(0);
        Some(match self.kind() {
            kind::SAMPLE => {
                let v = self.header.checked_shr(32).unwrap_or(0) as u32;
                let signed = i32::from_le_bytes(v.to_le_bytes());
                Input::Sample {
                    sensor: sensor()?,
                    value: match self.field(2) {
                        0 => Value::Bool(v != 0),
                        1 => Value::Int(signed),
                        2 => Value::Mm(signed),
                        3 => Value::Level(u8::try_from(v).ok()?),
                        4 => Value::NoEcho,
                        _ => return None,
                    },
                    holds: self.payload,
                }
            }
            kind::SAMPLE_LOST => Input::Lost { sensor: sensor()? },
            kind::SENSOR_FAILED => Input::Fault {
                sensor: sensor()?,
                fault: match self.field(2) {
                    0 => SensorFault::Timeout,
                    1 => SensorFault::OutOfRange,
                    2 => SensorFault::Stuck,
                    3 => SensorFault::Device(self.field(3)),
                    4 => SensorFault::Silent,
                    _ => return None,
                },
            },
            kind::STATE_ENTERED => Input::Entered {
                state: self.field(1),
                action: self.action()?,
            },
            kind::STATE_LEFT => Input::Left {
                state: self.field(1),
                action: self.action()?,
                outcome: match self.field(3) {
                    0 => None,
                    1 => Some(Outcome::Success),
                    2 => Some(Outcome::Failure),
                    3 => Some(Outcome::Interrupted),
                    _ => return None,
                },
            },
            kind::USER => Input::User {
                code: (self.header.checked_shr(16).unwrap_or(0) & 0xFFFF) as u16,
                value: i32::from_le_bytes(((low & 0xFFFF_FFFF) as u32).to_le_bytes()),
            },
            _ => return None,
        })
    }
}

/// Every frame of a recording after its header, in order, each or why it cannot be read (the
/// first error ends the iteration).
pub fn frames<const W: usize>(
    recording: &[u8],
) -> impl Iterator<Item = Result<Frame<W>, RecordError>> + '_ {
    let mut at = HEADER_LEN;
    let mut failed = false;
    core::iter::from_fn(move || {
        if failed || at >= recording.len() {
            return None;
        }
        let result = Frame::decode(recording.get(at..).unwrap_or(&[]), at);
        match result {
            Ok((frame, len)) => {
                at = at.saturating_add(len);
                Some(Ok(frame))
            }
            Err(e) => {
                failed = true;
                Some(Err(e))
            }
        }
    })
}

/// Where a [`Recorder`] puts its bytes: a byte stream (RTT, a file) or a ring in RAM.
pub trait RecordOut {
    /// Takes the bytes of one header or one frame, whole.
    fn write(&mut self, bytes: &[u8]);
}

/// A [`TraceSink`] that records every event into `out`, a header first. O(W) an event, no
/// allocation.
#[derive(Debug)]
pub struct Recorder<O> {
    out: O,
}

impl<O: RecordOut> Recorder<O> {
    /// Starts a recording of a `W`-word runtime's mission `mission` (a hash) in `out`.
    pub fn new<const W: usize>(mut out: O, mission: u64) -> Self {
        out.write(&Header::new(W as u8, mission).encode());
        Self { out }
    }

    /// A recorder that writes frames only: its caller wrote the header (and whatever it
    /// keeps between the header and the frames, a tool's prologue).
    pub const fn frames_only(out: O) -> Self {
        Self { out }
    }

    /// The output, giving up the recorder.
    pub fn into_inner(self) -> O {
        self.out
    }

    /// Encodes and writes `frame`: for a recorder that takes frames on the runtime's path
    /// ([`Frame::of`], a copy of the event's words) and encodes them later, in idle time.
    pub fn write_frame<const W: usize>(&mut self, frame: &Frame<W>) {
        let mut buf = [0u8; MAX_FRAME];
        if let Ok(n) = frame.encode(&mut buf) {
            self.out.write(buf.get(..n).unwrap_or(&[]));
        }
    }

    /// The output.
    pub fn out(&mut self) -> &mut O {
        &mut self.out
    }
}

impl<O: RecordOut, M: Mission<Facts = FactSetOf<W>>, const W: usize> TraceSink<M> for Recorder<O> {
    fn record(&mut self, at: Instant, event: &TraceEvent<W>) {
        self.write_frame(&Frame::of(at, event));
    }
}

fn byte(bytes: &[u8], i: usize) -> u8 {
    bytes.get(i).copied().unwrap_or(0)
}

fn u64_at(bytes: &[u8], i: usize) -> u64 {
    let mut b = [0u8; 8];
    for (k, v) in b.iter_mut().enumerate() {
        *v = byte(bytes, i.saturating_add(k));
    }
    u64::from_le_bytes(b)
}

/// A mission file's hash, for a recording's [`Header`]: FNV-1a over its bytes
/// (`include_mission!` computes it as `HASH` when the robot is built).
pub use psmpa_model::mission::mission_hash;

/// The remainders of the 16 nibbles, for [`crc32`]. (Evaluated at build time: an index out
/// of range fails the build.)
#[allow(clippy::indexing_slicing)]
const NIBBLE: [u32; 16] = {
    let mut t = [0u32; 16];
    let mut i = 0;
    while i < 16 {
        let mut crc = i as u32;
        let mut bit = 0;
        while bit < 4 {
            crc = (crc >> 1) ^ (0xEDB8_8320 & (crc & 1).wrapping_neg());
            bit += 1;
        }
        t[i] = crc;
        i += 1;
    }
    t
};

/// The remainder of `crc`'s low nibble (the `& 0xF` keeps the index in the table).
fn nibble(crc: u32) -> u32 {
    NIBBLE.get((crc & 0xF) as usize).copied().unwrap_or(0)
}

/// CRC-32 (IEEE 802.3, reflected, as zlib's), four bits at a time: a 64-byte table in flash,
/// a quarter of the bitwise loop's steps.
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = Crc32::new();
    crc.update(bytes);
    crc.finish()
}

/// [`crc32`] of bytes that come in parts.
#[derive(Clone, Copy, Debug)]
pub struct Crc32(u32);

impl Crc32 {
    /// Nothing yet.
    pub const fn new() -> Self {
        Self(!0)
    }

    /// Adds `bytes`.
    pub fn update(&mut self, bytes: &[u8]) {
        let mut crc = self.0;
        for &b in bytes {
            crc ^= u32::from(b);
            crc = (crc >> 4) ^ nibble(crc);
            crc = (crc >> 4) ^ nibble(crc);
        }
        self.0 = crc;
    }

    /// The checksum of everything added.
    pub const fn finish(self) -> u32 {
        !self.0
    }
}

impl Default for Crc32 {
    fn default() -> Self {
        Self::new()
    }
}

/// A RAM ring of the last `N` bytes of a recording, for a board's `.uninit` section: after a
/// watchdog or fault reset, [`Ring::recovered`] reads back the frames it still holds whole,
/// oldest first, so the seconds before the reset can be sent or read off by a probe.
///
/// `#[repr(C)]` with a magic word, so a board can tell a ring a previous boot wrote from what
/// power-on left ([`Ring::recovered`] also checks every frame's checksum). Writing is O(the
/// bytes written); nothing allocates, nothing is refused: the oldest bytes are overwritten.
#[repr(C)]
pub struct Ring<const N: usize> {
    magic: u32,
    /// Where the next byte goes, below `N`.
    head: u32,
    /// Bytes held, at most `N`.
    len: u32,
    bytes: [u8; N],
}

/// [`Ring`]'s magic word: "PSMR".
const RING_MAGIC: u32 = 0x524D_5350;

impl<const N: usize> Ring<N> {
    /// An empty ring (for a `static` that is not in `.uninit`, and for tests).
    pub const fn new() -> Self {
        Self {
            magic: RING_MAGIC,
            head: 0,
            len: 0,
            bytes: [0; N],
        }
    }

    /// Empties the ring: what a board calls at boot, after reading what a previous boot left.
    pub fn clear(&mut self) {
        self.magic = RING_MAGIC;
        self.head = 0;
        self.len = 0;
    }

    /// Bytes held: 0 unless a boot wrote this ring (its magic set, its counts in range), so
    /// that what power-on leaves reads as empty.
    pub fn held(&self) -> usize {
        let ok = self.magic == RING_MAGIC && (self.head as usize) < N.max(1);
        if ok { (self.len as usize).min(N) } else { 0 }
    }

    /// The byte `i` places after the oldest held.
    fn byte(&self, i: usize) -> u8 {
        let held = self.held();
        // head < N and held <= N: no overflow; checked_rem: no division by zero when N is 0.
        let oldest = (self.head as usize)
            .wrapping_add(N.wrapping_sub(held))
            .checked_rem(N)
            .unwrap_or(0);
        byte(
            &self.bytes,
            oldest.wrapping_add(i).checked_rem(N).unwrap_or(0),
        )
    }

    /// Copies the bytes held, oldest first, into `out`; how many (the newest when `out` is
    /// shorter).
    pub fn copy_into(&self, out: &mut [u8]) -> usize {
        let held = self.held();
        let skip = held.saturating_sub(out.len());
        let n = held.saturating_sub(skip);
        for (i, slot) in out.iter_mut().take(n).enumerate() {
            *slot = self.byte(skip.saturating_add(i));
        }
        n
    }

    /// The frame at byte `at` of what is held, and its length.
    fn frame_at<const W: usize>(&self, at: usize) -> Option<(Frame<W>, usize)> {
        let len = frame_len(W);
        if at.saturating_add(len) > self.held() || len > MAX_FRAME {
            return None;
        }
        // The length byte first: most offsets fail there, before any checksum.
        if usize::from(self.byte(at)) != len.saturating_sub(5) {
            return None;
        }
        let mut buf = [0u8; MAX_FRAME];
        for (i, slot) in buf.iter_mut().take(len).enumerate() {
            *slot = self.byte(at.saturating_add(i));
        }
        Frame::<W>::decode(buf.get(..len)?, at).ok()
    }

    /// The whole frames held, oldest first. The oldest bytes may be the end of a frame
    /// overwritten in part (or a header), so reading starts at the first offset where a
    /// frame's length and checksum hold (a CRC-32 over 25 or more bytes: a false start is a 1
    /// in 4 billion chance), and ends at the first frame that does not. No copy of the ring.
    pub fn recovered<const W: usize>(&self) -> impl Iterator<Item = Frame<W>> + '_ {
        let start = (0..self.held()).find(|&at| self.frame_at::<W>(at).is_some());
        let mut at = start.unwrap_or(usize::MAX);
        core::iter::from_fn(move || {
            let (frame, len) = self.frame_at::<W>(at)?;
            at = at.saturating_add(len);
            Some(frame)
        })
    }
}

impl<const N: usize> Default for Ring<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> RecordOut for Ring<N> {
    fn write(&mut self, bytes: &[u8]) {
        if N == 0 {
            return;
        }
        if self.magic != RING_MAGIC || self.head as usize >= N {
            self.clear();
        }
        let mut head = self.head as usize;
        for &b in bytes {
            if let Some(slot) = self.bytes.get_mut(head) {
                *slot = b;
            }
            head = head.saturating_add(1).checked_rem(N).unwrap_or(0);
        }
        self.head = head as u32;
        self.len = (self.len as usize).saturating_add(bytes.len()).min(N) as u32;
    }
}

/// An output lent to a recorder.
impl<T: RecordOut + ?Sized> RecordOut for &mut T {
    fn write(&mut self, bytes: &[u8]) {
        (**self).write(bytes);
    }
}

/// Writes a recording's start to `out`: `header`, then a tool's prologue: the length of
/// `body` (`u32`), `body`, a `kind` byte (what the body is), and a CRC-32 of the three.
pub fn write_start(out: &mut impl RecordOut, header: &Header, body: &[u8], kind: u8) {
    let len = (body.len() as u32).to_le_bytes();
    let kind = [kind];
    let mut crc = Crc32::new();
    for part in [&len[..], body, &kind] {
        crc.update(part);
    }
    out.write(&header.encode());
    out.write(&len);
    out.write(body);
    out.write(&kind);
    out.write(&crc.finish().to_le_bytes());
}

/// Two outputs at once: a stream and a ring, for example.
impl<A: RecordOut, B: RecordOut> RecordOut for (A, B) {
    fn write(&mut self, bytes: &[u8]) {
        self.0.write(bytes);
        self.1.write(bytes);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::action::SensorId;
    use crate::facts::{FactId, FactSet};
    use crate::store::Value;
    use std::vec::Vec;

    impl RecordOut for Vec<u8> {
        fn write(&mut self, bytes: &[u8]) {
            self.extend_from_slice(bytes);
        }
    }

    fn recording() -> Vec<u8> {
        let sonar = SensorId::new(0).unwrap();
        let clear = FactSet::single(FactId::new(3).unwrap());
        let mut rec = Recorder::new::<1>(Vec::new(), 0xABCD);
        for (t, e) in [
            (0, TraceEvent::SensorOn { sensor: sonar }),
            (
                100,
                TraceEvent::Sample {
                    sensor: sonar,
                    value: Value::Mm(-1234),
                    holds: clear,
                },
            ),
            (200, TraceEvent::SampleLost { sensor: sonar }),
        ] {
            TraceSink::<&crate::mission::Tables<'_, 1, 1, 1, 1>>::record(
                &mut rec,
                Instant::from_ticks(t),
                &e,
            );
        }
        rec.into_inner()
    }

    #[test]
    fn a_plan_generated_frame_says_how_many_nodes_its_search_expanded() {
        let generated = TraceEvent::<1>::PlanGenerated {
            length: 3,
            expanded: 70_000,
        };
        let at = Instant::from_ticks(5);
        assert_eq!(Frame::of(at, &generated).expanded(), Some(70_000));
        let other = TraceEvent::<1>::SensorOn {
            sensor: SensorId::new(0).unwrap(),
        };
        assert_eq!(Frame::of(at, &other).expanded(), None);
    }

    #[test]
    fn a_switch_frame_says_which_sensor_went_on_or_off() {
        let frames: Vec<Frame<1>> = frames(&recording()).map(Result::unwrap).collect();
        let sonar = SensorId::new(0).unwrap();
        let powers: Vec<_> = frames.iter().map(Frame::power).collect();
        assert_eq!(powers, [Some((sonar, true)), None, None]);
        let off = Frame::<1>::of(
            Instant::from_ticks(5),
            &TraceEvent::SensorOff { sensor: sonar },
        );
        assert_eq!(off.power(), Some((sonar, false)));
    }

    #[test]
    fn the_check_value_is_zlib_s() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn a_header_with_a_tick_rate_of_0_says_so() {
        let mut header = Header::new(1, 7).encode();
        header[19..23].copy_from_slice(&0u32.to_le_bytes());
        assert_eq!(Header::decode(&header), Err(RecordError::TickRate));
        assert_eq!(
            std::format!("{}", RecordError::TickRate),
            "its header gives a tick rate of 0 Hz"
        );
    }

    #[test]
    fn frames_read_back_as_written_and_hash_alike() {
        let bytes = recording();
        assert_eq!(bytes.len(), HEADER_LEN + 3 * frame_len(1));
        let header = Header::decode(&bytes).unwrap();
        assert_eq!((header.width, header.mission), (1, 0xABCD));
        let frames: Vec<Frame<1>> = frames(&bytes).map(Result::unwrap).collect();
        assert_eq!(
            frames.iter().map(|f| f.ticks).collect::<Vec<_>>(),
            [0, 100, 200]
        );
        // The words are the trace hash's: a recording hashes as the run did.
        let (h, p) = TraceHash::words::<1>(&TraceEvent::Sample {
            sensor: SensorId::new(0).unwrap(),
            value: Value::Mm(-1234),
            holds: FactSet::single(FactId::new(3).unwrap()),
        });
        assert_eq!((frames[1].header, frames[1].payload), (h, p));
        assert_eq!(frames[1].kind(), kind::SAMPLE);
    }

    #[test]
    fn a_changed_byte_or_a_cut_is_detected_never_read() {
        let bytes = recording();
        for i in HEADER_LEN..bytes.len() {
            let mut bad = bytes.clone();
            bad[i] ^= 0x10;
            let errors: Vec<_> = frames::<1>(&bad).filter_map(Result::err).collect();
            assert_eq!(errors.len(), 1, "byte {i}");
            assert!(matches!(errors[0], RecordError::Corrupt { .. }), "byte {i}");
        }
        for cut in HEADER_LEN + 1..bytes.len() {
            if (cut - HEADER_LEN).is_multiple_of(frame_len(1)) {
                continue;
            }
            let last = frames::<1>(&bytes[..cut]).last().unwrap();
            assert!(matches!(last, Err(RecordError::Cut { .. })), "cut at {cut}");
        }
        assert_eq!(Header::decode(&bytes[..5]), Err(RecordError::Cut { at: 0 }));
    }

    #[test]
    fn other_files_and_versions_are_refused_with_a_reason() {
        assert_eq!(
            Header::decode(b"{\"name\": \"sonar-8\"}"),
            Err(RecordError::NotARecording)
        );
        assert_eq!(Header::decode(b""), Err(RecordError::Cut { at: 0 }));
        let mut old = recording();
        old[8] = 1;
        assert_eq!(Header::decode(&old), Err(RecordError::Version { found: 1 }));
        // A version 1 header is shorter: still its version that is refused, not a cut.
        assert_eq!(
            Header::decode(&old[..19]),
            Err(RecordError::Version { found: 1 })
        );
        assert_eq!(
            std::format!("{}", RecordError::Version { found: 1 }),
            "a recording of format version 1, this reads version 2"
        );
    }

    #[test]
    fn a_ring_keeps_the_newest_whole_frames_after_a_reset() {
        let bytes = recording();
        // Room for two frames and a half: the oldest frame is cut, the header gone.
        let mut ring: Ring<{ 2 * 29 + 14 }> = Ring::new();
        ring.write(&bytes[..HEADER_LEN]);
        for f in bytes[HEADER_LEN..].chunks(frame_len(1)) {
            ring.write(f);
        }
        let all: Vec<Frame<1>> = frames(&bytes).map(Result::unwrap).collect();
        let back: Vec<Frame<1>> = ring.recovered().collect();
        assert_eq!(back, all[1..]);
        let mut out = [0u8; 100];
        let n = ring.copy_into(&mut out);
        assert_eq!(&out[..n], &bytes[bytes.len() - n..]);
        // What power-on leaves reads as nothing; a cleared ring holds nothing.
        let mut garbage: Ring<64> = Ring::new();
        garbage.magic = 0xDEAD_BEEF;
        garbage.len = 64;
        assert_eq!(garbage.recovered::<1>().count(), 0);
        ring.clear();
        assert_eq!(ring.recovered::<1>().count(), 0);
        // A corrupted byte ends the frames read at the frame it is in.
        let mut ring: Ring<256> = Ring::new();
        ring.write(&bytes);
        ring.bytes[HEADER_LEN + frame_len(1) + 3] ^= 1;
        assert_eq!(ring.recovered::<1>().collect::<Vec<_>>(), all[..1]);
    }

    /// The inputs a replay feeds read back as they were traced.
    #[test]
    fn inputs_read_back_from_their_frames() {
        let sonar = SensorId::new(2).unwrap();
        let action = ActionId::new(300).unwrap();
        let clear = FactSet::single(FactId::new(3).unwrap());
        for (event, input) in [
            (
                TraceEvent::Sample {
                    sensor: sonar,
                    value: Value::Mm(-7),
                    holds: clear,
                },
                Some(Input::Sample {
                    sensor: sonar,
                    value: Value::Mm(-7),
                    holds: clear,
                }),
            ),
            (
                TraceEvent::Sample {
                    sensor: sonar,
                    value: Value::Level(2),
                    holds: FactSet::EMPTY,
                },
                Some(Input::Sample {
                    sensor: sonar,
                    value: Value::Level(2),
                    holds: FactSet::EMPTY,
                }),
            ),
            (
                TraceEvent::SensorFailed {
                    sensor: sonar,
                    fault: SensorFault::Device(9),
                },
                Some(Input::Fault {
                    sensor: sonar,
                    fault: SensorFault::Device(9),
                }),
            ),
            (
                TraceEvent::StateLeft {
                    state: 3,
                    action,
                    outcome: Some(Outcome::Interrupted),
                },
                Some(Input::Left {
                    state: 3,
                    action,
                    outcome: Some(Outcome::Interrupted),
                }),
            ),
            (
                TraceEvent::User {
                    code: 513,
                    value: -2,
                },
                Some(Input::User {
                    code: 513,
                    value: -2,
                }),
            ),
            (TraceEvent::SensorOn { sensor: sonar }, None),
        ] {
            let frame = Frame::<1>::of(Instant::from_ticks(5), &event);
            assert_eq!(frame.input(), input, "{event:?}");
        }
    }
}

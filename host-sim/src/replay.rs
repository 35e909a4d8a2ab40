//! A run's flight recording and its replay: `psmpa-sim run --record FILE` records what the
//! runtime consumed and decided ([`psmpa_core::record`]); `psmpa-sim replay FILE` runs the
//! recorded mission again through the same runtime with no world, feeding it the recorded
//! readings, faults and behaviour outcomes at their instants, and compares every event it
//! traces with the recording.
//!
//! A file is the core's header (its mission hash covers the Fetch Tea mission, the scenario's
//! bytes and the architecture), a prologue (the scenario's bytes and the architecture, with
//! a CRC-32), then the core's frames.

use core::cell::{Cell, RefCell};
use core::future::{pending, poll_fn};
use core::task::{Poll, Waker};
use std::path::Path;

use embassy_futures::select::select;
use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_time::{Duration, Instant, Timer};
use psmpa_core::record::{self, Frame, Header, Input, RecordOut, Recorder, kind};
use psmpa_core::trace::Phase;
use psmpa_core::{
    Act, ActionOf, Actuator, Describe, FactSet, Mission, Outcome, Platform, Reading, Sensor,
    SensorFault, SensorId, SensorMode, SensorOf, TraceEvent, TraceSink,
};
use serde::Serialize;

use psmpa_fetch_tea::{RECORD_WORDS, Settings, fetch_tea};

use crate::backend::simulate_split;
use crate::cli::files::Output;
use crate::cli::foxglove::McapLog;
use crate::robot::{self, Arch};
use crate::scenario::Scenario;

/// The largest recording `replay` reads: 256 MiB (a day of 1 ms samples is about 10 GB; a
/// shipped scenario's, tens of kB).
pub const MAX_RECORDING: u64 = 256 << 20;

/// A recording's bytes before its frames: the core's header and the prologue
/// ([`robot::record_start`]).
pub fn start(scenario_json: &[u8], arch: Arch) -> Vec<u8> {
    let mut out = Bytes(Vec::new());
    robot::record_start(
        &mut out,
        robot::mission_hash(scenario_json, arch),
        scenario_json,
        arch,
    );
    out.0
}

/// Bytes gathered in memory.
struct Bytes(Vec<u8>);

impl RecordOut for Bytes {
    fn write(&mut self, bytes: &[u8]) {
        self.0.extend_from_slice(bytes);
    }
}

/// A recording streamed into an output file.
pub struct RecordFile(pub Output);

impl RecordOut for RecordFile {
    fn write(&mut self, bytes: &[u8]) {
        // An `Output` keeps a write error for its commit (and raises its alarm).
        let _ = std::io::Write::write_all(&mut self.0, bytes);
    }
}

/// The recorder of a run: a [`TraceSink`] into `out`, the header and prologue written first.
pub fn recorder(out: Output, scenario_json: &[u8], arch: Arch) -> Recorder<RecordFile> {
    let mut out = RecordFile(out);
    out.write(&start(scenario_json, arch));
    Recorder::frames_only(out)
}

/// The bytes of one `rec [..]` line of a decoded defmt log, or `None` for another line.
pub fn rec_bytes(line: &str) -> Option<Result<Vec<u8>, String>> {
    let list = match line.split_once(" rec [") {
        Some((_, list)) => list,
        None => line.strip_prefix("rec [")?,
    };
    // What follows the list (a location a log viewer adds) is not the recording's.
    let (list, _) = list.split_once(']')?;
    Some(
        list.split(", ")
            .filter(|b| !b.is_empty())
            .map(|b| {
                b.parse::<u8>()
                    .map_err(|_| format!("not a byte, {b:.10}, in the line {line:.60}"))
            })
            .collect(),
    )
}

/// The recordings in a firmware's decoded defmt log (`probe-rs run`, `defmt-print`): its
/// `rec [bytes]` lines, in order, a new recording at each header.
pub fn from_log(log: &str) -> Result<Vec<Vec<u8>>, String> {
    let mut out: Vec<Vec<u8>> = Vec::new();
    for line in log.lines() {
        let Some(bytes) = rec_bytes(line) else {
            continue;
        };
        let bytes = bytes?;
        match out.last_mut() {
            Some(last) if !bytes.starts_with(&record::MAGIC) => last.extend_from_slice(&bytes),
            None if !bytes.starts_with(&record::MAGIC) => {
                return Err("a recording's frame before any header".to_owned());
            }
            _ => out.push(bytes),
        }
    }
    Ok(out)
}

/// A file's recording: the file itself, or the first recording in a decoded firmware log.
pub fn bytes_of(file: &Path, bytes: Vec<u8>) -> Result<Vec<u8>, String> {
    if bytes.starts_with(&record::MAGIC) {
        return Ok(bytes);
    }
    // Read lossily: a log's other lines (a panic message, a serial port's noise) may hold
    // bytes that are not UTF-8; a `rec` line with one fails its own parse.
    match from_log(&String::from_utf8_lossy(&bytes)) {
        Ok(recs) if !recs.is_empty() => Ok(recs.into_iter().next().unwrap_or_default()),
        Err(e) => Err(format!("{}: {e}", file.display())),
        // Neither: the header's check says why.
        Ok(_) => Ok(bytes),
    }
}

/// Where a recording was made, and what its replay needs besides the frames.
pub enum Source {
    /// psmpa-sim's run of the Fetch Tea robot on the paper's NAO, or the QEMU firmware's:
    /// the scenario (its bytes, a file's or the canonical form) and the architecture.
    Simulator {
        /// The scenario's bytes as recorded.
        scenario_json: Vec<u8>,
        /// The scenario.
        scenario: Box<Scenario>,
        /// The architecture.
        arch: Arch,
    },
    /// The Fetch Tea robot on a board (`psmpa-fetch-tea`, the mission compiled in): its
    /// calibration record, which sets the sensors' periods.
    Board {
        /// The calibration.
        settings: Settings,
    },
}

/// The longest run a recording may hold, s: a day, as a scenario's `max_s`.
pub const LONGEST_S: u64 = 86_400;

/// The prologue's kind byte of a board's recording (after the architectures' 0 and 1).
pub const BOARD: u8 = 2;

/// A recording, read and checked.
pub struct Recording {
    /// Where it was made.
    pub source: Source,
    /// Every recorded event.
    pub frames: Vec<Frame<1>>,
}

impl Recording {
    /// A name for its file: `SCENARIO.ARCH`, or `board`.
    pub fn name(&self) -> String {
        match &self.source {
            Source::Simulator { scenario, arch, .. } => {
                format!("{}.{}", scenario.name, arch.name())
            }
            Source::Board { .. } => "board".to_owned(),
        }
    }
}

/// Reads a recording from `bytes` (from `file`): one line naming the file and the fault when
/// it is not one, not whole, or not of this mission.
pub fn read(file: &Path, bytes: &[u8]) -> Result<Recording, String> {
    let fail = |why: String| format!("{}: {why}", file.display());
    let header = Header::decode(bytes).map_err(|e| fail(e.to_string()))?;
    if header.width != 1 {
        return Err(fail(format!(
            "a recording of {}-word fact sets; the Fetch Tea mission has one",
            header.width
        )));
    }
    let at = record::HEADER_LEN;
    let cut = || fail(format!("cut short in its prologue (byte {at})"));
    let len_bytes = bytes.get(at..at + 4).ok_or_else(cut)?;
    let len = u32::from_le_bytes([len_bytes[0], len_bytes[1], len_bytes[2], len_bytes[3]]) as usize;
    let end = (at + 4)
        .checked_add(len)
        .and_then(|e| e.checked_add(1))
        .ok_or_else(cut)?;
    let body = bytes.get(at..end).ok_or_else(cut)?;
    let crc = bytes.get(end..end + 4).ok_or_else(cut)?;
    if record::crc32(body).to_le_bytes() != crc {
        return Err(fail(format!(
            "its prologue at byte {at} fails its checksum"
        )));
    }
    let prologue = &body[4..4 + len];
    // No larger than a scenario file may be: what a loader reads at most.
    if len as u64 > crate::cli::files::MAX_INPUT {
        return Err(fail(format!(
            "its prologue holds {len} bytes, more than a scenario file may ({} bytes)",
            crate::cli::files::MAX_INPUT
        )));
    }
    let source = match body[4 + len] {
        BOARD => {
            if header.mission != fetch_tea::HASH {
                return Err(fail(
                    "recorded on a board with another mission than missions/fetch-tea.json: refused"
                        .into(),
                ));
            }
            let mut words = [0u32; RECORD_WORDS];
            if prologue.len() != 4 * RECORD_WORDS {
                return Err(fail(format!(
                    "a board's prologue of {} bytes, not a calibration record's {}",
                    prologue.len(),
                    4 * RECORD_WORDS
                )));
            }
            for (w, b) in words.iter_mut().zip(prologue.chunks_exact(4)) {
                *w = u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
            }
            let settings = Settings::from_record(&words)
                .map_err(|e| fail(format!("its calibration record: {e}")))?;
            Source::Board { settings }
        }
        byte @ (0 | 1) => {
            let arch = if byte == 0 { Arch::PSmpa } else { Arch::Smpa };
            let scenario_json = prologue.to_vec();
            if header.mission != robot::mission_hash(&scenario_json, arch) {
                return Err(fail(
                    "recorded with another mission than this psmpa-sim's Fetch Tea: refused".into(),
                ));
            }
            let scenario = if scenario_json.first() == Some(&b'[') {
                // A firmware's recording: the canonical form it embeds.
                let mut s = Scenario::empty();
                s.read_canonical(&scenario_json).map_err(|_| {
                    fail(format!(
                        "its scenario, in canonical form, does not read: {}",
                        crate::scenario::canonical_problem(&scenario_json)
                    ))
                })?;
                // Made from a validated file, it holds only values a file may: checked as one.
                let checked = Scenario::validate(&s.to_file())
                    .map_err(|e| fail(format!("its scenario, in canonical form: {e}")))?;
                if canonical(&checked) != canonical(&s) {
                    return Err(fail(
                        "its scenario, in canonical form, holds values no scenario file gives"
                            .into(),
                    ));
                }
                s
            } else {
                crate::load::parse(file, &scenario_json).map_err(|e| e.to_string())?
            };
            Source::Simulator {
                scenario_json,
                scenario: Box::new(scenario),
                arch,
            }
        }
        other => {
            return Err(fail(format!(
                "unknown architecture {other} in its prologue"
            )));
        }
    };
    let mut frames = Vec::new();
    let mut offset = end + 4;
    while offset < bytes.len() {
        let (mut frame, used) =
            Frame::<1>::decode(&bytes[offset..], offset).map_err(|e| fail(e.to_string()))?;
        // In the host's ticks (a board counts 1 MHz): what it took less than one of them to do
        // comes at the same instant.
        let ticks = u128::from(frame.ticks) * u128::from(embassy_time::TICK_HZ)
            / u128::from(header.tick_hz);
        // No run lasts longer than a day (a scenario's longest): an instant beyond it would
        // overflow the replay's clock.
        if ticks > u128::from(LONGEST_S * embassy_time::TICK_HZ) {
            return Err(fail(format!(
                "the frame at byte {offset} is at {} s, after a day, the longest run",
                u128::from(frame.ticks) / u128::from(header.tick_hz)
            )));
        }
        frame.ticks = ticks as u64;
        frames.push(frame);
        offset += used;
    }
    Ok(Recording { source, frames })
}

/// A scenario's canonical bytes, to compare two.
fn canonical(s: &Scenario) -> Option<std::vec::Vec<u8>> {
    let mut out = vec![0u8; crate::cli::files::MAX_INPUT as usize];
    let n = s.to_canonical(&mut out).ok()?;
    out.truncate(n);
    Some(out)
}

/// The first event where the replay and the recording differ.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Divergence {
    /// Its number among the recorded events, from 0.
    pub event: usize,
    /// Its instant, seconds.
    pub at_s: f64,
    /// The recorded event, in words (`null`: the recording had ended).
    pub recorded: Option<String>,
    /// What the replay traced, in words (`null`: the replay had ended).
    pub replayed: Option<String>,
}

/// A replay's result.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Replayed {
    /// Decisions compared: events of the replay equal to the recording's, in order.
    pub decisions: usize,
    /// Whether an event differed.
    pub diverged: bool,
    /// The first difference.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub divergence: Option<Divergence>,
    /// The most an equal event came earlier or later than recorded, ms (0 unless a lag is
    /// allowed).
    pub skew_ms: u64,
    /// The instant the replay ran to, seconds: the run's end, or a second past the last
    /// recorded frame, whichever is sooner.
    pub replayed_s: f64,
}

/// How far the replay has traced: the platform hands each input over when every recorded
/// event before it has been traced again, so that inputs due at one instant arrive in the
/// recorded order.
#[derive(Default)]
struct Progress {
    traced: Cell<usize>,
    waiting: RefCell<Vec<Waker>>,
}

impl Progress {
    fn advance(&self) {
        self.traced.set(self.traced.get() + 1);
        for w in self.waiting.borrow_mut().drain(..) {
            w.wake();
        }
    }

    /// Until `index` events have been traced again.
    async fn reach(&self, index: usize) {
        poll_fn(|cx| {
            if self.traced.get() >= index {
                Poll::Ready(())
            } else {
                self.waiting.borrow_mut().push(cx.waker().clone());
                Poll::Pending
            }
        })
        .await;
    }
}

/// The platform of a replay: no world, the recorded inputs at their instants.
struct Replay<'f> {
    frames: &'f [Frame<1>],
    /// By sensor index: whether the mission reads it on demand.
    on_demand: Vec<bool>,
    progress: &'f Progress,
}

impl Replay<'_> {
    fn on_demand(&self, sensor: SensorId) -> bool {
        self.on_demand.get(sensor.index()).copied().unwrap_or(false)
    }
}

impl Replay<'_> {
    /// Until frame `index`'s instant, and every recorded event before it traced again.
    async fn until(&self, index: usize) {
        if let Some(frame) = self.frames.get(index) {
            Timer::at(Instant::from_ticks(frame.ticks)).await;
        }
        self.progress.reach(index).await;
    }
}

/// A replay reads any mission of one word of facts by id: the recording names its sensors so.
impl<Ms: Mission<Facts = FactSet>> Sensor<Ms> for Replay<'_> {
    async fn switch_on(&self, _: Ms::Sensor) -> Result<(), SensorFault> {
        Ok(())
    }

    async fn switch_off(&self, _: Ms::Sensor) {}

    async fn sample(&self, sensor: Ms::Sensor) -> Result<Option<Reading>, SensorFault> {
        let sensor = sensor.id();
        let Some((index, _, input)) = self.next_of(sensor) else {
            return pending().await;
        };
        self.until(index).await;
        match input {
            Input::Sample { value, holds, .. } => Ok(Some(Reading::new(value, holds))),
            Input::Lost { .. } => Ok(None),
            // The runtime's own verdicts: it reaches them again when no answer comes.
            Input::Fault {
                fault: SensorFault::Timeout | SensorFault::Silent,
                ..
            } => pending().await,
            Input::Fault { fault, .. } => Err(fault),
            _ => pending().await,
        }
    }

    /// Where the recording has a sample between two of the sensor's instants (a bump
    /// switch's edge woke it), at that sample's instant: a sample on the grid comes no earlier
    /// than its instant, so this never wakes one early.
    ///
    /// A sensor reads once an instant: where a board's samples came closer than one of the
    /// host's ticks (a chattering switch at 1 MHz), the next comes a tick later.
    async fn wake(&self, sensor: Ms::Sensor) {
        match self.next_of(sensor.id()) {
            Some((_, ticks, _)) if ticks > Instant::now().as_ticks() => {
                Timer::at(Instant::from_ticks(ticks)).await;
            }
            Some(_) => Timer::after_ticks(1).await,
            None => pending().await,
        }
    }
}

impl Replay<'_> {
    /// The next recorded reading, loss or fault of `sensor` not yet traced again, whatever
    /// its instant: where the recording was made, a sampler's period may be anchored a tick
    /// later or earlier than here (the chip's computing before it started), and its sample is
    /// still this one. Its index, instant and input.
    fn next_of(&self, sensor: SensorId) -> Option<(usize, u64, Input<1>)> {
        let from = self.progress.traced.get();
        // Past the recording's end (the replay went on) there is nothing more to feed.
        let rest = self.frames.get(from..).unwrap_or_default();
        rest.iter().enumerate().find_map(|(i, f)| match f.input()? {
            input @ (Input::Sample { sensor: s, .. }
            | Input::Lost { sensor: s }
            | Input::Fault { sensor: s, .. })
                if s == sensor =>
            {
                Some((from + i, f.ticks, input))
            }
            _ => None,
        })
    }
}

impl<Ms: Mission<Facts = FactSet>> Actuator<Ms> for Replay<'_> {
    async fn run(&self, act: Act<'_, Ms>) -> Outcome {
        let io = act.untyped();
        let action = io.action().id();
        // The state this behaviour runs in: the last entered for `action` by now (SMPA first
        // polls a behaviour at its first act phase, after the state was entered).
        let now = Instant::now().as_ticks();
        let upto = self
            .frames
            .partition_point(|f| f.ticks <= now)
            .max(self.progress.traced.get())
            .min(self.frames.len());
        let entered = self.frames[..upto].iter().rposition(
            |f| matches!(f.input(), Some(Input::Entered { action: a, .. }) if a == action),
        );
        let Some(start) = entered else {
            return pending().await;
        };
        for (index, frame) in self.frames.iter().enumerate().skip(start + 1) {
            match frame.input() {
                Some(Input::Left {
                    action: a, outcome, ..
                }) if a == action => {
                    // The behaviour returned before the runtime switched its sensors off and
                    // applied its effects: hand the outcome over before those are traced.
                    let mut returned = index;
                    while returned > start + 1
                        && self.frames.get(returned - 1).is_some_and(|f| {
                            matches!(f.kind(), kind::SENSOR_OFF | kind::EFFECTS_APPLIED)
                        })
                    {
                        returned -= 1;
                    }
                    self.until(returned).await;
                    return match outcome {
                        Some(o) => o,
                        // The runtime cut it short: it will again.
                        None => pending().await,
                    };
                }
                Some(Input::User { code, value }) => {
                    self.until(index).await;
                    io.trace(code, value);
                }
                Some(Input::Sample { sensor, .. }) if self.on_demand(sensor) => {
                    // Under SMPA a request made in an act phase waits, the sensor off, for the
                    // next sense phase: ask right after that act phase started, when the
                    // behaviour last ran; else at the sample's own turn.
                    let window = &self.frames[start..index];
                    let act = window.iter().rposition(|f| f.phase() == Some(Phase::Act));
                    let sensed_since = act.is_some_and(|a| {
                        window[a..].iter().any(|f| f.phase() == Some(Phase::Sense))
                    });
                    match act {
                        Some(a) if sensed_since => self.until(start + a + 1).await,
                        _ => self.until(index).await,
                    }
                    io.request(sensor);
                }
                _ => {}
            }
        }
        pending().await
    }

    fn halt(&self, _: Ms::Action) {
        // Nothing moves: a replay drives no actuator.
    }
}

impl Platform for Replay<'_> {
    type Mutex = NoopRawMutex;
}

/// Compares each traced event with the recording's next.
struct Compare<'f> {
    expected: &'f [Frame<1>],
    /// An event in the mission's words.
    describe: &'f dyn Fn(&TraceEvent) -> String,
    progress: &'f Progress,
    next: usize,
    divergence: Option<Divergence>,
    /// The replay's events for Foxglove (`--mcap`).
    mcap: Option<McapLog<Output>>,
    /// How much later or earlier than recorded an event may come, ticks.
    lag: u64,
    /// The most an equal event came later or earlier.
    skew: u64,
}

impl<Ms: psmpa_core::Mission<Facts = psmpa_core::FactSet>> TraceSink<Ms> for Compare<'_> {
    fn record(&mut self, at: Instant, event: &TraceEvent) {
        if let Some(log) = &mut self.mcap {
            log.runtime(at, event);
        }
        let got = Frame::of(at, event);
        if self.divergence.is_none() {
            let want = self.expected.get(self.next);
            let equal = want.is_some_and(|w| {
                (w.header, w.payload) == (got.header, got.payload)
                    && w.ticks.abs_diff(got.ticks) <= self.lag
            });
            if let Some(w) = want.filter(|_| equal) {
                self.skew = self.skew.max(w.ticks.abs_diff(got.ticks));
                // An event the replay made sooner than recorded: where it was recorded,
                // computing took that time (a chip's cycles), so the clock catches up. Only
                // then: moving it across a gap the replay spends waiting made waits the
                // recording did not have (past a sensor's timeout), and a wider lag rejected
                // what a narrower one accepted.
                if got.ticks < w.ticks {
                    crate::backend::advance_to(Instant::from_ticks(w.ticks));
                }
            }
            if !equal {
                // Where only the instants differ, say both.
                let when = |ticks: u64| match want {
                    Some(w) if w.ticks != got.ticks => format!(" at {:.3} s", seconds(ticks)),
                    _ => String::new(),
                };
                self.divergence = Some(Divergence {
                    event: self.next,
                    at_s: seconds(want.map_or(got.ticks, |w| w.ticks.min(got.ticks))),
                    recorded: want.map(|w| recorded_text(self.describe, w) + &when(w.ticks)),
                    replayed: Some((self.describe)(event) + &when(got.ticks)),
                });
            }
        }
        self.next += 1;
        self.progress.advance();
    }
}

fn seconds(ticks: u64) -> f64 {
    Instant::from_ticks(ticks).as_micros() as f64 / 1e6
}

/// A recorded frame in words: as the replay would trace it when it is one of its inputs, else
/// its kind.
fn recorded_text(describe: &dyn Fn(&TraceEvent) -> String, frame: &Frame<1>) -> String {
    let event = match frame.input() {
        Some(Input::Sample {
            sensor,
            value,
            holds,
        }) => Some(TraceEvent::Sample {
            sensor,
            value,
            holds,
        }),
        Some(Input::Lost { sensor }) => Some(TraceEvent::SampleLost { sensor }),
        Some(Input::Fault { sensor, fault }) => Some(TraceEvent::SensorFailed { sensor, fault }),
        Some(Input::Entered { .. })
        | Some(Input::Left { .. })
        | Some(Input::User { .. })
        | None => None,
    };
    match event {
        Some(e) => describe(&e),
        None => format!(
            "a trace event of kind {} (header {:#x})",
            frame.kind(),
            frame.header
        ),
    }
}

/// Replays `recording` through the runtime and compares every event; with `mcap`, also logs
/// the replay's events there for Foxglove, and gives the output back to commit.
///
/// `lag` 0 compares every event bit for bit, its instant included: a host's recording. A
/// chip's computing takes time the host's does not, and its samplers start when its interrupt
/// runs: there an event may come up to `lag` earlier or later than recorded, and everything
/// else must be equal, in order ([`Replayed::skew_ms`] says how far apart they came).
pub fn replay(
    recording: &Recording,
    mcap: Option<Output>,
    lag: Duration,
) -> Result<(Replayed, Option<Output>), String> {
    let progress = Progress::default();
    let frames = &recording.frames;
    let start = Instant::from_ticks(frames.first().map_or(0, |f| f.ticks));
    let mcap = |scenario: &Scenario| -> Result<Option<McapLog<Output>>, String> {
        match mcap {
            Some(out) => {
                let path = out.path().to_path_buf();
                McapLog::new(out, scenario)
                    .map(Some)
                    .map_err(|e| format!("{}: {e}", path.display()))
            }
            None => Ok(None),
        }
    };
    let compare = |describe, mcap| Compare {
        expected: frames,
        describe,
        progress: &progress,
        next: 0,
        divergence: None,
        mcap,
        lag: lag.as_ticks(),
        skew: 0,
    };
    let platform = |modes: Vec<bool>| Replay {
        frames,
        on_demand: modes,
        progress: &progress,
    };
    // Both run the compiled mission, as the simulator and the board do: the simulator's with
    // its scenario's policy and the periods its robot is calibrated with (the paper's NAO),
    // until the run's end or a second past the last frame; the board's with its calibration's
    // periods, a second past the last frame.
    let last = Instant::from_ticks(frames.last().map_or(0, |f| f.ticks)) + Duration::from_secs(1);
    let empty = Scenario::empty();
    let (scenario, config, periods, end) = match &recording.source {
        Source::Simulator { scenario, arch, .. } => {
            let settings = crate::rig::settings_for(scenario, crate::rig::Chassis::Nao);
            (
                &**scenario,
                robot::config(scenario, *arch),
                [settings.sonar_period, settings.bumper_period],
                Instant::from_millis(scenario.max_ms).min(last),
            )
        }
        Source::Board { settings } => (
            &empty,
            psmpa_core::Config::default(),
            [settings.sonar_period, settings.bumper_period],
            last,
        ),
    };
    let describe = |e: &TraceEvent| fetch_tea::FetchTea.describe(*e).to_string();
    let platform = platform(on_demand(fetch_tea::TABLES.domain.sensors()));
    let mut runtime = fetch_tea::Runtime::<'_, Replay<'_>, Compare<'_>>::new(
        fetch_tea::FetchTea,
        &platform,
        compare(&describe, mcap(scenario)?),
        config,
    );
    for (sensor, period) in [fetch_tea::Sensor::Sonar, fetch_tea::Sensor::Bumper]
        .into_iter()
        .zip(periods)
    {
        if period.is_some() && !runtime.set_period(sensor, period) {
            return Err(format!("the recording's periods: {period:?} for {sensor}"));
        }
    }
    // The control loop: the same planner, where no library plan applies.
    let mut space = psmpa_fetch_tea::PlannerSpace::new();
    let (mut sensing, mut deciding) = runtime.split();
    let decided = deciding.run_planning(&psmpa_fetch_tea::PLANNER, &mut space);
    let ran_to = drive(sensing.run(), decided, start, end)?;
    finish(runtime.into_sink(), ran_to)
}

/// By sensor index: whether the mission reads it on demand.
fn on_demand<const W: usize>(sensors: &[psmpa_core::SensorAction<'_, W>]) -> Vec<bool> {
    sensors
        .iter()
        .map(|s| matches!(s.mode, SensorMode::OnDemand))
        .collect()
}

/// Runs a replay's two sides until the deciding side ends or `end` (a second's margin); the
/// instant it ran to.
fn drive<S: core::future::Future, F: core::future::Future>(
    sensing: S,
    deciding: F,
    start: Instant,
    end: Instant,
) -> Result<Instant, String> {
    let deciding = async {
        // The runtime started at the first recorded instant: a board boots first.
        crate::backend::advance_to(start);
        let _ = select(deciding, Timer::at(end)).await;
        Instant::now()
    };
    let limit = Duration::from_ticks(end.as_ticks()) + Duration::from_secs(1);
    simulate_split(sensing, deciding, limit)
        .map(|done| done.output)
        .map_err(|e| format!("the replay failed: {e}"))
}

/// The last comparison (a recording longer than its replay), and the result.
fn finish(mut compare: Compare<'_>, ran_to: Instant) -> Result<(Replayed, Option<Output>), String> {
    if compare.divergence.is_none() && compare.next < compare.expected.len() {
        let want = &compare.expected[compare.next];
        compare.divergence = Some(Divergence {
            event: compare.next,
            at_s: seconds(want.ticks),
            recorded: Some(recorded_text(compare.describe, want)),
            replayed: None,
        });
    }
    let decisions = compare
        .divergence
        .as_ref()
        .map_or(compare.next, |d| d.event);
    let log = match compare.mcap.take() {
        Some(log) => Some(log.finish()?),
        None => None,
    };
    Ok((
        Replayed {
            decisions,
            diverged: compare.divergence.is_some(),
            divergence: compare.divergence,
            skew_ms: Duration::from_ticks(compare.skew).as_millis(),
            replayed_s: seconds(ran_to.as_ticks()),
        },
        log,
    ))
}

impl Replayed {
    /// The result in one line.
    pub fn text(&self) -> String {
        match &self.divergence {
            None if self.skew_ms > 0 => format!(
                "replay: {} decisions, every one as recorded, within {} ms of its instant\n",
                self.decisions, self.skew_ms
            ),
            None => format!(
                "replay: {} decisions, every one as recorded\n",
                self.decisions
            ),
            Some(d) => format!(
                "replay diverged at {:.3} s (event {}): recorded {}, the replay {}\n",
                d.at_s,
                d.event,
                d.recorded.as_deref().unwrap_or("nothing more"),
                d.replayed.as_deref().unwrap_or("traced nothing more"),
            ),
        }
    }
}

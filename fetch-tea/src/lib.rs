//! # psmpa-fetch-tea: the Fetch Tea robot
//!
//! The robot of the paper's experiment, `missions/fetch-tea.json` (compiled in as
//! [`fetch_tea`]), on the drivers of `psmpa-drivers`: the file to copy for a robot of your own.
//! Its sensors and behaviours are a `match` on the mission's [`fetch_tea::Sensor`] and
//! [`fetch_tea::Action`]: a mission that gains one does not compile until this file handles
//! it.
//!
//! * `sonar` (a [`Ranger`]: an [`Hcsr04`] on a board, a simulated module in `psmpa-sim`;
//!   cyclic, 100 ms): [`Value::Mm`] to the nearest obstacle, or
//!   [`Value::NoEcho`] when nothing is in range; `path_clear` when nothing is within
//!   [`Settings::clearance_mm`]. How each outcome of a read becomes a sample, a lost sample or
//!   a fault: [`sonar_reading`].
//! * `bumper` ([`Switch`], cyclic, 20 ms, and at once on an edge: [`Sensor::wake`]):
//!   [`Value::Bool`] pressed; `path_clear` when not.
//! * `camera` ([`Marker`], once at the door): the reflectance sensor standing in for the
//!   paper's camera; `handle_seen` when the marker is in view.
//! * `handle` ([`Switch`], on demand): the limit switch the arm presses on the handle;
//!   `door_unlocked` when it is pressed (the handle gave way).
//! * "go to door", "go to back door" (walk, on the typed I/O of either: it reads the sonar and
//!   the bumper, which run beside both): dead reckoning, as the robot has no wheel
//!   encoders: it drives at [`Settings::walk_permille`], which moves it at
//!   [`Settings::walk_mm_s`] (measure it on your robot), for as long as
//!   [`Settings::walk_mm`] (to the kitchen door) or [`Settings::back_door_mm`] (from there on
//!   to the back door) takes at that speed. It brakes as soon as its precondition is false
//!   (the sonar sees something, the bumper is pressed). With [`Settings::avoid`] of 0 it
//!   waits and drives on when the precondition holds again; otherwise it steps around the
//!   obstacle ([`Settings::avoid`] long: it turns away, passes it, turns back to its heading)
//!   and drives on, taking a violation seen before the step's end (a bumper contact up to
//!   [`STEP_SETTLE`] after it) as the obstacle it passed. Braked and stepping time does not
//!   count, nor the time from a bumper read that found a contact to the brake (the obstacle
//!   held the wheels). Accurate to the speed's calibration and the braking distance.
//! * "open door": asks for a `handle` reading, stops if the door is locked, then pushes the
//!   door open: a timed drive. "open back door": the push alone (the mission runs no handle
//!   beside it).
//! * "enter kitchen", "enter by back door": a timed drive through the door.
//!
//! Each device sits behind its own mutex ([`CriticalSectionRawMutex`]): sensing runs on an
//! interrupt executor above deciding, so [`FetchTea`] is `Sync` (when its pins are `Send`),
//! and a slow sonar read (up to 38 ms) never holds up a bumper read. The motors sit behind a
//! blocking mutex, so [`Actuator::halt`] (not async) can always brake them.
//!
//! Putting it together (here with the test kit's pins standing in for a HAL's):
//!
//! ```
//! use psmpa_core::Config;
//! use psmpa_drivers::Active;
//! use psmpa_drivers::hbridge::{Channel, Drive};
//! use psmpa_drivers::hcsr04::Hcsr04;
//! use psmpa_drivers::marker::Marker;
//! use psmpa_fetch_tea::{Devices, FetchTea, FetchTeaRuntime, Settings, fetch_tea};
//! use psmpa_drivers::switch::{DEBOUNCE, Switch};
//! // On a Pico 2: embassy-rp's `Output`, `Input` and `PwmOutput`.
//! use psmpa_testkit::pins::{RecordedPin as Output, RecordedPwm as Pwm, ScriptedPin as Input};
//!
//! let motor = || Channel::new(Output::new(), Output::new(), Pwm::new(1_000));
//! let robot = FetchTea::new(
//!     Devices {
//!         sonar: Hcsr04::new(Output::new(), Input::constant(false)),
//!         bumper: Switch::new(Input::constant(true), Active::Low, DEBOUNCE),
//!         camera: Marker::new(Input::constant(false), Active::Low),
//!         handle: Switch::new(Input::constant(false), Active::Low, DEBOUNCE),
//!         wheels: Drive::with_standby(motor(), motor(), Output::new()),
//!     },
//!     Settings::DEFAULT,
//! );
//! let mut runtime = FetchTeaRuntime::new(fetch_tea::FetchTea, &robot, (), Config::default());
//! // On the board: the sensing side's `run()` in a task on an interrupt executor, the
//! // deciding side's in a task on the thread-mode one.
//! let (sensing, deciding) = runtime.split();
//! # let _ = (sensing, deciding);
//! ```

#![no_std]
#![deny(missing_docs)]
#![forbid(unsafe_code)]
#![cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::indexing_slicing,
        clippy::unreachable,
        clippy::todo,
        clippy::unimplemented,
        clippy::arithmetic_side_effects
    )
)]

use core::cell::{Cell, RefCell};

use embassy_sync::blocking_mutex::Mutex as BlockingMutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::mutex::Mutex;
use embassy_time::{Duration, Instant, TICK_HZ, Timer};
use embedded_hal::digital::{InputPin, OutputPin};
use embedded_hal_async::digital::Wait;
use psmpa_core::planner::{Planner, Search, Strategy};
use psmpa_core::{Act, Actuator, Beside, Outcome, Platform, Reading, Sensor, SensorFault, Value};

use psmpa_drivers::PinError;
use psmpa_drivers::hbridge::{Drive, FULL, Motor};
#[cfg(doc)]
use psmpa_drivers::hcsr04::Hcsr04;
use psmpa_drivers::hcsr04::{Hcsr04Error, Range, Ranger};
use psmpa_drivers::marker::Marker;
use psmpa_drivers::switch::Switch;

// `missions/fetch-tea.json` here is a link to the project's, so that the published crate
// carries the file.
psmpa_core::include_mission!(
    /// The Fetch Tea mission, compiled in: checked when the crate builds, a type with no
    /// parsing at boot. 4 keys per data store (a reading and its pairs).
    pub mod fetch_tea = "missions/fetch-tea.json",
    keys = 4
);

/// The runtime of robot `P` (a [`FetchTea`]), tracing into `T`.
pub type FetchTeaRuntime<'r, P, T = ()> = fetch_tea::Runtime<'r, P, T>;

/// The planner the robot's control loop falls back on when no library plan applies (a locked
/// kitchen door: `run_planning(&PLANNER, space)`): shortest plans, 32 nodes. The Fetch Tea
/// actions add and delete five facts, so at most 2⁵ = 32 states are reachable and a
/// breadth-first search, which stores each state once, cannot run out.
pub const PLANNER: Planner<32> = Planner::new(Strategy::BreadthFirst);

/// The space [`PLANNER`] searches in (about 1 KiB): a `static` on a microcontroller.
pub type PlannerSpace = Search<32>;

/// After a side step, switch readings taken this soon still show the obstacle it went around
/// (a bump switch reads open within two debounce times; its bounces end within one): the walk
/// takes them for that one. A sonar reading that comes after the step sees what is there.
pub const STEP_SETTLE: Duration =
    Duration::from_ticks(psmpa_drivers::switch::DEBOUNCE.as_ticks() * 2);

/// [`SensorFault::Device`] code: a pin reported an error.
pub const PIN_FAULT: u8 = 1;

/// The robot's own trace events (`TraceEvent::User`'s codes), for a reader of its trace.
pub mod codes {
    /// The walk stopped for an obstacle and started a side step (value: the sonar's fresh
    /// reading, mm, or 0 when another sensor showed it).
    pub const AVOID: u16 = 1;
    /// The side step ended and the walk resumed.
    pub const RESUME: u16 = 2;
    /// The door handle did not give: the door is locked.
    pub const LOCKED: u16 = 3;
}

/// How far the robot drives ahead, mm, while its sonar keeps one distance before the sonar is
/// stuck: 5 cm, 0.2 s at the board's calibrated speed.
pub const STUCK_AFTER_MM: u32 = 50;

/// How close to its goal a walk ends, mm: the odometer counts wheel time, and a walk within
/// this of its goal is done (the world docks a robot within 20 mm of a door). The driving a
/// processor's own work takes from an act phase (a tick or two each time the wheels start)
/// then cannot decide alone whether the walk ends in this phase or the next.
pub const ARRIVE_WITHIN_MM: u32 = 2;

/// The robot's measurements and timings. A board keeps them in a calibration record in
/// flash ([`Settings::to_record`], [`Settings::from_record`]), so that a robot is calibrated
/// (and a bench sets up its world) without building the firmware again.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Settings {
    /// The path is clear when the sonar sees nothing within this, mm.
    pub clearance_mm: u16,
    /// The walk to the kitchen door, mm.
    pub walk_mm: u32,
    /// The walking duty, thousandths.
    pub walk_permille: i16,
    /// The speed that duty gives, mm/s (measured: time a run over a known distance).
    pub walk_mm_s: u32,
    /// The duty that pushes a door open, thousandths.
    pub push_permille: i16,
    /// How long pushing a door open takes.
    pub push: Duration,
    /// The duty through the door, thousandths.
    pub enter_permille: i16,
    /// How long going through the door takes.
    pub enter: Duration,
    /// Processor time the walk spends planning its way each time it starts or resumes
    /// driving (through [`FetchTea::with_compute`]; none by default): a robot's path planner,
    /// computing on the deciding side while the sensors keep sampling.
    pub plan: Duration,
    /// The sonar's sampling period, if not the mission's.
    pub sonar_period: Option<Duration>,
    /// The bumper's sampling period, if not the mission's.
    pub bumper_period: Option<Duration>,
    /// How long a side step around an obstacle takes (a quarter turning away at the walking
    /// duty, a half passing, a quarter turning back); 0: no side step, the walk waits for
    /// the path to clear.
    pub avoid: Duration,
    /// The longest the sonar's module may take to raise its echo after a trigger, if longer
    /// than its driver's [`RISE_TIMEOUT`](psmpa_drivers::hcsr04::RISE_TIMEOUT) (a module that answers
    /// later); 0: that.
    pub sonar_rise: Duration,
    /// The walk from the kitchen door on to the back door, mm: "go to back door", past a
    /// locked kitchen door.
    pub back_door_mm: u32,
}

/// Words in a calibration record: [`RECORD_MAGIC`], [`RECORD_VERSION`], the 14 settings, a
/// CRC-32 of the rest.
pub const RECORD_WORDS: usize = 17;
/// A calibration record's first word: `PSMC` in little-endian bytes.
pub const RECORD_MAGIC: u32 = u32::from_le_bytes(*b"PSMC");
/// The layout of the calibration record this crate reads and writes.
pub const RECORD_VERSION: u32 = 3;

/// Why a calibration record was not taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RecordError {
    /// No record: the words are erased flash (all ones) or zeros.
    Blank,
    /// The first word is not [`RECORD_MAGIC`].
    Magic,
    /// A record of another layout (its version).
    Version(u32),
    /// The CRC-32 does not match: the record is damaged.
    Checksum,
    /// A setting out of its range: the walking speed is 0, a duty beyond full, a period of 0.
    Invalid,
}

impl core::fmt::Display for RecordError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Blank => f.write_str("no calibration record"),
            Self::Magic => f.write_str("not a calibration record (bad magic)"),
            Self::Version(v) => write!(
                f,
                "a calibration record of version {v}, this firmware reads version {RECORD_VERSION}"
            ),
            Self::Checksum => f.write_str("the calibration record is damaged (CRC-32)"),
            Self::Invalid => f.write_str("the calibration record holds a setting out of range"),
        }
    }
}

#[cfg(feature = "defmt")]
impl defmt::Format for RecordError {
    fn format(&self, f: defmt::Formatter<'_>) {
        match self {
            Self::Blank => defmt::write!(f, "no calibration record"),
            Self::Magic => defmt::write!(f, "not a calibration record (bad magic)"),
            Self::Version(v) => defmt::write!(
                f,
                "a calibration record of version {=u32}, this firmware reads version {=u32}",
                v,
                RECORD_VERSION
            ),
            Self::Checksum => defmt::write!(f, "the calibration record is damaged (CRC-32)"),
            Self::Invalid => {
                defmt::write!(f, "the calibration record holds a setting out of range")
            }
        }
    }
}

/// CRC-32 (IEEE 802.3, as zlib's) of `words` in little-endian bytes. Bitwise: 8 steps a
/// byte, no table in flash.
pub fn crc32(words: &[u32]) -> u32 {
    let mut crc = u32::MAX;
    for byte in words.iter().flat_map(|w| w.to_le_bytes()) {
        crc ^= u32::from(byte);
        for _ in 0..8 {
            let mask = (crc & 1).wrapping_neg();
            crc = (crc >> 1) ^ (0xEDB8_8320 & mask);
        }
    }
    !crc
}

impl Settings {
    /// 300 mm clearance; a 2 m walk at 600 ‰, 250 mm/s (8 s); pushing at 300 ‰ for 1.5 s;
    /// entering at 500 ‰ for 3 s; no planning time; the mission's periods; no side step; the
    /// sonar driver's own rise timeout; the back door 2 m past the kitchen door.
    pub const DEFAULT: Self = Self {
        clearance_mm: 300,
        walk_mm: 2_000,
        walk_permille: 600,
        walk_mm_s: 250,
        push_permille: 300,
        push: Duration::from_millis(1_500),
        enter_permille: 500,
        enter: Duration::from_millis(3_000),
        plan: Duration::from_ticks(0),
        sonar_period: None,
        bumper_period: None,
        avoid: Duration::from_ticks(0),
        sonar_rise: Duration::from_ticks(0),
        back_door_mm: 2_000,
    };

    /// How long the walk to the kitchen door drives: `walk_mm / walk_mm_s`, rounded up to the
    /// millisecond; `None` for a speed of 0.
    pub fn walk_time(&self) -> Option<Duration> {
        self.drive_time(self.walk_mm)
    }

    /// How long the walk from the kitchen door to the back door drives: `back_door_mm /
    /// walk_mm_s`, as [`walk_time`](Self::walk_time).
    pub fn back_door_time(&self) -> Option<Duration> {
        self.drive_time(self.back_door_mm)
    }

    /// How long driving `mm` at the walking speed takes, rounded up to the millisecond.
    fn drive_time(&self, mm: u32) -> Option<Duration> {
        let ms = u64::from(mm)
            .saturating_mul(1_000)
            .checked_next_multiple_of(u64::from(self.walk_mm_s))?
            .checked_div(u64::from(self.walk_mm_s))?;
        Some(Duration::from_millis(ms))
    }

    /// The settings as a calibration record: durations in whole milliseconds (the planning
    /// time in microseconds), a period of 0 for the mission's, duties as two's complement.
    pub fn to_record(&self) -> [u32; RECORD_WORDS] {
        let ms = |d: Duration| u32::try_from(d.as_millis()).unwrap_or(u32::MAX);
        let period = |p: Option<Duration>| p.map_or(0, ms);
        let duty = |d: i16| i32::from(d) as u32;
        let mut r = [
            RECORD_MAGIC,
            RECORD_VERSION,
            u32::from(self.clearance_mm),
            self.walk_mm,
            duty(self.walk_permille),
            self.walk_mm_s,
            duty(self.push_permille),
            ms(self.push),
            duty(self.enter_permille),
            ms(self.enter),
            u32::try_from(self.plan.as_micros()).unwrap_or(u32::MAX),
            period(self.sonar_period),
            period(self.bumper_period),
            ms(self.avoid),
            ms(self.sonar_rise),
            self.back_door_mm,
            0,
        ];
        let (body, sum) = r.split_at_mut(RECORD_WORDS - 1);
        if let Some(sum) = sum.first_mut() {
            *sum = crc32(body);
        }
        r
    }

    /// The settings a calibration record holds, checked: its magic, version and CRC-32, and
    /// each setting's range (a walking speed above 0, duties within ±1,000 ‰, periods above
    /// 0).
    pub fn from_record(r: &[u32; RECORD_WORDS]) -> Result<Self, RecordError> {
        if r.iter().all(|w| *w == u32::MAX) || r.iter().all(|w| *w == 0) {
            return Err(RecordError::Blank);
        }
        let [
            magic,
            version,
            clearance,
            walk_mm,
            walk_permille,
            walk_mm_s,
            push_permille,
            push_ms,
            enter_permille,
            enter_ms,
            plan_us,
            sonar_ms,
            bumper_ms,
            avoid_ms,
            rise_ms,
            back_door_mm,
            sum,
        ] = *r;
        if magic != RECORD_MAGIC {
            return Err(RecordError::Magic);
        }
        if version != RECORD_VERSION {
            return Err(RecordError::Version(version));
        }
        if r.get(..RECORD_WORDS - 1).map(crc32) != Some(sum) {
            return Err(RecordError::Checksum);
        }
        let duty = |w: u32| {
            i16::try_from(w as i32)
                .ok()
                .filter(|d| d.unsigned_abs() <= FULL.unsigned_abs())
                .ok_or(RecordError::Invalid)
        };
        let period = |ms: u32| (ms > 0).then(|| Duration::from_millis(u64::from(ms)));
        let settings = Self {
            clearance_mm: u16::try_from(clearance).map_err(|_| RecordError::Invalid)?,
            walk_mm,
            walk_permille: duty(walk_permille)?,
            walk_mm_s,
            push_permille: duty(push_permille)?,
            push: Duration::from_millis(u64::from(push_ms)),
            enter_permille: duty(enter_permille)?,
            enter: Duration::from_millis(u64::from(enter_ms)),
            plan: Duration::from_micros(u64::from(plan_us)),
            sonar_period: period(sonar_ms),
            bumper_period: period(bumper_ms),
            avoid: Duration::from_millis(u64::from(avoid_ms)),
            sonar_rise: Duration::from_millis(u64::from(rise_ms)),
            back_door_mm,
        };
        if walk_mm_s == 0 {
            return Err(RecordError::Invalid);
        }
        Ok(settings)
    }
}

impl Default for Settings {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// How one sonar read becomes a sample for the runtime:
///
/// | read | sample |
/// |---|---|
/// | [`Range::Mm`] | [`Value::Mm`]; `path_clear` when farther than `clearance_mm` |
/// | [`Range::NothingInRange`] (the 38 ms no-echo pulse, or beyond 4 m) | [`Value::NoEcho`]; `path_clear` |
/// | [`Hcsr04Error::NoEcho`], [`Hcsr04Error::Busy`] | `Ok(None)`: a lost sample; the runtime keeps the last belief and faults the sonar ([`SensorFault::Silent`]) after `Config::max_lost` in a row |
/// | [`Hcsr04Error::OutOfRange`] (nearer than 20 mm) | [`SensorFault::OutOfRange`]: the sonar cannot tell, the runtime stops the walk |
/// | [`Hcsr04Error::Stuck`] | [`SensorFault::Stuck`] |
/// | [`Hcsr04Error::Pin`] | [`SensorFault::Device`]`(`[`PIN_FAULT`]`)` |
pub fn sonar_reading(
    read: Result<Range, Hcsr04Error>,
    clearance_mm: u16,
) -> Result<Option<Reading>, SensorFault> {
    match read {
        Ok(Range::Mm(mm)) => Ok(Some(Reading::of(
            Value::Mm(i32::from(mm)),
            mm > clearance_mm,
        ))),
        Ok(Range::NothingInRange) => Ok(Some(Reading::of(Value::NoEcho, true))),
        Err(Hcsr04Error::NoEcho | Hcsr04Error::Busy) => Ok(None),
        Err(Hcsr04Error::OutOfRange) => Err(SensorFault::OutOfRange),
        Err(Hcsr04Error::Stuck) => Err(SensorFault::Stuck),
        Err(Hcsr04Error::Pin) => Err(SensorFault::Device(PIN_FAULT)),
    }
}

/// The robot's devices, for [`FetchTea::new`].
#[derive(Debug)]
pub struct Devices<So, Bu, Ca, Ha, Wh> {
    /// The ultrasonic ranger (a [`Ranger`]: an [`Hcsr04`]).
    pub sonar: So,
    /// The bump switch ([`Switch`]).
    pub bumper: Bu,
    /// The marker sensor ([`Marker`]).
    pub camera: Ca,
    /// The handle's limit switch ([`Switch`]).
    pub handle: Ha,
    /// The wheels ([`Drive`]).
    pub wheels: Wh,
}

/// The Fetch Tea robot: its devices. Implements [`Sensor`],
/// [`Actuator`] and [`Platform`] when the devices are this crate's drivers:
/// `FetchTea<impl Ranger, Switch<_>, Marker<_>, Switch<_>, Drive<_, _, _>>` (the sonar an
/// [`Hcsr04`] on a board).
pub struct FetchTea<So, Bu, Ca, Ha, Wh, Pc = ()> {
    settings: Settings,
    sonar: Mutex<CriticalSectionRawMutex, So>,
    bumper: Mutex<CriticalSectionRawMutex, Bu>,
    camera: Mutex<CriticalSectionRawMutex, Ca>,
    handle: Mutex<CriticalSectionRawMutex, Ha>,
    wheels: BlockingMutex<CriticalSectionRawMutex, RefCell<Wh>>,
    /// What the wheels were told, and the time SMPA's sense phases held them.
    pause: BlockingMutex<CriticalSectionRawMutex, Cell<Pause>>,
    /// Spends [`Settings::plan`] of processor time.
    compute: Pc,
}

/// The wheels' last drive command, and the sense phases that held them (SMPA only: under
/// P-SMPA nothing holds the robot).
#[derive(Clone, Copy, Debug, Default)]
struct Pause {
    /// The wheels' drive command (left, right) while they drive.
    driving: Option<(i16, i16)>,
    /// When the current hold began.
    since: Option<Instant>,
    /// Ticks held in all, the current hold's aside.
    total: u64,
    /// The odometer: thousandths of full duty times ticks the wheels drove straight ahead,
    /// the current stretch's aside.
    odometer: u64,
    /// The current straight stretch ahead: since when, at which duty.
    ahead: Option<(Instant, i16)>,
    /// The sonar's last reading in range and the odometer (its units) when it was first read.
    echo: Option<(u16, u64)>,
    /// A side step is under way: its legs carry the robot around what is ahead, not towards
    /// it, and do not count on the odometer.
    stepping: bool,
}

impl Pause {
    /// The odometer now, the current stretch's part included.
    fn odometer_now(&self) -> u64 {
        let now = self.ahead.map_or(0, |(since, duty)| {
            let ticks = Instant::now().saturating_duration_since(since).as_ticks();
            ticks.saturating_mul(u64::from(duty.unsigned_abs()))
        });
        self.odometer.saturating_add(now)
    }

    /// Ends the current straight stretch ahead at `now` and starts one at `duty` if the
    /// wheels now drive straight ahead.
    fn moving(&mut self, now: Instant, command: Option<(i16, i16)>) {
        if let Some((since, duty)) = self.ahead.take() {
            let ticks = now.saturating_duration_since(since).as_ticks();
            let run = ticks.saturating_mul(u64::from(duty.unsigned_abs()));
            self.odometer = self.odometer.saturating_add(run);
        }
        self.ahead = command
            .filter(|&(left, right)| !self.stepping && left == right && left > 0)
            .map(|(duty, _)| (now, duty));
    }
}

/// Processor work: what a walk's planning costs ([`Settings::plan`]). `()` does none (on the
/// host, in virtual time, planning takes no time); a board busy-waits (a stand-in for a path
/// planner's computing). Static dispatch: a call through a pointer would be one the stack
/// analysis must assume may go anywhere.
pub trait Compute {
    /// Computes for `time`.
    fn compute(&self, time: Duration);
}

impl Compute for () {
    fn compute(&self, _: Duration) {}
}

impl<So, Bu, Ca, Ha, Wh> FetchTea<So, Bu, Ca, Ha, Wh> {
    /// The robot with `devices` and `settings`.
    pub fn new(devices: Devices<So, Bu, Ca, Ha, Wh>, settings: Settings) -> Self {
        let Devices {
            sonar,
            bumper,
            camera,
            handle,
            wheels,
        } = devices;
        Self {
            settings,
            sonar: Mutex::new(sonar),
            bumper: Mutex::new(bumper),
            camera: Mutex::new(camera),
            handle: Mutex::new(handle),
            wheels: BlockingMutex::new(RefCell::new(wheels)),
            pause: BlockingMutex::new(Cell::new(Pause {
                driving: None,
                since: None,
                total: 0,
                odometer: 0,
                ahead: None,
                echo: None,
                stepping: false,
            })),
            compute: (),
        }
    }

    /// The robot, spending [`Settings::plan`] through `compute` each time a walk starts or
    /// resumes driving: on a board, a busy wait of that long (`embassy_time::block_for`), the
    /// stand-in for a path planner. Without it (on the host, in virtual time) planning takes
    /// no time.
    pub fn with_compute<Pc: Compute>(self, compute: Pc) -> FetchTea<So, Bu, Ca, Ha, Wh, Pc> {
        FetchTea {
            settings: self.settings,
            sonar: self.sonar,
            bumper: self.bumper,
            camera: self.camera,
            handle: self.handle,
            wheels: self.wheels,
            pause: self.pause,
            compute,
        }
    }
}

impl<So, Bu, Ca, Ha, Wh, Pc> FetchTea<So, Bu, Ca, Ha, Wh, Pc> {
    /// The settings.
    pub const fn settings(&self) -> &Settings {
        &self.settings
    }

    /// Runs `change` on the wheels' record ([`Pause`]) under its lock, and keeps it.
    fn pause<T>(&self, change: impl FnOnce(&mut Pause) -> T) -> T {
        self.pause.lock(|p| {
            let mut pause = p.get();
            let out = change(&mut pause);
            p.set(pause);
            out
        })
    }

    /// Notes the sonar's reading (`None`: nothing in range, or switched on); whether it is
    /// stuck: an echo in range that keeps one distance while the wheels carry the robot
    /// [`STUCK_AFTER_MM`] on, the sonar on all along. (One stuck at "nothing in range" cannot
    /// be told from an empty path; nor, under SMPA, one that sticks while the wheels are held.)
    fn echo(&self, mm: Option<u16>) -> bool {
        self.pause(|pause| {
            let at = pause.odometer_now();
            match (pause.echo, mm) {
                (Some((last, since)), Some(mm)) if last == mm => {
                    // The odometer's units (ticks times duty) against the distance, both
                    // sides multiplied out: no division on the sampling path.
                    let s = &self.settings;
                    let driven = at
                        .saturating_sub(since)
                        .saturating_mul(u64::from(s.walk_mm_s));
                    let limit = u64::from(STUCK_AFTER_MM)
                        .saturating_mul(u64::from(s.walk_permille.unsigned_abs()))
                        .saturating_mul(TICK_HZ);
                    driven >= limit
                }
                _ => {
                    pause.echo = mm.map(|mm| (mm, at));
                    false
                }
            }
        })
    }
}

impl<So, B, C, H, Wh, Pc> Sensor<fetch_tea::FetchTea>
    for FetchTea<So, Switch<B>, Marker<C>, Switch<H>, Wh, Pc>
where
    So: Ranger,
    B: InputPin + Wait,
    C: InputPin,
    H: InputPin + Wait,
{
    async fn switch_on(&self, sensor: fetch_tea::Sensor) -> Result<(), SensorFault> {
        if sensor == fetch_tea::Sensor::Sonar {
            // What the echo did before the sonar was off says nothing about it now: under SMPA
            // the robot drives between sense phases, and the next obstacle, as far ahead as
            // the last, echoes at the same distance.
            self.echo(None);
        }
        Ok(())
    }

    async fn switch_off(&self, _: fetch_tea::Sensor) {}

    async fn sample(&self, sensor: fetch_tea::Sensor) -> Result<Option<Reading>, SensorFault> {
        use fetch_tea::Sensor::{Bumper, Camera, Handle, Sonar};
        let pin = |_: PinError| SensorFault::Device(PIN_FAULT);
        let reading = match sensor {
            Sonar => {
                let read = self.sonar.lock().await.measure().await;
                if let Ok(range) = read {
                    let mm = match range {
                        Range::Mm(mm) => Some(mm),
                        Range::NothingInRange => None,
                    };
                    if self.echo(mm) {
                        return Err(SensorFault::Stuck);
                    }
                }
                return sonar_reading(read, self.settings.clearance_mm);
            }
            Bumper => {
                let pressed = self.bumper.lock().await.pressed().await.map_err(pin)?;
                Reading::of(Value::Bool(pressed), !pressed)
            }
            Camera => Reading::flag(self.camera.lock().await.seen().map_err(pin)?),
            // Read on demand, once: a bounce must not pass for the state.
            Handle => Reading::flag(self.handle.lock().await.settled().await.map_err(pin)?),
        };
        Ok(Some(reading))
    }

    /// The bumper's next edge (a contact, a release, a bounce) makes its next sample due at
    /// once: the read debounces it, and a contact is seen the debounce time after the switch
    /// settles, not a period later. At most one such sample a debounce time ([`Switch::edge`]):
    /// a noisy wire cannot flood the sensing side. The runtime drops this future before it
    /// samples, so the lock it holds never keeps a read waiting. A pin error never wakes (the
    /// periodic reads report it).
    async fn wake(&self, sensor: fetch_tea::Sensor) {
        if sensor == fetch_tea::Sensor::Bumper && self.bumper.lock().await.edge().await.is_ok() {
            return;
        }
        core::future::pending().await
    }
}

impl<So, Bu, Ca, Ha, L: Motor, R: Motor, S: OutputPin, Pc: Compute>
    FetchTea<So, Bu, Ca, Ha, Drive<L, R, S>, Pc>
{
    /// Runs `command` on the wheels.
    fn wheels(
        &self,
        command: impl FnOnce(&mut Drive<L, R, S>) -> Result<(), PinError>,
    ) -> Result<(), PinError> {
        // No command re-enters the lock, so the borrow always succeeds.
        self.wheels.lock(|w| {
            w.try_borrow_mut()
                .map_err(|_| PinError)
                .and_then(|mut w| command(&mut w))
        })
    }

    /// Drives the wheels at `left` and `right` (thousandths), unless a sense phase holds
    /// them (then they drive once it ends).
    fn drive(&self, left: i16, right: i16) -> Result<(), PinError> {
        let held = self.pause(|pause| {
            pause.driving = Some((left, right));
            pause.since.is_some()
        });
        if held {
            return Ok(());
        }
        let set = self.wheels(|w| w.drive(left, right));
        self.moved(Some((left, right)));
        set
    }

    /// Notes on the odometer that the wheels now run as `command` says, once their pins are
    /// written: the wheels change when the pins do.
    fn moved(&self, command: Option<(i16, i16)>) {
        self.pause(|pause| pause.moving(Instant::now(), command));
    }

    /// Brakes the wheels.
    fn brake(&self) -> Result<(), PinError> {
        self.pause(|pause| pause.driving = None);
        let set = self.wheels(Drive::brake);
        self.moved(None);
        set
    }

    /// Starts or ends a side step.
    fn stepping(&self, stepping: bool) {
        self.pause(|pause| pause.stepping = stepping);
    }

    /// How long the wheels have driven straight ahead, at the walking duty: the odometer, in
    /// ticks. Counted from the wheels' own commands, it leaves out the held (SMPA), turning
    /// and braking times exactly, whenever the walk looks at it.
    fn driven(&self) -> u64 {
        if let Some(um) = self.rolled_um() {
            // An encoder: the distance rolled, as the ticks it takes at the calibrated speed.
            let per = u64::from(self.settings.walk_mm_s).saturating_mul(1_000);
            return um.saturating_mul(TICK_HZ).checked_div(per).unwrap_or(0);
        }
        let run = self.pause.lock(|p| p.get().odometer_now());
        run.checked_div(u64::from(self.settings.walk_permille.unsigned_abs()))
            .unwrap_or(0)
    }

    /// How far the wheels' encoder says the robot has rolled, µm: `None` without one.
    fn rolled_um(&self) -> Option<u64> {
        self.wheels
            .lock(|w| w.try_borrow().ok().and_then(|w| w.rolled_um()))
    }

    /// The time SMPA's sense phases have held the robot so far (0 under P-SMPA).
    fn paused(&self) -> Duration {
        let pause = self.pause.lock(Cell::get);
        let now = pause.since.map_or(0, |s| {
            Instant::now().saturating_duration_since(s).as_ticks()
        });
        Duration::from_ticks(pause.total.saturating_add(now))
    }

    /// Waits until the wheels have had `time` to drive: a sense phase that holds them
    /// meanwhile does not count.
    async fn drive_for(&self, time: Duration) {
        let mut left = time;
        while left.as_ticks() > 0 {
            let (start, paused) = (Instant::now(), self.paused());
            Timer::after(left).await;
            let ran = Instant::now()
                .saturating_duration_since(start)
                .checked_sub(self.paused().checked_sub(paused).unwrap_or_default())
                .unwrap_or_default();
            left = left.checked_sub(ran).unwrap_or(Duration::from_ticks(0));
        }
    }

    /// Brakes, and ends with `outcome` (a failure if the brake failed).
    fn stop(&self, outcome: Outcome) -> Outcome {
        match self.brake() {
            Ok(()) => outcome,
            Err(PinError) => Outcome::Failure,
        }
    }

    /// Drives straight at `permille` for `time`, then brakes.
    async fn timed(&self, permille: i16, time: Duration) -> Outcome {
        if self.drive(permille, permille).is_err() {
            return self.stop(Outcome::Failure);
        }
        self.drive_for(time).await;
        self.stop(Outcome::Success)
    }

    /// Steps around an obstacle: turns away, passes it and turns back to its heading, at the
    /// walking duty, [`Settings::avoid`] in all; then brakes.
    async fn side_step(&self) -> Result<(), PinError> {
        let (d, back) = (
            self.settings.walk_permille,
            self.settings.walk_permille.saturating_neg(),
        );
        let all = self.settings.avoid.as_ticks();
        let turn = all.checked_div(4).unwrap_or(0);
        let pass = all.saturating_sub(turn.saturating_mul(2));
        self.stepping(true);
        for (left, right, ticks) in [(back, d, turn), (d, d, pass), (d, back, turn)] {
            if let Err(e) = self.drive(left, right) {
                self.stepping(false);
                return Err(e);
            }
            self.drive_for(Duration::from_ticks(ticks)).await;
        }
        self.stepping(false);
        self.brake()
    }

    /// Drives for `time` (a walk's, `None` for a speed of 0), braking while the precondition
    /// is false, or stepping around what made it false ([`Settings::avoid`]); each time it
    /// starts or resumes driving it first plans its way ([`Settings::plan`]). The wheels are
    /// written only when the robot starts or stops, not on every sample. Any action beside
    /// which the sonar and the bumper run ("go to door", "go to back door").
    async fn walk<A>(&self, time: Option<Duration>, io: &fetch_tea::Io<'_, A>) -> Outcome
    where
        A: Beside<fetch_tea::sensor::Sonar> + Beside<fetch_tea::sensor::Bumper>,
    {
        use fetch_tea::sensor::{Bumper, Sonar};
        let Some(time) = time else {
            return Outcome::Failure;
        };
        let duty = self.settings.walk_permille;
        // The driving the walk needs, less what it may end short by.
        let within = ARRIVE_WITHIN_MM
            .saturating_mul(u32::try_from(TICK_HZ).unwrap_or(u32::MAX))
            .checked_div(self.settings.walk_mm_s)
            .unwrap_or(0);
        let goal = time.as_ticks().saturating_sub(u64::from(within));
        // The odometer when the walk began, and the driving that did not move the robot: the
        // wheels pushing against what the bumper touched.
        let (base, mut blocked) = (self.driven(), 0u64);
        let mut version = io.version();
        let mut moving = None;
        // When the last side step ended: a violation last seen before it (and a contact
        // before the bumper settled) is the obstacle it went around.
        let mut passed = Instant::from_ticks(0);
        // The sonar's last reading when it ended: one after it sees what is there now.
        let mut stepped_sonar = None;
        loop {
            // The sonar's own reading shows the obstacle (its threshold, decided by the
            // reading), and it is one taken after the last side step.
            let fresh = io
                .sample(Sonar)
                .is_some_and(|e| stepped_sonar.is_none_or(|at| e.at > at));
            let violation = io.violation().filter(|v| {
                (fresh && v.seen_by(fetch_tea::Sensor::Sonar))
                    || v.last_seen >= passed.saturating_add(STEP_SETTLE)
            });
            let go = violation.is_none();
            if moving != Some(go) {
                let set = if go {
                    if self.settings.plan.as_ticks() > 0 {
                        self.compute.compute(self.settings.plan);
                    }
                    self.drive(duty, duty)
                } else {
                    // The precondition turned false: brake at once.
                    self.brake()
                };
                if set.is_err() {
                    return self.stop(Outcome::Failure);
                }
                moving = Some(go);
            }
            if !go && self.settings.avoid.as_ticks() > 0 {
                let mm = match io.sample(Sonar).map(|e| e.value) {
                    Some(Value::Mm(mm)) if fresh => mm,
                    _ => 0,
                };
                io.trace(codes::AVOID, mm);
                if self.side_step().await.is_err() {
                    return self.stop(Outcome::Failure);
                }
                io.trace(codes::RESUME, 0);
                passed = Instant::now();
                stepped_sonar = io.sample(Sonar).map(|e| e.at);
                version = io.version();
                continue;
            }
            let (since, start) = (Instant::now(), self.driven());
            let left = goal.saturating_sub(start.saturating_sub(base).saturating_sub(blocked));
            let arrival = go.then(|| since.saturating_add(Duration::from_ticks(left)));
            let changed = if left == 0 {
                None
            } else {
                io.changed_until(version, arrival).await
            };
            if go && self.rolled_um().is_none() {
                // Wheels held by what the bumper touched do not move the robot: a contact
                // read since this stretch began ends its driving at the read's instant (an
                // encoder counts only what the wheels rolled).
                if let Some(at) = io
                    .sample(Bumper)
                    .filter(|e| e.value == Value::Bool(true) && e.at >= since)
                    .map(|e| e.at)
                {
                    let after = Instant::now().saturating_duration_since(at).as_ticks();
                    let ran = self.driven().saturating_sub(start);
                    blocked = blocked.saturating_add(after.min(ran));
                }
            }
            let driven = self.driven().saturating_sub(base).saturating_sub(blocked);
            if driven >= goal {
                return self.stop(Outcome::Success);
            }
            if let Some(v) = changed {
                version = v;
            }
        }
    }

    /// Asks the handle's limit switch whether the handle gave (an on-demand `handle` reading,
    /// taken once it settles) and pushes the door open if it did.
    async fn open_door(&self, io: &fetch_tea::Io<'_, fetch_tea::action::OpenDoor>) -> Outcome {
        let handle = fetch_tea::sensor::Handle;
        let asked = Instant::now();
        io.request(handle);
        let mut version = io.version();
        while io.sample(handle).is_none_or(|e| e.at < asked) {
            version = io.changed(version).await;
        }
        // Locked (or the marker is not in view): the precondition says which.
        if io.violation().is_some() {
            io.trace(codes::LOCKED, 0);
            return Outcome::Interrupted;
        }
        self.timed(self.settings.push_permille, self.settings.push)
            .await
    }
}

impl<So, Bu, Ca, Ha, L: Motor, R: Motor, S: OutputPin, Pc: Compute> Actuator<fetch_tea::FetchTea>
    for FetchTea<So, Bu, Ca, Ha, Drive<L, R, S>, Pc>
{
    async fn run(&self, act: Act<'_, fetch_tea::FetchTea>) -> Outcome {
        use fetch_tea::Run::{
            EnterByBackDoor, EnterKitchen, GoToBackDoor, GoToDoor, OpenBackDoor, OpenDoor,
        };
        match act.typed() {
            GoToDoor(io) => self.walk(self.settings.walk_time(), &io).await,
            GoToBackDoor(io) => self.walk(self.settings.back_door_time(), &io).await,
            OpenDoor(io) => self.open_door(&io).await,
            // No handle runs beside it (the mission's back door is never locked): a push.
            OpenBackDoor(_) => {
                let s = &self.settings;
                self.timed(s.push_permille, s.push).await
            }
            EnterKitchen(_) | EnterByBackDoor(_) => {
                let s = &self.settings;
                self.timed(s.enter_permille, s.enter).await
            }
        }
    }

    /// SMPA's sense phase: the wheels brake while it lasts and drive on as they were told
    /// when it ends; the time it held them does not count as driven.
    fn hold(&self, _: fetch_tea::Action, held: bool) {
        let resume = self.pause(|pause| {
            let now = Instant::now();
            match (held, pause.since) {
                (true, None) => pause.since = Some(now),
                (false, Some(since)) => {
                    pause.since = None;
                    let ticks = now.saturating_duration_since(since).as_ticks();
                    pause.total = pause.total.saturating_add(ticks);
                }
                _ => return None,
            }
            Some(pause.driving)
        });
        // Nothing more to do if a pin fails: the next command reports it.
        match (held, resume) {
            (true, Some(Some(_))) => {
                let _ = self.wheels(Drive::brake);
                self.moved(None);
            }
            (false, Some(Some((left, right)))) => {
                let _ = self.wheels(|w| w.drive(left, right));
                self.moved(Some((left, right)));
            }
            _ => {}
        }
    }

    fn halt(&self, _: fetch_tea::Action) {
        // Nothing more to do if even braking fails.
        let _ = self.brake();
    }
}

impl<So, Bu, Ca, Ha, Wh, Pc> Platform for FetchTea<So, Bu, Ca, Ha, Wh, Pc> {
    // Sensing runs on an interrupt executor above deciding.
    type Mutex = CriticalSectionRawMutex;
}

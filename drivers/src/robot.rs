//! The Fetch Tea robot of `missions/fetch-tea.json` ([`MISSION`]), on the drivers of this
//! crate: the file to copy for a robot of your own.
//!
//! * `sonar` ([`Hcsr04`], cyclic, 100 ms): [`Value::Mm`] to the nearest obstacle, or
//!   [`Value::NoEcho`] when nothing is in range; `path_clear` when nothing is within
//!   [`Settings::clearance_mm`]. How each outcome of a read becomes a sample, a lost sample or
//!   a fault: [`sonar_reading`].
//! * `bumper` ([`Switch`], cyclic, 20 ms, and at once on an edge: [`Sensor::wake`]):
//!   [`Value::Bool`] pressed; `path_clear` when not.
//! * `camera` ([`Marker`], once at the door): the reflectance sensor standing in for the
//!   paper's camera; `handle_seen` when the marker is in view.
//! * `handle` ([`Switch`], on demand): the limit switch the arm presses on the handle;
//!   `door_unlocked` when it is pressed (the handle gave way).
//! * "go to door", "go to back door" (walk): dead reckoning, as the robot has no wheel
//!   encoders: it drives at [`Settings::walk_permille`], which moves it at
//!   [`Settings::walk_mm_s`] (measure it on your robot), for as long as
//!   [`Settings::walk_mm`] takes at that speed. It brakes as soon as its precondition is false
//!   (the sonar sees something, the bumper is pressed) and drives on when it holds again;
//!   braked time does not count. Accurate to the speed's calibration and the braking distance.
//! * "open door", "open back door": asks for a `handle` reading (when the mission binds one),
//!   stops if the door is locked, then pushes the door open: a timed drive.
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
//! use psmpa_drivers::robot::{Devices, FetchTea, FetchTeaRuntime, Settings, mission};
//! use psmpa_drivers::switch::{DEBOUNCE, Switch};
//! // On a Pico 2: embassy-rp's `Output`, `Input` and `PwmOutput`.
//! use psmpa_testkit::pins::{RecordedPin as Output, RecordedPwm as Pwm, ScriptedPin as Input};
//!
//! let loaded = mission().unwrap();
//! let motor = || Channel::new(Output::new(), Output::new(), Pwm::new(1_000));
//! let robot = FetchTea::new(
//!     Devices {
//!         sonar: Hcsr04::new(Output::new(), Input::constant(false)),
//!         bumper: Switch::new(Input::constant(true), Active::Low, DEBOUNCE),
//!         camera: Marker::new(Input::constant(false), Active::Low),
//!         handle: Switch::new(Input::constant(false), Active::Low, DEBOUNCE),
//!         wheels: Drive::with_standby(motor(), motor(), Output::new()),
//!     },
//!     loaded.bindings.clone(),
//!     Settings::DEFAULT,
//! );
//! let runtime = FetchTeaRuntime::new(&loaded.mission, &robot, (), Config::default());
//! // On the board: `runtime.sensing()` in a task on an interrupt executor, `runtime.run()`
//! // in a task on the thread-mode one.
//! # let _ = runtime;
//! ```

use core::cell::RefCell;

use embassy_sync::blocking_mutex::Mutex as BlockingMutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::mutex::Mutex;
use embassy_time::{Duration, Instant, Timer};
use embedded_hal::digital::{InputPin, OutputPin};
use embedded_hal_async::digital::Wait;
use psmpa_core::mission::{LoadError, load};
use psmpa_core::{
    ActionId, ActionIo, Actuator, Bindings, Caps, LoadedOf, Outcome, Platform, Reading, Registry,
    Runtime, Sensor, SensorFault, SensorId, Value,
};

use crate::PinError;
use crate::hbridge::{Drive, Motor};
use crate::hcsr04::{Hcsr04, Hcsr04Error, Range};
use crate::marker::Marker;
use crate::switch::Switch;

/// The mission, as JSON.
pub const MISSION: &str = include_str!("../../missions/fetch-tea.json");

/// Capacities: 4 sensors, 8 actions, 4 plans of at most 6 actions, 4 keys per data store.
pub type FetchTeaCaps = Caps<4, 8, 4, 6, 4>;
/// Which [`Part`] and [`Motion`] each id of the mission is.
pub type Parts = Bindings<Part, Motion, 4, 8>;
/// The runtime of robot `P` (a [`FetchTea`]), tracing into `T`.
pub type FetchTeaRuntime<'r, P, T = ()> = Runtime<'r, P, FetchTeaCaps, T>;

/// [`SensorFault::Device`] code: a sensor id the mission does not bind.
pub const UNBOUND: u8 = 0;
/// [`SensorFault::Device`] code: a pin reported an error.
pub const PIN_FAULT: u8 = 1;

/// The sensors a mission may name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Part {
    /// The ultrasonic ranger.
    Sonar,
    /// The bump switch.
    Bumper,
    /// The marker sensor (the camera's stand-in).
    Camera,
    /// The limit switch the arm presses on the handle.
    Handle,
}

/// The behaviours a mission may name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Motion {
    /// Walk to a door.
    Walk,
    /// Open a door.
    OpenDoor,
    /// Go through an open door.
    Enter,
}

/// Binds the mission's names to [`Part`] and [`Motion`].
#[derive(Clone, Copy, Debug, Default)]
pub struct Names;

impl Registry for Names {
    type Sensor = Part;
    type Action = Motion;
    fn sensor(&self, name: &str) -> Option<Part> {
        Some(match name {
            "sonar" => Part::Sonar,
            "bumper" => Part::Bumper,
            "camera" => Part::Camera,
            "handle" => Part::Handle,
            _ => return None,
        })
    }
    fn action(&self, name: &str) -> Option<Motion> {
        Some(match name {
            "go to door" | "go to back door" => Motion::Walk,
            "open door" | "open back door" => Motion::OpenDoor,
            "enter kitchen" | "enter by back door" => Motion::Enter,
            _ => return None,
        })
    }
}

/// [`MISSION`], loaded and bound to [`Names`]. The result is large: on a microcontroller,
/// [`load_into`](psmpa_core::mission::load_into) statics instead.
pub fn mission() -> Result<LoadedOf<'static, Names, FetchTeaCaps>, LoadError<'static>> {
    load(MISSION.as_bytes(), &Names)
}

/// The robot's measurements and timings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Settings {
    /// The path is clear when the sonar sees nothing within this, mm.
    pub clearance_mm: u16,
    /// The walk to a door, mm.
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
}

impl Settings {
    /// 300 mm clearance; a 2 m walk at 600 ‰, 250 mm/s (8 s); pushing at 300 ‰ for 1.5 s;
    /// entering at 500 ‰ for 3 s.
    pub const DEFAULT: Self = Self {
        clearance_mm: 300,
        walk_mm: 2_000,
        walk_permille: 600,
        walk_mm_s: 250,
        push_permille: 300,
        push: Duration::from_millis(1_500),
        enter_permille: 500,
        enter: Duration::from_millis(3_000),
    };

    /// How long the walk drives: `walk_mm / walk_mm_s`, rounded up to the millisecond; `None`
    /// for a speed of 0.
    pub fn walk_time(&self) -> Option<Duration> {
        let ms = u64::from(self.walk_mm)
            .saturating_mul(1_000)
            .checked_next_multiple_of(u64::from(self.walk_mm_s))?
            .checked_div(u64::from(self.walk_mm_s))?;
        Some(Duration::from_millis(ms))
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
    /// The ultrasonic ranger ([`Hcsr04`]).
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

/// The Fetch Tea robot: its devices, bound to a mission's ids. Implements [`Sensor`],
/// [`Actuator`] and [`Platform`] when the devices are this crate's drivers:
/// `FetchTea<Hcsr04<_, _>, Switch<_>, Marker<_>, Switch<_>, Drive<_, _, _>>`.
pub struct FetchTea<So, Bu, Ca, Ha, Wh> {
    parts: Parts,
    settings: Settings,
    sonar: Mutex<CriticalSectionRawMutex, So>,
    bumper: Mutex<CriticalSectionRawMutex, Bu>,
    camera: Mutex<CriticalSectionRawMutex, Ca>,
    handle: Mutex<CriticalSectionRawMutex, Ha>,
    wheels: BlockingMutex<CriticalSectionRawMutex, RefCell<Wh>>,
}

impl<So, Bu, Ca, Ha, Wh> FetchTea<So, Bu, Ca, Ha, Wh> {
    /// The robot with `devices`, bound to a mission's ids by `parts` (from [`load`] or
    /// [`load_into`](psmpa_core::mission::load_into) with [`Names`]).
    pub fn new(devices: Devices<So, Bu, Ca, Ha, Wh>, parts: Parts, settings: Settings) -> Self {
        let Devices {
            sonar,
            bumper,
            camera,
            handle,
            wheels,
        } = devices;
        Self {
            parts,
            settings,
            sonar: Mutex::new(sonar),
            bumper: Mutex::new(bumper),
            camera: Mutex::new(camera),
            handle: Mutex::new(handle),
            wheels: BlockingMutex::new(RefCell::new(wheels)),
        }
    }

    /// The settings.
    pub const fn settings(&self) -> &Settings {
        &self.settings
    }
}

impl<T, E, B, C, H, Wh> Sensor for FetchTea<Hcsr04<T, E>, Switch<B>, Marker<C>, Switch<H>, Wh>
where
    T: OutputPin,
    E: InputPin + Wait,
    B: InputPin + Wait,
    C: InputPin,
    H: InputPin + Wait,
{
    async fn switch_on(&self, _: SensorId) -> Result<(), SensorFault> {
        Ok(())
    }

    async fn switch_off(&self, _: SensorId) {}

    async fn sample(&self, sensor: SensorId) -> Result<Option<Reading>, SensorFault> {
        let pin = |_: PinError| SensorFault::Device(PIN_FAULT);
        let reading = match self.parts.sensor(sensor) {
            Some(Part::Sonar) => {
                let read = self.sonar.lock().await.measure().await;
                return sonar_reading(read, self.settings.clearance_mm);
            }
            Some(Part::Bumper) => {
                let pressed = self.bumper.lock().await.pressed().await.map_err(pin)?;
                Reading::of(Value::Bool(pressed), !pressed)
            }
            Some(Part::Camera) => Reading::flag(self.camera.lock().await.seen().map_err(pin)?),
            // Read on demand, once: a bounce must not pass for the state.
            Some(Part::Handle) => {
                Reading::flag(self.handle.lock().await.settled().await.map_err(pin)?)
            }
            None => return Err(SensorFault::Device(UNBOUND)),
        };
        Ok(Some(reading))
    }

    /// The bumper's next edge (a contact, a release, a bounce) makes its next sample due at
    /// once: the read debounces it, and a contact is seen the debounce time after the switch
    /// settles, not a period later. At most one such sample a debounce time ([`Switch::edge`]):
    /// a noisy wire cannot flood the sensing side. The runtime drops this future before it
    /// samples, so the lock it holds never keeps a read waiting. A pin error never wakes (the
    /// periodic reads report it).
    async fn wake(&self, sensor: SensorId) {
        if self.parts.sensor(sensor) == Some(Part::Bumper)
            && self.bumper.lock().await.edge().await.is_ok()
        {
            return;
        }
        core::future::pending().await
    }
}

impl<So, Bu, Ca, Ha, L: Motor, R: Motor, S: OutputPin> FetchTea<So, Bu, Ca, Ha, Drive<L, R, S>> {
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

    /// Brakes, and ends with `outcome` (a failure if the brake failed).
    fn stop(&self, outcome: Outcome) -> Outcome {
        match self.wheels(Drive::brake) {
            Ok(()) => outcome,
            Err(PinError) => Outcome::Failure,
        }
    }

    /// Drives straight at `permille` for `time`, then brakes.
    async fn timed(&self, permille: i16, time: Duration) -> Outcome {
        if self.wheels(|w| w.drive(permille, permille)).is_err() {
            return self.stop(Outcome::Failure);
        }
        Timer::after(time).await;
        self.stop(Outcome::Success)
    }

    /// Drives for the walk's time, braking while the precondition is false. The wheels are
    /// written only when the robot starts or stops, not on every sample.
    async fn walk(&self, io: &ActionIo<'_>) -> Outcome {
        let Some(mut left) = self.settings.walk_time() else {
            return Outcome::Failure;
        };
        let duty = self.settings.walk_permille;
        let mut version = io.version();
        let mut moving = None;
        loop {
            let go = io.violation().is_none();
            if moving != Some(go) {
                let set = if go {
                    self.wheels(|w| w.drive(duty, duty))
                } else {
                    self.wheels(Drive::brake)
                };
                if set.is_err() {
                    return self.stop(Outcome::Failure);
                }
                moving = Some(go);
            }
            let since = Instant::now();
            let arrival = go.then(|| since.saturating_add(left));
            let changed = io.changed_until(version, arrival).await;
            if go {
                let driven = Instant::now().saturating_duration_since(since);
                left = left.checked_sub(driven).unwrap_or(Duration::from_ticks(0));
            }
            if left.as_ticks() == 0 {
                return self.stop(Outcome::Success);
            }
            if let Some(v) = changed {
                version = v;
            }
        }
    }

    /// Asks the handle's limit switch whether the handle gave (an on-demand `handle` reading,
    /// taken once it settles) and pushes the door open if it did.
    async fn open_door(&self, io: &ActionIo<'_>) -> Outcome {
        if let Some(handle) = self.parts.sensor_id(&Part::Handle) {
            let asked = Instant::now();
            io.request(handle);
            let mut version = io.version();
            while io.sample(handle).is_none_or(|e| e.at < asked) {
                version = io.changed(version).await;
            }
            // Locked (or the marker is not in view): the precondition says which.
            if io.violation().is_some() {
                return Outcome::Interrupted;
            }
        }
        self.timed(self.settings.push_permille, self.settings.push)
            .await
    }
}

impl<So, Bu, Ca, Ha, L: Motor, R: Motor, S: OutputPin> Actuator
    for FetchTea<So, Bu, Ca, Ha, Drive<L, R, S>>
{
    async fn run(&self, action: ActionId, io: &ActionIo<'_>) -> Outcome {
        match self.parts.action(action) {
            Some(Motion::Walk) => self.walk(io).await,
            Some(Motion::OpenDoor) => self.open_door(io).await,
            Some(Motion::Enter) => {
                let s = &self.settings;
                self.timed(s.enter_permille, s.enter).await
            }
            None => Outcome::Failure,
        }
    }

    fn halt(&self, _: ActionId) {
        // Nothing more to do if even braking fails.
        let _ = self.wheels(Drive::brake);
    }
}

impl<So, Bu, Ca, Ha, Wh> Platform for FetchTea<So, Bu, Ca, Ha, Wh> {
    // Sensing runs on an interrupt executor above deciding.
    type Mutex = CriticalSectionRawMutex;
}

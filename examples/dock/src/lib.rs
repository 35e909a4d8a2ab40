//! A differential-drive robot docking to its charger, on psmpa: the example to start a robot
//! of your own from. Its mission is data (`mission.json`, compiled in as [`dock`]); this crate
//! gives the mission's sensors and behaviours ([`Dock`]) and a small world for them to act in
//! ([`Yard`]).
//!
//! * `tof`, a time-of-flight ranger: cyclic every 100 ms, a read takes 30 ms; `path_clear`
//!   when nothing is within 300 mm.
//! * `cliff`, an infrared cliff sensor: cyclic every 20 ms, instant; `on_floor`.
//! * `camera`, once near the dock: `dock_seen` when the charger's marker is in view.
//! * `battery`, once: `battery_ok` at 30 % or more. It decides which plan runs: "drive in"
//!   (context `battery_ok`) or "creep in" (context not `battery_ok`).
//!
//! On a board, [`Yard`] is replaced by the drivers (a VL53L0X, a GPIO, a UART camera, an ADC)
//! and the motors; the mission and the behaviours stay as they are.
#![no_std]
#![deny(missing_docs)]

use core::cell::Cell;

use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_time::{Duration, Instant, Timer};
use psmpa_core::{Act, Actuator, Beside, Outcome, Platform, Reading, Sensor, SensorFault, Value};

// The mission, checked and built when the crate builds: its type (`dock::Dock`), its sensors,
// actions and plans as enums and types, its plans' states as constants, a sampler per sensor.
psmpa_core::include_mission!(pub mod dock = "mission.json");

/// The dock robot's runtime, tracing into `T`.
pub type DockRuntime<'r, T = ()> = dock::Runtime<'r, Dock<'r>, T>;

// Building the crate for a microcontroller compiles the runtime for this robot.
psmpa_core::compile_runtime!(DockRuntime<'_>);

/// Where the charger is, mm from the start.
pub const DOCK_MM: i32 = 3_000;
/// Close enough to align, mm before the charger.
pub const NEAR_MM: i32 = 200;
/// A time-of-flight read takes this long.
pub const TOF_LATENCY: Duration = Duration::from_millis(30);
/// Speeds, mm/s: driving and creeping.
pub const DRIVE_MM_S: i32 = 300;
/// Creeping speed, mm/s (a low battery).
pub const CREEP_MM_S: i32 = 100;

/// The robot's surroundings: a straight run to the charger, perhaps a box put in the way for a
/// while, perhaps a drop in the floor. Positions in mm from the start.
#[derive(Debug)]
pub struct Yard {
    /// A box stands 250 mm ahead of the robot from .. to (ms), if any.
    pub box_ms: Option<(u64, u64)>,
    /// The floor ends here, if anywhere before the dock.
    pub cliff_mm: Option<i32>,
    /// Battery charge, %.
    pub battery: u8,
    /// Whether the charger's marker can be seen.
    pub marker: bool,
    motion: Motion,
}

/// The robot's motion: position, µm, at `since`, and speed.
#[derive(Debug)]
struct Motion {
    /// Position, µm, at `since`.
    pos_um: Cell<i64>,
    speed_mm_s: Cell<i32>,
    since: Cell<Instant>,
}

impl Yard {
    /// A yard with nothing in the way, a full battery and the marker in view.
    pub const fn new() -> Self {
        Self {
            box_ms: None,
            cliff_mm: None,
            battery: 90,
            marker: true,
            motion: Motion {
                pos_um: Cell::new(0),
                speed_mm_s: Cell::new(0),
                since: Cell::new(Instant::from_ticks(0)),
            },
        }
    }

    /// This yard with a box in the way from `from_ms` to `to_ms`.
    pub const fn with_box(self, from_ms: u64, to_ms: u64) -> Self {
        Self {
            box_ms: Some((from_ms, to_ms)),
            ..self
        }
    }

    /// This yard with the floor ending `mm` from the start.
    pub const fn with_cliff(self, mm: i32) -> Self {
        Self {
            cliff_mm: Some(mm),
            ..self
        }
    }

    /// This yard with the battery at `percent`.
    pub const fn with_battery(self, percent: u8) -> Self {
        Self {
            battery: percent,
            ..self
        }
    }

    /// Where the robot is now, mm.
    pub fn position_mm(&self) -> i32 {
        let m = &self.motion;
        let now = Instant::now();
        let dt_us = now.duration_since(m.since.get()).as_micros() as i64;
        let pos = m.pos_um.get() + i64::from(m.speed_mm_s.get()) * dt_us / 1_000;
        m.pos_um.set(pos);
        m.since.set(now);
        (pos / 1_000) as i32
    }

    /// Sets the wheels' speed, mm/s (0 brakes).
    pub fn set_speed(&self, mm_s: i32) {
        self.position_mm();
        self.motion.speed_mm_s.set(mm_s);
    }

    fn blocked(&self, at: Instant) -> bool {
        self.box_ms
            .is_some_and(|(from, to)| (from..to).contains(&at.as_millis()))
    }
}

impl Default for Yard {
    fn default() -> Self {
        Self::new()
    }
}

/// The dock robot: its sensors and behaviours in `yard`.
pub struct Dock<'y> {
    /// The world it senses and moves in.
    pub yard: &'y Yard,
}

impl Sensor<dock::Dock> for Dock<'_> {
    async fn switch_on(&self, _: dock::Sensor) -> Result<(), SensorFault> {
        Ok(())
    }

    async fn switch_off(&self, _: dock::Sensor) {}

    async fn sample(&self, sensor: dock::Sensor) -> Result<Option<Reading>, SensorFault> {
        let yard = self.yard;
        let start = Instant::now();
        Ok(Some(match sensor {
            dock::Sensor::Tof => {
                // The distance as it was when the measurement started.
                Timer::after(TOF_LATENCY).await;
                let mm = if yard.blocked(start) { 250 } else { 2_000 };
                Reading::of(Value::Mm(mm), mm > 300)
            }
            dock::Sensor::Cliff => {
                let edge = yard.cliff_mm.is_some_and(|c| yard.position_mm() >= c);
                Reading::flag(!edge)
            }
            dock::Sensor::Camera => Reading::flag(yard.marker),
            dock::Sensor::Battery => Reading::of(Value::Level(yard.battery), yard.battery >= 30),
        }))
    }
}

impl Dock<'_> {
    /// Drives to `NEAR_MM` before the dock at `speed`, braking while the precondition is false:
    /// "drive" or "creep", each beside the time-of-flight ranger and the cliff sensor.
    async fn approach<A>(&self, io: &dock::Io<'_, A>, speed: i32) -> Outcome
    where
        A: Beside<dock::sensor::Tof> + Beside<dock::sensor::Cliff>,
    {
        let yard = self.yard;
        let mut version = io.version();
        loop {
            let left = DOCK_MM - NEAR_MM - yard.position_mm();
            if left <= 0 {
                yard.set_speed(0);
                return Outcome::Success;
            }
            let arrival = match io.violation() {
                Some(_) => {
                    yard.set_speed(0);
                    None
                }
                None => {
                    yard.set_speed(speed);
                    let ms = (left as u64 * 1_000).div_ceil(speed as u64);
                    Some(Instant::now().saturating_add(Duration::from_millis(ms)))
                }
            };
            if let Some(v) = io.changed_until(version, arrival).await {
                version = v;
            }
        }
    }
}

impl Actuator<dock::Dock> for Dock<'_> {
    async fn run(&self, act: Act<'_, dock::Dock>) -> Outcome {
        match act.typed() {
            dock::Run::Drive(io) => self.approach(&io, DRIVE_MM_S).await,
            dock::Run::Creep(io) => self.approach(&io, CREEP_MM_S).await,
            dock::Run::Align(_) => {
                Timer::after(Duration::from_millis(500)).await;
                Outcome::Success
            }
            dock::Run::Connect(_) => {
                Timer::after(Duration::from_millis(300)).await;
                Outcome::Success
            }
        }
    }

    fn halt(&self, _: dock::Action) {
        self.yard.set_speed(0);
    }
}

impl Platform for Dock<'_> {
    // Sensing and deciding on one executor; `CriticalSectionRawMutex` when sensing runs on an
    // interrupt executor above deciding.
    type Mutex = NoopRawMutex;
}

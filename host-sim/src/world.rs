//! The simulated NAO world of the paper's experiment (§6): a straight walk to the door while a
//! person puts obstacles in front of the robot and takes them away again.
//!
//! Integer units throughout: positions in micrometres, time in milliseconds of `embassy-time`.
//! The physics is event driven and exact: between two instants it knows when the next thing
//! happens (an obstacle appears or is removed, the robot touches an obstacle or reaches the
//! door, a side step ends, a box comes within the sonar threshold), so results do not depend
//! on how often anything wakes up.
//!
//! What counts (docs/simulator.md, "What the world counts"):
//! * **detected**: an active sensor registered the obstacle while it was present and before the
//!   robot touched it unregistered (sonar reading above 0 and below the threshold caused by a
//!   box, or bumper 2). A bumper that is on registers a touch itself, so touching with the
//!   bumper on is a detection, not a collision.
//! * **collision**: the robot touched an obstacle no active sensor had registered; it cannot
//!   walk through and is blocked until the obstacle is removed (or avoided once sensed).
//! * **reaction latency**: from the first instant an active sensor is certain to register the
//!   obstacle whatever the noise (see *detectable*) to the instant the walking stops for it (at
//!   once, if the robot was standing); from the registration itself if a lucky reading came
//!   first. The instant is the start of the certain interval in which the detection happened:
//!   if the obstacle stops being certain before any sample catches it (it enters the sonar's
//!   blind zone, a nearer box hides it, the sensor is switched off), the clock starts again
//!   when it becomes certain again. This is what the runtime can promise
//!   ([`psmpa_core::timing::latency_bound`]): before that instant, noise decides.
//! * **detectable**: at least one delivered sample fell in an instant where the obstacle was
//!   present and certain to register whatever the noise (a box in
//!   `[min + noise, threshold − noise)`, or a touch with the bumper on). Under P-SMPA, whose
//!   sensors run for the whole walk, this is "could physically be detected".

use core::cell::RefCell;

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::{NoopRawMutex, RawMutex};
use embassy_time::Instant;
use heapless::Vec;
use rand_core::{Rng, SeedableRng};
use rand_pcg::Pcg32;

use psmpa_core::TraceHash;

use crate::scenario::{FaultKind, Interference, Kind, MAX_INTERFERENCES, Scenario, to_mm};

/// How far from a door a robot that dead-reckons its walk may stop and be at it, µm: the
/// door's marker is a reflective strip 40 mm long, centred on the door, which a marker sensor
/// sees from anywhere above it.
pub const ARRIVAL_UM: i64 = 20_000;

/// How long a body that pushes must drive at the kitchen door to push it open, or to go
/// through it once open, ms ([`World::push_door`]).
pub const DOOR_PUSH_MS: u64 = 1_000;

/// The world's devices.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Device {
    /// Ultrasonic sonar.
    Sonar,
    /// Foot bumper.
    Bumper,
    /// Camera (one-shot, sees the door handle).
    Camera,
    /// The hand on the door handle (on demand: feels whether the door gives).
    Handle,
}

impl Device {
    /// Lower-case name.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Sonar => "sonar",
            Self::Bumper => "bumper",
            Self::Camera => "camera",
            Self::Handle => "handle",
        }
    }

    const fn slot(self) -> usize {
        match self {
            Self::Sonar => 0,
            Self::Bumper => 1,
            Self::Camera => 2,
            Self::Handle => 3,
        }
    }
}

/// Where the robot walks to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Place {
    /// The kitchen door, `door_m` from the start.
    KitchenDoor,
    /// The back door, `back_door_m` further along.
    BackDoor,
}

impl Place {
    fn at_um(self, sc: &Scenario) -> i64 {
        match self {
            Self::KitchenDoor => sc.door_um,
            Self::BackDoor => sc.door_um.saturating_add(sc.back_door_um),
        }
    }

    /// Its index in per-door state.
    fn slot(self) -> usize {
        match self {
            Self::KitchenDoor => 0,
            Self::BackDoor => 1,
        }
    }
}

/// Something that happened in the world.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WorldEvent {
    /// A sensor was switched on.
    SensorOn(Device),
    /// A sensor was switched off.
    SensorOff(Device),
    /// A sample: sonar in mm, bumper 1/2, camera 0/1.
    Sample(Device, u32),
    /// A sample lost to dropout.
    SampleLost(Device),
    /// Interference `index` was put down at `at_um`.
    Appeared {
        /// Index in the scenario.
        index: u8,
        /// Box or ball.
        kind: Kind,
        /// Its position, µm from the start.
        at_um: i64,
    },
    /// Interference `index` was taken away.
    Removed(u8),
    /// The robot had already reached the door: interference `index` was not put down.
    Skipped(u8),
    /// An active sensor registered interference `index`.
    Detected(u8, Device),
    /// The robot touched interference `index` unregistered.
    Collided(u8),
    /// The robot stopped for interference `index` this long after it became certain to register.
    Reacted(u8, u64),
    /// The robot started walking.
    Walk,
    /// The robot stopped walking.
    Stop,
    /// A side step started (around interference `index`, if one was registered).
    AvoidStarted(Option<u8>),
    /// The side step ended.
    AvoidDone(Option<u8>),
    /// SMPA: actuators held (sense phase) or released.
    Held(bool),
    /// The robot reached a door.
    Arrived(Place),
    /// A door is open.
    DoorOpened(Place),
    /// The robot pressed the kitchen door's handle: the door is locked.
    Locked,
    /// The robot entered the kitchen.
    InKitchen,
    /// The walking speed changed, in thousandths of `speed_mps`.
    Speed(u16),
}

impl WorldEvent {
    /// Adds the event to `hash` in a fixed little-endian encoding.
    pub fn hash_into(&self, hash: &mut TraceHash) {
        let dev = |d: Device| d.slot() as u8;
        let opt = |o: Option<u8>| o.map_or(0xff, |i| i);
        match *self {
            Self::SensorOn(d) => hash.write(&[0, dev(d)]),
            Self::SensorOff(d) => hash.write(&[1, dev(d)]),
            Self::Sample(d, v) => {
                hash.write(&[2, dev(d)]);
                hash.write(&v.to_le_bytes());
            }
            Self::SampleLost(d) => hash.write(&[3, dev(d)]),
            Self::Appeared { index, kind, at_um } => {
                hash.write(&[4, index, kind as u8]);
                hash.write(&at_um.to_le_bytes());
            }
            Self::Removed(i) => hash.write(&[5, i]),
            Self::Skipped(i) => hash.write(&[6, i]),
            Self::Detected(i, d) => hash.write(&[7, i, dev(d)]),
            Self::Collided(i) => hash.write(&[8, i]),
            Self::Reacted(i, ms) => {
                hash.write(&[9, i]);
                hash.write(&ms.to_le_bytes());
            }
            Self::Walk => hash.write(&[10]),
            Self::Stop => hash.write(&[11]),
            Self::AvoidStarted(t) => hash.write(&[12, opt(t)]),
            Self::AvoidDone(t) => hash.write(&[13, opt(t)]),
            Self::Held(h) => hash.write(&[14, u8::from(h)]),
            Self::Arrived(p) => hash.write(&[15, p as u8]),
            Self::DoorOpened(p) => hash.write(&[16, p as u8]),
            Self::InKitchen => hash.write(&[17]),
            Self::Locked => hash.write(&[18]),
            Self::Speed(permille) => {
                hash.write(&[19]);
                hash.write(&permille.to_le_bytes());
            }
        }
    }
}

/// Receives the world's events with their time and the robot's position.
pub trait WorldLog {
    /// One event.
    fn log(&mut self, at_ms: u64, pos_um: i64, event: WorldEvent);

    /// A read of `device` starts now (not an event of the world: not hashed). A platform can
    /// stamp it, to measure how long the reaction to what the read finds takes.
    fn read_started(&mut self, device: Device) {
        let _ = device;
    }
}

/// Discards the events.
impl WorldLog for () {
    fn log(&mut self, _at_ms: u64, _pos_um: i64, _event: WorldEvent) {}
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    Pending,
    Present,
    Removed,
    Avoided,
    Skipped,
}

/// How an interference ended for the robot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fate {
    /// Never registered nor touched.
    Unmet,
    /// Registered by this device before a collision.
    Detected(Device),
    /// Touched unregistered.
    Collided,
}

#[derive(Clone, Copy, Debug)]
struct Obstacle {
    kind: Kind,
    pos_um: i64,
    phase: Phase,
    fate: Fate,
    /// Start of the current interval in which an active sensor is certain to register it.
    certain_since: Option<u32>,
    reaction_ms: Option<u32>,
    certain_samples: u16,
    /// Some active sensor has registered it (also after a collision): a side step can aim at it.
    sensed: bool,
    /// How fast it walks towards the robot until it touches it, µm per ms.
    speed: u16,
    /// From how far the sonar's cone takes it in, µm ([`Sonar::seen_from_um`]; `i32::MAX`:
    /// never). 32 bits, as its when and where stay in the scenario: the world's state keeps
    /// the size it had before the cone.
    ///
    /// [`Sonar::seen_from_um`]: crate::scenario::Sonar::seen_from_um
    seen_from_um: i32,
    /// Since when the robot has touched it.
    touch_since: Option<u32>,
}

/// A box at `d` µm in range registers whatever the noise: both ends of the noise band do.
fn certain_at(sonar: &crate::scenario::Sonar, d: i64) -> bool {
    // `max`/`min`, not `clamp`: the range is valid (the scenario is), and `clamp`'s panic
    // would bring integer formatting into the firmware.
    [d - sonar.noise_um, d + sonar.noise_um]
        .map(|x| to_mm(x.max(sonar.min_um).min(sonar.max_um)))
        .iter()
        .all(|&r| sonar.registers(r))
}

impl Obstacle {
    fn blocks(&self) -> bool {
        self.phase == Phase::Present
    }

    fn walks(&self) -> i64 {
        i64::from(self.speed)
    }

    fn seen_from(&self) -> i64 {
        i64::from(self.seen_from_um)
    }
}

/// When interference `i` is taken away, ms.
fn removal_ms(i: &Interference) -> u64 {
    u64::from(i.at_ms) + u64::from(i.hold_ms)
}

impl Obstacle {}

/// What the robot's legs do.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Motion {
    /// Standing.
    Idle,
    /// Walking towards the door (unless held or blocked).
    Walking,
    /// Side-stepping around an obstacle; `left_ms` of stepping remain.
    Avoiding {
        /// Stepping time left.
        left_ms: u64,
        /// The obstacle being avoided.
        target: Option<u8>,
    },
}

/// Delivered samples of one device, for the largest gap between two while it stayed on.
#[derive(Clone, Copy, Debug, Default)]
struct Gaps {
    /// The last delivery since the device was switched on.
    last_ms: Option<u64>,
    max_ms: Option<u64>,
}

/// What a sonar read measured when it started; [`World::sonar_deliver`] hands it over.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[must_use = "a read is delivered with `sonar_deliver`"]
pub struct Echo {
    /// The reading in mm; `None`: lost to dropout.
    mm: Option<u32>,
    /// The obstacles it registers, by index.
    registers: u32,
    /// The obstacles it came from (nearest ahead, in the cone), by index: what registers when
    /// the reading is below the threshold.
    from: u32,
    /// The obstacles it was certain to register whatever the noise.
    certain: u32,
    /// Whether a stuck fault is to stick at this reading.
    sticks: bool,
    /// The robot's position when the read started (odometry), µm.
    pub pos_um: i64,
}

/// What a bumper read felt when it started; [`World::bumper_deliver`] hands it over.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[must_use = "a read is delivered with `bumper_deliver`"]
pub struct Touch {
    /// The obstacles touched, by index.
    touching: u32,
}

impl Echo {
    /// The reading in mm the echo carries (a ranger's pulse is this long); `None`: lost.
    pub const fn mm(&self) -> Option<u32> {
        self.mm
    }

    /// The obstacle the echo came from (the first, if several stand at that distance).
    pub fn came_from(&self) -> Option<u8> {
        bits(self.from).next().map(|i| i as u8)
    }
}

impl Touch {
    /// Whether the read felt an obstacle: a bump switch that is closed.
    pub const fn any(&self) -> bool {
        self.touching != 0
    }

    /// The obstacle felt (the first, if several).
    pub fn felt(&self) -> Option<u8> {
        bits(self.touching).next().map(|i| i as u8)
    }
}

/// Obstacles by index as bits: one `u32` holds them all.
const _: () = assert!(MAX_INTERFERENCES <= 32);

/// The indices of the set bits of `mask`, lowest first (scenario order).
fn bits(mut mask: u32) -> impl Iterator<Item = usize> {
    core::iter::from_fn(move || {
        let i = mask.trailing_zeros() as usize;
        mask &= mask.wrapping_sub(1);
        (i < 32).then_some(i)
    })
}

/// `State::flags`: a command changed the state since the last settle.
const DIRTY: u8 = 1;
/// `State::flags`: nothing changes by itself from now on.
const NEXT_NONE: u8 = 2;
/// `State::flags`: the next change by itself is at `State::next_ms`.
const NEXT_AT: u8 = 4;

struct State<L> {
    now: u64,
    pos_um: i64,
    /// Where a walk ends.
    target_um: i64,
    /// Walking speed, thousandths of the scenario's.
    speed_permille: u16,
    motion: Motion,
    held: bool,
    on: [bool; 4],
    on_ms: [u64; 4],
    gaps: [Gaps; 4],
    obstacles: Vec<Obstacle, MAX_INTERFERENCES>,
    /// The obstacles present, by index (kept by `set_phase`): the only ones the physics acts on.
    present: u32,
    /// The obstacles that walk, by index.
    walkers: u32,
    /// When a contact becomes long enough for the bumper to feel (`u64::MAX`: none pending):
    /// the certainty pass must run then, though nothing else changed.
    recheck_ms: u64,
    /// The earliest appearance or removal due (`u64::MAX`: none), or 0 while unknown (`settle`
    /// then searches).
    due_ms: u64,
    /// The last certainty pass's inputs: where the robot was, and [`how`](State::how) (0: an
    /// obstacle changed since). With the same inputs and obstacles the pass changes nothing.
    looked_um: i64,
    looked_how: u8,
    rng: Pcg32,
    at_door_ms: Option<u64>,
    /// Per door ([`Place::slot`]): the robot arrived there once.
    arrived: [bool; 2],
    /// Per door: open.
    door_open: [bool; 2],
    in_kitchen: bool,
    /// The reading a stuck sonar keeps reporting.
    stuck_mm: Option<u32>,
    /// [`DIRTY`]: a command changed the state since the last settle. [`NEXT_NONE`] or
    /// [`NEXT_AT`] (`next_ms`): what `next_event` found, while nothing changed since. A command
    /// sets it to `DIRTY`, forgetting that in the same store.
    flags: u8,
    next_ms: u64,
    hash: TraceHash,
    log: L,
}

/// The world of one run: the scenario's robot, sensors and interferences.
///
/// Both sides of the runtime act on it (the sensing side reads, the deciding side walks), so
/// its state is behind a mutex: `NoopRawMutex` where they take turns on one thread, a
/// `CriticalSectionRawMutex` where sensing preempts (each access then runs in a critical
/// section: the simulated physics stands still while it is computed).
pub struct World<'s, L: WorldLog, M: RawMutex = NoopRawMutex> {
    scenario: &'s Scenario,
    state: Mutex<M, RefCell<State<L>>>,
}

/// How one interference ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ObstacleReport {
    /// Detected, collided with, or neither.
    pub fate: Fate,
    /// Put down (not due after the robot reached the kitchen door, nor after the run ended).
    pub placed: bool,
    /// Due after the robot reached the door, so not put down. An interference neither placed
    /// nor skipped was due after the run ended.
    pub skipped: bool,
    /// Certain to register in at least one delivered sample (see the module doc).
    pub detectable: bool,
    /// Reaction latency, when detected and reacted to.
    pub reaction_ms: Option<u64>,
}

/// What a run of the world amounted to.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Tally {
    /// Interferences in the scenario.
    pub interferences: u32,
    /// Of which put down (those due after the robot reached the door, or after the run
    /// ended, are not).
    pub placed: u32,
    /// Registered before being touched.
    pub detected: u32,
    /// Touched unregistered.
    pub collisions: u32,
    /// Certain to register in at least one delivered sample (see the module doc).
    pub detectable: u32,
    /// Longest reaction latency over the detected obstacles, ms.
    pub max_reaction_ms: Option<u64>,
    /// Whether the robot reached the door.
    pub reached_door: bool,
    /// On-time of sonar, bumper, camera and handle, ms.
    pub on_ms: [u64; 4],
    /// The largest interval between two delivered samples of sonar, bumper, camera and handle
    /// while it stayed on, ms; `None` with fewer than two such samples.
    pub sample_gap_max_ms: [Option<u64>; 4],
}

/// A time in ms as 32 bits (a scenario spans at most a day).
fn ms32(t: u64) -> u32 {
    u32::try_from(t).unwrap_or(u32::MAX)
}

fn div_ceil(a: i64, b: i64) -> u64 {
    if b <= 0 || a <= 0 {
        return 0;
    }
    (a as u64).div_ceil(b as u64)
}

impl<L: WorldLog> State<L> {
    /// The door the robot stands at, having arrived there.
    fn door_here(&self, sc: &Scenario) -> Option<Place> {
        [Place::KitchenDoor, Place::BackDoor].into_iter().find(|p| {
            self.pos_um == p.at_um(sc) && self.arrived.get(p.slot()).copied().unwrap_or(false)
        })
    }

    /// Whether the handle of the door the robot stands at gives: the back door's always, the
    /// kitchen door's when it is not locked.
    fn door_gives(&self, sc: &Scenario) -> bool {
        match self.door_here(sc) {
            Some(Place::KitchenDoor) => !sc.door_locked,
            Some(Place::BackDoor) => true,
            None => false,
        }
    }

    /// The sonar's fault now, if it has one.
    fn fault(&self, sc: &Scenario) -> Option<FaultKind> {
        sc.fault
            .filter(|(_, at)| self.now >= u64::from(*at))
            .map(|(kind, _)| kind)
    }

    /// [`World::sonar_read`] on the state, with the sonar's `fault`.
    fn sonar_read(&mut self, sc: &Scenario, fault: Option<FaultKind>) -> Echo {
        self.log.read_started(Device::Sonar);
        let sonar = sc.sonar;
        let mut echo = Echo {
            mm: None,
            registers: 0,
            from: 0,
            certain: 0,
            sticks: false,
            pos_um: self.pos_um,
        };
        match fault {
            Some(FaultKind::OutOfRange) => {
                let mm = u32::try_from(to_mm(sonar.max_um) + 1_500).unwrap_or(u32::MAX);
                echo.mm = Some(mm);
                return echo;
            }
            Some(FaultKind::Stuck) if self.stuck_mm.is_some() => {
                echo.mm = self.stuck_mm;
                return echo;
            }
            _ => {}
        }
        if sonar.dropout > 0 && u64::from(self.rng.next_u32()) < sonar.dropout {
            return echo;
        }
        // The nearest box ahead, if it lies within the sonar's range.
        let seen = self
            .nearest_box()
            .filter(|d| (sonar.min_um..=sonar.max_um).contains(d));
        let reading_um = match seen {
            Some(d) => {
                let noise = if sonar.noise_um > 0 {
                    let span = 2 * sonar.noise_um as u64 + 1;
                    (u64::from(self.rng.next_u32()) % span) as i64 - sonar.noise_um
                } else {
                    0
                };
                (d + noise).max(sonar.min_um).min(sonar.max_um)
            }
            None => sonar.max_um,
        };
        let mm = to_mm(reading_um);
        if let Some(d) = seen {
            let certain = certain_at(&sonar, d);
            let registered = sonar.registers(mm);
            // Every box at that distance is what the echo came from.
            for (i, o) in self.present_obstacles() {
                if o.kind == Kind::Box && o.pos_um - self.pos_um == d && d >= o.seen_from() {
                    echo.certain |= u32::from(certain) << i;
                    echo.registers |= u32::from(registered) << i;
                    echo.from |= 1 << i;
                }
            }
        }
        echo.mm = Some(u32::try_from(mm).unwrap_or(u32::MAX));
        // The first reading after the fault is the one it sticks at.
        echo.sticks = fault == Some(FaultKind::Stuck);
        echo
    }

    fn moving(&self) -> bool {
        self.motion == Motion::Walking && !self.held
    }

    /// The walking speed now, µm/ms: at least 1 while the scenario's speed is.
    fn speed(&self, sc: &Scenario) -> i64 {
        let scaled = sc
            .speed_um_per_ms
            .saturating_mul(i64::from(self.speed_permille))
            / 1000;
        scaled.max(sc.speed_um_per_ms.min(1))
    }

    /// A sample of `device` was delivered now (and accepted by the robot).
    fn delivered(&mut self, device: Device) {
        let now = self.now;
        if let Some(g) = self.gaps.get_mut(device.slot()) {
            if let Some(last) = g.last_ms {
                g.max_ms = g.max_ms.max(Some(now - last));
            }
            g.last_ms = Some(now);
        }
    }

    fn emit(&mut self, event: WorldEvent) {
        let (now, pos) = (self.now, self.pos_um);
        self.hash.write(&now.to_le_bytes());
        self.hash.write(&pos.to_le_bytes());
        event.hash_into(&mut self.hash);
        self.log.log(now, pos, event);
    }

    /// Where a walking robot must stop: its target or the nearest obstacle in the way.
    fn limit_um(&self) -> i64 {
        self.present_obstacles()
            .filter(|(_, o)| o.pos_um >= self.pos_um)
            .map(|(_, o)| o.pos_um)
            .fold(self.target_um, i64::min)
    }

    /// The obstacles present, with their indices, in scenario order.
    fn present_obstacles(&self) -> impl Iterator<Item = (usize, &Obstacle)> {
        bits(self.present).filter_map(|i| self.obstacles.get(i).map(|o| (i, o)))
    }

    /// Whether a bumper sample now feels `o`: touched for at least the bumper's minimum
    /// contact.
    fn felt(&self, o: &Obstacle, sc: &Scenario) -> bool {
        o.blocks()
            && o.pos_um <= self.pos_um
            && o.touch_since
                .is_some_and(|t| self.now.saturating_sub(u64::from(t)) >= sc.bumper_min_contact_ms)
    }

    /// Whether an active sonar's next sample registers `o` whatever the noise; `nearest` is
    /// [`nearest_box`](Self::nearest_box).
    fn sonar_certain(&self, o: &Obstacle, sc: &Scenario, nearest: Option<i64>) -> bool {
        let d = o.pos_um - self.pos_um;
        self.on[0]
            && o.kind == Kind::Box
            && nearest == Some(d)
            && d >= o.seen_from()
            && (sc.sonar.min_um..=sc.sonar.max_um).contains(&d)
            && certain_at(&sc.sonar, d)
    }

    /// The distance to the nearest box ahead that the sonar's cone takes in.
    fn nearest_box(&self) -> Option<i64> {
        self.present_obstacles()
            .map(|(_, o)| (o, o.pos_um - self.pos_um))
            .filter(|&(o, d)| o.kind == Kind::Box && d >= 0 && d >= o.seen_from())
            .map(|(_, d)| d)
            .min()
    }

    /// The earliest instant after `now` at which something changes by itself.
    fn next_event(&mut self, sc: &Scenario) -> Option<u64> {
        // Often asked twice in a row (the walk, then the next advance): answered once.
        if self.flags & NEXT_AT != 0 {
            return Some(self.next_ms);
        }
        if self.flags & NEXT_NONE != 0 {
            return None;
        }
        let next = self.find_next(sc);
        self.flags |= if next.is_some() { NEXT_AT } else { NEXT_NONE };
        self.next_ms = next.unwrap_or(0);
        next
    }

    /// [`next_event`](Self::next_event), worked out.
    fn find_next(&self, sc: &Scenario) -> Option<u64> {
        let now = self.now;
        let mut next: Option<u64> = None;
        let mut consider = |t: u64| {
            if t > now {
                next = Some(next.map_or(t, |n| n.min(t)));
            }
        };
        // One put down for no time is still there, due at `now`: then look past it.
        let due = if self.due_ms > now {
            self.due_ms
        } else {
            self.first_due(sc, now.saturating_add(1))
        };
        if due != u64::MAX {
            consider(due);
        }
        let speed = self.speed(sc);
        let walking = if self.moving() { speed.max(0) } else { 0 };
        if walking > 0 && self.target_um > self.pos_um {
            consider(now.saturating_add(div_ceil(self.target_um - self.pos_um, walking)));
        }
        // The reading rounds below the threshold once d < threshold_mm - 0.5 mm.
        let below = sc.sonar.threshold_mm() * 1000 - 500;
        // Nothing closes in while the robot stands and no obstacle walks.
        let closing_any = walking > 0 || self.walkers & self.present != 0;
        for (_, o) in self.present_obstacles().filter(|_| closing_any) {
            let d = o.pos_um - self.pos_um;
            // An obstacle stops walking once it touches the robot.
            let closing = walking + if d > 0 { o.walks() } else { 0 };
            if closing <= 0 {
                continue;
            }
            // Contact.
            consider(now.saturating_add(div_ceil(d, closing)));
            if self.on[0] && o.kind == Kind::Box && o.fate == Fate::Unmet {
                // A box ahead enters the sonar threshold, then the blind zone below min_m,
                // and a low one leaves the cone.
                let cone = if o.seen_from() > 0 { o.seen_from() } else { -1 };
                for edge in [below, sc.sonar.min_um, cone] {
                    if edge >= 0 && d >= edge {
                        let dt = (d - edge) / closing + 1;
                        consider(now.saturating_add(dt as u64));
                    }
                }
            }
        }
        // A contact that becomes long enough for the bumper to feel.
        if self.recheck_ms != u64::MAX {
            consider(self.recheck_ms);
        }
        if let Motion::Avoiding { left_ms, .. } = self.motion
            && !self.held
        {
            consider(now.saturating_add(left_ms.max(1)));
        }
        next
    }

    /// Moves time forward by `dt` with nothing happening in between.
    fn integrate(&mut self, dt: u64, sc: &Scenario) {
        self.flags &= DIRTY;
        for (on, ms) in self.on.iter().zip(self.on_ms.iter_mut()) {
            if *on {
                *ms = ms.saturating_add(dt);
            }
        }
        if self.moving() {
            let step = self.speed(sc).saturating_mul(dt as i64);
            let limit = self.limit_um();
            self.pos_um = self.pos_um.saturating_add(step).min(limit).max(self.pos_um);
        }
        // Obstacles that walk towards the robot, up to it; one against it stands.
        let pos = self.pos_um;
        for i in bits(self.walkers & self.present) {
            if let Some(o) = self.obstacles.get_mut(i).filter(|o| o.pos_um > pos) {
                let step = o.walks().saturating_mul(dt as i64);
                o.pos_um = o.pos_um.saturating_sub(step).max(pos);
                // It moved: the certainty pass must look again.
                self.looked_how = 0;
            }
        }
        if let Motion::Avoiding { left_ms, target } = self.motion
            && !self.held
        {
            self.motion = Motion::Avoiding {
                left_ms: left_ms.saturating_sub(dt),
                target,
            };
        }
        self.now = self.now.saturating_add(dt);
    }

    /// Applies everything due at `now`.
    #[inline]
    fn settle(&mut self, sc: &Scenario) {
        // Most settles find nothing due and nothing moved: told here, without a call.
        if matches!(self.motion, Motion::Avoiding { left_ms: 0, .. })
            || self.due_ms <= self.now
            || self.recheck_ms <= self.now
            || !self.looked()
        {
            self.apply(sc);
        }
    }

    /// The certainty pass's inputs besides the position and the obstacles; never 0.
    fn how(&self) -> u8 {
        1 | u8::from(self.on[0]) << 1 | u8::from(self.on[1]) << 2 | u8::from(self.moving()) << 3
    }

    /// Whether the last certainty pass had the inputs of one now.
    fn looked(&self) -> bool {
        self.looked_um == self.pos_um && self.looked_how == self.how()
    }

    /// [`settle`](Self::settle) when something may be due.
    #[inline(never)] // Rare: kept out of the callers.
    fn apply(&mut self, sc: &Scenario) {
        self.flags &= DIRTY;
        let now = self.now;
        if let Motion::Avoiding { left_ms: 0, target } = self.motion {
            if let Some(i) = target.map(usize::from)
                && self.obstacles.get(i).is_some_and(Obstacle::blocks)
            {
                self.set_phase(i, Phase::Avoided);
            }
            self.motion = Motion::Idle;
            self.emit(WorldEvent::AvoidDone(target));
        }
        // None is due before `due_ms`.
        let due = if self.due_ms <= now {
            self.obstacles.len()
        } else {
            0
        };
        for i in 0..due {
            let (Some(o), Some(item)) = (self.obstacles.get(i), sc.interferences.get(i)) else {
                continue;
            };
            let (kind, ahead_um) = (o.kind, item.ahead_um);
            let index = i as u8;
            if o.phase == Phase::Present && removal_ms(item) <= now {
                // Touched and gone before any sensor registered it: the robot never knew.
                let unnoticed = o.fate == Fate::Unmet && o.touch_since.is_some();
                if unnoticed {
                    if let Some(o) = self.obstacles.get_mut(i) {
                        o.fate = Fate::Collided;
                    }
                    self.emit(WorldEvent::Collided(index));
                }
                self.set_phase(i, Phase::Removed);
                self.emit(WorldEvent::Removed(index));
            } else if o.phase == Phase::Pending && u64::from(item.at_ms) <= now {
                if self.at_door_ms.is_some() {
                    self.set_phase(i, Phase::Skipped);
                    self.emit(WorldEvent::Skipped(index));
                } else {
                    let at_um = self.pos_um.saturating_add(i64::from(ahead_um));
                    if let Some(o) = self.obstacles.get_mut(i) {
                        o.pos_um = at_um;
                    }
                    self.set_phase(i, Phase::Present);
                    self.emit(WorldEvent::Appeared { index, kind, at_um });
                }
            }
        }
        if due > 0 {
            self.due_ms = self.first_due(sc, 0);
        }
        // The certainty pass depends on the position, `how` and the obstacles only, and a second
        // run on the same ones changes nothing (a fate changed elsewhere leaves `Unmet` for
        // good, out of its reach): then skip it.
        if self.looked() && self.recheck_ms > now {
            return;
        }
        (self.looked_um, self.looked_how) = (self.pos_um, self.how());
        self.recheck_ms = u64::MAX;
        // Obstacles not present are neither touched nor certain (`set_phase` ended their
        // certain interval).
        let nearest = self.nearest_box();
        for i in bits(self.present) {
            let Some(o) = self.obstacles.get_mut(i) else {
                continue;
            };
            // Contact lasts while it is there: the robot cannot walk through it.
            let new_touch = o.pos_um <= self.pos_um && o.touch_since.is_none();
            if new_touch {
                o.touch_since = Some(ms32(now));
            }
            if let Some(t) = o.touch_since {
                let felt_at = u64::from(t).saturating_add(sc.bumper_min_contact_ms);
                if felt_at > now {
                    self.recheck_ms = self.recheck_ms.min(felt_at);
                }
            }
            let Some(o) = self.obstacles.get(i).filter(|o| o.fate == Fate::Unmet) else {
                continue;
            };
            // Walking into an obstacle nothing registered, with the bumper off, is a
            // collision; with the bumper on, the next bumper sample registers the touch. One
            // that walks into the robot unregistered hits it, whatever the bumper.
            let collided = o.pos_um <= self.pos_um
                && ((!self.on[1] && self.moving()) || (new_touch && o.speed > 0));
            let certain = self.sonar_certain(o, sc, nearest) || (self.on[1] && self.felt(o, sc));
            let Some(o) = self.obstacles.get_mut(i) else {
                continue;
            };
            if collided {
                o.fate = Fate::Collided;
            }
            o.certain_since = if certain {
                o.certain_since.or(Some(ms32(now)))
            } else {
                None
            };
            if collided {
                self.emit(WorldEvent::Collided(i as u8));
            }
        }
    }

    /// Moves obstacle `i` to `phase`, keeping `present`, `due_ms` and the certainty pass up to
    /// date.
    fn set_phase(&mut self, i: usize, phase: Phase) {
        let Some(o) = self.obstacles.get_mut(i) else {
            return;
        };
        // One no longer present is no longer certain: what the certainty pass, which visits
        // present ones only, would have found in this same settle.
        if o.phase == Phase::Present && phase != Phase::Present && o.fate == Fate::Unmet {
            o.certain_since = None;
        }
        o.phase = phase;
        let bit = 1u32 << i;
        if phase == Phase::Present {
            self.present |= bit;
        } else {
            self.present &= !bit;
        }
        // `apply`, the caller, works it out after its search for what is due.
        self.due_ms = 0;
        self.looked_how = 0;
    }

    /// The earliest appearance or removal due at `from` or later; `u64::MAX`: none.
    fn first_due(&self, sc: &Scenario, from: u64) -> u64 {
        let mut first = u64::MAX;
        for (o, item) in self.obstacles.iter().zip(&sc.interferences) {
            let t = match o.phase {
                Phase::Pending => u64::from(item.at_ms),
                Phase::Present => removal_ms(item),
                _ => continue,
            };
            if t >= from {
                first = first.min(t);
            }
        }
        first
    }

    #[inline]
    fn advance_to(&mut self, t: u64, sc: &Scenario) {
        if t > self.now {
            self.advance(t, sc);
        } else if self.flags & DIRTY != 0 {
            // Commanded since the last settle (else nothing moved: nothing to do).
            self.resettle(sc);
        }
    }

    /// [`advance_to`](Self::advance_to) the current instant: most calls, cheaper without
    /// `advance`'s frame.
    #[inline(never)] // Kept out of the callers.
    fn resettle(&mut self, sc: &Scenario) {
        self.settle(sc);
        self.flags &= !DIRTY;
    }

    /// [`advance_to`](Self::advance_to) when something may have changed.
    #[inline(never)] // Its frame stays out of the callers'.
    fn advance(&mut self, t: u64, sc: &Scenario) {
        self.settle(sc);
        self.flags &= !DIRTY;
        while self.now < t {
            let next = self.next_event(sc).map_or(t, |n| n.min(t));
            self.integrate(next - self.now, sc);
            self.settle(sc);
        }
    }

    /// An active sensor registered obstacle `i` now.
    fn register(&mut self, i: usize, by: Device) {
        let now = self.now;
        let moving = self.moving();
        let Some(o) = self.obstacles.get_mut(i) else {
            return;
        };
        o.sensed = true;
        if o.fate != Fate::Unmet {
            return;
        }
        o.fate = Fate::Detected(by);
        // With noise a reading can register a box before it is certain to.
        let first = o.certain_since.map_or(now, |f| u64::from(f).min(now));
        o.certain_since = Some(ms32(first));
        let reacted = (!moving && o.reaction_ms.is_none()).then(|| now - first);
        if let Some(r) = reacted {
            o.reaction_ms = Some(ms32(r));
        }
        self.emit(WorldEvent::Detected(i as u8, by));
        if let Some(r) = reacted {
            self.emit(WorldEvent::Reacted(i as u8, r));
        }
    }

    /// The robot stops walking: every registered obstacle still waiting for a reaction got one.
    fn react(&mut self) {
        let now = self.now;
        for i in 0..self.obstacles.len() {
            let Some(o) = self.obstacles.get_mut(i) else {
                continue;
            };
            if let (Fate::Detected(_), None, Some(first)) = (o.fate, o.reaction_ms, o.certain_since)
            {
                let r = now.saturating_sub(u64::from(first));
                o.reaction_ms = Some(ms32(r));
                self.emit(WorldEvent::Reacted(i as u8, r));
            }
        }
    }
}

impl<'s, L: WorldLog, M: RawMutex> World<'s, L, M> {
    /// The world at time 0 of `scenario`, logging into `log`.
    #[inline(never)] // Its temporaries stay out of the frame of the task polling a run.
    pub fn new(scenario: &'s Scenario, log: L) -> Self {
        let mut world = Self {
            scenario,
            state: Mutex::new(RefCell::new(State {
                now: 0,
                pos_um: 0,
                target_um: scenario.door_um,
                speed_permille: 1000,
                motion: Motion::Idle,
                held: false,
                on: [false; 4],
                on_ms: [0; 4],
                gaps: [Gaps::default(); 4],
                obstacles: Vec::new(),
                present: 0,
                walkers: 0,
                recheck_ms: u64::MAX,
                due_ms: 0,
                looked_um: 0,
                looked_how: 0,
                rng: Pcg32::seed_from_u64(scenario.seed),
                at_door_ms: None,
                arrived: [false; 2],
                door_open: [false; 2],
                in_kitchen: false,
                stuck_mm: None,
                flags: DIRTY,
                next_ms: 0,
                hash: TraceHash::new(),
                log,
            })),
        };
        // Pushed in place: a collected vector would be one more copy of it in this frame.
        let state = world.state.get_mut().get_mut();
        for (n, i) in scenario.interferences.iter().enumerate() {
            if i.speed_um_per_ms > 0 {
                state.walkers |= 1 << n;
            }
        }
        let obstacles = &mut state.obstacles;
        for i in &scenario.interferences {
            // The same capacity as the scenario's: room for each.
            let _ = obstacles.push(Obstacle {
                kind: i.kind,
                pos_um: 0,
                phase: Phase::Pending,
                fate: Fate::Unmet,
                certain_since: None,
                reaction_ms: None,
                certain_samples: 0,
                sensed: false,
                speed: i.speed_um_per_ms,
                seen_from_um: i32::try_from(scenario.sonar.seen_from_um(i64::from(i.height_um)))
                    .unwrap_or(i32::MAX),
                touch_since: None,
            });
        }
        world
    }

    /// The scenario.
    pub fn scenario(&self) -> &'s Scenario {
        self.scenario
    }

    /// Brings the world to the current `embassy-time` instant and runs `f` on it.
    fn with<R>(&self, f: impl FnOnce(&mut State<L>, &Scenario) -> R) -> R {
        let now = Instant::now().as_millis();
        self.state.lock(|cell| {
            // Never borrowed twice: no world method calls another inside its closure.
            let mut s = cell.borrow_mut();
            s.advance_to(now, self.scenario);
            let r = f(&mut s, self.scenario);
            s.flags = DIRTY;
            r
        })
    }

    /// [`with`](Self::with) for calls that change only what the physics never reads (the log,
    /// the noise generator, the sample gaps): the next call at this instant need not settle
    /// again, and the next event stays as worked out.
    fn quiet<R>(&self, f: impl FnOnce(&mut State<L>, &Scenario) -> R) -> R {
        let now = Instant::now().as_millis();
        self.state.lock(|cell| {
            let mut s = cell.borrow_mut();
            s.advance_to(now, self.scenario);
            f(&mut s, self.scenario)
        })
    }

    /// [`with`](Self::with) for queries that change nothing.
    fn view<R>(&self, f: impl FnOnce(&State<L>, &Scenario) -> R) -> R {
        self.quiet(|s, sc| f(s, sc))
    }

    /// The robot's position, µm.
    pub fn position_um(&self) -> i64 {
        self.view(|s, _| s.pos_um)
    }

    /// What the legs do, whether the robot stands at `place`, and the walking speed: a walk's
    /// questions in one look.
    pub fn legs(&self, place: Place) -> (Motion, bool, u16) {
        self.view(|s, sc| (s.motion, s.pos_um == place.at_um(sc), s.speed_permille))
    }

    /// When the world next changes by itself.
    pub fn next_event(&self) -> Option<Instant> {
        let now = Instant::now().as_millis();
        // As `view`, but the answer is kept: it changes nothing else.
        self.state
            .lock(|cell| {
                let mut s = cell.borrow_mut();
                s.advance_to(now, self.scenario);
                s.next_event(self.scenario)
            })
            .map(Instant::from_millis)
    }

    /// Starts walking to `place`.
    pub fn walk_to(&self, place: Place) {
        self.with(|s, sc| {
            s.target_um = place.at_um(sc);
            s.motion = Motion::Walking;
            s.emit(WorldEvent::Walk);
        });
    }

    /// Stops walking; this is the reaction to every registered obstacle not yet reacted to.
    pub fn stop(&self) {
        self.with(|s, _| {
            s.react();
            if s.motion == Motion::Walking {
                s.motion = Motion::Idle;
                s.emit(WorldEvent::Stop);
            }
        });
    }

    /// Starts a side step around the nearest registered obstacle ahead.
    pub fn begin_avoid(&self) {
        self.side_step(None);
    }

    /// Starts a side step around obstacle `shown` if it is still there and ahead: the one a
    /// body's sensors were last shown (the bench's robot, whose registrations reach the world
    /// from its recording after its wheels have moved); else as [`begin_avoid`](Self::begin_avoid).
    pub fn begin_avoid_around(&self, shown: Option<u8>) {
        self.side_step(shown);
    }

    fn side_step(&self, shown: Option<u8>) {
        self.with(|s, sc| {
            let ahead = |o: &Obstacle| o.pos_um >= s.pos_um;
            let target = shown
                .filter(|&i| s.present & 1 << i != 0)
                .filter(|&i| s.obstacles.get(usize::from(i)).is_some_and(ahead))
                .or_else(|| {
                    s.present_obstacles()
                        .filter(|(_, o)| ahead(o) && o.sensed)
                        .min_by_key(|(_, o)| o.pos_um)
                        .map(|(i, _)| i as u8)
                });
            s.motion = Motion::Avoiding {
                // A side step takes time, so that it cannot repeat at one instant.
                left_ms: sc.avoid_ms.max(1),
                target,
            };
            s.emit(WorldEvent::AvoidStarted(target));
        });
    }

    /// Notes that a walk to a door is over. Interferences stop once the robot stands at the
    /// kitchen door: the person interfered with the walk to it.
    pub fn arrived(&self, place: Place) {
        self.with(|s, _| {
            if place == Place::KitchenDoor && s.at_door_ms.is_none() {
                s.at_door_ms = Some(s.now);
            }
            if let Some(a) = s.arrived.get_mut(place.slot()) {
                *a = true;
            }
            s.emit(WorldEvent::Arrived(place));
        });
    }

    /// Puts a robot that stands within `within_um` of `place`, and no obstacle between, on
    /// it: where a robot that dead-reckons its walk (the bench's wheeled one) stops is its
    /// place, to its odometry's error. Whether the robot stands at `place` now.
    pub fn dock(&self, place: Place, within_um: i64) -> bool {
        self.with(|s, sc| {
            let at = place.at_um(sc);
            let (from, to) = (s.pos_um.min(at), s.pos_um.max(at));
            let between = s
                .present_obstacles()
                .any(|(_, o)| o.pos_um > from && o.pos_um < to);
            if s.pos_um.abs_diff(at) <= within_um.unsigned_abs() && !between {
                s.pos_um = at;
            }
            s.pos_um == at
        })
    }

    /// A robot that dead-reckons its walk (the bench's wheeled one) stopped on its way to
    /// `place`: within [`ARRIVAL_UM`] of it with no obstacle between, it stands there
    /// ([`dock`](Self::dock)) and has arrived ([`arrived`](Self::arrived), once). Whether it
    /// has arrived at `place`.
    pub fn stopped_near(&self, place: Place) -> bool {
        let arrived = self.view(|s, sc| s.door_here(sc) == Some(place));
        if arrived || !self.dock(place, ARRIVAL_UM) {
            return arrived;
        }
        self.arrived(place);
        true
    }

    /// Whether the robot stands at the kitchen door, having arrived there.
    pub fn at_kitchen_door(&self) -> bool {
        self.door_here() == Some(Place::KitchenDoor)
    }

    /// The door the robot stands at, having arrived there: its marker is in view, and its
    /// handle gives when the door is not locked (the back door never is).
    pub fn door_here(&self) -> Option<Place> {
        self.view(|s, sc| s.door_here(sc))
    }

    /// Whether the handle of the door the robot stands at gives under its hand now (what
    /// [`handle`](Self::handle) reads, with no sample).
    pub fn door_gives(&self) -> bool {
        self.view(|s, sc| s.door_gives(sc))
    }

    /// Where a body that drives forward from where it stands (the bench's wheeled robot)
    /// goes: the kitchen door before it, the back door after it (a locked kitchen door is
    /// passed by, the back door being further along); `None` at a door it may push.
    pub fn drive_target(&self) -> Option<Place> {
        self.view(|s, sc| match s.door_here(sc) {
            Some(Place::KitchenDoor) if sc.door_locked => Some(Place::BackDoor),
            Some(_) => None,
            None if s.pos_um < sc.door_um => Some(Place::KitchenDoor),
            None => Some(Place::BackDoor),
        })
    }

    /// A body that pushes (the bench's wheeled robot) drove for `ms` at a door: a drive of at
    /// least [`DOOR_PUSH_MS`] pushes the closed door open when its handle gives (the kitchen
    /// door not locked), and goes through the open door into the kitchen. A shorter one, or
    /// one anywhere else, does nothing.
    pub fn push_door(&self, ms: u64) {
        let Some(place) = self.door_here() else {
            return;
        };
        if ms < DOOR_PUSH_MS {
            return;
        }
        let (open, gives) = self.view(|s, sc| {
            (
                s.door_open.get(place.slot()).copied().unwrap_or(false),
                s.door_gives(sc),
            )
        });
        if !open && gives {
            self.open_door(place);
        } else if open {
            self.enter_kitchen();
        }
    }

    /// Opens a door.
    pub fn open_door(&self, place: Place) {
        self.with(|s, _| {
            if let Some(open) = s.door_open.get_mut(place.slot()) {
                *open = true;
            }
            s.emit(WorldEvent::DoorOpened(place));
        });
    }

    /// Whether the robot is in the kitchen.
    pub fn in_kitchen(&self) -> bool {
        self.view(|s, _| s.in_kitchen)
    }

    /// Presses the handle of the door the robot stands at: whether it gives (the back door's
    /// always, the kitchen door's when it is not locked; `Locked` only at a locked kitchen
    /// door).
    pub fn handle(&self) -> bool {
        self.with(|s, sc| {
            let at_door = s.pos_um == sc.door_um;
            let gives = s.door_gives(sc);
            s.emit(WorldEvent::Sample(Device::Handle, u32::from(gives)));
            s.delivered(Device::Handle);
            if at_door && sc.door_locked {
                s.emit(WorldEvent::Locked);
            }
            gives
        })
    }

    /// Enters the kitchen.
    pub fn enter_kitchen(&self) {
        self.with(|s, _| {
            s.in_kitchen = true;
            s.emit(WorldEvent::InKitchen);
        });
    }

    /// Holds (SMPA sense phase) or releases the actuators.
    pub fn hold(&self, held: bool) {
        self.with(|s, _| {
            if s.held != held {
                s.held = held;
                s.emit(WorldEvent::Held(held));
            }
        });
    }

    /// Stops everything at once (the runtime cancelled the behaviour).
    pub fn halt(&self) {
        self.with(|s, _| {
            s.react();
            s.motion = Motion::Idle;
            s.emit(WorldEvent::Stop);
        });
    }

    /// Switches a sensor on or off.
    pub fn power(&self, device: Device, on: bool) {
        self.with(|s, sc| {
            if let Some(slot) = s.on.get_mut(device.slot()) {
                *slot = on;
            }
            // An interval that spans a switch-off is no gap.
            if let Some(g) = s.gaps.get_mut(device.slot()) {
                g.last_ms = None;
            }
            s.emit(if on {
                WorldEvent::SensorOn(device)
            } else {
                WorldEvent::SensorOff(device)
            });
            // Switching a sensor on can make an obstacle certain at once.
            s.settle(sc);
        });
    }

    /// Starts a sonar read: what the echo will say describes the world now (the nearest box
    /// ahead within range, with noise; or nothing in range, `max_m`; or lost to dropout), and
    /// is delivered by [`sonar_deliver`](Self::sonar_deliver) when the read completes. A
    /// faulty sonar (the scenario's `fault`, once it has started) registers nothing: it reports
    /// beyond its range, or the same reading again and again.
    pub fn sonar_read(&self) -> Echo {
        self.quiet(|s, sc| {
            let fault = s.fault(sc);
            s.sonar_read(sc, fault)
        })
    }

    /// [`sonar_read`](Self::sonar_read) unless the sonar has fallen silent (`None`: its echo
    /// never comes, and no read starts): one look at the world for both.
    pub fn sonar_start(&self) -> Option<Echo> {
        self.quiet(|s, sc| {
            let fault = s.fault(sc);
            (fault != Some(FaultKind::Silent)).then(|| s.sonar_read(sc, fault))
        })
    }

    /// Completes a sonar read: the reading reaches the robot now, registering the boxes it
    /// saw that are still there (by the same rule the robot applies,
    /// [`Sonar::registers`](crate::scenario::Sonar::registers)). `None`: the sample was lost.
    pub fn sonar_deliver(&self, echo: Echo) -> Option<u32> {
        self.with(|s, _| {
            let Some(mm) = echo.mm else {
                s.emit(WorldEvent::SampleLost(Device::Sonar));
                return None;
            };
            if echo.sticks {
                s.stuck_mm = Some(mm);
            }
            // What the read saw counts only for obstacles still there: one taken away while the
            // echo travelled cannot be registered any more.
            for i in bits((echo.certain | echo.registers) & s.present) {
                let bit = 1u32 << i;
                let Some(o) = s.obstacles.get_mut(i) else {
                    continue;
                };
                if echo.certain & bit != 0 {
                    o.certain_samples = o.certain_samples.saturating_add(1);
                }
                if echo.registers & bit != 0 {
                    s.register(i, Device::Sonar);
                }
            }
            s.emit(WorldEvent::Sample(Device::Sonar, mm));
            Some(mm)
        })
    }

    /// [`sonar_deliver`](Self::sonar_deliver) of what the robot's ranger measured of `echo`,
    /// `mm`, rather than the world's reading: a real ranger times the echo, and an edge that
    /// waits moves its reading (the bench's firmware measures the pulse the world sent). The
    /// measured reading decides whether the boxes the echo came from register, by the same
    /// rule. `None`, and nothing registers, when the world's echo was lost.
    pub fn sonar_deliver_measured(&self, mut echo: Echo, mm: u32) -> Option<u32> {
        if echo.mm.is_none() {
            return self.sonar_deliver(echo);
        }
        echo.mm = Some(mm);
        echo.registers = if self.scenario.sonar.registers(i64::from(mm)) {
            echo.from
        } else {
            0
        };
        self.sonar_deliver(echo)
    }

    /// Starts a bumper read: what the robot touches now.
    pub fn bumper_read(&self) -> Touch {
        self.quiet(|s, sc| {
            s.log.read_started(Device::Bumper);
            Touch {
                touching: s
                    .present_obstacles()
                    .filter(|(_, o)| s.felt(o, sc))
                    .fold(0, |acc, (i, _)| acc | 1 << i),
            }
        })
    }

    /// Completes a bumper read: 2 when the read felt contact (registering every obstacle
    /// touched that is still there), else 1.
    pub fn bumper_deliver(&self, touch: Touch) -> u8 {
        self.with(|s, _| {
            // Contact with an obstacle taken away meanwhile is still contact felt.
            let level = if touch.touching != 0 { 2 } else { 1 };
            for i in bits(touch.touching & s.present) {
                let Some(o) = s.obstacles.get_mut(i) else {
                    continue;
                };
                o.certain_samples = o.certain_samples.saturating_add(1);
                s.register(i, Device::Bumper);
            }
            s.emit(WorldEvent::Sample(Device::Bumper, u32::from(level)));
            level
        })
    }

    /// [`bumper_deliver`](Self::bumper_deliver) of what the robot's switch read, `pressed`,
    /// rather than the world's contact: a read that found the switch open registers nothing,
    /// whatever touched the robot (the bench's firmware reads its pin through a debounce).
    pub fn bumper_deliver_measured(&self, touch: Touch, pressed: bool) -> u8 {
        let touching = if pressed { touch.touching } else { 0 };
        self.bumper_deliver(Touch { touching })
    }

    /// The robot accepted a delivered sample of `device` (its driver found it plausible):
    /// counted for the largest gap between samples. The camera and the handle count theirs
    /// themselves.
    pub fn sample_delivered(&self, device: Device) {
        self.quiet(|s, _| s.delivered(device));
    }

    /// A sonar read that starts and completes now, accepted.
    pub fn sonar(&self) -> Option<u32> {
        let mm = self.sonar_deliver(self.sonar_read());
        if mm.is_some() {
            self.sample_delivered(Device::Sonar);
        }
        mm
    }

    /// A bumper read that starts and completes now, accepted.
    pub fn bumper(&self) -> u8 {
        let level = self.bumper_deliver(self.bumper_read());
        self.sample_delivered(Device::Bumper);
        level
    }

    /// Sets the walking speed, in thousandths of the scenario's `speed_mps` (1 to 1000).
    pub fn set_speed(&self, permille: u16) {
        self.with(|s, _| {
            let permille = permille.clamp(1, 1000);
            if s.speed_permille != permille {
                s.speed_permille = permille;
                s.emit(WorldEvent::Speed(permille));
            }
        });
    }

    /// One camera image: whether the door handle is in view (the robot is at the door).
    pub fn camera(&self) -> bool {
        self.quiet(|s, sc| {
            let seen = s.pos_um == sc.door_um;
            s.emit(WorldEvent::Sample(Device::Camera, u32::from(seen)));
            s.delivered(Device::Camera);
            seen
        })
    }

    /// The outcome so far.
    #[inline(never)] // Its temporaries stay out of the frame of the task polling a run.
    pub fn tally(&self) -> Tally {
        self.view(|s, _| {
            // One pass, no closures through pointers: the firmware's stack bound stays tight.
            let mut t = Tally {
                interferences: s.obstacles.len() as u32,
                placed: 0,
                detected: 0,
                collisions: 0,
                detectable: 0,
                max_reaction_ms: None,
                reached_door: s.at_door_ms.is_some(),
                on_ms: s.on_ms,
                sample_gap_max_ms: s.gaps.map(|g| g.max_ms),
            };
            let placed = s
                .obstacles
                .iter()
                .filter(|o| matches!(o.phase, Phase::Present | Phase::Removed | Phase::Avoided));
            for o in placed {
                t.placed += 1;
                t.detectable += u32::from(o.certain_samples > 0);
                match o.fate {
                    Fate::Detected(_) => {
                        t.detected += 1;
                        let reaction = o.reaction_ms.map(u64::from);
                        t.max_reaction_ms = t.max_reaction_ms.max(reaction);
                    }
                    Fate::Collided => t.collisions += 1,
                    Fate::Unmet => {}
                }
            }
            t
        })
    }

    /// How each interference ended, in scenario order.
    #[inline(never)] // Its temporaries stay out of the frame of the task polling a run.
    pub fn obstacles(&self) -> Vec<ObstacleReport, MAX_INTERFERENCES> {
        self.view(|s, _| {
            s.obstacles
                .iter()
                .map(|o| ObstacleReport {
                    fate: o.fate,
                    placed: matches!(o.phase, Phase::Present | Phase::Removed | Phase::Avoided),
                    skipped: o.phase == Phase::Skipped,
                    detectable: o.certain_samples > 0,
                    reaction_ms: o.reaction_ms.map(u64::from),
                })
                .collect()
        })
    }

    /// Hash of every world event so far.
    pub fn hash(&self) -> TraceHash {
        self.state.lock(|cell| cell.borrow().hash)
    }

    /// Reads the log (a world kept in a `static`, which cannot be given up).
    pub fn with_log<R>(&self, f: impl FnOnce(&L) -> R) -> R {
        self.state.lock(|cell| f(&cell.borrow().log))
    }

    /// Gives the world up and returns its log.
    pub fn into_log(self) -> L {
        self.state.into_inner().into_inner().log
    }
}

//! The Fetch Tea robot's body in the [`World`]: moved by its motor pins, answering its sensors
//! through theirs. The one body of the simulator, QEMU and the bench: psmpa-sim and the QEMU
//! image hand it the pins of simulated devices, `cargo xtask hil` the emulated chip's.
//!
//! * **Motors.** Each wheel turns at its PWM duty while STBY is high and its direction pins
//!   say forward (IN1 high, IN2 low); a brake (both high), a coast (both low), reverse or
//!   standby stop it. The robot walks at the mean of its wheels: the walking duty of the
//!   robot's settings moves it at the scenario's `speed_mps` (the speed the robot is
//!   calibrated to), a smaller duty proportionally slower, a larger one no faster. The world
//!   is one straight line and the robot has no inertia: it stops when the wheels do.
//! * **Sonar** (HC-SR04, a driven output). On the falling edge of a trigger pulse of at least
//!   10 µs the module reads the world ([`World::sonar_start`]) and raises its echo 250 µs
//!   later for as long as sound takes to the obstacle and back (5.83 µs a millimetre);
//!   nothing in range is the module's own 38 ms pulse; a lost reading (dropout, a silent
//!   sonar) no pulse at all. With the scenario's read latency (`latency_ms`) the echo ends
//!   that long after the trigger at the earliest: it rises later, as wide.
//! * **Switches** (the bumper, the handle's limit switch) close to ground when pressed and are
//!   open otherwise: an open switch drives nothing (`None`), and the pin reads what its pad's
//!   pull gives it. The bumper closes when the world's bumper would feel an obstacle, and
//!   bounces: 1 to 3 bounces of 50 to 400 µs before it settles, from a generator seeded with
//!   the scenario's seed; the bumper's read latency delays its edges. The **marker** (an open
//!   collector) pulls low while the robot stands at a door; the handle's switch closes there
//!   when the door is not locked (the back door never is).
//! * **What the robot sensed** comes from its own record of its samples ([`Body::recorded`]:
//!   the bench's flight recording, the simulator's trace): the world registers an obstacle
//!   from a sample the robot took (a sonar reading below the threshold, a bumper read that
//!   found the switch closed) and switches its sensors with the robot's own `SensorOn` and
//!   `SensorOff`.
//! * **Doors and side steps** are the world's rules ([`World::drive_target`],
//!   [`World::stopped_near`], [`World::push_door`], [`World::begin_avoid_around`]); the body
//!   maps the motor pins to them: a drive goes to the next door (past a locked kitchen door,
//!   on to the back door), a stop on the way may be an arrival (within 20 mm, its dead
//!   reckoning's error), a drive at a door a push, a pivot a side step.
//!
//! Time is in nanoseconds since the run's start, the world's `embassy-time` instant.

use embassy_sync::blocking_mutex::raw::{NoopRawMutex, RawMutex};
use heapless::Deque;
use psmpa_core::Value;
use psmpa_core::record::{Frame, Input};

use crate::scenario::{FaultKind, Scenario, to_mm};
use crate::world::{Device, Echo, Motion, Place, World, WorldLog};

/// The pins (the boards' pin table).
pub mod pin {
    /// HC-SR04 trigger (output).
    pub const TRIGGER: u8 = 2;
    /// HC-SR04 echo (input).
    pub const ECHO: u8 = 3;
    /// Bump switch (input, low when pressed).
    pub const BUMPER: u8 = 4;
    /// Marker sensor (input, low when the marker is seen).
    pub const MARKER: u8 = 5;
    /// Handle limit switch (input, low when pressed).
    pub const HANDLE: u8 = 6;
    /// TB6612FNG STBY (output).
    pub const STBY: u8 = 9;
    /// Left IN1, IN2 (outputs), PWM.
    pub const LEFT: [u8; 3] = [10, 11, 12];
    /// Right IN1, IN2 (outputs), PWM.
    pub const RIGHT: [u8; 3] = [13, 14, 15];
}

/// The shortest trigger pulse the HC-SR04 fires on.
pub const TRIGGER_NS: u64 = 10_000;
/// The HC-SR04 raises its echo this long after the trigger falls (its 40 kHz burst).
pub const ECHO_DELAY_NS: u64 = 250_000;
/// What a sonar out of range measures: nearer than the HC-SR04's 20 mm minimum.
pub const TOO_NEAR_MM: u32 = 10;
/// The module's own pulse when no echo returns.
pub const NO_ECHO_NS: u64 = 38_000_000;

/// An echo pulse that the driver reads back as `mm` (its `width · 343 / 2000`, rounded
/// down): the middle of that millimetre's widths, so that a few microseconds of timing on
/// either edge do not change the reading.
pub const fn echo_ns(mm: u32) -> u64 {
    // (mm + 0.5) · 2000 / 343 µs.
    (mm as u64 * 2 + 1) * 1_000_000 / 343
}

/// SplitMix64: the switches' bounces, the same draws on every machine.
pub fn splitmix(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A fault played on the pins (a bench's; a scenario's own sonar fault the body plays
/// itself).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PinFault {
    /// The sonar never answers from `at_ns`: no echo pulse.
    NoEcho {
        /// From when, ns.
        at_ns: u64,
    },
    /// The echo line sticks high at the first trigger from `at_ns`.
    EchoStuck {
        /// From when, ns.
        at_ns: u64,
    },
    /// Every echo from `at_ns` is shorter than the module's minimum range.
    TooNear {
        /// From when, ns.
        at_ns: u64,
    },
    /// The marker sensor sees nothing from `at_ns` (its strip covered, its lens dirty): it
    /// leaves its open-drain output open, even at a door.
    MarkerGone {
        /// From when, ns.
        at_ns: u64,
    },
    /// The bumper's wire chatters (an edge every `every_ns`) from `at_ns` to `until_ns`.
    Chatter {
        /// From when, ns.
        at_ns: u64,
        /// Until when, ns.
        until_ns: u64,
        /// Between edges, ns.
        every_ns: u64,
    },
}

/// What the body does to an input from an instant on: drives it low or high, or leaves it
/// open (`None`: a switch that is open, a marker that sees nothing), so that it reads what the
/// pad gives it: (pin, level, ns).
pub type Set = (u8, Option<bool>, u64);

/// An echo the module sent for one trigger.
#[derive(Clone, Copy, Debug)]
struct Sent {
    /// The trigger's fall, ns.
    trigger_ns: u64,
    /// The reading its width means, mm (the module's own pulse: the sonar's range); `None`:
    /// no pulse.
    mm: Option<u32>,
    /// The world's read, until a recorded sample or loss delivers it.
    echo: Option<Echo>,
}

/// The slots of the mission's sensors the body has: sonar, bumper, camera, handle.
pub const SLOTS: usize = 4;

/// The world's device of each slot.
pub const DEVICES: [Device; SLOTS] = [
    Device::Sonar,
    Device::Bumper,
    Device::Camera,
    Device::Handle,
];

/// What a call did that a judge of the robot watches.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Effects {
    /// An echo was sent: its fall, ns, and the millimetres it means.
    pub echo: Option<(u64, u32)>,
    /// The wheels stopped driving.
    pub stopped: bool,
    /// The bump switch changed: when it settles, ns, and whether closed.
    pub bumper: Option<(u64, bool)>,
}

/// A sonar reading the robot recorded, against the echo the module sent for it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SonarSample {
    /// No trigger came before it.
    NoTrigger,
    /// The echo of the trigger before it meant this (`None`: no pulse at all).
    Meant(Option<u32>),
    /// A value no ranger gives (not delivered to the world).
    NotARange,
}

/// The body of one run.
pub struct Body<'s, L: WorldLog, M: RawMutex = NoopRawMutex> {
    world: World<'s, L, M>,
    sc: &'s Scenario,
    walk_permille: u16,
    /// The mission's sensor ids of the sonar, the bumper, the camera and the handle.
    ids: [usize; SLOTS],
    stby: bool,
    dirs: [[bool; 2]; 2],
    duties: [u16; 2],
    driving: Option<u64>,
    /// The wheels turn the robot around an obstacle (the world's side step).
    stepping: bool,
    /// The door the robot drives to ([`World::drive_target`]), while a drive walks (not a
    /// push at a door).
    target: Place,
    walking: bool,
    speed: u16,
    /// The last echoes sent, newest last.
    sent: Deque<Sent, 8>,
    /// The trigger's level, and its last rise, ns.
    trigger_high: bool,
    trigger_rise: Option<u64>,
    /// The obstacle the pins last showed the robot (an echo within the threshold, the bump
    /// switch closing): what a side step then goes around.
    shown: Option<u8>,
    /// What the body does to each input now.
    levels: [Option<bool>; 8],
    rng: u64,
    fault: Option<PinFault>,
    stuck: bool,
}

impl<'s, L: WorldLog, M: RawMutex> Body<'s, L, M> {
    /// The body in the world of `sc`, logging into `log`, for a robot whose walking duty is
    /// `walk_permille`, with the mission's sensor ids `ids` (sonar, bumper, camera, handle)
    /// and an optional fault on the pins.
    pub fn new(
        sc: &'s Scenario,
        log: L,
        walk_permille: u16,
        ids: [usize; SLOTS],
        fault: Option<PinFault>,
    ) -> Self {
        let mut levels = [None; 8];
        for (pin, level) in Self::initial_inputs() {
            if let Some(l) = levels.get_mut(usize::from(pin)) {
                *l = level;
            }
        }
        Self {
            world: World::new(sc, log),
            sc,
            walk_permille: walk_permille.max(1),
            ids,
            stby: false,
            dirs: [[false; 2]; 2],
            duties: [0; 2],
            driving: None,
            stepping: false,
            target: Place::KitchenDoor,
            walking: false,
            speed: 1000,
            sent: Deque::new(),
            trigger_high: false,
            trigger_rise: None,
            shown: None,
            levels,
            rng: sc.seed ^ 0x9E37_79B9_7F4A_7C15,
            fault,
            stuck: false,
        }
    }

    /// How fast the wheels turn the robot now, counterclockwise positive: the right wheel's
    /// duty less the left's, thousandths (0 in standby). A judge that integrates it over time
    /// has the robot's heading; the body itself needs none.
    pub fn turn_rate(&self) -> i64 {
        if self.stby {
            self.wheel(1) - self.wheel(0)
        } else {
            0
        }
    }

    /// The robot's walking duty, thousandths.
    pub const fn walk_permille(&self) -> u16 {
        self.walk_permille
    }

    /// The inputs at reset: the echo driven low, the switches open, the marker seeing nothing.
    pub const fn initial_inputs() -> [(u8, Option<bool>); 4] {
        [
            (pin::ECHO, Some(false)),
            (pin::BUMPER, None),
            (pin::MARKER, None),
            (pin::HANDLE, None),
        ]
    }

    /// The world.
    pub const fn world(&self) -> &World<'s, L, M> {
        &self.world
    }

    /// The world, at the end.
    pub fn into_world(self) -> World<'s, L, M> {
        self.world
    }

    /// The scenario.
    pub const fn scenario(&self) -> &'s Scenario {
        self.sc
    }

    /// When the world next changes by itself, ns.
    pub fn next_event_ns(&self) -> Option<u64> {
        self.world
            .next_event()
            .map(|t| t.as_millis().saturating_mul(1_000_000))
    }

    /// Whether the wheels drive the robot along its way now.
    pub const fn driving(&self) -> bool {
        self.driving.is_some()
    }

    /// Whether the H-bridge short-brakes both wheels now (the TB6612's truth table: STBY high
    /// and, on each channel, IN1 and IN2 high, or one of them with the PWM low). Otherwise a
    /// wheel that does not drive coasts (IN1 and IN2 low, or STBY low) and rolls on.
    pub fn braked(&self) -> bool {
        self.stby
            && self
                .dirs
                .iter()
                .zip(self.duties)
                .all(|([a, b], duty)| (*a && *b) || (*a != *b && duty == 0))
    }

    /// A random draw from SplitMix64: the bounces.
    fn draw(&mut self, below: u64) -> u64 {
        splitmix(&mut self.rng) % below.max(1)
    }

    fn set(&mut self, out: &mut impl FnMut(Set), pin: u8, level: Option<bool>, at: u64) {
        if let Some(l) = self.levels.get_mut(usize::from(pin)) {
            *l = level;
        }
        out((pin, level, at));
    }

    /// A switch closes (to ground) or opens at `at`, bouncing first; returns when it settles.
    fn bounce(&mut self, out: &mut impl FnMut(Set), pin: u8, closed: bool, at: u64) -> u64 {
        let (to, from) = if closed {
            (Some(false), None)
        } else {
            (None, Some(false))
        };
        let mut t = at;
        for _ in 0..1 + self.draw(3) {
            self.set(out, pin, to, t);
            t = t.saturating_add(50_000 + self.draw(350_000));
            self.set(out, pin, from, t);
            t = t.saturating_add(50_000 + self.draw(350_000));
        }
        self.set(out, pin, to, t);
        t
    }

    /// Whether the body holds `pin` low now (a closed switch, a marker that sees).
    pub fn closed(&self, pin: u8) -> bool {
        self.levels.get(usize::from(pin)).copied().flatten() == Some(false)
    }

    /// The wheels' direction and duty: +duty forward, -duty reverse, 0 otherwise.
    fn wheel(&self, i: usize) -> i64 {
        match (self.dirs.get(i), self.duties.get(i)) {
            (Some([true, false]), Some(d)) => i64::from(*d),
            (Some([false, true]), Some(d)) => -i64::from(*d),
            _ => 0,
        }
    }

    /// The robot's speed from its motor pins: thousandths of the scenario's, 0 when it does
    /// not drive forward.
    fn wheel_speed(&self) -> u16 {
        if !self.stby {
            return 0;
        }
        let mean = (self.wheel(0) + self.wheel(1)) / 2;
        if mean <= 0 {
            return 0;
        }
        let permille = mean * 1000 / i64::from(self.walk_permille);
        u16::try_from(permille.clamp(1, 1000)).unwrap_or(1000)
    }

    /// An output pin moved at `ns`: the robot starts, stops or changes speed; the sonar's
    /// module reads the world when its trigger falls. The inputs it changes go to `out`.
    pub fn output(&mut self, pin: u8, level: bool, ns: u64, out: &mut impl FnMut(Set)) -> Effects {
        let mut fx = Effects::default();
        let was_high = pin == pin::TRIGGER && core::mem::replace(&mut self.trigger_high, level);
        match pin {
            pin::TRIGGER if level && !was_high => self.trigger_rise = Some(ns),
            pin::TRIGGER if level => {}
            // The module fires on the fall of a pulse of at least 10 µs: not on the pin
            // becoming an output, low, at boot.
            pin::TRIGGER => {
                let pulse = self.trigger_rise.map(|rise| ns.saturating_sub(rise));
                if was_high && pulse.is_some_and(|p| p >= TRIGGER_NS) {
                    fx.echo = self.trigger(ns, out);
                }
            }
            pin::STBY => self.stby = level,
            p if p == pin::LEFT[0] => self.dirs[0][0] = level,
            p if p == pin::LEFT[1] => self.dirs[0][1] = level,
            p if p == pin::RIGHT[0] => self.dirs[1][0] = level,
            p if p == pin::RIGHT[1] => self.dirs[1][1] = level,
            _ => {}
        }
        fx.stopped = self.motion(ns);
        fx.bumper = self.inputs_now(ns, out);
        fx
    }

    /// A PWM output's duty changed at `ns`.
    pub fn duty(&mut self, pin: u8, permille: u16, ns: u64, out: &mut impl FnMut(Set)) -> Effects {
        if pin == pin::LEFT[2] {
            self.duties[0] = permille;
        } else if pin == pin::RIGHT[2] {
            self.duties[1] = permille;
        }
        Effects {
            echo: None,
            stopped: self.motion(ns),
            bumper: self.inputs_now(ns, out),
        }
    }

    /// The scenario's sonar fault as the HC-SR04 shows it on its pins, once it has begun: a
    /// silent sonar answers nothing and a stuck one sends the same echo again and again (the
    /// world's read says so); one out of range, which the module cannot report beyond its
    /// range (that is its "nothing in range"), measures below its 20 mm minimum instead.
    fn scenario_fault(&self, ns: u64) -> Option<PinFault> {
        let (kind, at_ms) = self.sc.fault?;
        let at_ns = u64::from(at_ms).saturating_mul(1_000_000);
        (kind == FaultKind::OutOfRange && ns >= at_ns).then_some(PinFault::TooNear { at_ns })
    }

    /// The module fired at `ns`: its echo, if it sends one it times (fall, mm).
    fn trigger(&mut self, ns: u64, out: &mut impl FnMut(Set)) -> Option<(u64, u32)> {
        match self.fault.or(self.scenario_fault(ns)) {
            Some(PinFault::NoEcho { at_ns }) if ns >= at_ns => return None,
            Some(PinFault::TooNear { at_ns }) if ns >= at_ns => {
                let rise = ns + ECHO_DELAY_NS;
                self.set(out, pin::ECHO, Some(true), rise);
                self.set(out, pin::ECHO, Some(false), rise + echo_ns(TOO_NEAR_MM));
                return None;
            }
            Some(PinFault::EchoStuck { at_ns }) if ns >= at_ns => {
                if !self.stuck {
                    self.stuck = true;
                    self.set(out, pin::ECHO, Some(true), ns + ECHO_DELAY_NS);
                }
                return None;
            }
            _ => {}
        }
        // Silent: the module never answers.
        let echo = self.world.sonar_start()?;
        let max_mm = u32::try_from(to_mm(self.sc.sonar.max_um)).unwrap_or(u32::MAX);
        let mm = echo.mm().map(|mm| mm.min(max_mm));
        if self.sent.is_full() {
            self.sent.pop_front();
        }
        let _ = self.sent.push_back(Sent {
            trigger_ns: ns,
            mm,
            echo: Some(echo),
        });
        // Lost to dropout: no pulse.
        let mm = mm?;
        let width = if mm >= max_mm {
            NO_ECHO_NS
        } else {
            echo_ns(mm)
        };
        // A module that answers after the scenario's read latency: its echo ends then at the
        // earliest, as wide as the distance says, so it rises later.
        let latency = self.sc.sonar.latency_ms.saturating_mul(1_000_000);
        let rise = ns + ECHO_DELAY_NS.max(latency.saturating_sub(width));
        self.set(out, pin::ECHO, Some(true), rise);
        self.set(out, pin::ECHO, Some(false), rise + width);
        if self.sc.sonar.registers(i64::from(mm)) {
            self.shown = echo.came_from().or(self.shown);
        }
        Some((rise + width, mm))
    }

    /// Whether the wheels turn the robot on the spot: one forward, one backwards.
    fn pivoting(&self) -> bool {
        let turning = |i: usize| self.duties[i] > 0 && self.dirs[i][0] != self.dirs[i][1];
        self.stby && turning(0) && turning(1) && self.dirs[0] != self.dirs[1]
    }

    /// Starts, stops or re-speeds the walk from the motor pins; whether it stopped. A pivot
    /// on the way to the door starts the world's side step around the obstacle the pins last
    /// showed it; until it is over and the wheels no longer turn the robot, the wheels are the
    /// step's, not the walk's.
    fn motion(&mut self, ns: u64) -> bool {
        let pivot = self.pivoting();
        if self.stepping {
            let (legs, _, _) = self.world.legs(self.target);
            if pivot || matches!(legs, Motion::Avoiding { .. }) {
                return false;
            }
            self.stepping = false;
        }
        let speed = if pivot { 0 } else { self.wheel_speed() };
        let mut stopped = false;
        match (self.driving, speed > 0) {
            (None, true) => {
                self.driving = Some(ns);
                self.speed = speed;
                self.walking = false;
                if let Some(target) = self.world.drive_target() {
                    self.target = target;
                    self.walking = true;
                    self.world.set_speed(speed);
                    self.world.walk_to(target);
                }
            }
            (Some(since), false) => {
                self.driving = None;
                self.world.stop();
                stopped = true;
                self.stopped(since, ns);
            }
            (Some(_), true) if speed != self.speed => {
                self.speed = speed;
                if self.walking {
                    self.world.set_speed(speed);
                }
            }
            _ => {}
        }
        if pivot && self.world.door_here().is_none() {
            self.stepping = true;
            self.world.begin_avoid_around(self.shown);
        }
        stopped
    }

    /// The robot stopped after driving since `since`: on its way, it may have arrived; at
    /// a door, it pushed the door for that long (the world's rules for a body that pushes).
    fn stopped(&mut self, since: u64, ns: u64) {
        if !core::mem::take(&mut self.walking) {
            self.world.push_door(ns.saturating_sub(since) / 1_000_000);
        } else {
            self.world.stopped_near(self.target);
        }
    }

    /// The slot (sonar, bumper, camera, handle) of a mission sensor id.
    pub fn slot(&self, id: usize) -> Option<usize> {
        self.ids.iter().position(|&i| i == id)
    }

    /// A frame of the robot's own record, recorded at `at_ns` and read at `ns`: the world
    /// follows what the robot switched and sampled. A sonar sample comes back with what its
    /// echo meant, for a judge, and a change of the bump switch as from
    /// [`inputs_now`](Self::inputs_now); the inputs it changes go to `out`.
    pub fn recorded(
        &mut self,
        at_ns: u64,
        frame: &Frame<1>,
        ns: u64,
        out: &mut impl FnMut(Set),
    ) -> (Option<SonarSample>, Option<(u64, bool)>) {
        if let Some((sensor, on)) = frame.power()
            && let Some(slot) = self.slot(sensor.index())
            && let Some(device) = DEVICES.get(slot)
        {
            self.world.power(*device, on);
        }
        let mut sonar = None;
        match frame.input() {
            Some(Input::Sample { sensor, value, .. }) => {
                if let Some(slot) = self.slot(sensor.index()) {
                    sonar = self.sample(slot, value, at_ns);
                }
            }
            Some(Input::Lost { sensor }) if self.slot(sensor.index()) == Some(0) => {
                // The module's echo, if it was one lost to dropout, is logged as that loss.
                if let Some(sent) = self.sent_before(at_ns)
                    && let Some(echo) = sent.echo.take()
                    && echo.mm().is_none()
                {
                    let _ = self.world.sonar_deliver(echo);
                }
            }
            _ => {}
        }
        (sonar, self.inputs_now(ns, out))
    }

    /// The echo sent for the last trigger before `at_ns`.
    fn sent_before(&mut self, at_ns: u64) -> Option<&mut Sent> {
        self.sent.iter_mut().rev().find(|s| s.trigger_ns <= at_ns)
    }

    /// A sample the robot recorded at `at_ns`, delivered to the world as the robot read it.
    fn sample(&mut self, slot: usize, value: Value, at_ns: u64) -> Option<SonarSample> {
        match slot {
            0 => {
                let max_mm = u32::try_from(to_mm(self.sc.sonar.max_um)).unwrap_or(u32::MAX);
                let read = match value {
                    Value::Mm(mm) => mm.unsigned_abs(),
                    // Nothing in range: the sonar's maximum, which registers nothing.
                    Value::NoEcho => max_mm,
                    _ => return Some(SonarSample::NotARange),
                };
                let Some(sent) = self.sent_before(at_ns) else {
                    return Some(SonarSample::NoTrigger);
                };
                let meant = sent.mm;
                if let Some(echo) = sent.echo.take() {
                    let _ = self.world.sonar_deliver_measured(echo, read);
                    self.world.sample_delivered(Device::Sonar);
                }
                Some(SonarSample::Meant(meant))
            }
            1 => {
                let touch = self.world.bumper_read();
                let _ = self
                    .world
                    .bumper_deliver_measured(touch, value == Value::Bool(true));
                self.world.sample_delivered(Device::Bumper);
                None
            }
            2 => {
                let _ = self.world.camera();
                None
            }
            _ => {
                let _ = self.world.handle();
                None
            }
        }
    }

    /// The inputs the world decides now: the bump switch, the marker, the handle. A change of
    /// the bump switch comes back: when it settles, and whether closed.
    pub fn inputs_now(&mut self, ns: u64, out: &mut impl FnMut(Set)) -> Option<(u64, bool)> {
        let chatter = match self.fault {
            Some(PinFault::Chatter {
                at_ns, until_ns, ..
            }) => ns >= at_ns && ns < until_ns,
            _ => false,
        };
        let touch = self.world.bumper_read();
        let pressed = touch.any();
        if pressed {
            self.shown = touch.felt().or(self.shown);
        }
        let mut bumper = None;
        if !chatter && self.closed(pin::BUMPER) != pressed {
            // A bumper that answers after the scenario's read latency: its contact shows that
            // much later.
            let at = ns.saturating_add(self.sc.bumper_latency_ms.saturating_mul(1_000_000));
            let settled = self.bounce(out, pin::BUMPER, pressed, at);
            bumper = Some((settled, pressed));
        }
        let blind = matches!(self.fault, Some(PinFault::MarkerGone { at_ns }) if ns >= at_ns);
        let seen = !blind && self.world.door_here().is_some();
        if self.closed(pin::MARKER) != seen {
            self.set(out, pin::MARKER, seen.then_some(false), ns);
        }
        let gives = seen && self.world.door_gives();
        if self.closed(pin::HANDLE) != gives {
            self.bounce(out, pin::HANDLE, gives, ns);
        }
        bumper
    }

    /// The chatter of a [`PinFault::Chatter`], all at once: the switch closing and opening,
    /// then open again.
    pub fn chatter(&mut self, out: &mut impl FnMut(Set)) {
        if let Some(PinFault::Chatter {
            at_ns,
            until_ns,
            every_ns,
        }) = self.fault
        {
            let mut t = at_ns;
            let mut closed = true;
            while t < until_ns {
                self.set(out, pin::BUMPER, closed.then_some(false), t);
                closed = !closed;
                t = t.saturating_add(every_ns.max(1));
            }
            self.set(out, pin::BUMPER, None, until_ns);
        }
    }

    /// Whether any wheel turns now (driving, stepping around, reversing).
    pub fn motors_on(&self) -> bool {
        self.stby && (0..2).any(|i| self.duties[i] > 0 && self.dirs[i][0] != self.dirs[i][1])
    }

    /// The world's device of a mission sensor id.
    pub fn device(&self, id: usize) -> Option<Device> {
        self.slot(id).and_then(|s| DEVICES.get(s).copied())
    }
}

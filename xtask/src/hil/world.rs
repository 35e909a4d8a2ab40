//! The project's world on the bench's pins: psmpa-sim's [`World`] of a scenario, moved by the
//! firmware's motor pins and answering its sensors through their pins, and judged only from
//! what a test rig sees: those pins and the chip's own flight recording ([`super::chip`]).
//!
//! * **Motors.** Each wheel turns at its PWM duty while STBY is high and its direction pins
//!   say forward (IN1 high, IN2 low); a brake (both high), a coast (both low), reverse or
//!   standby stop it. The robot walks at the mean of its wheels: the walking duty of the
//!   robot's settings moves it at the scenario's `speed_mps` (the speed the robot is
//!   calibrated to), a smaller duty proportionally slower, a larger one no faster. The world
//!   is one straight line and the robot has no inertia: it stops when the wheels do.
//! * **Sonar** (HC-SR04 on GP2/GP3, a driven output). On the falling edge of a trigger pulse
//!   of at least 10 µs the module reads the world ([`World::sonar_start`]) and raises its
//!   echo 250 µs later for as long as sound takes to the obstacle and back (5.83 µs a
//!   millimetre); nothing in range is the module's own 38 ms pulse; a lost reading (dropout,
//!   a silent sonar) no pulse at all. With the scenario's read latency (`latency_ms`) the echo
//!   ends that long after the trigger at the earliest: it rises later, as wide.
//! * **Switches** (the bumper on GP4, the handle's limit switch on GP6) close to ground when
//!   pressed and are open otherwise: an open switch drives nothing, and the pin reads what
//!   the chip's pad gives it (its pull-up, its pull-down, or a floating level: the harness).
//!   The bumper closes when the world's bumper would feel an obstacle (a touch of the
//!   scenario's minimum contact), and bounces: 1 to 3 bounces of 50 to 400 µs before it
//!   settles, from a generator seeded with the scenario's seed; the bumper's read latency
//!   (`latency_ms`) delays its edges as a slower sensor answers later. The **marker** (GP5, an open
//!   collector) pulls low while the robot stands at a door (the kitchen door, the back
//!   door); the handle's switch closes there when the door is not locked (the back door
//!   never is).
//! * **What the robot sensed** comes from its flight recording: the world registers an
//!   obstacle from a sample the robot recorded (a sonar reading below the threshold, a bumper
//!   read that found the switch closed), switches the world's sensors with the robot's own
//!   `SensorOn`/`SensorOff`, and checks every reading against what the rig put on the pins
//!   ([`BenchWorld::misreads`]): a reading the echo did not mean, a contact nothing made.
//! * **Reactions** are timed from the rig's side: an echo that means an obstacle within the
//!   threshold (by more than the reading's timing error), or the bump switch settling closed,
//!   while the robot drives, must be followed by the motor pins stopping.
//! * **Doors and side steps** are the world's rules ([`World::drive_target`],
//!   [`World::stopped_near`], [`World::push_door`], [`World::begin_avoid_around`]); this
//!   module only maps the motor pins to them: a drive goes to the next door (past a locked
//!   kitchen door, on to the back door), a stop on the way may be an arrival (within 20 mm,
//!   its dead reckoning's error), a drive at a door a push, a pivot a side step.
//!
//! Where the body differs from the simulator's NAO is listed in one place,
//! `super::body_difference`.

use std::collections::VecDeque;

use psmpa_core::Value;
use psmpa_core::record::{Frame, Input};
use psmpa_sim::scenario::{FaultKind, Scenario, to_mm};
use psmpa_sim::world::{Device, Echo, Motion, Place, World, WorldEvent, WorldLog};

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
/// What a sonar out of range measures on the bench: nearer than the HC-SR04's 20 mm minimum.
pub const TOO_NEAR_MM: u32 = 10;
/// The module's own pulse when no echo returns.
pub const NO_ECHO_NS: u64 = 38_000_000;
/// Cycles of the RP2040's 125 MHz clock a nanosecond: 8 ns a cycle.
pub const NS_PER_CYCLE: u64 = 8;

/// An echo pulse that the driver reads back as `mm` (its `width · 343 / 2000`, rounded
/// down): the middle of that millimetre's widths, so that a few microseconds of timing on
/// either edge do not change the reading.
pub fn echo_ns(mm: u32) -> u64 {
    // (mm + 0.5) · 2000 / 343 µs.
    (u64::from(mm) * 2 + 1) * 1_000_000 / 343
}

/// A fault the bench's world plays on the pins (the firmware's own faults are injected through
/// its test points, see [`super::fault`]).
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

/// The world's events with their time and place, for the report and the picture.
#[derive(Debug, Default)]
pub struct Events(pub Vec<(u64, i64, WorldEvent)>);

impl WorldLog for Events {
    fn log(&mut self, at_ms: u64, pos_um: i64, event: WorldEvent) {
        self.0.push((at_ms, pos_um, event));
    }
}

/// A sensor's health as the firmware reports it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct Health {
    /// Switched on.
    pub on: bool,
    /// Samples delivered.
    pub delivered: u32,
    /// Samples lost.
    pub lost: u32,
    /// Faults.
    pub failed: u32,
    /// The longest gap between two samples while on, µs.
    pub max_gap_us: u32,
    /// The last reading.
    pub value: u32,
}

/// Words per sensor in the firmware's health block (`boards/rp/src/log.rs`).
pub const HEALTH_SENSOR_WORDS: usize = 7;

impl Health {
    /// Sensor `i` of the health block's `words`.
    pub fn of(words: &[u32], i: usize) -> Self {
        let w = |k: usize| {
            words
                .get(1 + i * HEALTH_SENSOR_WORDS + k)
                .copied()
                .unwrap_or(0)
        };
        Self {
            on: w(0) == 1,
            delivered: w(1),
            lost: w(2),
            failed: w(3),
            max_gap_us: w(5),
            value: w(6),
        }
    }
}

/// What the rig does to an input from an instant on: drives it low or high, or leaves it open
/// (`None`: a switch that is open, a marker that sees nothing), so that it reads what the
/// chip's pad gives it.
pub type Set = (u8, Option<bool>, u64);

/// A reaction the bench waits for: an edge that shows an obstacle while the robot drives.
#[derive(Clone, Copy, Debug, Default)]
pub struct Reactions {
    /// The edge waiting for the motors to stop, ns.
    pub pending: Option<u64>,
    /// The worst reaction measured, cycles.
    pub worst_cycles: Option<u64>,
}

/// An echo the rig sent for one trigger.
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

/// The slots of the mission's sensors the bench knows: sonar, bumper, camera, handle.
pub const SLOTS: usize = 4;

/// What the robot's own recording says of one sensor: when it was on, when it sampled.
#[derive(Clone, Debug, Default)]
pub struct Sampled {
    /// Switched on and off: (ns, on), in order.
    pub power: Vec<(u64, bool)>,
    /// Delivered samples, ns.
    pub samples: Vec<u64>,
}

impl Sampled {
    /// Whether the sensor was on at `ns` (by its last switch before).
    pub fn on_at(&self, ns: u64) -> bool {
        self.power
            .iter()
            .take_while(|(t, _)| *t <= ns)
            .last()
            .is_some_and(|(_, on)| *on)
    }

    /// The longest interval between two consecutive instants of `at` (sorted) that lie in one
    /// stretch of the sensor being on, ns; `None` with fewer than two such instants.
    pub fn max_gap(&self, at: &[u64]) -> Option<u64> {
        let mut max = None;
        for pair in at.windows(2) {
            let (a, b) = (pair[0], pair[1]);
            let switched = self.power.iter().any(|(t, _)| *t > a && *t <= b);
            if self.on_at(a) && !switched {
                max = max.max(Some(b - a));
            }
        }
        max
    }
}

/// The world of one bench run.
pub struct BenchWorld<'s> {
    world: World<'s, Events>,
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
    sent: VecDeque<Sent>,
    /// The trigger's level.
    trigger_high: bool,
    /// The obstacle the pins last showed the robot (an echo within the threshold, the bump
    /// switch closing): what a side step then goes around.
    shown: Option<u8>,
    /// The fall of an echo that clearly means an obstacle, until the robot answers or the
    /// reaction is pending.
    watch: Option<u64>,
    /// What the rig does to each input now.
    levels: [Option<bool>; 8],
    /// When the bump switch closed and opened: (ns, closed), in order.
    bumper_closed: Vec<(u64, bool)>,
    rng: u64,
    fault: Option<PinFault>,
    stuck: bool,
    /// How far a reading may lie from what its echo meant, mm: an edge the sensing side
    /// serves late moves it.
    tolerance_mm: u32,
    /// Sonar, bumper.
    pub reactions: [Reactions; 2],
    /// Edges that showed an obstacle to a driving robot that never stopped for them: sensor,
    /// ns.
    pub unanswered: Vec<(usize, u64)>,
    /// What the recording says of each sensor.
    pub sampled: [Sampled; SLOTS],
    /// Readings that disagree with the pins: what the robot read, what the rig presented.
    pub misreads: Vec<String>,
    /// When the robot first recorded a sensor's failure, ns.
    pub sensor_failed: Option<u64>,
    /// The trigger's rising edges, ns.
    pub triggers: Vec<u64>,
}

impl<'s> BenchWorld<'s> {
    /// The world of `sc` for a robot whose walking duty is `walk_permille`, with the mission's
    /// sensor ids `ids` (sonar, bumper, camera, handle), an optional fault on the pins, and
    /// the most a sonar reading may lie from its echo, mm.
    pub fn new(
        sc: &'s Scenario,
        walk_permille: u16,
        ids: [usize; SLOTS],
        fault: Option<PinFault>,
        tolerance_mm: u32,
    ) -> Self {
        let mut levels = [None; 8];
        for (pin, level) in Self::initial_inputs() {
            levels[usize::from(pin)] = level;
        }
        Self {
            world: World::new(sc, Events::default()),
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

            sent: VecDeque::new(),
            trigger_high: false,
            shown: None,
            watch: None,
            levels,
            bumper_closed: Vec::new(),
            rng: sc.seed ^ 0x9E37_79B9_7F4A_7C15,
            fault,
            stuck: false,
            tolerance_mm,
            reactions: [Reactions::default(); 2],
            unanswered: Vec::new(),
            sampled: Default::default(),
            misreads: Vec::new(),
            sensor_failed: None,
            triggers: Vec::new(),
        }
    }

    /// The inputs at reset: the echo driven low, the switches open, the marker seeing nothing.
    pub fn initial_inputs() -> [(u8, Option<bool>); 4] {
        [
            (pin::ECHO, Some(false)),
            (pin::BUMPER, None),
            (pin::MARKER, None),
            (pin::HANDLE, None),
        ]
    }

    /// The world.
    pub fn world(&self) -> &World<'s, Events> {
        &self.world
    }

    /// When the world next changes by itself, ns.
    pub fn next_event_ns(&self) -> Option<u64> {
        self.world
            .next_event()
            .map(|t| t.as_millis().saturating_mul(1_000_000))
    }

    /// A random draw from SplitMix64: the bounces.
    fn draw(&mut self, below: u64) -> u64 {
        crate::splitmix::next(&mut self.rng) % below.max(1)
    }

    fn set(&mut self, out: &mut Vec<Set>, pin: u8, level: Option<bool>, at: u64) {
        if let Some(l) = self.levels.get_mut(usize::from(pin)) {
            *l = level;
        }
        if pin == pin::BUMPER {
            self.bumper_closed.push((at, level == Some(false)));
        }
        out.push((pin, level, at));
    }

    /// A switch closes (to ground) or opens at `at`, bouncing first; returns when it settles.
    fn bounce(&mut self, out: &mut Vec<Set>, pin: u8, closed: bool, at: u64) -> u64 {
        let (to, from) = if closed {
            (Some(false), None)
        } else {
            (None, Some(false))
        };
        let mut t = at;
        for _ in 0..1 + self.draw(3) {
            self.set(out, pin, to, t);
            t += 50_000 + self.draw(350_000);
            self.set(out, pin, from, t);
            t += 50_000 + self.draw(350_000);
        }
        self.set(out, pin, to, t);
        t
    }

    /// Whether the rig holds `pin` low now (a closed switch, a marker that sees).
    fn closed(&self, pin: u8) -> bool {
        self.levels.get(usize::from(pin)).copied().flatten() == Some(false)
    }

    /// The robot's speed from its motor pins: thousandths of the scenario's, 0 when it does
    /// not drive forward.
    fn wheel_speed(&self) -> u16 {
        if !self.stby {
            return 0;
        }
        let wheel = |i: usize| -> i64 {
            match (self.dirs[i], self.duties[i]) {
                ([true, false], d) => i64::from(d),
                ([false, true], d) => -i64::from(d),
                _ => 0,
            }
        };
        let mean = (wheel(0) + wheel(1)) / 2;
        if mean <= 0 {
            return 0;
        }
        let permille = mean * 1000 / i64::from(self.walk_permille);
        u16::try_from(permille.clamp(1, 1000)).unwrap_or(1000)
    }

    /// An output pin moved (or a duty changed) at `ns`: the robot starts, stops or changes
    /// speed; the sonar's module reads the world when its trigger falls.
    pub fn output(&mut self, pin: u8, level: bool, ns: u64) -> Vec<Set> {
        let mut out = Vec::new();
        // Whether the trigger was high before this edge.
        let was_high = pin == pin::TRIGGER && std::mem::replace(&mut self.trigger_high, level);
        match pin {
            pin::TRIGGER if level && !was_high => self.triggers.push(ns),
            pin::TRIGGER if level => {}
            // The module fires on the fall of a pulse of at least 10 µs: not on the pin
            // becoming an output, low, at boot.
            pin::TRIGGER => {
                let pulse = self.triggers.last().map(|rise| ns.saturating_sub(*rise));
                if was_high && pulse.is_some_and(|p| p >= TRIGGER_NS) {
                    self.trigger(ns, &mut out);
                }
            }
            pin::STBY => self.stby = level,
            p if p == pin::LEFT[0] => self.dirs[0][0] = level,
            p if p == pin::LEFT[1] => self.dirs[0][1] = level,
            p if p == pin::RIGHT[0] => self.dirs[1][0] = level,
            p if p == pin::RIGHT[1] => self.dirs[1][1] = level,
            _ => {}
        }
        self.motion(ns);
        self.inputs_now(ns, &mut out);
        out
    }

    /// A PWM output's duty changed at `ns`.
    pub fn duty(&mut self, pin: u8, permille: u16, ns: u64) -> Vec<Set> {
        if pin == pin::LEFT[2] {
            self.duties[0] = permille;
        } else if pin == pin::RIGHT[2] {
            self.duties[1] = permille;
        }
        self.motion(ns);
        let mut out = Vec::new();
        self.inputs_now(ns, &mut out);
        out
    }

    /// The scenario's sonar fault as the HC-SR04 shows it on its pins, once it has begun: a
    /// silent sonar answers nothing and a stuck one sends the same echo again and again (the
    /// world's read says so); one out of range, which the module cannot report beyond its
    /// range (that is its "nothing in range"), measures below its 20 mm minimum instead.
    fn scenario_fault(&self, ns: u64) -> Option<PinFault> {
        let (kind, at_ms) = self.sc.fault?;
        let at_ns = u64::from(at_ms) * 1_000_000;
        (kind == FaultKind::OutOfRange && ns >= at_ns).then_some(PinFault::TooNear { at_ns })
    }

    fn trigger(&mut self, ns: u64, out: &mut Vec<Set>) {
        match self.fault.or(self.scenario_fault(ns)) {
            Some(PinFault::NoEcho { at_ns }) if ns >= at_ns => return,
            Some(PinFault::TooNear { at_ns }) if ns >= at_ns => {
                let rise = ns + ECHO_DELAY_NS;
                self.set(out, pin::ECHO, Some(true), rise);
                self.set(out, pin::ECHO, Some(false), rise + echo_ns(TOO_NEAR_MM));
                return;
            }
            Some(PinFault::EchoStuck { at_ns }) if ns >= at_ns => {
                if !self.stuck {
                    self.stuck = true;
                    self.set(out, pin::ECHO, Some(true), ns + ECHO_DELAY_NS);
                }
                return;
            }
            _ => {}
        }
        let Some(echo) = self.world.sonar_start() else {
            // Silent: the module never answers.
            return;
        };
        let max_mm = u32::try_from(to_mm(self.sc.sonar.max_um)).unwrap_or(u32::MAX);
        let mm = echo.mm().map(|mm| mm.min(max_mm));
        if self.sent.len() == 8 {
            self.sent.pop_front();
        }
        self.sent.push_back(Sent {
            trigger_ns: ns,
            mm,
            echo: Some(echo),
        });
        let Some(mm) = mm else {
            // Lost to dropout: no pulse.
            return;
        };
        let width = if mm >= max_mm {
            NO_ECHO_NS
        } else {
            echo_ns(mm)
        };
        // A module that answers after the scenario's read latency: its echo ends then at the
        // earliest, as wide as the distance says, so it rises later.
        let latency = self.sc.sonar.latency_ms * 1_000_000;
        let rise = ns + ECHO_DELAY_NS.max(latency.saturating_sub(width));
        self.set(out, pin::ECHO, Some(true), rise);
        self.set(out, pin::ECHO, Some(false), rise + width);
        // An echo that means an obstacle whatever the reading's timing error: a driving robot
        // must stop once it has fallen.
        let clearly = i64::from(mm.saturating_add(self.tolerance_mm));
        if self.sc.sonar.registers(clearly) && self.watch.is_none() {
            self.watch = Some(rise + width);
        }
        if self.sc.sonar.registers(i64::from(mm)) {
            self.shown = echo.came_from().or(self.shown);
        }
    }

    /// An echo being watched has fallen by `ns`: if the robot drives, its reaction is pending.
    fn watched(&mut self, ns: u64) {
        if let Some(fall) = self.watch.filter(|f| *f <= ns) {
            self.watch = None;
            if self.driving.is_some() && self.reactions[0].pending.is_none() {
                self.reactions[0].pending = Some(fall);
            }
        }
    }

    /// Whether the wheels turn the robot on the spot: one forward, one backwards.
    fn pivoting(&self) -> bool {
        let turning = |i: usize| self.duties[i] > 0 && self.dirs[i][0] != self.dirs[i][1];
        self.stby && turning(0) && turning(1) && self.dirs[0] != self.dirs[1]
    }

    /// Starts, stops or re-speeds the walk from the motor pins. A pivot on the way to the
    /// door starts the world's side step around the obstacle the pins last showed it; until it is over
    /// and the wheels no longer turn the robot, the wheels are the step's, not the walk's.
    fn motion(&mut self, ns: u64) {
        self.watched(ns);
        let pivot = self.pivoting();
        if self.stepping {
            let (legs, _, _) = self.world.legs(self.target);
            if pivot || matches!(legs, Motion::Avoiding { .. }) {
                return;
            }
            self.stepping = false;
        }
        let speed = if pivot { 0 } else { self.wheel_speed() };
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
                for r in &mut self.reactions {
                    if let Some(edge) = r.pending.take() {
                        let cycles = ns.saturating_sub(edge) / NS_PER_CYCLE;
                        r.worst_cycles = r.worst_cycles.max(Some(cycles));
                    }
                }
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
    }

    /// The robot stopped after driving since `since`: on its way, it may have arrived; at
    /// a door, it pushed the door for that long (the world's rules for a body that pushes).
    fn stopped(&mut self, since: u64, ns: u64) {
        if !std::mem::take(&mut self.walking) {
            self.world.push_door(ns.saturating_sub(since) / 1_000_000);
        } else {
            self.world.stopped_near(self.target);
        }
    }

    /// The slot (sonar, bumper, camera, handle) of a mission sensor id.
    fn slot(&self, id: usize) -> Option<usize> {
        self.ids.iter().position(|&i| i == id)
    }

    /// A frame of the robot's flight recording, recorded at `at_ns` and read at `ns`: the
    /// world follows what the robot switched and sampled, and each reading is checked against
    /// the pins.
    pub fn recorded(&mut self, at_ns: u64, frame: &Frame<1>, ns: u64) -> Vec<Set> {
        if let Some((sensor, on)) = frame.power()
            && let Some(slot) = self.slot(sensor.index())
        {
            self.sampled[slot].power.push((at_ns, on));
            self.world.power(DEVICES[slot], on);
        }
        match frame.input() {
            Some(Input::Sample { sensor, value, .. }) => {
                if let Some(slot) = self.slot(sensor.index()) {
                    self.sampled[slot].samples.push(at_ns);
                    self.sample(slot, value, at_ns);
                }
            }
            Some(Input::Lost { sensor }) if self.slot(sensor.index()) == Some(0) => {
                // The rig's echo, if it was one it lost to dropout, is logged as that loss.
                if let Some(sent) = self.sent_before(at_ns)
                    && let Some(echo) = sent.echo.take()
                    && echo.mm().is_none()
                {
                    let _ = self.world.sonar_deliver(echo);
                }
            }
            Some(Input::Fault { .. }) => {
                self.sensor_failed.get_or_insert(at_ns);
            }
            _ => {}
        }
        let mut out = Vec::new();
        self.inputs_now(ns, &mut out);
        out
    }

    /// The echo sent for the last trigger before `at_ns`.
    fn sent_before(&mut self, at_ns: u64) -> Option<&mut Sent> {
        self.sent.iter_mut().rev().find(|s| s.trigger_ns <= at_ns)
    }

    /// A sample the robot recorded at `at_ns`, delivered to the world as the robot read it.
    fn sample(&mut self, slot: usize, value: Value, at_ns: u64) {
        let at = at_ns as f64 / 1e9;
        match slot {
            0 => {
                let max_mm = u32::try_from(to_mm(self.sc.sonar.max_um)).unwrap_or(u32::MAX);
                let tolerance = self.tolerance_mm;
                let read = match value {
                    Value::Mm(mm) => Some(mm.unsigned_abs()),
                    // Nothing in range: the sonar's maximum, which registers nothing.
                    Value::NoEcho => None,
                    _ => {
                        self.misreads
                            .push(format!("the sonar recorded {value:?} at {at:.3} s"));
                        return;
                    }
                };
                let Some(sent) = self.sent_before(at_ns) else {
                    self.misreads.push(format!(
                        "the sonar recorded a reading at {at:.3} s with no trigger before it"
                    ));
                    return;
                };
                let meant = sent.mm;
                let echo = sent.echo.take();
                let agrees = match (meant, read) {
                    (Some(m), None) => m >= max_mm,
                    (Some(m), Some(r)) => m < max_mm && m.abs_diff(r) <= tolerance,
                    (None, _) => false,
                };
                if !agrees {
                    let said = |mm: Option<u32>| match mm {
                        None => "nothing in range".to_owned(),
                        Some(mm) => format!("{mm} mm"),
                    };
                    let meant = match meant {
                        Some(m) if m >= max_mm => "nothing in range".to_owned(),
                        Some(m) => format!("{m} mm"),
                        None => "no echo at all".to_owned(),
                    };
                    self.misreads.push(format!(
                        "the sonar read {} at {at:.3} s where the rig's echo meant {meant} (within {tolerance} mm)",
                        said(read)
                    ));
                }
                if let Some(echo) = echo {
                    let _ = self
                        .world
                        .sonar_deliver_measured(echo, read.unwrap_or(max_mm));
                    self.world.sample_delivered(Device::Sonar);
                }
            }
            1 => {
                let pressed = value == Value::Bool(true);
                // A read that found the switch closed: it was, within a period and two
                // debounce times before (a read accepts a level that held for one).
                let window = (self.sc.bumper_period_ms + 2 * DEBOUNCE_MS + 1) * 1_000_000;
                if pressed && !self.bumper_closed_within(at_ns.saturating_sub(window), at_ns) {
                    self.misreads.push(format!(
                        "the bumper read contact at {at:.3} s where the rig had not closed its switch"
                    ));
                }
                let touch = self.world.bumper_read();
                let _ = self.world.bumper_deliver_measured(touch, pressed);
                self.world.sample_delivered(Device::Bumper);
            }
            2 => {
                let _ = self.world.camera();
            }
            _ => {
                let _ = self.world.handle();
            }
        }
    }

    /// Whether the rig held the bump switch closed at some instant of `[from, to]`.
    fn bumper_closed_within(&self, from: u64, to: u64) -> bool {
        let mut closed = false;
        for &(t, c) in &self.bumper_closed {
            if t > to {
                break;
            }
            if t < from {
                closed = c;
                continue;
            }
            if c || closed {
                return true;
            }
            closed = c;
        }
        closed
    }

    /// The inputs the world decides now: the bump switch, the marker, the handle.
    pub fn inputs_now(&mut self, ns: u64, out: &mut Vec<Set>) {
        self.watched(ns);
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
        if !chatter && self.closed(pin::BUMPER) != pressed {
            // A bumper that answers after the scenario's read latency: its contact shows that
            // much later.
            let at = ns + self.sc.bumper_latency_ms * 1_000_000;
            let settled = self.bounce(out, pin::BUMPER, pressed, at);
            if pressed && self.driving.is_some() && self.reactions[1].pending.is_none() {
                self.reactions[1].pending = Some(settled);
            }
        }
        let seen = self.world.door_here().is_some();
        if self.closed(pin::MARKER) != seen {
            self.set(out, pin::MARKER, seen.then_some(false), ns);
        }
        let gives = seen && self.world.door_gives();
        if self.closed(pin::HANDLE) != gives {
            self.bounce(out, pin::HANDLE, gives, ns);
        }
    }

    /// The chatter of a [`PinFault::Chatter`], all at once: the switch closing and opening,
    /// then open again.
    pub fn chatter(&mut self) -> Vec<Set> {
        let mut out = Vec::new();
        if let Some(PinFault::Chatter {
            at_ns,
            until_ns,
            every_ns,
        }) = self.fault
        {
            let mut t = at_ns;
            let mut closed = true;
            while t < until_ns {
                self.set(&mut out, pin::BUMPER, closed.then_some(false), t);
                closed = !closed;
                t += every_ns.max(1);
            }
            self.set(&mut out, pin::BUMPER, None, until_ns);
        }
        out
    }

    /// Whether any wheel turns now (driving, stepping around, reversing).
    pub fn motors_on(&self) -> bool {
        self.stby && (0..2).any(|i| self.duties[i] > 0 && self.dirs[i][0] != self.dirs[i][1])
    }

    /// At the end of a run: an obstacle shown to a driving robot that never stopped for it.
    pub fn finish(&mut self, ns: u64) {
        self.watched(ns);
        for (i, r) in self.reactions.iter_mut().enumerate() {
            if let Some(edge) = r.pending.take() {
                self.unanswered.push((i, edge));
            }
        }
    }

    /// The world's events, at the end.
    pub fn into_events(self) -> Vec<(u64, i64, WorldEvent)> {
        self.world.into_log().0
    }
}

/// The world's device of each slot.
const DEVICES: [Device; SLOTS] = [
    Device::Sonar,
    Device::Bumper,
    Device::Camera,
    Device::Handle,
];

/// The switches' debounce time, ms (`psmpa_drivers::switch::DEBOUNCE`).
const DEBOUNCE_MS: u64 = psmpa_drivers::switch::DEBOUNCE.as_millis();

#[cfg(test)]
mod tests {
    use super::*;
    use psmpa_drivers::hcsr04::mm_from_echo_us;

    use embassy_time::Instant;
    use psmpa_core::{FactSet, SensorId, TraceEvent};

    /// A box 0.35 m ahead from the start, for 10 s.
    fn boxed() -> Scenario {
        psmpa_sim::load::parse(
            std::path::Path::new("t.json"),
            br#"{"name": "t", "interferences": [{"kind": "box", "at_s": 0.0, "ahead_m": 0.35, "hold_s": 10.0}]}"#,
        )
        .unwrap()
    }

    /// The frame of a trace event (its own instant does not matter here).
    fn frame(event: TraceEvent) -> Frame<1> {
        Frame::of(Instant::from_ticks(0), &event)
    }

    fn sample(sensor: usize, value: Value) -> Frame<1> {
        frame(TraceEvent::Sample {
            sensor: SensorId::new(sensor).unwrap(),
            value,
            holds: FactSet::EMPTY,
        })
    }

    /// Plays one sonar read: switched on, triggered, and the reading `value` recorded.
    fn read_sonar(bw: &mut BenchWorld<'_>, value: Value) {
        let on = frame(TraceEvent::SensorOn {
            sensor: SensorId::new(0).unwrap(),
        });
        bw.recorded(0, &on, 0);
        bw.output(pin::TRIGGER, true, 1_000);
        bw.output(pin::TRIGGER, false, 11_000);
        bw.recorded(5_000_000, &sample(0, value), 5_000_000);
    }

    #[test]
    fn the_sonar_detects_only_what_the_robot_read() {
        let sc = boxed();
        // The echo the rig sends means 350 mm; the robot reads it so: detected by the sonar.
        let mut bw = BenchWorld::new(&sc, 600, [0, 1, 2, 3], None, 20);
        read_sonar(&mut bw, Value::Mm(352));
        assert!(bw.misreads.is_empty(), "{:?}", bw.misreads);
        assert_eq!(bw.world().tally().detected, 1);
        // A deaf sonar reads nothing in range: nothing is detected, and the reading is wrong.
        let mut bw = BenchWorld::new(&sc, 600, [0, 1, 2, 3], None, 20);
        read_sonar(&mut bw, Value::NoEcho);
        assert_eq!(bw.world().tally().detected, 0);
        assert!(
            bw.misreads[0].contains("where the rig's echo meant 350 mm"),
            "{:?}",
            bw.misreads
        );
        // Beyond the tolerance is a misread too.
        let mut bw = BenchWorld::new(&sc, 600, [0, 1, 2, 3], None, 20);
        read_sonar(&mut bw, Value::Mm(380));
        assert_eq!(bw.misreads.len(), 1);
    }

    #[test]
    fn a_slow_sonar_ends_its_echo_after_its_read_latency() {
        let rise_of = |latency: &str| {
            let json = format!(
                r#"{{"name": "t", "sonar": {{"latency_ms": {latency}}},
                    "interferences": [{{"kind": "box", "at_s": 0.0, "ahead_m": 0.35, "hold_s": 10.0}}]}}"#
            );
            let sc =
                psmpa_sim::load::parse(std::path::Path::new("t.json"), json.as_bytes()).unwrap();
            let mut bw = BenchWorld::new(&sc, 600, [0, 1, 2, 3], None, 20);
            bw.output(pin::TRIGGER, true, 0);
            let sets = bw.output(pin::TRIGGER, false, 10_000);
            let echo: Vec<u64> = sets
                .iter()
                .filter(|(p, _, _)| *p == pin::ECHO)
                .map(|(_, _, at)| *at)
                .collect();
            (echo[0], echo[1] - echo[0])
        };
        let (rise, width) = rise_of("0");
        assert_eq!(rise, 10_000 + ECHO_DELAY_NS);
        assert_eq!(width, echo_ns(350));
        // 40 ms: the same width, ending 40 ms after the trigger.
        let (rise, width) = rise_of("40");
        assert_eq!(width, echo_ns(350));
        assert_eq!(rise + width, 10_000 + 40_000_000);
    }

    #[test]
    fn a_trigger_too_short_or_never_raised_fires_nothing() {
        let sc = boxed();
        let mut bw = BenchWorld::new(&sc, 600, [0, 1, 2, 3], None, 20);
        // The pin becoming an output, low, at boot.
        assert!(bw.output(pin::TRIGGER, false, 1_000).is_empty());
        bw.output(pin::TRIGGER, true, 2_000);
        assert!(bw.output(pin::TRIGGER, false, 11_999).is_empty());
        assert!(bw.sent.is_empty());
    }

    /// Drives both wheels forward at 600 ‰ from `*t` for `ms`, then brakes; `*t` moves on.
    async fn drive(bw: &mut BenchWorld<'_>, t: &mut u64, ms: u64) {
        for p in [pin::STBY, pin::LEFT[0], pin::RIGHT[0]] {
            bw.output(p, true, *t);
        }
        bw.duty(pin::LEFT[2], 600, *t);
        bw.duty(pin::RIGHT[2], 600, *t);
        *t += ms * 1_000_000;
        embassy_time::Timer::at(Instant::from_millis(*t / 1_000_000)).await;
        bw.output(pin::LEFT[1], true, *t);
        bw.output(pin::RIGHT[1], true, *t);
        bw.output(pin::LEFT[1], false, *t);
        bw.output(pin::RIGHT[1], false, *t);
        bw.duty(pin::LEFT[2], 0, *t);
        bw.duty(pin::RIGHT[2], 0, *t);
    }

    /// The world's door events of a scenario `json` driven by `drives` (ms each), with
    /// `check` asked after each drive.
    fn doors_after(
        json: &[u8],
        drives: &[u64],
        check: impl Fn(usize, &BenchWorld<'_>),
    ) -> Vec<(u64, WorldEvent)> {
        let sc = psmpa_sim::load::parse(std::path::Path::new("t.json"), json).unwrap();
        let events = psmpa_sim::backend::simulate(
            async {
                let mut bw = BenchWorld::new(&sc, 600, [0, 1, 2, 3], None, 20);
                let mut t = 0;
                for (i, ms) in drives.iter().enumerate() {
                    drive(&mut bw, &mut t, *ms).await;
                    check(i, &bw);
                }
                bw.into_events()
            },
            embassy_time::Duration::from_secs(10),
        )
        .unwrap()
        .output;
        events
            .iter()
            .filter(|(_, _, e)| {
                matches!(
                    e,
                    WorldEvent::Arrived(_) | WorldEvent::DoorOpened(_) | WorldEvent::InKitchen
                )
            })
            .map(|(ms, _, e)| (*ms, *e))
            .collect()
    }

    #[test]
    fn the_wheels_arrive_push_the_door_and_go_through_by_the_worlds_rules() {
        // 99 of the 100 mm by dead reckoning: within 20 mm, at the door. Half a second of
        // pushing does not open it; a second does; a second more goes through.
        let doors = doors_after(
            br#"{"name": "t", "door_m": 0.1, "robot": {"speed_mps": 0.1}, "interferences": []}"#,
            &[990, 500, 1_000, 1_000],
            |i, bw| {
                if i == 0 {
                    assert!(bw.world().at_kitchen_door());
                    assert!(bw.closed(pin::MARKER) && bw.closed(pin::HANDLE));
                }
            },
        );
        assert_eq!(
            doors,
            [
                (990, WorldEvent::Arrived(Place::KitchenDoor)),
                (2_490, WorldEvent::DoorOpened(Place::KitchenDoor)),
                (3_490, WorldEvent::InKitchen)
            ]
        );
    }

    #[test]
    fn from_a_locked_door_the_wheels_go_on_to_the_back_door_and_through_it() {
        // At the locked kitchen door the marker shows and the handle does not give; a drive
        // from there goes on to the back door, 100 mm further, whose marker shows and whose
        // handle gives; pushing it opens it, and a second more goes through.
        let doors = doors_after(
            br#"{"name": "t", "door_m": 0.1, "robot": {"speed_mps": 0.1},
                 "doors": {"locked": true, "back_door_m": 0.1}, "interferences": []}"#,
            &[990, 1_010, 1_000, 1_000],
            |i, bw| match i {
                0 => {
                    assert_eq!(bw.world().door_here(), Some(Place::KitchenDoor));
                    assert!(bw.closed(pin::MARKER) && !bw.closed(pin::HANDLE));
                }
                1 => {
                    assert_eq!(bw.world().door_here(), Some(Place::BackDoor));
                    assert!(bw.closed(pin::MARKER) && bw.closed(pin::HANDLE));
                }
                _ => {}
            },
        );
        assert_eq!(
            doors,
            [
                (990, WorldEvent::Arrived(Place::KitchenDoor)),
                (2_000, WorldEvent::Arrived(Place::BackDoor)),
                (3_000, WorldEvent::DoorOpened(Place::BackDoor)),
                (4_000, WorldEvent::InKitchen)
            ]
        );
    }

    #[test]
    fn a_contact_the_rig_never_made_is_a_misread() {
        let sc = boxed();
        let mut bw = BenchWorld::new(&sc, 600, [0, 1, 2, 3], None, 20);
        bw.recorded(30_000_000, &sample(1, Value::Bool(true)), 30_000_000);
        assert!(bw.misreads[0].contains("the bumper read contact at 0.030 s"));
        assert_eq!(bw.world().tally().detected, 0);
        // A release read is no misread.
        let mut bw = BenchWorld::new(&sc, 600, [0, 1, 2, 3], None, 20);
        bw.recorded(30_000_000, &sample(1, Value::Bool(false)), 30_000_000);
        assert!(bw.misreads.is_empty());
    }

    #[test]
    fn a_switch_counts_as_closed_within_a_window_that_overlaps_it() {
        let sc = boxed();
        let mut bw = BenchWorld::new(&sc, 600, [0, 1, 2, 3], None, 20);
        let mut out = Vec::new();
        bw.set(&mut out, pin::BUMPER, Some(false), 100);
        bw.set(&mut out, pin::BUMPER, None, 200);
        assert!(bw.bumper_closed_within(0, 150));
        assert!(bw.bumper_closed_within(150, 160));
        assert!(bw.bumper_closed_within(190, 300));
        assert!(!bw.bumper_closed_within(0, 50));
        assert!(!bw.bumper_closed_within(250, 300));
        // An open switch drives nothing: the pin log says so.
        assert_eq!(
            out,
            [(pin::BUMPER, Some(false), 100), (pin::BUMPER, None, 200)]
        );
    }

    #[test]
    fn gaps_count_only_within_one_stretch_of_the_sensor_on() {
        let s = Sampled {
            power: vec![(0, true), (500, false), (900, true)],
            samples: vec![],
        };
        // 100 and 400 apart while on; 450 to 950 spans the switch-off.
        assert_eq!(s.max_gap(&[0, 100, 450, 950, 1_300]), Some(350));
        assert_eq!(s.max_gap(&[950]), None);
        assert!(s.on_at(499) && !s.on_at(500) && s.on_at(900));
    }

    #[test]
    fn an_echo_reads_back_as_its_millimetre_with_microseconds_to_spare() {
        for mm in [20u32, 349, 350, 499, 500, 2_549, 4_000] {
            let us = echo_ns(mm) / 1_000;
            // The driver times whole microseconds: 2 us early or late still read `mm`.
            for error in [-2i64, 0, 2] {
                let width = (us as i64 + error) as u64;
                assert_eq!(mm_from_echo_us(width), u64::from(mm), "{mm} mm, {error} us");
            }
        }
    }

    #[test]
    fn the_health_block_is_read_by_sensor() {
        // changes, then per sensor: on, delivered, lost, failed, last, max gap, value.
        let mut words = vec![9u32];
        words.extend([1, 5, 1, 0, 123, 100_000, 480]);
        words.extend([0, 7, 0, 1, 456, 20_000, 1]);
        let sonar = Health::of(&words, 0);
        assert_eq!(
            sonar,
            Health {
                on: true,
                delivered: 5,
                lost: 1,
                failed: 0,
                max_gap_us: 100_000,
                value: 480
            }
        );
        assert_eq!(Health::of(&words, 1).failed, 1);
        // A block too short reads as nothing seen.
        assert_eq!(Health::of(&words, 3), Health::default());
    }
}

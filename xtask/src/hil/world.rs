//! The project's world on the bench's pins: psmpa-sim's [`World`] of a scenario, moved by the
//! firmware's motor pins and answering its sensors through their pins.
//!
//! * **Motors.** Each wheel turns at its PWM duty while STBY is high and its direction pins
//!   say forward (IN1 high, IN2 low); a brake (both high), a coast (both low), reverse or
//!   standby stop it. The robot walks at the mean of its wheels: the walking duty of the
//!   robot's settings moves it at the scenario's `speed_mps` (the speed the robot is
//!   calibrated to), a smaller duty proportionally slower, a larger one no faster. The world
//!   is one straight line and the robot has no inertia: it stops when the wheels do.
//! * **Sonar** (HC-SR04 on GP2/GP3). On the trigger's falling edge the module reads the world
//!   ([`World::sonar_start`]) and raises its echo 250 µs later for as long as sound takes to
//!   the obstacle and back (5.83 µs a millimetre); nothing in range is the module's own 38 ms
//!   pulse; a lost reading (dropout, a silent sonar) no pulse at all.
//! * **Bumper** (GP4, pulled up, low when pressed) closes when the world's bumper would feel
//!   an obstacle (a touch of the scenario's minimum contact), and bounces: 1 to 3 bounces of
//!   50 to 400 µs before it settles, from a generator seeded with the scenario's seed.
//! * **Marker** (GP5, low when seen) while the robot stands at the kitchen door; **handle**
//!   limit switch (GP6, low when pressed, with bounce) while it stands there and the door is
//!   not locked.
//! * **What the robot sensed.** The firmware's health block says when a sample was delivered
//!   and what it read: the world counts a detection from the robot's own reading (an echo the
//!   firmware measured below the threshold, a bumper sample that felt contact), as psmpa-sim
//!   does from its robot's.
//! * **Doors.** A robot that stops within 20 mm of the kitchen door (its dead reckoning's
//!   error) is at the door. There, a drive of at least a second with the door closed pushes
//!   it open (if the handle gave) and one with the door open enters the kitchen.
//!
//! Where the body differs from the simulator's NAO: the wheeled robot brakes and waits for
//! the path to clear instead of stepping around an obstacle (so an obstacle stays until the
//! person takes it away, and a run takes longer), and it has no planner on board (at a
//! locked door it stops: the mission fails instead of taking the back door).

use psmpa_sim::scenario::{Scenario, to_mm};
use psmpa_sim::world::{Device, Echo, Place, World, WorldEvent, WorldLog};

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

/// The HC-SR04 raises its echo this long after the trigger falls (its 40 kHz burst).
pub const ECHO_DELAY_NS: u64 = 250_000;
/// The module's own pulse when no echo returns.
pub const NO_ECHO_NS: u64 = 38_000_000;
/// How far from the kitchen door a robot that stopped counts as at it, µm: the door's marker
/// is a reflective strip 40 mm long, centred on the door, which the marker sensor sees from
/// anywhere above it.
pub const ARRIVAL_UM: i64 = 20_000;
/// A drive at the door at least this long pushes the door open, or goes through it.
pub const DOOR_DRIVE_NS: u64 = 1_000_000_000;
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
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
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

/// Where the robot is in its task, as the world sees it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    /// Walking to the kitchen door (or stopped on the way).
    ToDoor,
    /// At the kitchen door.
    AtDoor,
}

/// A scheduled input level.
pub type Set = (u8, bool, u64);

/// A reaction the bench waits for: an edge that shows an obstacle while the robot drives.
#[derive(Clone, Copy, Debug, Default)]
pub struct Reactions {
    /// The edge waiting for the motors to stop, ns.
    pub pending: Option<u64>,
    /// The worst reaction measured, cycles.
    pub worst_cycles: Option<u64>,
    /// How many were measured.
    pub count: u32,
}

/// The world of one bench run.
pub struct BenchWorld<'s> {
    world: World<'s, Events>,
    sc: &'s Scenario,
    walk_permille: u16,
    /// The mission's sensor ids of the sonar, the bumper, the camera and the handle.
    ids: [usize; 4],
    stby: bool,
    dirs: [[bool; 2]; 2],
    duties: [u16; 2],
    driving: Option<u64>,
    speed: u16,
    phase: Phase,
    door_open: bool,
    /// The sonar read in flight, from its trigger to its delivery.
    echo: Option<Echo>,
    /// When the pulse of the echo in flight ends, ns.
    echo_end: Option<u64>,
    /// The levels last set on the inputs.
    levels: [bool; 8],
    health: [Health; 4],
    rng: u64,
    fault: Option<PinFault>,
    stuck: bool,
    /// Sonar, bumper.
    pub reactions: [Reactions; 2],
    /// Edges that showed an obstacle to a driving robot that never stopped for them: sensor,
    /// ns.
    pub unanswered: Vec<(usize, u64)>,
    /// Input changes, for the pin log.
    pub inputs: Vec<Set>,
    /// When the robot stopped driving, ns (the last time).
    pub stopped_ns: Option<u64>,
}

impl<'s> BenchWorld<'s> {
    /// The world of `sc` for a robot whose walking duty is `walk_permille`, with the mission's
    /// sensor ids `ids` (sonar, bumper, camera, handle) and an optional fault on the pins.
    pub fn new(
        sc: &'s Scenario,
        walk_permille: u16,
        ids: [usize; 4],
        fault: Option<PinFault>,
    ) -> Self {
        Self {
            world: World::new(sc, Events::default()),
            sc,
            walk_permille: walk_permille.max(1),
            ids,
            stby: false,
            dirs: [[false; 2]; 2],
            duties: [0; 2],
            driving: None,
            speed: 1000,
            phase: Phase::ToDoor,
            door_open: false,
            echo: None,
            echo_end: None,
            levels: [false, false, false, false, true, true, true, false],
            health: [Health::default(); 4],
            rng: sc.seed ^ 0x9E37_79B9_7F4A_7C15,
            fault,
            stuck: false,
            reactions: [Reactions::default(); 2],
            unanswered: Vec::new(),
            inputs: Vec::new(),
            stopped_ns: None,
        }
    }

    /// The inputs' levels at reset: echo low, the switches and the marker released (high).
    pub fn initial_inputs() -> [(u8, bool); 4] {
        [
            (pin::ECHO, false),
            (pin::BUMPER, true),
            (pin::MARKER, true),
            (pin::HANDLE, true),
        ]
    }

    /// The world.
    pub fn world(&self) -> &World<'s, Events> {
        &self.world
    }

    /// The firmware's last health report of sensor `i` (sonar, bumper, camera, handle).
    pub fn health(&self, i: usize) -> Health {
        self.health.get(i).copied().unwrap_or_default()
    }

    /// When the world next changes by itself, ns.
    pub fn next_event_ns(&self) -> Option<u64> {
        self.world
            .next_event()
            .map(|t| t.as_millis().saturating_mul(1_000_000))
    }

    /// A random draw from SplitMix64: the bounces.
    fn draw(&mut self, below: u64) -> u64 {
        self.rng = self.rng.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.rng;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        (z ^ (z >> 31)) % below.max(1)
    }

    fn set(&mut self, out: &mut Vec<Set>, pin: u8, level: bool, at: u64) {
        if let Some(l) = self.levels.get_mut(usize::from(pin)) {
            *l = level;
        }
        self.inputs.push((pin, level, at));
        out.push((pin, level, at));
    }

    /// A switch moves to `level` at `at`, bouncing first; returns when it settles.
    fn bounce(&mut self, out: &mut Vec<Set>, pin: u8, level: bool, at: u64) -> u64 {
        let mut t = at;
        for _ in 0..1 + self.draw(3) {
            self.set(out, pin, level, t);
            t += 50_000 + self.draw(350_000);
            self.set(out, pin, !level, t);
            t += 50_000 + self.draw(350_000);
        }
        self.set(out, pin, level, t);
        t
    }

    fn level(&self, pin: u8) -> bool {
        self.levels.get(usize::from(pin)).copied().unwrap_or(false)
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
        match pin {
            pin::TRIGGER if !level => self.trigger(ns, &mut out),
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

    fn trigger(&mut self, ns: u64, out: &mut Vec<Set>) {
        match self.fault {
            Some(PinFault::NoEcho { at_ns }) if ns >= at_ns => return,
            Some(PinFault::EchoStuck { at_ns }) if ns >= at_ns => {
                if !self.stuck {
                    self.stuck = true;
                    self.set(out, pin::ECHO, true, ns + ECHO_DELAY_NS);
                }
                return;
            }
            _ => {}
        }
        let Some(echo) = self.world.sonar_start() else {
            // Silent: the module never answers.
            return;
        };
        self.echo = Some(echo);
        self.echo_end = None;
        let Some(mm) = echo.mm() else {
            // Lost to dropout: no pulse.
            return;
        };
        let rise = ns + ECHO_DELAY_NS;
        let max_mm = u32::try_from(to_mm(self.sc.sonar.max_um)).unwrap_or(u32::MAX);
        let width = if mm >= max_mm {
            NO_ECHO_NS
        } else {
            echo_ns(mm)
        };
        self.set(out, pin::ECHO, true, rise);
        self.set(out, pin::ECHO, false, rise + width);
        self.echo_end = Some(rise + width);
    }

    /// Starts, stops or re-speeds the walk from the motor pins.
    fn motion(&mut self, ns: u64) {
        let speed = self.wheel_speed();
        match (self.driving, speed > 0) {
            (None, true) => {
                self.driving = Some(ns);
                self.speed = speed;
                if self.phase == Phase::ToDoor {
                    self.world.set_speed(speed);
                    self.world.walk_to(Place::KitchenDoor);
                }
            }
            (Some(since), false) => {
                self.driving = None;
                self.stopped_ns = Some(ns);
                self.world.stop();
                for r in &mut self.reactions {
                    if let Some(edge) = r.pending.take() {
                        let cycles = ns.saturating_sub(edge) / NS_PER_CYCLE;
                        r.worst_cycles = r.worst_cycles.max(Some(cycles));
                        r.count += 1;
                    }
                }
                self.stopped(since, ns);
            }
            (Some(_), true) if speed != self.speed => {
                self.speed = speed;
                if self.phase == Phase::ToDoor {
                    self.world.set_speed(speed);
                }
            }
            _ => {}
        }
    }

    /// The robot stopped after driving since `since`.
    fn stopped(&mut self, since: u64, ns: u64) {
        match self.phase {
            Phase::ToDoor => {
                if self.world.dock(Place::KitchenDoor, ARRIVAL_UM) {
                    self.world.arrived(Place::KitchenDoor);
                    self.phase = Phase::AtDoor;
                }
            }
            Phase::AtDoor if ns.saturating_sub(since) >= DOOR_DRIVE_NS => {
                if !self.door_open {
                    if !self.sc.door_locked {
                        self.world.open_door(Place::KitchenDoor);
                        self.door_open = true;
                    }
                } else {
                    self.world.enter_kitchen();
                }
            }
            Phase::AtDoor => {}
        }
    }

    /// The firmware's health block at `ns`: samples delivered, lost, sensors switched.
    pub fn health_report(&mut self, words: &[u32], ns: u64) -> Vec<Set> {
        for slot in 0..4 {
            let Some(&id) = self.ids.get(slot) else {
                continue;
            };
            let now = Health::of(words, id);
            let before = self.health[slot];
            self.health[slot] = now;
            let device = [
                Device::Sonar,
                Device::Bumper,
                Device::Camera,
                Device::Handle,
            ][slot];
            if now.on != before.on {
                self.world.power(device, now.on);
            }
            for _ in before.delivered..now.delivered {
                self.delivered(slot, now.value, ns);
            }
            if now.lost > before.lost && slot == 0 {
                // A read the firmware lost: the world's echo is not delivered (a dropout is
                // logged as the loss it was).
                if let Some(echo) = self.echo.take().filter(|e| e.mm().is_none()) {
                    let _ = self.world.sonar_deliver(echo);
                }
                self.echo_end = None;
            }
        }
        let mut out = Vec::new();
        self.inputs_now(ns, &mut out);
        out
    }

    fn delivered(&mut self, slot: usize, value: u32, ns: u64) {
        match slot {
            0 => {
                if let Some(echo) = self.echo.take() {
                    let _ = if value == u32::MAX {
                        self.world.sonar_deliver(echo)
                    } else {
                        self.world.sonar_deliver_measured(echo, value)
                    };
                    self.world.sample_delivered(Device::Sonar);
                }
                // The robot's ranger read an obstacle, the end of its echo showed it: a driving
                // robot must stop.
                let end = self.echo_end.take();
                let shows = value != u32::MAX && self.sc.sonar.registers(i64::from(value));
                if let Some(edge) = end.filter(|_| shows)
                    && self.driving.is_some()
                    && self.reactions[0].pending.is_none()
                {
                    self.reactions[0].pending = Some(edge.min(ns));
                }
            }
            1 => {
                let touch = self.world.bumper_read();
                let _ = self.world.bumper_deliver(touch);
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

    /// The inputs the world decides now: the bump switch, the marker, the handle.
    pub fn inputs_now(&mut self, ns: u64, out: &mut Vec<Set>) {
        let chatter = match self.fault {
            Some(PinFault::Chatter {
                at_ns, until_ns, ..
            }) => ns >= at_ns && ns < until_ns,
            _ => false,
        };
        // Pressed pulls the pin low.
        let pressed = self.world.bumper_read().any();
        if !chatter && self.level(pin::BUMPER) == pressed {
            let settled = self.bounce(out, pin::BUMPER, !pressed, ns);
            if pressed && self.driving.is_some() && self.reactions[1].pending.is_none() {
                self.reactions[1].pending = Some(settled);
            }
        }
        let (_, at_door, _) = self.world.legs(Place::KitchenDoor);
        let marker = !(at_door && self.phase == Phase::AtDoor);
        if self.level(pin::MARKER) != marker {
            self.set(out, pin::MARKER, marker, ns);
        }
        let handle = !(at_door && self.phase == Phase::AtDoor && !self.sc.door_locked);
        if self.level(pin::HANDLE) != handle {
            self.bounce(out, pin::HANDLE, handle, ns);
        }
    }

    /// The chatter of a [`PinFault::Chatter`], all at once: its edges, then the level the
    /// world wants back.
    pub fn chatter(&mut self) -> Vec<Set> {
        let mut out = Vec::new();
        if let Some(PinFault::Chatter {
            at_ns,
            until_ns,
            every_ns,
        }) = self.fault
        {
            let mut t = at_ns;
            let mut level = false;
            while t < until_ns {
                self.set(&mut out, pin::BUMPER, level, t);
                level = !level;
                t += every_ns.max(1);
            }
            // Released: as before the chatter.
            self.set(&mut out, pin::BUMPER, true, until_ns);
        }
        out
    }

    /// Whether the motors drive now.
    pub fn driving(&self) -> bool {
        self.driving.is_some()
    }

    /// At the end of a run: an obstacle shown to a driving robot that never stopped for it.
    pub fn finish(&mut self) {
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

#[cfg(test)]
mod tests {
    use super::*;
    use psmpa_drivers::hcsr04::mm_from_echo_us;

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

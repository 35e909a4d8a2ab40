//! The project's world on the bench's pins: psmpa-sim's [`Body`] of the Fetch Tea robot in
//! the [`World`] of a scenario (the one body psmpa-sim and the QEMU image run too), moved by
//! the firmware's motor pins and answering its sensors through their pins, and judged only
//! from what a test rig sees: those pins and the chip's own flight recording
//! ([`super::chip`]). What the body does with the pins: [`psmpa_sim::body`].
//!
//! This module is the judge around it:
//!
//! * **What the robot sensed** comes from its flight recording (the body registers obstacles
//!   from it), and every reading is checked against what the rig put on the pins
//!   ([`BenchWorld::misreads`]): a reading the echo did not mean, a contact nothing made.
//! * **Reactions** are timed from the rig's side: an echo that means an obstacle within the
//!   threshold (by more than the reading's timing error), or the bump switch settling closed,
//!   while the robot drives, must be followed by the motor pins stopping.

use psmpa_core::Value;
use psmpa_core::record::{Frame, Input};
use psmpa_sim::body::{Body, Effects, SonarSample};
use psmpa_sim::scenario::{Scenario, to_mm};
use psmpa_sim::world::{World, WorldEvent, WorldLog};

#[cfg(test)]
use psmpa_sim::body::{ECHO_DELAY_NS, echo_ns};
pub use psmpa_sim::body::{PinFault, SLOTS, Set, pin};

/// How far off its way a walk may set off, as ms of turning on the spot at the walking duty:
/// the wheels' pins are written one after the other, microseconds apart, and a turn back
/// lasts as long as the turn away to the tick.
pub const HEADING_SLACK_MS: i64 = 1;

/// Cycles of the RP2040's 125 MHz clock a nanosecond: 8 ns a cycle.
pub const NS_PER_CYCLE: u64 = 8;

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

/// A reaction the bench waits for: an edge that shows an obstacle while the robot drives.
#[derive(Clone, Copy, Debug, Default)]
pub struct Reactions {
    /// The edge waiting for the motors to stop, ns.
    pub pending: Option<u64>,
    /// The worst reaction measured, cycles.
    pub worst_cycles: Option<u64>,
}

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

/// How far the wheels have turned the robot from its heading at the start (where its way
/// lies), integrated from their pins: the right wheel's duty less the left's, thousandths,
/// times ns, counterclockwise positive; and when it was last brought up to date, ns.
#[derive(Clone, Copy, Debug, Default)]
struct Heading {
    turned: i64,
    at: u64,
}

impl Heading {
    /// Brings it up to `ns`, under the wheels' turning `rate` since the last pin change.
    fn until(&mut self, rate: i64, ns: u64) {
        let dt = i64::try_from(ns.saturating_sub(self.at)).unwrap_or(i64::MAX);
        self.at = self.at.max(ns);
        self.turned = self.turned.saturating_add(rate.saturating_mul(dt));
    }

    /// As milliseconds of turning on the spot at the walking duty (one wheel forward and one
    /// back): a side step that turns back as far as it turned away leaves it at 0.
    fn ms(&self, walk_permille: u16) -> i64 {
        self.turned / (2 * i64::from(walk_permille.max(1)) * 1_000_000)
    }
}

/// The world of one bench run: the body, and the judge's view of it.
pub struct BenchWorld<'s> {
    body: Body<'s, Events>,
    sc: &'s Scenario,
    /// The fall of an echo that clearly means an obstacle, until the robot answers or the
    /// reaction is pending.
    watch: Option<u64>,
    /// When the bump switch closed and opened: (ns, closed), in order.
    bumper_closed: Vec<(u64, bool)>,
    /// How far a reading may lie from what its echo meant, mm: an edge the sensing side
    /// serves late moves it.
    tolerance_mm: u32,
    /// Sonar, bumper.
    pub reactions: [Reactions; 2],
    /// Edges that showed an obstacle to a driving robot that never stopped for them: sensor,
    /// ns.
    pub unanswered: Vec<(usize, u64)>,
    /// Reactions that let the wheels coast to a stop instead of braking them: sensor, the
    /// obstacle's edge and the stop, ns.
    pub coasted: Vec<(usize, u64, u64)>,
    /// Walks the wheels set off on facing away from the robot's way (their turns did not
    /// cancel): ns, and how far off, as ms of turning on the spot.
    pub off_course: Vec<(u64, i64)>,
    /// Whether the wheels drove the robot along its way at the last pin change.
    was_driving: bool,
    /// How far the wheels have turned the robot since the start, from their pins.
    heading: Heading,
    /// What the recording says of each sensor.
    pub sampled: [Sampled; SLOTS],
    /// Readings that disagree with the pins: what the robot read, what the rig presented.
    pub misreads: Vec<String>,
    /// When the robot first recorded a sensor's failure, ns.
    pub sensor_failed: Option<u64>,
    /// The trigger's rising edges, ns.
    pub triggers: Vec<u64>,
    /// The trigger's level.
    trigger_high: bool,
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
        Self {
            body: Body::new(sc, Events::default(), walk_permille, ids, fault),
            sc,
            watch: None,
            bumper_closed: Vec::new(),
            tolerance_mm,
            reactions: [Reactions::default(); 2],
            unanswered: Vec::new(),
            coasted: Vec::new(),
            off_course: Vec::new(),
            was_driving: false,
            heading: Heading::default(),
            sampled: Default::default(),
            misreads: Vec::new(),
            sensor_failed: None,
            triggers: Vec::new(),
            trigger_high: false,
        }
    }

    /// The inputs at reset: the echo driven low, the switches open, the marker seeing nothing.
    pub fn initial_inputs() -> [(u8, Option<bool>); 4] {
        Body::<Events>::initial_inputs()
    }

    /// The world.
    pub fn world(&self) -> &World<'s, Events> {
        self.body.world()
    }

    /// When the world next changes by itself, ns.
    pub fn next_event_ns(&self) -> Option<u64> {
        self.body.next_event_ns()
    }

    /// Collects what the body sets, logging the bump switch.
    fn collect(log: &mut Vec<(u64, bool)>, out: &mut Vec<Set>) -> impl FnMut(Set) {
        move |set: Set| {
            if set.0 == pin::BUMPER {
                log.push((set.2, set.1 == Some(false)));
            }
            out.push(set);
        }
    }

    /// Whether the rig holds `pin` low now (a closed switch, a marker that sees).
    #[cfg(test)]
    fn closed(&self, pin: u8) -> bool {
        self.body.closed(pin)
    }

    /// What a call of the body did, judged: an echo that clearly means an obstacle is
    /// watched, a stop answers the pending reactions, a bump switch closing on a driving
    /// robot asks for one.
    fn judge(&mut self, fx: Effects, ns: u64) {
        if let Some((fall, mm)) = fx.echo {
            // An echo that means an obstacle whatever the reading's timing error: a driving
            // robot must stop once it has fallen.
            let clearly = i64::from(mm.saturating_add(self.tolerance_mm));
            if self.sc.sonar.registers(clearly) && self.watch.is_none() {
                self.watch = Some(fall);
            }
        }
        if fx.stopped {
            let braked = self.body.braked();
            for (i, r) in self.reactions.iter_mut().enumerate() {
                if let Some(edge) = r.pending.take() {
                    let cycles = ns.saturating_sub(edge) / NS_PER_CYCLE;
                    r.worst_cycles = r.worst_cycles.max(Some(cycles));
                    if !braked {
                        self.coasted.push((i, edge, ns));
                    }
                }
            }
        }
        let driving = self.body.driving();
        if driving && !self.was_driving {
            // Once a heading: the wheels' pins change one after the other, and a walk may
            // seem to set off between two of them.
            let off = self.heading.ms(self.body.walk_permille());
            let again = self.off_course.last().is_some_and(|(_, last)| *last == off);
            if off.abs() > HEADING_SLACK_MS && !again {
                self.off_course.push((ns, off));
            }
        }
        self.was_driving = driving;
        self.watched(ns);
        if let Some((settled, true)) = fx.bumper
            && self.body.driving()
            && self.reactions[1].pending.is_none()
        {
            self.reactions[1].pending = Some(settled);
        }
    }

    /// An output pin moved (or a duty changed) at `ns`: the robot starts, stops or changes
    /// speed; the sonar's module reads the world when its trigger falls.
    pub fn output(&mut self, pin: u8, level: bool, ns: u64) -> Vec<Set> {
        self.heading.until(self.body.turn_rate(), ns);
        if pin == pin::TRIGGER {
            if level && !self.trigger_high {
                self.triggers.push(ns);
            }
            self.trigger_high = level;
        }
        self.watched(ns);
        let mut out = Vec::new();
        let fx = self.body.output(
            pin,
            level,
            ns,
            &mut Self::collect(&mut self.bumper_closed, &mut out),
        );
        self.judge(fx, ns);
        out
    }

    /// A PWM output's duty changed at `ns`.
    pub fn duty(&mut self, pin: u8, permille: u16, ns: u64) -> Vec<Set> {
        self.heading.until(self.body.turn_rate(), ns);
        self.watched(ns);
        let mut out = Vec::new();
        let fx = self.body.duty(
            pin,
            permille,
            ns,
            &mut Self::collect(&mut self.bumper_closed, &mut out),
        );
        self.judge(fx, ns);
        out
    }

    /// An echo being watched has fallen by `ns`: if the robot drives, its reaction is pending.
    fn watched(&mut self, ns: u64) {
        if let Some(fall) = self.watch.filter(|f| *f <= ns) {
            self.watch = None;
            if self.body.driving() && self.reactions[0].pending.is_none() {
                self.reactions[0].pending = Some(fall);
            }
        }
    }

    /// A frame of the robot's flight recording, recorded at `at_ns` and read at `ns`: the
    /// world follows what the robot switched and sampled, and each reading is checked against
    /// the pins.
    pub fn recorded(&mut self, at_ns: u64, frame: &Frame<1>, ns: u64) -> Vec<Set> {
        if let Some((sensor, on)) = frame.power()
            && let Some(slot) = self.body.slot(sensor.index())
        {
            self.sampled[slot].power.push((at_ns, on));
        }
        let mut sample = None;
        match frame.input() {
            Some(Input::Sample { sensor, value, .. }) => {
                if let Some(slot) = self.body.slot(sensor.index()) {
                    self.sampled[slot].samples.push(at_ns);
                    sample = Some((slot, value));
                    if slot == 1 {
                        self.bumper_read(value, at_ns);
                    }
                }
            }
            Some(Input::Fault { .. }) => {
                self.sensor_failed.get_or_insert(at_ns);
            }
            _ => {}
        }
        self.watched(ns);
        let mut out = Vec::new();
        let (sonar, bumper) = self.body.recorded(
            at_ns,
            frame,
            ns,
            &mut Self::collect(&mut self.bumper_closed, &mut out),
        );
        if let (Some((_, value)), Some(sonar)) = (sample, sonar) {
            self.sonar_read(value, sonar, at_ns);
        }
        self.judge(
            Effects {
                bumper,
                ..Effects::default()
            },
            ns,
        );
        out
    }

    /// A sonar reading against the echo the rig sent for it.
    fn sonar_read(&mut self, value: Value, sonar: SonarSample, at_ns: u64) {
        let at = at_ns as f64 / 1e9;
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
        let meant = match sonar {
            SonarSample::Meant(meant) => meant,
            SonarSample::NoTrigger => {
                self.misreads.push(format!(
                    "the sonar recorded a reading at {at:.3} s with no trigger before it"
                ));
                return;
            }
            SonarSample::NotARange => return,
        };
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
    }

    /// A bumper reading: one that found the switch closed must find it so on the pins,
    /// within a period and two debounce times before (a read accepts a level that held for
    /// one).
    fn bumper_read(&mut self, value: Value, at_ns: u64) {
        let at = at_ns as f64 / 1e9;
        let pressed = value == Value::Bool(true);
        let window = (self.sc.bumper_period_ms + 2 * DEBOUNCE_MS + 1) * 1_000_000;
        if pressed && !self.bumper_closed_within(at_ns.saturating_sub(window), at_ns) {
            self.misreads.push(format!(
                "the bumper read contact at {at:.3} s where the rig had not closed its switch"
            ));
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
        let bumper = self
            .body
            .inputs_now(ns, &mut Self::collect(&mut self.bumper_closed, out));
        self.judge(
            Effects {
                bumper,
                ..Effects::default()
            },
            ns,
        );
    }

    /// The chatter of a [`PinFault::Chatter`], all at once: the switch closing and opening,
    /// then open again.
    pub fn chatter(&mut self) -> Vec<Set> {
        let mut out = Vec::new();
        self.body
            .chatter(&mut Self::collect(&mut self.bumper_closed, &mut out));
        out
    }

    /// Whether any wheel turns now (driving, stepping around, reversing).
    pub fn motors_on(&self) -> bool {
        self.body.motors_on()
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
        self.body.into_world().into_log().0
    }
}

/// The switches' debounce time, ms (`psmpa_drivers::switch::DEBOUNCE`).
const DEBOUNCE_MS: u64 = psmpa_drivers::switch::DEBOUNCE.as_millis();

#[cfg(test)]
mod tests {
    use super::*;
    use psmpa_drivers::hcsr04::mm_from_echo_us;

    use embassy_time::Instant;
    use psmpa_core::{FactSet, SensorId, TraceEvent};
    use psmpa_sim::world::Place;

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
        assert!(bw.world().tally().detected == 0);
    }

    /// A wheel's IN1 and IN2: forward, backwards, short brake, off (coasting).
    const AHEAD: (bool, bool) = (true, false);
    const BACK: (bool, bool) = (false, true);
    const BRAKE: (bool, bool) = (true, true);
    const OFF: (bool, bool) = (false, false);

    /// STBY high and both PWMs at 600 ‰ at `t`: the wheels turn as their IN pins say.
    fn power(bw: &mut BenchWorld<'_>, t: u64) {
        bw.output(pin::STBY, true, t);
        bw.duty(pin::LEFT[2], 600, t);
        bw.duty(pin::RIGHT[2], 600, t);
    }

    /// Sets each wheel's IN1 and IN2 at `*t` and holds them `ms`; `*t` moves on.
    async fn wheels(bw: &mut BenchWorld<'_>, t: &mut u64, pins: [(bool, bool); 2], ms: u64) {
        for (wheel, (in1, in2)) in [pin::LEFT, pin::RIGHT].into_iter().zip(pins) {
            bw.output(wheel[0], in1, *t);
            bw.output(wheel[1], in2, *t);
        }
        *t += ms * 1_000_000;
        embassy_time::Timer::at(Instant::from_millis(*t / 1_000_000)).await;
    }

    /// Drives both wheels forward at 600 ‰ from `*t` for `ms`, then brakes and lets go.
    async fn drive(bw: &mut BenchWorld<'_>, t: &mut u64, ms: u64) {
        power(bw, *t);
        wheels(bw, t, [AHEAD; 2], ms).await;
        wheels(bw, t, [BRAKE; 2], 0).await;
        wheels(bw, t, [OFF; 2], 0).await;
        bw.duty(pin::LEFT[2], 0, *t);
        bw.duty(pin::RIGHT[2], 0, *t);
    }

    /// The robot drives at the box 350 mm ahead, its echo falls, and by 10 ms the wheels stop:
    /// braked (IN2 raised beside IN1) or let coast (IN1 lowered). What was recorded of the
    /// reaction: whether it coasted, and its cycles.
    fn reaction_stopping(coast: bool) -> (Vec<(usize, u64, u64)>, Option<u64>) {
        let sc = boxed();
        let sc = &sc;
        psmpa_sim::backend::simulate(
            async move {
                let mut bw = BenchWorld::new(sc, 600, [0, 1, 2, 3], None, 20);
                let t = &mut 0;
                power(&mut bw, 0);
                wheels(&mut bw, t, [AHEAD; 2], 0).await;
                bw.output(pin::TRIGGER, true, 1_000);
                bw.output(pin::TRIGGER, false, 11_000);
                *t = 10_000_000;
                embassy_time::Timer::at(Instant::from_millis(10)).await;
                wheels(&mut bw, t, [if coast { OFF } else { BRAKE }; 2], 0).await;
                (bw.coasted.clone(), bw.reactions[0].worst_cycles)
            },
            embassy_time::Duration::from_secs(1),
        )
        .unwrap()
        .output
    }

    #[test]
    fn a_reaction_that_lets_the_wheels_coast_is_recorded() {
        let (coasted, cycles) = reaction_stopping(false);
        assert!(coasted.is_empty(), "{coasted:?}");
        assert!(cycles.is_some());
        let (coasted, cycles) = reaction_stopping(true);
        assert!(cycles.is_some());
        assert!(
            matches!(coasted[..], [(0, edge, 10_000_000)] if edge < 10_000_000),
            "{coasted:?}"
        );
    }

    /// The robot walks, steps aside around the box (turns left 250 ms, passes 500 ms, turns
    /// back right, or left again with `back_left`, 250 ms), brakes and walks on: the walks
    /// the bench found setting off facing away, and whether it walks at the end.
    fn after_side_step(back_left: bool) -> (Vec<(u64, i64)>, bool) {
        let sc = psmpa_sim::load::parse(
            std::path::Path::new("t.json"),
            br#"{"name": "t", "robot": {"speed_mps": 0.1, "avoid_s": 1.0}, "interferences": [{"kind": "box", "at_s": 0.0, "ahead_m": 0.35, "hold_s": 10.0}]}"#,
        )
        .unwrap();
        let sc = &sc;
        psmpa_sim::backend::simulate(
            async move {
                let mut bw = BenchWorld::new(sc, 600, [0, 1, 2, 3], None, 20);
                let t = &mut 0;
                power(&mut bw, 0);
                wheels(&mut bw, t, [AHEAD, AHEAD], 100).await;
                wheels(&mut bw, t, [BACK, AHEAD], 250).await;
                wheels(&mut bw, t, [AHEAD, AHEAD], 500).await;
                let turn_back = if back_left {
                    [BACK, AHEAD]
                } else {
                    [AHEAD, BACK]
                };
                wheels(&mut bw, t, turn_back, 250).await;
                wheels(&mut bw, t, [BRAKE, BRAKE], 10).await;
                wheels(&mut bw, t, [AHEAD, AHEAD], 100).await;
                (bw.off_course.clone(), bw.body.driving())
            },
            embassy_time::Duration::from_secs(5),
        )
        .unwrap()
        .output
    }

    #[test]
    fn a_walk_that_sets_off_facing_away_from_its_way_is_recorded() {
        assert_eq!(after_side_step(false), (vec![], true));
        // Turned left twice: 500 ms of turning off its way when it walks on.
        assert_eq!(after_side_step(true), (vec![(1_100_000_000, 500)], true));
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
        {
            let mut set = BenchWorld::collect(&mut bw.bumper_closed, &mut out);
            set((pin::BUMPER, Some(false), 100));
            set((pin::BUMPER, None, 200));
        }
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

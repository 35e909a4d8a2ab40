//! The runtime's trace in the defmt log, with the mission's names: what a robot builder
//! watches on the bench (`INFO go to door started`, `WARN go to door: precondition violated,
//! {path_clear} false`). defmt's timestamp (`defmt-timestamp-uptime`) is the event's instant.
//!
//! Levels, so that `DEFMT_LOG` (`info` in `.cargo/config.toml`) chooses how much: plans,
//! states, violations and faults at `info` and `warn`; sensors switched on and off, lost
//! samples and the beliefs at `debug`; every sample at `trace` (several a second while
//! walking). A level filtered out compiles to nothing.
//!
//! The runtime calls the sink inside its trace lock, a critical section on this board, and
//! defmt's RTT logger takes one for each message anyway. A message is encoded (names copied
//! as strings, no `core::fmt`) in a few microseconds, during which an interrupt waits: the
//! sonar's echo edge included, which moves a range by about a millimetre in 6 us. At `info`
//! that happens only when a state begins or ends, not while the robot senses.
//!
//! Beside the log, the sink keeps each sensor's health in [`HEALTH`] (samples delivered and
//! lost, faults, the longest gap between two samples) and logs it at `info` when the sensor
//! is switched off: `sonar off: 142 samples, 0 lost, longest gap 100000 us`. A debugger reads
//! [`HEALTH`] from RAM by its symbol; the bench in the loop reports it as a diagnostic and
//! judges nothing by it (a judge must not read what the judged writes for it).

use defmt::{debug, info, trace, warn};
use embassy_time::Instant;
use portable_atomic::{AtomicU32, Ordering};
use psmpa_core::plan::{MAX_PLANS, PlanSet};
use psmpa_core::{
    ActionId, ControlError, Failure, PlanId, SensorId, SensorSet, TraceEvent, TraceSink, Value,
};
use psmpa_fetch_tea::fetch_tea;

/// Sensors whose health is kept: the mission's.
pub const SENSORS: usize = fetch_tea::NS;

/// One sensor's health since boot. Words, so that a debugger reads them as they are.
#[repr(C)]
pub struct SensorHealth {
    /// 1 while the runtime has the sensor switched on.
    pub on: AtomicU32,
    /// Samples delivered.
    pub delivered: AtomicU32,
    /// Samples lost (the read returned none).
    pub lost: AtomicU32,
    /// Faults reported (the runtime gave the sensor up).
    pub failed: AtomicU32,
    /// The instant of the last delivered sample, µs since boot (wraps after 71 minutes).
    pub last_us: AtomicU32,
    /// The longest time between two delivered samples while the sensor stayed on, µs.
    pub max_gap_us: AtomicU32,
    /// The last delivered reading ([`reading`]).
    pub value: AtomicU32,
}

/// A reading as one word: a distance in mm, a level, 0 or 1 for a yes/no, `u32::MAX` for
/// no echo (nothing in range).
pub fn reading(value: Value) -> u32 {
    match value {
        Value::Bool(b) => u32::from(b),
        Value::Int(v) | Value::Mm(v) => v.cast_unsigned(),
        Value::Level(l) => u32::from(l),
        Value::NoEcho => u32::MAX,
    }
}

/// Every sensor's health, and a count of changes (a reader polls it to see that something
/// moved). Exported as `PSMPA_HEALTH`.
#[repr(C)]
pub struct Health {
    /// Incremented after every change below.
    pub changes: AtomicU32,
    /// By sensor id.
    pub sensors: [SensorHealth; SENSORS],
}

/// What the sink has seen of the sensors.
#[unsafe(export_name = "PSMPA_HEALTH")]
pub static HEALTH: Health = Health {
    changes: AtomicU32::new(0),
    sensors: [const { SensorHealth::new() }; SENSORS],
};

impl SensorHealth {
    /// Nothing seen yet.
    const fn new() -> Self {
        Self {
            on: AtomicU32::new(0),
            delivered: AtomicU32::new(0),
            lost: AtomicU32::new(0),
            failed: AtomicU32::new(0),
            last_us: AtomicU32::new(0),
            max_gap_us: AtomicU32::new(0),
            value: AtomicU32::new(0),
        }
    }
}

/// Adds one to a counter (a load and a store: the sink runs inside the runtime's trace lock,
/// and the Cortex-M0+ has no read-modify-write atomics).
fn bump(counter: &AtomicU32) {
    counter.store(
        counter.load(Ordering::Relaxed).wrapping_add(1),
        Ordering::Relaxed,
    );
}

/// Updates `sensor`'s health with `event` at `at`; false when the event is not about a sensor.
fn note(sensor: SensorId, at: Instant, event: &TraceEvent) -> bool {
    let Some(h) = HEALTH.sensors.get(sensor.index()) else {
        return false;
    };
    // Wraps with the counter it is compared with.
    let now = at.as_micros() as u32;
    match event {
        TraceEvent::SensorOn { .. } => {
            h.on.store(1, Ordering::Relaxed);
            // A gap that spans a switch-off is no gap.
            h.last_us.store(0, Ordering::Relaxed);
        }
        TraceEvent::SensorOff { .. } => h.on.store(0, Ordering::Relaxed),
        TraceEvent::Sample { value, .. } => {
            h.value.store(reading(*value), Ordering::Relaxed);
            let last = h.last_us.load(Ordering::Relaxed);
            if h.on.load(Ordering::Relaxed) == 1 && last != 0 {
                let gap = now.wrapping_sub(last);
                if gap > h.max_gap_us.load(Ordering::Relaxed) {
                    h.max_gap_us.store(gap, Ordering::Relaxed);
                }
            }
            // 0 means none: a sample at the very first microsecond reads as 1.
            h.last_us.store(now.max(1), Ordering::Relaxed);
            bump(&h.delivered);
        }
        TraceEvent::SampleLost { .. } => bump(&h.lost),
        TraceEvent::SensorFailed { .. } => bump(&h.failed),
        _ => return false,
    }
    bump(&HEALTH.changes);
    true
}

/// The tables of the mission whose names the log shows.
pub type Tables = psmpa_core::Tables<
    'static,
    { fetch_tea::NS },
    { fetch_tea::NA },
    { fetch_tea::NP },
    { fetch_tea::L },
    { fetch_tea::W },
    { fetch_tea::NF },
>;

/// Writes each trace event to the defmt log with the mission's names (its tables, in flash).
pub struct Log(pub &'static Tables);

/// A failure, or the control loop's error, with the mission's names (`go to door`, `sonar`,
/// `GetIn Kitchen`, `{path_clear}`) rather than ids.
pub struct Named<'l, T>(pub &'l Log, pub T);

impl defmt::Format for Named<'_, Failure> {
    fn format(&self, f: defmt::Formatter<'_>) {
        let (log, d) = (self.0, &self.0.0.domain);
        match self.1 {
            Failure::ActionFailed { action } => {
                defmt::write!(f, "{=str} failed", log.action(action))
            }
            Failure::ActionInterrupted { action } => {
                defmt::write!(f, "{=str} was interrupted", log.action(action))
            }
            Failure::PreconditionUnmet { action, missing } => defmt::write!(
                f,
                "{=str} could not start: {} false",
                log.action(action),
                d.names(missing)
            ),
            Failure::PreconditionViolated { action, missing } => defmt::write!(
                f,
                "{=str} stopped: {} false for too long",
                log.action(action),
                d.names(missing)
            ),
            Failure::SensorUnavailable { sensor } => {
                defmt::write!(f, "{=str} is out of service", log.sensor(sensor))
            }
            Failure::SensorFault { sensor, fault } => {
                defmt::write!(f, "{=str} failed: {}", log.sensor(sensor), fault)
            }
            other => defmt::write!(f, "{}", other),
        }
    }
}

impl defmt::Format for Named<'_, ControlError> {
    fn format(&self, f: defmt::Formatter<'_>) {
        let (log, d) = (self.0, &self.0.0.domain);
        let event = |e| d.event_name(e).unwrap_or("?");
        match self.1 {
            ControlError::NoApplicablePlan { event: e, beliefs } => defmt::write!(
                f,
                "no plan for {=str} applies under {}",
                event(e),
                d.names(beliefs)
            ),
            ControlError::Exhausted {
                event: e,
                failed,
                beliefs,
                faulty,
            } => defmt::write!(
                f,
                "every plan for {=str} failed ({}); beliefs {}; out of service: {}",
                event(e),
                Plans(log, failed),
                d.names(beliefs),
                Sensors(log, faulty)
            ),
            ControlError::TooManyFailures { failures, last } => defmt::write!(
                f,
                "{=u16} plans failed, the last because {}",
                failures,
                Named(log, last)
            ),
            ControlError::InitialModel { failure } => defmt::write!(
                f,
                "the initial model could not be established: {}",
                Named(log, failure)
            ),
            other => defmt::write!(f, "{}", other),
        }
    }
}

/// A set of plans by name.
struct Plans<'l>(&'l Log, PlanSet);

impl defmt::Format for Plans<'_> {
    fn format(&self, f: defmt::Formatter<'_>) {
        let mut first = true;
        for p in (0..MAX_PLANS).filter_map(PlanId::new) {
            if self.1.contains(p) {
                let sep = if first { "" } else { ", " };
                defmt::write!(f, "{=str}{=str}", sep, self.0.plan(p));
                first = false;
            }
        }
        if first {
            defmt::write!(f, "none");
        }
    }
}

/// A set of sensors by name.
struct Sensors<'l>(&'l Log, SensorSet);

impl defmt::Format for Sensors<'_> {
    fn format(&self, f: defmt::Formatter<'_>) {
        let mut first = true;
        for s in self.1.iter() {
            let sep = if first { "" } else { ", " };
            defmt::write!(f, "{=str}{=str}", sep, self.0.sensor(s));
            first = false;
        }
        if first {
            defmt::write!(f, "none");
        }
    }
}

impl Log {
    fn plan(&self, id: PlanId) -> &'static str {
        self.0.library.get(id).map_or("generated plan", |p| p.name)
    }

    fn sensor(&self, id: SensorId) -> &'static str {
        self.0.domain.sensor(id).map_or("?", |s| s.name)
    }

    fn action(&self, id: ActionId) -> &'static str {
        self.0.domain.action(id).map_or("?", |a| a.name)
    }
}

impl<Ms: psmpa_core::Mission<Facts = psmpa_core::FactSet>> TraceSink<Ms> for Log {
    fn record(&mut self, at: Instant, event: &TraceEvent) {
        #[cfg(feature = "recorder")]
        crate::record::take(at, event);
        match *event {
            TraceEvent::SensorOn { sensor }
            | TraceEvent::SensorOff { sensor }
            | TraceEvent::Sample { sensor, .. }
            | TraceEvent::SampleLost { sensor }
            | TraceEvent::SensorFailed { sensor, .. } => {
                note(sensor, at, event);
            }
            _ => {}
        }
        let d = &self.0.domain;
        let plan = |id| self.0.library.get(id).map_or("generated plan", |p| p.name);
        match *event {
            TraceEvent::PlanSelected { plan: p, event: e } => info!(
                "plan {=str} for {=str}",
                plan(p),
                d.event_name(e).unwrap_or("?")
            ),
            TraceEvent::PlanGenerated { length, expanded } => info!(
                "no library plan could run: generated {=u8} actions ({=u32} nodes expanded)",
                length, expanded
            ),
            TraceEvent::PlanSucceeded { plan: p } => info!("plan {=str} succeeded", plan(p)),
            TraceEvent::PlanFailed { plan: p, reason } => {
                warn!("plan {=str} failed: {}", plan(p), Named(self, reason))
            }
            TraceEvent::StateEntered { action, .. } => info!("{=str} started", self.action(action)),
            TraceEvent::StateLeft {
                action, outcome, ..
            } => match outcome {
                Some(o) => info!("{=str} ended: {}", self.action(action), o),
                None => info!("{=str} cut short", self.action(action)),
            },
            TraceEvent::PreconditionViolated { action, missing } => warn!(
                "{=str}: precondition violated, {} false",
                self.action(action),
                d.names(missing)
            ),
            TraceEvent::PreconditionRestored { action } => {
                info!("{=str}: precondition holds again", self.action(action))
            }
            TraceEvent::SensorFailed { sensor, fault } => {
                warn!("{=str} failed: {}", self.sensor(sensor), fault)
            }
            TraceEvent::GoalReached { beliefs } => info!("goal reached: {}", d.names(beliefs)),
            TraceEvent::SensorOn { sensor } => debug!("{=str} on", self.sensor(sensor)),
            TraceEvent::SensorOff { sensor } => {
                if let Some(h) = HEALTH.sensors.get(sensor.index()) {
                    info!(
                        "{=str} off: {=u32} samples, {=u32} lost, longest gap {=u32} us",
                        self.sensor(sensor),
                        h.delivered.load(Ordering::Relaxed),
                        h.lost.load(Ordering::Relaxed),
                        h.max_gap_us.load(Ordering::Relaxed)
                    )
                }
            }
            TraceEvent::SampleLost { sensor } => {
                debug!("{=str}: sample lost", self.sensor(sensor))
            }
            TraceEvent::ModelEstablished { beliefs }
            | TraceEvent::EffectsApplied { beliefs, .. } => {
                debug!("beliefs {}", d.names(beliefs))
            }
            TraceEvent::Sample {
                sensor,
                value,
                holds,
            } => trace!(
                "{=str} {} (holds {})",
                self.sensor(sensor),
                value,
                d.names(holds)
            ),
            ref other => debug!("{}", other),
        }
    }
}

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

use defmt::{debug, info, trace, warn};
use embassy_time::Instant;
use psmpa_core::{ActionId, MissionOf, SensorId, TraceEvent, TraceSink};
use psmpa_drivers::robot::FetchTeaCaps;

/// The mission whose names the log shows.
type Mission = MissionOf<'static, FetchTeaCaps>;

/// Writes each trace event to the defmt log with the mission's names.
pub struct Log(pub &'static Mission);

impl Log {
    fn sensor(&self, id: SensorId) -> &'static str {
        self.0.domain.sensor(id).map_or("?", |s| s.name)
    }

    fn action(&self, id: ActionId) -> &'static str {
        self.0.domain.action(id).map_or("?", |a| a.name)
    }
}

impl TraceSink for Log {
    fn record(&mut self, _at: Instant, event: &TraceEvent) {
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
                warn!("plan {=str} failed: {}", plan(p), reason)
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
            TraceEvent::SensorOff { sensor } => debug!("{=str} off", self.sensor(sensor)),
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

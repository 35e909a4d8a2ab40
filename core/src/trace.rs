//! The execution trace: typed events delivered to a sink the caller provides, with no
//! allocation, and a stable 64-bit hash of the whole trace for determinism checks.
//!
//! The hash is FNV-1a over a fixed little-endian encoding of every event and its timestamp in
//! ticks, so the same run gives the same hash on any host or microcontroller.

use embassy_time::Instant;

use crate::action::{ActionId, SensorId, SensorSet};
use crate::domain::EventId;
use crate::exec::Failure;
use crate::facts::FactSet;
use crate::plan::PlanId;
use crate::platform::{Outcome, SensorFault};
use crate::store::Value;

/// The two phases of the SMPA baseline.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Phase {
    /// Sensors on, actuators idle.
    Sense,
    /// Actuators run, sensors off.
    Act,
}

/// One event of the execution.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum TraceEvent {
    /// Algorithm 1 line 2: the initial beliefs after the first samples.
    ModelEstablished {
        /// The beliefs `φ`.
        beliefs: FactSet,
    },
    /// No library plan applied: the planner generated one.
    PlanGenerated {
        /// Its length.
        length: u8,
        /// Search nodes expanded.
        expanded: u32,
    },
    /// A plan was selected for an event ([`PlanId::GENERATED`] for a generated plan).
    PlanSelected {
        /// The plan.
        plan: PlanId,
        /// The event it was selected for.
        event: EventId,
    },
    /// A plan reached its final state.
    PlanSucceeded {
        /// The plan.
        plan: PlanId,
    },
    /// A plan took a failure edge.
    PlanFailed {
        /// The plan.
        plan: PlanId,
        /// Why.
        reason: Failure,
    },
    /// A behaviour state (or parallel state) started.
    StateEntered {
        /// Index of the state in its FSM.
        state: u8,
        /// The action it runs.
        action: ActionId,
        /// The sensors running beside it.
        sensors: SensorSet,
    },
    /// A behaviour state ended.
    StateLeft {
        /// Index of the state in its FSM.
        state: u8,
        /// The action it ran.
        action: ActionId,
        /// How it ended; `None` when the runtime cut it short.
        outcome: Option<Outcome>,
    },
    /// SMPA: a sense or act phase started.
    PhaseStarted {
        /// The action of the current state.
        action: ActionId,
        /// Which phase.
        phase: Phase,
    },
    /// A sensor was switched on.
    SensorOn {
        /// The sensor.
        sensor: SensorId,
    },
    /// A sensor was switched off.
    SensorOff {
        /// The sensor.
        sensor: SensorId,
    },
    /// A sensor delivered a sample.
    Sample {
        /// The sensor.
        sensor: SensorId,
        /// The value stored.
        value: Value,
        /// The perception facts that hold according to it.
        holds: FactSet,
    },
    /// A sample was lost (the sensor answered without a value).
    SampleLost {
        /// The sensor.
        sensor: SensorId,
    },
    /// A sensor failed to deliver a sample.
    SensorFailed {
        /// The sensor.
        sensor: SensorId,
        /// What went wrong.
        fault: SensorFault,
    },
    /// A percept made the running action's precondition false.
    PreconditionViolated {
        /// The running action.
        action: ActionId,
        /// The facts of `pre(a)` that no longer hold.
        missing: FactSet,
    },
    /// The running action's precondition holds again.
    PreconditionRestored {
        /// The running action.
        action: ActionId,
    },
    /// An action succeeded and `τ' = add(a) ∪ (τ \ del(a))` was applied.
    EffectsApplied {
        /// The action.
        action: ActionId,
        /// The beliefs afterwards.
        beliefs: FactSet,
    },
    /// The task's goal holds.
    GoalReached {
        /// The beliefs.
        beliefs: FactSet,
    },
    /// An application-defined event (a behaviour's decision, a world event).
    User {
        /// Application-defined code.
        code: u16,
        /// Application-defined value.
        value: i32,
    },
}

/// Receives trace events. Implementations must not block; they run in the control path.
pub trait TraceSink {
    /// Called once per event, in order.
    fn record(&mut self, at: Instant, event: &TraceEvent);
}

/// Discards every event (the hash is still computed).
impl TraceSink for () {
    fn record(&mut self, _at: Instant, _event: &TraceEvent) {}
}

impl<T: TraceSink + ?Sized> TraceSink for &mut T {
    fn record(&mut self, at: Instant, event: &TraceEvent) {
        (**self).record(at, event);
    }
}

/// FNV-1a, 64 bit: tiny, no tables, the same on every platform.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TraceHash(u64);

impl Default for TraceHash {
    fn default() -> Self {
        Self::new()
    }
}

impl TraceHash {
    const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;

    /// The hash of the empty trace.
    pub const fn new() -> Self {
        Self(Self::OFFSET)
    }

    /// The hash value.
    pub const fn value(self) -> u64 {
        self.0
    }

    fn bytes(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ u64::from(b)).wrapping_mul(Self::PRIME);
        }
    }

    /// Adds application bytes (a world's events, a device's state) to the hash. Encode values
    /// with a fixed byte order so that every platform hashes the same bytes.
    pub fn write(&mut self, bytes: &[u8]) {
        self.bytes(bytes);
    }

    fn u8(&mut self, v: u8) {
        self.bytes(&[v]);
    }

    fn u16(&mut self, v: u16) {
        self.bytes(&v.to_le_bytes());
    }

    fn u32(&mut self, v: u32) {
        self.bytes(&v.to_le_bytes());
    }

    fn u64(&mut self, v: u64) {
        self.bytes(&v.to_le_bytes());
    }

    fn value_of(&mut self, v: Value) {
        match v {
            Value::Bool(b) => self.bytes(&[0, u8::from(b)]),
            Value::Int(i) => {
                self.u8(1);
                self.bytes(&i.to_le_bytes());
            }
            Value::Mm(mm) => {
                self.u8(2);
                self.bytes(&mm.to_le_bytes());
            }
            Value::Level(l) => self.bytes(&[3, l]),
            Value::NoEcho => self.u8(4),
        }
    }

    fn fault(&mut self, f: SensorFault) {
        match f {
            SensorFault::Timeout => self.u8(0),
            SensorFault::OutOfRange => self.u8(1),
            SensorFault::Stuck => self.u8(2),
            SensorFault::Device(code) => self.bytes(&[3, code]),
            SensorFault::Silent => self.u8(4),
        }
    }

    fn failure(&mut self, f: Failure) {
        match f {
            Failure::ActionFailed { action } => self.bytes(&[0, action.index() as u8]),
            Failure::ActionInterrupted { action } => self.bytes(&[1, action.index() as u8]),
            Failure::PreconditionUnmet { action, missing } => {
                self.bytes(&[2, action.index() as u8]);
                self.u64(missing.bits());
            }
            Failure::PreconditionViolated { action, missing } => {
                self.bytes(&[3, action.index() as u8]);
                self.u64(missing.bits());
            }
            Failure::SensorUnavailable { sensor } => self.bytes(&[4, sensor.index() as u8]),
            Failure::SensorFault { sensor, fault } => {
                self.bytes(&[5, sensor.index() as u8]);
                self.fault(fault);
            }
            Failure::StoreFull { key } => self.bytes(&[6, key.0]),
            Failure::InvalidFsm { state } => self.bytes(&[7, state]),
            Failure::SensingStalled => self.u8(8),
        }
    }

    /// Adds one event at time `at` to the hash.
    pub fn add(&mut self, at: Instant, event: &TraceEvent) {
        use TraceEvent as E;
        self.u64(at.as_ticks());
        let id = |i: usize| i as u8;
        match *event {
            E::ModelEstablished { beliefs } => {
                self.u8(0);
                self.u64(beliefs.bits());
            }
            E::PlanSelected { plan, event } => {
                self.bytes(&[1, id(plan.index()), id(event.index())]);
            }
            E::PlanSucceeded { plan } => self.bytes(&[2, id(plan.index())]),
            E::PlanGenerated { length, expanded } => {
                self.bytes(&[18, length]);
                self.u32(expanded);
            }
            E::PlanFailed { plan, reason } => {
                self.bytes(&[3, id(plan.index())]);
                self.failure(reason);
            }
            E::StateEntered {
                state,
                action,
                sensors,
            } => {
                self.bytes(&[4, state, id(action.index())]);
                self.u32(sensors.bits());
            }
            E::StateLeft {
                state,
                action,
                outcome,
            } => {
                let o = match outcome {
                    None => 0,
                    Some(Outcome::Success) => 1,
                    Some(Outcome::Failure) => 2,
                    Some(Outcome::Interrupted) => 3,
                };
                self.bytes(&[5, state, id(action.index()), o]);
            }
            E::PhaseStarted { action, phase } => {
                let p = match phase {
                    Phase::Sense => 0,
                    Phase::Act => 1,
                };
                self.bytes(&[6, id(action.index()), p]);
            }
            E::SensorOn { sensor } => self.bytes(&[7, id(sensor.index())]),
            E::SensorOff { sensor } => self.bytes(&[8, id(sensor.index())]),
            E::Sample {
                sensor,
                value,
                holds,
            } => {
                self.bytes(&[9, id(sensor.index())]);
                self.value_of(value);
                self.u64(holds.bits());
            }
            E::SampleLost { sensor } => self.bytes(&[17, id(sensor.index())]),
            E::SensorFailed { sensor, fault } => {
                self.bytes(&[10, id(sensor.index())]);
                self.fault(fault);
            }
            E::PreconditionViolated { action, missing } => {
                self.bytes(&[11, id(action.index())]);
                self.u64(missing.bits());
            }
            E::PreconditionRestored { action } => self.bytes(&[12, id(action.index())]),
            E::EffectsApplied { action, beliefs } => {
                self.bytes(&[13, id(action.index())]);
                self.u64(beliefs.bits());
            }
            E::GoalReached { beliefs } => {
                self.u8(14);
                self.u64(beliefs.bits());
            }
            E::User { code, value } => {
                self.u8(16);
                self.u16(code);
                self.bytes(&value.to_le_bytes());
            }
        }
    }
}

/// A sink and the running hash and count of everything it was given.
#[derive(Debug)]
pub struct Tracer<T> {
    sink: T,
    hash: TraceHash,
    events: u32,
}

impl<T: TraceSink> Tracer<T> {
    /// A tracer in front of `sink`.
    pub const fn new(sink: T) -> Self {
        Self {
            sink,
            hash: TraceHash::new(),
            events: 0,
        }
    }

    /// Hashes the event and hands it to the sink. O(1).
    pub fn record(&mut self, at: Instant, event: &TraceEvent) {
        self.hash.add(at, event);
        self.events = self.events.wrapping_add(1);
        self.sink.record(at, event);
    }

    /// The hash of every event so far.
    pub fn hash(&self) -> TraceHash {
        self.hash
    }

    /// Number of events so far.
    pub fn events(&self) -> u32 {
        self.events
    }

    /// The sink.
    pub fn sink(&self) -> &T {
        &self.sink
    }

    /// The sink, mutably.
    pub fn sink_mut(&mut self) -> &mut T {
        &mut self.sink
    }

    /// The sink, giving up the tracer.
    pub fn into_sink(self) -> T {
        self.sink
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hash_depends_on_order_time_and_content() {
        let s = SensorId::new(1).unwrap();
        let on = TraceEvent::SensorOn { sensor: s };
        let off = TraceEvent::SensorOff { sensor: s };
        let hash = |events: &[(u64, TraceEvent)]| {
            let mut t = Tracer::new(());
            for (at, e) in events {
                t.record(Instant::from_ticks(*at), e);
            }
            t.hash().value()
        };
        let base = hash(&[(0, on), (5, off)]);
        assert_eq!(base, hash(&[(0, on), (5, off)]));
        assert_ne!(base, hash(&[(5, off), (0, on)]));
        assert_ne!(base, hash(&[(0, on), (6, off)]));
        assert_ne!(base, hash(&[(0, on)]));
        // FNV-1a of the empty trace is the offset basis: a fixed, documented value.
        assert_eq!(TraceHash::new().value(), 0xcbf2_9ce4_8422_2325);
    }
}

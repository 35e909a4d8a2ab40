//! The execution trace: typed events delivered to a sink the caller provides, with no
//! allocation, and a stable 64-bit hash of the whole trace for determinism checks.
//!
//! The hash mixes a fixed encoding of every event and its timestamp in ticks ([`TraceHash`]),
//! so the same run gives the same hash on any host or microcontroller.

use embassy_time::Instant;

use crate::action::{ActionId, SensorId, SensorSet};
use crate::domain::EventId;
use crate::facts::FactSetOf;
use crate::failure::Failure;
use crate::failure::SensorFault;
use crate::plan::PlanId;
use crate::platform::Outcome;
use crate::spec::{Mission, TraceEventOf};
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

/// One event of the execution, in a runtime whose fact sets have `W` words.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum TraceEvent<const W: usize = 1> {
    /// Algorithm 1 line 2: the initial beliefs after the first samples.
    ModelEstablished {
        /// The beliefs `φ`.
        beliefs: FactSetOf<W>,
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
        reason: Failure<W>,
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
        holds: FactSetOf<W>,
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
        missing: FactSetOf<W>,
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
        beliefs: FactSetOf<W>,
    },
    /// The task's goal holds.
    GoalReached {
        /// The beliefs.
        beliefs: FactSetOf<W>,
    },
    /// An application-defined event (a behaviour's decision, a world event).
    User {
        /// Application-defined code.
        code: u16,
        /// Application-defined value.
        value: i32,
    },
}

impl<const W: usize> TraceEvent<W> {
    /// The action the event is about, if any.
    pub const fn action(&self) -> Option<ActionId> {
        match *self {
            Self::StateEntered { action, .. }
            | Self::StateLeft { action, .. }
            | Self::PhaseStarted { action, .. }
            | Self::PreconditionViolated { action, .. }
            | Self::PreconditionRestored { action }
            | Self::EffectsApplied { action, .. } => Some(action),
            Self::PlanFailed { reason, .. } => reason.action(),
            _ => None,
        }
    }

    /// The sensor the event is about, if any.
    pub const fn sensor(&self) -> Option<SensorId> {
        match *self {
            Self::SensorOn { sensor }
            | Self::SensorOff { sensor }
            | Self::Sample { sensor, .. }
            | Self::SampleLost { sensor }
            | Self::SensorFailed { sensor, .. } => Some(sensor),
            Self::PlanFailed { reason, .. } => reason.sensor(),
            _ => None,
        }
    }

    /// The plan the event is about, if any ([`PlanId::GENERATED`] for a plan the planner
    /// generated).
    pub const fn plan(&self) -> Option<PlanId> {
        match *self {
            Self::PlanSelected { plan, .. }
            | Self::PlanSucceeded { plan }
            | Self::PlanFailed { plan, .. } => Some(plan),
            _ => None,
        }
    }
}

/// Receives the trace events of a runtime of mission `M` (a sink of one mission's events, or
/// of any mission's: `impl<M: Mission> TraceSink<M> for ..`). Implementations must not block;
/// they run in the control path.
#[diagnostic::on_unimplemented(
    message = "`{Self}` is not a trace sink of the mission `{M}`",
    label = "a sink of another mission",
    note = "a sink that reads names (a typed recorder) belongs to one mission: make it `{M}`'s"
)]
pub trait TraceSink<M: Mission> {
    /// Whether the runtime traces into this sink at all. `()` says no: the runtime then
    /// skips every event (no clock read, no lock, no hash), and its
    /// [`trace_hash`](crate::Runtime::trace_hash) and `trace_events` stay those of the empty
    /// trace. [`Hashing`] keeps nothing but the hash and the count.
    const TRACES: bool = true;

    /// Called once per event, in order.
    fn record(&mut self, at: Instant, event: &TraceEventOf<M>);
}

/// No trace: the runtime skips every event, the hash and count included.
impl<M: Mission> TraceSink<M> for () {
    const TRACES: bool = false;
    fn record(&mut self, _at: Instant, _event: &TraceEventOf<M>) {}
}

/// Keeps no event, but the runtime traces into it: the trace's hash and count are kept, for a
/// check that compares runs by their hash.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Hashing;

impl<M: Mission> TraceSink<M> for Hashing {
    fn record(&mut self, _at: Instant, _event: &TraceEventOf<M>) {}
}

impl<M: Mission, T: TraceSink<M> + ?Sized> TraceSink<M> for &mut T {
    const TRACES: bool = T::TRACES;
    fn record(&mut self, at: Instant, event: &TraceEventOf<M>) {
        (**self).record(at, event);
    }
}

/// A 64-bit hash of a trace: every event is three little words (its instant in ticks, a header
/// with the kind and the small fields, a payload), each mixed in with a rotate, an xor and a
/// multiply (the FxHash step). Tiny, no tables, the same on every platform, and about a
/// dozen instructions an event (a byte-wise FNV-1a took ten times that on a sample).
/// For determinism checks, not against an adversary.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TraceHash(u64);

impl Default for TraceHash {
    fn default() -> Self {
        Self::new()
    }
}

/// The header word of an event: its kind and up to three byte-sized fields.
const fn head(kind: u8, a: u8, b: u8, c: u8) -> u64 {
    u64::from_le_bytes([kind, a, b, c, 0, 0, 0, 0])
}

/// The two's-complement bits of `i`.
fn bits(i: i32) -> u64 {
    u64::from(u32::from_le_bytes(i.to_le_bytes()))
}

/// An id as a byte: sensor, plan and event ids are below capacities that fit a byte; an
/// action id's high byte goes in [`hi`].
fn id(i: usize) -> u8 {
    (i & 0xff) as u8
}

/// A payload of one word, as the first word of a fact set (the rest 0).
fn low<const W: usize>(w: u64) -> FactSetOf<W> {
    let mut words = [0; W];
    if let Some(first) = words.first_mut() {
        *first = w;
    }
    FactSetOf::from_words(words)
}

/// No payload.
const fn none<const W: usize>() -> FactSetOf<W> {
    FactSetOf::EMPTY
}

/// The high byte of an action id, at byte 5 of a header (0 for the first 256 actions, so
/// their hashes are what they were when ids were bytes).
fn hi(action: ActionId) -> u64 {
    ((action.index() >> 8) as u64 & 0xff) << 40
}

impl TraceHash {
    /// The hash of the empty trace (FNV-1a's offset basis, a fixed, documented value).
    const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    /// An odd constant with well-spread bits (FxHash's).
    const K: u64 = 0x517c_c1b7_2722_0a95;

    /// The hash of the empty trace.
    pub const fn new() -> Self {
        Self(Self::OFFSET)
    }

    /// The hash value.
    pub const fn value(self) -> u64 {
        self.0
    }

    fn word(&mut self, w: u64) {
        self.0 = (self.0.rotate_left(5) ^ w).wrapping_mul(Self::K);
    }

    /// Adds application bytes (a world's events, a device's state) to the hash, eight at a
    /// time and then their count. Encode values with a fixed byte order so that every platform
    /// hashes the same bytes.
    pub fn write(&mut self, bytes: &[u8]) {
        let mut chunks = bytes.chunks_exact(8);
        for chunk in &mut chunks {
            let mut w = [0u8; 8];
            w.copy_from_slice(chunk);
            self.word(u64::from_le_bytes(w));
        }
        let mut w = [0u8; 8];
        for (to, from) in w.iter_mut().zip(chunks.remainder()) {
            *to = *from;
        }
        self.word(u64::from_le_bytes(w));
        self.word(bytes.len() as u64);
    }

    /// A value as (kind, payload).
    fn value_of(v: Value) -> (u8, u64) {
        match v {
            Value::Bool(b) => (0, u64::from(b)),
            Value::Int(i) => (1, bits(i)),
            Value::Mm(mm) => (2, bits(mm)),
            Value::Level(l) => (3, u64::from(l)),
            Value::NoEcho => (4, 0),
        }
    }

    /// A sensor fault as (kind, code).
    fn fault(f: SensorFault) -> (u8, u8) {
        match f {
            SensorFault::Timeout => (0, 0),
            SensorFault::OutOfRange => (1, 0),
            SensorFault::Stuck => (2, 0),
            SensorFault::Device(code) => (3, code),
            SensorFault::Silent => (4, 0),
        }
    }

    /// A failure as (kind, subject, detail byte, payload, high byte of an action subject).
    fn failure<const W: usize>(f: Failure<W>) -> (u8, u8, u8, FactSetOf<W>, u64) {
        let (kind, subject, detail, payload) = match f {
            Failure::ActionFailed { action } => (0, id(action.index()), 0, none()),
            Failure::ActionInterrupted { action } => (1, id(action.index()), 0, none()),
            Failure::PreconditionUnmet { action, missing } => (2, id(action.index()), 0, missing),
            Failure::PreconditionViolated { action, missing } => {
                (3, id(action.index()), 0, missing)
            }
            Failure::SensorUnavailable { sensor } => (4, id(sensor.index()), 0, none()),
            Failure::SensorFault { sensor, fault } => {
                let (kind, code) = Self::fault(fault);
                (5, id(sensor.index()), kind, low(u64::from(code)))
            }
            Failure::StoreFull { key } => (6, key.0, 0, none()),
            Failure::InvalidFsm { state } => (7, state, 0, none()),
            Failure::SensingStalled => (8, 0, 0, none()),
        };
        let high = match f {
            Failure::ActionFailed { action }
            | Failure::ActionInterrupted { action }
            | Failure::PreconditionUnmet { action, .. }
            | Failure::PreconditionViolated { action, .. } => hi(action),
            _ => 0,
        };
        (kind, subject, detail, payload, high)
    }

    /// Adds one event at time `at` to the hash. O(W): three words, and a fact set's further
    /// words after them (none in a one-word runtime, whose hashes are therefore the same as
    /// before fact sets had a width).
    pub fn add<const W: usize>(&mut self, at: Instant, event: &TraceEvent<W>) {
        let (header, payload) = Self::words(event);
        self.word(at.as_ticks());
        self.word(header);
        for w in payload.words() {
            self.word(w);
        }
    }

    /// The fixed encoding of `event` that the hash mixes: a header word (the kind and its
    /// small fields) and a fact set (the event's facts, or a wider field in its low word).
    /// The flight recorder ([`crate::record`]) stores exactly these words. O(1).
    pub fn words<const W: usize>(event: &TraceEvent<W>) -> (u64, FactSetOf<W>) {
        use TraceEvent as E;
        match *event {
            E::ModelEstablished { beliefs } => (head(0, 0, 0, 0), beliefs),
            E::PlanSelected { plan, event } => {
                (head(1, id(plan.index()), id(event.index()), 0), none())
            }
            E::PlanSucceeded { plan } => (head(2, id(plan.index()), 0, 0), none()),
            E::PlanFailed { plan, reason } => {
                let (kind, subject, detail, payload, high) = Self::failure(reason);
                let h = head(3, id(plan.index()), kind, subject) | u64::from(detail) << 32 | high;
                (h, payload)
            }
            E::StateEntered {
                state,
                action,
                sensors,
            } => (
                head(4, state, id(action.index()), 0) | hi(action),
                low(u64::from(sensors.bits())),
            ),
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
                (head(5, state, id(action.index()), o) | hi(action), none())
            }
            E::PhaseStarted { action, phase } => {
                let p = match phase {
                    Phase::Sense => 0,
                    Phase::Act => 1,
                };
                (head(6, id(action.index()), p, 0) | hi(action), none())
            }
            E::SensorOn { sensor } => (head(7, id(sensor.index()), 0, 0), none()),
            E::SensorOff { sensor } => (head(8, id(sensor.index()), 0, 0), none()),
            E::Sample {
                sensor,
                value,
                holds,
            } => {
                let (kind, v) = Self::value_of(value);
                (head(9, id(sensor.index()), kind, 0) | v << 32, holds)
            }
            E::SensorFailed { sensor, fault } => {
                let (kind, code) = Self::fault(fault);
                (head(10, id(sensor.index()), kind, code), none())
            }
            E::PreconditionViolated { action, missing } => {
                (head(11, id(action.index()), 0, 0) | hi(action), missing)
            }
            E::PreconditionRestored { action } => {
                (head(12, id(action.index()), 0, 0) | hi(action), none())
            }
            E::EffectsApplied { action, beliefs } => {
                (head(13, id(action.index()), 0, 0) | hi(action), beliefs)
            }
            E::GoalReached { beliefs } => (head(14, 0, 0, 0), beliefs),
            E::User { code, value } => {
                (head(16, 0, 0, 0) | u64::from(code) << 16, low(bits(value)))
            }
            E::SampleLost { sensor } => (head(17, id(sensor.index()), 0, 0), none()),
            E::PlanGenerated { length, expanded } => {
                (head(18, length, 0, 0), low(u64::from(expanded)))
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

impl<T> Tracer<T> {
    /// A tracer in front of `sink`.
    pub const fn new(sink: T) -> Self {
        Self {
            sink,
            hash: TraceHash::new(),
            events: 0,
        }
    }

    /// Hashes the event and hands it to the sink. O(1).
    pub fn record<M, const W: usize>(&mut self, at: Instant, event: &TraceEvent<W>)
    where
        M: Mission<Facts = FactSetOf<W>>,
        T: TraceSink<M>,
    {
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

    /// A mission type of one word of facts, for the sinks' type parameter.
    type One = &'static crate::mission::Tables<'static, 1, 1, 1, 1>;

    #[test]
    fn hash_depends_on_order_time_and_content() {
        let s = SensorId::new(1).unwrap();
        let on = TraceEvent::SensorOn { sensor: s };
        let off = TraceEvent::SensorOff { sensor: s };
        let hash = |events: &[(u64, TraceEvent)]| {
            let mut t = Tracer::new(());
            for (at, e) in events {
                t.record::<One, 1>(Instant::from_ticks(*at), e);
            }
            t.hash().value()
        };
        let base = hash(&[(0, on), (5, off)]);
        assert_eq!(base, hash(&[(0, on), (5, off)]));
        assert_ne!(base, hash(&[(5, off), (0, on)]));
        assert_ne!(base, hash(&[(0, on), (6, off)]));
        assert_ne!(base, hash(&[(0, on)]));
        // The empty trace hashes to the offset basis: a fixed, documented value.
        assert_eq!(TraceHash::new().value(), 0xcbf2_9ce4_8422_2325);
    }
}

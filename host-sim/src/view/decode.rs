//! The recorder's frames read back as trace events: the inverse of
//! [`TraceHash::words`](psmpa_core::TraceHash::words) for a runtime of one fact word (the Fetch
//! Tea mission's). The view takes every source through this one format: the simulator's events
//! become frames ([`Frame::of`]), a recording and a board's stream are frames already.

use psmpa_core::record::Frame;
use psmpa_core::trace::Phase;
use psmpa_core::{
    ActionId, EventId, FactSet, Failure, Key, Outcome, PlanId, SensorFault, SensorId, SensorSet,
    TraceEvent, Value,
};

/// Byte `i` of the header word.
fn field(header: u64, i: u32) -> u8 {
    (header.checked_shr(i * 8).unwrap_or(0) & 0xFF) as u8
}

/// The action of a header whose low id byte is at `at` (its high byte is byte 5).
fn action_at(header: u64, at: u32) -> Option<ActionId> {
    ActionId::new(usize::from(field(header, at)) | usize::from(field(header, 5)) << 8)
}

fn plan(byte: u8) -> Option<PlanId> {
    if byte == u8::MAX {
        Some(PlanId::GENERATED)
    } else {
        PlanId::new(usize::from(byte))
    }
}

fn signed(v: u64) -> i32 {
    i32::from_le_bytes((v as u32).to_le_bytes())
}

fn fault(kind: u8, code: u8) -> Option<SensorFault> {
    Some(match kind {
        0 => SensorFault::Timeout,
        1 => SensorFault::OutOfRange,
        2 => SensorFault::Stuck,
        3 => SensorFault::Device(code),
        4 => SensorFault::Silent,
        _ => return None,
    })
}

/// The trace event a frame records, or `None` for a frame whose kind or fields are out of
/// range (a frame of another version, or garbage that passed its checksum).
pub fn event_of(frame: &Frame<1>) -> Option<TraceEvent> {
    let h = frame.header;
    let payload: FactSet = frame.payload;
    let low = payload.words()[0];
    let sensor = || SensorId::new(usize::from(field(h, 1)));
    Some(match field(h, 0) {
        0 => TraceEvent::ModelEstablished { beliefs: payload },
        1 => TraceEvent::PlanSelected {
            plan: plan(field(h, 1))?,
            event: EventId::new(usize::from(field(h, 2)))?,
        },
        2 => TraceEvent::PlanSucceeded {
            plan: plan(field(h, 1))?,
        },
        3 => {
            let subject = field(h, 3);
            let action = || action_at(h, 3);
            let reason = match field(h, 2) {
                0 => Failure::ActionFailed { action: action()? },
                1 => Failure::ActionInterrupted { action: action()? },
                2 => Failure::PreconditionUnmet {
                    action: action()?,
                    missing: payload,
                },
                3 => Failure::PreconditionViolated {
                    action: action()?,
                    missing: payload,
                },
                4 => Failure::SensorUnavailable {
                    sensor: SensorId::new(usize::from(subject))?,
                },
                5 => Failure::SensorFault {
                    sensor: SensorId::new(usize::from(subject))?,
                    fault: fault(field(h, 4), low as u8)?,
                },
                6 => Failure::StoreFull { key: Key(subject) },
                7 => Failure::InvalidFsm { state: subject },
                8 => Failure::SensingStalled,
                _ => return None,
            };
            TraceEvent::PlanFailed {
                plan: plan(field(h, 1))?,
                reason,
            }
        }
        4 => TraceEvent::StateEntered {
            state: field(h, 1),
            action: action_at(h, 2)?,
            sensors: SensorSet::from_bits(low as u32),
        },
        5 => TraceEvent::StateLeft {
            state: field(h, 1),
            action: action_at(h, 2)?,
            outcome: match field(h, 3) {
                0 => None,
                1 => Some(Outcome::Success),
                2 => Some(Outcome::Failure),
                3 => Some(Outcome::Interrupted),
                _ => return None,
            },
        },
        6 => TraceEvent::PhaseStarted {
            action: action_at(h, 1)?,
            phase: match field(h, 2) {
                0 => Phase::Sense,
                1 => Phase::Act,
                _ => return None,
            },
        },
        7 => TraceEvent::SensorOn { sensor: sensor()? },
        8 => TraceEvent::SensorOff { sensor: sensor()? },
        9 => {
            let v = h >> 32;
            TraceEvent::Sample {
                sensor: sensor()?,
                value: match field(h, 2) {
                    0 => Value::Bool(v != 0),
                    1 => Value::Int(signed(v)),
                    2 => Value::Mm(signed(v)),
                    3 => Value::Level(u8::try_from(v).ok()?),
                    4 => Value::NoEcho,
                    _ => return None,
                },
                holds: payload,
            }
        }
        10 => TraceEvent::SensorFailed {
            sensor: sensor()?,
            fault: fault(field(h, 2), field(h, 3))?,
        },
        11 => TraceEvent::PreconditionViolated {
            action: action_at(h, 1)?,
            missing: payload,
        },
        12 => TraceEvent::PreconditionRestored {
            action: action_at(h, 1)?,
        },
        13 => TraceEvent::EffectsApplied {
            action: action_at(h, 1)?,
            beliefs: payload,
        },
        14 => TraceEvent::GoalReached { beliefs: payload },
        16 => TraceEvent::User {
            code: ((h >> 16) & 0xFFFF) as u16,
            value: signed(low),
        },
        17 => TraceEvent::SampleLost { sensor: sensor()? },
        18 => TraceEvent::PlanGenerated {
            length: field(h, 1),
            expanded: low as u32,
        },
        _ => return None,
    })
}

//! What goes wrong, as the runtime reports it: a sensor's fault, a behaviour state's failure,
//! a running action's violated precondition. Below the platform and the trace, so that both
//! name them without depending on the runtime.

use embassy_time::Instant;

use crate::action::{ActionId, SensorId, SensorSet};
use crate::facts::FactSetOf;
use crate::store::{Key, Value};

/// Why a sensor could not deliver a sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum SensorFault {
    /// No answer within the sensor's timeout (set by the runtime).
    Timeout,
    /// The value lies outside what the sensor can measure.
    OutOfRange,
    /// The sensor keeps returning the same value where the world must have changed.
    Stuck,
    /// Too many samples in a row were lost ([`Config::max_lost`](crate::Config::max_lost)).
    Silent,
    /// The device reported an error (platform-specific code).
    Device(u8),
}

impl core::fmt::Display for SensorFault {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Timeout => f.write_str("no answer within its timeout"),
            Self::OutOfRange => f.write_str("a value outside its range"),
            Self::Stuck => f.write_str("stuck on one value"),
            Self::Silent => f.write_str("too many samples lost in a row"),
            Self::Device(code) => write!(f, "device error {code}"),
        }
    }
}

impl core::error::Error for SensorFault {}

/// Why a behaviour state took its failure edge (fact sets of `W` words).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum Failure<const W: usize = 1> {
    /// The behaviour returned [`Outcome::Failure`](crate::Outcome::Failure).
    ActionFailed {
        /// The action.
        action: ActionId,
    },
    /// The behaviour returned [`Outcome::Interrupted`](crate::Outcome::Interrupted).
    ActionInterrupted {
        /// The action.
        action: ActionId,
    },
    /// Facts of `pre(a)` that no sensor of the state decides did not hold when it started.
    PreconditionUnmet {
        /// The action.
        action: ActionId,
        /// The facts that did not hold.
        missing: FactSetOf<W>,
    },
    /// A percept made `pre(a)` false and it stayed false longer than the action's
    /// [`max_violation`](crate::ActuatorAction::max_violation) (or [`Config::max_violation`](crate::Config::max_violation)).
    PreconditionViolated {
        /// The action.
        action: ActionId,
        /// The facts that did not hold.
        missing: FactSetOf<W>,
    },
    /// A sensor the state needs cannot run: it failed earlier and is out of service
    /// ([`Runtime::faulty_sensors`](crate::Runtime::faulty_sensors)), `pre(s)` does not hold, or the domain has no such sensor.
    SensorUnavailable {
        /// The sensor.
        sensor: SensorId,
    },
    /// A sensor did not switch on, or failed to deliver a sample.
    SensorFault {
        /// The sensor.
        sensor: SensorId,
        /// What went wrong.
        fault: SensorFault,
    },
    /// A sensor's store had no room for a value of its sample.
    StoreFull {
        /// The key that found no room.
        key: Key,
    },
    /// The FSM has no state `state`, or its success edge leads to failure.
    InvalidFsm {
        /// The state index.
        state: u8,
    },
    /// The sensing side did not answer within the sensors' own timeouts: nothing polls
    /// [`SensingSide::run`](crate::SensingSide::run). Run it beside the deciding side.
    SensingStalled,
}

impl<const W: usize> Failure<W> {
    /// The action the failure is about, if any.
    pub const fn action(&self) -> Option<ActionId> {
        match *self {
            Self::ActionFailed { action }
            | Self::ActionInterrupted { action }
            | Self::PreconditionUnmet { action, .. }
            | Self::PreconditionViolated { action, .. } => Some(action),
            _ => None,
        }
    }

    /// The sensor the failure is about, if any.
    pub const fn sensor(&self) -> Option<SensorId> {
        match *self {
            Self::SensorUnavailable { sensor } | Self::SensorFault { sensor, .. } => Some(sensor),
            _ => None,
        }
    }
}

/// A running action's precondition is false.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Violation<const W: usize = 1> {
    /// The facts of `pre(a)` that do not hold.
    pub missing: FactSetOf<W>,
    /// When the first sample that showed it was taken.
    pub since: Instant,
    /// When the latest sample that showed it was taken.
    pub last_seen: Instant,
    /// The running sensors whose latest sample shows it.
    pub by: SensorSet,
    /// The latest sample that showed it: `None` while only a belief from before the state
    /// shows it (no sensor of the state has sampled a missing fact yet).
    pub evidence: Option<Evidence>,
}

/// The sample that shows a precondition false: which sensor, when, what it read. A behaviour
/// tells by it what it is facing (the sonar's distance, the bumper's contact) without
/// deciding the sensor's threshold again.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Evidence {
    /// The sensor.
    pub sensor: SensorId,
    /// When its sample was taken.
    pub at: Instant,
    /// What it read.
    pub value: Value,
}

impl<const W: usize> Violation<W> {
    /// Whether sensor `sensor`'s latest sample shows it (a compiled mission's `Sensor`, or a
    /// [`SensorId`]).
    pub fn seen_by(&self, sensor: impl Into<SensorId>) -> bool {
        self.by.contains(sensor.into())
    }
}

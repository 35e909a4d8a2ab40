//! What the platform implements: the sensors behind sensor-based actions and the actuator
//! behaviours behind actuator-based actions.
//!
//! One implementation serves every sensor (or action) of a platform, dispatched by id: async
//! trait methods cannot be called through `dyn` without allocation, and a `match` on the id
//! compiles to a jump table. Methods take `&self` because sensors and actuators run at the same
//! time; platforms keep their state in cells or mutexes.

use crate::action::{ActionId, SensorId};
use crate::exec::ActionIo;
use crate::facts::FactSet;
use crate::store::Value;

/// One sample of a sensor: the measured value and the perception facts it makes true.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Reading {
    /// The measurement, stored in the sensor's data store.
    pub value: Value,
    /// The facts of `per(s)` that hold according to this sample; the facts of `per(s)` not in
    /// `holds` are false. Facts outside `per(s)` are ignored.
    pub holds: FactSet,
}

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
    /// Too many samples in a row were lost ([`Config::max_lost`](crate::exec::Config::max_lost)).
    Silent,
    /// The device reported an error (platform-specific code).
    Device(u8),
}

/// How an actuator behaviour ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Outcome {
    /// The action achieved its effects.
    Success,
    /// The action could not achieve its effects.
    Failure,
    /// The behaviour stopped because its precondition no longer held.
    Interrupted,
}

/// The sensors of a platform (the sensing side of the sensory controller).
#[allow(async_fn_in_trait)] // Runs on single-threaded executors: no `Send` bound wanted.
pub trait Sensor {
    /// Powers the sensor up. Called when a state that needs it starts (least commitment).
    async fn switch_on(&self, sensor: SensorId) -> Result<(), SensorFault>;
    /// Powers the sensor down. Called when the action it serves ends.
    async fn switch_off(&self, sensor: SensorId);
    /// Takes one sample. The runtime bounds it with the sensor's timeout. `Ok(None)` means this
    /// sample was lost (an echo that never came back); the runtime keeps the previous belief
    /// and fails the state after [`Config::max_lost`](crate::exec::Config::max_lost) losses in
    /// a row.
    async fn sample(&self, sensor: SensorId) -> Result<Option<Reading>, SensorFault>;
}

/// The actuator behaviours of a platform (the acting side of the deliberative controller).
#[allow(async_fn_in_trait)] // Runs on single-threaded executors: no `Send` bound wanted.
pub trait Actuator {
    /// Runs actuator-based action `action` until it succeeds, fails or gives up.
    ///
    /// `io` gives the mutual data store (the latest samples of the sensors running beside the
    /// action), the precondition status, and a way to await the next change. When a percept
    /// makes the precondition false the behaviour is told at once ([`ActionIo::violation`]) and
    /// may stop, avoid, or return [`Outcome::Interrupted`].
    async fn run(&self, action: ActionId, io: &ActionIo<'_>) -> Outcome;

    /// SMPA only: `true` at the start of a sense phase (the robot must stand still while the
    /// behaviour is not polled), `false` when acting resumes.
    fn hold(&self, action: ActionId, held: bool) {
        let _ = (action, held);
    }

    /// The runtime cancelled the behaviour (a sensor fault, or the precondition stayed false):
    /// bring the actuators to a safe stop.
    fn halt(&self, action: ActionId) {
        let _ = action;
    }
}

//! Naming a runtime in one line: the platform and one type for every capacity.
//!
//! ```
//! use embassy_sync::blocking_mutex::raw::NoopRawMutex;
//! use psmpa_core::{ActionId, ActionIo, Actuator, Caps, Outcome, Platform, Reading, Runtime,
//!     Sensor, SensorFault, SensorId};
//!
//! struct Dock;
//! # impl Sensor for Dock {
//! #     type Id = SensorId;
//! #     async fn switch_on(&self, _: SensorId) -> Result<(), SensorFault> { Ok(()) }
//! #     async fn switch_off(&self, _: SensorId) {}
//! #     async fn sample(&self, _: SensorId) -> Result<Option<Reading>, SensorFault> { Ok(None) }
//! # }
//! # impl Actuator for Dock {
//! #     type Id = ActionId;
//! #     async fn run(&self, _: ActionId, _: &ActionIo<'_>) -> Outcome { Outcome::Success }
//! # }
//! impl Platform for Dock {
//!     type Mutex = NoopRawMutex; // both sides on one executor
//! }
//!
//! /// 4 sensors, 6 actions, 2 plans of at most 4 actions, 8 keys per data store.
//! type DockCaps = Caps<4, 6, 2, 4, 8>;
//! type DockRuntime = Runtime<'static, Dock, DockCaps>;
//! ```

pub mod control;
pub mod engine;
pub mod fsm;
pub mod sensing;
pub(crate) mod shared;

use crate::mission::{Bindings, Loaded, Mission};
use crate::platform::Platform;
use engine::Engine;

/// Every capacity of a runtime in one type: `NS` sensors, `NA` actions, `NP` plans of at most
/// `L` actions each, `K` keys per data store, and `NF` facts in fact sets of `W` 64-bit words
/// (64 facts in one word by default; `NF` is at most `64 · W`). Only a name: it holds nothing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Caps<
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const K: usize,
    const W: usize = 1,
    const NF: usize = 64,
>;

/// What a capacity type ([`Caps`]) sizes: the mission, its bindings and the runtime's engine.
pub trait Capacity {
    /// The mission of these capacities.
    type Mission<'a>;
    /// The loaded mission with the platform's behaviours of sensors `S` and actions `A`.
    type Loaded<'a, S, A>;
    /// The bindings of sensors `S` and actions `A`.
    type Bindings<S, A>;
    /// The runtime's engine on platform `P`, tracing into `T` (a [`TraceSink`](crate::TraceSink)).
    type Engine<'r, P: Platform + 'r, T>;
}

impl<
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const K: usize,
    const W: usize,
    const NF: usize,
> Capacity for Caps<NS, NA, NP, L, K, W, NF>
{
    type Mission<'a> = Mission<'a, NS, NA, NP, L, W, NF>;
    type Loaded<'a, S, A> = Loaded<'a, S, A, NS, NA, NP, L, W, NF>;
    type Bindings<S, A> = Bindings<S, A, NS, NA>;
    type Engine<'r, P: Platform + 'r, T> = Engine<'r, P, T, NS, NA, NP, L, K, W, NF>;
}

/// The mission of capacities `C`.
pub type MissionOf<'a, C> = <C as Capacity>::Mission<'a>;

/// A mission loaded for registry `R`'s behaviours, of capacities `C`.
pub type LoadedOf<'a, R, C> = <C as Capacity>::Loaded<
    'a,
    <R as crate::mission::Registry>::Sensor,
    <R as crate::mission::Registry>::Action,
>;

/// The bindings of registry `R`'s behaviours, of capacities `C`: what a platform keeps to go
/// from a device to its sensor ([`Bindings::sensor_id`](crate::mission::Bindings::sensor_id)).
pub type BindingsOf<R, C> = <C as Capacity>::Bindings<
    <R as crate::mission::Registry>::Sensor,
    <R as crate::mission::Registry>::Action,
>;

/// The P-SMPA runtime of one robot: platform `P`, capacities `C` ([`Caps`]), trace sink `T`
/// (none by default). A name for the [`Engine`] of those capacities, which does the work:
/// [`sensing`](Engine::sensing), [`run`](Engine::run), [`beliefs`](Engine::beliefs), ...
/// Build it through a concrete name (`DockRuntime::new(&mission, &dock, (), config)`).
///
/// Everything lives inside this value; put it in a `static` (with a `StaticCell`) or on the
/// stack of the task that runs it. With `P::Mutex = CriticalSectionRawMutex` and a `Sync`
/// platform it is `Sync`: a `&'static Runtime` can be shared by tasks at two priorities.
pub type Runtime<'r, P, C, T = ()> = <C as Capacity>::Engine<'r, P, T>;

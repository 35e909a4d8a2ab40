//! The runtime: the engine, its two sides, the state they share, the FSM, the control loop.
//!
//! A compiled mission names its runtime and every capacity: `include_mission!` generates
//! `Runtime<'r, P, T>` and `Caps` in the mission's module, so a robot writes none by hand.
//!
//! ```
//! use embassy_sync::blocking_mutex::raw::NoopRawMutex;
//! use psmpa_core::{ActionIo, Actuator, Outcome, Platform, Reading, Sensor, SensorFault};
//!
//! psmpa_core::include_mission!(mod hello = "../testkit/tests/hello.json");
//!
//! struct Robot;
//! # impl Sensor for Robot {
//! #     type Id = hello::Sensor;
//! #     async fn switch_on(&self, _: hello::Sensor) -> Result<(), SensorFault> { Ok(()) }
//! #     async fn switch_off(&self, _: hello::Sensor) {}
//! #     async fn sample(&self, _: hello::Sensor) -> Result<Option<Reading>, SensorFault> { Ok(None) }
//! # }
//! # impl Actuator for Robot {
//! #     type Id = hello::Action;
//! #     fn halt(&self, _: hello::Action) {} // nothing to stop
//! #     async fn run(&self, _: hello::Action, _: &ActionIo<'_>) -> Outcome { Outcome::Success }
//! # }
//! impl Platform for Robot {
//!     type Mutex = NoopRawMutex; // both sides on one executor
//! }
//!
//! type RobotRuntime<'r> = hello::Runtime<'r, Robot>;
//! ```
//!
//! A mission loaded at run time names its capacities with [`Caps`] instead.

pub mod control;
pub mod engine;
pub mod fsm;
pub mod sensing;
pub(crate) mod shared;
pub mod sides;

use core::marker::PhantomData;

use crate::mission::{Bindings, Loaded, Mission};
use crate::platform::Platform;
use engine::Engine;

/// Every capacity of a runtime in one type, each named by what it counts so that two cannot
/// be swapped: `Caps<Sensors<4>, Actions<6>, Plans<2>, Body<4>, Keys<8>>` runs 4 sensors, 6
/// actions, 2 plans of at most 4 actions each, 8 keys per data store, and facts in one 64-bit
/// word; add `Words<W>, Facts<NF>` for `NF` facts in sets of `W` words (`NF` at most `64 · W`).
/// Only a name: it holds nothing. A compiled mission's module names its own (`dock::Caps`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Caps<S, A, P, B, K, W = Words<1>, F = Facts<64>>(PhantomData<(S, A, P, B, K, W, F)>);

/// How many sensor-based actions (sensors) a runtime holds: [`Caps`]'s first.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Sensors<const N: usize>;
/// How many actuator-based actions a runtime holds: [`Caps`]'s second.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Actions<const N: usize>;
/// How many plans the library holds: [`Caps`]'s third.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Plans<const N: usize>;
/// The most actions in a plan's body: [`Caps`]'s fourth.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Body<const N: usize>;
/// How many keys each data store holds: [`Caps`]'s fifth.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Keys<const N: usize>;
/// How many 64-bit words a fact set takes: [`Caps`]'s sixth (1 by default).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Words<const N: usize>;
/// How many facts the domain holds: [`Caps`]'s seventh (64 by default).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Facts<const N: usize>;

/// What a capacity type ([`Caps`]) sizes: the mission, its bindings and the runtime's engine.
#[diagnostic::on_unimplemented(
    message = "`{Self}` is not a runtime's capacities",
    label = "not `Caps<Sensors<_>, Actions<_>, Plans<_>, Body<_>, Keys<_>>`",
    note = "name each capacity, in this order: `Caps<Sensors<NS>, Actions<NA>, Plans<NP>, Body<L>, Keys<K>>`, then `Words<W>, Facts<NF>` for more than 64 facts"
)]
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
> Capacity for Caps<Sensors<NS>, Actions<NA>, Plans<NP>, Body<L>, Keys<K>, Words<W>, Facts<NF>>
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
/// [`split`](Engine::split) into its two sides, [`run_with_sensing`](Engine::run_with_sensing),
/// [`beliefs`](Engine::beliefs), ...
/// Build it through a concrete name (`DockRuntime::new(&mission, &dock, (), config)`).
///
/// Everything lives inside this value; put it in a `static` (with a `StaticCell`) or on the
/// stack of the task that runs it. With `P::Mutex = CriticalSectionRawMutex` and a `Sync`
/// platform it is `Sync`, and its sensing side `Send`: [`split`](Engine::split) the
/// `&'static mut` a `StaticCell` gives and hand a `SensingSide<'static, R>` and a
/// `DecidingSide<'static, R>` to tasks at two priorities.
pub type Runtime<'r, P, C, T = ()> = <C as Capacity>::Engine<'r, P, T>;

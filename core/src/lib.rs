//! # psmpa-core: the P-SMPA robot control architecture, `no_std` and heap-free
//!
//! Classic robot software runs sense, model, plan, act in sequence, so a plan executes blind to
//! changes. P-SMPA (Yang et al., "Towards a Robust Software Architecture for Autonomous Robot
//! Software") runs the sensor-based actions a plan step needs *in parallel* with the
//! actuator-based action, and lets them talk through a mutual data store.
//!
//! | paper | here |
//! |---|---|
//! | facts, `τ' = add(a) ∪ (τ \ del(a))` | [`facts`] |
//! | `s = <pre, per>`, `a = <pre, add, del>` | [`action`] |
//! | planning domain `Δ` | [`domain`] |
//! | `p = <t(p), c(p), bd(p)>`, library `P`, BDI selection | [`plan`] |
//! | world model `M = <ω, φ, Π>`, task `Π = <Δ, τ0, τG>` | [`model`], [`mission`] |
//! | Algorithm 2: plan → FSM `f(Λ, T)` with parallel states | [`runtime::fsm`], run by [`runtime::engine`] (deciding) and [`runtime::sensing`], on the two sides [`runtime::sides`] hands out |
//! | Algorithm 3: data stores `D`, mutual store | [`store`] |
//! | Algorithm 1: the control loop | [`runtime::control`] |
//! | the SMPA baseline | [`Policy::Smpa`] |
//! | sensors and actuator behaviours | [`platform`] |
//! | what goes wrong: faults, failures, violations | [`failure`] |
//! | the trace, the flight recording | [`trace`], [`record`] |
//! | worst-case reaction latency | [`timing`] |
//!
//! Layers, each module using only those above it: the model ([`facts`], [`action`],
//! [`domain`], [`plan`], [`mission`], [`planner`] from psmpa-model, and [`model`]); [`store`];
//! [`failure`]; [`platform`]; [`trace`] and [`record`]; [`runtime`] (the engine with its
//! sensing and deciding sides, the state they share, the FSM, the control loop); [`timing`]
//! and [`text`]. A test (`tests/layers.rs`) fails on a cycle between them.
//!
//! The platform (a robot, or a simulator) implements [`platform::Sensor`] and
//! [`platform::Actuator`]. The core only exposes futures: the sensing side
//! ([`SensingSide`]: every sensor samples on its own schedule) and the deciding side
//! ([`DecidingSide`]: the control loop, the FSM, the behaviours), handed out once by
//! [`Engine::split`]. The platform places them, on
//! one executor or sensing at a higher priority. The core never spawns a task and never reads a
//! clock other than `embassy-time`, so the same code runs on a microcontroller under the
//! embassy executor and on a host in virtual time. Capacities are const generics; a full
//! store or table is an `Err`; nothing allocates, nothing panics.
#![no_std]
#![deny(missing_docs)]
#![forbid(unsafe_code)]
#![cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::indexing_slicing,
        clippy::unreachable,
        clippy::todo,
        clippy::unimplemented,
        clippy::arithmetic_side_effects
    )
)]

#[cfg(test)]
extern crate std;

pub(crate) mod fmt;

/// Compiles a mission file into a module of typed names, capacities, a runtime type and the
/// mission itself, checked when the robot is built: see [`psmpa_macros::include_mission`].
pub use psmpa_macros::include_mission;

/// What `include_mission!` generates needs: `defmt::Format` for a generated enum, printing its
/// name, when this crate's `defmt` feature is on (nothing otherwise).
#[doc(hidden)]
#[cfg(feature = "defmt")]
#[macro_export]
macro_rules! __format_as_name {
    ($ty:ty) => {
        impl $crate::__defmt::Format for $ty {
            fn format(&self, f: $crate::__defmt::Formatter<'_>) {
                $crate::__defmt::Format::format(&self.name(), f)
            }
        }
    };
}

#[doc(hidden)]
#[cfg(not(feature = "defmt"))]
#[macro_export]
macro_rules! __format_as_name {
    ($ty:ty) => {};
}

#[doc(hidden)]
#[cfg(feature = "defmt")]
pub use defmt as __defmt;

/// Makes a robot crate's build compile the whole runtime for its platform. A library's
/// generic code is only type-checked until a non-generic function uses it; this macro adds
/// one, public but hidden and never called, that polls [`Engine::run_with_sensing`] of
/// `runtime`, the robot's runtime type (`dock::Runtime<'static, Dock>`, or an alias of it).
/// `cargo build --target thumbv7em-none-eabihf` on the robot's crate then compiles the
/// runtime's futures for its platform, as its firmware will; a firmware that does not call
/// it does not link it.
///
/// Invoke it once, at the crate's root (a function in a private module is dead code, which
/// the compiler does not build).
///
/// ```
/// # use psmpa_core::{ActionIo, Actuator, Outcome, Platform, Reading, Sensor, SensorFault};
/// psmpa_core::include_mission!(mod hello = "../testkit/tests/hello.json");
/// # struct Robot;
/// # impl Sensor for Robot {
/// #     type Id = hello::Sensor;
/// #     async fn switch_on(&self, _: hello::Sensor) -> Result<(), SensorFault> { Ok(()) }
/// #     async fn switch_off(&self, _: hello::Sensor) {}
/// #     async fn sample(&self, _: hello::Sensor) -> Result<Option<Reading>, SensorFault> { Ok(None) }
/// # }
/// # impl Actuator for Robot {
/// #     type Id = hello::Action;
/// #     fn halt(&self, _: hello::Action) {} // nothing to stop
/// #     async fn run(&self, _: hello::Action, _: &ActionIo<'_>) -> Outcome { Outcome::Success }
/// # }
/// # impl Platform for Robot { type Mutex = psmpa_core::embassy_sync::blocking_mutex::raw::NoopRawMutex; }
/// type RobotRuntime<'r> = hello::Runtime<'r, Robot>;
///
/// psmpa_core::compile_runtime!(RobotRuntime<'_>);
/// # fn main() {}
/// ```
///
/// A robot generic over its hardware names the parameters and their bounds: the function is
/// then generic, and the build type-checks the whole runtime for every hardware the bounds
/// admit (the firmware that picks one compiles it for that one):
/// `psmpa_core::compile_runtime!(<H> RobotRuntime<'_, H> where H: Wheels + Ranger);`
#[macro_export]
macro_rules! compile_runtime {
    (<$($param:ident),+> $runtime:ty $(where $($bound:tt)+)?) => {
        /// Type-checks the runtime for this crate's platforms (`psmpa_core::compile_runtime!`):
        /// never called.
        #[doc(hidden)]
        pub fn __psmpa_compile_runtime<$($param),+>(
            runtime: &mut $runtime,
            cx: &mut ::core::task::Context<'_>,
        ) -> ::core::task::Poll<()>
        $(where $($bound)+)?
        {
            let run = ::core::pin::pin!(runtime.run_with_sensing());
            ::core::future::Future::poll(run, cx).map(|_| ())
        }
    };
    ($runtime:ty) => {
        /// Compiles the runtime for this crate's platform (`psmpa_core::compile_runtime!`):
        /// never called.
        #[doc(hidden)]
        pub fn __psmpa_compile_runtime(
            runtime: &mut $runtime,
            cx: &mut ::core::task::Context<'_>,
        ) -> ::core::task::Poll<()> {
            let run = ::core::pin::pin!(runtime.run_with_sensing());
            ::core::future::Future::poll(run, cx).map(|_| ())
        }
    };
}

// The model layer (psmpa-model): facts, actions, domains, plans, tasks, the mission format.
pub use psmpa_model::{action, domain, facts, mission, plan, planner};

pub mod failure;
pub mod model;
pub mod platform;
pub mod record;
pub mod runtime;
pub mod store;
pub mod text;
pub mod timing;
pub mod trace;

// The embassy crates the API is built on, at the versions this crate uses: a robot's code can
// name them through here rather than match their versions by hand.
pub use embassy_futures;
pub use embassy_sync;
pub use embassy_time;

pub use action::{ActionId, ActuatorAction, SensorAction, SensorId, SensorMode, SensorSet};
pub use domain::{Domain, DomainError, EventId};
pub use facts::{FactId, FactSet, FactSetOf};
pub use failure::{Failure, SensorFault, Violation};
pub use mission::{Bindings, LoadError, Loaded, Mission, Registry};
pub use model::{Task, WorldModel};
pub use plan::{Plan, PlanError, PlanId, PlanLibrary};
pub use platform::{
    ActionIo, Actuator, MAX_PAIRS, Outcome, PairRejected, Platform, Reading, Sensor,
};
pub use runtime::control::{ControlError, Report};
pub use runtime::engine::{Config, Engine, Policy};
pub use runtime::fsm::{BehaviourState, Fsm, FsmError, Target};
pub use runtime::sides::{DecidingSide, SensingSide};
pub use runtime::{
    Actions, BindingsOf, Body, Capacity, Caps, Facts, Keys, LoadedOf, MissionOf, Plans, Runtime,
    Sensors, Words,
};
pub use store::{DataStore, Entry, Key, MutualStore, StoreAccess, StoreFull, Value};
pub use text::{Describe, Described, FactNames};
pub use trace::{Hashing, Phase, TraceEvent, TraceHash, TraceSink, Tracer};

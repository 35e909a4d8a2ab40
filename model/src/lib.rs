//! # psmpa-model: the P-SMPA model and the mission format, `no_std` and heap-free
//!
//! The model layer of [psmpa](https://crates.io/crates/psmpa-core): what a robot's job is,
//! without how it runs. `psmpa-core` re-exports every module here at the same path
//! (`psmpa_core::facts`, `psmpa_core::mission`, ...); its runtime executes what this crate
//! describes, and its `include_mission!` macro checks a mission file with this crate's loader
//! when the robot is built.
//!
//! | paper | here |
//! |---|---|
//! | facts, `τ' = add(a) ∪ (τ \ del(a))` | [`facts`] |
//! | `s = <pre, per>`, `a = <pre, add, del>` | [`action`] |
//! | planning domain `Δ` | [`domain`] |
//! | `p = <t(p), c(p), bd(p)>`, library `P` | [`plan`] |
//! | task `Π = <Δ, τ0, τG>` | [`task`] |
//! | the robot's job `<S, A, P, Π>` as a file | [`mission`] |
//! | generatePlans when no library plan applies: a STRIPS planner | [`planner`] |
//!
//! Capacities are const generics; a full table is an `Err`; nothing allocates, nothing panics.
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
// Host tools only: strict JSON and the checks of a mission file (feature `std`).
#[cfg(all(feature = "std", not(test)))]
extern crate std;

pub mod action;
#[cfg(feature = "std")]
pub mod check;
pub mod domain;
pub mod facts;
// Host-only position arithmetic (line and column counts within a file held in memory); the
// no-overflow rule is for what runs on the robot.
#[cfg(feature = "std")]
#[allow(clippy::arithmetic_side_effects)]
pub mod json;
pub mod mission;
pub mod names;
pub mod plan;
pub mod planner;
pub mod task;

pub use action::{ActionId, ActuatorAction, SensorAction, SensorId, SensorMode, SensorSet};
pub use domain::{Domain, DomainError, EventId};
pub use facts::{FactId, FactSet, FactSetOf};
pub use mission::{Bindings, LoadError, Loaded, Registry, Tables};
pub use names::FactNames;
pub use plan::{Plan, PlanError, PlanId, PlanLibrary};
pub use task::Task;

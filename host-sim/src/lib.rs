//! # psmpa-sim: the host side of psmpa
//!
//! * [`backend`] (feature `std`): `psmpa-testkit`'s virtual-time backend, re-exported: runs
//!   `psmpa-core` futures to completion in virtual time, on a poll loop of two priorities
//!   (sensing above deciding), deterministically and on any number of threads.
#![cfg_attr(not(feature = "std"), no_std)]
#![deny(missing_docs)]
#![forbid(unsafe_code)]

#[cfg(feature = "std")]
pub use psmpa_testkit::sim as backend;
pub mod body;
#[cfg(feature = "std")]
pub mod cli;
#[cfg(feature = "std")]
pub use psmpa_model::json;
#[cfg(feature = "std")]
pub mod load;
#[cfg(feature = "std")]
pub mod planning;
#[cfg(feature = "std")]
pub mod replay;
pub mod rig;
pub mod robot;
pub mod run;
pub mod scenario;
#[cfg(feature = "std")]
pub mod sim;
#[cfg(feature = "std")]
pub mod view;
pub mod world;

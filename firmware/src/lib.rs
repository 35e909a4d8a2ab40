//! What both firmware images share on QEMU's mps2-an386 (Cortex-M4F, `thumbv7em-none-eabihf`)
//! and mps2-an505 (Cortex-M33, `thumbv8m.main-none-eabihf`): the two executors, the clock, and
//! the board's constants, vector table, fault and panic handling.
//!
//! * `psmpa-firmware` (`src/main.rs`): the simulated NAO world and every embedded scenario,
//!   checked against the host by `cargo xtask qemu`.
//! * `psmpa-product` (`src/bin/product.rs`): what a robot's firmware carries, the core, the
//!   mission loader and a platform of stubs where the drivers go; `cargo xtask size` holds it
//!   to its budget.
//!
//! [`world_trace`] is built on the host too: xtask reads the firmware's trace with it.
#![cfg_attr(target_os = "none", no_std)]
#![deny(missing_docs)]

#[cfg(target_os = "none")]
pub mod board;
pub mod clock;
#[cfg(target_os = "none")]
pub mod executor;
#[cfg(target_os = "none")]
mod logger;
#[cfg(target_os = "none")]
pub mod time_driver;
pub mod world_trace;

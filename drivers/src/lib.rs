//! # psmpa-drivers: devices on `embedded-hal` 1.0
//!
//! The drivers a small psmpa robot needs, each generic over the `embedded-hal` /
//! `embedded-hal-async` traits (never a HAL's own types), so that a board crate hands in its
//! pins and host tests hand in mocked or scripted ones:
//!
//! | module | device | traits |
//! |---|---|---|
//! | [`hcsr04`] | HC-SR04-class ultrasonic ranger | trigger `OutputPin`, echo `InputPin + Wait` |
//! | [`switch`] | debounced switch (bumper, limit switch) | `InputPin + Wait` |
//! | [`marker`] | IR reflectance sensor (TCRT5000-class) | `InputPin` |
//! | [`hbridge`] | TB6612FNG motor channel, differential drive | `OutputPin`, `SetDutyCycle` |
//!
//! Time comes from `embassy-time` only (`Timer`, `Instant`, `with_timeout`): every wait is an
//! await, nothing spins, and the crate picks no tick rate (the board's time driver does). No
//! allocation, no panics: device errors are `Err` values that say what went wrong.
//!
//! The Fetch Tea robot built from them is the crate `psmpa-fetch-tea`.
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

pub mod hbridge;
pub mod hcsr04;
pub mod marker;
pub mod switch;

/// A pin or PWM channel reported an error. (The HALs' GPIO errors say little more; most are
/// `Infallible`.)
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PinError;

/// Which level of an input means "active" (pressed, seen).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Active {
    /// Active when the pin is low: a switch to ground with a pull-up, a TCRT5000 module's
    /// comparator output.
    Low,
    /// Active when the pin is high: a switch to the supply with a pull-down.
    High,
}

impl Active {
    /// Whether a pin at level `high` is active.
    pub const fn is_active(self, high: bool) -> bool {
        match self {
            Self::Low => !high,
            Self::High => high,
        }
    }
}

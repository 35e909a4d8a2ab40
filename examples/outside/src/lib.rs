//! The dock mission compiled in ([`dock`]); the tests are the point.
#![no_std]

// The dock mission compiled in: checked when this crate builds, on the host and for a
// microcontroller alike (`scripts/test.sh` builds it for thumbv7em-none-eabihf).
psmpa_core::include_mission!(pub mod dock = "../dock/mission.json");

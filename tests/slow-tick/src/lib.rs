//! A mission whose every duration is whole tenths of a second compiles at 10 Hz; the test
//! `tests/ui.rs` holds the ones that must not.
#![no_std]

psmpa_core::include_mission!(pub mod slow = "ui/tenths.json");

//! The robot's calibration record: [`Settings`] in the last 4 KiB sector of flash
//! (`SETTINGS` in the board's `memory.x`), read at boot.
//!
//! A robot is calibrated without building the firmware again: write the record
//! ([`Settings::to_record`], 17 little-endian words) at the sector's start, with a probe
//! (`probe-rs download --binary-format bin --base-address ...`) or `picotool`. Erased flash
//! (no record), a record of another version or a damaged one is reported in the log and the
//! firmware runs with [`Settings::DEFAULT`]. The bench in the loop (`cargo xtask hil`) writes
//! the record of each scenario's robot into the emulated flash before it boots the chip.

use psmpa_fetch_tea::{RECORD_WORDS, RecordError, Settings};

unsafe extern "C" {
    /// The start of the `SETTINGS` region (`memory.x`): execute-in-place flash, readable as
    /// memory.
    static __psmpa_settings: [u32; RECORD_WORDS];
}

/// The settings of the calibration record in flash, checked ([`Settings::from_record`]).
pub fn read() -> Result<Settings, RecordError> {
    // SAFETY: the linker script places `__psmpa_settings` at the start of a flash region no
    // section is linked into, word-aligned; flash is always readable. Volatile: the compiler
    // must not assume what a region outside the image holds.
    let record = unsafe { (&raw const __psmpa_settings).read_volatile() };
    Settings::from_record(&record)
}

//! The Fetch Tea robot on a Raspberry Pi Pico2: the firmware is [`psmpa_board_rp`]'s (its entry,
//! its tasks and its pin table); this crate chooses the chip and the memory map.
#![no_std]
#![no_main]

use psmpa_board_rp as _;

//! The Fetch Tea robot on a Raspberry Pi Pico: the firmware is [`psmpa_board_rp`]'s (its entry,
//! its tasks and its pin table); this crate chooses the chip and the memory map, and starts the
//! image from SRAM.
#![no_std]
#![no_main]

use psmpa_board_rp as _;

// Runs from flash before anything else (boot2 jumps here, memory.x's boot vectors): copies the
// vector table, the code and the constants from their load address in flash to where they are
// linked in SRAM, points VTOR at the copied table and starts cortex-m-rt's reset handler from
// it. Four words a round, the whole code region (memory.x): the copy is the boot's only cost
// of running from SRAM, and the same for every build.
core::arch::global_asm!(
    ".pushsection .psmpa_boot, \"ax\"",
    ".global psmpa_boot",
    ".type psmpa_boot, %function",
    ".thumb_func",
    "psmpa_boot:",
    "    ldr r0, =__psmpa_code_load",
    "    ldr r1, =__psmpa_code_start",
    "    ldr r2, =__psmpa_code_end",
    "1:  cmp r1, r2",
    "    bhs 2f",
    "    ldm r0!, {{r4, r5, r6, r7}}",
    "    stm r1!, {{r4, r5, r6, r7}}",
    "    b 1b",
    "2:  ldr r0, =0xE000ED08",
    "    ldr r1, =__psmpa_code_start",
    "    str r1, [r0]",
    "    dsb",
    "    isb",
    "    ldr r0, [r1, #4]",
    "    bx r0",
    ".ltorg",
    ".size psmpa_boot, . - psmpa_boot",
    ".popsection",
);

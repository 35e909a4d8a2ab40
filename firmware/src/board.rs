//! The board as both images use it: what differs between the two QEMU machines (addresses,
//! interrupts, clock), the interrupt vector, leaving QEMU, the stack's high-water mark, and what
//! a fault or a panic does.
//!
//! The firmware runs on two machines, one code path: `firmware/build.rs` sets the cfg
//! `board_an505` for a `thumbv8m.main` target, and the constants below are the one place the
//! machines differ.
//!
//! * mps2-an386: a Cortex-M4F (`thumbv7em-none-eabihf`), CMSDK timers at 0x4000_0000, 25 MHz.
//! * mps2-an505: a Cortex-M33 (`thumbv8m.main-none-eabihf`, the RP2350's core family) in Arm's
//!   IoT Kit. The core starts in Secure state (vector table at 0x1000_0000, `memory-an505.x`);
//!   the IoT Kit's own CMSDK timers sit behind its peripheral protection controller, which
//!   leaves them Secure at reset, so the firmware uses their Secure aliases at 0x5000_0000
//!   (QEMU's `hw/arm/armsse.c`: TIMER0 interrupt 3, TIMER1 4, the dual timer 5). QEMU clocks
//!   them at the board's 20 MHz (`hw/arm/mps2-tz.c`). Interrupts 14 and 15 are wired to
//!   nothing on either machine: the executors use them.

use core::sync::atomic::{AtomicBool, Ordering};

use cortex_m_rt::{ExceptionFrame, exception};
use cortex_m_semihosting::debug::{self, EXIT_FAILURE, EXIT_SUCCESS};
use defmt::error;

use crate::executor::{self, Irq};
use crate::time_driver;

#[cfg(not(board_an505))]
mod machine {
    /// QEMU's `-machine`.
    pub const NAME: &str = "mps2-an386";
    /// The system clock, which the core and the timers count.
    pub const CORE_HZ: u32 = 25_000_000;
    /// CMSDK APB TIMER0 (the clock), TIMER1 (the alarm), the dual timer (the reference).
    pub const TIMER0: usize = 0x4000_0000;
    /// See [`TIMER0`].
    pub const TIMER1: usize = 0x4000_1000;
    /// See [`TIMER0`].
    pub const DUALTIMER: usize = 0x4000_2000;
    /// TIMER1's interrupt.
    pub const TIMER1_IRQ: u16 = 9;
}

#[cfg(board_an505)]
mod machine {
    /// QEMU's `-machine`.
    pub const NAME: &str = "mps2-an505";
    /// The system clock (MAINCLK), which the IoT Kit's timers count.
    pub const CORE_HZ: u32 = 20_000_000;
    /// CMSDK APB TIMER0 (the clock), TIMER1 (the alarm), the dual timer (the reference): the
    /// Secure aliases.
    pub const TIMER0: usize = 0x5000_0000;
    /// See [`TIMER0`].
    pub const TIMER1: usize = 0x5000_1000;
    /// See [`TIMER0`].
    pub const DUALTIMER: usize = 0x5000_2000;
    /// TIMER1's interrupt.
    pub const TIMER1_IRQ: u16 = 4;
}

pub use machine::*;

defmt::timestamp!("{=u64:ms}", embassy_time::Instant::now().as_millis());

unsafe extern "C" {
    fn DefaultHandler();
}

/// The device part of the vector table: 16 entries (cortex-m-rt's default has 240, 960 bytes
/// of flash): the alarm and the two executors' interrupts, the rest to the default handler.
#[unsafe(link_section = ".vector_table.interrupts")]
#[unsafe(no_mangle)]
static __INTERRUPTS: [unsafe extern "C" fn(); 16] = {
    let mut table: [unsafe extern "C" fn(); 16] = [DefaultHandler; 16];
    table[Irq::Alarm as usize] = time_driver::alarm_interrupt;
    table[Irq::Sensing as usize] = executor::sensing_interrupt;
    table[Irq::Deciding as usize] = executor::deciding_interrupt;
    table
};

/// Leaves QEMU with success.
pub fn exit() -> ! {
    debug::exit(EXIT_SUCCESS);
    loop {
        cortex_m::asm::wfi();
    }
}

/// Logs `what` and leaves QEMU with failure.
pub fn fail(what: &str) -> ! {
    error!("failure: {=str}", what);
    debug::exit(EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}

/// The stack's high-water mark and size, bytes. cortex-m-rt's `paint-stack` fills the stack
/// region with a pattern at reset: the deepest word it no longer holds is the mark.
pub fn stack_high_water() -> (u32, u32) {
    unsafe extern "C" {
        static mut _stack_end: u32;
        static mut _stack_start: u32;
    }
    let bottom = (&raw const _stack_end).cast::<u32>();
    let top = (&raw const _stack_start).cast::<u32>();
    let mut p = bottom;
    // SAFETY: [bottom, top) is the stack region, word aligned, and readable.
    while p < top && unsafe { p.read_volatile() } == cortex_m_rt::STACK_PAINT_VALUE {
        p = p.wrapping_add(1);
    }
    (
        (top as u32).wrapping_sub(p as u32),
        (top as u32).wrapping_sub(bottom as u32),
    )
}

/// Makes a stack overflow fault instead of running on: flip-link puts the stack at the bottom
/// of RAM, but QEMU's mps2 machines map the addresses below it to a reserved region that
/// ignores writes and reads as zero, so an overflow there ran on silently. The M33 checks
/// MSPLIM; the M4F's MPU forbids the 32 bytes below RAM (the rest of the map stays as it is).
/// A push into the guard faults, and stacking the fault's frame there locks the core up.
pub fn guard_stack() {
    unsafe extern "C" {
        static mut _stack_end: u32;
    }
    let bottom = (&raw const _stack_end) as u32;
    #[cfg(board_an505)]
    // SAFETY: the limit is the stack region's own bottom; the stack is above it.
    unsafe {
        cortex_m::register::msplim::write(bottom)
    };
    #[cfg(not(board_an505))]
    {
        const SIZE_32_B: u32 = 4 << 1; // RASR.SIZE: 2^(4 + 1) bytes
        const XN: u32 = 1 << 28; // never execute; AP = 0: no access
        const ENABLE: u32 = 1;
        const PRIVDEFENA: u32 = 1 << 2; // the default map everywhere else
        // SAFETY: the MPU is set once, at boot, before any task runs; region 0 covers only
        // addresses no code or data uses.
        unsafe {
            let mpu = &*cortex_m::peripheral::MPU::PTR;
            mpu.rnr.write(0);
            mpu.rbar.write(bottom.wrapping_sub(32) & !31);
            mpu.rasr.write(XN | SIZE_32_B | ENABLE);
            mpu.ctrl.write(PRIVDEFENA | ENABLE);
        }
        cortex_m::asm::dsb();
        cortex_m::asm::isb();
    }
}

/// Set by the first panic: a panic while logging one exits at once, so the handler nests at
/// most once (the stack bound of `cargo xtask stack` relies on it).
static PANICKING: AtomicBool = AtomicBool::new(false);

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    if !PANICKING.swap(true, Ordering::Relaxed) {
        match info.location() {
            Some(l) => error!("panic at {=str}:{=u32}", l.file(), l.line()),
            None => error!("panic"),
        }
    }
    debug::exit(EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}

#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    error!(
        "HardFault at pc {=u32:#010x}, lr {=u32:#010x}",
        frame.pc(),
        frame.lr()
    );
    debug::exit(EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}

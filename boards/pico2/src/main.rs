//! The Fetch Tea robot on a Raspberry Pi Pico 2: `missions/fetch-tea.json` run by psmpa on the
//! RP2350, with the drivers and the robot of `psmpa-drivers`. This file only hands them pins
//! (the table in README.md) and places the runtime's two sides:
//!
//! * sensing (every sensor's sampler) on an interrupt executor, `SWI_IRQ_1` at priority 2, so
//!   that a sample falls due on time whatever the deciding side is computing;
//! * deciding (the control loop, the plan's state machine, the behaviours) in thread mode,
//!   in `main`.
//!
//! It runs the task once, logs the runtime's trace with the mission's names and the outcome
//! over RTT (defmt, [`log`]), and then keeps the wheels braked.
//!
//! When something goes wrong the motors stop: a panic or a fault puts the H-bridge in standby
//! before anything else; a watchdog fed from thread mode resets the board when deciding stops
//! running (a hang, a flood of interrupts), and a board reset by the watchdog stays still.
//! A stack overflow faults (the Cortex-M33's stack limit register).
#![no_std]
#![no_main]

use core::panic::PanicInfo;
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

use defmt::{error, info};
use defmt_rtt as _;
use embassy_executor::Spawner;
use embassy_rp::Peri;
use embassy_rp::executor::InterruptExecutor;
use embassy_rp::gpio::{Input, Level, Output, Pin, Pull};
use embassy_rp::interrupt;
use embassy_rp::interrupt::{InterruptExt, Priority};
use embassy_rp::pwm::{self, Pwm};
use embassy_rp::watchdog::{ResetReason, Watchdog};
use embassy_time::{Duration, Instant, Timer};
use psmpa_core::{Config, LoadedOf};
use psmpa_drivers::Active;
use psmpa_drivers::hbridge::{Channel, Drive};
use psmpa_drivers::hcsr04::Hcsr04;
use psmpa_drivers::marker::Marker;
use psmpa_drivers::robot::{
    Devices, FetchTea, FetchTeaCaps, FetchTeaRuntime, Names, Settings, mission,
};
use psmpa_drivers::switch::{DEBOUNCE, Switch};
use static_cell::StaticCell;

mod log;
use log::Log;

/// One TB6612FNG channel: IN1, IN2 and the PWM of its speed.
type Motor = Channel<Output<'static>, Output<'static>, Pwm<'static>>;
/// The robot on this board's pins.
type Robot = FetchTea<
    Hcsr04<Output<'static>, Input<'static>>,
    Switch<Input<'static>>,
    Marker<Input<'static>>,
    Switch<Input<'static>>,
    Drive<Motor, Motor, Output<'static>>,
>;
type Runtime = FetchTeaRuntime<'static, Robot, Log>;

/// The PWM's counter wraps at this value: 150 MHz / 7,500 = 20 kHz, above hearing. A period
/// is 7,500 counts; `SetDutyCycle`'s maximum is 7,499 of them (a brake does not need more:
/// with IN1 = IN2 = high the TB6612FNG brakes whatever the PWM).
const PWM_TOP: u16 = 7_499;

/// The watchdog resets the board when thread mode (deciding) has not run for this long.
const WATCHDOG_TIMEOUT: Duration = Duration::from_millis(500);

/// The H-bridge's STBY and direction pins, as a mask of SIO outputs, once they are outputs:
/// what a panic or a fault clears.
static MOTOR_PINS: AtomicU32 = AtomicU32::new(0);

/// Stops the motors from anywhere, a fault handler included: STBY low puts the TB6612FNG in
/// standby (the motors coast) and the direction inputs go low. A write to SIO's GPIO_OUT_CLR,
/// through no driver and no lock.
fn motors_off() {
    /// SIO's GPIO_OUT_CLR (RP2350 datasheet, SIO registers: base 0xd000_0000, offset 0x020).
    const GPIO_OUT_CLR: *mut u32 = 0xd000_0020 as *mut u32;
    // SAFETY: a write-only register whose ones clear those output bits of SIO; the mask holds
    // only the motor driver's pins, which are SIO outputs once they are in it.
    unsafe { GPIO_OUT_CLR.write_volatile(MOTOR_PINS.load(Ordering::Relaxed)) }
}

/// Stops the motors first, then logs the panic (on its first entry only: a panic while
/// logging ends here) and raises a HardFault, where a debug probe stops with a backtrace.
#[panic_handler]
fn panic(info: &PanicInfo) -> ! {
    motors_off();
    cortex_m::interrupt::disable();
    static PANICKED: AtomicBool = AtomicBool::new(false);
    if !PANICKED.swap(true, Ordering::Relaxed) {
        error!("{}", defmt::Display2Format(info));
    }
    cortex_m::asm::udf()
}

/// Any fault: the motors stop, and the watchdog, no longer fed, resets the board.
#[cortex_m_rt::exception(trampoline = false)]
unsafe fn HardFault() -> ! {
    motors_off();
    loop {
        cortex_m::asm::wfi();
    }
}

static SENSING: InterruptExecutor = InterruptExecutor::new();

#[interrupt]
unsafe fn SWI_IRQ_1() {
    // SAFETY: the interrupt `SENSING` was started on, and only that.
    unsafe { SENSING.on_interrupt() }
}

/// One motor's channel: its direction pins, low until the first command, and its PWM.
fn motor(in1: Peri<'static, impl Pin>, in2: Peri<'static, impl Pin>, pwm: Pwm<'static>) -> Motor {
    Channel::new(
        Output::new(in1, Level::Low),
        Output::new(in2, Level::Low),
        pwm,
    )
}

#[embassy_executor::task]
async fn sensing(runtime: &'static Runtime) {
    match runtime.sensing().await {}
}

/// Feeds the watchdog from thread mode: starved of it, the board resets.
#[embassy_executor::task]
async fn feed(mut watchdog: Watchdog) {
    loop {
        watchdog.feed(WATCHDOG_TIMEOUT);
        Timer::after(WATCHDOG_TIMEOUT / 4).await;
    }
}

#[embassy_executor::main(
    executor = "embassy_rp::executor::Executor",
    entry = "cortex_m_rt::entry"
)]
async fn main(spawner: Spawner) {
    // MSPLIM at the stack's end (flip-link puts it at the bottom of RAM).
    if embassy_rp::install_core0_stack_guard().is_err() {
        error!("the stack guard could not be installed");
    }
    let p = embassy_rp::init(Default::default());

    let mut watchdog = Watchdog::new(p.WATCHDOG);
    if watchdog.reset_reason() == Some(ResetReason::TimedOut) {
        // Stopped by a hang or a fault: a robot does not drive off again by itself.
        watchdog.stop();
        error!("the watchdog reset the board (a hang or a fault): reset it to run again");
        return;
    }
    // A probe's halt does not reset the board.
    watchdog.pause_on_debug(true);
    watchdog.start(WATCHDOG_TIMEOUT);
    match feed(watchdog) {
        Ok(task) => spawner.spawn(task),
        Err(_) => {
            error!("the watchdog task is already running");
            return;
        }
    }

    static MISSION: StaticCell<LoadedOf<'static, Names, FetchTeaCaps>> = StaticCell::new();
    let loaded = match mission() {
        Ok(loaded) => MISSION.init(loaded),
        Err(e) => {
            error!("the mission does not load: {}", e);
            return;
        }
    };

    let motor_pins = [
        p.PIN_9.pin(),
        p.PIN_10.pin(),
        p.PIN_11.pin(),
        p.PIN_13.pin(),
        p.PIN_14.pin(),
    ];
    let mut speed = pwm::Config::default();
    speed.top = PWM_TOP;
    let left = motor(
        p.PIN_10,
        p.PIN_11,
        Pwm::new_output_a(p.PWM_SLICE6, p.PIN_12, speed.clone()),
    );
    let right = motor(
        p.PIN_13,
        p.PIN_14,
        Pwm::new_output_b(p.PWM_SLICE7, p.PIN_15, speed),
    );
    let devices = Devices {
        sonar: Hcsr04::new(
            Output::new(p.PIN_2, Level::Low),
            Input::new(p.PIN_3, Pull::Down),
        ),
        bumper: Switch::new(Input::new(p.PIN_4, Pull::Up), Active::Low, DEBOUNCE),
        // Pulled up: unplugged, it reads "no marker", not noise.
        camera: Marker::new(Input::new(p.PIN_5, Pull::Up), Active::Low),
        handle: Switch::new(Input::new(p.PIN_6, Pull::Up), Active::Low, DEBOUNCE),
        wheels: Drive::with_standby(left, right, Output::new(p.PIN_9, Level::Low)),
    };

    // The pins are SIO outputs now: a panic or a fault may clear them.
    MOTOR_PINS.store(
        motor_pins.iter().fold(0, |mask, pin| mask | 1 << pin),
        Ordering::Relaxed,
    );

    static ROBOT: StaticCell<Robot> = StaticCell::new();
    static RUNTIME: StaticCell<Runtime> = StaticCell::new();
    let robot = ROBOT.init(FetchTea::new(
        devices,
        loaded.bindings.clone(),
        Settings::DEFAULT,
    ));
    let runtime: &'static Runtime = RUNTIME.init(Runtime::new(
        &loaded.mission,
        robot,
        Log(&loaded.mission),
        Config::default(),
    ));

    // Sensing above deciding: priority 2 preempts thread mode; GPIO (embassy-rp's bank 0
    // interrupt) is at 3, so an edge's waker only pends the sensing executor.
    interrupt::SWI_IRQ_1.set_priority(Priority::P2);
    let spawner = SENSING.start(interrupt::SWI_IRQ_1);
    match sensing(runtime) {
        Ok(task) => spawner.spawn(task),
        Err(_) => {
            error!("the sensing task is already running");
            return;
        }
    }

    match runtime.run().await {
        Ok(report) => info!(
            "Fetch Tea: goal reached at {=u64} ms, {=u16} plan(s) started",
            Instant::now().as_millis(),
            report.plans_started
        ),
        Err(e) => error!("Fetch Tea failed: {}", e),
    }
}

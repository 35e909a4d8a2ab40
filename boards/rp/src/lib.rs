//! The Fetch Tea robot on a Raspberry Pi Pico (RP2040, feature `rp2040`) or Pico 2 (RP2350A,
//! feature `rp235xa`): `missions/fetch-tea.json` run by psmpa, with the drivers and the robot
//! of `psmpa-drivers`. This crate hands them pins (the one pin table, in [`main`]), reads the
//! robot's calibration from flash ([`calibration`]) and places the runtime's two sides:
//!
//! * sensing (every sensor's sampler) on an interrupt executor, `SWI_IRQ_1` at priority 2, so
//!   that a sample falls due on time whatever the deciding side is computing;
//! * deciding (the control loop, the plan's state machine, the behaviours, and the planner
//!   when no library plan applies: a locked kitchen door) in thread mode.
//!
//! It runs the task once, logs the runtime's trace with the mission's names and the outcome
//! over RTT (defmt, [`log`]), and then keeps the wheels braked.
//!
//! When something goes wrong the motors stop: a panic or a fault puts the H-bridge in standby
//! before anything else; a watchdog fed from thread mode resets the board when deciding stops
//! running (a hang, a flood of interrupts), and a board reset by the watchdog stays still.
//! A stack overflow faults (flip-link puts the stack below the statics; the RP2350's stack
//! limit register, the RP2040's MPU guard).
//!
//! The board crates (`boards/pico`, `boards/pico2`) only choose the chip and the memory map:
//! this crate holds the entry ([`main`]), the interrupt handlers and the panic handler.
#![no_std]

#[cfg(all(feature = "rp2040", feature = "rp235xa"))]
compile_error!("choose one chip: feature `rp2040` (Pico) or `rp235xa` (Pico 2), not both");
#[cfg(not(any(feature = "rp2040", feature = "rp235xa")))]
compile_error!("choose a chip: feature `rp2040` (Pico) or `rp235xa` (Pico 2)");

pub mod calibration;
pub mod log;
#[cfg(feature = "recorder")]
pub mod record;

use core::panic::PanicInfo;

use defmt::{error, info, warn};
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
use portable_atomic::{AtomicBool, AtomicU32, Ordering};
use psmpa_core::{Config, DecidingSide, SensingSide};
use psmpa_drivers::Active;
use psmpa_drivers::hbridge::{Channel, Drive};
use psmpa_drivers::hcsr04::Hcsr04;
use psmpa_drivers::marker::Marker;
use psmpa_drivers::switch::{DEBOUNCE, Switch};
use psmpa_fetch_tea::{
    Compute, Devices, FetchTea, FetchTeaRuntime, PLANNER, PlannerSpace, Settings, fetch_tea,
};
use static_cell::StaticCell;

use crate::log::Log;

/// One TB6612FNG channel: IN1, IN2 and the PWM of its speed.
type Motor = Channel<Output<'static>, Output<'static>, Pwm<'static>>;
/// The robot on this board's pins.
type Robot = FetchTea<
    Hcsr04<Output<'static>, Input<'static>>,
    Switch<Input<'static>>,
    Marker<Input<'static>>,
    Switch<Input<'static>>,
    Drive<Motor, Motor, Output<'static>>,
    Busy,
>;

/// The walk's path planning ([`Settings::plan`](psmpa_fetch_tea::Settings::plan)) is
/// processor time: a busy wait on the deciding side, which sensing preempts.
struct Busy;

impl Compute for Busy {
    fn compute(&self, time: Duration) {
        // A busy wait on the clock, written here (not `embassy_time::block_for`, which the
        // compiler may keep out of line): `cargo xtask wcet` takes it as the declared planning
        // time of this function, and refuses one anywhere else.
        let until = Instant::now().saturating_add(time);
        while Instant::now() < until {}
    }
}
type Runtime = FetchTeaRuntime<'static, Robot, Log>;

/// The motors' PWM frequency: above hearing.
const PWM_HZ: u32 = 20_000;

/// The watchdog resets the board when thread mode (deciding) has not run for this long.
pub const WATCHDOG_TIMEOUT: Duration = Duration::from_millis(500);

/// SIO's GPIO_OUT_CLR: writing ones clears those outputs (RP2040 datasheet 2.3.1.7, offset
/// 0x018; RP2350 datasheet 3.1.11, offset 0x020; SIO's base is 0xd000_0000 on both).
#[cfg(feature = "rp2040")]
const GPIO_OUT_CLR: usize = 0xd000_0018;
#[cfg(not(feature = "rp2040"))]
const GPIO_OUT_CLR: usize = 0xd000_0020;

/// The H-bridge's STBY and direction pins, as a mask of SIO outputs, once they are outputs:
/// what a panic or a fault clears.
static MOTOR_PINS: AtomicU32 = AtomicU32::new(0);

/// Stops the motors from anywhere, a fault handler included: STBY low puts the TB6612FNG in
/// standby (the motors coast) and the direction inputs go low. A write to SIO's GPIO_OUT_CLR,
/// through no driver and no lock.
fn motors_off() {
    // SAFETY: a write-only register whose ones clear those output bits of SIO; the mask holds
    // only the motor driver's pins, which are SIO outputs once they are in it.
    unsafe { (GPIO_OUT_CLR as *mut u32).write_volatile(MOTOR_PINS.load(Ordering::Relaxed)) }
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

/// A test point the firmware never calls: a debug probe (`call psmpa_test_panic()` in gdb) or
/// the bench makes thread mode call it, to panic as a bug would and check that the motors stop
/// first. In section `.psmpa_test`, which the boards' `memory.x` keeps: nothing refers to it.
#[unsafe(no_mangle)]
#[unsafe(link_section = ".psmpa_test")]
pub extern "C" fn psmpa_test_panic() -> ! {
    panic!("test point psmpa_test_panic: a panic on purpose")
}

/// A test point the firmware never calls: thread mode loops here for ever, as a behaviour
/// stuck in a loop would, and the watchdog must reset the board.
#[unsafe(no_mangle)]
#[unsafe(link_section = ".psmpa_test")]
pub extern "C" fn psmpa_test_hang() -> ! {
    loop {
        cortex_m::asm::nop();
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
async fn sensing(mut side: SensingSide<'static, Runtime>) {
    match side.run().await {}
}

/// Feeds the watchdog from thread mode: starved of it, the board resets.
#[embassy_executor::task]
async fn feed(mut watchdog: Watchdog) {
    loop {
        watchdog.feed(WATCHDOG_TIMEOUT);
        Timer::after(WATCHDOG_TIMEOUT / 4).await;
    }
}

/// The firmware: checks how the board last stopped, starts the watchdog, reads the robot's
/// calibration, hands the pins to the drivers (the pin table below, as in the boards'
/// READMEs), starts sensing above deciding and the control task in thread mode.
#[embassy_executor::main(
    executor = "embassy_rp::executor::Executor",
    entry = "cortex_m_rt::entry"
)]
async fn main(spawner: Spawner) {
    // The stack's guard: the RP2350's MSPLIM, an MPU region on the RP2040 (flip-link puts
    // the stack at the bottom of RAM).
    if embassy_rp::install_core0_stack_guard().is_err() {
        error!("the stack guard could not be installed");
    }
    let p = embassy_rp::init(Default::default());

    let mut watchdog = Watchdog::new(p.WATCHDOG);
    let reset = watchdog.reset_reason() == Some(ResetReason::TimedOut);
    if reset {
        watchdog.stop();
    }

    let settings = match calibration::read() {
        Ok(s) => {
            info!(
                "calibration from flash: clearance {=u16} mm, walk {=u32} mm at {=u32} mm/s ({=i16} permille), planning {=u64} us, side step {=u64} ms, echo rise {=u64} ms",
                s.clearance_mm,
                s.walk_mm,
                s.walk_mm_s,
                s.walk_permille,
                s.plan.as_micros(),
                s.avoid.as_millis(),
                s.sonar_rise.as_millis()
            );
            s
        }
        Err(e) => {
            warn!("{}: the default settings", e);
            Settings::DEFAULT
        }
    };

    // The flight recording begins; after a watchdog reset, what the ring kept comes first.
    #[cfg(feature = "recorder")]
    record::start(&settings, reset);
    if reset {
        // Stopped by a hang or a fault: a robot does not drive off again by itself.
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
    #[cfg(feature = "recorder")]
    match record::drain() {
        Ok(task) => spawner.spawn(task),
        Err(_) => {
            error!("the recorder task is already running");
            return;
        }
    }

    // The compiled mission's tables, in flash: the log's names.
    let mission = &fetch_tea::TABLES;

    // The pin table (README.md): GP2 trigger, GP3 echo, GP4 bumper, GP5 marker, GP6 handle,
    // GP9 STBY, GP10/11/12 left IN1/IN2/PWM (slice 6 A), GP13/14/15 right (slice 7 B).
    let motor_pins = [
        p.PIN_9.pin(),
        p.PIN_10.pin(),
        p.PIN_11.pin(),
        p.PIN_13.pin(),
        p.PIN_14.pin(),
    ];
    let mut speed = pwm::Config::default();
    // 125 MHz / 6,250 on the RP2040, 150 MHz / 7,500 on the RP2350: 20 kHz.
    speed.top = u16::try_from(embassy_rp::clocks::clk_sys_freq() / PWM_HZ)
        .unwrap_or(u16::MAX)
        .saturating_sub(1);
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
        sonar: {
            let sonar = Hcsr04::new(
                Output::new(p.PIN_2, Level::Low),
                Input::new(p.PIN_3, Pull::Down),
            );
            if settings.sonar_rise.as_ticks() > 0 {
                sonar.with_rise_timeout(settings.sonar_rise)
            } else {
                sonar
            }
        },
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
    let robot = ROBOT.init(FetchTea::new(devices, settings).with_compute(Busy));
    let runtime: &'static mut Runtime = RUNTIME.init(Runtime::new(
        fetch_tea::FetchTea,
        robot,
        Log(mission),
        Config::default(),
    ));
    // The calibration's sampling periods, where it gives them.
    for (sensor, period) in [
        (fetch_tea::Sensor::Sonar, settings.sonar_period),
        (fetch_tea::Sensor::Bumper, settings.bumper_period),
    ] {
        if period.is_some() && !runtime.set_period(sensor, period) {
            error!("the {} period cannot be set", sensor);
            return;
        }
    }
    let (sensing_side, deciding_side) = runtime.split();

    // Sensing above deciding: priority 2 preempts thread mode; GPIO (embassy-rp's bank 0
    // interrupt) is at 3, so an edge's waker only pends the sensing executor.
    interrupt::SWI_IRQ_1.set_priority(Priority::P2);
    let sensing_spawner = SENSING.start(interrupt::SWI_IRQ_1);
    match sensing(sensing_side) {
        Ok(task) => sensing_spawner.spawn(task),
        Err(_) => {
            error!("the sensing task is already running");
            return;
        }
    }

    // The search space, a `static` (about 1 KiB): searched in slices of
    // `Config::plan_slice` nodes, between which sensing and the watchdog's task run.
    static SPACE: StaticCell<PlannerSpace> = StaticCell::new();
    let space = SPACE.init(PlannerSpace::new());
    match control(deciding_side, mission, space) {
        Ok(task) => spawner.spawn(task),
        Err(_) => error!("the control task is already running"),
    }
}

/// Runs the task once (the control loop, Algorithm 1, planning in `space` when no library
/// plan applies) in thread mode: a task of its own, so that each of its polls is a deciding
/// step and no more (`cargo xtask wcet` bounds one).
#[embassy_executor::task]
async fn control(
    mut side: DecidingSide<'static, Runtime>,
    mission: &'static log::Tables,
    space: &'static mut PlannerSpace,
) {
    let outcome = side.run_planning(&PLANNER, space).await;
    #[cfg(feature = "recorder")]
    record::flush();
    match outcome {
        Ok(report) => info!(
            "Fetch Tea: goal reached at {=u64} ms, {=u16} plan(s) started",
            Instant::now().as_millis(),
            report.plans_started
        ),
        Err(e) => error!("Fetch Tea failed: {}", log::Named(&Log(mission), e)),
    }
}

//! The Fetch Tea robot on a Raspberry Pi Pico 2: `missions/fetch-tea.json` run by psmpa on the
//! RP2350, with the drivers and the robot of `psmpa-drivers`. This file only hands them pins
//! (the table in README.md) and places the runtime's two sides:
//!
//! * sensing (every sensor's sampler) on an interrupt executor, `SWI_IRQ_1` at priority 2, so
//!   that a sample falls due on time whatever the deciding side is computing;
//! * deciding (the control loop, the plan's state machine, the behaviours) in thread mode,
//!   in `main`.
//!
//! It runs the task once, logs the outcome over RTT (defmt), and then keeps the wheels braked.
#![no_std]
#![no_main]

use defmt::{error, info};
use defmt_rtt as _;
use embassy_executor::Spawner;
use embassy_rp::Peri;
use embassy_rp::executor::InterruptExecutor;
use embassy_rp::gpio::{Input, Level, Output, Pin, Pull};
use embassy_rp::interrupt;
use embassy_rp::interrupt::{InterruptExt, Priority};
use embassy_rp::pwm::{self, Pwm};
use embassy_time::Instant;
use panic_probe as _;
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
type Runtime = FetchTeaRuntime<'static, Robot>;

/// The PWM's counter wraps at this value: 150 MHz / 7,500 = 20 kHz, above hearing, and
/// `SetDutyCycle` gets 7,501 steps.
const PWM_TOP: u16 = 7_499;

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

#[embassy_executor::main(
    executor = "embassy_rp::executor::Executor",
    entry = "cortex_m_rt::entry"
)]
async fn main(_spawner: Spawner) {
    let p = embassy_rp::init(Default::default());

    static MISSION: StaticCell<LoadedOf<'static, Names, FetchTeaCaps>> = StaticCell::new();
    let loaded = match mission() {
        Ok(loaded) => MISSION.init(loaded),
        Err(e) => {
            error!("the mission does not load: {}", e);
            return;
        }
    };

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
        camera: Marker::new(Input::new(p.PIN_5, Pull::None), Active::Low),
        handle: Switch::new(Input::new(p.PIN_6, Pull::Up), Active::Low, DEBOUNCE),
        wheels: Drive::with_standby(left, right, Output::new(p.PIN_9, Level::Low)),
    };

    static ROBOT: StaticCell<Robot> = StaticCell::new();
    static RUNTIME: StaticCell<Runtime> = StaticCell::new();
    let robot = ROBOT.init(FetchTea::new(
        devices,
        loaded.bindings.clone(),
        Settings::DEFAULT,
    ));
    let runtime: &'static Runtime =
        RUNTIME.init(Runtime::new(&loaded.mission, robot, (), Config::default()));

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

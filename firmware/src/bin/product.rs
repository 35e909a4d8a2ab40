//! The product-shaped firmware: what a robot's own firmware carries, with no simulated world,
//! no scenario parser and no JSON parser. The Fetch Tea mission is compiled in
//! (`include_mission!`: checked when the firmware builds, a `static` built at compile time); a
//! platform of stubs stands where the drivers go (each sensor read awaits its device, each
//! action takes time), matching the mission's sensors and actions exhaustively; the sensing
//! side runs on the interrupt executor above the deciding side, as on the simulator-carrying
//! firmware. It runs the task once, logs the outcome, its longest poll and critical section
//! and its stack, and leaves QEMU. `cargo xtask size` holds it to its budgets.
//!
//! It runs the mission's library plan (`DecidingSide::run`, which links no search): re-planning
//! with the planner (`DecidingSide::run_planning`) would add the search's code and its 1 KiB search
//! space, past the RAM budget.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "psmpa-product runs on the target: cargo run -p psmpa-firmware --bin psmpa-product --target thumbv7em-none-eabihf --profile firmware (mps2-an386), or --target thumbv8m.main-none-eabihf (mps2-an505)"
    );
}

#[cfg(target_os = "none")]
mod product {
    use core::mem::MaybeUninit;

    use cortex_m_rt::entry;
    use defmt::info;
    use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
    use embassy_time::{Instant, Timer};
    use psmpa_core::{
        Act, Actuator, Config, Outcome, Platform, Reading, Sensor, SensorFault, Value,
    };
    use psmpa_core::{DecidingSide, SensingSide};
    use psmpa_firmware::board::{exit, fail, guard_stack, stack_high_water};
    use psmpa_firmware::executor;

    psmpa_core::include_mission!(mod fetch_tea = "../missions/fetch-tea.json");

    type ProductRuntime = fetch_tea::Runtime<'static, Stubs>;

    /// The platform of stubs: a free path, a visible and unlocked door. Where a driver would
    /// await its device, a stub awaits a timer of the device's time.
    struct Stubs;

    impl Sensor<fetch_tea::FetchTea> for Stubs {
        async fn switch_on(&self, _sensor: fetch_tea::Sensor) -> Result<(), SensorFault> {
            Ok(())
        }

        async fn switch_off(&self, _sensor: fetch_tea::Sensor) {}

        async fn sample(&self, sensor: fetch_tea::Sensor) -> Result<Option<Reading>, SensorFault> {
            use fetch_tea::Sensor::{Bumper, Camera, Handle, Sonar};
            // The device's time: an echo from 1 m (5.8 ms), a camera frame; the switches
            // answer at once. Every fact the sensor perceives holds.
            let (wait_us, value) = match sensor {
                Sonar => (5_800, Value::Mm(1_000)),
                Camera => (30_000, Value::Bool(true)),
                Bumper | Handle => (0, Value::Bool(false)),
            };
            Timer::after_micros(wait_us).await;
            Ok(Some(Reading::of(value, true)))
        }
    }

    impl Platform for Stubs {
        type Mutex = CriticalSectionRawMutex;
    }

    impl Actuator<fetch_tea::FetchTea> for Stubs {
        fn halt(&self, _: fetch_tea::Action) {} // nothing to stop

        async fn run(&self, act: Act<'_, fetch_tea::FetchTea>) -> Outcome {
            use fetch_tea::Action::{
                EnterByBackDoor, EnterKitchen, GoToBackDoor, GoToDoor, OpenBackDoor, OpenDoor,
            };
            let steps = match act.action() {
                GoToDoor | GoToBackDoor => 20,
                OpenDoor | OpenBackDoor => 5,
                EnterKitchen | EnterByBackDoor => 10,
            };
            // 100 ms a step; a step does not start while the precondition is false. (Every
            // action's I/O alike: the stubs read no sensor.)
            let io = act.untyped();
            for _ in 0..steps {
                if io.violation().is_some() {
                    return Outcome::Interrupted;
                }
                Timer::after_millis(100).await;
            }
            Outcome::Success
        }
    }

    #[embassy_executor::task]
    async fn sensing(mut side: SensingSide<'static, ProductRuntime>) {
        match side.run().await {}
    }

    #[embassy_executor::task]
    async fn deciding(mut side: DecidingSide<'static, ProductRuntime>) {
        let result = side.run().await;
        let polls = executor::take_polls();
        match result {
            Ok(report) => info!(
                "product goal reached: plans={=u16} at_ms={=u64} longest_poll_cycles={=u32} longest_critical_cycles={=u32}",
                report.plans_started,
                Instant::now().as_millis(),
                polls.max_cycles,
                polls.max_critical
            ),
            Err(e) => {
                defmt::error!("product run failed: {}", e);
                fail("the mission failed");
            }
        }
        let (used, size) = stack_high_water();
        info!("stack high-water {=u32} of {=u32} bytes", used, size);
        exit()
    }

    #[entry]
    fn main() -> ! {
        // `#[entry]` makes these `&'static mut`, safely: main runs once. Uninitialised (`.bss`)
        // until written: no initial values in flash.
        static mut DECIDING: executor::Slot = MaybeUninit::uninit();
        static mut RUNTIME: MaybeUninit<ProductRuntime> = MaybeUninit::uninit();
        guard_stack();
        let (sensing_side, deciding_side) = init(RUNTIME).split();
        psmpa_firmware::time_driver::start();
        executor::run(DECIDING, |thread, interrupt| {
            match (deciding(deciding_side), sensing(sensing_side)) {
                (Ok(d), Ok(s)) => {
                    thread.spawn(d);
                    interrupt.spawn(s);
                }
                _ => fail("a task is already running"),
            }
        })
    }

    /// Recurses until the stack runs out (the `inject-fault` build): with flip-link the stack
    /// sits below the statics, so this must fault at the start of RAM, not overwrite them.
    #[inline(never)]
    fn overflow(depth: u32) -> u32 {
        let frame = core::hint::black_box([depth; 16]);
        match depth {
            0 => 0,
            _ => overflow(depth - 1).wrapping_add(frame[1]),
        }
    }

    /// Builds the runtime in its static, out of line: the frame that builds it (on the stack,
    /// then moved) ends before the executors start, instead of staying under them for good.
    #[inline(never)]
    fn init(runtime: &'static mut MaybeUninit<ProductRuntime>) -> &'static mut ProductRuntime {
        if cfg!(feature = "inject-fault") {
            overflow(u32::MAX);
        }
        runtime.write(ProductRuntime::new(
            fetch_tea::FetchTea,
            &Stubs,
            (),
            Config::default(),
        ))
    }
}

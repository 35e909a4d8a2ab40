//! The product-shaped firmware: what a robot's own firmware carries, with no simulated world
//! and no scenario parser. The Fetch Tea mission is loaded from JSON at boot; a platform of
//! stubs stands where the drivers go (each sensor read awaits its device, each action takes
//! time); the sensing side runs on the interrupt executor above the deciding side, as on the
//! simulator-carrying firmware. It runs the task once, logs the outcome, its longest poll and
//! critical section and its stack, and leaves QEMU. `cargo xtask size` holds it to 8 KiB of RAM
//! with the stack and to 32 KiB of flash.
//!
//! It runs the mission's library plan (`Engine::run`, which links no search): re-planning with
//! the planner (`Engine::run_planning`) would add the search's code and its 1 KiB search
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
        ActionId, ActionIo, Actuator, Bindings, Capacity, Caps, Config, MissionOf, Outcome,
        Platform, Reading, Registry, Runtime, Sensor, SensorFault, SensorId, Value,
    };
    use psmpa_firmware::board::{exit, fail, stack_high_water};
    use psmpa_firmware::executor;

    /// `missions/fetch-tea.json`, whitespace removed at build time.
    static FETCH_TEA: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fetch-tea.json"));

    /// Capacities: 4 sensors, 8 actions, 4 plans of at most 6 actions, 4 keys per store.
    type FetchTeaCaps = Caps<4, 8, 4, 6, 4>;
    type FetchTea = MissionOf<'static, FetchTeaCaps>;
    type Parts = <FetchTeaCaps as Capacity>::Bindings<Part, Motion>;
    type ProductRuntime = Runtime<'static, Stubs, FetchTeaCaps>;

    /// The sensors a mission may name, each a driver on a real board.
    #[derive(Clone, Copy)]
    enum Part {
        /// Ultrasonic ranger: a read waits for the echo.
        Sonar,
        /// Foot bump switches.
        Bumper,
        /// Marker camera, one shot at the door.
        Camera,
        /// Limit switch the arm presses on the handle.
        Handle,
    }

    /// The actuator behaviours a mission may name.
    #[derive(Clone, Copy)]
    enum Motion {
        Walk,
        OpenDoor,
        Enter,
    }

    struct Board;

    impl Registry for Board {
        type Sensor = Part;
        type Action = Motion;
        fn sensor(&self, name: &str) -> Option<Part> {
            Some(match name {
                "sonar" => Part::Sonar,
                "bumper" => Part::Bumper,
                "camera" => Part::Camera,
                "handle" => Part::Handle,
                _ => return None,
            })
        }
        fn action(&self, name: &str) -> Option<Motion> {
            Some(match name {
                "go to door" | "go to back door" => Motion::Walk,
                "open door" | "open back door" => Motion::OpenDoor,
                "enter kitchen" | "enter by back door" => Motion::Enter,
                _ => return None,
            })
        }
    }

    /// The platform of stubs: a free path, a visible and unlocked door. Where a driver would
    /// await its device, a stub awaits a timer of the device's time.
    struct Stubs {
        mission: &'static FetchTea,
        parts: &'static Parts,
    }

    impl Sensor for Stubs {
        async fn switch_on(&self, _sensor: SensorId) -> Result<(), SensorFault> {
            Ok(())
        }

        async fn switch_off(&self, _sensor: SensorId) {}

        async fn sample(&self, sensor: SensorId) -> Result<Option<Reading>, SensorFault> {
            let per = self
                .mission
                .domain
                .sensor(sensor)
                .ok_or(SensorFault::Device(0))?
                .per;
            // The device's time: an echo from 1 m (5.8 ms), a camera frame; the switches
            // answer at once.
            let (wait_us, value) = match self.parts.sensor(sensor) {
                Some(Part::Sonar) => (5_800, Value::Mm(1_000)),
                Some(Part::Camera) => (30_000, Value::Bool(true)),
                Some(Part::Bumper | Part::Handle) => (0, Value::Bool(false)),
                None => return Err(SensorFault::Device(0)),
            };
            Timer::after_micros(wait_us).await;
            Ok(Some(Reading::new(value, per)))
        }
    }

    impl Platform for Stubs {
        type Mutex = CriticalSectionRawMutex;
    }

    impl Actuator for Stubs {
        async fn run(&self, action: ActionId, io: &ActionIo<'_>) -> Outcome {
            let steps = match self.parts.action(action) {
                Some(Motion::Walk) => 20,
                Some(Motion::OpenDoor) => 5,
                Some(Motion::Enter) => 10,
                None => return Outcome::Failure,
            };
            // 100 ms a step; a step does not start while the precondition is false.
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
    async fn sensing(runtime: &'static ProductRuntime) {
        match runtime.sensing().await {}
    }

    #[embassy_executor::task]
    async fn deciding(runtime: &'static ProductRuntime) {
        let result = runtime.run().await;
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
        static mut MISSION: MaybeUninit<FetchTea> = MaybeUninit::uninit();
        static mut PARTS: MaybeUninit<Parts> = MaybeUninit::uninit();
        static mut STUBS: MaybeUninit<Stubs> = MaybeUninit::uninit();
        static mut RUNTIME: MaybeUninit<ProductRuntime> = MaybeUninit::uninit();
        let runtime = init(MISSION, PARTS, STUBS, RUNTIME);
        psmpa_firmware::time_driver::start();
        executor::run(DECIDING, |thread, interrupt| {
            match (deciding(runtime), sensing(runtime)) {
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

    /// Loads the mission and builds the runtime in their statics, out of line: the frames
    /// that build them (the runtime is built on the stack, then moved) end before the
    /// executors start, instead of staying under them for good.
    #[inline(never)]
    fn init(
        mission: &'static mut MaybeUninit<FetchTea>,
        parts: &'static mut MaybeUninit<Parts>,
        stubs: &'static mut MaybeUninit<Stubs>,
        runtime: &'static mut MaybeUninit<ProductRuntime>,
    ) -> &'static ProductRuntime {
        if cfg!(feature = "inject-fault") {
            overflow(u32::MAX);
        }
        let mission = mission.write(FetchTea::empty());
        let parts = parts.write(Bindings::new());
        if psmpa_core::mission::load_into(FETCH_TEA, &Board, mission, parts).is_err() {
            fail("the Fetch Tea mission does not load");
        }
        let (mission, parts) = (&*mission, &*parts);
        let stubs = &*stubs.write(Stubs { mission, parts });
        runtime.write(ProductRuntime::new(mission, stubs, (), Config::default()))
    }
}

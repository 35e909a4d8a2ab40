//! psmpa on a Cortex-M4F (QEMU mps2-an386): the same core, the same Fetch Tea mission and the
//! same simulated world as the host simulator. Every embedded scenario runs under both
//! architectures from tick 0; each run logs the summary fields of `psmpa-sim run --json`,
//! which `cargo xtask qemu` compares with the host. The runtime's sensing side runs on an
//! executor of its own, polled before the deciding side's whenever it has work.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "psmpa-firmware runs on the target: cargo run -p psmpa-firmware --target thumbv7em-none-eabihf --release"
    );
}

#[cfg(target_os = "none")]
mod executor;
#[cfg(target_os = "none")]
mod time_driver;

#[cfg(target_os = "none")]
mod firmware {
    use cortex_m_rt::{ExceptionFrame, entry, exception};
    use cortex_m_semihosting::debug::{self, EXIT_FAILURE, EXIT_SUCCESS};
    use defmt::{error, info};
    use defmt_semihosting as _;
    use psmpa_core::{TraceEvent, TraceSink};
    use psmpa_sim::robot::{Arch, Robot};
    use psmpa_sim::run::{Beside, Sides};
    use psmpa_sim::scenario::Scenario;

    use crate::{executor, time_driver};

    include!(concat!(env!("OUT_DIR"), "/scenarios.rs"));

    /// `missions/fetch-tea.json`, whitespace removed at build time.
    static FETCH_TEA: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/fetch-tea.json"));

    defmt::timestamp!("{=u64:ms}", embassy_time::Instant::now().as_millis());

    unsafe extern "C" {
        fn DefaultHandler();
    }

    /// The device part of the vector table: no device interrupt is ever enabled, so 16 entries
    /// to the default handler do (cortex-m-rt's default has 240, 960 bytes of flash).
    #[unsafe(link_section = ".vector_table.interrupts")]
    #[unsafe(no_mangle)]
    static __INTERRUPTS: [unsafe extern "C" fn(); 16] = [DefaultHandler; 16];

    #[entry]
    fn main() -> ! {
        // `#[entry]` makes these `&'static mut`, safely: main runs once.
        static mut EXECUTORS: executor::Slots = executor::Slots::new();
        static mut ROBOT: Robot<'static> = Robot::empty();
        static mut SCENARIO: Scenario = Scenario::empty();
        static mut SPACE: psmpa_sim::robot::PlannerSpace = psmpa_sim::robot::PlannerSpace::new();
        let Some(mut core) = cortex_m::Peripherals::take() else {
            fail("peripherals already taken")
        };
        time_driver::start(&mut core.SYST);
        info!(
            "psmpa firmware: {=usize} scenarios, core clock {=u32} Hz, tick {=u64} Hz",
            SCENARIOS.len(),
            time_driver::CORE_HZ,
            embassy_time_driver::TICK_HZ
        );
        load_robot(ROBOT);
        let (robot, scenario, space) = (ROBOT, SCENARIO, SPACE);
        executor::run(EXECUTORS, |deciding, sensing| {
            match (missions(robot, scenario, space), executor::trampoline()) {
                (Ok(missions), Ok(trampoline)) => {
                    deciding.spawn(missions);
                    sensing.spawn(trampoline);
                }
                _ => fail("a task is already running"),
            }
        })
    }

    /// Each run's sensing side on the sensing executor.
    struct SensingFirst;

    impl Sides for SensingFirst {
        type Mutex = embassy_sync::blocking_mutex::raw::NoopRawMutex;

        async unsafe fn beside<S: core::future::Future, D: core::future::Future>(
            &self,
            sensing: S,
            deciding: D,
        ) -> D::Output {
            // SAFETY: the caller's contract, the same as `Beside::new`'s.
            unsafe { Beside::new(&executor::SensingSlot, sensing, deciding) }.await
        }
    }

    /// Reads a scenario's canonical form in place, out of line: no copy of it on the stack.
    #[inline(never)]
    fn parse(slot: &mut Scenario, json: &[u8], index: usize) -> bool {
        let ok = slot.read_canonical(json).is_ok();
        // A test build breaks the first embedded scenario on purpose: xtask qemu must notice.
        if let Some(first) = slot
            .interferences
            .first_mut()
            .filter(|_| cfg!(feature = "inject-fault") && index == 0)
        {
            first.at_ms += 37;
        }
        ok
    }

    /// Loads the mission once, in place, out of line.
    #[inline(never)]
    fn load_robot(robot: &mut Robot<'static>) {
        if robot.load_into(FETCH_TEA).is_err() {
            fail("the Fetch Tea mission does not load");
        }
    }

    /// Tells the executor what each poll did, for the cost of each kind of step.
    struct Steps;

    impl TraceSink for Steps {
        fn record(&mut self, _at: embassy_time::Instant, event: &TraceEvent) {
            executor::note(match event {
                TraceEvent::Sample { sensor, .. }
                | TraceEvent::SampleLost { sensor }
                | TraceEvent::SensorOn { sensor }
                | TraceEvent::SensorOff { sensor }
                | TraceEvent::SensorFailed { sensor, .. } => {
                    1u32.checked_shl(sensor.index() as u32).unwrap_or(0) & 0xff
                }
                // Part of a sample step, or of a behaviour step.
                TraceEvent::PreconditionViolated { .. }
                | TraceEvent::PreconditionRestored { .. }
                | TraceEvent::User { .. } => 0,
                _ => executor::CONTROL,
            });
        }
    }

    #[embassy_executor::task]
    async fn missions(
        robot: &'static mut Robot<'static>,
        scenario: &'static mut Scenario,
        space: &'static mut psmpa_sim::robot::PlannerSpace,
    ) {
        for (index, (file, json)) in SCENARIOS.iter().enumerate() {
            if !parse(scenario, json, index) {
                error!("{=str}: invalid scenario", file);
                fail("invalid scenario");
            }
            if robot.apply(scenario).is_err() {
                fail("the scenario's sensor periods do not apply");
            }
            for arch in Arch::ALL {
                // Everything is prepared: the run starts at tick 0, in a poll of its own.
                time_driver::restart();
                embassy_futures::yield_now().await;
                executor::take_polls();
                time_driver::take_isr_max_cycles();
                // SAFETY: the task awaits the run to its end; nothing leaks or moves it.
                let run = unsafe {
                    psmpa_sim::run::run_robot(
                        &SensingFirst,
                        robot,
                        scenario,
                        arch,
                        space,
                        (),
                        Steps,
                    )
                };
                let (s, (), _) = run.await;
                let polls = executor::take_polls();
                info!(
                    "polls scenario={=str} arch={=str} count={=u32} max_cycles={=u32} max_at_ms={=u64} total_cycles={=u64}",
                    scenario.name.as_str(),
                    arch.name(),
                    polls.count,
                    polls.max_cycles,
                    polls.max_at,
                    polls.total_cycles
                );
                info!(
                    "steps scenario={=str} arch={=str} sample0={=u32} sample1={=u32} sample2={=u32} sample3={=u32} control={=u32} behaviour={=u32} deciding={=u32} isr={=u32}",
                    scenario.name.as_str(),
                    arch.name(),
                    polls.max_sample[0],
                    polls.max_sample[1],
                    polls.max_sample[2],
                    polls.max_sample[3],
                    polls.max_control,
                    polls.max_behaviour,
                    polls.max_deciding,
                    time_driver::take_isr_max_cycles()
                );
                let t = s.tally;
                info!(
                    "result scenario={=str} arch={=str} interferences={=u32} detected={=u32} collisions={=u32} reached_door={=bool} time_cost_ms={=u64} max_reaction_ms={=i64} sonar_on_ms={=u64} bumper_on_ms={=u64} sonar_gap_ms={=i64} bumper_gap_ms={=i64} trace_hash={=u64:016x}",
                    scenario.name.as_str(),
                    arch.name(),
                    t.interferences,
                    t.detected,
                    t.collisions,
                    t.reached_door,
                    s.time_cost_ms,
                    t.max_reaction_ms.map_or(-1, |ms| ms as i64),
                    t.on_ms[0],
                    t.on_ms[1],
                    t.sample_gap_max_ms[0].map_or(-1, |ms| ms as i64),
                    t.sample_gap_max_ms[1].map_or(-1, |ms| ms as i64),
                    s.trace_hash
                );
            }
        }
        let (used, size) = stack_high_water();
        info!("stack high-water {=u32} of {=u32} bytes", used, size);
        debug::exit(EXIT_SUCCESS);
    }

    /// cortex-m-rt's `paint-stack` fills the stack region with a pattern at reset: the
    /// deepest word it no longer holds is the high-water mark.
    fn stack_high_water() -> (u32, u32) {
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

    fn fail(what: &str) -> ! {
        error!("failure: {=str}", what);
        debug::exit(EXIT_FAILURE);
        loop {
            cortex_m::asm::wfi();
        }
    }

    /// Set by the first panic: a panic while logging one exits at once, so the handler nests
    /// at most once (the stack bound of `cargo xtask stack` relies on it).
    static PANICKING: core::sync::atomic::AtomicBool = core::sync::atomic::AtomicBool::new(false);

    #[panic_handler]
    fn panic(info: &core::panic::PanicInfo) -> ! {
        if !PANICKING.swap(true, core::sync::atomic::Ordering::Relaxed) {
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
}

//! psmpa on a Cortex-M4F (QEMU mps2-an386) or a Cortex-M33 (QEMU mps2-an505): the same core,
//! the same Fetch Tea robot (`psmpa-fetch-tea`, on its devices simulated behind the drivers'
//! traits, `psmpa_sim::rig`) and the same simulated world as the host simulator. Every embedded scenario runs under both
//! architectures, one run per boot, from tick 0 of a fresh clock; each run logs every world
//! event and the summary fields of `psmpa-sim run --json`, which `cargo xtask qemu` compares
//! with the host, and what it measured in cycles. The runtime's sensing side runs on an
//! interrupt executor that preempts the deciding side.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "psmpa-firmware runs on the target: cargo run -p psmpa-firmware --target thumbv7em-none-eabihf --profile firmware (mps2-an386), or --target thumbv8m.main-none-eabihf (mps2-an505)"
    );
}

#[cfg(target_os = "none")]
mod firmware {
    use core::mem::MaybeUninit;
    use core::sync::atomic::{AtomicU32, Ordering};

    use cortex_m_rt::entry;
    use defmt::{error, info};
    use embassy_futures::join::join;
    use embassy_futures::select::select;
    use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
    use embassy_sync::signal::Signal;
    use psmpa_core::record::{Frame, RecordOut, Recorder};
    use psmpa_core::{DecidingSide, SensingSide, TraceEvent, TraceSink};
    use psmpa_fetch_tea::fetch_tea;
    use psmpa_sim::rig::{self, Chassis, Observed, Rig, RigRobot};
    use psmpa_sim::robot::{Arch, PlannerSpace};
    use psmpa_sim::scenario::Scenario;
    use psmpa_sim::world::{Device, Fate, WorldEvent, WorldLog};

    use psmpa_firmware::board::{self, fail, stack_high_water};
    use psmpa_firmware::{executor, time_driver, world_trace};

    include!(concat!(env!("OUT_DIR"), "/scenarios.rs"));

    /// Marks [`NEXT_RUN`] as written by a previous boot.
    const MAGIC: u32 = 0x7053_4d50;

    /// The run the next boot performs, and [`MAGIC`]: kept across the reset between runs (not
    /// initialised at boot), so that every run starts on a fresh clock at tick 0.
    #[unsafe(link_section = ".uninit.NEXT_RUN")]
    static mut NEXT_RUN: MaybeUninit<[u32; 2]> = MaybeUninit::uninit();

    /// The run this boot performs: 0 after power-on.
    fn this_run() -> u32 {
        // SAFETY: a volatile read through `NEXT_RUN`'s own pointer (no reference is made), at
        // boot, before any interrupt or task could write it; `MaybeUninit<[u32; 2]>` has the
        // layout of `[u32; 2]`, for which any bit pattern is a value (what power-on leaves is
        // told apart by the magic).
        let [magic, run] = unsafe { (&raw const NEXT_RUN).cast::<[u32; 2]>().read_volatile() };
        if magic == MAGIC { run } else { 0 }
    }

    /// Boots again for run `run`, or, with `None`, forgets the runs and exits.
    fn next(run: Option<u32>) -> ! {
        let word = run.map_or([0, 0], |r| [MAGIC, r]);
        // SAFETY: a volatile write through `NEXT_RUN`'s own pointer (no reference is made) by
        // the one task that ends the run, right before resetting or exiting: nothing reads or
        // writes it meanwhile.
        unsafe { (&raw mut NEXT_RUN).cast::<[u32; 2]>().write_volatile(word) };
        if run.is_some() {
            cortex_m::peripheral::SCB::sys_reset();
        }
        board::exit()
    }

    #[entry]
    fn main() -> ! {
        // `#[entry]` makes these `&'static mut`, safely: main runs once. Uninitialised (`.bss`)
        // until written here: no initial values in flash.
        static mut DECIDING: executor::Slot = MaybeUninit::uninit();
        static mut SCENARIO: MaybeUninit<Scenario> = MaybeUninit::uninit();
        static mut SPACE: PlannerSpace = PlannerSpace::new();
        static mut RIG: MaybeUninit<RunRig> = MaybeUninit::uninit();
        static mut ROBOT: MaybeUninit<RunRobot> = MaybeUninit::uninit();
        static mut RUNTIME: MaybeUninit<RunRuntime> = MaybeUninit::uninit();
        board::guard_stack();
        let run = this_run();
        let runs = (SCENARIOS.len() * Arch::ALL.len()) as u32;
        let (Some((file, json, hashes)), Some(&arch)) = (
            SCENARIOS.get((run / 2) as usize),
            Arch::ALL.get((run % 2) as usize),
        ) else {
            fail("no such run")
        };
        if run == 0 {
            info!(
                "psmpa firmware: {=usize} scenarios, core clock {=u32} Hz, tick {=u64} Hz; one run per boot",
                SCENARIOS.len(),
                time_driver::CORE_HZ,
                embassy_time_driver::TICK_HZ
            );
        }
        // The flight recording of this run begins: header and prologue, then one frame an
        // event.
        let mission = hashes.get((run % 2) as usize).copied().unwrap_or(0);
        let mut start = LogOut::new();
        psmpa_sim::robot::record_start(&mut start, mission, json, arch);
        start.flush();
        let scenario = SCENARIO.write(Scenario::empty());
        if !parse(scenario, json, run) {
            error!("{=str}: invalid scenario", file);
            fail("invalid scenario");
        }
        let scenario = &*scenario;
        let (rig, runtime) = build(RIG, ROBOT, RUNTIME, scenario, arch);
        let (sensing, deciding) = runtime.split();
        // Everything is prepared: the clock starts, and the run with it, at tick 0.
        time_driver::start();
        executor::run_idle(
            DECIDING,
            |thread, interrupt| {
                let task = one_run(deciding, rig, scenario, SPACE, arch, run, runs);
                match (task, sense(sensing, rig)) {
                    (Ok(task), Ok(sense)) => {
                        thread.spawn(task);
                        interrupt.spawn(sense);
                    }
                    _ => fail("a task is already running"),
                }
            },
            idle,
        )
    }

    /// A run's rig (the robot's body in the world, its devices simulated), robot and
    /// runtime, each in a `static` of its own: their two sides run as two tasks, sensing on
    /// the interrupt executor, which preempts deciding. What they share is behind critical
    /// sections (`CriticalSectionRawMutex`).
    type RunRig = Rig<'static, Reactions, CriticalSectionRawMutex>;
    type RunRobot = RigRobot<'static, 'static, Reactions, CriticalSectionRawMutex, Busy>;
    type RunRuntime = fetch_tea::Runtime<
        'static,
        RunRobot,
        Observed<'static, 'static, Reactions, CriticalSectionRawMutex, Sink>,
    >;

    /// Builds the run's rig, robot and runtime in their statics, each out of line: the
    /// frames that build them (each holds its value before it is moved in) never nest. The
    /// robot is calibrated for the scenario on the paper's NAO, as psmpa-sim runs it.
    fn build(
        rig: &'static mut MaybeUninit<RunRig>,
        robot: &'static mut MaybeUninit<RunRobot>,
        runtime: &'static mut MaybeUninit<RunRuntime>,
        scenario: &'static Scenario,
        arch: Arch,
    ) -> (&'static RunRig, &'static mut RunRuntime) {
        let settings = rig::settings_for(scenario, Chassis::Nao);
        let rig = build_rig(rig, scenario, settings.walk_permille.unsigned_abs());
        let robot = build_robot(robot, rig, settings);
        let runtime = build_runtime(runtime, robot, rig, scenario, arch);
        for (sensor, period) in [
            (fetch_tea::Sensor::Sonar, settings.sonar_period),
            (fetch_tea::Sensor::Bumper, settings.bumper_period),
        ] {
            runtime.set_period(sensor, period);
        }
        (rig, runtime)
    }

    #[inline(never)]
    fn build_rig(
        slot: &'static mut MaybeUninit<RunRig>,
        scenario: &'static Scenario,
        walk_permille: u16,
    ) -> &'static RunRig {
        slot.write(Rig::new(
            scenario,
            Reactions::default(),
            walk_permille,
            rig::sensor_ids(),
        ))
    }

    #[inline(never)]
    fn build_robot(
        slot: &'static mut MaybeUninit<RunRobot>,
        rig: &'static RunRig,
        settings: psmpa_fetch_tea::Settings,
    ) -> &'static RunRobot {
        slot.write(rig.robot(settings, rig::Chassis::Nao).with_compute(Busy))
    }

    #[inline(never)]
    fn build_runtime(
        slot: &'static mut MaybeUninit<RunRuntime>,
        robot: &'static RunRobot,
        rig: &'static RunRig,
        scenario: &'static Scenario,
        arch: Arch,
    ) -> &'static mut RunRuntime {
        slot.write(fetch_tea::Runtime::new(
            fetch_tea::FetchTea,
            robot,
            Observed::new(rig, Sink),
            psmpa_sim::robot::config(scenario, arch),
        ))
    }

    /// A behaviour's computation: busy cycles of the deciding side's own.
    struct Busy;

    impl psmpa_fetch_tea::Compute for Busy {
        fn compute(&self, time: embassy_time::Duration) {
            let us = u32::try_from(time.as_micros()).unwrap_or(u32::MAX);
            executor::compute(us.saturating_mul(time_driver::CORE_HZ / 1_000_000));
        }
    }

    /// Ends the sensing side when the deciding side has ended, as the host's loop polls it no
    /// more then: signalled from thread mode, it preempts at once, before the summary.
    static STOP: Signal<CriticalSectionRawMutex, ()> = Signal::new();

    /// The sensing side, on the interrupt executor, with the rig's inputs (they change at
    /// the sensing side's priority, as a board's pins raise interrupts).
    #[embassy_executor::task]
    async fn sense(mut side: SensingSide<'static, RunRuntime>, rig: &'static RunRig) {
        // The stop first: once it is signalled, not one more sample.
        let _ = select(STOP.wait(), join(side.run(), rig.pump())).await;
    }

    /// Reads a scenario's canonical form in place, out of line: no copy of it on the stack.
    #[inline(never)]
    fn parse(slot: &mut Scenario, json: &[u8], run: u32) -> bool {
        let ok = slot.read_canonical(json).is_ok();
        // A test build breaks the first embedded scenario on purpose: xtask qemu must notice.
        if let Some(first) = slot
            .interferences
            .first_mut()
            .filter(|_| cfg!(feature = "inject-fault") && run / 2 == 0)
        {
            // A minute late: the robot has passed by then, so it never meets it.
            first.at_ms += 60_000;
        }
        ok
    }

    /// The flight recorder's transport here: whole frames gathered in RAM and sent as one
    /// defmt line, `rec [bytes]`, when the next does not fit (and at the end of a run), which
    /// `cargo xtask qemu` gathers into one recording a run and replays on the host. A board
    /// streams the same over RTT. The lines go out by semihosting, a cost no chip has: left
    /// out of every measured cost, as the trace log's lines are.
    struct LogOut {
        buf: [u8; SEND],
        len: usize,
    }

    /// Bytes gathered before a line: 8 one-word frames (a line costs about 900 cycles, a
    /// byte in it a few).
    const SEND: usize = 256;

    impl LogOut {
        const fn new() -> Self {
            Self {
                buf: [0; SEND],
                len: 0,
            }
        }

        /// Sends what is gathered.
        fn flush(&mut self) {
            let Some(bytes) = self.buf.get(..self.len).filter(|b| !b.is_empty()) else {
                return;
            };
            critical_section::with(|_| {
                let begin = time_driver::counter();
                info!("rec {=[u8]}", bytes);
                let spent = begin.wrapping_sub(time_driver::counter());
                TRANSPORT.fetch_add(spent, Ordering::Relaxed);
                executor::uncounted(spent);
            });
            self.len = 0;
        }
    }

    /// Cycles the transport took this boot.
    static TRANSPORT: AtomicU32 = AtomicU32::new(0);

    impl RecordOut for LogOut {
        fn write(&mut self, bytes: &[u8]) {
            if self.len + bytes.len() > SEND {
                self.flush();
            }
            match self.buf.get_mut(self.len..self.len + bytes.len()) {
                Some(room) => {
                    room.copy_from_slice(bytes);
                    self.len += bytes.len();
                }
                // Longer than the buffer (a prologue): sent on its own.
                None => {
                    let mut whole = LogOut::new();
                    for part in bytes.chunks(SEND) {
                        if let Some(room) = whole.buf.get_mut(..part.len()) {
                            room.copy_from_slice(part);
                            whole.len = part.len();
                        }
                        whole.flush();
                    }
                }
            }
        }
    }

    /// The recorder's cost this boot: frames, and cycles in all and the most for one, on the
    /// runtime's path (taking the frame) and in idle time (encoding it).
    static RECORDED: AtomicU32 = AtomicU32::new(0);
    static TAKE_CYCLES: AtomicU32 = AtomicU32::new(0);
    static TAKE_MAX: AtomicU32 = AtomicU32::new(0);
    static ENCODE_CYCLES: AtomicU32 = AtomicU32::new(0);
    static ENCODE_MAX: AtomicU32 = AtomicU32::new(0);
    /// Frames encoded on the runtime's path because the queue was full.
    static INLINE: AtomicU32 = AtomicU32::new(0);
    /// The most frames queued at once.
    static QUEUED_MAX: AtomicU32 = AtomicU32::new(0);

    /// Frames taken and not yet encoded: the runtime's path only copies an event's words
    /// here; the idle loop encodes them ([`idle`]). When it is full the oldest is encoded
    /// on the spot: nothing is dropped. 64 (1.5 KB): every shipped run queues 22 at most.
    const QUEUE: usize = 64;

    struct Recording {
        queue: heapless::Deque<Frame<1>, QUEUE>,
        recorder: RecordSink,
    }

    /// The recorder's encoder and its transport.
    type RecordSink = Recorder<LogOut>;

    static RECORDING: embassy_sync::blocking_mutex::Mutex<
        CriticalSectionRawMutex,
        core::cell::RefCell<Recording>,
    > = embassy_sync::blocking_mutex::Mutex::new(core::cell::RefCell::new(Recording {
        queue: heapless::Deque::new(),
        recorder: Recorder::frames_only(LogOut::new()),
    }));

    /// Encodes one frame, timed.
    fn encode(recorder: &mut RecordSink, frame: &Frame<1>) {
        let (begin, sent) = (time_driver::counter(), TRANSPORT.load(Ordering::Relaxed));
        recorder.write_frame(frame);
        let own = begin
            .wrapping_sub(time_driver::counter())
            .wrapping_sub(TRANSPORT.load(Ordering::Relaxed).wrapping_sub(sent));
        ENCODE_CYCLES.fetch_add(own, Ordering::Relaxed);
        ENCODE_MAX.fetch_max(own, Ordering::Relaxed);
    }

    /// The idle loop's work: encodes one queued frame; whether more are queued.
    fn idle() -> bool {
        critical_section::with(|cs| {
            let mut r = RECORDING.borrow(cs).borrow_mut();
            let Recording { queue, recorder } = &mut *r;
            if let Some(frame) = queue.pop_front() {
                encode(recorder, &frame);
            }
            !queue.is_empty()
        })
    }

    /// Encodes and sends whatever is queued: at the end of a run.
    fn finish_recording() {
        while idle() {}
        critical_section::with(|cs| RECORDING.borrow(cs).borrow_mut().recorder.out().flush());
    }

    /// The runtime's trace: queued for the recording ([`RECORDING`]), and told to the
    /// executor, for the cost of each kind of step.
    struct Sink;

    impl<Ms: psmpa_core::Mission<Facts = psmpa_core::FactSet>> TraceSink<Ms> for Sink {
        fn record(&mut self, at: embassy_time::Instant, event: &TraceEvent) {
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
            critical_section::with(|cs| {
                let begin = time_driver::counter();
                let frame = Frame::of(at, event);
                let mut r = RECORDING.borrow(cs).borrow_mut();
                let Recording { queue, recorder } = &mut *r;
                if queue.is_full()
                    && let Some(oldest) = queue.pop_front()
                {
                    INLINE.fetch_add(1, Ordering::Relaxed);
                    encode(recorder, &oldest);
                }
                let _ = queue.push_back(frame);
                QUEUED_MAX.fetch_max(queue.len() as u32, Ordering::Relaxed);
                let own = begin.wrapping_sub(time_driver::counter());
                RECORDED.fetch_add(1, Ordering::Relaxed);
                TAKE_CYCLES.fetch_add(own, Ordering::Relaxed);
                TAKE_MAX.fetch_max(own, Ordering::Relaxed);
            });
        }
    }

    /// Measures reactions in cycles from the world's events: from the release of the sample
    /// that registers an obstacle while the robot walks to the stop that follows. A sample is
    /// released at the start of the tick its read starts in: reads start in the tick they are
    /// due (the sample gaps equal the host's, which `cargo xtask qemu` checks). Logs every
    /// event too ([`log_line`]), whose cycles the reactions leave out.
    #[derive(Default)]
    struct Reactions {
        /// The release of each device's latest read (sonar, bumper), cycles.
        release: [u64; 2],
        walking: bool,
        /// The device and release of the registering sample awaiting the stop.
        pending: Option<(usize, u64)>,
        /// The longest reaction per device, cycles.
        worst: [u64; 2],
    }

    fn slot(device: Device) -> Option<usize> {
        match device {
            Device::Sonar => Some(0),
            Device::Bumper => Some(1),
            _ => None,
        }
    }

    /// Cycles the trace log took this boot (one run). Statics, not fields of [`Reactions`]:
    /// the world's state, with its log, is moved on the stack, and each byte there counts.
    static LOGGED: AtomicU32 = AtomicU32::new(0);
    /// The tick of the latest line logged, and [`LOGGED`] when that tick began.
    static LOGGED_TICK: AtomicU32 = AtomicU32::new(0);
    static LOGGED_AT_TICK: AtomicU32 = AtomicU32::new(0);
    /// [`LOGGED`] at the release of each device's latest read, and at the pending one's.
    static RELEASE_LOGGED: [AtomicU32; 2] = [AtomicU32::new(0), AtomicU32::new(0)];
    static PENDING_LOGGED: AtomicU32 = AtomicU32::new(0);

    /// Logs a world event for `cargo xtask qemu`: `w MS KIND A B VALUE` ([`world_trace`]).
    /// The world calls its log inside its critical section, so the line's cycles are its own:
    /// they are left out of the polls and the critical sections ([`executor::uncounted`]) and
    /// of the reactions ([`LOGGED`]).
    fn log_line(at_ms: u64, event: &WorldEvent) {
        let begin = time_driver::counter();
        let tick = time_driver::ticks() as u32;
        let logged = LOGGED.load(Ordering::Relaxed);
        if tick != LOGGED_TICK.load(Ordering::Relaxed) {
            LOGGED_TICK.store(tick, Ordering::Relaxed);
            LOGGED_AT_TICK.store(logged, Ordering::Relaxed);
        }
        let f = world_trace::encode(event);
        info!(
            "w {=u64} {=u8} {=u8} {=u8} {=i64}",
            at_ms, f.kind, f.a, f.b, f.value
        );
        let spent = begin.wrapping_sub(time_driver::counter());
        LOGGED.store(logged.wrapping_add(spent), Ordering::Relaxed);
        executor::uncounted(spent);
    }

    impl WorldLog for Reactions {
        fn log(&mut self, at_ms: u64, _pos_um: i64, event: WorldEvent) {
            match event {
                WorldEvent::Walk | WorldEvent::AvoidDone(_) => self.walking = true,
                WorldEvent::Detected(_, device) if self.walking && self.pending.is_none() => {
                    self.pending = slot(device).and_then(|i| {
                        let logged = RELEASE_LOGGED.get(i)?.load(Ordering::Relaxed);
                        PENDING_LOGGED.store(logged, Ordering::Relaxed);
                        Some((i, *self.release.get(i)?))
                    });
                }
                WorldEvent::Stop | WorldEvent::AvoidStarted(_) | WorldEvent::Arrived(_) => {
                    self.walking = false;
                    if let Some((i, release)) = self.pending.take() {
                        let log = LOGGED
                            .load(Ordering::Relaxed)
                            .wrapping_sub(PENDING_LOGGED.load(Ordering::Relaxed));
                        let cycles = time_driver::cycles()
                            .saturating_sub(release)
                            .saturating_sub(u64::from(log));
                        if let Some(worst) = self.worst.get_mut(i) {
                            *worst = (*worst).max(cycles);
                        }
                    }
                }
                _ => {}
            }
            // After the measurement: a stop is not charged for its own line.
            log_line(at_ms, &event);
        }

        fn read_started(&mut self, device: Device) {
            let tick = time_driver::ticks();
            // The release is the tick's start: what was logged since is not the reaction's.
            let logged = if tick as u32 == LOGGED_TICK.load(Ordering::Relaxed) {
                LOGGED_AT_TICK.load(Ordering::Relaxed)
            } else {
                LOGGED.load(Ordering::Relaxed)
            };
            if let Some(i) = slot(device) {
                if let Some(r) = self.release.get_mut(i) {
                    *r = tick * time_driver::CYCLES_PER_TICK;
                }
                if let Some(l) = RELEASE_LOGGED.get(i) {
                    l.store(logged, Ordering::Relaxed);
                }
            }
        }
    }

    #[embassy_executor::task]
    async fn one_run(
        mut deciding: DecidingSide<'static, RunRuntime>,
        rig: &'static RunRig,
        scenario: &'static Scenario,
        space: &'static mut PlannerSpace,
        arch: Arch,
        run: u32,
        runs: u32,
    ) {
        let ended = psmpa_sim::run::decide_on(&mut deciding, scenario, space, || rig.halt()).await;
        STOP.signal(());
        if rig.overflowed() {
            fail("the rig scheduled more input changes than it holds");
        }
        let s = rig.world(|w| psmpa_sim::run::summary(arch, w, deciding.runtime(), ended));
        let worst = rig.world(|w| w.with_log(|reactions| reactions.worst));
        finish_recording();
        let (ticks, reference) = (
            embassy_time::Instant::now().as_ticks(),
            time_driver::reference_cycles(),
        );
        let polls = executor::take_polls();
        let name = scenario.name.as_str();
        info!(
            "polls scenario={=str} arch={=str} count={=u32} max_cycles={=u32} max_at_ms={=u64} total_cycles={=u64}",
            name,
            arch.name(),
            polls.count,
            polls.max_cycles,
            polls.max_at,
            polls.total_cycles
        );
        info!(
            "steps scenario={=str} arch={=str} sample0={=u32} sample1={=u32} sample2={=u32} sample3={=u32} control={=u32} behaviour={=u32} deciding={=u32} critical={=u32} isr={=u32}",
            name,
            arch.name(),
            polls.max_sample[0],
            polls.max_sample[1],
            polls.max_sample[2],
            polls.max_sample[3],
            polls.max_control,
            polls.max_behaviour,
            polls.max_deciding,
            polls.max_critical,
            time_driver::take_isr_max_cycles()
        );
        info!(
            "clock scenario={=str} arch={=str} ticks={=u64} reference_cycles={=u64} reaction_sonar_cycles={=u64} reaction_bumper_cycles={=u64} trace_cycles={=u32}",
            name,
            arch.name(),
            ticks,
            reference,
            worst[0],
            worst[1],
            LOGGED.load(Ordering::Relaxed)
        );
        let t = s.tally;
        // One letter per interference: detected by the Sonar or the Bumper, Collided, or `-`.
        let mut fates = [0u8; psmpa_sim::scenario::MAX_INTERFERENCES];
        for (letter, o) in fates.iter_mut().zip(&s.obstacles) {
            *letter = match o.fate {
                Fate::Detected(Device::Sonar) => b'S',
                Fate::Detected(Device::Bumper) => b'B',
                Fate::Detected(_) => b'D',
                Fate::Collided => b'C',
                Fate::Unmet => b'-',
            };
        }
        let fates = fates.get(..s.obstacles.len()).unwrap_or_default();
        let fates = core::str::from_utf8(fates).unwrap_or("?");
        info!(
            "result scenario={=str} arch={=str} interferences={=u32} detected={=u32} collisions={=u32} reached_door={=bool} fates={=str} time_cost_ms={=u64} max_reaction_ms={=i64} sonar_gap_ms={=i64} bumper_gap_ms={=i64} trace_hash={=u64:016x}",
            name,
            arch.name(),
            t.interferences,
            t.detected,
            t.collisions,
            t.reached_door,
            fates,
            s.time_cost_ms,
            t.max_reaction_ms.map_or(-1, |ms| ms as i64),
            t.sample_gap_max_ms[0].map_or(-1, |ms| ms as i64),
            t.sample_gap_max_ms[1].map_or(-1, |ms| ms as i64),
            s.trace_hash
        );
        info!(
            "recorder scenario={=str} arch={=str} frames={=u32} cycles={=u32} max_cycles={=u32} encode_cycles={=u32} encode_max={=u32} inline={=u32} queued_max={=u32}",
            name,
            arch.name(),
            RECORDED.load(Ordering::Relaxed),
            TAKE_CYCLES.load(Ordering::Relaxed),
            TAKE_MAX.load(Ordering::Relaxed),
            ENCODE_CYCLES.load(Ordering::Relaxed),
            ENCODE_MAX.load(Ordering::Relaxed),
            INLINE.load(Ordering::Relaxed),
            QUEUED_MAX.load(Ordering::Relaxed)
        );
        let (used, size) = stack_high_water();
        info!("stack high-water {=u32} of {=u32} bytes", used, size);
        next((run + 1 < runs).then_some(run + 1))
    }
}

//! The sensing side: every sensor samples on its own schedule, above the deciding side.
//!
//! A two-sensor robot: a time-of-flight ranger (`tof`, cyclic, a read takes `latency`) and a
//! cliff sensor (`cliff`, cyclic every 20 ms, instant). Both perceive `clear`, which "drive"
//! needs, so both run beside it. The platform records when every read started and ended.

use core::cell::{Cell, RefCell};

use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_time::{Duration, Instant, Timer};
use psmpa_core::{
    Act, ActionId, ActionIo, Actuator, ActuatorAction, Config, ControlError, Domain, Entry,
    FactSet, Failure, Key, Outcome, Plan, PlanLibrary, Platform, Reading, Runtime, Sensor,
    SensorAction, SensorFault, SensorId, SensorMode, Tables, Task, TraceEvent, Value,
};
use psmpa_testkit::{simulate, simulate_split};
use psmpa_tests::Recorder;

const CLIFF_PERIOD: Duration = Duration::from_millis(20);
const TOF_PERIOD: Duration = Duration::from_millis(100);
/// Where the ranger puts its signal strength beside the distance.
const STRENGTH: Key = Key(1);
const LIMIT: Duration = Duration::from_secs(60);

type Pair = Tables<'static, 2, 2, 1, 2>;
/// The mission as the runtime's mission type: its tables, loaded at run time.
type PairOf<'a> = &'a Pair;

struct Ids {
    tof: SensorId,
    cliff: SensorId,
}

fn mission() -> (Pair, Ids) {
    two_states(false)
}

/// The mission; with `park`, the plan drives and then parks, both beside the two sensors.
fn two_states(park: bool) -> (Pair, Ids) {
    let mut d: Domain<'static, 2, 2> = Domain::new();
    let clear = d.add_fact("clear").unwrap();
    let arrived = d.add_fact("arrived").unwrap();
    let go = d.add_event("go").unwrap();
    let cyclic = |period| SensorMode::Cyclic { period };
    let tof = d
        .add_sensor(
            SensorAction::new("tof", FactSet::single(clear), cyclic(TOF_PERIOD))
                .with_timeout(Duration::from_millis(500)),
        )
        .unwrap();
    let cliff = d
        .add_sensor(SensorAction::new(
            "cliff",
            FactSet::single(clear),
            cyclic(CLIFF_PERIOD),
        ))
        .unwrap();
    let drive = d
        .add_action(ActuatorAction::new(
            "drive",
            FactSet::single(clear),
            FactSet::single(arrived),
            FactSet::EMPTY,
        ))
        .unwrap();
    let parked = d.add_fact("parked").unwrap();
    let park_action = d
        .add_action(ActuatorAction::new(
            "park",
            FactSet::single(clear),
            FactSet::single(parked),
            FactSet::EMPTY,
        ))
        .unwrap();
    let mut library: PlanLibrary<'static, 1, 2> = PlanLibrary::new();
    let (body, goal): (&[ActionId], _) = if park {
        (&[drive, park_action], FactSet::single(parked))
    } else {
        (&[drive], FactSet::single(arrived))
    };
    library
        .add(Plan::new("drive", go, FactSet::EMPTY, body).unwrap())
        .unwrap();
    let task = Task {
        event: go,
        init: FactSet::EMPTY,
        goal,
    };
    let mission = Tables {
        name: "pair",
        domain: d,
        library,
        task,
    };
    (mission, Ids { tof, cliff })
}

/// A plan of two states: "prepare" (no sensor) makes `z` hold, which the ranger needs to be
/// switched on; "drive" needs `x` (the cliff sensor's) and `y` (the ranger's). The ranger has
/// never sampled before "drive", so nothing says `y` holds until its first read ends.
fn slow_fact() -> Pair {
    let mut d: Domain<'static, 2, 2> = Domain::new();
    let [x, y, z, done] = ["x", "y", "z", "done"].map(|f| d.add_fact(f).unwrap());
    let go = d.add_event("go").unwrap();
    let cyclic = |period| SensorMode::Cyclic { period };
    d.add_sensor(
        SensorAction::new("tof", FactSet::single(y), cyclic(TOF_PERIOD))
            .with_pre(FactSet::single(z))
            .with_timeout(Duration::from_millis(500)),
    )
    .unwrap();
    d.add_sensor(SensorAction::new(
        "cliff",
        FactSet::single(x),
        cyclic(CLIFF_PERIOD),
    ))
    .unwrap();
    let prepare = d
        .add_action(ActuatorAction::new(
            "prepare",
            FactSet::EMPTY,
            FactSet::single(z),
            FactSet::EMPTY,
        ))
        .unwrap();
    let drive = d
        .add_action(
            ActuatorAction::new(
                "drive",
                FactSet::single(x).with(y),
                FactSet::single(done),
                FactSet::EMPTY,
            )
            .with_max_violation(Duration::from_ticks(0)),
        )
        .unwrap();
    let mut library: PlanLibrary<'static, 1, 2> = PlanLibrary::new();
    library
        .add(Plan::new("drive", go, FactSet::EMPTY, &[prepare, drive]).unwrap())
        .unwrap();
    Tables {
        name: "slow fact",
        domain: d,
        library,
        task: Task {
            event: go,
            init: FactSet::EMPTY,
            goal: FactSet::single(done),
        },
    }
}

/// One read: which sensor, when it started, when it ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Read {
    sensor: SensorId,
    start: Instant,
    end: Instant,
}

/// What a behaviour saw when it woke.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Seen {
    at: Instant,
    cliff: Option<Entry>,
    tof: Option<Entry>,
    strength: Option<Entry>,
    /// The ranger's key, asked of the cliff sensor.
    cliff_strength: Option<Entry>,
}

struct Robot<const WAKES: bool = true> {
    ids: Ids,
    tof_latency: Duration,
    /// The drive wakes this long after it starts, looks, and ends.
    drive: Duration,
    reads: RefCell<Vec<Read>>,
    seen: Cell<Option<Seen>>,
    /// When each behaviour started and what it saw then.
    started: RefCell<Vec<Seen>>,
    /// When the cliff sensor's device signals an edge (`Sensor::wake`), ms.
    edges: Vec<u64>,
}

impl<const WAKES: bool> Robot<WAKES> {
    fn new(tof_latency_ms: u64, drive_ms: u64) -> Self {
        Self {
            ids: mission().1,
            tof_latency: Duration::from_millis(tof_latency_ms),
            drive: Duration::from_millis(drive_ms),
            reads: RefCell::new(Vec::new()),
            seen: Cell::new(None),
            started: RefCell::new(Vec::new()),
            edges: Vec::new(),
        }
    }

    /// When the reads of `sensor` from `from` on started, ms.
    fn starts(&self, sensor: SensorId, from: Instant) -> Vec<u64> {
        self.reads
            .borrow()
            .iter()
            .filter(|r| r.sensor == sensor && r.start >= from)
            .map(|r| r.start.as_millis())
            .collect()
    }
}

impl<const WAKES: bool> Sensor<PairOf<'_>> for Robot<WAKES> {
    const WAKES: bool = WAKES;

    async fn switch_on(&self, _: SensorId) -> Result<(), SensorFault> {
        Ok(())
    }

    async fn switch_off(&self, _: SensorId) {}

    async fn sample(&self, sensor: SensorId) -> Result<Option<Reading>, SensorFault> {
        let start = Instant::now();
        let clear = FactSet::ALL;
        let reading = if sensor == self.ids.tof {
            Timer::after(self.tof_latency).await;
            Reading::new(Value::Mm(1200), clear)
                .with(STRENGTH, Value::Int(-42))
                .map_err(|_| SensorFault::Device(0))?
        } else {
            Reading::new(Value::Bool(false), clear)
        };
        self.reads.borrow_mut().push(Read {
            sensor,
            start,
            end: Instant::now(),
        });
        Ok(Some(reading))
    }

    async fn wake(&self, sensor: SensorId) {
        let now = Instant::now().as_millis();
        match self.edges.iter().find(|&&e| e > now) {
            Some(&edge) if sensor == self.ids.cliff => Timer::at(Instant::from_millis(edge)).await,
            _ => core::future::pending().await,
        }
    }
}

impl<const WAKES: bool> Robot<WAKES> {
    fn look(&self, io: &ActionIo<'_, PairOf<'_>>) -> Seen {
        Seen {
            at: Instant::now(),
            cliff: io.sample(self.ids.cliff),
            tof: io.sample(self.ids.tof),
            strength: io.get(self.ids.tof, STRENGTH),
            cliff_strength: io.get(self.ids.cliff, STRENGTH),
        }
    }
}

impl<const WAKES: bool> Actuator<PairOf<'_>> for Robot<WAKES> {
    fn halt(&self, _: ActionId) {} // nothing to stop

    async fn run(&self, act: Act<'_, PairOf<'_>>) -> Outcome {
        let io = act.untyped();
        self.started.borrow_mut().push(self.look(&io));
        Timer::after(self.drive).await;
        self.seen.set(Some(self.look(&io)));
        Outcome::Success
    }
}

impl<const WAKES: bool> Platform for Robot<WAKES> {
    type Mutex = NoopRawMutex;
}

type PairRuntime<'r> = Runtime<'r, PairOf<'r>, Robot, Recorder<PairOf<'r>>>;

/// Runs the mission; returns the trace and when the drive state started.
fn run(robot: &Robot) -> (Vec<(Instant, TraceEvent)>, Instant) {
    run_mission(robot, mission().0)
}

fn run_mission(robot: &Robot, mission: Pair) -> (Vec<(Instant, TraceEvent)>, Instant) {
    let mut rt = PairRuntime::new(&mission, robot, Recorder::default(), Config::default());
    let (mut sensing, mut deciding) = rt.split();
    let done = simulate_split(sensing.run(), deciding.run(), LIMIT).unwrap();
    done.output.unwrap();
    let trace = rt.into_sink().events;
    let start = trace
        .iter()
        .find(|(_, e)| matches!(e, TraceEvent::StateEntered { .. }))
        .map(|(t, _)| *t)
        .unwrap();
    (trace, start)
}

/// The instants `from, from + step, ...` up to `to`, ms.
fn grid(from: Instant, step: u64, to: Instant) -> Vec<u64> {
    (from.as_millis()..=to.as_millis())
        .step_by(step as usize)
        .collect()
}

/// A state's precondition is judged on that state's samples: the cliff sensor's first sample
/// does not make "drive" violated on `y`, which only the ranger (30 ms a read) decides and has
/// not read yet; the drive, which tolerates no violation, runs to its end.
#[test]
fn a_fast_sensor_does_not_violate_a_fact_a_slower_one_has_yet_to_read() {
    let robot = Robot::new(30, 200);
    let (trace, _) = run_mission(&robot, slow_fact());
    let violations: Vec<_> = trace
        .iter()
        .filter(|(_, e)| matches!(e, TraceEvent::PreconditionViolated { .. }))
        .collect();
    assert!(violations.is_empty(), "{violations:?}");
}

#[test]
fn a_read_longer_than_another_sensors_period_leaves_its_instants_unchanged() {
    let ids = mission().1;
    // The drive lasts 1 s; the ranger's read takes nothing, 40 ms (twice the cliff sensor's
    // period) or 150 ms (longer than its own period).
    let runs: Vec<(Robot, Instant)> = [0, 40, 150]
        .into_iter()
        .map(|latency| {
            let robot = Robot::new(latency, 1_000);
            let (_, start) = run(&robot);
            (robot, start)
        })
        .collect();
    for (robot, start) in &runs {
        // The drive starts once every sensor has delivered its first sample.
        let end = *start + robot.tof_latency + Duration::from_millis(1_000);
        // The cliff sensor: every 20 ms from the start of the state, whatever the ranger does.
        assert_eq!(
            robot.starts(ids.cliff, *start),
            grid(*start, 20, end),
            "tof latency {}",
            robot.tof_latency.as_millis()
        );
        // The ranger keeps its own phase: every 100 ms, or every 200 ms when a read takes
        // 150 ms (the instants it overran are skipped, none is taken twice).
        let step = if robot.tof_latency > TOF_PERIOD {
            200
        } else {
            100
        };
        let tof = robot.starts(ids.tof, *start);
        let last_start = end - robot.tof_latency;
        assert_eq!(tof, grid(*start, step, last_start));
    }
    // Reads overlap: while a slow ranger read was in flight, the cliff sensor read too.
    let (slow, start) = &runs[1];
    let reads = slow.reads.borrow();
    let tof = reads
        .iter()
        .find(|r| r.sensor == ids.tof && r.start > *start)
        .unwrap();
    let during = reads
        .iter()
        .filter(|r| r.sensor == ids.cliff && r.start > tof.start && r.start < tof.end)
        .count();
    assert_eq!(during, 1, "one cliff read 20 ms into the 40 ms one");
}

#[test]
fn a_sample_due_at_the_instant_a_behaviour_wakes_is_taken_first() {
    // The drive wakes 200 ms after it starts: a cliff sample (every 20 ms) and a ranger sample
    // (every 100 ms) are due at that very instant.
    let robot = Robot::new(0, 200);
    let (trace, start) = run(&robot);
    let seen = robot.seen.get().unwrap();
    let woke = start + Duration::from_millis(200);
    assert_eq!(seen.at, woke);
    assert_eq!(
        seen.cliff.unwrap().at,
        woke,
        "the cliff sample of that instant"
    );
    assert_eq!(
        seen.tof.unwrap().at,
        woke,
        "the ranger sample of that instant"
    );
    // In the trace, the samples of that instant come before the state ends.
    let at_woke: Vec<&TraceEvent> = trace
        .iter()
        .filter(|(t, _)| *t == woke)
        .map(|(_, e)| e)
        .collect();
    let left = at_woke
        .iter()
        .position(|e| matches!(e, TraceEvent::StateLeft { .. }))
        .unwrap();
    assert_eq!(
        at_woke[..left]
            .iter()
            .filter(|e| matches!(e, TraceEvent::Sample { .. }))
            .count(),
        2
    );
}

#[test]
fn an_edge_the_device_signals_makes_a_sample_due_at_once_and_the_grid_stays() {
    let ids = mission().1;
    // Two edges of the cliff sensor's device during a 1 s drive, between its 20 ms instants,
    // and one at an instant it samples anyway.
    let mut robot = Robot::new(0, 1_000);
    let (_, start) = run(&robot);
    let s = start.as_millis();
    robot = Robot::new(0, 1_000);
    robot.edges = vec![s + 307, s + 553, s + 600];
    let (_, again) = run(&robot);
    assert_eq!(again, start, "the edges do not move the state");
    let end = start + Duration::from_millis(1_000);
    let mut expected = grid(start, 20, end);
    expected.extend([s + 307, s + 553]);
    expected.sort();
    assert_eq!(
        robot.starts(ids.cliff, start),
        expected,
        "a read at each edge, the 20 ms grid unchanged, no instant read twice"
    );
    // The ranger, whose device signals nothing, keeps its own instants.
    assert_eq!(robot.starts(ids.tof, start), grid(start, 100, end));
}

#[test]
fn a_platform_that_says_its_sensors_never_wake_early_keeps_the_grid() {
    let (pair, ids) = mission();
    let (_, start) = run(&Robot::new(0, 1_000));
    let s = start.as_millis();
    // The same edges as above, on a platform that says `WAKES = false`: not one early read.
    let mut robot = Robot::<false>::new(0, 1_000);
    robot.edges = vec![s + 307, s + 553, s + 600];
    let mut rt = Runtime::<'_, PairOf<'_>, Robot<false>, Recorder<PairOf<'_>>>::new(
        &pair,
        &robot,
        Recorder::default(),
        Config::default(),
    );
    let (mut sensing, mut deciding) = rt.split();
    simulate_split(sensing.run(), deciding.run(), LIMIT)
        .unwrap()
        .output
        .unwrap();
    let end = start + Duration::from_millis(1_000);
    assert_eq!(robot.starts(ids.cliff, start), grid(start, 20, end));
}

#[test]
fn a_behaviour_reads_every_pair_a_sensor_put_by_sensor() {
    let robot = Robot::new(40, 200);
    let (_, start) = run(&robot);
    let seen = robot.seen.get().unwrap();
    let tof = seen.tof.unwrap();
    assert_eq!(tof.value, Value::Mm(1200));
    assert_eq!(seen.strength.unwrap().value, Value::Int(-42));
    // The drive started when the first 40 ms read was in and woke 200 ms later, as the read
    // that started 200 ms after the first was delivered: both pairs of that sample carry the
    // instant its read started.
    assert_eq!(seen.at, start + Duration::from_millis(240));
    assert_eq!(tof.at, start + Duration::from_millis(200));
    assert_eq!(seen.strength.unwrap().at, tof.at);
    // The cliff sensor's store has no such key: a read names its sensor.
    assert_eq!(seen.cliff.unwrap().value, Value::Bool(false));
    assert_eq!(seen.cliff_strength, None);
}

/// A state that ends on a due instant of a sensor whose read takes time cancels that read: the
/// next state, starting at the same instant with the same sensor, reads afresh there, and its
/// behaviour starts when that read is in.
#[test]
fn a_read_cancelled_by_the_end_of_a_state_is_taken_again_by_the_next() {
    // The first read of the drive state ends 40 ms after it starts; the drive then lasts
    // 960 ms, ending on the ranger's due instant +1000 ms, with that read in flight.
    let robot = Robot::new(40, 960);
    let (_, start) = run_mission(&robot, two_states(true).0);
    let ends = start + Duration::from_millis(1_000);
    let started = robot.started.borrow();
    assert_eq!(started.len(), 2, "drive, then park");
    let park = started[1];
    assert_eq!(park.at, ends + Duration::from_millis(40));
    assert_eq!(park.tof.unwrap().at, ends, "a fresh read of that instant");
    // Two reads started at that instant: the one cancelled, the one that delivered.
    let reads = robot.reads.borrow();
    let at_end: Vec<&Read> = reads
        .iter()
        .filter(|r| r.sensor == robot.ids.tof && r.start == ends)
        .collect();
    assert_eq!(at_end.len(), 1, "only completed reads are recorded");
    assert_eq!(at_end[0].end, ends + Duration::from_millis(40));
}

#[test]
fn a_control_loop_without_its_sensing_side_fails_clearly_instead_of_hanging() {
    let robot = Robot::new(0, 200);
    let (mission, _) = mission();
    let mut rt = PairRuntime::new(&mission, &robot, Recorder::default(), Config::default());
    // Nobody runs the sensing side.
    let (_sensing, mut deciding) = rt.split();
    let done = simulate(deciding.run(), LIMIT).unwrap();
    assert_eq!(
        done.output,
        Err(ControlError::InitialModel {
            failure: Failure::SensingStalled
        })
    );
    // Within the sensors' own bounds: switching on and one sample, 500 ms each, and a tick.
    assert_eq!(done.elapsed, Duration::from_millis(1_001));
}

/// With a critical-section mutex and a platform that is `Sync`, the runtime is `Sync` and its
/// sensing side a `Send` future, as sharing it with a task of an `InterruptExecutor` needs.
/// A compile-time property: it says nothing of how the two sides behave under preemption.
#[test]
fn with_a_critical_section_mutex_the_runtime_is_sync_and_its_sensing_side_send() {
    use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;

    /// A platform whose state would live in atomics or critical-section mutexes.
    struct Stateless;
    impl Sensor<PairOf<'_>> for Stateless {
        async fn switch_on(&self, _: SensorId) -> Result<(), SensorFault> {
            Ok(())
        }
        async fn switch_off(&self, _: SensorId) {}
        async fn sample(&self, _: SensorId) -> Result<Option<Reading>, SensorFault> {
            Timer::after_millis(5).await;
            Ok(None)
        }
    }
    impl Actuator<PairOf<'_>> for Stateless {
        fn halt(&self, _: ActionId) {} // nothing to stop

        async fn run(&self, _: Act<'_, PairOf<'_>>) -> Outcome {
            Outcome::Success
        }
    }
    fn shared<T: Sync>(_: &T) {}
    fn sendable<F: core::future::Future + Send>(_: &F) {}

    let (mission, _) = mission();
    impl Platform for Stateless {
        type Mutex = CriticalSectionRawMutex;
    }
    type StatelessRuntime<'r> = Runtime<'r, PairOf<'r>, Stateless>;
    let mut rt = StatelessRuntime::new(&mission, &Stateless, (), Config::default());
    shared(&rt);
    let (mut sensing, _) = rt.split();
    sendable(&sensing.run());
}

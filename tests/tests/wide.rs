//! A runtime whose facts do not fit one word: 128 facts in fact sets of two words, with the
//! facts the robot senses and acts on past the first 64.
//!
//! A robot drives while a ranger (cyclic, 50 ms) decides `clear`; a box stands in the way
//! from 300 ms to 700 ms. The drive needs `clear` (fact 100) and adds `arrived` (fact 120).

use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_time::{Duration, Instant};
use psmpa_core::{
    Act, ActionId, ActionIo, Actuator, ActuatorAction, Config, Describe, Domain, FactId, FactSetOf,
    Mission, Outcome, Plan, PlanLibrary, Platform, Reading, Runtime, Sensor, SensorAction,
    SensorFault, SensorId, SensorMode, Tables, Task, TraceEvent, TraceHash, Value,
};
use psmpa_testkit::simulate_split;
use psmpa_tests::Recorder;

/// Two words of facts.
const W: usize = 2;
const NF: usize = 128;
type Wide = FactSetOf<W>;
type WideMission = Tables<'static, 1, 1, 1, 1, W, NF>;
type WideRuntime<'r> = Runtime<'r, &'r WideMission, Robot, Recorder<&'r WideMission, W>>;

/// The box stands in the way from .. to, ms.
const BOX: (u64, u64) = (300, 700);
/// The drive takes this long once the way is clear.
const DRIVE_MS: u64 = 1_000;

struct Facts {
    clear: FactId,
    arrived: FactId,
}

/// A name that lives as long as the test (the domain borrows its names).
fn name(i: usize) -> &'static str {
    Box::leak(format!("f{i}").into_boxed_str())
}

fn mission() -> (WideMission, Facts) {
    let mut d: Domain<'static, 1, 1, W, NF> = Domain::new();
    // Facts 0..100 and 101..120 stand for the rest of the robot's task model.
    for i in 0..100 {
        d.add_fact(name(i)).unwrap();
    }
    let clear = d.add_fact("clear").unwrap();
    for i in 101..120 {
        d.add_fact(name(i)).unwrap();
    }
    let arrived = d.add_fact("arrived").unwrap();
    assert_eq!((clear.index(), arrived.index()), (100, 120));
    let go = d.add_event("go").unwrap();
    d.add_sensor(SensorAction::new(
        "ranger",
        Wide::single(clear),
        SensorMode::Cyclic {
            period: Duration::from_millis(50),
        },
    ))
    .unwrap();
    let drive = d
        .add_action(ActuatorAction::new(
            "drive",
            Wide::single(clear),
            Wide::single(arrived),
            Wide::EMPTY,
        ))
        .unwrap();
    let mut library: PlanLibrary<'static, 1, 1, W> = PlanLibrary::new();
    library
        .add(Plan::new("drive", go, Wide::EMPTY, &[drive]).unwrap())
        .unwrap();
    let task = Task {
        event: go,
        init: Wide::EMPTY,
        goal: Wide::single(arrived),
    };
    let mission = Tables {
        name: "wide",
        domain: d,
        library,
        task,
    };
    (mission, Facts { clear, arrived })
}

struct Robot;

impl Sensor<&WideMission> for Robot {
    async fn switch_on(&self, _: SensorId) -> Result<(), SensorFault> {
        Ok(())
    }

    async fn switch_off(&self, _: SensorId) {}

    async fn sample(&self, _: SensorId) -> Result<Option<Reading<W>>, SensorFault> {
        let now = Instant::now().as_millis();
        let blocked = (BOX.0..BOX.1).contains(&now);
        Ok(Some(Reading::of(Value::Bool(blocked), !blocked)))
    }
}

impl Actuator<&WideMission> for Robot {
    fn halt(&self, _: ActionId) {} // nothing to stop

    async fn run(&self, act: Act<'_, &WideMission>) -> Outcome {
        drive(&act.untyped()).await
    }
}

/// Drives for `DRIVE_MS` of clear way: waits while the precondition is violated.
async fn drive<M: Mission, A>(io: &ActionIo<'_, M, A>) -> Outcome {
    let mut driven = 0;
    let mut version = io.version();
    while driven < DRIVE_MS {
        if io.violation().is_some() {
            version = io.changed(version).await;
            continue;
        }
        let step = Instant::now();
        if let Some(v) = io.changed_within(version, Duration::from_millis(10)).await {
            version = v;
        }
        driven += Instant::now().as_millis() - step.as_millis();
    }
    Outcome::Success
}

impl Platform for Robot {
    type Mutex = NoopRawMutex;
}

fn run() -> (WideMission, Vec<(Instant, TraceEvent<W>)>, TraceHash) {
    let (mission, _) = mission();
    let trace = {
        let mut rt = WideRuntime::new(&mission, &Robot, Recorder::default(), Config::default());
        let (mut sensing, mut deciding) = rt.split();
        let done = simulate_split(sensing.run(), deciding.run(), Duration::from_secs(10)).unwrap();
        let report = done.output.unwrap();
        assert!(
            report
                .beliefs
                .contains(mission.task.goal.iter().next().unwrap())
        );
        let hash = rt.trace_hash();
        (rt.into_sink().events, hash)
    };
    (mission, trace.0, trace.1)
}

#[test]
fn facts_past_the_first_word_are_sensed_monitored_and_achieved() {
    let facts = mission().1;
    let (mission, trace, hash) = run();
    let clear = Wide::single(facts.clear);
    // The box makes the drive's precondition false: the fact past the first word is the one
    // missing, from the first sample that sees the box until the first that does not.
    let violated: Vec<_> = trace
        .iter()
        .filter_map(|(t, e)| match e {
            TraceEvent::PreconditionViolated { missing, .. } => Some((t.as_millis(), *missing)),
            _ => None,
        })
        .collect();
    assert_eq!(violated, vec![(BOX.0, clear)]);
    let restored: Vec<u64> = trace
        .iter()
        .filter(|(_, e)| matches!(e, TraceEvent::PreconditionRestored { .. }))
        .map(|(t, _)| t.as_millis())
        .collect();
    assert_eq!(restored, vec![BOX.1]);
    // The effects reach the second word; the goal holds at the end.
    let last = trace.last().unwrap();
    assert!(
        matches!(last.1, TraceEvent::GoalReached { beliefs } if beliefs.contains(facts.arrived))
    );
    // Events print with the mission's names, whatever the word a fact is in.
    let text = format!(
        "{}",
        (&mission).describe(TraceEvent::PreconditionViolated {
            action: ActionId::new(0).unwrap(),
            missing: clear,
        })
    );
    assert!(text.contains("{clear}"), "{text}");
    // The same run, the same trace.
    assert_eq!(run().2, hash);
}

#[test]
fn the_trace_hash_covers_every_word_of_a_fact_set() {
    let at = Instant::from_ticks(5);
    let hash = |fact: usize| {
        let mut h = TraceHash::new();
        h.add(
            at,
            &TraceEvent::<W>::GoalReached {
                beliefs: Wide::single(FactId::within(fact, NF).unwrap()),
            },
        );
        h.value()
    };
    // Facts 70 and 71 differ only in the second word.
    assert_ne!(hash(70), hash(71));
    assert_ne!(hash(6), hash(70));
    // Every word is hashed, a 0 one too: the same facts hash differently in a one-word and a
    // two-word runtime. (That one-word hashes are what they were before fact sets had a width
    // is pinned by psmpa-sim's scenario hashes.)
    let mut one = TraceHash::new();
    one.add(
        at,
        &TraceEvent::<1>::GoalReached {
            beliefs: FactSetOf::single(FactId::new(6).unwrap()),
        },
    );
    let mut words = TraceHash::new();
    words.add(
        at,
        &TraceEvent::<W>::GoalReached {
            beliefs: Wide::single(FactId::new(6).unwrap()),
        },
    );
    assert_ne!(
        one.value(),
        words.value(),
        "a second word is hashed even when 0"
    );
}

// 200 facts in four words, compiled in: the same robot, its sensor and action named by the
// mission's enums.
psmpa_core::include_mission!(mod wide200 = "missions/wide-200.json");

/// The robot of the 200-fact mission: the same box, the same drive.
struct Typed;

impl Sensor<wide200::Wide200> for Typed {
    async fn switch_on(&self, _: wide200::Sensor) -> Result<(), SensorFault> {
        Ok(())
    }

    async fn switch_off(&self, _: wide200::Sensor) {}

    async fn sample(
        &self,
        sensor: wide200::Sensor,
    ) -> Result<Option<Reading<{ wide200::W }>>, SensorFault> {
        match sensor {
            wide200::Sensor::Ranger => {
                let now = Instant::now().as_millis();
                let blocked = (BOX.0..BOX.1).contains(&now);
                Ok(Some(Reading::of(Value::Bool(blocked), !blocked)))
            }
        }
    }
}

impl Actuator<wide200::Wide200> for Typed {
    fn halt(&self, _: wide200::Action) {} // nothing to stop

    async fn run(&self, act: Act<'_, wide200::Wide200>) -> Outcome {
        match act.typed() {
            wide200::Run::Drive(io) => drive(&io).await,
        }
    }
}

impl Platform for Typed {
    type Mutex = NoopRawMutex;
}

#[test]
fn a_compiled_mission_of_200_facts_runs_end_to_end_in_four_words() {
    use wide200::Fact;
    assert_eq!((wide200::NF, wide200::W), (200, 4));
    assert_eq!(
        (Fact::Clear.id().index(), Fact::Arrived.id().index()),
        (150, 199)
    );
    let run = || {
        let mut rt = wide200::Runtime::new(
            wide200::Wide200,
            &Typed,
            Recorder::<wide200::Wide200, { wide200::W }>::default(),
            Config::default(),
        );
        let (mut sensing, mut deciding) = rt.split();
        let done = simulate_split(sensing.run(), deciding.run(), Duration::from_secs(10)).unwrap();
        let report = done.output.unwrap();
        let hash = rt.trace_hash();
        (report, rt.into_sink().events, hash)
    };
    let (report, trace, hash) = run();
    // The goal, in the fourth word, holds.
    assert!(report.beliefs.contains(Fact::Arrived.id()));
    // The box makes `clear` (third word) false from the first sample that sees it until the
    // first that does not.
    let clear = FactSetOf::<{ wide200::W }>::single(Fact::Clear.id());
    let at = |matching: fn(&TraceEvent<{ wide200::W }>) -> bool| -> Vec<u64> {
        trace
            .iter()
            .filter(|(_, e)| matching(e))
            .map(|(t, _)| t.as_millis())
            .collect()
    };
    assert_eq!(
        at(|e| matches!(e, TraceEvent::PreconditionViolated { .. })),
        [BOX.0]
    );
    assert!(trace.iter().any(|(_, e)| matches!(
        e,
        TraceEvent::PreconditionViolated { missing, .. } if *missing == clear
    )));
    assert_eq!(
        at(|e| matches!(e, TraceEvent::PreconditionRestored { .. })),
        [BOX.1]
    );
    // The drive's second of clear way, after the box's 400 ms, from the first sample's end.
    let goal = at(|e| matches!(e, TraceEvent::GoalReached { .. }));
    assert_eq!(goal, [DRIVE_MS + (BOX.1 - BOX.0)]);
    // The same run, the same trace; and the same mission loaded from the file at run time.
    assert_eq!(run().2, hash);
    let loaded: psmpa_core::Loaded<'_, (), (), 1, 1, 1, 1, 4, 200> = psmpa_core::mission::load(
        include_bytes!("../missions/wide-200.json"),
        &psmpa_core::mission::AnyBehaviour,
    )
    .unwrap();
    assert_eq!(loaded.mission, wide200::TABLES);
}

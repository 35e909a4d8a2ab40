//! The tiny corridor world and its mission.

use core::cell::RefCell;

use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_time::{Duration, Instant, Timer};
use psmpa_core::{
    Act, ActionId, ActionIo, Actuator, ActuatorAction, Config, Domain, FactSet, Key, Outcome, Plan,
    PlanLibrary, Platform, Reading, Runtime, Sensor, SensorAction, SensorFault, SensorId,
    SensorMode, Tables, Task, Value,
};

use crate::Recorder;

/// The tiny mission's tables: 2 sensors, 4 actions, 4 plans of up to 4 actions.
pub type TinyMission = Tables<'static, 2, 4, 4, 4>;
/// The tiny mission as the runtime's mission type: its tables, loaded at run time.
pub type Tiny<'m> = &'m TinyMission;
/// The runtime of the tiny mission.
pub type TinyRuntime<'r> = Runtime<'r, Tiny<'r>, TinyWorld, Recorder<Tiny<'r>>>;

/// Ids in the tiny mission.
#[derive(Clone, Copy, Debug)]
pub struct Ids {
    /// Cyclic range sensor deciding `path_clear`.
    pub range: SensorId,
    /// One-shot camera deciding `handle_seen`, needs `at_door`.
    pub camera: SensorId,
    /// Walk to the door: pre `path_clear`, add `at_door`.
    pub walk: ActionId,
    /// Open the door: pre `at_door, handle_seen`, add `door_open`.
    pub open: ActionId,
    /// A walk that always fails.
    pub stumble: ActionId,
}

/// Where the range sensor puts its echo's time of flight, ns, beside the distance.
pub const TIME_OF_FLIGHT: Key = Key(1);

/// Range sensor period.
pub const RANGE_PERIOD: Duration = Duration::from_millis(100);
/// Door distance, millimetres.
pub const DOOR_MM: u64 = 2000;
/// Walking speed, millimetres per second.
pub const SPEED_MM_S: u64 = 200;

/// The mission: plans "stumble-first" (if `with_failing_plan`) then "get-in".
pub fn mission(with_failing_plan: bool) -> (TinyMission, Ids) {
    let mut d: Domain<'static, 2, 4> = Domain::new();
    let clear = d.add_fact("path_clear").unwrap();
    let at_door = d.add_fact("at_door").unwrap();
    let handle = d.add_fact("handle_seen").unwrap();
    let open_f = d.add_fact("door_open").unwrap();
    let ev = d.add_event("get_in").unwrap();
    let range = d
        .add_sensor(SensorAction::new(
            "range",
            FactSet::single(clear),
            SensorMode::Cyclic {
                period: RANGE_PERIOD,
            },
        ))
        .unwrap();
    let camera = d
        .add_sensor(
            SensorAction::new("camera", FactSet::single(handle), SensorMode::OneShot)
                .with_pre(FactSet::single(at_door)),
        )
        .unwrap();
    let walk = d
        .add_action(ActuatorAction::new(
            "walk",
            FactSet::single(clear),
            FactSet::single(at_door),
            FactSet::EMPTY,
        ))
        .unwrap();
    let open = d
        .add_action(ActuatorAction::new(
            "open",
            FactSet::single(at_door).with(handle),
            FactSet::single(open_f),
            FactSet::EMPTY,
        ))
        .unwrap();
    let stumble = d
        .add_action(ActuatorAction::new(
            "stumble",
            FactSet::single(clear),
            FactSet::single(at_door),
            FactSet::EMPTY,
        ))
        .unwrap();
    let mut library: PlanLibrary<'static, 4, 4> = PlanLibrary::new();
    if with_failing_plan {
        library
            .add(Plan::new("stumble-first", ev, FactSet::EMPTY, &[stumble, open]).unwrap())
            .unwrap();
    }
    library
        .add(Plan::new("get-in", ev, FactSet::EMPTY, &[walk, open]).unwrap())
        .unwrap();
    let task = Task {
        event: ev,
        init: FactSet::EMPTY,
        goal: FactSet::single(open_f),
    };
    (
        Tables {
            name: "tiny",
            domain: d,
            library,
            task,
        },
        Ids {
            range,
            camera,
            walk,
            open,
            stumble,
        },
    )
}

/// What the world noted, for the tests to check.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Note {
    /// The walking behaviour saw its precondition violated and stopped.
    Stopped(Instant),
    /// The walking behaviour read this range sample through the mutual store.
    ReadRange(Instant, Option<Value>),
}

#[derive(Debug, Default)]
struct State {
    pos_um: u64,
    last: u64,
    walking: bool,
    held: bool,
    stopped: bool,
    on: [bool; 2],
    notes: Vec<Note>,
}

/// The corridor world; implements both platform traits.
#[derive(Debug)]
pub struct TinyWorld {
    ids: Ids,
    /// Time windows `[from, to)` in which an obstacle stands right in front of the robot.
    obstacles: Vec<(Instant, Instant)>,
    /// When false the camera never answers a sample.
    pub camera_answers: core::cell::Cell<bool>,
    /// When true the camera answers without a frame: the sample is lost.
    pub camera_loses: core::cell::Cell<bool>,
    /// What the camera sees: whether the handle is in view.
    pub handle_visible: core::cell::Cell<bool>,
    /// How long "open" works, ms.
    pub open_ms: core::cell::Cell<u64>,
    state: RefCell<State>,
}

impl TinyWorld {
    /// A world with obstacles during `windows` (milliseconds).
    pub fn new(ids: Ids, windows: &[(u64, u64)]) -> Self {
        Self {
            ids,
            obstacles: windows
                .iter()
                .map(|&(a, b)| (Instant::from_millis(a), Instant::from_millis(b)))
                .collect(),
            camera_answers: core::cell::Cell::new(true),
            camera_loses: core::cell::Cell::new(false),
            handle_visible: core::cell::Cell::new(true),
            open_ms: core::cell::Cell::new(500),
            state: RefCell::new(State::default()),
        }
    }

    fn blocked(&self, at: Instant) -> bool {
        self.obstacles.iter().any(|&(a, b)| a <= at && at < b)
    }

    /// Integrates the robot's position up to now.
    fn advance(&self) {
        let now = Instant::now().as_millis();
        let mut s = self.state.borrow_mut();
        let moving = s.walking && !s.held && !s.stopped;
        if moving {
            let dt = now - s.last;
            s.pos_um = (s.pos_um + dt * SPEED_MM_S).min(DOOR_MM * 1000);
        }
        s.last = now;
    }

    /// Notes taken so far.
    pub fn notes(&self) -> Vec<Note> {
        self.state.borrow().notes.clone()
    }

    async fn walk(&self, io: &ActionIo<'_, Tiny<'_>>, fail: bool) -> Outcome {
        if fail {
            Timer::after_millis(300).await;
            return Outcome::Failure;
        }
        self.advance();
        self.state.borrow_mut().walking = true;
        let mut version = io.version();
        loop {
            self.advance();
            let value = io.sample(self.ids.range).map(|e| e.value);
            let eta = {
                let mut s = self.state.borrow_mut();
                s.notes.push(Note::ReadRange(Instant::now(), value));
                if s.pos_um >= DOOR_MM * 1000 {
                    s.walking = false;
                    return Outcome::Success;
                }
                match io.violation() {
                    Some(_) if !s.stopped => {
                        s.stopped = true;
                        s.notes.push(Note::Stopped(Instant::now()));
                    }
                    None => s.stopped = false,
                    _ => {}
                }
                (!s.stopped && !s.held).then(|| {
                    let left_um = DOOR_MM * 1000 - s.pos_um;
                    Duration::from_millis(left_um.div_ceil(SPEED_MM_S))
                })
            };
            let wake = eta.map(|d| Instant::now().saturating_add(d));
            if let Some(v) = io.changed_until(version, wake).await {
                version = v;
            }
        }
    }
}

impl Sensor<Tiny<'_>> for TinyWorld {
    async fn switch_on(&self, sensor: SensorId) -> Result<(), SensorFault> {
        self.advance();
        if let Some(on) = self.state.borrow_mut().on.get_mut(sensor.index()) {
            *on = true;
        }
        Ok(())
    }

    async fn switch_off(&self, sensor: SensorId) {
        self.advance();
        if let Some(on) = self.state.borrow_mut().on.get_mut(sensor.index()) {
            *on = false;
        }
    }

    async fn sample(&self, sensor: SensorId) -> Result<Option<Reading>, SensorFault> {
        self.advance();
        if sensor == self.ids.range {
            let blocked = self.blocked(Instant::now());
            let mm = if blocked { 300 } else { 2550 };
            // Light: about 6.67 ns per mm, there and back.
            let reading = Reading::of(Value::Mm(mm), !blocked)
                .with(TIME_OF_FLIGHT, Value::Int(mm * 20 / 3))
                .map_err(|_| SensorFault::Device(0))?;
            Ok(Some(reading))
        } else {
            if !self.camera_answers.get() {
                core::future::pending::<()>().await;
            }
            if self.camera_loses.get() {
                return Ok(None);
            }
            let seen = self.handle_visible.get();
            Ok(Some(Reading::new(
                Value::Bool(seen),
                if seen {
                    FactSet::single(psmpa_core::FactId::new(2).unwrap())
                } else {
                    FactSet::EMPTY
                },
            )))
        }
    }
}

impl Platform for TinyWorld {
    type Mutex = NoopRawMutex;
}

impl Actuator<Tiny<'_>> for TinyWorld {
    async fn run(&self, act: Act<'_, Tiny<'_>>) -> Outcome {
        let io = act.untyped();
        let action = io.action();
        if action == self.ids.walk || action == self.ids.stumble {
            self.walk(&io, action == self.ids.stumble).await
        } else {
            Timer::after_millis(self.open_ms.get()).await;
            Outcome::Success
        }
    }

    fn hold(&self, _action: ActionId, held: bool) {
        self.advance();
        self.state.borrow_mut().held = held;
    }

    fn halt(&self, _action: ActionId) {
        self.advance();
        self.state.borrow_mut().walking = false;
    }
}

/// The default configuration for the tiny world under a policy: a long violation tolerance,
/// so the walk waits for obstacles to go away.
pub fn config(policy: psmpa_core::Policy) -> Config {
    let mut config = Config::default();
    config.policy = policy;
    config.max_violation = Duration::from_secs(30);
    config
}

/// A runtime of `mission` on `world`, recording its trace, with `config`.
pub fn runtime<'r>(
    mission: &'r TinyMission,
    world: &'r TinyWorld,
    config: Config,
) -> TinyRuntime<'r> {
    TinyRuntime::new(mission, world, Recorder::default(), config)
}

/// SMPA with 1 s sense and 3 s act phases.
pub const SMPA: psmpa_core::Policy = psmpa_core::Policy::Smpa {
    sense: Duration::from_secs(1),
    act: Duration::from_secs(3),
};

//! The mission as a type: what a [`Runtime`](crate::Runtime) is made for (the layer below the
//! platform's traits, the trace and the runtime, which are written for a mission).
//!
//! A mission known when the robot is built is a type (`include_mission!` generates it: a unit
//! struct such as `fetch_tea::FetchTea`), and everything of it is code or constants: its names
//! ([`Mission::Sensor`], [`Mission::Action`], ...), its storage ([`Mission::Storage`], every
//! capacity in it), its plans' states (Algorithm 2 at build time: [`Mission::states`]), a
//! sampler per sensor ([`Mission::sensing`]) and a typed I/O per action ([`Mission::Run`]). The platform's
//! traits are written for a mission ([`Sensor<M>`](crate::Sensor),
//! [`Actuator<M>`](crate::Actuator)), so a platform, a trace or a description of another
//! mission does not compile.
//!
//! A mission loaded at run time is its tables: `&Tables<..>` implements [`Mission`] with the
//! ids as its names, the run-time FSM and the general sampler.

use core::convert::Infallible;
use core::fmt::Debug;
use core::future::Future;

use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_time::Duration;

use crate::action::{ActionId, ActuatorAction, SensorAction, SensorId, SensorMode, SensorSet};
use crate::domain::EventId;
use crate::facts::{FactId, FactSetOf};
use crate::mission::Tables;
use crate::model::Task;
use crate::plan::{Plan, PlanId};
use crate::planner::{PlanningError, Search};

pub mod io;
pub mod storage;

pub use io::{Act, ActionIo, Beside, Changed, KeyOf, OwnKey, Untyped};
pub use storage::{Storage, Store};

/// A fact-set type: [`FactSetOf<W>`]. Names the types of a mission whose fact sets have `W`
/// words, so that a mission's trait says `ReadingOf<M>` where a robot writes `Reading` (one
/// word) or `Reading<4>`.
pub trait Width: Copy + Eq + Debug + 'static {
    /// `Reading<W>`.
    type Reading: Copy + Debug;
    /// `Failure<W>`.
    type Failure: Copy + Debug + Eq;
    /// `Violation<W>`.
    type Violation: Copy + Debug + Eq;
    /// `TraceEvent<W>`.
    type TraceEvent: Copy + Debug + Eq;
    /// `ControlError<W>`.
    type ControlError: Copy + Debug + Eq;
    /// `Report<W>`.
    type Report: Copy + Debug + Eq;
    /// `Task<W>`.
    type Task: Copy + Debug + Eq;
    /// `SensorAction<'a, W>`.
    type SensorAction<'a>: Copy + Debug;
    /// `ActuatorAction<'a, W>`.
    type ActuatorAction<'a>: Copy + Debug;
}

/// The facts of mission `M`: `FactSetOf<W>`.
pub type FactsOf<M> = <M as Mission>::Facts;
/// A reading of mission `M`'s sensors.
pub type ReadingOf<M> = <FactsOf<M> as Width>::Reading;
/// A failure of mission `M`.
pub type FailureOf<M> = <FactsOf<M> as Width>::Failure;
/// A violation of mission `M`'s preconditions.
pub type ViolationOf<M> = <FactsOf<M> as Width>::Violation;
/// A trace event of mission `M`.
pub type TraceEventOf<M> = <FactsOf<M> as Width>::TraceEvent;
/// Why mission `M`'s control loop stopped.
pub type ControlErrorOf<M> = <FactsOf<M> as Width>::ControlError;
/// How mission `M`'s control loop ended.
pub type ReportOf<M> = <FactsOf<M> as Width>::Report;
/// Mission `M`'s task.
pub type TaskOf<M> = <FactsOf<M> as Width>::Task;
/// A sensor-based action of mission `M`.
pub type SensorActionOf<'a, M> = <FactsOf<M> as Width>::SensorAction<'a>;
/// An actuator-based action of mission `M`.
pub type ActuatorActionOf<'a, M> = <FactsOf<M> as Width>::ActuatorAction<'a>;

macro_rules! name_trait {
    ($(#[$doc:meta])* $trait:ident, $id:ty, $message:literal, $label:literal) => {
        $(#[$doc])*
        #[diagnostic::on_unimplemented(
            message = $message,
            label = $label,
            note = "a typed name belongs to one mission: use the enum (or type) of `{M}`'s module, or an id"
        )]
        pub trait $trait<M>: Copy + Debug + 'static {
            /// Its id in the mission.
            fn id(self) -> $id;
            /// The one of id `id`, if it names one.
            fn from_id(id: $id) -> Option<Self>;
        }

        impl<M> $trait<M> for $id {
            fn id(self) -> $id {
                self
            }
            fn from_id(id: $id) -> Option<Self> {
                Some(id)
            }
        }
    };
}

name_trait!(
    /// A name of one of mission `M`'s sensors: its `Sensor` enum, one of its sensor types
    /// (`fetch_tea::sensor::Sonar`), or a [`SensorId`].
    SensorOf,
    SensorId,
    "`{Self}` names no sensor of the mission `{M}`",
    "not a sensor of `{M}`"
);
name_trait!(
    /// A name of one of mission `M`'s actions: its `Action` enum, or an [`ActionId`].
    ActionOf,
    ActionId,
    "`{Self}` names no action of the mission `{M}`",
    "not an action of `{M}`"
);
name_trait!(
    /// A name of one of mission `M`'s plans: its `Plan` enum, or a [`PlanId`] (which also
    /// names a plan the planner generated, [`PlanId::GENERATED`]).
    PlanOf,
    PlanId,
    "`{Self}` names no plan of the mission `{M}`",
    "not a plan of `{M}`"
);
name_trait!(
    /// A name of one of mission `M`'s facts: its `Fact` enum, or a [`FactId`].
    FactOf,
    FactId,
    "`{Self}` names no fact of the mission `{M}`",
    "not a fact of `{M}`"
);
name_trait!(
    /// A name of one of mission `M`'s events: its `Event` enum, or an [`EventId`].
    EventOf,
    EventId,
    "`{Self}` names no event of the mission `{M}`",
    "not an event of `{M}`"
);

/// A plan body the planner writes ([`Mission::Body`]).
pub trait Body: AsRef<[ActionId]> + Sized {
    /// Runs `slice` nodes of `search` over `actions`: the plan and the nodes expanded once it
    /// ended.
    fn step<const N: usize, const W: usize>(
        search: &mut Search<N, W>,
        actions: &[ActuatorAction<'_, W>],
        slice: u32,
    ) -> Option<Result<(Self, u32), PlanningError>>;
}

impl<const L: usize> Body for heapless::Vec<ActionId, L> {
    fn step<const N: usize, const W: usize>(
        search: &mut Search<N, W>,
        actions: &[ActuatorAction<'_, W>],
        slice: u32,
    ) -> Option<Result<(Self, u32), PlanningError>> {
        search
            .step::<L>(actions, slice)
            .map(|r| r.map(|found| (found.body, found.expanded)))
    }
}

/// A plan of a mission's library, as the runtime reads it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PlanRef<'p, F> {
    /// Its name.
    pub name: &'p str,
    /// `t(p)`: the event it is for.
    pub trigger: EventId,
    /// `c(p)`: facts that must hold.
    pub context: F,
    /// Facts that must not hold.
    pub context_not: F,
    /// `bd(p)`: its actions, in order.
    pub body: &'p [ActionId],
}

impl<'p, const W: usize> PlanRef<'p, FactSetOf<W>> {
    /// Whether it is applicable to `event` under `beliefs` ([`Plan::applicable`]'s rule). O(1).
    pub fn applicable(&self, event: EventId, beliefs: FactSetOf<W>) -> bool {
        crate::plan::applicable(
            (self.trigger, self.context, self.context_not),
            event,
            beliefs,
        )
    }
}

impl<'p, const L: usize, const W: usize> From<&'p Plan<'p, L, W>> for PlanRef<'p, FactSetOf<W>> {
    fn from(p: &'p Plan<'p, L, W>) -> Self {
        Self {
            name: p.name,
            trigger: p.trigger,
            context: p.context,
            context_not: p.context_not,
            body: &p.body,
        }
    }
}

/// A mission, as a type: its names, storage, tables, plans and samplers. `include_mission!`
/// implements it for the unit struct it generates; `&Tables` implements it for a mission
/// loaded at run time. Not meant to be implemented by hand.
pub trait Mission: Sized {
    /// The fact-set type, `FactSetOf<W>`.
    type Facts: Width;
    /// The sensors' names: a compiled mission's `Sensor` enum, or [`SensorId`].
    type Sensor: SensorOf<Self>;
    /// The actions' names: a compiled mission's `Action` enum, or [`ActionId`].
    type Action: ActionOf<Self>;
    /// The plans' names: a compiled mission's `Plan` enum, or [`PlanId`].
    type Plan: PlanOf<Self>;
    /// The facts' names.
    type Fact: FactOf<Self>;
    /// The events' names.
    type Event: EventOf<Self>;
    /// The runtime's data stores and shared state, every capacity in the type
    /// ([`Store`]).
    type Storage<Mx: RawMutex>: Storage<Mx, Self::Facts>;
    /// An action to run with its typed I/O: a compiled mission's `Run` enum (one variant an
    /// action, each with an [`ActionIo`] that reads only the sensors the action runs beside);
    /// an untyped [`ActionIo`] for a mission loaded at run time.
    type Run<'io>
    where
        Self: 'io;
    /// A plan body the planner writes: `heapless::Vec<ActionId, L>`, `L` the longest body
    /// of the library.
    type Body: Body;
    /// The actions as the planner sees them: `heapless::Vec<ActuatorAction<'a, W>, NA>`.
    type Actions<'a>: AsRef<[ActuatorActionOf<'a, Self>]> + FromIterator<ActuatorActionOf<'a, Self>>
    where
        Self: 'a;

    /// The mission's name.
    fn name(&self) -> &str;
    /// The facts' names, by id.
    fn fact_names(&self) -> &[&str];
    /// The events' names, by id.
    fn event_names(&self) -> &[&str];
    /// The sensor-based actions `S`, by id.
    fn sensors(&self) -> &[SensorActionOf<'_, Self>];
    /// The actuator-based actions `A`, by id.
    fn actions(&self) -> &[ActuatorActionOf<'_, Self>];
    /// Plans in the library.
    fn plan_count(&self) -> usize;
    /// The library's plan `id`.
    fn plan(&self, id: PlanId) -> Option<PlanRef<'_, Self::Facts>>;
    /// `Π`: the task.
    fn task(&self) -> TaskOf<Self>;

    /// The typed I/O of the action `io` runs: what [`Actuator::run`](crate::Actuator::run)
    /// receives.
    fn typed(io: ActionIo<'_, Self, Untyped>) -> Self::Run<'_>;

    /// Algorithm 2 at build time: the states of the library's plan `plan`, computed when the
    /// mission was compiled (a state per action of its body, the sensors that run beside each,
    /// its effects, as constants in flash); `None` where the runtime compiles the plan itself
    /// when it is selected (a mission loaded at run time: [`Fsm`](crate::Fsm)).
    fn states(&self, plan: PlanId) -> Option<&[State<Self>]>;

    /// The sensing side: one sampler per sensor, concurrent, never ending. A compiled
    /// mission's samplers are each specialised for their sensor ([`SensorSpec`]). The samplers
    /// are built when this is called, not in the future's first poll: the temporaries of
    /// building them stay off the stack of whatever polls the sensing side (an interrupt on a
    /// microcontroller, on top of the deciding side's stack).
    fn sensing<E: Sensing<Mission = Self>>(&self, sensing: &E) -> impl Future<Output = Infallible>;
}

/// A behaviour state `δ_i` of a plan's FSM `f(Λ, T)`, or the parallel state `δ'_i` when
/// `sensors` is not empty (Algorithm 2): its action, the sensors that run beside it, and what
/// running it needs and does. Its transition rules are its place in the plan: success leads to
/// the next state (the last to done), failure to failed. A compiled mission's are constants
/// ([`Mission::states`]); the run-time FSM makes them from the tables.
#[derive(Debug)]
pub struct State<M: Mission> {
    /// Index of the state in its FSM.
    pub index: u8,
    /// The action `a_i` it runs.
    pub action: M::Action,
    /// `{s_k | per(s_k) ⊆ pre(a_i)}`: the sensors that run beside it.
    pub sensors: SensorSet,
    /// `pre(a_i)`.
    pub pre: M::Facts,
    /// `add(a_i)`.
    pub add: M::Facts,
    /// `del(a_i)`.
    pub del: M::Facts,
    /// The action's own tolerance of a violated precondition, if any.
    pub max_violation: Option<Duration>,
}

impl<M: Mission> Clone for State<M> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<M: Mission> Copy for State<M> {}

/// One sensor as its sampler runs it: a compiled mission generates one type per sensor, whose
/// answers are constants, so each sensor's sampler is its own machine code with no branch for
/// the modes it lacks; the general sampler gives a [`DynSensor`].
pub trait SensorSpec<M: Mission>: Copy {
    /// Its id.
    fn id(self) -> SensorId;
    /// Its name, as the platform's [`Sensor`](crate::Sensor) takes it.
    fn sensor(self) -> M::Sensor;
    /// How it samples (a cyclic sensor's period may be changed at run time:
    /// [`Runtime::set_period`](crate::Runtime::set_period)).
    fn mode(self) -> SensorMode;
    /// How long a switch or a sample may take.
    fn timeout(self) -> Duration;
    /// `per(s)`.
    fn per(self) -> M::Facts;
}

/// A sensor of a mission read from its tables ([`SensorSpec`]).
#[derive(Debug)]
pub struct DynSensor<M: Mission> {
    /// Its id.
    pub id: SensorId,
    /// Its name.
    pub sensor: M::Sensor,
    /// Its mode.
    pub mode: SensorMode,
    /// Its timeout.
    pub timeout: Duration,
    /// `per(s)`.
    pub per: M::Facts,
}

impl<M: Mission> Clone for DynSensor<M> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<M: Mission> Copy for DynSensor<M> {}

impl<M: Mission> SensorSpec<M> for DynSensor<M> {
    fn id(self) -> SensorId {
        self.id
    }
    fn sensor(self) -> M::Sensor {
        self.sensor
    }
    fn mode(self) -> SensorMode {
        self.mode
    }
    fn timeout(self) -> Duration {
        self.timeout
    }
    fn per(self) -> M::Facts {
        self.per
    }
}

pin_project_lite::pin_project! {
    /// Samplers that never end, joined and polled in place: what [`Mission::sensing`] gives
    /// (a future of its own, not an `async` block around the join, which would hold the
    /// samplers twice: once before its first poll, once across its await).
    #[must_use = "futures do nothing unless polled"]
    pub struct Samplers<F> {
        #[pin]
        samplers: F,
    }
}

impl<F> Samplers<F> {
    /// The joined samplers `samplers`.
    pub const fn new(samplers: F) -> Self {
        Self { samplers }
    }
}

impl<F: Future> Future for Samplers<F> {
    type Output = Infallible;

    fn poll(
        self: core::pin::Pin<&mut Self>,
        cx: &mut core::task::Context<'_>,
    ) -> core::task::Poll<Infallible> {
        // Samplers never end.
        let _ = self.project().samplers.poll(cx);
        core::task::Poll::Pending
    }
}

/// The sensing side, as a mission's samplers run on it ([`Mission::sensing`]).
pub trait Sensing {
    /// The mission.
    type Mission: Mission;
    /// The sampler of one sensor: serves every command that includes it, forever.
    fn sampler<S: SensorSpec<Self::Mission>>(&self, sensor: S) -> impl Future<Output = Infallible>;
    /// The general samplers of every sensor of the mission's tables, `N` of them (a
    /// mission loaded at run time).
    fn samplers<const N: usize>(&self) -> impl Future<Output = Infallible>;
}

/// Keys each data store of a mission loaded at run time holds: a sample and its pairs
/// ([`MAX_PAIRS`](crate::MAX_PAIRS) + 1).
pub const RUN_TIME_KEYS: usize = 5;

impl<
    'a,
    const NS: usize,
    const NA: usize,
    const NP: usize,
    const L: usize,
    const W: usize,
    const NF: usize,
> Mission for &Tables<'a, NS, NA, NP, L, W, NF>
{
    type Facts = FactSetOf<W>;
    type Sensor = SensorId;
    type Action = ActionId;
    type Plan = PlanId;
    type Fact = FactId;
    type Event = EventId;
    type Storage<Mx: RawMutex> = Store<Mx, NS, NA, RUN_TIME_KEYS, W>;
    type Run<'io>
        = ActionIo<'io, Self, Untyped>
    where
        Self: 'io;
    type Body = heapless::Vec<ActionId, L>;
    type Actions<'b>
        = heapless::Vec<ActuatorAction<'b, W>, NA>
    where
        Self: 'b;

    fn name(&self) -> &str {
        self.name
    }
    fn fact_names(&self) -> &[&str] {
        self.domain.fact_names()
    }
    fn event_names(&self) -> &[&str] {
        self.domain.event_names()
    }
    fn sensors(&self) -> &[SensorAction<'_, W>] {
        self.domain.sensors()
    }
    fn actions(&self) -> &[ActuatorAction<'_, W>] {
        self.domain.actions()
    }
    fn plan_count(&self) -> usize {
        self.library.plans().len()
    }
    fn plan(&self, id: PlanId) -> Option<PlanRef<'_, FactSetOf<W>>> {
        self.library.get(id).map(PlanRef::from)
    }
    fn task(&self) -> Task<W> {
        self.task
    }
    fn typed(io: ActionIo<'_, Self, Untyped>) -> ActionIo<'_, Self, Untyped> {
        io
    }
    fn states(&self, _: PlanId) -> Option<&[State<Self>]> {
        None
    }
    fn sensing<E: Sensing<Mission = Self>>(&self, sensing: &E) -> impl Future<Output = Infallible> {
        // Built here, not in the first poll (as an `async fn` would): see `Mission::sensing`.
        sensing.samplers::<NS>()
    }
}

//! The runtime's storage for a mission: every data store, and the state the sensing and
//! deciding sides share behind one mutex (the command the deciding side gives, the beliefs
//! and their version, the violation, each sensor's latest percept, and each side's waker).
//! A mission's type names it ([`Mission::Storage`](crate::Mission::Storage)), every capacity
//! in it, and the runtime reads it through [`Storage`], as slices.

use core::cell::{Cell, RefCell};
use core::task::{Context, Poll, Waker};

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_time::{Duration, Instant};

use crate::action::{ActionId, SensorId, SensorSet};
use crate::facts::FactSetOf;
use crate::spec::Width;
use crate::store::{DataStore, Entry, SensorStores, StoreAccess};

/// A runtime's data stores and shared state for a mission, every capacity in the type:
/// [`Store`] (a mission's [`Mission::Storage`](crate::Mission::Storage)). The runtime reads it
/// through this trait, as slices, so that no capacity is a parameter of the runtime.
pub trait Storage<Mx: RawMutex, F: Width>: Sized {
    /// A data store.
    type Store: StoreAccess;
    /// The per-sensor state, one an id.
    type Sensors: AsRef<[PerSensor<F>]>;
    /// Empty storage.
    const NEW: Self;
    /// The sensors' data stores, by id.
    fn sensor_stores(&self) -> &[Self::Store];
    /// The same, as a behaviour's mutual store reads them.
    fn sensor_table(&self) -> &dyn SensorStores;
    /// The actions' data stores, by id.
    fn action_stores(&self) -> &[Self::Store];
    /// The state both sides share, behind one lock.
    fn shared(&self) -> &Mutex<Mx, Shared<F, Self::Sensors>>;
    /// The same, owned: no lock needed.
    fn shared_mut(&mut self) -> &mut Mutex<Mx, Shared<F, Self::Sensors>>;
}

/// Storage for `NS` sensors, `NA` actions, `K` keys per data store, fact sets of `W` words.
pub struct Store<Mx: RawMutex, const NS: usize, const NA: usize, const K: usize, const W: usize> {
    sensor_stores: [DataStore<Mx, K>; NS],
    action_stores: [DataStore<Mx, K>; NA],
    shared: Mutex<Mx, Shared<FactSetOf<W>, [PerSensor<FactSetOf<W>>; NS]>>,
}

impl<Mx: RawMutex, const NS: usize, const NA: usize, const K: usize, const W: usize>
    Storage<Mx, FactSetOf<W>> for Store<Mx, NS, NA, K, W>
{
    type Store = DataStore<Mx, K>;
    type Sensors = [PerSensor<FactSetOf<W>>; NS];
    const NEW: Self = Self {
        sensor_stores: [const { DataStore::new() }; NS],
        action_stores: [const { DataStore::new() }; NA],
        shared: Mutex::new(Shared::new([const { PerSensor::new() }; NS])),
    };
    fn sensor_stores(&self) -> &[Self::Store] {
        &self.sensor_stores
    }
    fn sensor_table(&self) -> &dyn SensorStores {
        &self.sensor_stores
    }
    fn action_stores(&self) -> &[Self::Store] {
        &self.action_stores
    }
    fn shared(&self) -> &Mutex<Mx, Shared<FactSetOf<W>, Self::Sensors>> {
        &self.shared
    }
    fn shared_mut(&mut self) -> &mut Mutex<Mx, Shared<FactSetOf<W>, Self::Sensors>> {
        &mut self.shared
    }
}

/// What the deciding side asks of the sensing side: the sensors to run and how.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Command {
    /// Moves on with every command; a sampler serves one epoch at a time.
    pub(crate) epoch: u32,
    pub(crate) sensors: SensorSet,
    pub(crate) mode: Mode,
    /// Cyclic sensors are due at this instant first.
    pub(crate) start: Instant,
}

/// How the commanded sensors sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Mode {
    /// Beside an action: cyclic sensors every period, one-shot ones once at the start,
    /// on-demand ones on request.
    Parallel,
    /// An SMPA sense phase: as `Parallel`, with one-shot sensors only in the first phase.
    Phase { first: bool },
    /// The initial model: every commanded sensor samples once.
    Once,
}

/// What the two sides know of one sensor (of a runtime whose fact sets are `F`).
#[doc(hidden)]
pub struct PerSensor<F> {
    /// Its latest sample's value and instant.
    pub(crate) percept: Cell<Option<Entry>>,
    /// What its latest sample says of its `per(s)`.
    pub(crate) holds: Cell<F>,
    /// Samples lost in a row.
    pub(crate) lost: Cell<u8>,
    /// When its latest read started.
    pub(crate) last_read: Cell<Option<Instant>>,
    /// Its period, where the runtime was given one other than the mission's.
    pub(crate) period: Cell<Option<Duration>>,
}

impl<const W: usize> Default for PerSensor<FactSetOf<W>> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const W: usize> PerSensor<FactSetOf<W>> {
    /// Nothing known yet.
    pub const fn new() -> Self {
        Self {
            percept: Cell::new(None),
            holds: Cell::new(FactSetOf::EMPTY),
            lost: Cell::new(0),
            last_read: Cell::new(None),
            period: Cell::new(None),
        }
    }
}

/// State the two sides share, with `S` the per-sensor state ([`PerSensor`], one an id). Only
/// `Cell`s, so reads and writes cannot fail; the waker lists are the `RefCell`s, never
/// borrowed across a call out.
#[doc(hidden)]
pub struct Shared<F: Width, S> {
    pub(crate) beliefs: Cell<F>,
    /// The sensors switched on.
    pub(crate) running: Cell<SensorSet>,
    /// The running sensors that have sampled since they were switched on.
    pub(crate) fresh: Cell<SensorSet>,
    /// Facts some sample has decided (true or false) since the start.
    pub(crate) sensed: Cell<F>,
    /// Sensors that failed: out of service until [`Runtime::clear_faults`](crate::Runtime::clear_faults).
    pub(crate) faulty: Cell<SensorSet>,
    pub(crate) violation: Cell<Option<F::Violation>>,
    /// Whether a violation or a failure is set ([`set_violation`](Self::set_violation),
    /// [`set_failure`](Self::set_failure)): what the deciding side looks at first, at every
    /// step, instead of copying either out.
    pub(crate) alert: Cell<bool>,
    pub(crate) requests: Cell<SensorSet>,
    pub(crate) version: Cell<u32>,
    pub(crate) command: Cell<Command>,
    /// The running action and its precondition, checked after every sample (the command's,
    /// apart: a sample reads it alone).
    pub(crate) watch: Cell<Option<(ActionId, F)>>,
    /// The command's epoch, apart: samplers read it at every await.
    pub(crate) epoch: Cell<u32>,
    /// Sensors of the current command that are on and have taken the samples due at its start.
    pub(crate) ready: Cell<SensorSet>,
    /// Sensors whose sampler is between switching on and having switched off.
    pub(crate) active: Cell<SensorSet>,
    /// The first failure under the command of that epoch.
    pub(crate) failure: Cell<Option<(u32, F::Failure)>>,
    /// The deciding side's task (behaviours, the precondition watch and the control loop).
    /// One task per side: a registration of another waker wakes the one it replaces.
    pub(crate) deciding: Waiter,
    /// The sensing side's task (the samplers).
    pub(crate) sensing: Waiter,
    pub(crate) sensors: S,
}

impl<const W: usize, S> Shared<FactSetOf<W>, S> {
    /// Nothing known, nothing running, beliefs empty.
    pub const fn new(sensors: S) -> Self {
        Self {
            beliefs: Cell::new(FactSetOf::EMPTY),
            running: Cell::new(SensorSet::EMPTY),
            fresh: Cell::new(SensorSet::EMPTY),
            sensed: Cell::new(FactSetOf::EMPTY),
            faulty: Cell::new(SensorSet::EMPTY),
            violation: Cell::new(None),
            alert: Cell::new(false),
            requests: Cell::new(SensorSet::EMPTY),
            version: Cell::new(0),
            command: Cell::new(Command {
                epoch: 0,
                sensors: SensorSet::EMPTY,
                mode: Mode::Parallel,
                start: Instant::from_ticks(0),
            }),
            watch: Cell::new(None),
            epoch: Cell::new(0),
            ready: Cell::new(SensorSet::EMPTY),
            active: Cell::new(SensorSet::EMPTY),
            failure: Cell::new(None),
            deciding: Waiter::new(),
            sensing: Waiter::new(),
            sensors,
        }
    }
}

impl<F: Width, S> Shared<F, S> {
    /// Sets the running action's violation.
    pub(crate) fn set_violation(&self, violation: Option<F::Violation>) {
        self.violation.set(violation);
        self.alert
            .set(violation.is_some() || self.failure.get().is_some());
    }

    /// Sets the failure the sensing side reports under a command.
    pub(crate) fn set_failure(&self, failure: Option<(u32, F::Failure)>) {
        self.failure.set(failure);
        self.alert
            .set(failure.is_some() || self.violation.get().is_some());
    }

    /// Something the deciding side may wait for changed: bump the version and wake it.
    pub(crate) fn notify(&self) {
        self.version.set(self.version.get().wrapping_add(1));
        self.deciding.wake();
    }
}

impl<F: Width, S: AsRef<[PerSensor<F>]>> Shared<F, S> {
    /// The state of sensor `sensor`.
    pub(crate) fn sensor(&self, sensor: SensorId) -> Option<&PerSensor<F>> {
        self.sensors.as_ref().get(sensor.index())
    }

    /// A read of `sensor` started at `at`.
    pub(crate) fn record_read(&self, sensor: SensorId, at: Instant) {
        if let Some(s) = self.sensor(sensor) {
            s.last_read.set(Some(at));
        }
    }
}

/// The waker of one side's task. Unlike embassy-sync's `WakerRegistration` it keeps the waker
/// when it wakes it: a side registers again at nearly every poll, and a kept waker makes that a
/// comparison instead of a clone. A later wake of a task that waits for something else is a
/// spurious wake, which futures allow.
pub(crate) struct Waiter(RefCell<Option<Waker>>);

impl Waiter {
    pub(crate) const fn new() -> Self {
        Self(RefCell::new(None))
    }

    /// Makes `waker` the one woken. One task per side: a different waker replaces the one
    /// registered, which is woken so that it can register again.
    pub(crate) fn register(&self, waker: &Waker) {
        let replaced = match self.0.try_borrow_mut() {
            Ok(mut slot) => match &*slot {
                Some(kept) if kept.will_wake(waker) => None,
                _ => slot.replace(waker.clone()),
            },
            Err(_) => None,
        };
        if let Some(replaced) = replaced {
            replaced.wake();
        }
    }

    /// Wakes the registered task, if any.
    pub(crate) fn wake(&self) {
        if let Ok(slot) = self.0.try_borrow()
            && let Some(waker) = &*slot
        {
            waker.wake_by_ref();
        }
    }
}

/// A wait on the shared state `shared`: `done` decides, and when it says not yet the waker is
/// registered with the side's wakers (`wakers`), in the same lock, so that a side that preempts
/// in between cannot wake nobody.
pub(crate) fn poll_shared<M: RawMutex, T, R>(
    shared: &Mutex<M, T>,
    cx: &Context<'_>,
    wakers: impl FnOnce(&T) -> &Waiter,
    done: impl FnOnce(&T) -> Option<R>,
) -> Poll<R> {
    shared.lock(|s| match done(s) {
        Some(r) => Poll::Ready(r),
        None => {
            wakers(s).register(cx.waker());
            Poll::Pending
        }
    })
}

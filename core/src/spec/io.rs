//! What a running actuator behaviour sees ([`ActionIo`]): the mutual data store of its action
//! with the sensors running beside it, the beliefs, the state of its precondition, and a way
//! to wait for the next change. A compiled mission's action types say what it may read
//! ([`Beside`], [`KeyOf`], [`OwnKey`]): another sensor, or an undeclared key, is a compile
//! error.

use core::future::Future;
use core::marker::PhantomData;
use core::pin::Pin;
use core::task::{Context, Poll};

use embassy_futures::select::{Either, select};
use embassy_time::{Duration, Instant, Timer};

use crate::action::SensorId;
use crate::spec::{Mission, SensorOf, ViolationOf};
use crate::store::{Entry, Key, MutualStore, StoreFull, Value};

/// The I/O of an action with no types of its own: a mission loaded at run time's, or a
/// platform's written for any mission ([`Act::untyped`]). It reads any sensor by id, with
/// any [`Key`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Untyped;

/// Sensor `S` runs beside this action: its precondition needs what `S` perceives
/// (`per(s) ⊆ pre(a)`, Algorithm 2). `include_mission!` implements it for every pair of a
/// compiled mission's action and sensor types that Algorithm 2 puts together.
#[diagnostic::on_unimplemented(
    message = "sensor `{S}` does not run beside action `{Self}`",
    label = "not beside `{Self}`",
    note = "a sensor runs beside an action when the action's precondition needs what it perceives (per(s) ⊆ pre(a)): read it in an action that does"
)]
pub trait Beside<S> {}

impl<S> Beside<S> for Untyped {}

/// No sensor: what every compiled action type runs "beside" besides its sensors, so that the
/// compiler never takes an action's one sensor for the one a read names, and a read of another
/// says so ([`Beside`]'s message) instead of "expected `Sonar`".
#[doc(hidden)]
#[derive(Clone, Copy, Debug)]
pub enum Nowhere {}

/// `K` is a key of sensor `S`'s data store: declared in the mission (`"keys"` of the sensor).
#[diagnostic::on_unimplemented(
    message = "`{Self}` is not a key of sensor `{S}`'s data store",
    label = "undeclared",
    note = "declare it in the mission: `\"keys\": [..]` of the sensor"
)]
pub trait KeyOf<S>: Copy {
    /// The key.
    fn key(self) -> Key;
}

impl KeyOf<crate::action::SensorId> for Key {
    fn key(self) -> Key {
        self
    }
}

/// `K` is a key of action `A`'s own data store: declared in the mission (`"keys"` of the
/// action).
#[diagnostic::on_unimplemented(
    message = "`{Self}` is not a key of action `{A}`'s data store",
    label = "undeclared",
    note = "declare it in the mission: `\"keys\": [..]` of the action"
)]
pub trait OwnKey<A>: Copy {
    /// The key.
    fn key(self) -> Key;
}

impl OwnKey<Untyped> for Key {
    fn key(self) -> Key {
        self
    }
}

/// What the runtime shares with a running behaviour, object safe so that [`ActionIo`] carries
/// no runtime's type.
pub(crate) trait Monitor<M: Mission> {
    fn beliefs(&self) -> M::Facts;
    fn violation(&self) -> Option<ViolationOf<M>>;
    fn version(&self) -> u32;
    fn poll_changed(&self, cx: &mut Context<'_>, since: u32) -> Poll<u32>;
    fn request(&self, sensor: SensorId);
    fn user(&self, code: u16, value: i32);
}

/// An action to run, with its I/O: what [`Actuator::run`](crate::Actuator::run) receives.
pub struct Act<'io, M: Mission>(ActionIo<'io, M, Untyped>);

impl<'io, M: Mission> Act<'io, M> {
    pub(crate) fn new(io: ActionIo<'io, M, Untyped>) -> Self {
        Self(io)
    }

    /// The action.
    pub fn action(&self) -> M::Action {
        self.0.action
    }

    /// The mission's `Run`: the action with its typed I/O, to `match` on.
    pub fn typed(self) -> M::Run<'io> {
        M::typed(self.0)
    }

    /// The I/O untyped: any sensor by id, any key. For a platform written for any mission
    /// (a replay, a simulator); a robot of one mission reads through [`typed`](Self::typed).
    pub fn untyped(self) -> ActionIo<'io, M, Untyped> {
        self.0
    }
}

/// What a running actuator behaviour sees: the mutual data store of its action with the
/// sensors running beside it, the beliefs, the state of its precondition, and a way to wait
/// for the next change. `A` is the action's type in a compiled mission
/// (`fetch_tea::action::GoToDoor`), which says what it may read; [`Untyped`] reads anything.
pub struct ActionIo<'io, M: Mission, A = Untyped> {
    pub(crate) action: M::Action,
    pub(crate) store: MutualStore<'io>,
    pub(crate) monitor: &'io dyn Monitor<M>,
    pub(crate) typed: PhantomData<fn() -> A>,
}

impl<'io, M: Mission> ActionIo<'io, M, Untyped> {
    /// This I/O as action `A`'s, for the `Run` enum `include_mission!` generates (which names
    /// the action's type with its variant).
    #[doc(hidden)]
    pub fn __as<A>(self) -> ActionIo<'io, M, A> {
        ActionIo {
            action: self.action,
            store: self.store,
            monitor: self.monitor,
            typed: PhantomData,
        }
    }

    /// The mutual data store `d_mutual(s_j, a_i)`, by id and key.
    pub fn store(&self) -> &MutualStore<'io> {
        &self.store
    }
}

impl<'io, M: Mission, A> ActionIo<'io, M, A> {
    /// The action being run.
    pub fn action(&self) -> M::Action {
        self.action
    }

    /// The latest sample of sensor `sensor`, running beside the action.
    pub fn sample<S: SensorOf<M>>(&self, sensor: S) -> Option<Entry>
    where
        A: Beside<S>,
    {
        self.store.sample(sensor.id())
    }

    /// `get(d_mutual, k')`: what sensor `sensor`, running beside the action, put under `key`.
    pub fn get<S: SensorOf<M>, K: KeyOf<S>>(&self, sensor: S, key: K) -> Option<Entry>
    where
        A: Beside<S>,
    {
        self.store.get(sensor.id(), key.key())
    }

    /// The action's own value for `key`.
    pub fn own<K: OwnKey<A>>(&self, key: K) -> Option<Entry> {
        self.store.own(key.key())
    }

    /// Writes into the action's own store, stamped now.
    pub fn put<K: OwnKey<A>>(&self, key: K, value: Value) -> Result<(), StoreFull> {
        self.store.put(key.key(), value, Instant::now())
    }

    /// Asks for a sample of an on-demand sensor running beside the action. Under SMPA the
    /// request is served in the next sense phase.
    pub fn request<S: SensorOf<M>>(&self, sensor: S)
    where
        A: Beside<S>,
    {
        self.monitor.request(sensor.id());
    }

    /// The current beliefs `φ`.
    pub fn beliefs(&self) -> M::Facts {
        self.monitor.beliefs()
    }

    /// `Some` while the action's precondition is false according to the beliefs: the latest
    /// samples, and, for a fact no sensor of this state has sampled yet, the belief from
    /// before the state. A fact only an on-demand sensor perceives is therefore violated
    /// from the state's start until the behaviour asks for a sample that shows it, if it was
    /// false or never sensed before: give such an action a tolerance
    /// ([`ActuatorAction::max_violation`](crate::ActuatorAction::max_violation)) at least as
    /// long as that request takes. Its [`evidence`](crate::Violation::evidence) is the sample
    /// that showed it.
    pub fn violation(&self) -> Option<ViolationOf<M>> {
        self.monitor.violation()
    }

    /// A counter that moves on every sample and every change of the precondition.
    pub fn version(&self) -> u32 {
        self.monitor.version()
    }

    /// Waits until [`version`](Self::version) differs from `since` and returns the new value.
    /// Returns at once if it already differs.
    pub fn changed(&self, since: u32) -> Changed<'_, M> {
        // A future of its own, not an `async fn` around a `poll_fn`: a behaviour awaits it at
        // every step.
        Changed {
            monitor: self.monitor,
            since,
        }
    }

    /// Waits until [`version`](Self::version) differs from `since` or the instant `at` comes,
    /// whichever is first: `Some(new version)`, or `None` at the deadline. The loop of a
    /// behaviour that reacts to percepts and also has its own next instant.
    pub async fn changed_until(&self, since: u32, at: Option<Instant>) -> Option<u32> {
        let deadline = async {
            match at {
                Some(at) => Timer::at(at).await,
                None => core::future::pending().await,
            }
        };
        match select(self.changed(since), deadline).await {
            Either::First(v) => Some(v),
            Either::Second(()) => None,
        }
    }

    /// [`changed_until`](Self::changed_until) `timeout` from now.
    pub async fn changed_within(&self, since: u32, timeout: Duration) -> Option<u32> {
        self.changed_until(since, Some(Instant::now().saturating_add(timeout)))
            .await
    }

    /// Records an application-defined trace event.
    pub fn trace(&self, code: u16, value: i32) {
        self.monitor.user(code, value);
    }
}

/// The future of [`ActionIo::changed`]: the next [`version`](ActionIo::version) after `since`.
#[must_use = "futures do nothing unless polled"]
pub struct Changed<'io, M: Mission> {
    monitor: &'io dyn Monitor<M>,
    since: u32,
}

impl<M: Mission> Future for Changed<'_, M> {
    type Output = u32;

    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<u32> {
        self.monitor.poll_changed(cx, self.since)
    }
}

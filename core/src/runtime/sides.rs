//! The runtime's two sides, handed out once: [`Runtime::split`] takes the runtime mutably and
//! returns the sensing side and the deciding side, so a second sampler, a second control loop
//! running at once, or a second split while the first is in use does not compile.
//!
//! ```
//! # use psmpa_core::{Act, Actuator, Outcome, Platform, Reading, Sensor, SensorFault};
//! # psmpa_core::include_mission!(mod hello = "../testkit/tests/hello.json");
//! # use hello::Hello;
//! # struct Robot;
//! # impl Sensor<Hello> for Robot {
//! #     async fn switch_on(&self, _: hello::Sensor) -> Result<(), SensorFault> { Ok(()) }
//! #     async fn switch_off(&self, _: hello::Sensor) {}
//! #     async fn sample(&self, _: hello::Sensor) -> Result<Option<Reading>, SensorFault> { Ok(None) }
//! # }
//! # impl Actuator<Hello> for Robot {
//! #     async fn run(&self, _: Act<'_, Hello>) -> Outcome { Outcome::Success }
//! #     fn halt(&self, _: hello::Action) {}
//! # }
//! # impl Platform for Robot { type Mutex = psmpa_core::embassy_sync::blocking_mutex::raw::NoopRawMutex; }
//! # type RobotRuntime<'r> = hello::Runtime<'r, Robot>;
//! use psmpa_core::embassy_futures::select::{Either, select};
//!
//! /// Both sides on one executor, sensing polled first: what `rt.run_with_sensing()` does.
//! /// On a microcontroller, each side goes to a task instead: sensing on an interrupt
//! /// executor, deciding below it in thread mode.
//! async fn fly(rt: &mut RobotRuntime<'_>) -> bool {
//!     let (mut sensing, mut deciding) = rt.split();
//!     match select(sensing.run(), deciding.run()).await {
//!         Either::First(never) => match never {},
//!         Either::Second(report) => report.is_ok(),
//!     }
//! }
//! ```

use core::future::Future;
use core::ops::Deref;

use core::convert::Infallible;

use crate::facts::FactSetOf;
use crate::planner::{Planner, Search};
use crate::platform::{Actuator, Platform, Sensor};
use crate::runtime::Runtime;
use crate::runtime::control::{ControlError, Report, beside_sensing};
use crate::spec::Mission;
use crate::trace::TraceSink;

/// The sensing side of a runtime ([`Runtime::split`]): every sensor samples on its own schedule.
/// Place its [`run`](SensingSide::run) on an executor of higher priority than the deciding
/// side, or beside it on one executor ([`Runtime::run_with_sensing`]). Dereferences to the
/// runtime for what it knows (beliefs, stores, faults).
pub struct SensingSide<'a, R>(&'a R);

/// The deciding side of a runtime ([`Runtime::split`]): Algorithm 1's control loop, the FSM,
/// the behaviours. Its runs take it mutably: one control loop at a time (run again once one
/// ended). Dereferences to the runtime for what it knows (beliefs, stores, faults).
pub struct DecidingSide<'a, R>(&'a R);

impl<'a, R> SensingSide<'a, R> {
    /// The runtime, for the life of the side: what another task may read while it runs.
    pub fn runtime(&self) -> &'a R {
        self.0
    }
}

impl<'a, R> DecidingSide<'a, R> {
    /// The runtime, for the life of the side: what another task may read while it runs.
    pub fn runtime(&self) -> &'a R {
        self.0
    }
}

impl<R> Deref for SensingSide<'_, R> {
    type Target = R;
    fn deref(&self) -> &R {
        self.0
    }
}

impl<R> Deref for DecidingSide<'_, R> {
    type Target = R;
    fn deref(&self) -> &R {
        self.0
    }
}

impl<'r, M, P, T, const W: usize> Runtime<'r, M, P, T>
where
    M: Mission<Facts = FactSetOf<W>>,
    P: Platform + Sensor<M> + Actuator<M>,
    T: TraceSink<M>,
{
    /// The two sides, each handed out once for as long as they are in use.
    pub fn split(&mut self) -> (SensingSide<'_, Self>, DecidingSide<'_, Self>) {
        (SensingSide(self), DecidingSide(self))
    }

    /// The sensing side's samplers, built here, out of line, not in the first poll: the
    /// temporaries of building them stay off the stack of whatever polls them (an interrupt,
    /// on a microcontroller, on top of the deciding side's stack).
    #[inline(never)]
    pub(crate) fn sensing(&self) -> impl Future<Output = Infallible> + '_ {
        self.mission.sensing(self)
    }

    /// Both sides on the executor that polls this future: the sensing side (polled first at
    /// every wake, so a due sample is taken before the deciding side's turn) beside the control
    /// loop with plans from the library only ([`DecidingSide::run`]). Ends with the control
    /// loop's result. For a robot with one executor; with an interrupt executor, [`split`] the
    /// runtime and run the sensing side on it.
    ///
    /// [`split`]: Runtime::split
    pub async fn run_with_sensing(&mut self) -> Result<Report<W>, ControlError<W>> {
        beside_sensing(self.sensing(), self.run()).await
    }

    /// [`DecidingSide::run_planning`] beside the sensing side, as [`Runtime::run_with_sensing`]
    /// runs [`DecidingSide::run`].
    pub async fn run_planning_with_sensing<const N: usize>(
        &mut self,
        planner: &Planner<N, W>,
        space: &mut Search<N, W>,
    ) -> Result<Report<W>, ControlError<W>> {
        beside_sensing(self.sensing(), self.run_planning(planner, space)).await
    }
}

impl<'r, M, P, T, const W: usize> SensingSide<'_, Runtime<'r, M, P, T>>
where
    M: Mission<Facts = FactSetOf<W>>,
    P: Platform + Sensor<M> + Actuator<M>,
    T: TraceSink<M>,
{
    /// The samplers, one per sensor, all concurrent. Never ends; drop it to stop sensing.
    ///
    /// The samplers are built here, out of line, not in the first poll. Pin the result where
    /// it is made (`pin!(sensing.run())`) and it is never copied again.
    pub fn run(&mut self) -> impl Future<Output = Infallible> + '_ {
        self.0.sensing()
    }
}

impl<'r, M, P, T, const W: usize> DecidingSide<'_, Runtime<'r, M, P, T>>
where
    M: Mission<Facts = FactSetOf<W>>,
    P: Platform + Sensor<M> + Actuator<M>,
    T: TraceSink<M>,
{
    /// Algorithm 1 with plans from the library only: establishes the model, then selects and
    /// executes plans until the task's goal holds. Ends with an error, never a hang, when no
    /// plan applies, every applicable plan failed, or the failure or plan limit of the
    /// [`Config`](crate::Config) is reached.
    pub fn run(&mut self) -> impl Future<Output = Result<Report<W>, ControlError<W>>> + '_ {
        self.0.run()
    }

    /// Algorithm 1 where `generatePlans` falls back on `planner` when no library plan applies,
    /// and plans again from the current beliefs after a failure. The search runs in `space`
    /// (keep it in a `static` on a microcontroller), in slices of
    /// [`Config::plan_slice`](crate::Config::plan_slice) nodes with a yield
    /// between two, so that on a cooperative executor it holds the deciding side's turn for one
    /// slice at a time.
    pub fn run_planning<'s, const N: usize>(
        &'s mut self,
        planner: &'s Planner<N, W>,
        space: &'s mut Search<N, W>,
    ) -> impl Future<Output = Result<Report<W>, ControlError<W>>> + 's {
        self.0.run_planning(planner, space)
    }
}

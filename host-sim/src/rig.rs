//! The Fetch Tea robot's devices, simulated: pins and a ranger on the [`Body`] in the world,
//! behind the traits the drivers are written on (`embedded-hal`'s `OutputPin`, `InputPin`,
//! `Wait` and `SetDutyCycle`, the drivers' [`Ranger`]). The robot of `psmpa-fetch-tea` runs on
//! them unchanged: its switches debounce, its marker reads and its motors drive through the
//! drivers of `psmpa-drivers`, as on a board.
//!
//! * An output pin ([`RigOutput`], [`RigPwm`]) moves the body at the instant it is written.
//! * An input pin ([`RigInput`]) reads the level the body set for it, as the board's pad
//!   pulls it up where nothing drives it; it waits for an edge in virtual time.
//! * The sonar ([`RigSonar`]) is an HC-SR04 module on the body's trigger and echo: its echo
//!   is timed in the world, not by the 1 kHz clock (at which an echo timed by the clock reads
//!   in steps of 171 mm), and read back by the driver's own conversion
//!   ([`range_from_echo_us`]).
//! * [`Rig::pump`] plays the inputs the body schedules (a bounce, a contact after the
//!   bumper's latency, an echo's edges) and the world's own events at their instants; it runs
//!   beside the sensing side.
//! * [`Observed`] hands the robot's trace to the body, as the bench hands it the chip's
//!   flight recording: the world registers what the robot sensed from it.
//!
//! Time is `embassy-time`'s, in nanoseconds for the body.

use core::cell::RefCell;
use core::convert::Infallible;
use core::task::Poll;

use embassy_futures::select::select;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::{NoopRawMutex, RawMutex};
use embassy_sync::waitqueue::WakerRegistration;
use embassy_time::{Duration, Instant, TICK_HZ, Timer, with_timeout};
use embedded_hal::digital::{ErrorType, InputPin, OutputPin};
use embedded_hal::pwm::SetDutyCycle;
use embedded_hal_async::digital::Wait;
use psmpa_core::record::Frame;
use psmpa_core::{FactSet, Mission, TraceEvent, TraceSink};
use psmpa_drivers::hcsr04::range_from_echo_us;
use psmpa_drivers::hcsr04::{Hcsr04Error, PULSE_LIMIT, RISE_TIMEOUT, Range, Ranger};

use psmpa_drivers::Active;
use psmpa_drivers::PinError;
use psmpa_drivers::hbridge::{Channel, Drive, Motor};
use psmpa_drivers::marker::Marker;
use psmpa_drivers::switch::{DEBOUNCE, Switch};
use psmpa_fetch_tea::{Devices, FetchTea, Settings, fetch_tea};

use crate::body::{Body, SLOTS, Set, TRIGGER_NS, pin};
use crate::scenario::Scenario;
use crate::scenario::to_mm;
use crate::world::{World, WorldLog};

/// Input changes the body may have scheduled and not yet played: an echo's two edges, a
/// bumper's bounces (at most 8 edges), the marker, the handle's bounces.
pub const PENDING: usize = 48;

/// The full duty of the rig's PWM channels: a duty is thousandths.
pub const FULL_DUTY: u16 = 1_000;

/// Pins the rig has (the boards' pin table runs to GP15).
const PINS: usize = 16;

/// Now, ns.
fn now_ns() -> u64 {
    let ns = u128::from(Instant::now().as_ticks()) * 1_000_000_000 / u128::from(TICK_HZ);
    u64::try_from(ns).unwrap_or(u64::MAX)
}

/// The first tick at or after `ns`: a timer set for an instant between two ticks must not
/// fire before it.
fn instant_at(ns: u64) -> Instant {
    let ticks = (u128::from(ns) * u128::from(TICK_HZ)).div_ceil(1_000_000_000);
    Instant::from_ticks(u64::try_from(ticks).unwrap_or(u64::MAX))
}

/// Adds `set` to `pending` and wakes the pump; `overflow` when it is full.
fn schedule(
    pending: &mut heapless::Vec<Set, PENDING>,
    overflow: &mut bool,
    pump: &mut WakerRegistration,
    set: Set,
) {
    if pending.push(set).is_err() {
        *overflow = true;
    }
    pump.wake();
}

struct State<'s, L: WorldLog> {
    body: Body<'s, L>,
    /// Input changes scheduled, in the order the body set them.
    pending: heapless::Vec<Set, PENDING>,
    /// Each input's level now: driven high or low, or open (`None`).
    levels: [Option<bool>; PINS],
    /// Whoever waits for an input's edge.
    wakers: [WakerRegistration; PINS],
    /// The pump, when something new is scheduled.
    pump: WakerRegistration,
    /// More input changes were scheduled than [`PENDING`] holds: the run is void.
    overflow: bool,
    /// The world's next event when last asked, ns: the world answers with one after now, so
    /// the instant it is due is kept to be played then.
    world_due: Option<u64>,
}

impl<'s, L: WorldLog> State<'s, L> {
    /// Schedules the body's input changes.
    fn schedule(&mut self, set: Set) {
        schedule(&mut self.pending, &mut self.overflow, &mut self.pump, set);
    }

    /// The body, and where its input changes go: scheduled as it makes them (one past
    /// [`PENDING`] marks the run void, none is dropped).
    fn body_and_schedule(&mut self) -> (&mut Body<'s, L>, impl FnMut(Set) + '_) {
        let Self {
            body,
            pending,
            overflow,
            pump,
            ..
        } = self;
        (body, move |set| schedule(pending, overflow, pump, set))
    }

    /// Plays every change due by `ns`, in time order, and the world's own events.
    fn advance(&mut self, ns: u64) {
        if self.world_due.is_some_and(|t| t <= ns) {
            self.world_due = None;
            let (body, mut schedule) = self.body_and_schedule();
            body.inputs_now(ns, &mut schedule);
        }
        while let Some(i) = self
            .pending
            .iter()
            .enumerate()
            .filter(|(_, (_, _, at))| *at <= ns)
            .min_by_key(|(i, (_, _, at))| (*at, *i))
            .map(|(i, _)| i)
        {
            let (pin, level, _) = self.pending.remove(i);
            let p = usize::from(pin);
            if let (Some(l), Some(w)) = (self.levels.get_mut(p), self.wakers.get_mut(p)) {
                if *l != level {
                    w.wake();
                }
                *l = level;
            }
        }
    }

    /// The next instant something scheduled or the world changes, ns.
    fn next_ns(&mut self) -> Option<u64> {
        let pending = self.pending.iter().map(|(_, _, at)| *at).min();
        self.world_due = self.body.next_event_ns();
        match (pending, self.world_due) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }
}

/// The robot's devices on its body in the world, shared by the pins through `M` (a
/// `CriticalSectionRawMutex` where sensing runs on an interrupt executor).
pub struct Rig<'s, L: WorldLog, M: RawMutex = NoopRawMutex> {
    state: Mutex<M, RefCell<State<'s, L>>>,
}

impl<'s, L: WorldLog, M: RawMutex> Rig<'s, L, M> {
    /// The robot's body in the world of `sc`, logging into `log`, for a robot whose walking
    /// duty is `walk_permille`, its mission's sensor ids `ids` (sonar, bumper, camera,
    /// handle).
    pub fn new(sc: &'s Scenario, log: L, walk_permille: u16, ids: [usize; SLOTS]) -> Self {
        let mut levels = [None; PINS];
        for (pin, level) in Body::<L>::initial_inputs() {
            if let Some(l) = levels.get_mut(usize::from(pin)) {
                *l = level;
            }
        }
        Self {
            state: Mutex::new(RefCell::new(State {
                body: Body::new(sc, log, walk_permille, ids, None),
                pending: heapless::Vec::new(),
                levels,
                wakers: [const { WakerRegistration::new() }; PINS],
                pump: WakerRegistration::new(),
                overflow: false,
                world_due: None,
            })),
        }
    }

    fn with<R>(&self, f: impl FnOnce(&mut State<'s, L>) -> R) -> R {
        self.state.lock(|s| f(&mut s.borrow_mut()))
    }

    /// Reads the world.
    pub fn world<R>(&self, f: impl FnOnce(&World<'s, L>) -> R) -> R {
        self.with(|s| f(s.body.world()))
    }

    /// The world, at the end.
    pub fn into_world(self) -> World<'s, L> {
        self.state.into_inner().into_inner().body.into_world()
    }

    /// Whether more input changes were scheduled than the rig holds ([`PENDING`]): the run
    /// is void.
    pub fn overflowed(&self) -> bool {
        self.with(|s| s.overflow)
    }

    /// An output pin written now.
    fn output(&self, pin: u8, level: bool) {
        let ns = now_ns();
        self.with(|s| {
            s.advance(ns);
            let (body, mut schedule) = s.body_and_schedule();
            let _ = body.output(pin, level, ns, &mut schedule);
        });
    }

    /// A PWM duty written now, thousandths.
    fn duty(&self, pin: u8, permille: u16) {
        let ns = now_ns();
        self.with(|s| {
            s.advance(ns);
            let (body, mut schedule) = s.body_and_schedule();
            let _ = body.duty(pin, permille, ns, &mut schedule);
        });
    }

    /// An input's level now: driven, or pulled up by its pad where nothing drives it.
    fn level(&self, pin: u8) -> bool {
        let ns = now_ns();
        self.with(|s| {
            s.advance(ns);
            s.levels
                .get(usize::from(pin))
                .copied()
                .flatten()
                .unwrap_or(true)
        })
    }

    /// Waits until `done` says so of an input's level, checked at each of its edges.
    async fn wait_input(&self, pin: u8, mut done: impl FnMut(bool) -> bool) {
        core::future::poll_fn(|cx| {
            let ns = now_ns();
            self.with(|s| {
                s.advance(ns);
                let p = usize::from(pin);
                let level = s.levels.get(p).copied().flatten().unwrap_or(true);
                if done(level) {
                    return Poll::Ready(());
                }
                if let Some(w) = s.wakers.get_mut(p) {
                    w.register(cx.waker());
                }
                Poll::Pending
            })
        })
        .await;
    }

    /// Plays the inputs the body schedules and the world's own events at their instants;
    /// never ends. Run it beside the robot's sensing side, at its priority.
    pub async fn pump(&self) {
        loop {
            let ns = now_ns();
            let next = self.with(|s| {
                s.advance(ns);
                s.next_ns()
            });
            let timer = async {
                match next {
                    Some(at) => Timer::at(instant_at(at)).await,
                    None => core::future::pending().await,
                }
            };
            let mut first = true;
            let news = core::future::poll_fn(|cx| {
                if core::mem::take(&mut first) {
                    self.with(|s| s.pump.register(cx.waker()));
                    return Poll::Pending;
                }
                Poll::Ready(())
            });
            select(timer, news).await;
        }
    }

    /// A frame of the robot's record at `at`: the world follows what it switched and sampled.
    fn recorded(&self, at: Instant, frame: &Frame<1>) {
        let ns = now_ns();
        let at_ns = {
            let ns = u128::from(at.as_ticks()) * 1_000_000_000 / u128::from(TICK_HZ);
            u64::try_from(ns).unwrap_or(u64::MAX)
        };
        self.with(|s| {
            s.advance(ns);
            let (body, mut schedule) = s.body_and_schedule();
            let _ = body.recorded(at_ns, frame, ns, &mut schedule);
        });
    }

    /// Stops the world's robot where it stands (the run's time is up).
    pub fn halt(&self) {
        self.with(|s| s.body.world().halt());
    }
}

/// An output pin of the rig.
pub struct RigOutput<'r, 's, L: WorldLog, M: RawMutex> {
    rig: &'r Rig<'s, L, M>,
    pin: u8,
}

impl<'r, 's, L: WorldLog, M: RawMutex> RigOutput<'r, 's, L, M> {
    /// Output `pin` of `rig`.
    pub const fn new(rig: &'r Rig<'s, L, M>, pin: u8) -> Self {
        Self { rig, pin }
    }
}

impl<L: WorldLog, M: RawMutex> ErrorType for RigOutput<'_, '_, L, M> {
    type Error = Infallible;
}

impl<L: WorldLog, M: RawMutex> OutputPin for RigOutput<'_, '_, L, M> {
    fn set_low(&mut self) -> Result<(), Infallible> {
        self.rig.output(self.pin, false);
        Ok(())
    }

    fn set_high(&mut self) -> Result<(), Infallible> {
        self.rig.output(self.pin, true);
        Ok(())
    }
}

/// A PWM channel of the rig, its full duty [`FULL_DUTY`].
pub struct RigPwm<'r, 's, L: WorldLog, M: RawMutex> {
    rig: &'r Rig<'s, L, M>,
    pin: u8,
}

impl<'r, 's, L: WorldLog, M: RawMutex> RigPwm<'r, 's, L, M> {
    /// PWM output `pin` of `rig`.
    pub const fn new(rig: &'r Rig<'s, L, M>, pin: u8) -> Self {
        Self { rig, pin }
    }
}

impl<L: WorldLog, M: RawMutex> embedded_hal::pwm::ErrorType for RigPwm<'_, '_, L, M> {
    type Error = Infallible;
}

impl<L: WorldLog, M: RawMutex> SetDutyCycle for RigPwm<'_, '_, L, M> {
    fn max_duty_cycle(&self) -> u16 {
        FULL_DUTY
    }

    fn set_duty_cycle(&mut self, duty: u16) -> Result<(), Infallible> {
        self.rig.duty(self.pin, duty.min(FULL_DUTY));
        Ok(())
    }
}

/// An input pin of the rig, pulled up by its pad.
pub struct RigInput<'r, 's, L: WorldLog, M: RawMutex> {
    rig: &'r Rig<'s, L, M>,
    pin: u8,
}

impl<'r, 's, L: WorldLog, M: RawMutex> RigInput<'r, 's, L, M> {
    /// Input `pin` of `rig`.
    pub const fn new(rig: &'r Rig<'s, L, M>, pin: u8) -> Self {
        Self { rig, pin }
    }
}

impl<L: WorldLog, M: RawMutex> ErrorType for RigInput<'_, '_, L, M> {
    type Error = Infallible;
}

impl<L: WorldLog, M: RawMutex> InputPin for RigInput<'_, '_, L, M> {
    fn is_high(&mut self) -> Result<bool, Infallible> {
        Ok(self.rig.level(self.pin))
    }

    fn is_low(&mut self) -> Result<bool, Infallible> {
        Ok(!self.rig.level(self.pin))
    }
}

impl<L: WorldLog, M: RawMutex> Wait for RigInput<'_, '_, L, M> {
    async fn wait_for_high(&mut self) -> Result<(), Infallible> {
        self.rig.wait_input(self.pin, |high| high).await;
        Ok(())
    }

    async fn wait_for_low(&mut self) -> Result<(), Infallible> {
        self.rig.wait_input(self.pin, |high| !high).await;
        Ok(())
    }

    async fn wait_for_rising_edge(&mut self) -> Result<(), Infallible> {
        self.rig.wait_input(self.pin, |high| !high).await;
        self.rig.wait_input(self.pin, |high| high).await;
        Ok(())
    }

    async fn wait_for_falling_edge(&mut self) -> Result<(), Infallible> {
        self.rig.wait_input(self.pin, |high| high).await;
        self.rig.wait_input(self.pin, |high| !high).await;
        Ok(())
    }

    async fn wait_for_any_edge(&mut self) -> Result<(), Infallible> {
        let start = self.rig.level(self.pin);
        self.rig.wait_input(self.pin, |high| high != start).await;
        Ok(())
    }
}

/// An HC-SR04 module on the rig's trigger and echo, read as the driver reads one: a trigger
/// pulse, the echo's rise within the rise timeout, its fall within [`PULSE_LIMIT`], the
/// width converted by [`range_from_echo_us`].
pub struct RigSonar<'r, 's, L: WorldLog, M: RawMutex> {
    rig: &'r Rig<'s, L, M>,
    rise_timeout: Duration,
}

impl<'r, 's, L: WorldLog, M: RawMutex> RigSonar<'r, 's, L, M> {
    /// The module on `rig`, given [`RISE_TIMEOUT`] to raise its echo.
    pub const fn new(rig: &'r Rig<'s, L, M>) -> Self {
        Self {
            rig,
            rise_timeout: RISE_TIMEOUT,
        }
    }

    /// The module, given `timeout` to raise its echo ([`Hcsr04::with_rise_timeout`]).
    ///
    /// [`Hcsr04::with_rise_timeout`]: psmpa_drivers::hcsr04::Hcsr04::with_rise_timeout
    #[must_use]
    pub const fn with_rise_timeout(mut self, timeout: Duration) -> Self {
        self.rise_timeout = timeout;
        self
    }
}

impl<L: WorldLog, M: RawMutex> Ranger for RigSonar<'_, '_, L, M> {
    async fn measure(&mut self) -> Result<Range, Hcsr04Error> {
        // As the driver: a pulse still running (a cancelled read's) is waited out.
        if self.rig.level(pin::ECHO) {
            let fell = self.rig.wait_input(pin::ECHO, |high| !high);
            if with_timeout(PULSE_LIMIT, fell).await.is_err() {
                return Err(Hcsr04Error::Busy);
            }
        }
        let start = now_ns();
        // The pulse: its fall 10 µs after its rise fires the module, which schedules its echo.
        let (rise, fall) = self.rig.with(|s| {
            s.advance(start);
            let mut out = heapless::Vec::<Set, 24>::new();
            for (level, ns) in [(false, start), (true, start), (false, start + TRIGGER_NS)] {
                let _ = s.body.output(pin::TRIGGER, level, ns, &mut |set| {
                    let _ = out.push(set);
                });
            }
            let echo = |high: bool| {
                out.iter()
                    .find(|(p, l, _)| *p == pin::ECHO && *l == Some(high))
                    .map(|(_, _, at)| *at)
            };
            let edges = (echo(true), echo(false));
            for set in out {
                s.schedule(set);
            }
            edges
        });
        let fired = start + TRIGGER_NS;
        let rise_by = fired.saturating_add(self.rise_timeout.as_micros().saturating_mul(1_000));
        let Some(rise) = rise.filter(|r| *r <= rise_by) else {
            Timer::at(instant_at(rise_by)).await;
            return Err(Hcsr04Error::NoEcho);
        };
        let fall_by = rise.saturating_add(PULSE_LIMIT.as_micros().saturating_mul(1_000));
        let Some(fall) = fall.filter(|f| *f <= fall_by) else {
            Timer::at(instant_at(fall_by)).await;
            return Err(Hcsr04Error::Stuck);
        };
        Timer::at(instant_at(fall)).await;
        range_from_echo_us((fall - rise) / 1_000)
    }
}

/// A trace sink that hands the robot's trace to the rig's body (the world registers what the
/// robot sensed from its samples, and switches its sensors with the robot's) before `T`.
pub struct Observed<'r, 's, L: WorldLog, M: RawMutex, T> {
    rig: &'r Rig<'s, L, M>,
    sink: T,
}

impl<'r, 's, L: WorldLog, M: RawMutex, T> Observed<'r, 's, L, M, T> {
    /// `sink`, observed by `rig`.
    pub const fn new(rig: &'r Rig<'s, L, M>, sink: T) -> Self {
        Self { rig, sink }
    }

    /// The sink back.
    pub fn into_inner(self) -> T {
        self.sink
    }
}

impl<Ms, L, M, T> TraceSink<Ms> for Observed<'_, '_, L, M, T>
where
    Ms: Mission<Facts = FactSet>,
    L: WorldLog,
    M: RawMutex,
    T: TraceSink<Ms>,
{
    fn record(&mut self, at: Instant, event: &TraceEvent) {
        self.rig.recorded(at, &Frame::of(at, event));
        self.sink.record(at, event);
    }
}

/// A wheel of the rig's robot: its H-bridge channel, with an encoder on the NAO's body.
pub type RigWheel<'r, 's, L, M> = RigMotor<
    'r,
    's,
    L,
    M,
    Channel<RigOutput<'r, 's, L, M>, RigOutput<'r, 's, L, M>, RigPwm<'r, 's, L, M>>,
>;

/// A motor of the rig, and its encoder when the body has one: how far the body rolled forward
/// in the world (a side step's legs are not along the way).
pub struct RigMotor<'r, 's, L: WorldLog, M: RawMutex, Mo> {
    rig: &'r Rig<'s, L, M>,
    motor: Mo,
    encoder: bool,
}

impl<L: WorldLog, M: RawMutex, Mo: Motor> Motor for RigMotor<'_, '_, L, M, Mo> {
    fn drive(&mut self, permille: i16) -> Result<(), PinError> {
        self.motor.drive(permille)
    }

    fn brake(&mut self) -> Result<(), PinError> {
        self.motor.brake()
    }

    fn coast(&mut self) -> Result<(), PinError> {
        self.motor.coast()
    }

    fn rolled_um(&self) -> Option<u64> {
        if !self.encoder {
            return None;
        }
        let ns = now_ns();
        let um = self.rig.with(|s| {
            s.advance(ns);
            s.body.world().position_um()
        });
        u64::try_from(um).ok()
    }
}

/// The Fetch Tea robot of `psmpa-fetch-tea` on the rig's devices, computing its planning with
/// `Pc` (none by default: virtual time).
pub type RigRobot<'r, 's, L, M, Pc = ()> = FetchTea<
    RigSonar<'r, 's, L, M>,
    Switch<RigInput<'r, 's, L, M>>,
    Marker<RigInput<'r, 's, L, M>>,
    Switch<RigInput<'r, 's, L, M>>,
    Drive<RigWheel<'r, 's, L, M>, RigWheel<'r, 's, L, M>, RigOutput<'r, 's, L, M>>,
    Pc,
>;

/// The mission's sensor ids of the sonar, the bumper, the camera and the handle.
pub fn sensor_ids() -> [usize; SLOTS] {
    use fetch_tea::Sensor::{Bumper, Camera, Handle, Sonar};
    [Sonar, Bumper, Camera, Handle].map(|s| s.id().index())
}

impl<'s, L: WorldLog, M: RawMutex> Rig<'s, L, M> {
    /// The robot of `psmpa-fetch-tea` on this rig's devices, calibrated with `settings`, as a
    /// board wires it (the boards' pin table; switches and the marker active low, pulled up).
    pub fn robot(&self, settings: Settings, chassis: Chassis) -> RigRobot<'_, 's, L, M> {
        let wheel = |[in1, in2, pwm]: [u8; 3]| RigMotor {
            rig: self,
            motor: Channel::new(
                RigOutput::new(self, in1),
                RigOutput::new(self, in2),
                RigPwm::new(self, pwm),
            ),
            encoder: chassis.encoders(),
        };
        let mut sonar = RigSonar::new(self);
        if settings.sonar_rise.as_ticks() > 0 {
            sonar = sonar.with_rise_timeout(settings.sonar_rise);
        }
        FetchTea::new(
            Devices {
                sonar,
                bumper: Switch::new(RigInput::new(self, pin::BUMPER), Active::Low, DEBOUNCE),
                camera: Marker::new(RigInput::new(self, pin::MARKER), Active::Low),
                handle: Switch::new(RigInput::new(self, pin::HANDLE), Active::Low, DEBOUNCE),
                wheels: Drive::with_standby(
                    wheel(pin::LEFT),
                    wheel(pin::RIGHT),
                    RigOutput::new(self, pin::STBY),
                ),
            },
            settings,
        )
    }
}

/// The body the robot drives in the world: one simulated body, two settings of it. The
/// robot's code is the same on both; what differs is how long its body takes at a door.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Chassis {
    /// The paper's NAO, which walks: it pushes a door open in [`OPEN_DOOR`] and goes through
    /// it in [`ENTER_KITCHEN`] (Table I and the sensitivity study).
    #[default]
    Nao,
    /// The boards' wheeled chassis on its H-bridge, with the door times of its calibration
    /// ([`Settings::DEFAULT`]): the bench's robot.
    Wheeled,
}

impl Chassis {
    /// The name on the command line and in reports.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Nao => "nao",
            Self::Wheeled => "wheeled",
        }
    }

    /// Whether the body counts its way by what it rolled (the NAO counts the steps it took),
    /// not by wheel time (the boards' chassis has no encoders).
    pub const fn encoders(self) -> bool {
        matches!(self, Self::Nao)
    }

    /// How long the body pushes a door open and how long it takes through the door.
    pub const fn door_times(self) -> (Duration, Duration) {
        match self {
            Self::Nao => (OPEN_DOOR, ENTER_KITCHEN),
            Self::Wheeled => (Settings::DEFAULT.push, Settings::DEFAULT.enter),
        }
    }
}

/// How long the NAO takes to push a door open (the world opens a door pushed for at least
/// [`DOOR_PUSH_MS`](crate::world::DOOR_PUSH_MS)).
pub const OPEN_DOOR: Duration = Duration::from_millis(1_000);

/// How long the NAO takes to walk through an open door.
pub const ENTER_KITCHEN: Duration = Duration::from_millis(1_000);

/// The robot's settings for `sc` on `chassis`: the walk to its door (and on to the back door) at its speed,
/// the sonar's threshold as the clearance (the robot stops for a reading below it, as the world
/// registers one), its sensors' periods, the walk's planning time and its side step, and the
/// time its sonar may take to answer, the chassis' door times. The rest as the board's defaults. The bench writes the
/// same into the Pico's calibration record.
pub fn settings_for(sc: &Scenario, chassis: Chassis) -> Settings {
    let ms = Duration::from_millis;
    let (push, enter) = chassis.door_times();
    Settings {
        push,
        enter,
        clearance_mm: u16::try_from(sc.sonar.threshold_mm().saturating_sub(1)).unwrap_or(u16::MAX),
        walk_mm: u32::try_from(to_mm(sc.door_um)).unwrap_or(u32::MAX),
        back_door_mm: u32::try_from(to_mm(sc.back_door_um)).unwrap_or(u32::MAX),
        // µm a ms is mm a s.
        walk_mm_s: u32::try_from(sc.speed_um_per_ms).unwrap_or(u32::MAX).max(1),
        plan: Duration::from_micros(u64::from(sc.plan_us)),
        sonar_period: Some(ms(sc.sonar.period_ms)),
        bumper_period: Some(ms(sc.bumper_period_ms)),
        // The side step the scenario gives its robot.
        avoid: ms(sc.avoid_ms),
        // A sonar that answers after a read latency raises its echo that much later.
        sonar_rise: if sc.sonar.latency_ms > 0 {
            ms(sc.sonar.latency_ms) + RISE_TIMEOUT
        } else {
            Duration::from_ticks(0)
        },
        ..Settings::DEFAULT
    }
}

//! What the robot tests share: an HC-SR04 stand-in that answers the driver's triggers, and the
//! Fetch Tea robot on scripted and recorded pins.
//!
//! The tests run at the workspace's 1 kHz tick: every instant and every echo width is a whole
//! number of milliseconds (a 6 ms echo is 1,029 mm; the driver's 10 µs trigger pulse lasts one
//! tick, 1 ms).
#![allow(dead_code)] // Each test binary uses a part.

use std::convert::Infallible;
use std::sync::Arc;

use embassy_time::{Duration, Instant, Timer};
use embedded_hal::digital::{ErrorType, InputPin};
use embedded_hal_async::digital::Wait;
use psmpa_core::{ActionId, Config, ControlError, Report, SensorId, TraceEvent};
use psmpa_drivers::Active;
use psmpa_drivers::hbridge::{Channel, Drive};
use psmpa_drivers::hcsr04::Hcsr04;
use psmpa_drivers::marker::Marker;
use psmpa_drivers::switch::{DEBOUNCE, Switch};
use psmpa_fetch_tea::{Devices, FetchTea, FetchTeaRuntime, Settings, fetch_tea};
use psmpa_testkit::pins::{RecordedPin, RecordedPwm, ScriptedPin};
use psmpa_testkit::{Recorder, simulate_split};

/// The module raises its echo this long after the trigger falls (a real one: about 0.5 ms).
pub const ECHO_DELAY: Duration = Duration::from_millis(1);

/// The echo's width for a trigger at an instant; `None`: the module does not answer.
pub type Widths = Arc<dyn Fn(Instant) -> Option<Duration> + Send + Sync>;

/// An HC-SR04's echo output: after each falling edge of the trigger (a clone of the driver's
/// [`RecordedPin`]) it rises [`ECHO_DELAY`] later and stays high for the width `widths` gives
/// for that instant.
#[derive(Clone)]
pub struct EchoPin {
    trigger: RecordedPin,
    widths: Widths,
}

impl EchoPin {
    /// The echo answering `trigger`.
    pub fn new(trigger: RecordedPin, widths: Widths) -> Self {
        Self { trigger, widths }
    }

    /// The pulse answering the latest trigger at or before `at`: (rise, fall).
    fn pulse(&self, at: Instant) -> Option<(Instant, Instant)> {
        let edges = self.trigger.edges();
        let fell = edges
            .windows(2)
            .filter(|w| w[0].1 && !w[1].1 && w[1].0 <= at)
            .map(|w| w[1].0)
            .next_back()?;
        let width = (self.widths)(fell)?;
        let rise = fell + ECHO_DELAY;
        Some((rise, rise + width))
    }

    fn level_at(&self, at: Instant) -> bool {
        self.pulse(at)
            .is_some_and(|(rise, fall)| rise <= at && at < fall)
    }

    /// The next change after now: the latest pulse's rise or fall; none until a new trigger.
    async fn next_change(&self) {
        let now = Instant::now();
        match self
            .pulse(now)
            .and_then(|(rise, fall)| [rise, fall].into_iter().find(|t| *t > now))
        {
            Some(at) => Timer::at(at).await,
            None => core::future::pending().await,
        }
    }

    async fn wait_for(&self, high: bool) {
        while self.level_at(Instant::now()) != high {
            self.next_change().await;
        }
    }
}

impl ErrorType for EchoPin {
    type Error = Infallible;
}

impl InputPin for EchoPin {
    fn is_high(&mut self) -> Result<bool, Infallible> {
        Ok(self.level_at(Instant::now()))
    }

    fn is_low(&mut self) -> Result<bool, Infallible> {
        Ok(!self.level_at(Instant::now()))
    }
}

impl Wait for EchoPin {
    async fn wait_for_high(&mut self) -> Result<(), Infallible> {
        self.wait_for(true).await;
        Ok(())
    }

    async fn wait_for_low(&mut self) -> Result<(), Infallible> {
        self.wait_for(false).await;
        Ok(())
    }

    async fn wait_for_rising_edge(&mut self) -> Result<(), Infallible> {
        self.next_change().await;
        self.wait_for(true).await;
        Ok(())
    }

    async fn wait_for_falling_edge(&mut self) -> Result<(), Infallible> {
        self.next_change().await;
        self.wait_for(false).await;
        Ok(())
    }

    async fn wait_for_any_edge(&mut self) -> Result<(), Infallible> {
        self.next_change().await;
        Ok(())
    }
}

/// Echoes of `ms` milliseconds, always.
pub fn echo_ms(ms: u64) -> Widths {
    Arc::new(move |_| Some(Duration::from_millis(ms)))
}

/// A far wall's echo: 6 or 7 ms (1,029 or 1,200 mm) by turns, a period (100 ms) each, as a
/// real echo wavers. At the tests' 1 kHz tick an echo resolves 171 mm, coarser than the 50 mm
/// of driving after which a sonar that keeps one reading is stuck (`STUCK_AFTER_MM`): a wall
/// that always echoed the same width while the robot drove would be a stuck sonar.
pub fn far_echo_ms(at: Instant) -> Duration {
    Duration::from_millis(6 + (at.as_millis() / 100) % 2)
}

/// One motor channel's recorded pins.
#[derive(Clone)]
pub struct Wheel {
    /// IN1.
    pub in1: RecordedPin,
    /// IN2.
    pub in2: RecordedPin,
    /// PWM, full duty [`MAX_DUTY`].
    pub pwm: RecordedPwm,
}

/// The PWM channels' full duty in the rig (a 12-bit timer).
pub const MAX_DUTY: u16 = 4_000;

/// What a wheel's pins say at `at`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wheeling {
    /// IN1 high, IN2 low, at this duty.
    Forward(u16),
    /// IN1 and IN2 high, full duty.
    Brake,
    /// Anything else (nothing written yet, coasting, reverse).
    Other,
}

impl Wheel {
    fn new() -> Self {
        Self {
            in1: RecordedPin::new(),
            in2: RecordedPin::new(),
            pwm: RecordedPwm::new(MAX_DUTY),
        }
    }

    fn channel(&self) -> Channel<RecordedPin, RecordedPin, RecordedPwm> {
        Channel::new(self.in1.clone(), self.in2.clone(), self.pwm.clone())
    }

    /// What the pins say at `at`.
    pub fn at(&self, at: Instant) -> Wheeling {
        match (
            self.in1.level_at(at),
            self.in2.level_at(at),
            self.pwm.duty_at(at),
        ) {
            (Some(true), Some(false), Some(duty)) => Wheeling::Forward(duty),
            (Some(true), Some(true), Some(MAX_DUTY)) => Wheeling::Brake,
            _ => Wheeling::Other,
        }
    }

    /// The instants at which any of the wheel's pins was written, in order.
    pub fn writes(&self) -> Vec<Instant> {
        let mut at: Vec<Instant> = self.in1.log().iter().map(|(t, _)| *t).collect();
        at.extend(self.in2.log().iter().map(|(t, _)| *t));
        at.extend(self.pwm.log().iter().map(|(t, _)| *t));
        at.sort();
        at.dedup();
        at
    }
}

/// The robot's surroundings, as its pins see them. Switches and the marker are active low.
pub struct World {
    /// The sonar's echo widths.
    pub echo: Widths,
    /// The bumper pin's edges (high: released).
    pub bumper: Vec<(u64, bool)>,
    /// Whether the handle gives (the door is unlocked): its limit switch is pressed.
    pub unlocked: bool,
    /// Whether the marker is in view.
    pub marker: bool,
}

impl World {
    /// Nothing within 1 m (a far wall, [`far_echo_ms`]), no bump, an unlocked door, the
    /// marker in view.
    pub fn clear() -> Self {
        Self {
            echo: Arc::new(|at| Some(far_echo_ms(at))),
            bumper: Vec::new(),
            unlocked: true,
            marker: true,
        }
    }
}

/// The robot on test pins.
pub type TestRobot = FetchTea<
    Hcsr04<RecordedPin, EchoPin>,
    Switch<ScriptedPin>,
    Marker<ScriptedPin>,
    Switch<ScriptedPin>,
    Drive<
        Channel<RecordedPin, RecordedPin, RecordedPwm>,
        Channel<RecordedPin, RecordedPin, RecordedPwm>,
        RecordedPin,
    >,
>;

/// What a run leaves to look at.
pub struct Run {
    /// How the mission ended.
    pub result: Result<Report, ControlError>,
    /// The runtime's trace.
    pub trace: Recorder<fetch_tea::FetchTea>,
    /// The sonar's trigger pin.
    pub trigger: RecordedPin,
    /// The bumper's pin (its reads).
    pub bumper: ScriptedPin,
    /// The motors.
    pub left: Wheel,
    /// The motors.
    pub right: Wheel,
    /// The H-bridge's STBY pin.
    pub standby: RecordedPin,
}

/// The longest run.
pub const LIMIT: Duration = Duration::from_secs(60);

/// Runs the Fetch Tea mission on the robot in `world`.
pub fn run(world: World) -> Run {
    run_with(world, Settings::DEFAULT)
}

/// Runs the Fetch Tea mission on the robot in `world`, calibrated with `settings`.
pub fn run_with(world: World, settings: Settings) -> Run {
    run_config(world, settings, Config::default())
}

/// Runs the Fetch Tea mission on the robot in `world`, calibrated with `settings`, the
/// runtime set up by `config`.
pub fn run_config(world: World, settings: Settings, config: Config) -> Run {
    let trigger = RecordedPin::new();
    let bumper = ScriptedPin::new(true, &world.bumper);
    let (left, right, standby) = (Wheel::new(), Wheel::new(), RecordedPin::new());
    let robot: TestRobot = FetchTea::new(
        Devices {
            sonar: Hcsr04::new(trigger.clone(), EchoPin::new(trigger.clone(), world.echo)),
            bumper: Switch::new(bumper.clone(), Active::Low, DEBOUNCE),
            camera: Marker::new(ScriptedPin::constant(!world.marker), Active::Low),
            handle: Switch::new(
                ScriptedPin::constant(!world.unlocked),
                Active::Low,
                DEBOUNCE,
            ),
            wheels: Drive::with_standby(left.channel(), right.channel(), standby.clone()),
        },
        settings,
    );
    let mut rt = FetchTeaRuntime::new(fetch_tea::FetchTea, &robot, Recorder::default(), config);
    let (mut sensing, mut deciding) = rt.split();
    let done = simulate_split(sensing.run(), deciding.run(), LIMIT).expect("the run ends in time");
    Run {
        result: done.output,
        trace: rt.into_sink(),
        trigger,
        bumper,
        left,
        right,
        standby,
    }
}

/// The id of the mission's sensor `name`.
pub fn sensor(name: &str) -> SensorId {
    fetch_tea::TABLES.domain.sensor_id(name).expect("a sensor")
}

/// The id of the mission's action `name`.
pub fn action(name: &str) -> ActionId {
    fetch_tea::TABLES.domain.action_id(name).expect("an action")
}

impl Run {
    /// The samples of `sensor`: their instants and values.
    pub fn samples(&self, of: SensorId) -> Vec<(Instant, psmpa_core::Value)> {
        self.trace
            .events
            .iter()
            .filter_map(|(at, e)| match *e {
                TraceEvent::Sample { sensor, value, .. } if sensor == of => Some((*at, value)),
                _ => None,
            })
            .collect()
    }

    /// When the state of `action` was entered and left (the first time).
    pub fn state(&self, of: ActionId) -> (Instant, Instant) {
        let entered = self
            .trace
            .first(|e| matches!(e, TraceEvent::StateEntered { action, .. } if *action == of))
            .expect("the state was entered");
        let left = self
            .trace
            .first(|e| matches!(e, TraceEvent::StateLeft { action, .. } if *action == of))
            .expect("the state was left");
        (entered, left)
    }
}

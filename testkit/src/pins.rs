//! Pins for testing drivers written on `embedded-hal` 1.0 in virtual time: an input whose
//! level follows a script ([`ScriptedPin`]), an output and a PWM channel that record what was
//! written and when ([`RecordedPin`], [`RecordedPwm`]).
//!
//! Clones share their script and their records: hand one clone to the driver, keep another to
//! look at afterwards. They are `Send` and `Sync`, like a HAL's pins, so a robot built on them
//! is as `Sync` as it is on a board.
//!
//! ```
//! use embassy_time::{Duration, Instant};
//! use embedded_hal_async::digital::Wait;
//! use psmpa_testkit::pins::ScriptedPin;
//! use psmpa_testkit::sim::simulate;
//!
//! // Low, high from 5 ms to 8 ms.
//! let pin = ScriptedPin::new(false, &[(5, true), (8, false)]);
//! let mut driver_side = pin.clone();
//! let done = simulate(
//!     async move {
//!         driver_side.wait_for_high().await.unwrap();
//!         let rose = Instant::now();
//!         driver_side.wait_for_low().await.unwrap();
//!         (rose.as_millis(), Instant::now().as_millis())
//!     },
//!     Duration::from_secs(1),
//! )
//! .unwrap();
//! assert_eq!(done.output, (5, 8));
//! ```

use std::convert::Infallible;
use std::sync::{Arc, Mutex, PoisonError};
use std::vec::Vec;

use embassy_time::{Instant, Timer};
use embedded_hal::digital::{ErrorType, InputPin, OutputPin, StatefulOutputPin};
use embedded_hal::pwm::{self, SetDutyCycle};
use embedded_hal_async::digital::Wait;

/// A shared list: what clones of one pin record.
type Shared<T> = Arc<Mutex<Vec<T>>>;

fn snapshot<T: Clone>(list: &Shared<T>) -> Vec<T> {
    list.lock().unwrap_or_else(PoisonError::into_inner).clone()
}

fn push<T>(list: &Shared<T>, item: T) {
    list.lock()
        .unwrap_or_else(PoisonError::into_inner)
        .push(item);
}

/// An input pin whose level is a function of virtual time: `initial` until the first edge,
/// then each edge's level from its instant on. Implements [`InputPin`] and [`Wait`]: a wait
/// sleeps on a timer until the script's next change, so a simulation jumps straight to it.
/// Records the instant of every read.
#[derive(Clone, Debug)]
pub struct ScriptedPin {
    initial: bool,
    edges: Arc<[(Instant, bool)]>,
    reads: Shared<Instant>,
}

impl ScriptedPin {
    /// `initial` until the first edge; each `(ms, level)` holds from `ms` milliseconds of
    /// virtual time on.
    ///
    /// # Panics
    ///
    /// If the edges are not in time order.
    pub fn new(initial: bool, edges: &[(u64, bool)]) -> Self {
        assert!(
            edges.is_sorted_by_key(|(ms, _)| *ms),
            "a ScriptedPin's edges must be in time order: {edges:?}"
        );
        Self {
            initial,
            edges: edges
                .iter()
                .map(|&(ms, level)| (Instant::from_millis(ms), level))
                .collect(),
            reads: Shared::default(),
        }
    }

    /// A pin that stays at `level`.
    pub fn constant(level: bool) -> Self {
        Self::new(level, &[])
    }

    /// The level at `at`.
    pub fn level_at(&self, at: Instant) -> bool {
        self.edges
            .iter()
            .take_while(|(t, _)| *t <= at)
            .last()
            .map_or(self.initial, |(_, level)| *level)
    }

    /// The first instant after `after` at which the level changes, if any.
    pub fn next_change(&self, after: Instant) -> Option<Instant> {
        let mut level = self.level_at(after);
        for &(t, l) in self.edges.iter().filter(|(t, _)| *t > after) {
            if l != level {
                return Some(t);
            }
            level = l;
        }
        None
    }

    /// When the pin was read (`is_high`, `is_low`), in order, by this pin and its clones.
    pub fn reads(&self) -> Vec<Instant> {
        snapshot(&self.reads)
    }

    /// Sleeps until the next change and returns the level after it; never returns when the
    /// script has no more changes.
    async fn next_level(&self) -> bool {
        match self.next_change(Instant::now()) {
            Some(at) => {
                Timer::at(at).await;
                self.level_at(at)
            }
            None => core::future::pending().await,
        }
    }

    async fn wait_for_level(&self, high: bool) {
        if self.level_at(Instant::now()) == high {
            return;
        }
        while self.next_level().await != high {}
    }

    async fn wait_for_edge_to(&self, high: bool) {
        while self.next_level().await != high {}
    }
}

impl ErrorType for ScriptedPin {
    type Error = Infallible;
}

impl InputPin for ScriptedPin {
    fn is_high(&mut self) -> Result<bool, Infallible> {
        let now = Instant::now();
        push(&self.reads, now);
        Ok(self.level_at(now))
    }

    fn is_low(&mut self) -> Result<bool, Infallible> {
        self.is_high().map(|high| !high)
    }
}

impl Wait for ScriptedPin {
    async fn wait_for_high(&mut self) -> Result<(), Infallible> {
        self.wait_for_level(true).await;
        Ok(())
    }

    async fn wait_for_low(&mut self) -> Result<(), Infallible> {
        self.wait_for_level(false).await;
        Ok(())
    }

    async fn wait_for_rising_edge(&mut self) -> Result<(), Infallible> {
        self.wait_for_edge_to(true).await;
        Ok(())
    }

    async fn wait_for_falling_edge(&mut self) -> Result<(), Infallible> {
        self.wait_for_edge_to(false).await;
        Ok(())
    }

    async fn wait_for_any_edge(&mut self) -> Result<(), Infallible> {
        self.next_level().await;
        Ok(())
    }
}

/// An output pin that records every write with its instant of virtual time. Its level is
/// unknown (`None`) until the first write.
#[derive(Clone, Debug, Default)]
pub struct RecordedPin {
    log: Shared<(Instant, bool)>,
}

impl RecordedPin {
    /// A pin with no writes yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Every write (`true` for high), in order, by this pin and its clones.
    pub fn log(&self) -> Vec<(Instant, bool)> {
        snapshot(&self.log)
    }

    /// The writes that changed the level (the first write counts as one): the pin's edges.
    pub fn edges(&self) -> Vec<(Instant, bool)> {
        let mut edges: Vec<(Instant, bool)> = Vec::new();
        for (at, level) in self.log() {
            if edges.last().is_none_or(|(_, l)| *l != level) {
                edges.push((at, level));
            }
        }
        edges
    }

    /// The level at `at`: the last write at or before it.
    pub fn level_at(&self, at: Instant) -> Option<bool> {
        self.log()
            .iter()
            .take_while(|(t, _)| *t <= at)
            .last()
            .map(|(_, level)| *level)
    }

    /// The level last written.
    pub fn level(&self) -> Option<bool> {
        self.log().last().map(|(_, level)| *level)
    }
}

impl ErrorType for RecordedPin {
    type Error = Infallible;
}

impl OutputPin for RecordedPin {
    fn set_low(&mut self) -> Result<(), Infallible> {
        push(&self.log, (Instant::now(), false));
        Ok(())
    }

    fn set_high(&mut self) -> Result<(), Infallible> {
        push(&self.log, (Instant::now(), true));
        Ok(())
    }
}

impl StatefulOutputPin for RecordedPin {
    fn is_set_high(&mut self) -> Result<bool, Infallible> {
        Ok(self.level() == Some(true))
    }

    fn is_set_low(&mut self) -> Result<bool, Infallible> {
        Ok(self.level() == Some(false))
    }
}

/// A PWM channel that records every duty cycle set, with its instant of virtual time. A duty
/// above the maximum is refused ([`DutyAboveMax`]) and not recorded.
#[derive(Clone, Debug)]
pub struct RecordedPwm {
    max: u16,
    log: Shared<(Instant, u16)>,
}

impl RecordedPwm {
    /// A channel whose full duty is `max_duty`.
    pub fn new(max_duty: u16) -> Self {
        Self {
            max: max_duty,
            log: Shared::default(),
        }
    }

    /// Every duty set, in order, by this channel and its clones.
    pub fn log(&self) -> Vec<(Instant, u16)> {
        snapshot(&self.log)
    }

    /// The duty at `at`: the last one set at or before it.
    pub fn duty_at(&self, at: Instant) -> Option<u16> {
        self.log()
            .iter()
            .take_while(|(t, _)| *t <= at)
            .last()
            .map(|(_, duty)| *duty)
    }

    /// The duty last set.
    pub fn duty(&self) -> Option<u16> {
        self.log().last().map(|(_, duty)| *duty)
    }
}

/// [`RecordedPwm`] was given a duty above its maximum.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DutyAboveMax {
    /// The duty asked for.
    pub duty: u16,
    /// The channel's maximum.
    pub max: u16,
}

impl pwm::Error for DutyAboveMax {
    fn kind(&self) -> pwm::ErrorKind {
        pwm::ErrorKind::Other
    }
}

impl pwm::ErrorType for RecordedPwm {
    type Error = DutyAboveMax;
}

impl SetDutyCycle for RecordedPwm {
    fn max_duty_cycle(&self) -> u16 {
        self.max
    }

    fn set_duty_cycle(&mut self, duty: u16) -> Result<(), DutyAboveMax> {
        if duty > self.max {
            return Err(DutyAboveMax {
                duty,
                max: self.max,
            });
        }
        push(&self.log, (Instant::now(), duty));
        Ok(())
    }
}

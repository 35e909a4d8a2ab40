//! An HC-SR04-class ultrasonic ranger: a 10 µs pulse on the trigger starts a measurement; the
//! module sends a 40 kHz burst and then holds its echo line high until the echo returns, so
//! the width of the echo pulse is the sound's round trip.
//!
//! A read ([`Hcsr04::measure`]) is async throughout: it awaits the trigger pulse, the echo's
//! rise and the echo's fall, and never spins, so a 38 ms read costs other tasks nothing. Every
//! wait is bounded: the echo must rise within [`RISE_TIMEOUT`] (or the time a slower module
//! is given, [`Hcsr04::with_rise_timeout`]) and fall within [`PULSE_LIMIT`].
//!
//! The width is timed with `embassy_time::Instant` from when the task sees the rise to when it
//! sees the fall. Each edge reaches the task through the GPIO interrupt and an executor poll:
//! the two latencies cancel only when both edges find the processor equally busy. An edge
//! that waits behind other work (another sensor's sample on the same executor, a critical
//! section) lengthens or shortens the pulse by that wait, 0.17 mm a microsecond; a late fall
//! reads farther. For better, time the pulse in hardware (PWM input or PIO). The resolution is
//! the time driver's tick: 1 µs (0.17 mm) at 1 MHz; at a 1 kHz tick, whole milliseconds
//! (171 mm).

use embassy_time::{Duration, Instant, Timer, with_timeout};
use embedded_hal::digital::{InputPin, OutputPin};
use embedded_hal_async::digital::Wait;

/// The trigger pulse: at least 10 µs (one tick at coarse tick rates, which the module accepts:
/// it starts on the falling edge).
pub const TRIGGER_PULSE: Duration = Duration::from_micros(10);
/// The echo must rise this long after the trigger falls, or the module did not answer. The
/// module raises it after its 200 µs burst, well within this.
pub const RISE_TIMEOUT: Duration = Duration::from_millis(5);
/// The echo must fall this long after it rose, or the line is stuck. The module ends a pulse
/// by itself after about 38 ms when no echo returns. A whole read (trigger, rise, pulse) stays
/// within 48 ms; one that first waits out a pulse still running (a read cut short before)
/// takes up to this longer: 90 ms, inside the Fetch Tea sonar's 100 ms timeout, so a stuck
/// line is this driver's [`Hcsr04Error::Stuck`], not the runtime's timeout.
pub const PULSE_LIMIT: Duration = Duration::from_millis(42);
/// Nearer than this the module cannot measure (its rated minimum).
pub const MIN_MM: u32 = 20;
/// Farther than this the module's readings are not rated; a reading beyond counts as
/// "nothing in range".
pub const MAX_MM: u32 = 4_000;

/// What a read found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Range {
    /// An obstacle this many millimetres away ([`MIN_MM`]..=[`MAX_MM`]).
    Mm(u16),
    /// Nothing within [`MAX_MM`]: a pulse beyond the rated range, or the module's own
    /// no-echo pulse of about 38 ms. Not a distance.
    NothingInRange,
}

/// Why a read found no range.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Hcsr04Error {
    /// The echo line was high before the trigger and stayed high for [`PULSE_LIMIT`]: longer
    /// than any pulse of the module's own, so the line is stuck high (or a neighbour keeps
    /// it so). Nothing was triggered; a later read may succeed.
    Busy,
    /// The echo did not rise within [`RISE_TIMEOUT`] of the trigger: the module did not
    /// answer (unpowered, disconnected, or it missed the trigger). A lost sample.
    NoEcho,
    /// The echo did not fall within [`PULSE_LIMIT`]: the echo line is stuck high.
    Stuck,
    /// The pulse was shorter than [`MIN_MM`] takes: something is too close to measure.
    OutOfRange,
    /// A pin reported an error.
    Pin,
}

/// A ranger that measures like an HC-SR04: one read gives a [`Range`] or an [`Hcsr04Error`].
/// [`Hcsr04`] is one on its two pins; a simulator's module, whose echo is timed in its
/// world rather than by a 1 µs clock, is another. A robot written on this trait runs on both.
#[allow(async_fn_in_trait)] // Runs on single-threaded executors: no `Send` bound wanted.
pub trait Ranger {
    /// Takes one measurement ([`Hcsr04::measure`]).
    async fn measure(&mut self) -> Result<Range, Hcsr04Error>;
}

/// Millimetres to an obstacle whose echo pulse is `width_us` wide: sound at 343 m/s (dry air
/// at 20 °C) travels 0.343 mm/µs, there and back, so `width_us · 343 / 2000`. About 0.2 %
/// more per °C above 20, less below. Saturates instead of overflowing.
pub const fn mm_from_echo_us(width_us: u64) -> u64 {
    width_us.saturating_mul(343) / 2_000
}

/// The range an echo pulse of `width_us` means: [`Range::Mm`] within the rated range,
/// [`Range::NothingInRange`] beyond it, [`Hcsr04Error::OutOfRange`] below [`MIN_MM`].
pub const fn range_from_echo_us(width_us: u64) -> Result<Range, Hcsr04Error> {
    let mm = mm_from_echo_us(width_us);
    if mm < MIN_MM as u64 {
        Err(Hcsr04Error::OutOfRange)
    } else if mm > MAX_MM as u64 {
        Ok(Range::NothingInRange)
    } else {
        // At most `MAX_MM`, which fits.
        Ok(Range::Mm(mm as u16))
    }
}

/// An HC-SR04-class ranger on a trigger output and an echo input. The HC-SR04 is a 5 V part:
/// on an MCU whose inputs are not 5 V tolerant, bring the echo in through a divider (or use a
/// 3.3 V variant such as the HC-SR04P).
#[derive(Debug)]
pub struct Hcsr04<T, E> {
    trigger: T,
    echo: E,
    rise_timeout: Duration,
}

impl<T: OutputPin, E: InputPin + Wait> Hcsr04<T, E> {
    /// The ranger on these pins. Touches neither until the first read.
    pub const fn new(trigger: T, echo: E) -> Self {
        Self {
            trigger,
            echo,
            rise_timeout: RISE_TIMEOUT,
        }
    }

    /// The ranger, waiting up to `timeout` for its echo to rise instead of [`RISE_TIMEOUT`]:
    /// for a module that answers later (one that processes before it pings, or sits behind a
    /// converter). A longer read must still fit the sensor's sample timeout.
    #[must_use]
    pub const fn with_rise_timeout(mut self, timeout: Duration) -> Self {
        self.rise_timeout = timeout;
        self
    }

    /// Takes one measurement: triggers, waits for the echo to rise (at most [`RISE_TIMEOUT`],
    /// or the module's own [`with_rise_timeout`](Self::with_rise_timeout))
    /// and times the pulse (at most [`PULSE_LIMIT`]). Takes the pulse's width plus about the
    /// trigger pulse: 38 ms and a little with nothing in range.
    ///
    /// An echo already high (a pulse of an earlier read, cancelled) is first waited out, at
    /// most [`PULSE_LIMIT`] ([`Hcsr04Error::Busy`] if it does not fall): the read then takes
    /// that much longer.
    ///
    /// Cancel-safe: dropped at any await, it leaves at worst the trigger high (the next read
    /// pulls it low first) or a pulse running (the next read waits for it to end).
    pub async fn measure(&mut self) -> Result<Range, Hcsr04Error> {
        // A pulse still running (this module's, from a read cancelled mid-echo: the sensor
        // switched off and on again) ends by itself: wait for it rather than lose the sample.
        if self.echo.is_high().map_err(|_| Hcsr04Error::Pin)? {
            match with_timeout(PULSE_LIMIT, self.echo.wait_for_low()).await {
                Ok(fell) => fell.map_err(|_| Hcsr04Error::Pin)?,
                Err(_) => return Err(Hcsr04Error::Busy),
            }
        }
        // Low first: a read cancelled during the trigger pulse left it high.
        self.trigger.set_low().map_err(|_| Hcsr04Error::Pin)?;
        self.trigger.set_high().map_err(|_| Hcsr04Error::Pin)?;
        Timer::after(TRIGGER_PULSE).await;
        self.trigger.set_low().map_err(|_| Hcsr04Error::Pin)?;
        match with_timeout(self.rise_timeout, self.echo.wait_for_high()).await {
            Ok(rose) => rose.map_err(|_| Hcsr04Error::Pin)?,
            Err(_) => return Err(Hcsr04Error::NoEcho),
        }
        let rose = Instant::now();
        match with_timeout(PULSE_LIMIT, self.echo.wait_for_low()).await {
            Ok(fell) => fell.map_err(|_| Hcsr04Error::Pin)?,
            Err(_) => return Err(Hcsr04Error::Stuck),
        }
        let width = Instant::now().saturating_duration_since(rose);
        range_from_echo_us(width.as_micros())
    }

    /// The pins back.
    pub fn release(self) -> (T, E) {
        (self.trigger, self.echo)
    }
}

impl<T: OutputPin, E: InputPin + Wait> Ranger for Hcsr04<T, E> {
    async fn measure(&mut self) -> Result<Range, Hcsr04Error> {
        Hcsr04::measure(self).await
    }
}

//! A debounced switch: a bump switch, the limit switch the arm presses on a door handle.
//!
//! A mechanical contact bounces for a few milliseconds when it closes or opens. A read
//! ([`Switch::pressed`]) that sees the level differ from the state it last accepted watches the
//! pin for the debounce time: only a level that holds that long, with no edge, is accepted;
//! a bounce keeps the previous state, and a later read tries again. So a bouncing switch gives
//! one contact, and a read costs nothing (no await) while nothing changes, and at most the
//! debounce time when something does. A one-off read, which no later read follows up
//! ([`Switch::settled`]), waits the bounces out instead.

use embassy_time::{Duration, Instant, Timer, with_timeout};
use embedded_hal::digital::InputPin;
use embedded_hal_async::digital::Wait;

use crate::{Active, PinError};

/// A debounce time that suits small snap-action switches, which settle within a few ms.
pub const DEBOUNCE: Duration = Duration::from_millis(5);

/// A switch on an input pin, with its active level and debounce time.
#[derive(Debug)]
pub struct Switch<P> {
    pin: P,
    active: Active,
    debounce: Duration,
    pressed: bool,
    /// When [`Switch::edge`] last returned.
    last_edge: Option<Instant>,
}

impl<P: InputPin + Wait> Switch<P> {
    /// The switch on `pin`, pressed when the pin is at `active`, accepting a change after it
    /// held for `debounce` ([`DEBOUNCE`] suits most). Released until a read sees it pressed.
    pub const fn new(pin: P, active: Active, debounce: Duration) -> Self {
        Self {
            pin,
            active,
            debounce,
            pressed: false,
            last_edge: None,
        }
    }

    /// Reads the switch: `true` when pressed. A level that differs from the last accepted
    /// state is accepted only if no edge comes within the debounce time and the pin still
    /// shows it then; otherwise the last accepted state is returned. Takes no time when the
    /// level is unchanged, the debounce time when it changed. Cancel-safe: a cancelled read
    /// accepts nothing.
    pub async fn pressed(&mut self) -> Result<bool, PinError> {
        let seen = self.level()?;
        if seen == self.pressed {
            return Ok(seen);
        }
        match with_timeout(self.debounce, self.pin.wait_for_any_edge()).await {
            // An edge within the debounce time: it bounced.
            Ok(edge) => edge.map_err(|_| PinError)?,
            // It held for the debounce time; an edge just before the wait began shows here.
            Err(_) => {
                if self.level()? == seen {
                    self.pressed = seen;
                }
            }
        }
        Ok(self.pressed)
    }

    /// Reads the switch once and for all: waits until the level has held for the debounce time
    /// with no edge, accepts it and returns it (`true`: pressed). For a read no later read
    /// follows up (an on-demand one): [`Switch::pressed`] may return the previous state while
    /// the contact bounces, this never does. Takes the debounce time at least; a contact that
    /// keeps chattering never settles, so bound it with a timeout (the runtime bounds every
    /// read). Cancel-safe: a cancelled read accepts nothing.
    pub async fn settled(&mut self) -> Result<bool, PinError> {
        // The watch repeats `pressed`'s on purpose: shared through an async helper, the nested
        // future cost the Pico 2 board 32 B of static RAM (`cargo xtask size`).
        loop {
            let seen = self.level()?;
            match with_timeout(self.debounce, self.pin.wait_for_any_edge()).await {
                // It bounced: watch again.
                Ok(edge) => edge.map_err(|_| PinError)?,
                Err(_) if self.level()? == seen => {
                    self.pressed = seen;
                    return Ok(seen);
                }
                // An edge just before the wait began: watch again.
                Err(_) => {}
            }
        }
    }

    /// The state the last read accepted, without reading the pin.
    pub const fn last(&self) -> bool {
        self.pressed
    }

    /// Waits for the next edge of the pin, rising or falling (a contact, a release, a bounce):
    /// the moment to read again. At most one a debounce time: an edge that comes sooner after
    /// the last one this returned is returned when that time is up, so a chattering contact
    /// or a noisy wire (motor switching noise on a line held by a weak pull-up) cannot ask
    /// for reads faster than that. Does not change the accepted state. Cancel-safe.
    pub async fn edge(&mut self) -> Result<(), PinError> {
        self.pin.wait_for_any_edge().await.map_err(|_| PinError)?;
        if let Some(quiet) = self.last_edge.map(|t| t.saturating_add(self.debounce)) {
            // (A timer always yields once, even for an instant that has passed.)
            if Instant::now() < quiet {
                Timer::at(quiet).await;
            }
        }
        self.last_edge = Some(Instant::now());
        Ok(())
    }

    /// The pin back.
    pub fn release(self) -> P {
        self.pin
    }

    /// Whether the pin shows the switch pressed now (no debouncing).
    fn level(&mut self) -> Result<bool, PinError> {
        let high = self.pin.is_high().map_err(|_| PinError)?;
        Ok(self.active.is_active(high))
    }
}

//! The marker sensor: an IR reflectance sensor that sees the reflective marker on the door.
//!
//! It stands in for the paper's camera, which finds the door handle in an image: here a
//! TCRT5000-class module (an IR LED and phototransistor behind an LM393 comparator, threshold
//! set by its trimmer) looks at a reflective patch on the door beside the handle, and its
//! digital output says whether the patch is in view. Such modules pull their output low when
//! they see reflection ([`Active::Low`]). A read is one pin read: no wait, no debouncing (the
//! comparator's output is clean, and the mission reads it once).

use embedded_hal::digital::InputPin;

use crate::{Active, PinError};

/// A reflectance sensor on a digital input.
#[derive(Debug)]
pub struct Marker<P> {
    pin: P,
    active: Active,
}

impl<P: InputPin> Marker<P> {
    /// The sensor on `pin`, seeing the marker when the pin is at `active` ([`Active::Low`] for
    /// TCRT5000 modules).
    pub const fn new(pin: P, active: Active) -> Self {
        Self { pin, active }
    }

    /// Whether the marker is in view now.
    pub fn seen(&mut self) -> Result<bool, PinError> {
        let high = self.pin.is_high().map_err(|_| PinError)?;
        Ok(self.active.is_active(high))
    }

    /// The pin back.
    pub fn release(self) -> P {
        self.pin
    }
}

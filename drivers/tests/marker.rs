//! The marker sensor (the camera's stand-in) against embedded-hal-mock pins.

use std::io::ErrorKind;

use embedded_hal_mock::eh1::MockError;
use embedded_hal_mock::eh1::digital::{Mock as Pin, State, Transaction as P};
use psmpa_drivers::marker::Marker;
use psmpa_drivers::{Active, PinError};

#[test]
fn a_tcrt5000_module_pulls_low_when_it_sees_the_marker() {
    let mut pin = Pin::new(&[P::get(State::Low), P::get(State::High)]);
    let mut marker = Marker::new(pin.clone(), Active::Low);
    assert_eq!(marker.seen(), Ok(true));
    assert_eq!(marker.seen(), Ok(false));
    pin.done();
}

#[test]
fn an_active_high_sensor_sees_the_marker_when_high() {
    let mut pin = Pin::new(&[P::get(State::High), P::get(State::Low)]);
    let mut marker = Marker::new(pin.clone(), Active::High);
    assert_eq!(marker.seen(), Ok(true));
    assert_eq!(marker.seen(), Ok(false));
    pin.done();
}

#[test]
fn a_pin_error_is_reported() {
    let error = MockError::Io(ErrorKind::NotConnected);
    let mut pin = Pin::new(&[P::get(State::Low).with_error(error)]);
    let mut marker = Marker::new(pin.clone(), Active::Low);
    assert_eq!(marker.seen(), Err(PinError));
    pin.done();
}

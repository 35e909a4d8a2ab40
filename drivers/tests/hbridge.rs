//! The TB6612FNG channel and the differential drive against embedded-hal-mock pins: each
//! command must make exactly the listed writes, in order (`done()` fails on a missing one, the
//! mock panics on an unexpected one).

use std::io::ErrorKind;

use embedded_hal_mock::eh1::MockError;
use embedded_hal_mock::eh1::digital::{Mock as Pin, State, Transaction as P};
use embedded_hal_mock::eh1::pwm::{Mock as Pwm, Transaction as D};
use psmpa_drivers::PinError;
use psmpa_drivers::hbridge::{Channel, Drive, Motor};

/// A channel expecting these writes; the mocks are checked when it is dropped by `check`.
struct Expect {
    in1: Pin,
    in2: Pin,
    pwm: Pwm,
}

impl Expect {
    fn new(in1: &[P], in2: &[P], pwm: &[D]) -> Self {
        Self {
            in1: Pin::new(in1),
            in2: Pin::new(in2),
            pwm: Pwm::new(pwm),
        }
    }

    fn channel(&self) -> Channel<Pin, Pin, Pwm> {
        Channel::new(self.in1.clone(), self.in2.clone(), self.pwm.clone())
    }

    fn done(mut self) {
        self.in1.done();
        self.in2.done();
        self.pwm.done();
    }
}

#[test]
fn a_stop_command_sets_the_brake_levels_and_full_duty() {
    // Short brake: IN1 = IN2 = high, PWM at 100 % (its maximum, whatever the timer's).
    let expect = Expect::new(
        &[P::set(State::High)],
        &[P::set(State::High)],
        &[D::max_duty_cycle(2_047), D::set_duty_cycle(2_047)],
    );
    assert_eq!(expect.channel().brake(), Ok(()));
    expect.done();
}

#[test]
fn a_forward_command_sets_the_direction_pins_then_the_duty() {
    // 600 ‰ of a 2,000-step timer: 1,200.
    let expect = Expect::new(
        &[P::set(State::High)],
        &[P::set(State::Low)],
        &[D::max_duty_cycle(2_000), D::set_duty_cycle(1_200)],
    );
    assert_eq!(expect.channel().drive(600), Ok(()));
    expect.done();
}

#[test]
fn a_reverse_command_swaps_the_direction_pins() {
    let expect = Expect::new(
        &[P::set(State::Low)],
        &[P::set(State::High)],
        &[D::max_duty_cycle(4_000), D::set_duty_cycle(1_000)],
    );
    assert_eq!(expect.channel().drive(-250), Ok(()));
    expect.done();
}

#[test]
fn duties_beyond_full_are_clamped_and_zero_brakes() {
    let expect = Expect::new(
        &[P::set(State::High), P::set(State::Low), P::set(State::High)],
        &[P::set(State::Low), P::set(State::High), P::set(State::High)],
        &[
            D::max_duty_cycle(1_000),
            D::set_duty_cycle(1_000),
            D::max_duty_cycle(1_000),
            D::set_duty_cycle(1_000),
            D::max_duty_cycle(1_000),
            D::set_duty_cycle(1_000),
        ],
    );
    let mut channel = expect.channel();
    assert_eq!(channel.drive(i16::MAX), Ok(()));
    assert_eq!(channel.drive(i16::MIN), Ok(()));
    assert_eq!(channel.drive(0), Ok(()));
    expect.done();
}

#[test]
fn coasting_sets_both_direction_pins_low_and_no_duty() {
    let expect = Expect::new(
        &[P::set(State::Low)],
        &[P::set(State::Low)],
        &[D::set_duty_cycle(0)],
    );
    assert_eq!(expect.channel().coast(), Ok(()));
    expect.done();
}

#[test]
fn a_pin_error_is_reported_and_stops_the_command() {
    // IN1 fails: IN2 and the PWM are not touched.
    let error = MockError::Io(ErrorKind::NotConnected);
    let expect = Expect::new(&[P::set(State::High).with_error(error)], &[], &[]);
    assert_eq!(expect.channel().drive(500), Err(PinError));
    expect.done();
}

#[test]
fn the_drive_wakes_the_chip_then_commands_both_wheels() {
    let left = Expect::new(
        &[P::set(State::High), P::set(State::High)],
        &[P::set(State::Low), P::set(State::High)],
        &[
            D::max_duty_cycle(1_000),
            D::set_duty_cycle(300),
            D::max_duty_cycle(1_000),
            D::set_duty_cycle(1_000),
        ],
    );
    let right = Expect::new(
        &[P::set(State::Low), P::set(State::High)],
        &[P::set(State::High), P::set(State::High)],
        &[
            D::max_duty_cycle(1_000),
            D::set_duty_cycle(300),
            D::max_duty_cycle(1_000),
            D::set_duty_cycle(1_000),
        ],
    );
    // STBY high before each command that needs the chip awake; low for standby.
    let mut standby = Pin::new(&[P::set(State::High), P::set(State::High), P::set(State::Low)]);
    let mut drive = Drive::with_standby(left.channel(), right.channel(), standby.clone());
    // Turning on the spot: left forward, right reverse.
    assert_eq!(drive.drive(300, -300), Ok(()));
    assert_eq!(drive.brake(), Ok(()));
    assert_eq!(drive.standby(), Ok(()));
    left.done();
    right.done();
    standby.done();
}

#[test]
fn a_drive_without_a_standby_pin_commands_the_wheels_alone() {
    let left = Expect::new(
        &[P::set(State::High)],
        &[P::set(State::Low)],
        &[D::max_duty_cycle(100), D::set_duty_cycle(50)],
    );
    let right = Expect::new(
        &[P::set(State::High)],
        &[P::set(State::Low)],
        &[D::max_duty_cycle(100), D::set_duty_cycle(50)],
    );
    let mut drive = Drive::new(left.channel(), right.channel());
    assert_eq!(drive.drive(500, 500), Ok(()));
    left.done();
    right.done();
}

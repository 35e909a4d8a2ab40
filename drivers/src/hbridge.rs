//! DC motors on a TB6612FNG dual H-bridge: one [`Channel`] per motor, and [`Drive`], two
//! channels of a differential drive with the chip's optional standby pin.
//!
//! The chip's truth table, per channel (with STBY high):
//!
//! | IN1 | IN2 | PWM | outputs |
//! |---|---|---|---|
//! | H | L | duty | forward (CW), at the duty |
//! | L | H | duty | reverse (CCW), at the duty |
//! | H | H | any | short brake: both motor leads to ground, the motor stops fast |
//! | L | L | any | off: the motor coasts |
//!
//! (PWM low with one IN high is a short brake too: the duty alternates driving and braking.)
//! STBY low turns both channels off. Which way "forward" turns a wheel depends on how its motor
//! is wired: swap the motor's leads, or IN1 and IN2, if a wheel runs backwards.
//!
//! Every operation is a few pin writes: no waits, so safe to call from `Actuator::halt`.

use embedded_hal::digital::OutputPin;
use embedded_hal::pwm::SetDutyCycle;

use crate::PinError;

/// Full duty, in thousandths.
pub const FULL: i16 = 1_000;

/// A motor that can be driven at a signed duty, braked and let coast.
pub trait Motor {
    /// Drives at `permille` thousandths of full duty: positive forward, negative reverse,
    /// clamped to ±[`FULL`]; 0 brakes.
    fn drive(&mut self, permille: i16) -> Result<(), PinError>;
    /// Short brake: stops the motor fast and holds it.
    fn brake(&mut self) -> Result<(), PinError>;
    /// Lets the motor run down freely.
    fn coast(&mut self) -> Result<(), PinError>;
    /// How far its wheel has rolled forward in all, µm, read from an encoder on it; `None`
    /// for a motor without one (a robot then counts its way by wheel time).
    fn rolled_um(&self) -> Option<u64> {
        None
    }
}

/// One channel of a TB6612FNG: direction pins IN1, IN2 and the PWM input.
#[derive(Debug)]
pub struct Channel<A, B, P> {
    in1: A,
    in2: B,
    pwm: P,
}

impl<A: OutputPin, B: OutputPin, P: SetDutyCycle> Channel<A, B, P> {
    /// The channel on these pins. Touches none until the first command.
    pub const fn new(in1: A, in2: B, pwm: P) -> Self {
        Self { in1, in2, pwm }
    }

    /// The pins back.
    pub fn release(self) -> (A, B, P) {
        (self.in1, self.in2, self.pwm)
    }

    fn pins(&mut self, in1: bool, in2: bool) -> Result<(), PinError> {
        self.in1.set_state(in1.into()).map_err(|_| PinError)?;
        self.in2.set_state(in2.into()).map_err(|_| PinError)
    }
}

impl<A: OutputPin, B: OutputPin, P: SetDutyCycle> Motor for Channel<A, B, P> {
    /// Direction pins first, then the duty.
    fn drive(&mut self, permille: i16) -> Result<(), PinError> {
        if permille == 0 {
            return self.brake();
        }
        let forward = permille > 0;
        self.pins(forward, !forward)?;
        let duty = permille.unsigned_abs().min(FULL.unsigned_abs());
        self.pwm
            .set_duty_cycle_fraction(duty, FULL.unsigned_abs())
            .map_err(|_| PinError)
    }

    /// IN1 and IN2 high, duty 100 %.
    fn brake(&mut self) -> Result<(), PinError> {
        self.pins(true, true)?;
        self.pwm.set_duty_cycle_fully_on().map_err(|_| PinError)
    }

    /// IN1 and IN2 low, duty 0.
    fn coast(&mut self) -> Result<(), PinError> {
        self.pins(false, false)?;
        self.pwm.set_duty_cycle_fully_off().map_err(|_| PinError)
    }
}

/// No standby pin: STBY is wired high on the board. Writes to it do nothing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NoStandby;

impl embedded_hal::digital::ErrorType for NoStandby {
    type Error = core::convert::Infallible;
}

impl OutputPin for NoStandby {
    fn set_low(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }

    fn set_high(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

/// A differential drive: the left and right motors and the H-bridge's STBY pin, if the board
/// wires it to the MCU ([`NoStandby`] otherwise).
///
/// [`drive`](Self::drive) and [`brake`](Self::brake) set STBY high (they need the chip awake);
/// [`standby`](Self::standby) sets it low.
#[derive(Debug)]
pub struct Drive<L, R, S = NoStandby> {
    left: L,
    right: R,
    standby: S,
}

impl<L: Motor, R: Motor> Drive<L, R> {
    /// The drive with STBY wired high.
    pub const fn new(left: L, right: R) -> Self {
        Self::with_standby(left, right, NoStandby)
    }
}

impl<L: Motor, R: Motor, S: OutputPin> Drive<L, R, S> {
    /// The drive with STBY on `standby`. Touches no pin until the first command.
    pub const fn with_standby(left: L, right: R, standby: S) -> Self {
        Self {
            left,
            right,
            standby,
        }
    }

    /// Drives the left and right motors at their duties (thousandths, see [`Motor::drive`]).
    pub fn drive(&mut self, left: i16, right: i16) -> Result<(), PinError> {
        self.wake()?;
        self.left.drive(left)?;
        self.right.drive(right)
    }

    /// Brakes both motors (short brake).
    pub fn brake(&mut self) -> Result<(), PinError> {
        self.wake()?;
        self.left.brake()?;
        self.right.brake()
    }

    /// Lets both motors coast.
    pub fn coast(&mut self) -> Result<(), PinError> {
        self.left.coast()?;
        self.right.coast()
    }

    /// Puts the chip in standby (STBY low): both channels off, the motors coast. The next
    /// [`drive`](Self::drive) or [`brake`](Self::brake) wakes it.
    pub fn standby(&mut self) -> Result<(), PinError> {
        self.standby.set_low().map_err(|_| PinError)
    }

    /// How far the robot has rolled forward, µm, by the left wheel's encoder: `None` without
    /// one ([`Motor::rolled_um`]).
    pub fn rolled_um(&self) -> Option<u64> {
        self.left.rolled_um()
    }

    /// The left motor.
    pub fn left(&mut self) -> &mut L {
        &mut self.left
    }

    /// The right motor.
    pub fn right(&mut self) -> &mut R {
        &mut self.right
    }

    /// The motors and the standby pin back.
    pub fn release(self) -> (L, R, S) {
        (self.left, self.right, self.standby)
    }

    fn wake(&mut self) -> Result<(), PinError> {
        self.standby.set_high().map_err(|_| PinError)
    }
}

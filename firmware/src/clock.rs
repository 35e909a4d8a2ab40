//! The arithmetic of the firmware's clock (`time_driver`, built for the target only), apart
//! so that it is tested on the host: a free-running 32-bit down-counter extended to whole
//! ticks and the cycles into the current tick, with no 64-bit division: on a Cortex-M that is
//! a library routine of 0.9 KB, and a sample step, which reads `now()` several times, took
//! 392 cycles more with it (`cargo xtask timing` on mps2-an386 when this module came, 66abcc6:
//! 8,977 against 8,585).

/// The time counted from a 32-bit down-counter of period 2³² at `CYCLES_PER_TICK` cycles a
/// tick (at least 1, at most 2³¹).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Clock<const CYCLES_PER_TICK: u32> {
    /// The counter's value when last read.
    last: u32,
    /// Whole ticks.
    ticks: u64,
    /// Cycles into the current tick, below `CYCLES_PER_TICK`.
    into_tick: u32,
}

impl<const CYCLES_PER_TICK: u32> Clock<CYCLES_PER_TICK> {
    const VALID: () = assert!(CYCLES_PER_TICK >= 1 && CYCLES_PER_TICK <= 1 << 31);

    /// Time 0, with the counter at `value`.
    pub const fn start(value: u32) -> Self {
        let () = Self::VALID;
        Self {
            last: value,
            ticks: 0,
            into_tick: 0,
        }
    }

    /// Whole ticks since the start.
    pub fn ticks(self) -> u64 {
        self.ticks
    }

    /// Cycles since the start.
    pub fn cycles(self) -> u64 {
        self.ticks * u64::from(CYCLES_PER_TICK) + u64::from(self.into_tick)
    }

    /// The clock when the counter reads `value`: at most one period (2³² cycles) after it was
    /// read last. In 32-bit arithmetic; a division by a constant becomes a multiplication.
    #[must_use]
    pub fn advance(self, value: u32) -> Self {
        // A down-counter with a period of 2³²: the wrapping difference is the cycles elapsed.
        let elapsed = self.last.wrapping_sub(value);
        let whole = elapsed / CYCLES_PER_TICK;
        // Both below `CYCLES_PER_TICK`, at most 2³¹: no overflow.
        let part = self.into_tick + elapsed % CYCLES_PER_TICK;
        let carry = part >= CYCLES_PER_TICK;
        Self {
            last: value,
            ticks: self.ticks + u64::from(whole) + u64::from(carry),
            into_tick: if carry { part - CYCLES_PER_TICK } else { part },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Advances a clock of `C` cycles a tick by each of `steps` (cycles elapsed, below 2³²)
    /// from the counter value `first`, and checks it against 64-bit arithmetic at every read.
    fn agrees<const C: u32>(first: u32, steps: &[u32]) {
        let mut clock = Clock::<C>::start(first);
        let (mut value, mut total) = (first, 0_u64);
        for &step in steps {
            value = value.wrapping_sub(step);
            total += u64::from(step);
            clock = clock.advance(value);
            assert_eq!(clock.cycles(), total);
            assert_eq!(clock.ticks(), total / u64::from(C));
        }
    }

    #[test]
    fn wraps_and_tick_boundaries() {
        // Across the counter's wrap, by a whole period less one, and onto tick boundaries.
        agrees::<25_000>(1 << 24, &[1 << 24, 1, u32::MAX, 24_999, 1, 25_000, 0]);
        agrees::<20_000>(0, &[u32::MAX, u32::MAX, 19_999, 19_999, 2]);
        agrees::<1>(5, &[0, 1, u32::MAX]);
        agrees::<{ 1 << 31 }>(0, &[u32::MAX, u32::MAX, 1, 1 << 31]);
    }

    proptest! {
        #[test]
        fn agrees_with_64_bit_division(
            first: u32,
            steps in prop::collection::vec(any::<u32>(), 0..64),
        ) {
            agrees::<25_000>(first, &steps);
            agrees::<20_000>(first, &steps);
            agrees::<7>(first, &steps);
        }
    }
}

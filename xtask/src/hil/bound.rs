//! The response-time bound of a reaction on the bench, from the step costs the bench measured
//! on the emulated RP2040 ([`Costs`]) and [`psmpa_core::timing`]'s analysis.
//!
//! A reaction is timed from the pin edge that shows an obstacle to the motor pins stopping:
//!
//! * **sonar**: from the echo's fall. What is left of the sample after it is one segment (the
//!   edge's interrupt and the sensing poll that measures and delivers), then the behaviour
//!   step that brakes: the analysis of a job of that segment's cost (no read latency),
//!   beside the bumper's job, with sensing preempting deciding.
//! * **bumper**: from the edge after which the switch stays closed. Its next sample is
//!   released within `max(period, debounce)` (its wake-up is held back a debounce time after
//!   the last one; a read in progress that took the edge for a bounce leaves the contact to
//!   the next periodic sample), reads for a debounce time (a read latency) and reacts: that
//!   wait plus the analysis of the bumper's job with the debounce as its read latency.
//!
//! Costs, all measured (the worst over the run, cycles of the 125 MHz clock): a sensing
//! segment is the longest activation of the sensing executor (`SWI_IRQ_1`) plus the longest
//! interrupt that releases one (the alarm `TIMER_IRQ_0`, or `IO_IRQ_BANK0` for an edge). A
//! sample is [`SONAR_SEGMENTS`] or [`BUMPER_SEGMENTS`] of them: every wait of the driver and
//! the runtime (trigger, echo rise, echo fall, the runtime's timeout and period for the
//! sonar; period, debounce, timeout and wake-up for the bumper) may end in one. The deciding
//! side's longest busy stretch in thread mode (between two sleeps, handlers excluded) is both
//! the poll a reaction may wait for and the behaviour step that reacts. A segment may wait for
//! the longest critical section (spinlock 31, embassy-rp's) taken anywhere.

use psmpa_core::timing::{self, Blocking, Job, TimingError};
use psmpa_drivers::switch::DEBOUNCE;
use serde::Serialize;

use super::harness::Stats;

/// The alarm: `TIMER_IRQ_0` (IRQ 0).
pub const EXC_ALARM: u32 = 16;
/// GPIO edges: `IO_IRQ_BANK0` (IRQ 13).
pub const EXC_GPIO: u32 = 16 + 13;
/// The sensing executor: `SWI_IRQ_1` (IRQ 27).
pub const EXC_SENSING: u32 = 16 + 27;

/// Sensing segments of a sonar sample: the period's and the trigger's timers, the echo's
/// rise and fall, the rise's and the pulse's timeouts.
pub const SONAR_SEGMENTS: u64 = 6;
/// Sensing segments of a bumper sample: the period's timer or the wake-up's edge, the
/// wake-up's hold-back, the debounce, the timeout.
pub const BUMPER_SEGMENTS: u64 = 4;

/// Nanoseconds a cycle at 125 MHz.
const NS: u64 = 8;

/// The step costs the bench measured, cycles.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Costs {
    /// The longest activation of the sensing executor.
    pub sensing_poll: u64,
    /// The longest alarm interrupt.
    pub alarm: u64,
    /// The longest GPIO interrupt.
    pub gpio: u64,
    /// The deciding side's longest busy stretch.
    pub deciding: u64,
    /// The longest critical section.
    pub critical: u64,
}

impl Costs {
    /// From the harness's accounts.
    pub fn of(stats: &Stats) -> Self {
        let max = |n| stats.handlers.get(&n).map_or(0, |h| h.max);
        Self {
            sensing_poll: max(EXC_SENSING),
            alarm: max(EXC_ALARM),
            gpio: max(EXC_GPIO),
            deciding: stats.thread.max,
            critical: stats.critical.thread.max(stats.critical.handler),
        }
    }

    fn segment(&self) -> u64 {
        self.sensing_poll + self.alarm.max(self.gpio)
    }
}

/// The sonar's and the bumper's bounds, cycles, for their periods in ms.
pub fn bounds(costs: &Costs, periods_ms: [u64; 2]) -> Result<[u64; 2], TimingError> {
    let seg = costs.segment() * NS;
    let period = |ms: u64| ms.saturating_mul(1_000_000);
    let (sonar_t, bumper_t) = (period(periods_ms[0]), period(periods_ms[1]));
    let debounce = DEBOUNCE.as_micros() * 1_000;
    let blocking = Blocking::preemptive(costs.deciding * NS, costs.critical * NS);
    let reaction = costs.deciding * NS;
    let sonar = Job {
        period_ns: sonar_t,
        cost_ns: SONAR_SEGMENTS * seg,
        latency_ns: 0,
    };
    let bumper = Job {
        period_ns: bumper_t,
        cost_ns: BUMPER_SEGMENTS * seg,
        latency_ns: 0,
    };
    // The sonar after its echo's fall: one segment left.
    let tail = Job {
        cost_ns: seg,
        ..sonar
    };
    let s = timing::response(&[tail, bumper], 0, blocking, reaction)?;
    // The bumper from its settled edge: the wait for a sample, then a read of a debounce time.
    let read = Job {
        latency_ns: debounce,
        ..bumper
    };
    let b = timing::response(&[read, sonar], 0, blocking, reaction)?;
    let wait = bumper_t.max(debounce);
    Ok([
        s.response_ns.div_ceil(NS),
        (wait + b.response_ns).div_ceil(NS),
    ])
}

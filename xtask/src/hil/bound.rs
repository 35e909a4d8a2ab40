//! The response-time bound of a reaction on the bench, from the committed step costs of the
//! emulated RP2040 ([`Budget`]) and [`psmpa_core::timing`]'s analysis.
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
//! Costs come from the committed budget ([`Budget`], `boards/pico/bench-budget.json`), never
//! from the run being judged: `cargo xtask hil --calibrate` measures them once over every
//! shipped scenario and fault and writes the worst of each with a margin; a run whose measured
//! costs exceed the budget fails, and so does one whose reactions exceed the bound computed
//! from it. The deciding side's budget is its step without the planning time a scenario
//! declares (`plan_us`): a scenario's bound adds its own.
//!
//! The costs (cycles of the 125 MHz clock): a sensing segment is the longest activation of the sensing executor (`SWI_IRQ_1`) plus the longest
//! interrupt that releases one (the alarm `TIMER_IRQ_0`, or `IO_IRQ_BANK0` for an edge). A
//! sample is [`SONAR_SEGMENTS`] or [`BUMPER_SEGMENTS`] of them: every wait of the driver and
//! the runtime (trigger, echo rise, echo fall, the runtime's timeout and period for the
//! sonar; period, debounce, timeout and wake-up for the bumper) may end in one. The deciding
//! side's longest busy stretch in thread mode (between two sleeps, handlers excluded) is both
//! the poll a reaction may wait for and the behaviour step that reacts. A segment may wait for
//! the longest critical section (spinlock 31, embassy-rp's) taken anywhere.

use psmpa_core::timing::{self, Blocking, Job, TimingError};
use psmpa_drivers::switch::DEBOUNCE;
use serde::{Deserialize, Serialize};

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

/// Step costs, cycles.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
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
    /// The longest poll of the control task, its own cycles (handlers excluded): the job
    /// `cargo xtask wcet` bounds as "deciding" (a busy stretch is this poll and the other
    /// tasks' and the executor's between two sleeps).
    #[serde(default)]
    pub control_poll: u64,
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
            control_poll: control_polls(&stats.calls),
        }
    }

    /// A sensing segment: the longest sensing poll and the interrupt that released it.
    pub fn segment(&self) -> u64 {
        self.sensing_poll.saturating_add(self.alarm.max(self.gpio))
    }

    /// These costs with `plan` cycles of declared planning added to the deciding step.
    pub fn with_plan(self, plan: u64) -> Self {
        Self {
            deciding: self.deciding.saturating_add(plan),
            ..self
        }
    }

    /// Each cost, by name.
    pub fn named(&self) -> [(&'static str, u64); 6] {
        [
            ("sensing_poll", self.sensing_poll),
            ("alarm", self.alarm),
            ("gpio", self.gpio),
            ("deciding", self.deciding),
            ("critical", self.critical),
            ("control_poll", self.control_poll),
        ]
    }

    /// The worst of both, cost by cost.
    pub fn max(self, other: Self) -> Self {
        Self {
            sensing_poll: self.sensing_poll.max(other.sensing_poll),
            alarm: self.alarm.max(other.alarm),
            gpio: self.gpio.max(other.gpio),
            deciding: self.deciding.max(other.deciding),
            critical: self.critical.max(other.critical),
            control_poll: self.control_poll.max(other.control_poll),
        }
    }

    /// Each cost with `percent` more (rounded up), or [`MARGIN_CYCLES`] more, whichever is
    /// more; `None` when a cost is beyond [`MAX_COST`] or the margin beyond 100 %.
    pub fn with_margin(self, percent: u64) -> Option<Self> {
        if percent > 100 {
            return None;
        }
        let up = |c: u64| {
            (c <= MAX_COST).then(|| (c * (100 + percent)).div_ceil(100).max(c + MARGIN_CYCLES))
        };
        Some(Self {
            sensing_poll: up(self.sensing_poll)?,
            alarm: up(self.alarm)?,
            gpio: up(self.gpio)?,
            deciding: up(self.deciding)?,
            critical: up(self.critical)?,
            control_poll: up(self.control_poll)?,
        })
    }

    /// The costs of these that exceed `budget`'s, in words.
    pub fn over(&self, budget: &Self) -> Vec<String> {
        self.named()
            .iter()
            .zip(budget.named())
            .filter(|((_, c), (_, b))| c > b)
            .map(|((name, c), (_, b))| {
                format!("the {name} cost of {c} cycles exceeds its budget of {b} cycles")
            })
            .collect()
    }
}

/// The longest poll of the control task among the harness's timed `calls` (in the order they
/// returned), without the declared planning time it waited out inside (the busy waits that
/// returned since the poll before it): a scenario declares that time, and the bounds add it.
pub(super) fn control_polls(calls: &[(usize, u64)]) -> u64 {
    let mut waited = 0u64;
    let mut worst = 0;
    for &(i, cycles) in calls {
        if i == super::COMPUTE {
            waited = waited.saturating_add(cycles);
        } else if i == super::CONTROL_POLL {
            worst = worst.max(cycles.saturating_sub(waited));
            waited = 0;
        }
    }
    worst
}

/// Cycles of the 125 MHz clock in `us` microseconds: a scenario's declared planning time.
pub fn cycles_of_us(us: u64) -> u64 {
    us.saturating_mul(1_000) / NS
}

/// Microseconds of `cycles` of the 125 MHz clock: how the decisions' cycles are shown.
pub fn us_of_cycles(cycles: u64) -> f64 {
    cycles.saturating_mul(NS) as f64 / 1_000.0
}

/// The committed cost budget of the Pico's image (`boards/pico/bench-budget.json`).
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Budget {
    /// What the file is.
    pub about: String,
    /// The margin over the worst measured, percent (and at least [`MARGIN_CYCLES`]).
    pub margin_percent: u64,
    /// The worst of each cost over the calibration's runs (the deciding step without the
    /// scenarios' declared planning).
    pub measured: Costs,
    /// The budget: `measured` with the margin, rounded up.
    pub budget: Costs,
}

/// The margin a calibration adds to the worst measured costs, percent.
pub const MARGIN_PERCENT: u64 = 25;
/// The most a measured cost may be, cycles: a second at 125 MHz, far beyond any step of the
/// firmware (its deciding step with a plan is a few ms), and far from overflowing the
/// bound's arithmetic.
pub const MAX_COST: u64 = 125_000_000;
/// The least margin of any cost, cycles (8 µs): a handler of a few hundred cycles takes paths
/// of different lengths (one alarm or two due, an edge or none) that a quarter of it does not
/// cover. Found on a scenario the project does not ship: an alarm of 744 cycles where the
/// shipped ones measured at most 457.
pub const MARGIN_CYCLES: u64 = 1_000;

impl Budget {
    /// The file.
    pub fn path() -> std::path::PathBuf {
        crate::firmware::root().join("boards/pico/bench-budget.json")
    }

    /// Reads the committed budget.
    pub fn load() -> Result<Self, String> {
        let path = Self::path();
        let text = psmpa_sim::cli::files::read_input(&path, "budget")
            .map_err(|e| format!("{e} (cargo xtask hil --calibrate writes it)"))?;
        Self::parse(&path, &text)
    }

    /// The budget file `path`'s bytes, checked.
    pub fn parse(path: &std::path::Path, bytes: &[u8]) -> Result<Self, String> {
        // Strict JSON first: a byte order mark, bad UTF-8, a duplicate key named as such.
        let text = psmpa_sim::json::strict_file(path, bytes)?;
        let budget: Self =
            serde_json::from_slice(&text).map_err(|e| format!("{}: {e}", path.display()))?;
        budget
            .check()
            .map_err(|e| format!("{}: {e}", path.display()))?;
        Ok(budget)
    }

    /// Whether the budget is its measured costs with its margin, as a calibration writes it.
    pub fn check(&self) -> Result<(), String> {
        if self.margin_percent != MARGIN_PERCENT {
            return Err(format!(
                "margin_percent {}: a calibration writes {MARGIN_PERCENT} %: write it with cargo xtask hil --calibrate",
                self.margin_percent
            ));
        }
        for (name, c) in self.measured.named().iter().chain(&self.budget.named()) {
            if *c > MAX_COST {
                return Err(format!(
                    "the {name} cost of {c} cycles is beyond any step of the firmware (at most {MAX_COST}, a second): write it with cargo xtask hil --calibrate"
                ));
            }
        }
        if Some(self.budget) == self.measured.with_margin(self.margin_percent) {
            Ok(())
        } else {
            Err(format!(
                "its budget is not its measured costs with a {} % margin: write it with cargo xtask hil --calibrate",
                self.margin_percent
            ))
        }
    }

    /// The budget of `measured`, the worst costs of a calibration.
    pub fn of(measured: Costs) -> Result<Self, String> {
        let budget = measured.with_margin(MARGIN_PERCENT).ok_or_else(|| {
            format!("a measured cost is beyond {MAX_COST} cycles (a second): {measured:?}")
        })?;
        Ok(Self {
            about: "Worst step costs of the Pico's image (cycles at 125 MHz) over every shipped bench scenario and fault, and the budget the bench judges by: written by cargo xtask hil --calibrate, never by hand".to_owned(),
            margin_percent: MARGIN_PERCENT,
            measured,
            budget,
        })
    }

    /// The sonar's timing error a sensing segment of the budget may cause, mm: an edge served
    /// that much late moves the reading by 0.1715 mm a microsecond; one more for rounding.
    pub fn tolerance_mm(&self) -> u32 {
        let ns = self.budget.segment().saturating_mul(NS);
        u32::try_from(ns.saturating_mul(343).div_ceil(2_000_000) + 1).unwrap_or(u32::MAX)
    }
}

/// The sonar's and the bumper's bounds, cycles, for their periods in ms.
pub fn bounds(costs: &Costs, periods_ms: [u64; 2]) -> Result<[u64; 2], TimingError> {
    // Saturating: costs beyond any step (a static bound of an absurd annotation) make an
    // unschedulable set, not an overflow.
    let seg = costs.segment().saturating_mul(NS);
    let period = |ms: u64| ms.saturating_mul(1_000_000);
    let (sonar_t, bumper_t) = (period(periods_ms[0]), period(periods_ms[1]));
    let debounce = DEBOUNCE.as_micros() * 1_000;
    let blocking = Blocking::preemptive(
        costs.deciding.saturating_mul(NS),
        costs.critical.saturating_mul(NS),
    );
    let reaction = costs.deciding.saturating_mul(NS);
    let sonar = Job {
        period_ns: sonar_t,
        cost_ns: SONAR_SEGMENTS.saturating_mul(seg),
        latency_ns: 0,
    };
    let bumper = Job {
        period_ns: bumper_t,
        cost_ns: BUMPER_SEGMENTS.saturating_mul(seg),
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
        wait.saturating_add(b.response_ns).div_ceil(NS),
    ])
}

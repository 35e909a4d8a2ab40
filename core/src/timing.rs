//! Response-time analysis of the runtime: how late a sample can be, and how long after an
//! obstacle appears the acting can react to it.
//!
//! The model is the one the runtime runs ([`crate::runtime`], [`crate::runtime::sensing`]). Each cyclic
//! sensor `i` is a periodic job: released every `Tᵢ`, it costs `Cᵢ` of processor time on the
//! sensing side (starting the read, then delivering it: store, fuse, check, wake) and waits
//! `Lᵢ` for its read between the two (an echo, a conversion: no processor time; other work
//! runs meanwhile). Interrupt handlers that release work (a timer's alarm) are jobs too, of
//! the highest priority. The deciding side then reacts in one behaviour step of cost `C_b`.
//! The worst response, from release to the behaviour having reacted, has two parts, each the
//! least fixed point of its equation:
//!
//! * the sample, from release to delivery, which sees only the other sensing jobs and the
//!   interrupts (sensing jobs share a priority, so any released meanwhile may run first):
//!   `Sᵢ = nᵢ·b + Lᵢ + Cᵢ + Σⱼ≠ᵢ ⌈Sᵢ / Tⱼ⌉ · Cⱼ`
//! * the reaction, from delivery to the end of the behaviour step, which sees everything,
//!   this sensor's next samples included: `Aᵢ = a + C_b + Σⱼ ⌈Aᵢ / Tⱼ⌉ · Cⱼ`
//!
//! and `Rᵢ = Sᵢ + Aᵢ`. `nᵢ` is the number of processor segments of a sample (1 without a read
//! latency, 2 with one); the blocking terms `b` (per segment) and `a` (before the reaction)
//! come from where the two sides run ([`Blocking`]):
//!
//! * one executor, sensing polled first ([`Blocking::one_executor`]): each segment may wait
//!   for the deciding poll in progress, `b = B`; the behaviour step is the next deciding poll,
//!   `a = 0`;
//! * sensing on an executor that preempts deciding ([`Blocking::preemptive`]): a segment waits
//!   at most for a critical section the deciding side is in, `b = B_cs`; the behaviour step
//!   waits for the deciding poll in progress, `a = B`.
//!
//! The set is unschedulable when the utilisation `Σ Cⱼ / Tⱼ` reaches 1, and overloaded when a
//! sample's processor time, blocking and interference, `Sᵢ − Lᵢ`, exceed its period. A read
//! longer than the period is not an overload: the sampler skips the instants it overran, so
//! samples start at most [`Response::gap_ns`] apart.
//!
//! The reaction latency to an obstacle seen by sensor `i` adds the wait for the sample that
//! sees it: [`latency_bound`].
//!
//! Integer nanoseconds throughout; every function is O(jobs) per iteration, and the iteration
//! ends when the utilisation is below 1.

/// A periodic job: a cyclic sensor's sample and the behaviour step it wakes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Job {
    /// Release period, ns.
    pub period_ns: u64,
    /// Worst processor time of one release on the sensing side, ns.
    pub cost_ns: u64,
    /// Worst time a read waits for its device, ns (no processor time).
    pub latency_ns: u64,
}

/// What a released sample, and the behaviour step it wakes, can be kept waiting by.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Blocking {
    /// Before each processor segment of a sample, ns.
    pub per_segment_ns: u64,
    /// Before the behaviour step that reacts, ns.
    pub before_reaction_ns: u64,
}

impl Blocking {
    /// No blocking at all (virtual time, where computing takes none).
    pub const NONE: Self = Self {
        per_segment_ns: 0,
        before_reaction_ns: 0,
    };

    /// Sensing and deciding on one executor, sensing polled first; `longest_deciding_ns` is the
    /// longest poll of the deciding side.
    pub const fn one_executor(longest_deciding_ns: u64) -> Self {
        Self {
            per_segment_ns: longest_deciding_ns,
            before_reaction_ns: 0,
        }
    }

    /// Sensing on an executor that preempts the deciding side: a sample waits at most for the
    /// longest critical section entered below its priority, the reaction for the longest
    /// deciding poll.
    pub const fn preemptive(longest_deciding_ns: u64, longest_critical_ns: u64) -> Self {
        Self {
            per_segment_ns: longest_critical_ns,
            before_reaction_ns: longest_deciding_ns,
        }
    }
}

/// The worst case of one sampling job.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Response {
    /// From a release to the sample's delivery, ns: `Sᵢ`.
    pub sample_ns: u64,
    /// From a release to the behaviour step it wakes having run, ns: `Rᵢ = Sᵢ + Aᵢ`.
    pub response_ns: u64,
    /// The longest time between the starts of two samples, ns: the period, or a multiple of it
    /// when a sample can outlast the period.
    pub gap_ns: u64,
}

/// Why a job set has no bound.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TimingError {
    /// The jobs need the whole processor or more: `Σ C/T ≥ 1`.
    Unschedulable {
        /// `Σ C/T` in parts per million, rounded up.
        utilisation_ppm: u64,
    },
    /// Job `job`'s processor time and blocking exceed its period.
    Overrun {
        /// Index of the job.
        job: usize,
        /// Its response time so far, ns.
        response_ns: u64,
        /// Its period, ns.
        period_ns: u64,
    },
    /// A job with period 0, or an index out of range.
    BadJob {
        /// Index of the job.
        job: usize,
    },
}

impl core::fmt::Display for TimingError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Unschedulable { utilisation_ppm } => write!(
                f,
                "unschedulable: the jobs need {}.{:04} of the processor",
                utilisation_ppm / 1_000_000,
                utilisation_ppm % 1_000_000 / 100
            ),
            Self::Overrun {
                job,
                response_ns,
                period_ns,
            } => write!(
                f,
                "unschedulable: job {job} may take {response_ns} ns, more processor time than its period of {period_ns} ns"
            ),
            Self::BadJob { job } => write!(f, "job {job} has no period"),
        }
    }
}

impl core::error::Error for TimingError {}

/// `Σ C/T` in parts per million, rounded up per job. O(jobs).
pub fn utilisation_ppm(jobs: &[Job]) -> Result<u64, TimingError> {
    jobs.iter().enumerate().try_fold(0u64, |acc, (i, j)| {
        let share = j
            .cost_ns
            .saturating_mul(1_000_000)
            .checked_div(j.period_ns)
            .ok_or(TimingError::BadJob { job: i })?;
        // Round up: a share that does not divide evenly is a little more, never less.
        let exact = share.saturating_mul(j.period_ns) == j.cost_ns.saturating_mul(1_000_000);
        Ok(acc.saturating_add(share).saturating_add(u64::from(!exact)))
    })
}

/// The least fixed point of `R = base + Σ ⌈R / Tⱼ⌉ · Cⱼ` over the jobs `interferes` keeps,
/// or the first `R` that `overrun` refuses. The utilisation is below 1, so it exists.
fn fixed_point(
    jobs: &[Job],
    base: u64,
    interferes: impl Fn(usize) -> bool,
    overrun: impl Fn(u64) -> Result<(), TimingError>,
) -> Result<u64, TimingError> {
    let mut r = base;
    loop {
        overrun(r)?;
        let interference = jobs
            .iter()
            .enumerate()
            .filter(|(j, _)| interferes(*j))
            .fold(0u64, |acc, (_, other)| {
                // Periods are not zero: `utilisation_ppm` checked them.
                let releases = r.div_ceil(other.period_ns.max(1));
                acc.saturating_add(releases.saturating_mul(other.cost_ns))
            });
        let next = base.saturating_add(interference);
        if next == r {
            return Ok(r);
        }
        r = next;
    }
}

/// The worst response of job `i`: from its release to its delivery, and on to the end of the
/// behaviour step of cost `reaction_ns` it wakes; and the longest gap between the starts of
/// two of its samples. Every other job interferes with the sample; every job, `i` included,
/// with the reaction.
///
/// Errors when the set needs the whole processor, or when the sample's processor time,
/// blocking and interference exceed its period.
pub fn response(
    jobs: &[Job],
    i: usize,
    blocking: Blocking,
    reaction_ns: u64,
) -> Result<Response, TimingError> {
    let job = jobs.get(i).ok_or(TimingError::BadJob { job: i })?;
    let utilisation_ppm = utilisation_ppm(jobs)?;
    if utilisation_ppm >= 1_000_000 {
        return Err(TimingError::Unschedulable { utilisation_ppm });
    }
    let segments = if job.latency_ns > 0 { 2 } else { 1 };
    let sample_base = blocking
        .per_segment_ns
        .saturating_mul(segments)
        .saturating_add(job.latency_ns)
        .saturating_add(job.cost_ns);
    let sample = fixed_point(
        jobs,
        sample_base,
        |j| j != i,
        |r| match r.saturating_sub(job.latency_ns) > job.period_ns {
            true => Err(TimingError::Overrun {
                job: i,
                response_ns: r,
                period_ns: job.period_ns,
            }),
            false => Ok(()),
        },
    )?;
    let reaction_base = blocking.before_reaction_ns.saturating_add(reaction_ns);
    let reaction = fixed_point(jobs, reaction_base, |_| true, |_| Ok(()))?;
    // A sample that can outlast its period skips the instants it overran.
    let periods = sample.div_ceil(job.period_ns.max(1)).max(1);
    Ok(Response {
        sample_ns: sample,
        response_ns: sample.saturating_add(reaction),
        gap_ns: periods.saturating_mul(job.period_ns),
    })
}

/// The longest time from an obstacle becoming certain to register (its distance beyond
/// doubt, `margin_ns` after it first could) to the behaviour having reacted, ns:
///
/// `margin + max_lost · G + R`
///
/// A sample starts within one gap `G` (the period, see [`Response::gap_ns`]) after the
/// obstacle. A lost sample delays the detection by a gap; the runtime tolerates
/// `max_lost - 1` in a row and fails safe at the next (the robot stops), so the detecting
/// sample is at most the `max_lost`-th. Its read, its delivery and the behaviour's reaction
/// finish within the response time `R`. O(1).
pub fn latency_bound(response: Response, max_lost: u8, margin_ns: u64) -> u64 {
    margin_ns
        .saturating_add(response.gap_ns.saturating_mul(u64::from(max_lost.max(1))))
        .saturating_add(response.response_ns)
}

/// The ticks `ms` milliseconds take at a tick rate of `hz`: rounded up, as
/// `embassy_time::Duration::from_millis` rounds them (at 10 Hz, 20 ms is 1 tick: 100 ms).
pub const fn ms_in_ticks(ms: u64, hz: u64) -> u128 {
    (ms as u128).saturating_mul(hz as u128).div_ceil(1000)
}

/// Whether `ms` milliseconds at a tick rate of `hz` come out within 1 % of themselves (a whole
/// number of ticks at most 1 % longer; never shorter). `include_mission!` refuses a mission
/// with a period or a timeout that does not, at the crate's `embassy_time::TICK_HZ`.
pub const fn ms_represented(ms: u64, hz: u64) -> bool {
    // ticks / hz <= ms / 1000 · 1.01, in integers.
    let exact = (ms as u128).saturating_mul(hz as u128);
    ms_in_ticks(ms, hz).saturating_mul(100_000) <= exact.saturating_mul(101)
}

/// What `include_mission!` emits for each period or timeout of a mission: a build-time check
/// that the crate's tick rate represents it within 1 %, failing the build with a message
/// naming the value and the rate (`docs/guide.md`, "Milliseconds and ticks").
#[doc(hidden)]
#[macro_export]
macro_rules! __tick_rate_check {
    ($what:literal, $ms:literal) => {
        const _: () = if !$crate::timing::ms_represented($ms, $crate::embassy_time::TICK_HZ) {
            $crate::__tick_rate_panic!(
                $what,
                (1, "1"),
                (2, "2"),
                (4, "4"),
                (8, "8"),
                (10, "10"),
                (16, "16"),
                (32, "32"),
                (64, "64"),
                (100, "100"),
                (128, "128"),
                (256, "256"),
                (512, "512"),
                (1_024, "1_024"),
                (2_048, "2_048"),
                (4_096, "4_096"),
                (8_192, "8_192"),
                (16_384, "16_384"),
                (32_768, "32_768")
            )
        };
    };
}

#[doc(hidden)]
#[macro_export]
macro_rules! __tick_rate_panic {
    ($what:literal, $(($hz:literal, $name:literal)),*) => {
        match $crate::embassy_time::TICK_HZ {
            $($hz => panic!(concat!(
                $what,
                " is not within 1 % of a whole number of ticks at embassy-time's tick-hz-",
                $name,
                " (a duration rounds up to whole ticks): choose a multiple of the tick, or a faster tick rate"
            )),)*
            _ => panic!(concat!(
                $what,
                " is not within 1 % of a whole number of ticks at this crate's embassy-time tick rate (a duration rounds up to whole ticks): choose a multiple of the tick, or a faster tick rate"
            )),
        }
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn milliseconds_round_up_to_ticks_and_a_percent_off_is_refused() {
        // 20 ms at 10 Hz is one tick, 100 ms.
        assert_eq!(ms_in_ticks(20, 10), 1);
        assert!(!ms_represented(20, 10));
        assert!(ms_represented(100, 10) && ms_represented(20, 1_000));
        // 1,024 Hz: 1 ms is 2 ticks (1.95 ms); 100 ms is 103 ticks (100.6 ms, within 1 %).
        assert!(!ms_represented(1, 1_024) && ms_represented(100, 1_024));
        // 32,768 Hz: 1 ms is 33 ticks, 0.7 % long.
        assert!(ms_represented(1, 32_768));
        // The largest values do not overflow.
        assert!(ms_represented(u64::from(u32::MAX), 5_242_880_000));
    }

    fn job(period_ms: u64, cost_ns: u64, latency_ms: u64) -> Job {
        Job {
            period_ns: period_ms * MS,
            cost_ns,
            latency_ns: latency_ms * MS,
        }
    }

    #[test]
    fn response_time_is_the_least_fixed_point() {
        // C = 0.5, 1, 1 ms every 4, 6, 10 ms; one executor, longest deciding poll 0.5 ms; a
        // behaviour step of 0 ms.
        let jobs = [job(4, MS / 2, 0), job(6, MS, 0), job(10, MS, 0)];
        let one = Blocking::one_executor(MS / 2);
        // S = 0.5 + 0.5 = 1 → 1 + ⌈1/6⌉·1 + ⌈1/10⌉·1 = 3 → 3 (⌈3/6⌉ = ⌈3/10⌉ = 1); a
        // reaction of 0 sees no release: A = 0.
        let r = response(&jobs, 0, one, 0).unwrap();
        assert_eq!(
            r,
            Response {
                sample_ns: 3 * MS,
                response_ns: 3 * MS,
                gap_ns: 4 * MS
            }
        );
        // R₂ = 0.5 + 1 = 1.5 → + ⌈1.5/4⌉·0.5 + ⌈1.5/6⌉·1 = 3 → 3.
        assert_eq!(response(&jobs, 2, one, 0).unwrap().response_ns, 3 * MS);
        // More blocking, more interference: R₀ = 3 + 0.5 = 3.5 → + 1 + 1 = 5.5 > 4.
        assert_eq!(
            response(&jobs, 0, Blocking::one_executor(3 * MS), 0),
            Err(TimingError::Overrun {
                job: 0,
                response_ns: 5_500_000,
                period_ns: 4 * MS,
            })
        );
    }

    #[test]
    fn a_read_latency_adds_its_wait_and_a_second_blocked_segment() {
        // A 100 ms sonar whose read takes 40 ms beside a 20 ms bumper; 0.3 ms per sample,
        // longest deciding poll 1 ms, behaviour step 0.2 ms.
        let jobs = [job(100, 300_000, 40), job(20, 300_000, 0)];
        let reaction = 200_000;
        // One executor: the sonar's read start and its delivery may each wait for a deciding
        // poll. S = 2·1 + 40 + 0.3 = 42.3 → + ⌈42.3/20⌉·0.3 = 43.2 → 43.2. The reaction sees
        // both sensors: A = 0.2 → + 0.3 + 0.3 = 0.8 → 0.8. R = 44.
        let r = response(&jobs, 0, Blocking::one_executor(MS), reaction).unwrap();
        assert_eq!((r.sample_ns, r.response_ns), (43_200_000, 44 * MS));
        assert_eq!(r.gap_ns, 100 * MS);
        // The bumper reads at once: one segment, one blocking. S = 1 + 0.3 → + 0.3 = 1.6.
        let b = response(&jobs, 1, Blocking::one_executor(MS), reaction).unwrap();
        assert_eq!((b.sample_ns, b.response_ns), (1_600_000, 2_400_000));
        // Sensing preempting deciding, critical sections of 0.05 ms: a segment waits for one,
        // the behaviour step for a deciding poll. S = 2·0.05 + 40 + 0.3 = 40.4 → + 0.9 = 41.3;
        // A = 1 + 0.2 = 1.2 → + 0.3 + 0.3 = 1.8. R = 43.1.
        let p = response(&jobs, 0, Blocking::preemptive(MS, 50_000), reaction).unwrap();
        assert_eq!((p.sample_ns, p.response_ns), (41_300_000, 43_100_000));
        // A long deciding poll no longer overruns a sample: 30 ms beside a 20 ms bumper is an
        // overrun on one executor, a slower reaction when sensing preempts.
        assert!(matches!(
            response(&jobs, 1, Blocking::one_executor(30 * MS), reaction),
            Err(TimingError::Overrun { job: 1, .. })
        ));
        let long = response(&jobs, 1, Blocking::preemptive(30 * MS, 0), reaction).unwrap();
        // S = 0.3 → + 0.3 = 0.6. A = 30.2 → + ⌈30.2/100⌉·0.3 + ⌈30.2/20⌉·0.3 = 31.1 → 31.1.
        assert_eq!((long.sample_ns, long.response_ns), (600_000, 31_700_000));
        // A read longer than the period is no overload: every second instant is skipped.
        let slow = [job(100, 300_000, 150)];
        let s = response(&slow, 0, Blocking::NONE, 0).unwrap();
        assert_eq!(
            s,
            Response {
                sample_ns: 150_300_000,
                response_ns: 150_300_000,
                gap_ns: 200 * MS
            }
        );
    }

    #[test]
    fn an_overloaded_set_is_refused_loudly() {
        let jobs = [job(10, 6 * MS, 0), job(20, 9 * MS, 0)];
        assert_eq!(utilisation_ppm(&jobs), Ok(1_050_000));
        let err = response(&jobs, 0, Blocking::NONE, 0).unwrap_err();
        assert_eq!(
            err,
            TimingError::Unschedulable {
                utilisation_ppm: 1_050_000
            }
        );
        assert_eq!(
            std::format!("{err}"),
            "unschedulable: the jobs need 1.0500 of the processor"
        );
        // Exactly full is unschedulable too; a share that does not divide rounds up.
        let full = [Job {
            period_ns: 3,
            cost_ns: 3,
            latency_ns: 0,
        }];
        assert!(response(&full, 0, Blocking::NONE, 0).is_err());
        let third = [Job {
            period_ns: 3,
            cost_ns: 1,
            latency_ns: 0,
        }];
        assert_eq!(utilisation_ppm(&third), Ok(333_334));
    }

    #[test]
    fn a_zero_period_or_a_missing_job_is_an_error_not_a_division_by_zero() {
        let jobs = [Job {
            period_ns: 0,
            cost_ns: 1,
            latency_ns: 0,
        }];
        assert_eq!(utilisation_ppm(&jobs), Err(TimingError::BadJob { job: 0 }));
        assert_eq!(
            response(&jobs[..0], 0, Blocking::NONE, 0),
            Err(TimingError::BadJob { job: 0 })
        );
    }

    #[test]
    fn latency_adds_the_wait_for_the_detecting_sample() {
        // 100 ms gap, up to 9 lost samples tolerated, 2 ms response, 30 ms margin.
        let r = Response {
            sample_ns: MS,
            response_ns: 2 * MS,
            gap_ns: 100 * MS,
        };
        assert_eq!(latency_bound(r, 10, 30 * MS), 1032 * MS);
        // max_lost 0 still waits for one sample.
        let r = Response {
            sample_ns: 0,
            response_ns: 0,
            gap_ns: 100 * MS,
        };
        assert_eq!(latency_bound(r, 0, 0), 100 * MS);
    }
}

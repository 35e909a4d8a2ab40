//! Response-time analysis of the runtime: how late a sample can be, and how long after an
//! obstacle appears the acting can react to it.
//!
//! The model is the one the runtime runs: a single embassy task polls the parallel state,
//! cooperatively. Each cyclic sensor is a periodic job `i` (period `Tᵢ`, worst cost `Cᵢ`: the
//! sample step and the behaviour step it wakes). A job cannot start while another poll runs,
//! so it is blocked by at most the longest poll `B`, and every other job released meanwhile
//! may run first. The worst response time is the least fixed point of
//!
//! `Rᵢ = B + Cᵢ + Σⱼ≠ᵢ ⌈Rᵢ / Tⱼ⌉ · Cⱼ`
//!
//! (non-preemptive, no priorities: the conservative reading of a FIFO run queue). A job
//! whose response time exceeds its period would delay its own next release: the set is then
//! unschedulable, and so it is when the utilisation `Σ Cⱼ / Tⱼ` reaches 1.
//!
//! The reaction latency to an obstacle seen by sensor `i` adds the wait for the sample that
//! sees it: [`latency_bound`].
//!
//! Integer nanoseconds throughout; every function is O(jobs) per iteration and iterates at
//! most `Tᵢ / min Cⱼ` times.

/// A periodic job: a cyclic sensor's sampling step and the behaviour step it wakes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Job {
    /// Release period, ns.
    pub period_ns: u64,
    /// Worst cost of one release, ns.
    pub cost_ns: u64,
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
    /// Job `job` may still run when it is released again.
    Overrun {
        /// Index of the job.
        job: usize,
        /// Its response time so far (already beyond its period), ns.
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
                "unschedulable: job {job} may take {response_ns} ns, longer than its period of {period_ns} ns"
            ),
            Self::BadJob { job } => write!(f, "job {job} has no period"),
        }
    }
}

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

/// The worst response time of job `i`, ns: from its release to the end of the behaviour step
/// it wakes, with `blocking_ns` the longest poll that may be running when it is released.
///
/// Errors when the set needs the whole processor, or when the response time exceeds the job's
/// period (it would be released again before it finishes).
pub fn response_time(jobs: &[Job], i: usize, blocking_ns: u64) -> Result<u64, TimingError> {
    let job = jobs.get(i).ok_or(TimingError::BadJob { job: i })?;
    let utilisation_ppm = utilisation_ppm(jobs)?;
    if utilisation_ppm >= 1_000_000 {
        return Err(TimingError::Unschedulable { utilisation_ppm });
    }
    let base = blocking_ns.saturating_add(job.cost_ns);
    let mut r = base;
    loop {
        if r > job.period_ns {
            return Err(TimingError::Overrun {
                job: i,
                response_ns: r,
                period_ns: job.period_ns,
            });
        }
        let interference =
            jobs.iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
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

/// The longest time from an obstacle becoming certain to register (its distance beyond
/// doubt, `margin_ns` after it first could) to the behaviour having reacted, ns:
///
/// `margin + max_lost · T + R`
///
/// The first release after the obstacle comes within one period `T`. A lost sample delays
/// the detection by a period; the runtime tolerates `max_lost - 1` in a row and fails safe at
/// the next (the robot stops), so the detecting sample is at most the `max_lost`-th release.
/// Its processing and the behaviour's reaction finish within the response time `R`. O(1).
pub fn latency_bound(period_ns: u64, max_lost: u8, response_ns: u64, margin_ns: u64) -> u64 {
    margin_ns
        .saturating_add(period_ns.saturating_mul(u64::from(max_lost.max(1))))
        .saturating_add(response_ns)
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn response_time_is_the_least_fixed_point() {
        // C = 0.5, 1, 1 ms every 4, 6, 10 ms, blocking 0.5 ms:
        // R₀ = B + C₀ + ⌈R₀/6⌉·1 + ⌈R₀/10⌉·1, iterated from B + C₀.
        let jobs = [
            Job {
                period_ns: 4 * MS,
                cost_ns: MS / 2,
            },
            Job {
                period_ns: 6 * MS,
                cost_ns: MS,
            },
            Job {
                period_ns: 10 * MS,
                cost_ns: MS,
            },
        ];
        // R = 0.5 + 0.5 = 1 → 1 + 1 + 1 = 3 → 3 (⌈3/6⌉ = ⌈3/10⌉ = 1).
        assert_eq!(response_time(&jobs, 0, MS / 2), Ok(3 * MS));
        // R₂ = 0.5 + 1 = 1.5 → + ⌈1.5/4⌉·0.5 + ⌈1.5/6⌉·1 = 3 → 3 (⌈3/4⌉ = 1, ⌈3/6⌉ = 1).
        assert_eq!(response_time(&jobs, 2, MS / 2), Ok(3 * MS));
        // More blocking, more interference: R₀ = 3 + 0.5 = 3.5 → + 1 + 1 = 5.5 → 5.5.
        assert_eq!(
            response_time(&jobs, 0, 3 * MS),
            Err(TimingError::Overrun {
                job: 0,
                response_ns: 5_500_000,
                period_ns: 4 * MS,
            })
        );
    }

    #[test]
    fn an_overloaded_set_is_refused_loudly() {
        let jobs = [
            Job {
                period_ns: 10 * MS,
                cost_ns: 6 * MS,
            },
            Job {
                period_ns: 20 * MS,
                cost_ns: 9 * MS,
            },
        ];
        assert_eq!(utilisation_ppm(&jobs), Ok(1_050_000));
        let err = response_time(&jobs, 0, 0).unwrap_err();
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
        }];
        assert!(response_time(&full, 0, 0).is_err());
        assert_eq!(
            utilisation_ppm(&[Job {
                period_ns: 3,
                cost_ns: 1
            }]),
            Ok(333_334)
        );
    }

    #[test]
    fn a_zero_period_or_a_missing_job_is_an_error_not_a_division_by_zero() {
        let jobs = [Job {
            period_ns: 0,
            cost_ns: 1,
        }];
        assert_eq!(utilisation_ppm(&jobs), Err(TimingError::BadJob { job: 0 }));
        assert_eq!(
            response_time(&jobs[..0], 0, 0),
            Err(TimingError::BadJob { job: 0 })
        );
    }

    #[test]
    fn latency_adds_the_wait_for_the_detecting_sample() {
        // 100 ms sonar, up to 9 lost samples tolerated, 2 ms response, 30 ms margin.
        assert_eq!(latency_bound(100 * MS, 10, 2 * MS, 30 * MS), 1032 * MS);
        // max_lost 0 still waits for one sample.
        assert_eq!(latency_bound(100 * MS, 0, 0, 0), 100 * MS);
    }
}

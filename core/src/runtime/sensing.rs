//! The sensing side of the runtime (the paper's sensory controller): every sensor samples on
//! its own, above the deciding side.
//!
//! [`SensingSide::run`](crate::SensingSide::run) runs one *sampler* per sensor of the mission
//! ([`Mission::sensing`]): a compiled mission's are each specialised
//! for their sensor ([`SensorSpec`]: one machine code a sensor, no branch for the modes it
//! lacks), a run-time mission's read their sensor from the tables. A sampler waits until the
//! deciding side commands its sensor (a state that needs it started: least commitment), then
//! switches it on and samples it:
//!
//! * cyclic: at `start`, `start + T`, `start + 2T`, ... (`T` the mission's period, or the one
//!   [`Runtime::set_period`](crate::Runtime::set_period) gave). The next instant follows from
//!   the previous *due* instant, not from when the sample finished, so the phase is kept; an
//!   instant that passed while a slow read was still running is skipped, so one sensor never
//!   samples twice at one instant and never queues up a backlog;
//! * one-shot: once, at the start of the state (under SMPA, of its first sense phase);
//! * on demand: whenever the running behaviour asks ([`ActionIo::request`](crate::ActionIo::request)).
//!
//! A sample's read is bounded by the sensor's timeout and awaits only that sensor's I/O:
//! another sensor's read time, timeout, loss or fault never moves this sensor's instants, and
//! nothing on the deciding side waits for a read. Its result is *delivered* in one step:
//!
//! 1. the value and the sensor's own `(k', v')` pairs go into the sensor's store, stamped with
//!    the instant the read started (Algorithm 3 line 6);
//! 2. the perception facts are fused into the beliefs: a fact of `per(s)` holds only if no
//!    running sensor that perceives it and has sampled says otherwise;
//! 3. the running action's precondition is checked, and a change traced;
//! 4. the deciding side is woken.
//!
//! Cost of a delivery: the store writes (O(1) per key for keys below `K`, O(K) worst case),
//! the fusion over the running sensors (O(NS)), the precondition check (O(NS)), two or three
//! trace events (O(1) each). Every wake of the sensing future polls each of the NS samplers
//! once (O(NS)).

use core::convert::Infallible;
use core::future::{Future, pending, poll_fn};
use core::pin::{Pin, pin};
use core::task::{Context, Poll};

use embassy_futures::join::join_array;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_time::{Instant, TimeoutError, Timer, with_timeout};
use pin_project_lite::pin_project;

use crate::action::{ActionId, SensorAction, SensorId, SensorMode, SensorSet};
use crate::facts::FactSetOf;
use crate::failure::{Evidence, Failure, SensorFault, Violation};
use crate::platform::{Actuator, Platform, Reading, Sensor};
use crate::runtime::{Runtime, SensorsOf};
use crate::spec::storage::{Mode, PerSensor, Shared, poll_shared};
use crate::spec::{DynSensor, Mission, Samplers, Sensing, SensorOf, SensorSpec, Storage};
use crate::store::{Entry, SAMPLE_KEY, StoreAccess};
use crate::trace::{TraceEvent, TraceSink};

/// The instant after `due` at which a cyclic sensor of period `period` (in ticks, at least 1)
/// is next due, once its sample has finished at `now`: `due + k·period` for the least `k ≥ 1`
/// that is not before `now`. A sample that took longer than a period skips the instants it
/// overran; one 2³² ticks late (or of a period that long) restarts the phase at `now`. O(1),
/// and no 64-bit division.
pub(crate) fn next_due(due: Instant, period: u64, now: Instant) -> Instant {
    let period = period.max(1);
    let late = now.as_ticks().saturating_sub(due.as_ticks());
    // Nearly always: the read ended within its period. No division then.
    if late <= period {
        return Instant::from_ticks(due.as_ticks().saturating_add(period));
    }
    // In 32 bits: a 64-bit division is a library routine on a Cortex-M, 0.9 KB of flash that
    // nothing else of a firmware may need.
    match (u32::try_from(late), u32::try_from(period)) {
        (Ok(late), Ok(period)) => {
            let periods = late.div_ceil(period);
            Instant::from_ticks(
                due.as_ticks()
                    .saturating_add(u64::from(periods).saturating_mul(u64::from(period))),
            )
        }
        // A read 2³² ticks late (49 days at 1 kHz: a timeout that long), or as long a period:
        // the phase restarts.
        _ => now,
    }
}

/// The shared state of a runtime of facts `F` and per-sensor state `S`.
type SharedMutex<Mx, F, S> = Mutex<Mx, Shared<F, S>>;

impl<'r, M, P, T, const W: usize> Sensing for Runtime<'r, M, P, T>
where
    M: Mission<Facts = FactSetOf<W>>,
    P: Platform + Sensor<M> + Actuator<M>,
    T: TraceSink<M>,
{
    type Mission = M;

    fn sampler<S: SensorSpec<M>>(&self, sensor: S) -> impl Future<Output = Infallible> {
        self.sample_loop(sensor)
    }

    fn samplers<const N: usize>(&self) -> impl Future<Output = Infallible> {
        let samplers: [_; N] = core::array::from_fn(|index| self.table_sampler(index));
        Samplers::new(join_array(samplers))
    }
}

impl<'r, M, P, T, const W: usize> Runtime<'r, M, P, T>
where
    M: Mission<Facts = FactSetOf<W>>,
    P: Platform + Sensor<M> + Actuator<M>,
    T: TraceSink<M>,
{
    /// The general sampler of sensor `index`, its sensor read from the mission's tables.
    async fn table_sampler(&self, index: usize) -> Infallible {
        let spec = SensorId::new(index).and_then(|id| {
            let s = self.mission.sensors().get(index)?;
            Some(DynSensor::<M> {
                id,
                sensor: M::Sensor::from_id(id)?,
                mode: s.mode,
                timeout: s.timeout,
                per: s.per,
            })
        });
        match spec {
            Some(spec) => self.sample_loop(spec).await,
            // A capacity the mission does not use.
            None => pending().await,
        }
    }

    /// The sampler of sensor `spec`: serves every command that includes it, forever. One flat
    /// loop, so that little of its state lives across awaits.
    async fn sample_loop<S: SensorSpec<M>>(&self, spec: S) -> Infallible {
        let sensor = spec.id();
        let name = spec.sensor();
        let timeout = spec.timeout();
        let mut served = None;
        loop {
            // A command that includes this sensor, and that it has not served yet.
            let (epoch, mode, start, period) = poll_fn(|cx| {
                self.poll_sensing(cx, |s| {
                    let c = s.command.get();
                    (c.sensors.contains(sensor) && served != Some(c.epoch)).then(|| {
                        let period = s.sensor(sensor).and_then(|p| p.period.get());
                        (c.epoch, c.mode, c.start, period)
                    })
                })
            })
            .await;
            served = Some(epoch);
            self.shared()
                .lock(|s| s.active.set(s.active.get().with(sensor)));
            let fault = match with_timeout(timeout, self.platform.switch_on(name)).await {
                Ok(Ok(())) => None,
                Ok(Err(fault)) => Some(fault),
                Err(_) => Some(SensorFault::Timeout),
            };
            if !self.switched_on(sensor, fault, epoch) {
                continue;
            }
            // A cyclic sensor's period: the mission's, or the one the runtime was given.
            let cyclic = match spec.mode() {
                SensorMode::Cyclic { period: own } => Some(period.unwrap_or(own).as_ticks()),
                _ => None,
            };
            let mut due = match (spec.mode(), mode) {
                (SensorMode::Cyclic { .. }, _) => Some(start),
                (SensorMode::OneShot, Mode::Phase { first: false }) => None,
                (SensorMode::OneShot, _) => Some(start),
                (SensorMode::OnDemand, _) => None,
            };
            let mut marked = due.is_none();
            if marked {
                self.mark_ready(sensor, epoch);
            }
            // The instant of this command's latest read: a read never repeats an instant. Only
            // the command's first instant can have been read before it (by the state that just
            // ended, or the initial model): that one is checked against the shared record.
            let mut last: Option<Instant> = None;
            // Sample until the command ends or the sensor fails. The end of the command comes
            // first at every await: no sample starts, or is delivered, once the state is over.
            loop {
                let waited = match (spec.mode(), due) {
                    (SensorMode::OnDemand, _) => {
                        self.bounded(epoch, None, self.requested(sensor)).await
                    }
                    // The sample's instant, if any (else the command's end); a cyclic
                    // sensor's device may make it due early (`wake`). One wait for all.
                    (sensor_mode, due) => {
                        let mut timer = due.map(Timer::at);
                        let mut timed = move |cx: &mut Context<'_>| {
                            timer
                                .as_mut()
                                .is_some_and(|t| Pin::new(t).poll(cx).is_ready())
                        };
                        let early =
                            matches!(sensor_mode, SensorMode::Cyclic { .. }) && due.is_some();
                        if early && <P as Sensor<M>>::WAKES {
                            let mut wake = pin!(self.platform.wake(name));
                            let wait = poll_fn(move |cx| {
                                if timed(cx) || wake.as_mut().poll(cx).is_ready() {
                                    Poll::Ready(())
                                } else {
                                    Poll::Pending
                                }
                            });
                            self.bounded(epoch, None, wait).await
                        } else {
                            // No `wake` future where it cannot complete (`Sensor::WAKES`).
                            let wait = poll_fn(move |cx| {
                                if timed(cx) {
                                    Poll::Ready(())
                                } else {
                                    Poll::Pending
                                }
                            });
                            self.bounded(epoch, None, wait).await
                        }
                    }
                };
                if !matches!(waited, Bound::Done(())) {
                    break;
                }
                let started = Instant::now();
                if last == Some(started) {
                    // Read and delivered at this instant under this command already.
                } else if last.is_none() && self.read_at(sensor, started) {
                    self.read_again(sensor, spec.per(), started);
                } else {
                    let limit = started.saturating_add(timeout);
                    let read = match self
                        .bounded(epoch, Some(limit), self.platform.sample(name))
                        .await
                    {
                        Bound::Done(read) => Ok(read),
                        Bound::TimedOut => Err(TimeoutError),
                        // Cancelled: no read of this instant was taken.
                        Bound::Ended => break,
                    };
                    last = Some(started);
                    if self.take(sensor, spec.per(), read, started, epoch).is_err() {
                        break;
                    }
                }
                if !marked {
                    self.mark_ready(sensor, epoch);
                    marked = true;
                }
                due = match (cyclic, mode, due) {
                    (Some(_), Mode::Once, _) => None,
                    (Some(period), _, Some(due)) => {
                        let now = Instant::now();
                        // An early sample (`wake`) that ended before its instant keeps it.
                        Some(if now < due {
                            due
                        } else {
                            next_due(due, period, now)
                        })
                    }
                    _ => None,
                };
            }
            let answered = with_timeout(timeout, self.platform.switch_off(name)).await;
            self.switched_off(sensor, answered.is_ok());
        }
    }

    // The samplers' steps that await nothing, out of line: one copy for every sensor's
    // sampler, which keeps only its own waits and reads.

    /// The sensor's switch-on ended with `fault` (if any): it runs (`true`), or it failed and
    /// is reported.
    #[inline(never)]
    fn switched_on(&self, sensor: SensorId, fault: Option<SensorFault>, epoch: u32) -> bool {
        if let Some(fault) = fault {
            self.sensor_failed(sensor, fault, epoch);
            self.shared().lock(|s| {
                s.active.set(s.active.get().without(sensor));
                s.notify();
            });
            return false;
        }
        self.trace(TraceEvent::SensorOn { sensor });
        self.shared().lock(|s| {
            s.running.set(s.running.get().with(sensor));
            s.fresh.set(s.fresh.get().without(sensor));
        });
        true
    }

    /// A read of `sensor` that started at `started` was completed already (by the state or
    /// sense phase that just ended, or the initial model): a sensor never takes two samples of
    /// one instant. Its percept counts for this command too: the beliefs may have been reset
    /// since (a new initial model).
    #[inline(never)]
    fn read_again(&self, sensor: SensorId, per: FactSetOf<W>, started: Instant) {
        let table = self.mission.sensors();
        let change = self.shared().lock(|s| {
            let delivered = s
                .sensor(sensor)
                .and_then(|p| p.percept.get())
                .is_some_and(|e| e.at == started);
            if !delivered {
                return None;
            }
            let holds = s.sensor(sensor).map_or(FactSetOf::EMPTY, |p| p.holds.get());
            fuse(s, table, sensor, per, holds);
            let change = check(s, table);
            s.notify();
            change
        });
        self.trace_change(change);
    }

    /// The sensor's switch-off ended (`answered`, or timed out): it is off. A sensor that does
    /// not answer is traced and counted off: it is not used again until it is switched on.
    #[inline(never)]
    fn switched_off(&self, sensor: SensorId, answered: bool) {
        if !answered {
            self.trace(TraceEvent::SensorFailed {
                sensor,
                fault: SensorFault::Timeout,
            });
        }
        self.trace(TraceEvent::SensorOff { sensor });
        self.shared().lock(|s| {
            s.running.set(s.running.get().without(sensor));
            s.fresh.set(s.fresh.get().without(sensor));
            s.active.set(s.active.get().without(sensor));
            s.notify();
        });
    }

    /// Awaits `inner` unless the command of `epoch` ends first, or `deadline` passes: every
    /// await of a sampler in one future, one lock a poll. The end of the command is checked
    /// first, then `inner`, then the deadline (as `with_timeout` would). Built in place.
    fn bounded<F: Future>(
        &self,
        epoch: u32,
        deadline: Option<Instant>,
        inner: F,
    ) -> Bounded<'_, P::Mutex, FactSetOf<W>, SensorsOf<M, P>, F> {
        Bounded {
            shared: self.shared(),
            epoch,
            inner,
            timer: deadline.map(Timer::at),
        }
    }

    /// Whether a read of `sensor` started at `at`.
    fn read_at(&self, sensor: SensorId, at: Instant) -> bool {
        self.shared().lock(|s| {
            s.sensor(sensor)
                .is_some_and(|p| p.last_read.get() == Some(at))
        })
    }

    /// Waits until the behaviour asks for a sample of `sensor`, and takes the request.
    async fn requested(&self, sensor: SensorId) {
        poll_fn(|cx| {
            self.poll_sensing(cx, |s| {
                let requests = s.requests.get();
                s.requests.set(requests.without(sensor));
                requests.contains(sensor).then_some(())
            })
        })
        .await;
    }

    fn mark_ready(&self, sensor: SensorId, epoch: u32) {
        self.shared().lock(|s| {
            let current = s.epoch.get() == epoch && !s.ready.get().contains(sensor);
            if current {
                s.ready.set(s.ready.get().with(sensor));
                s.notify();
            }
        });
    }

    /// Takes the outcome of one read of `sensor` (perceiving `per`) that started at `started`:
    /// delivers a reading, counts a lost sample, or reports a fault. `Err` when the sensor
    /// failed (reported).
    fn take(
        &self,
        sensor: SensorId,
        per: FactSetOf<W>,
        read: Result<Result<Option<Reading<W>>, SensorFault>, TimeoutError>,
        started: Instant,
        epoch: u32,
    ) -> Result<(), ()> {
        let fault = match read {
            Ok(Ok(Some(reading))) => {
                return self.deliver(sensor, per, &reading, started).map_err(|f| {
                    self.report(f, epoch);
                });
            }
            Ok(Ok(None)) => {
                self.trace(TraceEvent::SampleLost { sensor });
                let lost = self.shared().lock(|s| {
                    s.record_read(sensor, started);
                    s.sensor(sensor).map_or(u8::MAX, |p| {
                        p.lost.set(p.lost.get().saturating_add(1));
                        p.lost.get()
                    })
                });
                if lost < self.config.max_lost {
                    return Ok(());
                }
                SensorFault::Silent
            }
            Ok(Err(fault)) => fault,
            Err(TimeoutError) => SensorFault::Timeout,
        };
        self.shared().lock(|s| s.record_read(sensor, started));
        self.sensor_failed(sensor, fault, epoch);
        Err(())
    }

    /// Delivers a reading taken at `at`: store (Algorithm 3 line 6), fuse, check, wake.
    fn deliver(
        &self,
        sensor: SensorId,
        per: FactSetOf<W>,
        reading: &Reading<W>,
        at: Instant,
    ) -> Result<(), Failure<W>> {
        let store = self
            .storage
            .sensor_stores()
            .get(sensor.index())
            .ok_or(Failure::SensorUnavailable { sensor })?;
        let full = |e: crate::store::StoreFull| Failure::StoreFull { key: e.key };
        store.put(SAMPLE_KEY, reading.value, at).map_err(full)?;
        for (key, value) in reading.pairs() {
            store.put(key, value, at).map_err(full)?;
        }
        let holds = reading.holds.intersection(per);
        let table = self.mission.sensors();
        // One lock for the whole delivery: fuse, record, check pre(a), wake the deciding side.
        let change = self.shared().lock(|s| {
            if let Some(p) = s.sensor(sensor) {
                p.last_read.set(Some(at));
                p.lost.set(0);
                p.holds.set(holds);
                p.percept.set(Some(Entry {
                    value: reading.value,
                    at,
                }));
            }
            fuse(s, table, sensor, per, holds);
            let change = check(s, table);
            s.notify();
            change
        });
        self.trace(TraceEvent::Sample {
            sensor,
            value: reading.value,
            holds,
        });
        self.trace_change(change);
        Ok(())
    }

    /// Compares the watched action's `pre(a)` with the beliefs and traces a change. The
    /// deciding side fails the state once a violation has lasted its action's `max_violation`.
    /// Reads and updates the violation in one lock: the two sides both call it.
    pub(crate) fn check_precondition(&self) {
        let table = self.mission.sensors();
        let change = self.shared().lock(|s| check(s, table));
        self.trace_change(change);
    }

    fn trace_change(&self, change: Option<Change<W>>) {
        match change {
            Some((action, _, None)) => self.trace(TraceEvent::PreconditionRestored { action }),
            Some((action, b, Some(a))) if b.is_none_or(|b| b.missing != a.missing) => {
                self.trace(TraceEvent::PreconditionViolated {
                    action,
                    missing: a.missing,
                });
            }
            _ => {}
        }
    }

    /// A sensor failed: it is out of service until [`clear_faults`](Self::clear_faults), and
    /// the deciding side is told.
    fn sensor_failed(&self, sensor: SensorId, fault: SensorFault, epoch: u32) {
        self.shared()
            .lock(|s| s.faulty.set(s.faulty.get().with(sensor)));
        self.trace(TraceEvent::SensorFailed { sensor, fault });
        self.report(Failure::SensorFault { sensor, fault }, epoch);
    }

    /// Hands `failure` to the deciding side, unless an earlier one of the same command is
    /// pending or the command is over.
    fn report(&self, failure: Failure<W>, epoch: u32) {
        self.shared().lock(|s| {
            if s.epoch.get() == epoch && s.failure.get().is_none() {
                s.set_failure(Some((epoch, failure)));
            }
            s.notify();
        });
    }
}

pin_project! {
    /// A sampler's await ([`Runtime::bounded`]).
    #[must_use = "futures do nothing unless polled"]
    struct Bounded<'s, Mx: RawMutex, F: crate::spec::Width, S, Fut> {
        shared: &'s SharedMutex<Mx, F, S>,
        epoch: u32,
        #[pin]
        inner: Fut,
        timer: Option<Timer>,
    }
}

impl<Mx: RawMutex, F: crate::spec::Width, S, Fut: Future> Future for Bounded<'_, Mx, F, S, Fut> {
    type Output = Bound<Fut::Output>;

    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Self::Output> {
        let this = self.project();
        let epoch = *this.epoch;
        let ended = |s: &Shared<F, S>| s.epoch.get() != epoch;
        if this.shared.lock(ended) {
            return Poll::Ready(Bound::Ended);
        }
        if let Poll::Ready(out) = this.inner.poll(cx) {
            return Poll::Ready(Bound::Done(out));
        }
        if let Some(Poll::Ready(())) = this.timer.as_mut().map(|t| Pin::new(t).poll(cx)) {
            return Poll::Ready(Bound::TimedOut);
        }
        // Waiting: registered in the same lock as a last look at the command, so that a
        // deciding side that ends it in between wakes this one.
        match poll_shared(this.shared, cx, |s| &s.sensing, |s| ended(s).then_some(())) {
            Poll::Ready(()) => Poll::Ready(Bound::Ended),
            Poll::Pending => Poll::Pending,
        }
    }
}

/// How a sampler's [`bounded`](Runtime::bounded) await ended.
enum Bound<T> {
    /// The awaited future completed.
    Done(T),
    /// The command ended first.
    Ended,
    /// The deadline passed first.
    TimedOut,
}

/// Fuses a sample of `sensor` (perceiving `per`, saying `holds`) into the beliefs, in the
/// caller's lock, and marks the sensor fresh. Fusion by conjunction: a fact of `per(s)` holds
/// only if no running sensor that perceives it and has sampled says otherwise (the sonar sees a
/// box while the bumper feels nothing: the path is not clear). O(NS).
fn fuse<const W: usize, S: AsRef<[PerSensor<FactSetOf<W>>]>>(
    s: &Shared<FactSetOf<W>, S>,
    table: &[SensorAction<'_, W>],
    sensor: SensorId,
    per: FactSetOf<W>,
    holds: FactSetOf<W>,
) {
    let fresh = s.fresh.get().with(sensor);
    s.fresh.set(fresh);
    let sampled = SensorSet::from_bits(s.running.get().bits() & fresh.bits()).without(sensor);
    let decided = sampled.iter().fold(holds, |acc, t| {
        let per_t = table.get(t.index()).map_or(FactSetOf::EMPTY, |t| t.per);
        let holds_t = s.sensor(t).map_or(FactSetOf::EMPTY, |p| p.holds.get());
        acc.difference(per_t.difference(holds_t))
    });
    s.beliefs
        .set(s.beliefs.get().difference(per).union(decided));
    s.sensed.set(s.sensed.get().union(per));
}

/// A change of the watched action's violation: (action, before, after).
type Change<const W: usize> = (ActionId, Option<Violation<W>>, Option<Violation<W>>);

/// Compares the watched action's `pre(a)` with the beliefs and updates the violation, in the
/// caller's lock. `None` when nothing is watched or nothing changed. O(NS).
#[inline]
fn check<const W: usize, S: AsRef<[PerSensor<FactSetOf<W>>]>>(
    s: &Shared<FactSetOf<W>, S>,
    table: &[SensorAction<'_, W>],
) -> Option<Change<W>> {
    let (action, pre) = s.watch.get()?;
    let missing = pre.difference(s.beliefs.get());
    // Nearly every sample: the precondition holds and held. Decided here, in the caller.
    if missing.is_empty() && s.violation.get().is_none() {
        return None;
    }
    check_changed(s, table, action, missing)
}

/// [`check`] when the precondition is false or was.
#[inline(never)]
fn check_changed<const W: usize, S: AsRef<[PerSensor<FactSetOf<W>>]>>(
    s: &Shared<FactSetOf<W>, S>,
    table: &[SensorAction<'_, W>],
    action: ActionId,
    missing: FactSetOf<W>,
) -> Option<Change<W>> {
    // A fact a running sensor perceives counts once a sensor perceiving it has delivered under
    // this command or is ready (it has attempted the samples due at the command's start, or has
    // none due): until then its belief is the last state's, not this state's evidence, and a
    // fast sensor's first sample must not fail the action on a fact a slower one is still
    // reading. Only until then: a sample lost, or none due (a one-shot sensor in a later SMPA
    // phase, an on-demand one not asked), leaves the belief to count as before.
    let running = s.running.get();
    let ready = running.intersection(s.ready.get().union(s.fresh.get()));
    let waiting = running.intersection(SensorSet::from_bits(!ready.bits()));
    let perception = |set: SensorSet| crate::action::perception_of(table, set);
    let unread = perception(waiting).difference(perception(ready));
    let missing = missing.difference(unread);
    let before = s.violation.get();
    let after = match (missing.is_empty(), before) {
        (true, None) => return None,
        (true, Some(_)) => None,
        (false, before) => {
            let (by, evidence) = evidence(s, table, missing);
            let seen = evidence.map(|e| e.at);
            Some(match before {
                None => {
                    let at = seen.unwrap_or_else(Instant::now);
                    Violation {
                        missing,
                        since: at,
                        last_seen: at,
                        by,
                        evidence,
                    }
                }
                Some(v) => Violation {
                    missing,
                    last_seen: seen.unwrap_or(v.last_seen),
                    by,
                    evidence: evidence.or(v.evidence),
                    ..v
                },
            })
        }
    };
    s.set_violation(after);
    Some((action, before, after))
}

/// The running, sampled sensors whose latest sample says one of `missing` does not hold, and
/// the newest of those samples: the evidence of a violation. Samples of other sensors that
/// only repeat the fused verdict are not evidence. O(NS).
fn evidence<const W: usize, S: AsRef<[PerSensor<FactSetOf<W>>]>>(
    s: &Shared<FactSetOf<W>, S>,
    table: &[SensorAction<'_, W>],
    missing: FactSetOf<W>,
) -> (SensorSet, Option<Evidence>) {
    let sampled = SensorSet::from_bits(s.running.get().bits() & s.fresh.get().bits());
    let mut by = SensorSet::EMPTY;
    let mut newest: Option<Evidence> = None;
    for t in sampled.iter() {
        let per_t = table.get(t.index()).map_or(FactSetOf::EMPTY, |t| t.per);
        let Some(p) = s.sensor(t) else { continue };
        if !per_t.difference(p.holds.get()).intersects(missing) {
            continue;
        }
        by = by.with(t);
        if let Some(e) = p.percept.get()
            && newest.is_none_or(|n| e.at > n.at)
        {
            newest = Some(Evidence {
                sensor: t,
                at: e.at,
                value: e.value,
            });
        }
    }
    (by, newest)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(t: u64) -> Instant {
        Instant::from_ticks(t)
    }

    #[test]
    fn the_next_instant_keeps_the_phase_and_skips_what_a_slow_read_overran() {
        // A read that takes no time: the next period.
        assert_eq!(next_due(at(100), 20, at(100)), at(120));
        // A read that ends within the period: still the next period.
        assert_eq!(next_due(at(100), 20, at(115)), at(120));
        // A read that ends exactly on the next instant: that instant (a new sample, not the
        // same one twice).
        assert_eq!(next_due(at(100), 20, at(120)), at(120));
        // A 40 ms read on a 15 ms period: 115 and 130 passed during the read; 145 is next.
        assert_eq!(next_due(at(100), 15, at(140)), at(145));
        // A period of 0 ticks counts as 1: never twice at one instant.
        assert_eq!(next_due(at(7), 0, at(7)), at(8));
        // Late by most of 2³² ticks: still the phase.
        let late = u64::from(u32::MAX) - 5;
        assert_eq!(
            next_due(at(3), 1000, at(3 + late)),
            at(3 + late.div_ceil(1000) * 1000)
        );
        // Late by 2³² ticks or more: the phase restarts at the end of the read.
        let late = 1 << 40;
        assert_eq!(next_due(at(3), 1000, at(3 + late)), at(3 + late));
    }
}

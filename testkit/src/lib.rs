//! Run a psmpa robot in virtual time, in a test.
//!
//! * [`sim::simulate_split`] runs a runtime's sensing side at a higher priority beside its
//!   deciding side on an `embassy-time` driver whose clock only moves when everything waits:
//!   a minute of robot time takes milliseconds, and every run of the same code is the same
//!   run. A future that waits with no timer pending is a [`SimError::Deadlock`], one that is
//!   still running at the limit a [`SimError::TimeLimit`].
//! * [`Recorder`] keeps the runtime's trace events; [`Script`] says what a scripted sensor
//!   reads at each instant.
//! * [`pins`] has `embedded-hal` pins for driver tests: an input whose level follows a script
//!   of edges in virtual time, an output and a PWM channel that record what was written when.
//!
//! The crate defines the `embassy-time` driver (there can be one per program) and chooses no
//! tick rate: the rate is whatever the program's `embassy-time-driver` features say (1 MHz by
//! default), so a firmware crate with its own rate can use the kit as a dev-dependency.
//!
//! ```
//! use embassy_time::{Duration, Instant, Timer};
//! use psmpa_testkit::{Script, sim::simulate};
//!
//! // A door that opens at 2 s.
//! const OPENS: [(Duration, bool); 1] = [(Duration::from_secs(2), true)];
//! let door = Script::new(false, &OPENS);
//! let done = simulate(
//!     async {
//!         while !door.now() {
//!             Timer::after(Duration::from_millis(100)).await;
//!         }
//!         Instant::now()
//!     },
//!     Duration::from_secs(60),
//! )
//! .unwrap();
//! assert_eq!(done.output.as_millis(), 2_000);
//! ```
#![deny(missing_docs)]
#![forbid(unsafe_code)]

pub mod pins;
pub mod sim;

pub use sim::{Completed, SimError, simulate, simulate_split};

mod record {
    use core::fmt;
    use core::marker::PhantomData;

    use embassy_time::{Duration, Instant};
    use psmpa_core::{
        ActionOf, Describe, FactSetOf, Failure, Mission, PlanOf, SensorOf, TraceEvent, TraceSink,
    };

    /// A trace sink that keeps every event of a runtime of mission `M` with its instant. Its
    /// views name what they list with `M`'s names (`plans_selected::<dock::Plan>()`): another
    /// mission's names do not compile.
    pub struct Recorder<M: Mission<Facts = FactSetOf<W>>, const W: usize = 1> {
        /// The events, in order, with their instants.
        pub events: Vec<(Instant, TraceEvent<W>)>,
        mission: PhantomData<fn() -> M>,
    }

    impl<M: Mission<Facts = FactSetOf<W>>, const W: usize> Default for Recorder<M, W> {
        fn default() -> Self {
            Self {
                events: Vec::new(),
                mission: PhantomData,
            }
        }
    }

    impl<M: Mission<Facts = FactSetOf<W>>, const W: usize> Clone for Recorder<M, W> {
        fn clone(&self) -> Self {
            Self {
                events: self.events.clone(),
                mission: PhantomData,
            }
        }
    }

    impl<M: Mission<Facts = FactSetOf<W>>, const W: usize> fmt::Debug for Recorder<M, W> {
        fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            f.debug_list().entries(&self.events).finish()
        }
    }

    impl<M: Mission<Facts = FactSetOf<W>>, const W: usize> TraceSink<M> for Recorder<M, W> {
        fn record(&mut self, at: Instant, event: &TraceEvent<W>) {
            self.events.push((at, *event));
        }
    }

    impl<M: Mission<Facts = FactSetOf<W>>, const W: usize> Recorder<M, W> {
        /// The events `matching` picks, with their instants.
        pub fn find(
            &self,
            matching: impl Fn(&TraceEvent<W>) -> bool,
        ) -> Vec<(Instant, TraceEvent<W>)> {
            self.events
                .iter()
                .filter(|(_, e)| matching(e))
                .copied()
                .collect()
        }

        /// The instant of the first event `matching` picks.
        pub fn first(&self, matching: impl Fn(&TraceEvent<W>) -> bool) -> Option<Instant> {
            self.events
                .iter()
                .find(|(_, e)| matching(e))
                .map(|(t, _)| *t)
        }

        /// The plans selected, in order, as `P` names them: `M`'s `Plan`
        /// (`plans_selected::<dock::Plan>()`), or [`PlanId`](psmpa_core::PlanId), which
        /// also names a plan the planner generated
        /// ([`PlanId::GENERATED`](psmpa_core::PlanId::GENERATED); the mission's `Plan` has
        /// none, so it is left out of a list of those).
        pub fn plans_selected<P: PlanOf<M>>(&self) -> Vec<P> {
            self.events
                .iter()
                .filter(|(_, e)| matches!(e, TraceEvent::PlanSelected { .. }))
                .filter_map(|(_, e)| P::from_id(e.plan()?))
                .collect()
        }

        /// Every plan that failed, when, and why (its plan as [`Recorder::plans_selected`]
        /// names it).
        pub fn plan_failures<P: PlanOf<M>>(&self) -> Vec<(Instant, P, Failure<W>)> {
            self.events
                .iter()
                .filter_map(|(t, e)| match e {
                    TraceEvent::PlanFailed { plan, reason } => {
                        Some((*t, P::from_id(*plan)?, *reason))
                    }
                    _ => None,
                })
                .collect()
        }

        /// Every state entered, in order: its action and the sensors running beside it, as
        /// `M`'s `Action` and `Sensor` name them (or by id).
        pub fn states_entered<A: ActionOf<M>, S: SensorOf<M>>(&self) -> Vec<(A, Vec<S>)> {
            self.events
                .iter()
                .filter_map(|(_, e)| match e {
                    TraceEvent::StateEntered {
                        action, sensors, ..
                    } => Some((
                        A::from_id(*action)?,
                        sensors.iter().filter_map(S::from_id).collect(),
                    )),
                    _ => None,
                })
                .collect()
        }

        /// The trace in words, one line an event with its instant, with `mission`'s names
        /// (`M`'s: another mission's does not compile).
        pub fn describe(&self, mission: &M) -> Vec<String> {
            self.events
                .iter()
                .map(|(at, e)| {
                    let ms = Duration::from_ticks(at.as_ticks()).as_millis();
                    format!("{ms} ms: {}", mission.describe(*e))
                })
                .collect()
        }
    }

    #[cfg(test)]
    mod tests {
        use super::*;
        use psmpa_core::{EventId, PlanId, TraceSink};

        psmpa_core::include_mission!(mod hello = "tests/hello.json");

        #[test]
        fn the_recorder_lists_the_plans_selected_and_those_that_failed() {
            let mut r: Recorder<hello::Hello> = Recorder::default();
            let (first, second) = (PlanId::new(0).unwrap(), PlanId::GENERATED);
            let failed = Failure::SensingStalled;
            let at = |ms| Instant::from_millis(ms);
            let selected = |plan| TraceEvent::PlanSelected {
                plan,
                event: EventId::FIRST,
            };
            let mut record = |at, e| TraceSink::<hello::Hello>::record(&mut r, at, &e);
            record(at(0), selected(first));
            record(
                at(5),
                TraceEvent::PlanFailed {
                    plan: first,
                    reason: failed,
                },
            );
            record(at(5), selected(second));
            assert_eq!(r.plans_selected::<PlanId>(), [first, second]);
            assert_eq!(r.plan_failures::<PlanId>(), [(at(5), first, failed)]);
            // The mission's own names leave the generated plan out.
            assert_eq!(r.plans_selected::<hello::Plan>(), [hello::Plan::GoThere]);
        }
    }

    /// A value that changes at given times after the start of the simulation: what a scripted
    /// sensor reads, or what a simulated world holds, at each instant.
    #[derive(Clone, Copy, Debug)]
    pub struct Script<'a, T> {
        initial: T,
        steps: &'a [(Duration, T)],
    }

    impl<'a, T: Copy> Script<'a, T> {
        /// `initial` until the first step; each step `(after, value)` holds from `after` on.
        /// Steps are in time order.
        pub const fn new(initial: T, steps: &'a [(Duration, T)]) -> Self {
            Self { initial, steps }
        }

        /// The value at `at`.
        pub fn at(&self, at: Instant) -> T {
            let since = at.duration_since(Instant::from_ticks(0));
            self.steps
                .iter()
                .take_while(|(after, _)| *after <= since)
                .last()
                .map_or(self.initial, |(_, v)| *v)
        }

        /// The value now.
        pub fn now(&self) -> T {
            self.at(Instant::now())
        }
    }
}

pub use record::{Recorder, Script};

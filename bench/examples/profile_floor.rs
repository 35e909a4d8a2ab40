//! The floor under psmpa's action step on this backend: the same work as `profile_plan`'s, with
//! none of the runtime around it. Two futures in the host's virtual time, sensing above deciding
//! (`simulate_split`); per action step a timer wakes the sensing future, which samples the
//! sonar, puts the value into a store, fuses the fact, checks the precondition and signals; the
//! deciding future wakes, checks the violation, reads the sample and writes its progress. No
//! FSM, no control loop, no switching sensors on and off, no trace (`profile_plan` runs with
//! no sink, which traces nothing).
//!
//! `valgrind --tool=callgrind target/release/examples/profile_floor 1000` (and 2000): the
//! difference over the 30,000 action steps between the two is the floor's cost per step.

use core::cell::Cell;

use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_sync::signal::Signal;
use embassy_time::{Duration, Instant, Timer};
use psmpa_bench::workload::{ACTIONS, STEPS_PER_ACTION, Sonar, path_clear};
use psmpa_core::{DataStore, FactId, FactSet, Key, StoreAccess, Value};

/// One run of the plan's work; returns the action steps run.
fn run_once() -> u32 {
    let sample: DataStore<NoopRawMutex, 4> = DataStore::new();
    let own: DataStore<NoopRawMutex, 4> = DataStore::new();
    let beliefs = Cell::new(FactSet::EMPTY);
    let violated = Cell::new(false);
    let signal: Signal<NoopRawMutex, ()> = Signal::new();
    let Some(clear) = FactId::new(0) else {
        return 0;
    };
    let pre = FactSet::single(clear);
    let sensing = async {
        let mut sonar = Sonar::new();
        loop {
            Timer::after_ticks(1).await;
            let now = Instant::now();
            let mm = sonar.sample();
            if sample.put(Key(0), Value::Mm(mm), now).is_err() {
                return;
            }
            let holds = if path_clear(mm) { pre } else { FactSet::EMPTY };
            beliefs.set(beliefs.get().difference(pre).union(holds));
            violated.set(!pre.is_subset(beliefs.get()));
            signal.signal(());
        }
    };
    let deciding = async {
        let mut steps = 0;
        for _ in 0..ACTIONS {
            for step in 0..STEPS_PER_ACTION {
                signal.wait().await;
                if violated.get() {
                    return steps;
                }
                let Some(Value::Mm(mm)) = sample.get(Key(0)).map(|e| e.value) else {
                    return steps;
                };
                let progress = Value::Int(mm.wrapping_add(step as i32));
                if own.put(Key(1), progress, Instant::now()).is_err() {
                    return steps;
                }
                steps += 1;
            }
        }
        steps
    };
    psmpa_sim::backend::simulate_split(sensing, deciding, Duration::from_secs(60))
        .map_or(0, |done| done.output)
}

fn main() {
    let runs: u32 = std::env::args()
        .nth(1)
        .and_then(|n| n.parse().ok())
        .unwrap_or(1000);
    let steps: u32 = (0..runs).map(|_| run_once()).sum();
    println!("{steps} action steps in {runs} plans");
}

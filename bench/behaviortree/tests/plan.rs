//! The workload's outcome with `behaviortree`.

use behaviortree::prelude::*;
use psmpa_bench_behaviortree::{
    PROGRESS_KEYS, Sensor, prepare, prepare_with, run_plan, run_prepared, workload,
};

#[test]
fn plan_runs_all_steps() {
    assert_eq!(run_plan(), workload::EXPECTED_STEPS);
}

#[test]
fn plan_succeeds_with_one_sample_per_step_and_progress_on_the_blackboard() {
    let mut p = prepare();
    let (state, steps) = p.run();
    assert_eq!(state, BehaviorState::Success);
    assert_eq!(steps, workload::EXPECTED_STEPS);
    assert_eq!(p.sensor().lock().samples(), workload::EXPECTED_STEPS);
    for key in PROGRESS_KEYS {
        assert_eq!(
            p.tree().blackboard().get::<u32>(key),
            Ok(workload::STEPS_PER_ACTION),
            "{key}"
        );
    }
}

#[test]
fn prepared_tree_reruns() {
    let mut p = prepare();
    for _ in 0..3 {
        assert_eq!(run_prepared(&mut p), workload::EXPECTED_STEPS);
        assert_eq!(p.sensor().lock().samples(), workload::EXPECTED_STEPS);
    }
}

#[test]
fn blocked_path_fails_the_plan_early() {
    // The 14th reading sees an obstacle: 13 steps ran (10 of the first action, 3 of the
    // second); the 14th is not run.
    let mut p = prepare_with(Sensor::blocked_at(14));
    let (state, steps) = p.run();
    assert_eq!(state, BehaviorState::Failure);
    assert_eq!(steps, 13);
    assert_eq!(p.sensor().lock().samples(), 14);
    assert_eq!(p.tree().blackboard().get::<u32>("leg2"), Ok(3));
    assert_eq!(p.tree().blackboard().get::<u32>("leg3"), Ok(0));

    // The same tree, reset, fails at the same reading again.
    p.reset();
    assert_eq!(p.run(), (BehaviorState::Failure, 13));
}

#[test]
fn blocked_first_reading_runs_no_step() {
    let (state, steps) = prepare_with(Sensor::blocked_at(1)).run();
    assert_eq!(state, BehaviorState::Failure);
    assert_eq!(steps, 0);
}

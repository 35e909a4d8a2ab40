//! The workload of `psmpa_bench::workload` (3 actions of 10 steps, a sensor condition and a
//! store read and write per step) in psmpa and its peers, measured in one run. Criterion's
//! throughput is in action steps, so `elem/s` is action steps per second.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use psmpa_bench::alloc::{Counting, allocations_of};
use psmpa_bench::workload::EXPECTED_STEPS;
use psmpa_bench::{bonsai_plan, hand, psmpa_plan, statig_plan};

#[global_allocator]
static ALLOCATOR: Counting = Counting;

fn plan(c: &mut Criterion) {
    let (mission, platform) = (psmpa_plan::mission(), psmpa_plan::Platform::default());
    let psmpa = || psmpa_plan::run_plan_on(&mission, &platform);
    let peers: [(&str, &dyn Fn() -> u32); 4] = [
        ("hand-written FSM", &hand::run_plan),
        ("psmpa", &psmpa),
        ("statig", &statig_plan::run_plan),
        ("bonsai-bt", &bonsai_plan::run_plan),
    ];
    for (name, run) in peers {
        // Every implementation does the same work.
        assert_eq!(run(), EXPECTED_STEPS, "{name}");
        println!("allocations per plan: {name}: {}", allocations_of(run));
    }
    let mut group = c.benchmark_group("plan");
    group.throughput(Throughput::Elements(u64::from(EXPECTED_STEPS)));
    for (name, run) in peers {
        group.bench_function(name, |b| b.iter(run));
    }
    group.finish();
}

criterion_group!(benches, plan);
criterion_main!(benches);

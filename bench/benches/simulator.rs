//! Simulator throughput: one whole run of a paper scenario per iteration. Throughput is given
//! in elements = simulated seconds, so criterion's `elem/s` is simulated seconds per wall-clock
//! second (the real-time factor) on one core.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use psmpa_bench::scenario;
use psmpa_sim::robot::Arch;
use psmpa_sim::sim::run_summary;

fn simulator(c: &mut Criterion) {
    let mut group = c.benchmark_group("simulator");
    for name in ["sonar-8", "bumper-6"] {
        let sc = scenario(name);
        for arch in Arch::ALL {
            let simulated_ms = run_summary(&sc, arch).map(|s| s.time_cost_ms).unwrap_or(1);
            group.throughput(Throughput::Elements(simulated_ms / 1000));
            group.bench_function(format!("{name}/{}", arch.name()), |b| {
                b.iter(|| run_summary(std::hint::black_box(&sc), arch).map(|s| s.trace_hash))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, simulator);
criterion_main!(benches);

//! Runs the psmpa plan workload many times, for a profiler:
//! `valgrind --tool=callgrind target/release/examples/profile_plan 1000`.

fn main() {
    let runs: u32 = std::env::args()
        .nth(1)
        .and_then(|n| n.parse().ok())
        .unwrap_or(1000);
    let (mission, platform) = (
        psmpa_bench::psmpa_plan::mission(),
        psmpa_bench::psmpa_plan::Platform::default(),
    );
    let steps: u32 = (0..runs)
        .map(|_| psmpa_bench::psmpa_plan::run_plan_on(&mission, &platform))
        .sum();
    println!("{steps} action steps in {runs} plans");
}

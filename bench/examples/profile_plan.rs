//! Runs the psmpa plan workload many times, for a profiler:
//! `valgrind --tool=callgrind target/release/examples/profile_plan 1000` (its plan's constant states), or
//! `profile_plan run-time 1000` (through the run-time FSM).

use psmpa_core::Plans;

fn main() {
    let mut args = std::env::args().skip(1).peekable();
    let plans = match args.peek().map(String::as_str) {
        Some("run-time") => {
            args.next();
            Plans::RunTime
        }
        _ => Plans::Compiled,
    };
    let runs: u32 = args.next().and_then(|n| n.parse().ok()).unwrap_or(1000);
    let (mission, platform) = (
        psmpa_bench::psmpa_plan::mission(),
        psmpa_bench::psmpa_plan::Platform::default(),
    );
    let steps: u32 = (0..runs)
        .map(|_| psmpa_bench::psmpa_plan::run_plan_with(&mission, &platform, plans))
        .sum();
    println!("{steps} action steps in {runs} plans");
}

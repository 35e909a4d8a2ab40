//! Runs a peer's plan workload (the same work as `profile_plan`'s) many times, for callgrind:
//! `valgrind --tool=callgrind target/release/examples/profile_peer bonsai-bt 200` (and 400):
//! the difference between two counts over the difference in plans is the peer's cost per
//! plan. Names as in the benchmark table: `bonsai-bt`, `statig`, `hand-written FSM`.

use psmpa_bench::{bonsai_plan, hand, statig_plan};

fn main() {
    let mut args = std::env::args().skip(1);
    let name = args.next().unwrap_or_default();
    let runs: u32 = args.next().and_then(|n| n.parse().ok()).unwrap_or(1000);
    let run: fn() -> u32 = match name.as_str() {
        "bonsai-bt" => bonsai_plan::run_plan,
        "statig" => statig_plan::run_plan,
        "hand-written FSM" => hand::run_plan,
        other => {
            eprintln!("profile_peer: no peer {other:?}: bonsai-bt, statig or \"hand-written FSM\"");
            std::process::exit(2);
        }
    };
    // Through `black_box`, so that no run is folded into another.
    let steps: u32 = (0..runs).map(|_| std::hint::black_box(run)()).sum();
    println!("{steps} action steps in {runs} plans");
}

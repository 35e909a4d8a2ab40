//! Runs a paper scenario many times under P-SMPA, for a profiler:
//! `valgrind --tool=callgrind target/release/examples/profile_sim sonar-8 100`.

use psmpa_sim::robot::Arch;
use psmpa_sim::sim::run_summary;

fn main() {
    let mut args = std::env::args().skip(1);
    let name = args.next().unwrap_or_else(|| "sonar-8".to_owned());
    let runs: u32 = args.next().and_then(|n| n.parse().ok()).unwrap_or(100);
    let scenario = psmpa_bench::scenario(&name);
    let mut hash = 0u64;
    for _ in 0..runs {
        match run_summary(&scenario, Arch::PSmpa) {
            Ok(summary) => hash ^= summary.trace_hash,
            Err(e) => {
                eprintln!("{e}");
                std::process::exit(1);
            }
        }
    }
    println!("{runs} runs of {name}, hashes xor {hash:016x}");
}

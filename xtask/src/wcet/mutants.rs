//! `cargo xtask wcet --mutants`: the analysis must be able to fail. Each mutant is a bug
//! planted in a scratch copy of the sources (`target/mutants/wcet-tree`), built as the
//! analysis builds the Pico's image, and analysed; it is caught when the analysis does what it
//! exists for: a busy computation added to the switches' sampling path raises the sensing job's
//! bound by at least what it costs, and a busy wait on time in the safety stop (`halt`) makes
//! the analysis fail, naming it. A last mutant is planted in the analysis's own cost table:
//! `--emulated`, which compares it with rp2040js's count, must fail.

use std::path::Path;

use super::thumb::Table;
use super::{Annotations, JobWcet, analyse};
use crate::firmware;
use crate::hil::Ending;
use crate::hil::mutants::{copy_tree, plant_in, restore, warm_target};
use crate::stack::CallGraph;

/// What catches a mutant.
enum Expect {
    /// The named job's instruction cycles rise by at least this many (its XIP misses move
    /// with the layout of the whole image, by more than a small change costs).
    Rises(&'static str, u64),
    /// The analysis fails with a message holding this.
    Fails(&'static str),
}

/// A planted bug: its file and the exact text it replaces (which must occur once).
struct Mutant {
    name: &'static str,
    what: &'static str,
    file: &'static str,
    find: &'static str,
    replace: &'static str,
    expect: Expect,
}

const MUTANTS: &[Mutant] = &[
    Mutant {
        name: "switch-busy-loop",
        what: "the switches' driver computes 1,000 rounds after each read of the pin",
        // In a function of its own: inlined, LLVM keeps the limit in a stack slot, which the
        // analysis does not follow (it then refuses the loop, unbounded).
        file: "drivers/src/switch.rs",
        find: "        let high = self.pin.is_high().map_err(|_| PinError)?;",
        replace: "        let high = self.pin.is_high().map_err(|_| PinError)?;
        #[inline(never)]
        fn busy() {
            for i in 0..1000u32 {
                core::hint::black_box(i);
            }
        }
        busy();",
        // A round is at least an add, a compare and a taken branch: 4 cycles.
        expect: Expect::Rises("sensing_poll", 3_000),
    },
    Mutant {
        name: "busy-halt",
        what: "the safety stop waits 1 ms on the clock before it brakes",
        file: "fetch-tea/src/lib.rs",
        find: "        // Nothing more to do if even braking fails.
        let _ = self.brake();",
        replace: "        embassy_time::block_for(Duration::from_millis(1));
        let _ = self.brake();",
        expect: Expect::Fails("embassy_time::delay::block_for"),
    },
];

/// The analysed jobs of the image at `path`, or why the analysis failed.
fn jobs(path: &Path, annotations: &Annotations) -> Result<Vec<JobWcet>, String> {
    let (results, _) = analyse(path, annotations)?;
    results.into_iter().collect()
}

/// Plants each mutant, analyses it, and says which were caught; exit 0 only if all were.
pub fn run() -> Ending {
    match catch() {
        Ok(missed) if missed.is_empty() => Ending::Passed,
        Ok(missed) => Ending::Failed(format!("not caught: {}", missed.join(", "))),
        Err(e) => Ending::Failed(e),
    }
}

fn catch() -> Result<Vec<String>, String> {
    let root = firmware::root();
    let tree = root.join("target/mutants/wcet-tree");
    let target = root.join("target/mutants/wcet-target");
    copy_tree(&root, &tree)?;
    warm_target(&firmware::boards().join("target/stack"), &target)?;
    let annotations = Annotations::load()?;
    // The clean image, built where the mutants are, as the baseline.
    for m in MUTANTS {
        restore(&root, &tree, m.file)?;
    }
    let clean = jobs(&CallGraph::build_pico_in(&tree, &target)?, &annotations)
        .map_err(|e| format!("the clean image does not pass the analysis: {e}"))?;
    let mut missed = Vec::new();
    println!("{:<16} {:<56} caught", "mutant", "bug");
    for m in MUTANTS {
        plant_in(m.name, &root, &tree, m.file, m.find, m.replace)?;
        let built = CallGraph::build_pico_in(&tree, &target);
        restore(&root, &tree, m.file)?;
        let analysed = jobs(&built?, &annotations);
        let verdict = match (&m.expect, analysed) {
            (Expect::Rises(job, at_least), Ok(jobs)) => {
                let get = |js: &[JobWcet]| {
                    js.iter()
                        .find(|j| j.job == *job)
                        .map(|j| j.cycles - j.xip_cycles)
                };
                match (get(&clean), get(&jobs)) {
                    (Some(before), Some(after)) if after >= before.saturating_add(*at_least) => {
                        Ok(format!("{job}: {before} -> {after} cycles of instructions"))
                    }
                    (before, after) => Err(format!(
                        "{job}: {before:?} -> {after:?} cycles of instructions, not {at_least} more"
                    )),
                }
            }
            (Expect::Rises(..), Err(e)) => Err(format!("the analysis failed: {e}")),
            (Expect::Fails(what), Err(e)) if e.contains(what) => Ok(format!(
                "refused: {}",
                e.lines().last().unwrap_or("").trim()
            )),
            (Expect::Fails(what), Err(e)) => Err(format!("failed without naming {what}: {e}")),
            (Expect::Fails(what), Ok(_)) => Err(format!("passed: {what} went unnoticed")),
        };
        match verdict {
            Ok(how) => println!("{:<16} {:<56} yes: {how}", m.name, m.what),
            Err(why) => {
                println!("{:<16} {:<56} NO: {why}", m.name, m.what);
                missed.push(m.name.to_owned());
            }
        }
    }
    // A bug in the analysis itself: its cost table, against rp2040js's count.
    let (name, what) = (
        "cheap-memory",
        "the analysis charges a load or store 1 cycle, not 2",
    );
    let cheap = Table {
        memory: 1,
        ..Table::RP2040JS
    };
    match super::emulated::check(cheap, false) {
        Ok(failures) if !failures.is_empty() => {
            let first = failures.first().map_or("", String::as_str);
            println!("{name:<16} {what:<56} yes: --emulated fails: {first}");
        }
        Ok(_) => {
            println!("{name:<16} {what:<56} NO: --emulated passed");
            missed.push(name.to_owned());
        }
        Err(e) => return Err(format!("{name}: {e}")),
    }
    Ok(missed)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A mutant whose text the code no longer holds fails the run late (after minutes of
    /// building): each names exactly one place now.
    #[test]
    fn every_mutant_names_one_place_in_the_code() {
        let root = firmware::root();
        for m in MUTANTS {
            let code = std::fs::read_to_string(root.join(m.file)).unwrap();
            assert_eq!(code.matches(m.find).count(), 1, "{}", m.name);
        }
    }
}

//! `cargo xtask`: the project's tasks around the firmware.
//!
//! * `qemu`: build the firmware for both QEMU machines (mps2-an386's Cortex-M4F, mps2-an505's
//!   Cortex-M33), run it (`-icount`: deterministic), decode its defmt log and check that every
//!   embedded scenario, under both architectures, gives the same result as the host simulator,
//!   and that its world trace matches the expected one in `scenarios/traces/`. Instants may
//!   come a little later on the target, by a stated lag (`trace.rs`); a difference fails with
//!   a diff that names the event.
//! * `size`: flash and static RAM of the firmware and its stack high-water mark in QEMU,
//!   checked against the budget and the committed snapshot `firmware/size.json`.
//! * `stack`: a static bound on the firmware's stack from its call graph and frame sizes,
//!   checked against the high-water mark the same binary measures in QEMU.
//! * `bench`: every benchmark in one run, written as the README's table; `--instructions`: only
//!   psmpa's instructions per action step (callgrind).
//! * `timing`: response-time analysis from the step costs the firmware measures in QEMU, on
//!   both machines: the reaction-latency bound of every sensor, checked against the measured
//!   reactions.
//! * `hil`: the Pico's image on an emulated RP2040 against the project's world, judged from
//!   its pins and flight recording (`--mutants`: images with planted bugs must fail it).
//! * `wcet`: static cycle bounds of the Pico's jobs from its binary.
//! * `experiment`: the sensitivity study's figures on the pages.

mod bench;
mod callgrind;
mod experiment;
mod firmware;
mod hil;
mod live;
mod pages;
mod planning;
mod recording;
mod size;
mod splitmix;
mod stack;
mod timing;
mod trace;
mod view_soak;
mod wcet;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "cargo xtask", about = "psmpa project tasks")]
struct Cli {
    #[command(subcommand)]
    task: Task,
}

#[derive(Subcommand)]
enum Task {
    /// Runs the firmware in QEMU on mps2-an386 and mps2-an505 and checks every scenario
    /// against the host simulator, and its world trace against scenarios/traces/.
    Qemu {
        /// Build with the `inject-fault` feature: one scenario is broken on purpose, and the
        /// check must fail (on mps2-an386 only).
        #[arg(long)]
        inject_fault: bool,
        /// Succeed only if the check fails (to show that it can).
        #[arg(long)]
        expect_failure: bool,
    },
    /// Reports flash, static RAM and stack high-water against the budget and the snapshot.
    Size {
        /// Write the measured figures as the new snapshot.
        #[arg(long)]
        bless: bool,
    },
    /// Bounds the firmware's worst-case stack from its binary and checks the bound against
    /// the high-water mark measured in QEMU (LLVM's frame sizes, unlocked on the stable
    /// compiler with RUSTC_BOOTSTRAP).
    Stack,
    /// Every benchmark in one run (psmpa and its peers, stores, simulator, a 10,000-scenario
    /// sweep); writes bench/RESULTS.md and the README's table.
    Bench {
        /// Only rewrite the table from the last run's results.
        #[arg(long)]
        no_run: bool,
        /// Only count instructions under callgrind: psmpa's per action step, the floor's (the
        /// same work with no runtime around it), every implementation's per plan, and where
        /// psmpa's step goes; quick and deterministic; writes docs/benchmarks.md's figures.
        #[arg(long, conflicts_with = "no_run")]
        instructions: bool,
        /// Only the planning benchmark: psmpa's planner beside pyperplan (when installed) on
        /// generated gripper and blocks problems; writes bench/PLANNING.md and README's table
        /// (without pyperplan it only prints psmpa's figures).
        #[arg(long, conflicts_with_all = ["no_run", "instructions"])]
        planning: bool,
    },
    /// The robot's firmware on an emulated Raspberry Pi Pico (RP2040, rp2040js), in the loop
    /// with the project's world: every shipped scenario, the bench's fault scenarios and its
    /// soak, or the files given; each checked against psmpa-sim and its response-time bounds.
    Hil {
        /// Scenario files (psmpa-sim's format) or the bench's fault scenarios
        /// (boards/faults/*.json); none: every shipped one, and boards/soak/*.json.
        files: Vec<std::path::PathBuf>,
        /// Print one JSON object a run on stdout, nothing else.
        #[arg(long)]
        json: bool,
        /// Measure the step costs over every shipped scenario and fault and rewrite the
        /// committed budget the bench judges by (boards/pico/bench-budget.json), printing the
        /// old and new figures side by side.
        #[arg(long, conflicts_with_all = ["files", "mutants"])]
        calibrate: bool,
        /// Play the bench on images with planted bugs (a deaf sonar, a missing pull-up, a slow
        /// brake ...): exit 0 only when every one fails it; a table of what caught each.
        #[arg(long, conflicts_with_all = ["files"])]
        mutants: bool,
        /// Also show the chip's run live in psmpa-sim's view (a web page on 127.0.0.1 at
        /// --port), frame by frame as its recording comes off RTT (with several runs, one at a
        /// time); it serves on after the bench until interrupted.
        #[arg(long, conflicts_with_all = ["json", "calibrate", "mutants"])]
        view: bool,
        /// The view's port (0: a free one; the address printed says which).
        #[arg(long, default_value_t = 8077, requires = "view")]
        port: u16,
    },
    /// Static worst-case execution times of the Pico image's jobs (cycles of the RP2040's
    /// Cortex-M0+), from the binary: exit 1 naming any loop it cannot bound.
    Wcet {
        /// The board (only `pico`: the RP2040 image the bench runs).
        #[arg(long, default_value = "pico", value_parser = ["pico"])]
        board: String,
        /// Print one JSON object on stdout.
        #[arg(long)]
        json: bool,
        /// Analyse images with planted bugs (a busy loop on the sonar's path, a busy wait in
        /// the safety stop): exit 0 only when the analysis catches every one.
        #[arg(long, conflicts_with = "json")]
        mutants: bool,
        /// Check the analysis's cycle costs against rp2040js: call functions of the image on
        /// the emulated chip with chosen arguments and compare each count with the static bound
        /// (instructions only: rp2040js models no XIP cache).
        #[arg(long, conflicts_with_all = ["json", "mutants"])]
        emulated: bool,
    },
    /// The sensitivity study (`psmpa-sim sensitivity`, its seeded defaults) and its figures
    /// written into README.md and docs/experiment.md.
    Experiment,
    /// The live view under load: `psmpa-sim view scenarios/sonar-8.json --speed 100` run again
    /// and again (--repeat) for the minutes asked, pages following its updates; fails when it
    /// falls behind or its memory grows, else writes the figures into docs/simulator.md.
    ViewSoak {
        /// How long, minutes.
        #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..=600))]
        minutes: u64,
        /// Pages following the view's updates, as browser tabs do.
        #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u16).range(0..=64))]
        pages: u16,
    },
    /// Response-time analysis from step costs measured in QEMU on both machines: a latency
    /// bound per sensor, checked against every measured reaction; the tables also go to a
    /// JSON file.
    Timing {
        /// Core clock the cycle counts of every machine are converted at (default: each
        /// machine's own, 25 MHz on mps2-an386, 20 MHz on mps2-an505).
        #[arg(long)]
        clock_hz: Option<u64>,
        /// Where to write the JSON report (default `target/timing.json`).
        #[arg(long)]
        json: Option<std::path::PathBuf>,
        /// Succeed only if the analysis fails (to show that it can: a slow clock).
        #[arg(long)]
        expect_failure: bool,
    },
}

fn main() -> ExitCode {
    let task = Cli::parse().task;
    if let Task::Hil {
        files,
        json,
        calibrate,
        mutants,
        view,
        port,
    } = &task
    {
        if *view && let Err(e) = live::start(*port) {
            eprintln!("xtask hil: {e}");
            return ExitCode::from(2);
        }
        let mode = if *calibrate {
            hil::Mode::Calibrate
        } else if *mutants {
            hil::Mode::Mutants
        } else {
            hil::Mode::Check
        };
        let code = match hil::run(files, *json, mode) {
            hil::Ending::Passed => ExitCode::SUCCESS,
            // Names and paths from the files given may hold control characters: one line,
            // never raw.
            hil::Ending::Failed(e) => {
                eprintln!("xtask hil: {}", psmpa_sim::json::printable(&e));
                ExitCode::FAILURE
            }
            hil::Ending::BadInput(e) => {
                eprintln!("xtask hil: {}", psmpa_sim::json::printable(&e));
                ExitCode::from(2)
            }
        };
        // The bench's verdict is out; with --view, the page stays until interrupted.
        live::serve_on();
        return code;
    }
    if let Task::Wcet {
        json,
        mutants,
        emulated,
        ..
    } = &task
    {
        let ending = if *mutants {
            wcet::mutants::run()
        } else if *emulated {
            wcet::emulated::run()
        } else {
            wcet::run(*json)
        };
        return match ending {
            hil::Ending::Passed => ExitCode::SUCCESS,
            hil::Ending::Failed(e) => {
                eprintln!("xtask wcet: {e}");
                ExitCode::FAILURE
            }
            hil::Ending::BadInput(e) => {
                eprintln!("xtask wcet: {e}");
                ExitCode::from(2)
            }
        };
    }
    let result = match task {
        Task::Qemu {
            inject_fault,
            expect_failure,
        } => firmware::qemu_check(inject_fault).then_expect(expect_failure),
        Task::Size { bless } => size::run(bless),
        Task::Stack => stack::run(),
        Task::Experiment => experiment::run(),
        Task::ViewSoak { minutes, pages } => view_soak::run(minutes, usize::from(pages)),
        Task::Bench {
            instructions: true, ..
        } => bench::instructions(),
        Task::Bench { planning: true, .. } => planning::run(),
        Task::Bench { no_run, .. } => bench::run(no_run),
        Task::Timing {
            clock_hz,
            json,
            expect_failure,
        } => timing::run(clock_hz, json).then_expect(expect_failure),
        Task::Hil { .. } | Task::Wcet { .. } => Ok(()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: {e}");
            ExitCode::FAILURE
        }
    }
}

trait ThenExpect {
    fn then_expect(self, failure: bool) -> Result<(), String>;
}

impl ThenExpect for Result<(), String> {
    /// With `failure`, turns a failure into success and a success into a failure.
    fn then_expect(self, failure: bool) -> Result<(), String> {
        match (self, failure) {
            (r, false) => r,
            (Ok(()), true) => Err("the check passed, but a failure was expected".to_owned()),
            (Err(e), true) => {
                println!("the check failed, as expected: {e}");
                Ok(())
            }
        }
    }
}

//! `psmpa-sim`: the P-SMPA simulator's command line. The contract (`SIMULATION.md`): exit
//! status 0 when the simulation ran, whatever its outcome; 2 for bad input, with one line on
//! stderr naming the file and what is wrong; never a panic.

use std::fs::File;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Parser, Subcommand, ValueEnum};
use psmpa_sim::cli::{check, outputs, report, sweep, table1};
use psmpa_sim::load;
use psmpa_sim::robot::Arch;
use psmpa_sim::sim::{run_recorded, run_summary};

#[derive(Parser)]
#[command(
    name = "psmpa-sim",
    version,
    about = "Simulates the P-SMPA robot architecture against sequential SMPA (the paper's NAO go-to-door experiment)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Clone, Copy, ValueEnum)]
enum ArchArg {
    /// Sensors run in parallel with acting.
    Psmpa,
    /// Sensing and acting alternate.
    Smpa,
}

impl From<ArchArg> for Arch {
    fn from(a: ArchArg) -> Self {
        match a {
            ArchArg::Psmpa => Arch::PSmpa,
            ArchArg::Smpa => Arch::Smpa,
        }
    }
}

#[derive(Subcommand)]
enum Command {
    /// Runs one scenario file under one architecture.
    Run {
        /// Scenario file (JSON, see SIMULATION.md).
        scenario: PathBuf,
        /// Architecture.
        #[arg(long, value_enum)]
        arch: ArchArg,
        /// Print exactly one JSON object instead of text.
        #[arg(long)]
        json: bool,
        /// Write the trace (time, sensor readings, robot position, events) as CSV.
        #[arg(long, value_name = "FILE.csv")]
        trace: Option<PathBuf>,
        /// Plot sonar and bumper readings over time for both architectures (SVG).
        #[arg(long, value_name = "FILE.svg")]
        plot: Option<PathBuf>,
        /// Write a Chrome trace-event timeline of the behaviours (open in Perfetto).
        #[arg(long, value_name = "FILE.json")]
        timeline: Option<PathBuf>,
    },
    /// Validates a mission file and prints each plan's FSM with its parallel sensor sets.
    Check {
        /// Mission file (JSON, see missions/fetch-tea.json).
        mission: PathBuf,
        /// Also write the FSMs as a Graphviz graph.
        #[arg(long, value_name = "FILE.dot")]
        dot: Option<PathBuf>,
        /// Accept behaviour names this robot does not have (check the logic only).
        #[arg(long)]
        any_platform: bool,
    },
    /// Reproduces the paper's Table I: six scenarios under both architectures.
    Table1 {
        /// Print the rows as JSON.
        #[arg(long)]
        json: bool,
        /// Also write each row's plot as DIR/<scenario>.svg.
        #[arg(long, value_name = "DIR")]
        plots: Option<PathBuf>,
    },
    /// Runs randomized scenarios and prints summary statistics.
    Sweep {
        /// Number of scenarios (at most 1,000,000: the results are kept for the median).
        #[arg(long, default_value_t = 1000,
              value_parser = clap::value_parser!(u64).range(1..=psmpa_sim::cli::sweep::MAX_RUNS))]
        runs: u64,
        /// Seed of the scenario generator.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Run only this architecture (default: both).
        #[arg(long, value_enum)]
        arch: Option<ArchArg>,
        /// Print the statistics as JSON.
        #[arg(long)]
        json: bool,
    },
}

/// A failure and the exit status it gets.
struct Fail(u8, String);

fn bad_input(message: impl ToString) -> Fail {
    Fail(2, message.to_string())
}

fn internal(message: impl ToString) -> Fail {
    Fail(1, message.to_string())
}

fn write_to(path: &Path, mut file: File, content: &[u8]) -> Result<(), Fail> {
    file.write_all(content)
        .map_err(|e| bad_input(format!("{}: cannot write: {e}", path.display())))
}

fn write_file(path: &Path, content: &[u8]) -> Result<(), Fail> {
    std::fs::write(path, content)
        .map_err(|e| bad_input(format!("{}: cannot write: {e}", path.display())))
}

fn run(cli: Cli) -> Result<(), Fail> {
    match cli.command {
        Command::Run {
            scenario,
            arch,
            json,
            trace,
            plot,
            timeline,
        } => {
            let sc = load::load(&scenario).map_err(bad_input)?;
            let arch = Arch::from(arch);
            // Outputs are opened first: a bad path fails before any result is printed.
            let open = |path: &Option<PathBuf>| -> Result<Option<(PathBuf, File)>, Fail> {
                path.as_ref()
                    .map(|p| {
                        File::create(p)
                            .map(|f| (p.clone(), f))
                            .map_err(|e| bad_input(format!("{}: cannot write: {e}", p.display())))
                    })
                    .transpose()
            };
            let (trace, timeline) = (open(&trace)?, open(&timeline)?);
            let plot = open(&plot)?.map(|(p, _)| p);
            let recorded = if trace.is_some() || timeline.is_some() || plot.is_some() {
                Some(run_recorded(&sc, arch).map_err(internal)?)
            } else {
                None
            };
            let summary = match &recorded {
                Some(rec) => rec.summary.clone(),
                // Nothing to write: keep no event log (a long run would fill memory).
                None => run_summary(&sc, arch).map_err(internal)?,
            };
            if json {
                let j = report::RunJson::new(&sc, &summary);
                println!("{}", serde_json::to_string(&j).map_err(internal)?);
            } else {
                print!("{}", report::human(&sc, &summary));
            }
            if let Some(rec) = recorded {
                if let Some((path, file)) = trace {
                    write_to(&path, file, outputs::trace_csv(&sc, &rec).as_bytes())?;
                }
                if let Some((path, file)) = timeline {
                    let doc = serde_json::to_vec_pretty(&outputs::timeline(&sc, &rec))
                        .map_err(internal)?;
                    write_to(&path, file, &doc)?;
                }
                if let Some(path) = plot {
                    let other = run_recorded(
                        &sc,
                        if arch == Arch::PSmpa {
                            Arch::Smpa
                        } else {
                            Arch::PSmpa
                        },
                    )
                    .map_err(internal)?;
                    let mut both = [rec, other];
                    both.sort_by_key(|r| r.summary.arch != Arch::PSmpa);
                    outputs::plot(&path, &sc, &both)
                        .map_err(|e| bad_input(format!("{}: {e}", path.display())))?;
                }
            }
        }
        Command::Check {
            mission,
            dot,
            any_platform,
        } => {
            let bytes = std::fs::read(&mission).map_err(|e| {
                bad_input(format!("{}: cannot read the file: {e}", mission.display()))
            })?;
            // The mission borrows its names from the file for the life of the process.
            let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
            let (report, graph) = check::check(&mission, bytes, any_platform).map_err(bad_input)?;
            print!("{report}");
            if let Some(path) = dot {
                write_file(&path, graph.as_bytes())?;
            }
        }
        Command::Table1 { json, plots } => {
            let rows = table1::compute().map_err(internal)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&rows).map_err(internal)?);
            } else {
                print!("{}", table1::render(&rows));
            }
            if let Some(dir) = plots {
                std::fs::create_dir_all(&dir)
                    .map_err(|e| bad_input(format!("{}: {e}", dir.display())))?;
                for sc in table1::scenarios().map_err(internal)? {
                    let runs = [
                        run_recorded(&sc, Arch::PSmpa),
                        run_recorded(&sc, Arch::Smpa),
                    ];
                    let runs: Vec<_> = runs
                        .into_iter()
                        .collect::<Result<_, _>>()
                        .map_err(internal)?;
                    let path = dir.join(format!("{}.svg", sc.name.as_str()));
                    outputs::plot(&path, &sc, &runs)
                        .map_err(|e| bad_input(format!("{}: {e}", path.display())))?;
                }
            }
        }
        Command::Sweep {
            runs,
            seed,
            arch,
            json,
        } => {
            let arches = sweep::arches(arch.map(Arch::from));
            let stats = sweep::sweep(seed, runs, &arches, !json).map_err(internal)?;
            if json {
                println!(
                    "{}",
                    serde_json::to_string_pretty(&stats).map_err(internal)?
                );
            } else {
                print!("{}", sweep::render(&stats));
            }
        }
    }
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(Fail(code, message)) => {
            eprintln!("psmpa-sim: {message}");
            ExitCode::from(code)
        }
    }
}

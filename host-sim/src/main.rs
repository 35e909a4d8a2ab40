//! `psmpa-sim`: the P-SMPA simulator's command line. The contract (docs/simulator.md): exit
//! status 0 when the simulation ran, whatever its outcome (and when standard output was closed
//! by its reader); 2 for bad input or an output that cannot be written, with one line on
//! stderr naming the file and what is wrong; never a panic. Reading and writing go through
//! [`files`].

use std::cell::RefCell;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use clap::{Parser, Subcommand, ValueEnum};
use psmpa_sim::cli::files::{self, Output, Stop};
use psmpa_sim::cli::outputs::{Streams, TraceStream, WorldStream};
use psmpa_sim::cli::{check, outputs, plan, report, sensitivity, sweep, table1};
use psmpa_sim::robot::Arch;
use psmpa_sim::run::Summary;
use psmpa_sim::scenario::Scenario;
use psmpa_sim::sim::{
    Recorded, RunError, TraceRecord, WorldRecord, run_logged, run_logged_until, run_recorded,
    run_summary,
};
use psmpa_sim::view::server;
use psmpa_sim::view::source::{self, Pace, Shared};
use psmpa_sim::{json, load};

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

/// A platform whose sensors and behaviours `check --platform` requires.
#[derive(Clone, Copy, ValueEnum)]
enum CheckPlatform {
    /// The simulated NAO robot of the Fetch Tea scenarios (sonar, bumper, camera, handle).
    Nao,
}

#[derive(Subcommand)]
enum Command {
    /// Runs one scenario file under one architecture.
    Run {
        /// Scenario file (JSON; the format is in docs/simulator.md).
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
        /// Write an MCAP log for Foxglove: /sensor/<name> readings, /robot/pose, /events
        /// (JSON messages, log time = simulated time).
        #[arg(long, value_name = "FILE.mcap")]
        mcap: Option<PathBuf>,
        /// Write the run's flight recording (what the runtime consumed and decided, with the
        /// scenario), for `psmpa-sim replay`.
        #[arg(long, value_name = "FILE.rec")]
        record: Option<PathBuf>,
    },
    /// Replays a flight recording through the runtime with no world, the recorded readings and
    /// outcomes at their instants, and compares every decision. Exit status 0 when all match,
    /// 1 at the first divergence, 2 for a file that is not a whole recording of this mission.
    Replay {
        /// The recording (`run --record`), or a firmware's decoded log with its `rec` lines
        /// (the first recording in it).
        recording: PathBuf,
        /// Print exactly one JSON object: decisions, diverged, and the divergence.
        #[arg(long)]
        json: bool,
        /// Also write the replay's events as an MCAP log for Foxglove.
        #[arg(long, value_name = "FILE.mcap")]
        mcap: Option<PathBuf>,
        /// A chip's recording: an event may come up to this many ms earlier or later than
        /// recorded (the chip's computing takes time); all else must be equal, in order. 0
        /// (the default): bit for bit, instants included.
        #[arg(long, value_name = "MS", default_value_t = 0, allow_negative_numbers = true,
              value_parser = clap::value_parser!(u32).range(0..=60_000))]
        lag_ms: u32,
        /// Instead of comparing, play the recording's events at their instants in the live
        /// view (as `psmpa-sim view`), and serve it until interrupted.
        #[arg(long, conflicts_with_all = ["json", "mcap", "lag_ms"])]
        view: bool,
        #[command(flatten)]
        serve: ServeArgs,
    },
    /// Shows the running mission live in a web page: the simulator running SCENARIO, paced to
    /// real time times --speed, or a frame stream (`--frames -`: a recording, or a board's
    /// decoded defmt log with its `rec` lines, on standard input). Serves `/` (the page) and
    /// `/snapshot` (JSON) until interrupted; prints the page's address on standard output.
    View {
        /// Scenario file (JSON) to run.
        #[arg(required_unless_present = "frames", conflicts_with = "frames")]
        scenario: Option<PathBuf>,
        /// Architecture.
        #[arg(long, value_enum, default_value = "psmpa")]
        arch: ArchArg,
        /// Read the recorder's frames from standard input (`-`) as they come, instead of
        /// running a scenario: the page cannot pause them.
        #[arg(long, value_name = "-", value_parser = stdin_only,
              conflicts_with_all = ["arch", "speed", "paused", "repeat"])]
        frames: Option<String>,
        /// Run the scenario this many times back to back, virtual time going on (a long run
        /// from a short scenario: `cargo xtask view-soak` measures the view on one).
        #[arg(long, default_value_t = 1, value_name = "N",
              value_parser = clap::value_parser!(u64).range(1..))]
        repeat: u64,
        #[command(flatten)]
        serve: ServeArgs,
    },
    /// Validates a mission file and prints each plan's FSM with its parallel sensor sets.
    Check {
        /// Mission file (JSON, see missions/fetch-tea.json).
        mission: PathBuf,
        /// Also write the FSMs as a Graphviz graph.
        #[arg(long, value_name = "FILE.dot")]
        dot: Option<PathBuf>,
        /// Also check that a platform has every sensor and behaviour the mission names (by
        /// default any names are accepted: the mission's logic is checked, whatever robot it
        /// is for).
        #[arg(long, value_enum, value_name = "PLATFORM")]
        platform: Option<CheckPlatform>,
        /// The default; kept so that older scripts still run.
        #[arg(long, hide = true)]
        any_platform: bool,
    },
    /// Plans from a mission's task init to its goal with the mission's actions (sensors and
    /// library plans play no part). Capacities: 256 facts, 4,096 actions, 917,503 search
    /// nodes. Exit status 0 with a plan, 1 without one, 2 for bad input.
    Plan {
        /// Mission file (JSON); `sensors` and `plans` may be empty.
        mission: PathBuf,
        /// How to search.
        #[arg(long, value_enum, default_value = "bfs")]
        search: plan::Method,
        /// Most nodes to generate, the start included (at most 917,503).
        #[arg(long, allow_negative_numbers = true, value_parser = clap::value_parser!(u32).range(1..=i64::from(plan::BUDGET)))]
        budget: Option<u32>,
        /// Most seconds of search (1 to 86,400): when it runs out the search ends as when
        /// the node budget does (status 1, `budget`). A node costs at most one heuristic
        /// estimate past it.
        #[arg(long, allow_negative_numbers = true, value_name = "SECONDS", default_value_t = plan::TIME_LIMIT_S,
              value_parser = clap::value_parser!(u32).range(1..=86_400))]
        time_limit: u32,
        /// Print exactly one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Reproduces the paper's Table I: six scenarios under both architectures.
    Table1 {
        /// Print the rows as JSON.
        #[arg(long)]
        json: bool,
        /// Runs of each row with its interference instants shifted by a random offset within
        /// one SMPA cycle (1 to 100,000).
        #[arg(long, allow_negative_numbers = true, default_value_t = psmpa_sim::cli::table1::SHIFTS,
              value_parser = clap::value_parser!(u32).range(1..=100_000))]
        shifts: u32,
        /// Also write each row's plot as DIR/<scenario>.svg.
        #[arg(long, value_name = "DIR")]
        plots: Option<PathBuf>,
    },
    /// Runs randomized scenarios and prints summary statistics.
    Sweep {
        /// Number of scenarios (at most 1,000,000).
        #[arg(long, allow_negative_numbers = true, default_value_t = 1000, value_parser = sweep_runs)]
        runs: u64,
        /// Seed of the scenario generator.
        #[arg(long, allow_negative_numbers = true, default_value_t = 1, value_parser = whole)]
        seed: u64,
        /// Run only this architecture (default: both).
        #[arg(long, value_enum)]
        arch: Option<ArchArg>,
        /// Print the statistics as JSON.
        #[arg(long)]
        json: bool,
        /// Also write one run of the sweep as an MCAP log for Foxglove (as `run --mcap`).
        #[arg(long, value_name = "FILE.mcap")]
        mcap: Option<PathBuf>,
        /// The scenario written by --mcap: N of sweep-SEED-N, from 0 to runs - 1.
        #[arg(long, allow_negative_numbers = true, value_name = "N", default_value_t = 0,
              requires = "mcap", value_parser = whole)]
        mcap_run: u64,
        /// The architecture written by --mcap (default: --arch, or psmpa when the sweep runs
        /// both).
        #[arg(long, value_enum, value_name = "ARCH", requires = "mcap")]
        mcap_arch: Option<ArchArg>,
    },
    /// How SMPA's settings change the comparison with P-SMPA (a sensitivity study).
    ///
    /// A grid of sense fraction (10 % to 90 %) x cycle length (0.5 s to 6 s), every cell on the
    /// same random worlds, clean and again with sensor faults and read latencies. P-SMPA runs
    /// once a world, SMPA once a world a cell. Per cell: SMPA's detection rate (of the
    /// obstacles detectable in the world's P-SMPA run; also of those it met), collisions per
    /// run, and the time ratio SMPA / P-SMPA over the worlds where both reached the door (the
    /// others are left out and counted); P-SMPA's rates and collisions. Each with a 95 %
    /// interval: mean ± 1.96·sd/√n over the runs.
    Sensitivity {
        /// Random worlds per cell (at most 100,000); each runs once under P-SMPA and once per
        /// cell under SMPA, clean and with faults.
        #[arg(long, allow_negative_numbers = true, default_value_t = 1000,
              value_parser = sensitivity_runs)]
        runs: u64,
        /// Seed of the world generator.
        #[arg(long, allow_negative_numbers = true, default_value_t = 1, value_parser = whole)]
        seed: u64,
        /// Print exactly one JSON object (docs/simulator.md describes its shape).
        #[arg(long)]
        json: bool,
        /// Also plot detection rate and time ratio against the sense fraction (SVG).
        #[arg(long, value_name = "FILE.svg")]
        plot: Option<PathBuf>,
    },
}

/// Where and how the live view serves (`view`, `replay --view`).
#[derive(clap::Args)]
struct ServeArgs {
    /// Port to serve on; 0 picks a free one (the address printed says which).
    #[arg(long, default_value_t = 8077, value_name = "N")]
    port: u16,
    /// Address to listen on: the machine alone by default; 0.0.0.0 shows the page to the
    /// network (it can pause and step the simulator, never command a robot).
    #[arg(long, default_value = "127.0.0.1", value_name = "ADDR")]
    bind: String,
    /// Virtual time at this many times real time (0.01 to 10,000), for the simulator and a
    /// replay; the page can change it.
    #[arg(long, default_value_t = 1.0, value_name = "X", value_parser = speed)]
    speed: f64,
    /// Start paused (the page resumes or steps).
    #[arg(long)]
    paused: bool,
}

/// `--speed`: a number from 0.01 to 10,000.
fn speed(text: &str) -> Result<f64, String> {
    let (lo, hi) = psmpa_sim::view::source::SPEEDS;
    match text.parse::<f64>() {
        Ok(x) if (lo..=hi).contains(&x) => Ok(x),
        _ => Err(format!("must be a number from {lo} to {hi}")),
    }
}

/// `--frames`: standard input only.
fn stdin_only(text: &str) -> Result<String, String> {
    if text == "-" {
        Ok(text.to_owned())
    } else {
        Err("must be - (standard input)".to_owned())
    }
}

/// Serves the live view from `source` (run on its own thread) on the address `serve` asks
/// for; prints the page's address first. Runs until the process is interrupted.
fn view(
    serve: &ServeArgs,
    mission: psmpa_sim::robot::FetchTea<'static>,
    name: String,
    pace: bool,
    source: impl FnOnce(&Arc<Shared>) + Send + 'static,
) -> Result<(), Stop> {
    let bind: std::net::IpAddr = serve
        .bind
        .parse()
        .map_err(|_| Stop::Bad(format!("--bind: not an IP address: {}", serve.bind)))?;
    let listener = server::listen(bind, serve.port).map_err(Stop::Bad)?;
    let addr = listener
        .local_addr()
        .map_err(|e| Stop::Bad(format!("cannot listen: {e}")))?;
    let shared = Arc::new(Shared {
        view: std::sync::Mutex::new(psmpa_sim::view::model::View::new(mission)),
        pace: pace.then(|| Pace::new(serve.speed, serve.paused)),
        source: name,
    });
    files::print(format!("psmpa-sim view: http://{addr}/\n").as_bytes())?;
    let feeding = Arc::clone(&shared);
    std::thread::Builder::new()
        .name("view-source".into())
        .spawn(move || source(&feeding))
        .map_err(|e| Stop::Resource(format!("cannot start the view's source: {e}")))?;
    server::serve(listener, shared).map_err(Stop::Bad)
}

/// A whole number from 0 to 2^64 - 1 (a seed, a run's number), with a message that says so.
fn whole(text: &str) -> Result<u64, String> {
    if text.starts_with('-') {
        return Err("must not be negative".to_owned());
    }
    text.parse()
        .map_err(|_| format!("must be a whole number from 0 to {}", u64::MAX))
}

/// `sweep --runs`: 1 to [`sweep::MAX_RUNS`].
fn sweep_runs(text: &str) -> Result<u64, String> {
    let max = sweep::MAX_RUNS;
    match whole(text) {
        Ok(n) if (1..=max).contains(&n) => Ok(n),
        _ => Err(format!("must be a whole number from 1 to {max}")),
    }
}

/// `sensitivity --runs`: 1 to [`sensitivity::MAX_RUNS`].
fn sensitivity_runs(text: &str) -> Result<u64, String> {
    let max = sensitivity::MAX_RUNS;
    match whole(text) {
        Ok(n) if (1..=max).contains(&n) => Ok(n),
        _ => Err(format!("must be a whole number from 1 to {max}")),
    }
}

fn create(path: Option<&Path>) -> Result<Option<Output>, Stop> {
    path.map(Output::create).transpose().map_err(Stop::Bad)
}

fn run(cli: Cli) -> Result<(), Stop> {
    match cli.command {
        Command::Run {
            scenario,
            arch,
            json,
            trace,
            plot,
            timeline,
            mcap,
            record,
        } => {
            let bytes = files::read_input(&scenario, "scenario").map_err(Stop::Bad)?;
            let sc = load::parse(&scenario, &bytes).map_err(Stop::bad)?;
            let arch = Arch::from(arch);
            let mut named = vec![("the scenario", scenario.as_path())];
            for (flag, path) in [
                ("--trace", &trace),
                ("--plot", &plot),
                ("--timeline", &timeline),
                ("--mcap", &mcap),
                ("--record", &record),
            ] {
                named.extend(path.as_deref().map(|p| (flag, p)));
            }
            files::distinct(&named).map_err(Stop::Bad)?;
            if json {
                files::not_into_json(named.get(1..).unwrap_or_default()).map_err(Stop::Bad)?;
            }
            if plot.is_some() {
                outputs::plot_fits(&sc).map_err(Stop::Bad)?;
            }
            // Outputs are opened before the run: a bad path fails before anything runs.
            let (mut trace, mut timeline) =
                (create(trace.as_deref())?, create(timeline.as_deref())?);
            let plot = create(plot.as_deref())?;
            let mut mcap = create(mcap.as_deref())?;
            let mut record = create(record.as_deref())?;
            // A streamed output that fails stops the run at once (`--trace /dev/full`).
            let failed = Arc::new(AtomicBool::new(false));
            for out in [&mut trace, &mut timeline, &mut mcap, &mut record]
                .into_iter()
                .flatten()
            {
                out.alarm(Arc::clone(&failed));
            }
            warn_of_size(&sc, trace.is_some(), mcap.is_some());
            let (summary, done) = if trace.is_none()
                && timeline.is_none()
                && plot.is_none()
                && mcap.is_none()
                && record.is_none()
            {
                // Nothing to write: keep no event log.
                (run_summary(&sc, arch).map_err(Stop::internal)?, Vec::new())
            } else {
                let mut streams = Streams::new(&sc, arch, trace, timeline, plot.is_some());
                if let Some(out) = mcap {
                    streams = streams.with_mcap(out, &sc).map_err(Stop::Bad)?;
                }
                if let Some(out) = record {
                    streams = streams.with_record(out, &bytes, arch);
                }
                let streams = RefCell::new(streams);
                let (summary, _, _) = match run_logged_until(
                    &sc,
                    arch,
                    WorldStream(&streams),
                    TraceStream(&streams),
                    || failed.load(Ordering::Relaxed),
                ) {
                    Ok(done) => done,
                    Err(RunError::Stopped) => {
                        return Err(Stop::Bad(first_write_error(streams.into_inner())));
                    }
                    Err(e) => return Err(Stop::internal(e)),
                };
                let (done, world) = streams
                    .into_inner()
                    .finish(summary.time_cost_ms)
                    .map_err(Stop::Bad)?;
                let mut done = done;
                if let Some(out) = plot {
                    done.push(plot_both(out, world, &summary, &sc)?);
                }
                (summary, done)
            };
            let text = if json {
                let j = report::RunJson::new(&sc, &summary);
                serde_json::to_string(&j).map_err(Stop::internal)? + "\n"
            } else {
                report::human(&sc, &summary)
            };
            files::print_and_commit(text.as_bytes(), done)?;
        }
        Command::Replay {
            recording,
            json,
            mcap,
            lag_ms,
            view,
            serve,
        } => {
            if let Some(out) = &mcap {
                files::distinct(&[("the recording", &recording), ("--mcap", out)])
                    .map_err(Stop::Bad)?;
                if json {
                    files::not_into_json(&[("--mcap", out)]).map_err(Stop::Bad)?;
                }
            }
            let mcap = create(mcap.as_deref())?;
            let bytes =
                files::read_limited(&recording, "recording", psmpa_sim::replay::MAX_RECORDING)
                    .map_err(Stop::Bad)?;
            let bytes = psmpa_sim::replay::bytes_of(&recording, bytes).map_err(Stop::Bad)?;
            let rec = psmpa_sim::replay::read(&recording, &bytes).map_err(Stop::Bad)?;
            if view {
                let mission = source::mission_of(&rec).map_err(Stop::internal)?;
                let name = format!("the recording {}", recording.display());
                return self::view(&serve, mission, name, true, move |shared| {
                    source::play(&rec, shared);
                });
            }
            let (result, log) = psmpa_sim::replay::replay(
                &rec,
                mcap,
                embassy_time::Duration::from_millis(lag_ms.into()),
            )
            .map_err(Stop::internal)?;
            let text = if json {
                serde_json::to_string(&result).map_err(Stop::internal)? + "\n"
            } else {
                result.text()
            };
            let printed = files::print_and_commit(text.as_bytes(), log);
            // A divergence is status 1 even when the reader has gone.
            if result.diverged {
                return Err(match printed {
                    Err(Stop::Bad(m)) => Stop::Bad(m),
                    _ => Stop::NoPlan,
                });
            }
            printed?;
        }
        Command::View {
            scenario,
            arch,
            frames,
            repeat,
            serve,
        } => {
            let Some(scenario) = scenario.filter(|_| frames.is_none()) else {
                let mission = source::fetch_tea_names().map_err(|e| {
                    Stop::internal(format!("the mission could not be built: {e:?}"))
                })?;
                return view(
                    &serve,
                    mission,
                    "frames on standard input".into(),
                    false,
                    |shared| {
                        source::stdin_frames(shared);
                    },
                );
            };
            let bytes = files::read_input(&scenario, "scenario").map_err(Stop::Bad)?;
            let sc = load::parse(&scenario, &bytes).map_err(Stop::bad)?;
            let arch = Arch::from(arch);
            let mission = psmpa_sim::robot::fetch_tea(&sc)
                .map_err(|e| Stop::bad(format!("{}: {e:?}", scenario.display())))?
                .mission;
            let name = format!("{} under {}", sc.name, arch.name());
            return view(&serve, mission, name, true, move |shared| {
                source::simulate(&sc, arch, repeat, shared);
            });
        }
        Command::Check {
            mission,
            dot,
            platform,
            any_platform: _,
        } => {
            let any_platform = platform.is_none();
            let bytes = files::read_input(&mission, "mission").map_err(Stop::Bad)?;
            if let Some(dot) = &dot {
                files::distinct(&[("the mission", &mission), ("--dot", dot)]).map_err(Stop::Bad)?;
            }
            let dot = create(dot.as_deref())?;
            // The mission borrows its names from the file for the life of the process.
            let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
            let (report, graph, warnings) =
                check::check(&mission, bytes, any_platform).map_err(Stop::Bad)?;
            // Valid, so status 0; what is most likely a mistake, said before the report.
            for w in warnings {
                eprintln!("psmpa-sim: warning: {w}");
            }
            let dot = dot.map(|mut out| {
                // An `Output` keeps a write error for its commit.
                let _ = out.write_all(graph.as_bytes());
                out
            });
            // Names are shown as the file has them; a control character (DEL, C1) escaped.
            let shown: String = report.lines().map(|l| json::printable(l) + "\n").collect();
            files::print_and_commit(shown.as_bytes(), dot)?;
        }
        Command::Plan {
            mission,
            search,
            budget,
            time_limit,
            json,
        } => {
            let bytes = files::read_input(&mission, "mission").map_err(Stop::Bad)?;
            let limits = plan::Limits {
                budget,
                time: std::time::Duration::from_secs(u64::from(time_limit)),
            };
            let outcome = plan::plan(&mission, &bytes, search, limits)?;
            let text = if json {
                serde_json::to_string(&outcome).map_err(Stop::internal)? + "\n"
            } else {
                // Action names as `check` shows them: a control or bidi character escaped.
                outcome
                    .text()
                    .lines()
                    .map(|l| json::printable(l) + "\n")
                    .collect()
            };
            let printed = files::print(text.as_bytes());
            // No plan is status 1 even when the reader has gone.
            if outcome.plan.is_none() {
                return Err(match printed {
                    Err(Stop::Bad(m)) => Stop::Bad(m),
                    _ => Stop::NoPlan,
                });
            }
            printed?;
        }
        Command::Table1 {
            json,
            shifts,
            plots,
        } => {
            psmpa_sim::cli::workers()?;
            // The folder is checked before the work and made only for the files at the end.
            if let Some(dir) = &plots {
                files::writable_folder(dir).map_err(Stop::Bad)?;
            }
            let rows = table1::compute(shifts).map_err(Stop::internal)?;
            let mut svgs = Vec::new();
            if let Some(dir) = &plots {
                for sc in table1::scenarios().map_err(Stop::internal)? {
                    let path = dir.join(format!("{}.svg", sc.name.as_str()));
                    let runs = [
                        run_recorded(&sc, Arch::PSmpa).map_err(Stop::internal)?,
                        run_recorded(&sc, Arch::Smpa).map_err(Stop::internal)?,
                    ];
                    let svg = outputs::plot(&sc, &runs)
                        .map_err(|e| Stop::bad(format!("{}: {e}", path.display())))?;
                    svgs.push((path, svg));
                }
            }
            let text = if json {
                serde_json::to_string_pretty(&rows).map_err(Stop::internal)? + "\n"
            } else {
                table1::render(&rows)
            };
            let made = match &plots {
                Some(dir) => files::make_folder(dir).map_err(Stop::Bad)?,
                None => None,
            };
            let written = (|| {
                let mut done = Vec::new();
                for (path, svg) in &svgs {
                    let mut out = Output::create(path).map_err(Stop::Bad)?;
                    let _ = out.write_all(svg.as_bytes());
                    done.push(out);
                }
                files::print_and_commit(text.as_bytes(), done)
            })();
            if let (Err(Stop::Bad(_)), Some(top)) = (&written, &made) {
                // Nothing was put in place: the folders this command made go too.
                let _ = std::fs::remove_dir_all(top);
            }
            written?;
        }
        Command::Sweep {
            runs,
            seed,
            arch,
            json,
            mcap,
            mcap_run,
            mcap_arch,
        } => {
            let arches = sweep::arches(arch.map(Arch::from));
            // The chosen run is streamed first, on its own: a run depends only on the seed,
            // its number and the architecture, so it is the one the sweep runs.
            let log = match mcap {
                Some(path) => {
                    let arch = sweep::mcap_arch(&arches, mcap_arch.map(Arch::from), mcap_run, runs)
                        .map_err(Stop::Bad)?;
                    let out = Output::create(&path).map_err(Stop::Bad)?;
                    Some(log_run(out, &sweep::scenario(seed, mcap_run), arch)?)
                }
                None => None,
            };
            psmpa_sim::cli::workers()?;
            let stats = sweep::sweep(seed, runs, &arches, !json).map_err(Stop::internal)?;
            let text = if json {
                serde_json::to_string_pretty(&stats).map_err(Stop::internal)? + "\n"
            } else {
                sweep::render(&stats)
            };
            files::print_and_commit(text.as_bytes(), log)?;
        }
        Command::Sensitivity {
            runs,
            seed,
            json,
            plot,
        } => {
            // Opened before the study: a bad path fails before anything runs.
            let plot = create(plot.as_deref())?;
            psmpa_sim::cli::workers()?;
            let study = sensitivity::study(seed, runs, true).map_err(Stop::internal)?;
            let plot = match plot {
                Some(mut out) => {
                    let svg = sensitivity::plot(&study)
                        .map_err(|e| Stop::bad(format!("{}: {e}", out.path().display())))?;
                    // An `Output` keeps a write error for its commit.
                    let _ = out.write_all(svg.as_bytes());
                    Some(out)
                }
                None => None,
            };
            let text = if json {
                serde_json::to_string_pretty(&study).map_err(Stop::internal)? + "\n"
            } else {
                sensitivity::render(&study)
            };
            files::print_and_commit(text.as_bytes(), plot)?;
        }
    }
    Ok(())
}

/// The first write error of a run's streamed outputs, as one line.
fn first_write_error(streams: Streams) -> String {
    match streams.finish(0) {
        Err(e) => e,
        Ok((outputs, _)) => outputs
            .into_iter()
            .find_map(|mut o| o.finish().err())
            .unwrap_or_else(|| "an output could not be written".to_owned()),
    }
}

/// Output bytes a sample takes, at most about (measured on a 1 ms sonar and bumper: 122 B of
/// CSV and 191 B of MCAP a sample, with the world's events); the timeline grows with events,
/// not samples.
const CSV_PER_SAMPLE: u64 = 128;
const MCAP_PER_SAMPLE: u64 = 192;
/// Above this estimate `run` warns before it starts.
const WARN_BYTES: u64 = 1 << 30;

/// One line on stderr when the outputs asked for may exceed [`WARN_BYTES`] (a day at 1 ms
/// samples is over 20 GB of CSV); the run goes on.
fn warn_of_size(sc: &Scenario, csv: bool, mcap: bool) {
    let samples = [sc.sonar.period_ms, sc.bumper_period_ms]
        .iter()
        .map(|p| sc.max_ms / (*p).max(1))
        .sum::<u64>();
    let per = u64::from(csv) * CSV_PER_SAMPLE + u64::from(mcap) * MCAP_PER_SAMPLE;
    let bytes = samples.saturating_mul(per);
    if bytes > WARN_BYTES {
        say(&format!(
            "warning: the outputs may take up to about {:.1} GB ({samples} samples of {} s)",
            bytes as f64 / 1e9,
            outputs::seconds_text(sc.max_ms)
        ));
    }
}

/// Streams a run of `sc` under `arch` into the MCAP log `out` alone; gives it back to commit.
fn log_run(out: Output, sc: &Scenario, arch: Arch) -> Result<Output, Stop> {
    let streams = Streams::new(sc, arch, None, None, false)
        .with_mcap(out, sc)
        .map_err(Stop::Bad)?;
    let streams = RefCell::new(streams);
    let (summary, _, _) = run_logged(sc, arch, WorldStream(&streams), TraceStream(&streams))
        .map_err(Stop::internal)?;
    let (done, _) = streams
        .into_inner()
        .finish(summary.time_cost_ms)
        .map_err(Stop::Bad)?;
    done.into_iter()
        .next()
        .ok_or_else(|| Stop::internal("the MCAP log was lost"))
}

/// Draws the plot of a streamed run beside a recorded run of the other architecture, and
/// adds it to the outputs to commit.
fn plot_both(
    out: Output,
    world: Option<WorldRecord>,
    summary: &Summary,
    sc: &Scenario,
) -> Result<Output, Stop> {
    let mut out = out;
    let other = match summary.arch {
        Arch::PSmpa => Arch::Smpa,
        Arch::Smpa => Arch::PSmpa,
    };
    let this = Recorded {
        summary: summary.clone(),
        world: world.unwrap_or_default(),
        trace: TraceRecord::default(),
    };
    let mut both = [this, run_recorded(sc, other).map_err(Stop::internal)?];
    both.sort_by_key(|r| r.summary.arch != Arch::PSmpa);
    let svg = outputs::plot(sc, &both)
        .map_err(|e| Stop::bad(format!("{}: {e}", out.path().display())))?;
    // An `Output` keeps a write error for its commit.
    let _ = out.write_all(svg.as_bytes());
    Ok(out)
}

/// One line on standard error; control characters (from a file name or an argument) are
/// shown escaped, never sent to the terminal, and a long word quoted from the input is
/// shortened ([`shorten`]).
fn say(message: &str) {
    let _ = writeln!(
        std::io::stderr().lock(),
        "psmpa-sim: {}",
        shorten(&json::printable(message))
    );
}

/// A word (a run without spaces) longer than [`LONG_WORD`] bytes shown as its first 48 and
/// last 16 bytes, with how many were left out: an error quotes names and keys from the input,
/// which may be a megabyte long.
fn shorten(line: &str) -> String {
    let mut out = String::with_capacity(line.len().min(4 * LONG_WORD));
    for (i, word) in line.split(' ').enumerate() {
        if i > 0 {
            out.push(' ');
        }
        if word.len() <= LONG_WORD {
            out.push_str(word);
            continue;
        }
        let head = (0..=48)
            .rev()
            .find(|&i| word.is_char_boundary(i))
            .unwrap_or(0);
        let tail = (word.len() - 16..word.len())
            .find(|&i| word.is_char_boundary(i))
            .unwrap_or(word.len());
        out.push_str(&format!(
            "{}...({} bytes)...{}",
            &word[..head],
            tail - head,
            &word[tail..]
        ));
    }
    out
}

/// The longest word [`say`] shows whole, bytes.
const LONG_WORD: usize = 100;

/// clap's message for a bad command line, in one line; help and version as clap prints them.
fn usage_error(e: &clap::Error) -> ExitCode {
    use clap::error::ErrorKind;
    let text = e.render().to_string();
    match e.kind() {
        ErrorKind::DisplayHelp | ErrorKind::DisplayVersion => {
            return match files::print(text.as_bytes()) {
                Ok(()) | Err(Stop::ClosedPipe) => ExitCode::SUCCESS,
                Err(Stop::NoPlan) => ExitCode::from(1),
                Err(Stop::Bad(m) | Stop::Internal(m) | Stop::Resource(m)) => {
                    say(&m);
                    ExitCode::from(2)
                }
            };
        }
        ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => {
            say(
                "no command given: run, check, plan, table1, sweep or sensitivity (see psmpa-sim --help)",
            );
        }
        _ => {
            // "error: ..." and its notes and tips, up to the usage clap would print.
            let mut line = String::new();
            for l in text
                .lines()
                .map(str::trim)
                .take_while(|l| !l.starts_with("Usage:") && !l.starts_with("For more"))
                .filter(|l| !l.is_empty())
            {
                if !line.is_empty() {
                    line.push_str(if line.ends_with(':') { " " } else { "; " });
                }
                line.push_str(l.strip_prefix("error: ").unwrap_or(l));
            }
            say(&format!("{line} (see psmpa-sim --help)"));
        }
    }
    ExitCode::from(2)
}

fn main() -> ExitCode {
    files::clean_up_on_interrupt();
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => return usage_error(&e),
    };
    match run(cli) {
        Ok(()) | Err(Stop::ClosedPipe) => ExitCode::SUCCESS,
        Err(Stop::NoPlan) => ExitCode::from(1),
        Err(Stop::Bad(message)) => {
            say(&message);
            ExitCode::from(2)
        }
        Err(Stop::Internal(message)) => {
            say(&message);
            ExitCode::from(1)
        }
        Err(Stop::Resource(message)) => {
            say(&message);
            ExitCode::from(3)
        }
    }
}

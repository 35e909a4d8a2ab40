//! Building and running the firmware, and comparing it with the host.

use std::collections::BTreeMap;
use std::hash::{DefaultHasher, Hash, Hasher};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use psmpa_sim::robot::Arch;
use psmpa_sim::sim::run_summary;

use crate::recording;
use crate::trace::{self, Allowance};

/// The workspace root.
pub fn root() -> PathBuf {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    root.canonicalize().unwrap_or(root)
}

/// `cargo` as this task was started with (`$CARGO`), run from the workspace root, building
/// into the workspace's `target/` whatever `CARGO_TARGET_DIR` says: the tasks read what they
/// build there (criterion's results, the profiles' callgrind files, the firmware's ELFs).
pub fn cargo() -> Command {
    cargo_in(&root())
}

/// `cargo` run from the package or workspace at `dir`, building into its own `target/`.
pub fn cargo_in(dir: &Path) -> Command {
    let mut cmd = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    cmd.current_dir(dir)
        .env("CARGO_TARGET_DIR", dir.join("target"));
    cmd
}

/// Builds the simulator's command line in release mode and returns its path.
pub fn build_host_sim() -> Result<PathBuf, String> {
    build_executable(
        &["--release", "-p", "psmpa-sim", "--bin", "psmpa-sim"],
        "psmpa-sim",
    )
}

/// Runs `cargo build` with `args` and returns the path of the executable `name` it built, from
/// cargo's own report.
pub fn build_executable(args: &[&str], name: &str) -> Result<PathBuf, String> {
    let out = cargo()
        .arg("build")
        .args(args)
        .arg("--message-format=json-render-diagnostics")
        .stderr(Stdio::inherit())
        .output()
        .map_err(|e| format!("cannot run cargo: {e}"))?;
    if !out.status.success() {
        return Err(format!("{name} does not build"));
    }
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|m| m["reason"] == "compiler-artifact" && m["target"]["name"] == name)
        .find_map(|m| m["executable"].as_str().map(PathBuf::from))
        .ok_or_else(|| format!("cargo reported no {name} executable"))
}

/// A QEMU machine the firmware runs on, and the target it is built for to run there
/// (`firmware/build.rs` picks the board's constants and memory map from the target).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Machine {
    /// QEMU's `-machine`.
    pub name: &'static str,
    /// Its core.
    pub core: &'static str,
    /// The Rust target of its images.
    pub target: &'static str,
    /// The clock its timers count, Hz: the unit of every cycle the firmware logs
    /// (`firmware/src/board.rs`, `CORE_HZ`).
    pub clock_hz: u64,
}

/// QEMU's Cortex-M4F board.
pub const AN386: Machine = Machine {
    name: "mps2-an386",
    core: "Cortex-M4F",
    target: "thumbv7em-none-eabihf",
    clock_hz: 25_000_000,
};

/// QEMU's Cortex-M33 board (the RP2350's core family, not its peripherals).
pub const AN505: Machine = Machine {
    name: "mps2-an505",
    core: "Cortex-M33",
    target: "thumbv8m.main-none-eabihf",
    clock_hz: 20_000_000,
};

/// Every machine `cargo xtask qemu` and `cargo xtask timing` run the firmware on.
pub const MACHINES: [Machine; 2] = [AN386, AN505];

/// QEMU's `-icount shift=5`: virtual time advances 32 ns per instruction.
const NS_PER_INSTRUCTION: u64 = 32;

impl Machine {
    /// Core cycles per 1 kHz tick.
    pub fn cycles_per_tick(self) -> u64 {
        self.clock_hz / 1_000
    }

    /// The instructions QEMU executed in `cycles` of this machine's timers (`-icount`: 32 ns
    /// each), the one unit in which both machines' costs compare.
    pub fn instructions(self, cycles: u64) -> u64 {
        cycles.saturating_mul(1_000_000_000) / self.clock_hz / NS_PER_INSTRUCTION
    }
}

/// The target `cargo xtask size` and `cargo xtask stack` measure: mps2-an386's.
pub const TARGET: &str = AN386.target;
/// The firmware's cargo profile.
pub const PROFILE: &str = "firmware";

/// Paths in panic locations, mapped to fixed prefixes: sizes do not depend on where the
/// registry or the checkout lives.
pub fn rustflags() -> String {
    let cargo_home = std::env::var("CARGO_HOME")
        .map(PathBuf::from)
        .unwrap_or_else(|_| {
            PathBuf::from(std::env::var("HOME").unwrap_or_default()).join(".cargo")
        });
    let root = root();
    let mut flags = vec![format!(
        "--remap-path-prefix={}=cargo",
        cargo_home.display()
    )];
    // Each registry's sources, shorter still (the last matching prefix wins): about 50 bytes
    // of flash less per crate with a panic location.
    let sources = cargo_home.join("registry/src");
    let mut registries: Vec<PathBuf> = std::fs::read_dir(&sources)
        .map(|dir| dir.filter_map(|e| Some(e.ok()?.path())).collect())
        .unwrap_or_default();
    registries.sort();
    flags.extend(
        registries
            .iter()
            .map(|r| format!("--remap-path-prefix={}=crates", r.display())),
    );
    flags.push(format!("--remap-path-prefix={}=psmpa", root.display()));
    // Symbol names with their generic arguments: `cargo xtask stack` tells the two executors'
    // tasks apart by them.
    flags.push("-Csymbol-mangling-version=v0".to_owned());
    flags.join("\x1f")
}

/// Runs the `inject-fault` product image, which overflows its stack at boot: `true` when it
/// faulted (flip-link: the stack runs off the start of RAM; QEMU stops on the lockup).
fn stack_overflow_faults(machine: Machine, elf: &Path) -> Result<bool, String> {
    match run_on(machine, elf) {
        Ok(log) => {
            println!("psmpa-product ran to its end with its stack overflowed:\n{log}");
            Ok(false)
        }
        Err(e) if e.contains("goal reached") => {
            println!("psmpa-product ran on with its stack overflowed: {e}");
            Ok(false)
        }
        // QEMU aborts on the lockup (SIGABRT: 134 through the pipe).
        Err(e) if e.contains("exit Some(134)") => {
            println!("psmpa-product: the stack overflow at boot faulted (lockup), as it must");
            Ok(true)
        }
        Err(e) => {
            // Not the failure wanted: the check must not count it as one.
            println!("psmpa-product failed otherwise than by a fault on its stack overflow: {e}");
            Ok(false)
        }
    }
}

/// A board of `boards/` (a workspace of its own, one target folder `boards/target`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Board {
    /// Its crate and image.
    pub name: &'static str,
    /// Its folder under `boards/`.
    pub dir: &'static str,
    /// The target its `.cargo/config.toml` builds for.
    pub target: &'static str,
    /// The board, for messages.
    pub what: &'static str,
}

/// The Raspberry Pi Pico 2 (RP2350A, Cortex-M33).
pub const PICO2: Board = Board {
    name: "psmpa-pico2",
    dir: "pico2",
    target: "thumbv8m.main-none-eabihf",
    what: "Raspberry Pi Pico 2",
};

/// The Raspberry Pi Pico (RP2040, Cortex-M0+).
pub const PICO: Board = Board {
    name: "psmpa-pico",
    dir: "pico",
    target: "thumbv6m-none-eabi",
    what: "Raspberry Pi Pico",
};

/// The boards' workspace.
pub fn boards() -> PathBuf {
    root().join("boards")
}

/// Builds a board's image as its README says (`cargo build --release` in its folder, whose
/// `.cargo/config.toml` sets the target and linker) and returns its ELF: the image a user
/// flashes, so no flags of this task's.
pub fn build_board(board: Board) -> Result<PathBuf, String> {
    let status = cargo_in(&boards().join(board.dir))
        .env("CARGO_TARGET_DIR", boards().join("target"))
        .args(["build", "--quiet", "--release"])
        .status()
        .map_err(|e| format!("cannot run cargo: {e}"))?;
    if !status.success() {
        return Err(format!("the {} board does not build", board.what));
    }
    Ok(boards()
        .join("target")
        .join(board.target)
        .join("release")
        .join(board.name))
}

/// The product-shaped image beside the firmware `elf` (one build makes both).
pub fn product(elf: &Path) -> PathBuf {
    elf.with_file_name("psmpa-product")
}

/// Builds the firmware and the product-shaped image for mps2-an386 and returns the firmware's
/// ELF.
pub fn build(features: &[&str]) -> Result<PathBuf, String> {
    build_for(&[AN386], features)?
        .pop()
        .ok_or_else(|| "no firmware built".to_owned())
}

/// Builds the firmware and the product-shaped image for every machine of `machines`, in one
/// cargo command, and returns the firmware's ELFs in their order.
pub fn build_for(machines: &[Machine], features: &[&str]) -> Result<Vec<PathBuf>, String> {
    let mut cmd = cargo();
    cmd.args(["build", "--quiet", "-p", "psmpa-firmware"]);
    for m in machines {
        cmd.args(["--target", m.target]);
    }
    cmd.args(["--profile", PROFILE])
        .env("CARGO_ENCODED_RUSTFLAGS", rustflags());
    // The injected fault builds elsewhere, so the good firmware is not rebuilt afterwards.
    let target_dir = if features.is_empty() {
        root().join("target")
    } else {
        cmd.args(["--features", &features.join(",")]);
        root().join("target/fault")
    };
    cmd.env("CARGO_TARGET_DIR", &target_dir);
    let status = cmd.status().map_err(|e| format!("cannot run cargo: {e}"))?;
    if !status.success() {
        return Err("the firmware does not build".to_owned());
    }
    Ok(machines
        .iter()
        .map(|m| {
            target_dir
                .join(m.target)
                .join(PROFILE)
                .join("psmpa-firmware")
        })
        .collect())
}

/// Runs an mps2-an386 ELF in QEMU (see [`run_on`]).
pub fn run(elf: &Path) -> Result<String, String> {
    run_on(AN386, elf)
}

/// What decides a run's log: the ELF, the runner script, QEMU's version and the machine.
/// `None` when one of them cannot be read.
fn run_key(machine: Machine, elf: &Path) -> Option<u64> {
    let mut h = DefaultHasher::new();
    machine.name.hash(&mut h);
    std::fs::read(elf).ok()?.hash(&mut h);
    std::fs::read(root().join("scripts/qemu-run.sh"))
        .ok()?
        .hash(&mut h);
    let qemu = Command::new("qemu-system-arm")
        .arg("--version")
        .output()
        .ok()?;
    qemu.stdout.hash(&mut h);
    Some(h.finish())
}

/// Where the log of the last successful run of `elf` on `machine` is kept.
fn log_path(machine: Machine, elf: &Path) -> PathBuf {
    let mut h = DefaultHasher::new();
    elf.hash(&mut h);
    root().join(format!(
        "target/qemu-logs/{}-{:016x}.log",
        machine.name,
        h.finish()
    ))
}

/// Runs the ELF in QEMU on `machine` through `scripts/qemu-run.sh` and returns the decoded
/// log.
///
/// Under `-icount` a run is a function of the ELF, the runner and QEMU: a successful run's log
/// is kept in `target/qemu-logs/` with a hash of the three, and the same ELF on the same
/// machine is not run again while none of them changed (the tasks that follow `cargo xtask
/// qemu` in CI read its logs). `PSMPA_QEMU_RERUN=1` runs it anyway.
pub fn run_on(machine: Machine, elf: &Path) -> Result<String, String> {
    let key = run_key(machine, elf).map(|k| format!("key {k:016x}\n"));
    let kept = log_path(machine, elf);
    let last = key
        .as_ref()
        .filter(|_| std::env::var_os("PSMPA_QEMU_RERUN").is_none())
        .and_then(|key| {
            let text = std::fs::read_to_string(&kept).ok()?;
            text.strip_prefix(key.as_str()).map(str::to_owned)
        });
    if let Some(log) = last {
        eprintln!(
            "{}: the log of this ELF, runner and QEMU from its last run ({}; runs are deterministic)",
            machine.name,
            kept.display()
        );
        return Ok(log);
    }
    let started = Instant::now();
    let out = Command::new("bash")
        .arg(root().join("scripts/qemu-run.sh"))
        .args(["--machine", machine.name])
        .arg(elf)
        .stdin(Stdio::null())
        .stderr(Stdio::inherit())
        .output()
        .map_err(|e| format!("cannot run QEMU: {e}"))?;
    let log = String::from_utf8_lossy(&out.stdout).into_owned();
    eprintln!(
        "{}: QEMU ran for {:.1} s of wall time",
        machine.name,
        started.elapsed().as_secs_f64()
    );
    match out.status.code() {
        Some(0) => {
            if let Some(key) = key {
                // A cache: not keeping it only costs a run next time.
                let _ = std::fs::create_dir_all(root().join("target/qemu-logs"))
                    .and_then(|()| std::fs::write(&kept, key + &log));
            }
            Ok(log)
        }
        Some(124) => Err(format!(
            "{}: the firmware hung (QEMU timed out); log:\n{log}",
            machine.name
        )),
        code => Err(format!(
            "{}: the firmware failed (exit {code:?}); log:\n{log}",
            machine.name
        )),
    }
}

/// Runs each `(machine, ELF)` in QEMU, all at once (one QEMU per machine), and returns their
/// logs in the same order.
pub fn run_all(runs: &[(Machine, PathBuf)]) -> Vec<Result<String, String>> {
    std::thread::scope(|scope| {
        let handles: Vec<_> = runs
            .iter()
            .map(|(m, elf)| scope.spawn(move || run_on(*m, elf)))
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join()
                    .unwrap_or_else(|_| Err("a QEMU run panicked".to_owned()))
            })
            .collect()
    })
}

/// The core clock the firmware's log says it counts, Hz.
pub fn logged_clock_hz(log: &str) -> Option<u64> {
    log.split_once("core clock ")?
        .1
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// What must be equal on both sides for one run: what the robot met and how, and how
/// regularly it sampled. Real time on the target shifts instants by the computing it takes
/// (the start of a run, planning, a side step), which virtual time does not count; so the
/// time cost is compared, not required equal, and the world trace is compared within an
/// allowed lag ([`trace`]).
#[derive(Debug, Clone, PartialEq, Eq)]
struct Outcome {
    interferences: String,
    detected: String,
    collisions: String,
    reached_door: String,
    fates: String,
    sonar_gap_ms: String,
    bumper_gap_ms: String,
}

impl Outcome {
    /// Whether the firmware's outcome `got` agrees with this, the host's: every field equal
    /// but the sample gaps, which may differ by the bump switch's debounce time (a read that
    /// waits for a switch to settle ends on the tick its last edge is played in, which real
    /// time shifts).
    fn agrees(&self, got: &Self) -> bool {
        let gap = |s: &str| s.parse::<i64>().ok();
        let close = |a: &str, b: &str| match (gap(a), gap(b)) {
            (Some(a), Some(b)) => a.abs_diff(b) <= psmpa_drivers::switch::DEBOUNCE.as_millis(),
            _ => a == b,
        };
        let exact = |o: &Self| {
            (
                o.interferences.clone(),
                o.detected.clone(),
                o.collisions.clone(),
                o.reached_door.clone(),
                o.fates.clone(),
            )
        };
        exact(self) == exact(got)
            && close(&self.sonar_gap_ms, &got.sonar_gap_ms)
            && close(&self.bumper_gap_ms, &got.bumper_gap_ms)
    }
}

/// What may differ, reported beside.
#[derive(Debug, Clone, Default)]
struct Timing {
    time_cost_ms: i64,
}

/// The fields of every `TAG key=value ...` line of the firmware log: lines whose message (after
/// the timestamp and the level) starts with the word `tag`.
pub fn tagged<'l>(log: &'l str, tag: &str) -> Vec<BTreeMap<&'l str, &'l str>> {
    log.lines()
        .filter_map(|line| {
            let mut words = line.split_whitespace().skip(2);
            (words.next() == Some(tag)).then(|| words.filter_map(|kv| kv.split_once('=')).collect())
        })
        .collect()
}

/// The scenario files, sorted.
pub fn scenario_files() -> Result<Vec<PathBuf>, String> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(root().join("scenarios"))
        .map_err(|e| format!("scenarios/: {e}"))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "json"))
        .collect();
    files.sort();
    Ok(files)
}

type Runs = BTreeMap<(String, String), (Outcome, Timing)>;

/// The `result key=value ...` lines of the firmware log, by (scenario, arch).
fn parse_results(log: &str) -> Runs {
    tagged(log, "result")
        .into_iter()
        .map(|fields| {
            let get = |k: &str| fields.get(k).map(|v| (*v).to_owned()).unwrap_or_default();
            (
                (get("scenario"), get("arch")),
                (
                    Outcome {
                        interferences: get("interferences"),
                        detected: get("detected"),
                        collisions: get("collisions"),
                        reached_door: get("reached_door"),
                        fates: get("fates"),
                        sonar_gap_ms: get("sonar_gap_ms"),
                        bumper_gap_ms: get("bumper_gap_ms"),
                    },
                    Timing {
                        time_cost_ms: get("time_cost_ms").parse().unwrap_or(-1),
                    },
                ),
            )
        })
        .collect()
}

/// A sample gap as the firmware logs it: -1 for none.
fn gap(ms: Option<u64>) -> String {
    ms.map_or("-1".to_owned(), |m| m.to_string())
}

/// How each interference ended, one letter each as the firmware logs it: `S`onar or `B`umper
/// detected it, the robot `C`ollided, or `-` neither.
pub fn fates(obstacles: &[psmpa_sim::world::ObstacleReport]) -> String {
    use psmpa_sim::world::{Device, Fate};
    obstacles
        .iter()
        .map(|o| match o.fate {
            Fate::Detected(Device::Sonar) => 'S',
            Fate::Detected(Device::Bumper) => 'B',
            Fate::Detected(_) => 'D',
            Fate::Collided => 'C',
            Fate::Unmet => '-',
        })
        .collect()
}

/// The host simulator's outcome for every scenario file and both architectures.
fn host_results() -> Result<Runs, String> {
    let mut out = BTreeMap::new();
    for file in scenario_files()? {
        let sc = psmpa_sim::load::load(&file).map_err(|e| e.to_string())?;
        for arch in Arch::ALL {
            let s = run_summary(&sc, arch).map_err(|e| e.to_string())?;
            let t = s.tally;
            out.insert(
                (sc.name.as_str().to_owned(), arch.name().to_owned()),
                (
                    Outcome {
                        interferences: t.interferences.to_string(),
                        detected: t.detected.to_string(),
                        collisions: t.collisions.to_string(),
                        reached_door: t.reached_door.to_string(),
                        fates: fates(&s.obstacles),
                        sonar_gap_ms: gap(t.sample_gap_max_ms[0]),
                        bumper_gap_ms: gap(t.sample_gap_max_ms[1]),
                    },
                    Timing {
                        time_cost_ms: i64::try_from(s.time_cost_ms).unwrap_or(i64::MAX),
                    },
                ),
            );
        }
    }
    Ok(out)
}

/// Ticks the firmware counted and core cycles by the reference timer, per run: they must
/// agree within a tick.
fn clock_errors(machine: Machine, log: &str) -> Vec<String> {
    let mut errors = Vec::new();
    for f in tagged(log, "clock") {
        let number = |k: &str| f.get(k).and_then(|v| v.parse::<u64>().ok());
        let name = format!(
            "{} {}",
            f.get("scenario").unwrap_or(&"?"),
            f.get("arch").unwrap_or(&"?")
        );
        match (number("ticks"), number("reference_cycles")) {
            (Some(ticks), Some(reference)) => {
                let by_reference = reference / machine.cycles_per_tick();
                if ticks.abs_diff(by_reference) > 1 {
                    errors.push(format!(
                        "{name}: the clock counted {ticks} ticks, the reference {reference} cycles ({by_reference} ticks)"
                    ));
                }
            }
            _ => errors.push(format!("{name}: no ticks or reference in its clock line")),
        }
    }
    errors
}

/// What one machine's runs measured, for the pages.
struct QemuFigures {
    machine: Machine,
    runs: usize,
    /// World-trace lines compared.
    lines: u64,
    /// The largest lag, ms; its scenario; the lag allowed there, ms.
    lag: (u64, String, u64),
    /// Cycles a logged line took.
    line_cycles: u64,
}

/// The pages' figures of `cargo xtask qemu`: the README's cell and the trace paragraph's.
fn qemu_pages(figures: &[QemuFigures]) -> Vec<(&'static str, &'static str, String)> {
    let group = crate::hil::thousands;
    let runs = figures.first().map_or(0, |f| f.runs);
    let mut lines: Vec<String> = figures.iter().map(|f| group(f.lines)).collect();
    lines.dedup();
    let cell = format!(
        "{runs} runs a core, {} trace lines compared on each",
        lines.join(" and ")
    );
    let text = figures
        .iter()
        .map(|f| {
            format!(
                "on `{}`, {} lines compared, the largest lag {} ms in `{}` ({} allowed), a logged line {} cycles",
                f.machine.name,
                group(f.lines),
                f.lag.0,
                f.lag.1,
                f.lag.2,
                group(f.line_cycles)
            )
        })
        .collect::<Vec<_>>()
        .join("; ");
    vec![
        ("README.md", "qemu", cell),
        ("docs/firmware.md", "qemu-figures", text),
    ]
}

/// Compares one machine's log with the host's runs: the outcome of each run, its clock and
/// its world trace; prints the table and a summary; returns the differences.
fn compare(
    machine: Machine,
    log: &str,
    host: &Runs,
    allowances: &BTreeMap<String, Allowance>,
    traces_dir: &Path,
    figures: &mut Vec<QemuFigures>,
) -> Vec<String> {
    let target = parse_results(log);
    let mut failures = Vec::new();
    println!("\n{} ({}, {}):", machine.name, machine.core, machine.target);
    // The image must be the one built for this machine: its clock says so.
    match logged_clock_hz(log) {
        Some(hz) if hz == machine.clock_hz => {}
        logged => failures.push(format!(
            "the firmware logged a core clock of {logged:?} Hz, not this machine's {} Hz",
            machine.clock_hz
        )),
    }
    let (traces, errors) = traces(machine, log, host, allowances, traces_dir);
    failures.extend(errors);
    println!(
        "{:<12} {:<6} {:>8} {:>10} {:<8} {:>10} {:>9}  {:<14} {:<14}",
        "scenario",
        "arch",
        "detected",
        "collisions",
        "fates",
        "time ms",
        "fw - host",
        "world lag ms",
        "outcome equal"
    );
    for (key, (expected, host_timing)) in host {
        let got = target.get(key);
        let same = got.is_some_and(|(o, _)| expected.agrees(o));
        let shift = got.map_or("-".to_owned(), |(_, t)| {
            format!("{:+}", t.time_cost_ms - host_timing.time_cost_ms)
        });
        let lag = match traces.get(key) {
            Some(Ok(s)) => format!("{} of {}", s.max_shift_ms, s.bound_ms),
            Some(Err(_)) => "DIFFERS".to_owned(),
            None => "-".to_owned(),
        };
        println!(
            "{:<12} {:<6} {:>8} {:>10} {:<8} {:>10} {:>9}  {:<14} {}",
            key.0,
            key.1,
            expected.detected,
            expected.collisions,
            expected.fates,
            host_timing.time_cost_ms,
            shift,
            lag,
            if same { "yes" } else { "NO" }
        );
        if !same {
            failures.push(format!(
                "{} {}: host {expected:?}, firmware {:?}",
                key.0,
                key.1,
                got.map(|(o, _)| o)
            ));
        }
    }
    for key in target.keys().filter(|k| !host.contains_key(*k)) {
        failures.push(format!(
            "{} {}: reported by the firmware only",
            key.0, key.1
        ));
    }
    let clock_lines = tagged(log, "clock").len();
    if clock_lines != host.len() {
        failures.push(format!("{clock_lines} clock lines for {} runs", host.len()));
    }
    failures.extend(clock_errors(machine, log));
    let mut sum = trace::Stats::default();
    let mut largest = ("-", "-");
    for (key, s) in traces
        .iter()
        .filter_map(|(k, r)| Some((k, r.as_ref().ok()?)))
    {
        if s.max_shift_ms >= sum.max_shift_ms {
            (sum.max_shift_ms, sum.bound_ms) = (s.max_shift_ms, s.bound_ms);
            largest = (key.0.as_str(), key.1.as_str());
        }
        sum.lines += s.lines;
        sum.samples += s.samples;
        sum.accepted += s.accepted;
    }
    let equal = traces.values().filter(|r| r.is_ok()).count();
    let trace_cycles: u64 = tagged(log, "clock")
        .iter()
        .filter_map(|c| c.get("trace_cycles")?.parse::<u64>().ok())
        .sum();
    let logged = log
        .lines()
        .filter(|l| l.split_whitespace().nth(2) == Some("w"))
        .count() as u64;
    println!(
        "{}: world traces: {equal} of {} runs as scenarios/traces/ within the allowed lag; {} lines compared ({} samples; {} on one side only, accepted: xtask/src/trace.rs); largest lag {} ms ({} {}, allowed {} ms); a line took {} cycles to log, left out of every measured cost",
        machine.name,
        host.len(),
        sum.lines,
        sum.samples,
        sum.accepted,
        sum.max_shift_ms,
        largest.0,
        largest.1,
        sum.bound_ms,
        trace_cycles.checked_div(logged).unwrap_or(0)
    );
    if failures.is_empty() {
        println!(
            "{}: all {} runs: the same outcome, sampling and world trace on the host and the firmware; every clock within a tick of the reference",
            machine.name,
            host.len()
        );
    }
    figures.push(QemuFigures {
        machine,
        runs: host.len(),
        lines: sum.lines as u64,
        lag: (sum.max_shift_ms, largest.0.to_owned(), sum.bound_ms),
        line_cycles: trace_cycles.checked_div(logged).unwrap_or(0),
    });
    failures
        .into_iter()
        .map(|f| format!("{}: {f}", machine.name))
        .collect()
}

/// Each scenario's allowance for its firmware trace ([`trace`]), by name.
fn allowances() -> Result<BTreeMap<String, Allowance>, String> {
    scenario_files()?
        .iter()
        .map(|file| {
            let sc = psmpa_sim::load::load(file).map_err(|e| e.to_string())?;
            Ok((sc.name.as_str().to_owned(), Allowance::of(&sc)))
        })
        .collect()
}

type TraceResults = BTreeMap<(String, String), Result<trace::Stats, String>>;

/// Compares the world trace of every run in `log` with its expected trace; returns each
/// run's result and the log's other errors (a run's difference is among the results). The
/// firmware's traces, in the expected traces' form, go to `dir` for reading or diffing by
/// hand.
fn traces(
    machine: Machine,
    log: &str,
    host: &Runs,
    allowances: &BTreeMap<String, Allowance>,
    dir: &Path,
) -> (TraceResults, Vec<String>) {
    let (traces, mut errors) = trace::firmware_traces(log);
    let kept = std::fs::create_dir_all(dir).and_then(|()| {
        traces.iter().try_for_each(|((name, arch), lines)| {
            std::fs::write(
                dir.join(format!("{name}.{arch}.trace")),
                trace::as_text(lines),
            )
        })
    });
    if let Err(e) = kept {
        // Only a copy for reading: the comparison goes on.
        eprintln!(
            "{}: cannot keep the traces in {}: {e}",
            machine.name,
            dir.display()
        );
    }
    let mut results = BTreeMap::new();
    for key @ (name, arch) in host.keys() {
        let path = trace::expected_path(name, arch);
        let ours = dir.join(format!("{name}.{arch}.trace"));
        let relative = |p: &Path| p.strip_prefix(root()).unwrap_or(p).display().to_string();
        let names = (relative(&path), relative(&ours));
        let result = match (traces.get(key), allowances.get(name)) {
            (None, _) => Err("no world trace in the log".to_owned()),
            (_, None) => Err("no such scenario file".to_owned()),
            (Some(got), Some(allow)) => std::fs::read_to_string(&path)
                .map_err(|e| format!("{}: {e}", path.display()))
                .and_then(|text| {
                    let want = trace::world_lines(&text);
                    trace::compare(&want, got, allow, (&names.0, &names.1))
                }),
        };
        if let Err(e) = &result {
            errors.push(format!("{name} {arch}: world trace: {e}"));
        }
        results.insert(key.clone(), result);
    }
    (results, errors)
}

/// Replays every run's flight recording in `log` on the host ([`recording`]) and prints what
/// the recorder cost on the firmware; the replays that did not match.
fn replay_recordings(machine: Machine, log: &str, inject_fault: bool) -> Vec<String> {
    let label = format!(
        "{}{}",
        if inject_fault { "fault/" } else { "" },
        machine.name
    );
    let dir = recording::dir(&label);
    let r = recording::replay_log(log, &dir, recording::CHIP_LAG, None);
    let costs = tagged(log, "recorder");
    let sum = |key: &str| -> u64 {
        costs
            .iter()
            .filter_map(|c| c.get(key)?.parse::<u64>().ok())
            .sum()
    };
    let most = |key: &str| -> u64 {
        costs
            .iter()
            .filter_map(|c| c.get(key)?.parse::<u64>().ok())
            .max()
            .unwrap_or(0)
    };
    let (frames, cycles, encode) = (sum("frames"), sum("cycles"), sum("encode_cycles"));
    println!(
        "{}: flight recordings: {} of {} runs replayed on the host with every decision as recorded ({} decisions; {} bytes for {:.1} s recorded, {:.0} kB a minute; kept in {}); the recorder took {} cycles a frame on the runtime's path on average, {} at most, and {} on average, {} at most, to encode it in idle time ({} frames; at most {} queued at once, {} encoded on the path for a full queue)",
        machine.name,
        r.runs - r.failures.len().min(r.runs),
        r.runs,
        r.decisions,
        r.bytes,
        r.recorded_ms as f64 / 1e3,
        r.bytes as f64 / 1e3 / (r.recorded_ms.max(1) as f64 / 60e3),
        dir.display(),
        cycles.checked_div(frames).unwrap_or(0),
        most("max_cycles"),
        encode.checked_div(frames).unwrap_or(0),
        most("encode_max"),
        frames,
        most("queued_max"),
        sum("inline")
    );
    let mut failures = r.failures;
    if r.runs != costs.len() {
        failures.push(format!(
            "{}: {} recordings for {} runs",
            machine.name,
            r.runs,
            costs.len()
        ));
    }
    failures
        .into_iter()
        .map(|f| format!("{}: replay: {f}", machine.name))
        .collect()
}

/// Builds and runs the firmware on every machine and compares it with the host. `Ok` only if,
/// on each machine, every run of the host has a run on the firmware with the same outcome, and
/// nothing else, and every run's clock kept time. With `inject_fault`, mps2-an386 only.
pub fn qemu_check(inject_fault: bool) -> Result<(), String> {
    let features: &[&str] = if inject_fault { &["inject-fault"] } else { &[] };
    let machines: &[Machine] = if inject_fault { &[AN386] } else { &MACHINES };
    let elfs = build_for(machines, features)?;
    let runs: Vec<(Machine, PathBuf)> = machines.iter().copied().zip(elfs).collect();
    let logs = run_all(&runs);
    let host = host_results()?;
    let allowances = allowances()?;
    // The broken image's traces apart, so the good ones stay for reading.
    let traces = root().join(if inject_fault {
        "target/fault/qemu-traces"
    } else {
        "target/qemu-traces"
    });
    let mut failures = Vec::new();
    let mut figures = Vec::new();
    for ((machine, _), log) in runs.iter().zip(logs) {
        match log {
            Ok(log) => {
                let dir = traces.join(machine.name);
                failures.extend(compare(
                    *machine,
                    &log,
                    &host,
                    &allowances,
                    &dir,
                    &mut figures,
                ));
                failures.extend(replay_recordings(*machine, &log, inject_fault));
            }
            Err(e) => failures.push(e),
        }
    }
    if inject_fault {
        let elf = runs.first().map(|(_, elf)| product(elf));
        if !elf.map_or(Ok(false), |e| stack_overflow_faults(AN386, &e))? {
            // The second half of the failure the check must show is missing: it passes.
            return Ok(());
        }
    }
    if failures.is_empty() && !inject_fault {
        let regions: Vec<_> = qemu_pages(&figures)
            .into_iter()
            .map(|(page, marker, text)| (root().join(page), marker, text))
            .collect();
        crate::pages::write_pages(&regions)?;
    }
    if failures.is_empty() {
        println!(
            "\nall {} runs on each of {}: the same as the host",
            host.len(),
            machines
                .iter()
                .map(|m| format!("{} ({})", m.name, m.core))
                .collect::<Vec<_>>()
                .join(" and ")
        );
        Ok(())
    } else {
        Err(format!(
            "{} differences:\n{}",
            failures.len(),
            failures.join("\n")
        ))
    }
}

/// The stack high-water mark: the deepest any run's boot logged.
pub fn stack_high_water(log: &str) -> Option<u64> {
    log.lines()
        .filter_map(|l| {
            l.split_once("stack high-water ")?
                .1
                .split_whitespace()
                .next()?
                .parse()
                .ok()
        })
        .max()
}

#[cfg(test)]
mod tests {
    use super::{AN386, AN505, logged_clock_hz};

    #[test]
    fn cycles_convert_to_instructions_at_32_ns_each() {
        // A second of timer cycles is 31.25 million instructions on either machine.
        assert_eq!(AN386.instructions(25_000_000), 31_250_000);
        assert_eq!(AN505.instructions(20_000_000), 31_250_000);
        assert_eq!(AN386.cycles_per_tick(), 25_000);
        assert_eq!(AN505.cycles_per_tick(), 20_000);
    }

    #[test]
    fn the_logged_clock_is_read_from_the_first_line() {
        let log = "0.000 INFO  psmpa firmware: 15 scenarios, core clock 20000000 Hz, tick 1000 Hz; one run per boot\n";
        assert_eq!(logged_clock_hz(log), Some(20_000_000));
        assert_eq!(logged_clock_hz("no clock here"), None);
    }
}

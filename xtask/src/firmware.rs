//! Building and running the firmware, and comparing it with the host.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use psmpa_sim::robot::Arch;
use psmpa_sim::sim::run_summary;

/// The workspace root.
pub fn root() -> PathBuf {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    root.canonicalize().unwrap_or(root)
}

/// `cargo` as this task was started with (`$CARGO`), run from the workspace root.
pub fn cargo() -> Command {
    let mut cmd = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    cmd.current_dir(root());
    cmd
}

/// Builds the simulator's command line in release mode and returns its path.
pub fn build_host_sim() -> Result<PathBuf, String> {
    let status = cargo()
        .args(["build", "--quiet", "--release", "-p", "psmpa-sim"])
        .status()
        .map_err(|e| format!("cannot run cargo: {e}"))?;
    if !status.success() {
        return Err("psmpa-sim does not build".to_owned());
    }
    Ok(root().join("target/release/psmpa-sim"))
}

/// The firmware's target.
pub const TARGET: &str = "thumbv7em-none-eabihf";
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
fn stack_overflow_faults(elf: &Path) -> Result<bool, String> {
    match run(elf) {
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

/// The product-shaped image beside the firmware `elf` (one build makes both).
pub fn product(elf: &Path) -> PathBuf {
    elf.with_file_name("psmpa-product")
}

/// Builds the firmware and the product-shaped image and returns the firmware's ELF.
pub fn build(features: &[&str]) -> Result<PathBuf, String> {
    let mut cmd = cargo();
    cmd.args([
        "build",
        "--quiet",
        "-p",
        "psmpa-firmware",
        "--target",
        TARGET,
        "--profile",
        PROFILE,
    ])
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
    Ok(target_dir.join(TARGET).join(PROFILE).join("psmpa-firmware"))
}

/// Runs the ELF in QEMU through `scripts/qemu-run.sh` and returns the decoded log.
pub fn run(elf: &Path) -> Result<String, String> {
    let started = Instant::now();
    let out = Command::new("bash")
        .arg(root().join("scripts/qemu-run.sh"))
        .arg(elf)
        .stdin(Stdio::null())
        .stderr(Stdio::inherit())
        .output()
        .map_err(|e| format!("cannot run QEMU: {e}"))?;
    let log = String::from_utf8_lossy(&out.stdout).into_owned();
    eprintln!(
        "QEMU ran for {:.1} s of wall time",
        started.elapsed().as_secs_f64()
    );
    match out.status.code() {
        Some(0) => Ok(log),
        Some(124) => Err(format!("the firmware hung (QEMU timed out); log:\n{log}")),
        code => Err(format!("the firmware failed (exit {code:?}); log:\n{log}")),
    }
}

/// What must be equal on both sides for one run: what the robot met and how, and how
/// regularly it sampled. Real time on the target shifts instants by the computing it takes
/// (the start of a run, planning, a side step), which virtual time does not count; so the
/// trace hash and the time cost are compared, not required equal.
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

/// What may differ, reported beside.
#[derive(Debug, Clone, Default)]
struct Timing {
    time_cost_ms: i64,
    trace_hash: String,
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
                        trace_hash: get("trace_hash"),
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
                        trace_hash: format!("{:016x}", s.trace_hash),
                    },
                ),
            );
        }
    }
    Ok(out)
}

/// Ticks the firmware counted and core cycles by the reference timer, per run: they must
/// agree within a tick.
fn clock_errors(log: &str) -> Vec<String> {
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
                let by_reference = reference / CYCLES_PER_TICK;
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

/// Core cycles per tick of the QEMU firmware (`firmware/src/time_driver.rs`): 25 MHz, 1 kHz.
pub const CYCLES_PER_TICK: u64 = 25_000;

/// Builds and runs the firmware and compares it with the host. `Ok` only if every run of the
/// host has a run on the firmware with the same outcome, and nothing else, and every run's
/// clock kept time.
pub fn qemu_check(inject_fault: bool) -> Result<(), String> {
    let features: &[&str] = if inject_fault { &["inject-fault"] } else { &[] };
    let elf = build(features)?;
    let log = run(&elf)?;
    let target = parse_results(&log);
    let host = host_results()?;
    let mut failures = Vec::new();
    println!(
        "{:<12} {:<6} {:>8} {:>10} {:<8} {:>10} {:>9}  {:<5} {:<14}",
        "scenario",
        "arch",
        "detected",
        "collisions",
        "fates",
        "time ms",
        "fw - host",
        "trace",
        "outcome equal"
    );
    let mut same_traces = 0;
    for (key, (expected, host_timing)) in &host {
        let got = target.get(key);
        let same = got.is_some_and(|(o, _)| o == expected);
        let (shift, trace) = match got {
            Some((_, t)) => {
                let equal = t.trace_hash == host_timing.trace_hash;
                same_traces += usize::from(equal);
                (
                    format!("{:+}", t.time_cost_ms - host_timing.time_cost_ms),
                    if equal { "same" } else { "moved" },
                )
            }
            None => ("-".to_owned(), "-"),
        };
        println!(
            "{:<12} {:<6} {:>8} {:>10} {:<8} {:>10} {:>9}  {:<5} {}",
            key.0,
            key.1,
            expected.detected,
            expected.collisions,
            expected.fates,
            host_timing.time_cost_ms,
            shift,
            trace,
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
    let clock = clock_errors(&log);
    if tagged(&log, "clock").len() != host.len() {
        failures.push(format!(
            "{} clock lines for {} runs",
            tagged(&log, "clock").len(),
            host.len()
        ));
    }
    failures.extend(clock);
    if inject_fault && !stack_overflow_faults(&product(&elf))? {
        // The second half of the failure the check must show is missing: it passes.
        return Ok(());
    }
    println!(
        "traces equal to the host's: {same_traces} of {} (the others start or go on a few ms later: computing takes real time on the target, none in virtual time)",
        host.len()
    );
    if failures.is_empty() {
        println!(
            "all {} runs: the same outcome and sampling on the host and the firmware; every clock within a tick of the reference",
            host.len()
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

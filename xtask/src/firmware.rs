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
    [
        format!("--remap-path-prefix={}=cargo", cargo_home.display()),
        format!("--remap-path-prefix={}=psmpa", root.display()),
    ]
    .join("\x1f")
}

/// Builds the firmware and returns its ELF.
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

/// The fields both sides report for one run.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Outcome {
    interferences: String,
    detected: String,
    collisions: String,
    reached_door: String,
    time_cost_ms: String,
    max_reaction_ms: String,
    sonar_on_ms: String,
    bumper_on_ms: String,
    sonar_gap_ms: String,
    bumper_gap_ms: String,
    trace_hash: String,
}

/// The fields of every `TAG key=value ...` line of the firmware log.
pub fn tagged<'l>(log: &'l str, tag: &str) -> Vec<BTreeMap<&'l str, &'l str>> {
    let tag = format!(" {tag} ");
    log.lines()
        .filter_map(|line| {
            let (_, rest) = line.split_once(tag.as_str())?;
            Some(
                rest.split_whitespace()
                    .filter_map(|kv| kv.split_once('='))
                    .collect(),
            )
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

/// The `result key=value ...` lines of the firmware log, by (scenario, arch).
fn parse_results(log: &str) -> BTreeMap<(String, String), Outcome> {
    tagged(log, "result")
        .into_iter()
        .map(|fields| {
            let get = |k: &str| fields.get(k).map(|v| (*v).to_owned()).unwrap_or_default();
            (
                (get("scenario"), get("arch")),
                Outcome {
                    interferences: get("interferences"),
                    detected: get("detected"),
                    collisions: get("collisions"),
                    reached_door: get("reached_door"),
                    time_cost_ms: get("time_cost_ms"),
                    max_reaction_ms: get("max_reaction_ms"),
                    sonar_on_ms: get("sonar_on_ms"),
                    bumper_on_ms: get("bumper_on_ms"),
                    sonar_gap_ms: get("sonar_gap_ms"),
                    bumper_gap_ms: get("bumper_gap_ms"),
                    trace_hash: get("trace_hash"),
                },
            )
        })
        .collect()
}

/// A sample gap as the firmware logs it: -1 for none.
fn gap(ms: Option<u64>) -> String {
    ms.map_or("-1".to_owned(), |m| m.to_string())
}

/// The host simulator's outcome for every scenario file and both architectures.
fn host_results() -> Result<BTreeMap<(String, String), Outcome>, String> {
    let mut out = BTreeMap::new();
    for file in scenario_files()? {
        let sc = psmpa_sim::load::load(&file).map_err(|e| e.to_string())?;
        for arch in Arch::ALL {
            let s = run_summary(&sc, arch).map_err(|e| e.to_string())?;
            let t = s.tally;
            out.insert(
                (sc.name.as_str().to_owned(), arch.name().to_owned()),
                Outcome {
                    interferences: t.interferences.to_string(),
                    detected: t.detected.to_string(),
                    collisions: t.collisions.to_string(),
                    reached_door: t.reached_door.to_string(),
                    time_cost_ms: s.time_cost_ms.to_string(),
                    max_reaction_ms: t.max_reaction_ms.map_or("-1".to_owned(), |m| m.to_string()),
                    sonar_on_ms: t.on_ms[0].to_string(),
                    bumper_on_ms: t.on_ms[1].to_string(),
                    sonar_gap_ms: gap(t.sample_gap_max_ms[0]),
                    bumper_gap_ms: gap(t.sample_gap_max_ms[1]),
                    trace_hash: format!("{:016x}", s.trace_hash),
                },
            );
        }
    }
    Ok(out)
}

/// Builds and runs the firmware and compares it with the host. `Ok` only if every run of the
/// host has an equal run on the firmware and nothing else.
pub fn qemu_check(inject_fault: bool) -> Result<(), String> {
    let features: &[&str] = if inject_fault { &["inject-fault"] } else { &[] };
    let elf = build(features)?;
    let log = run(&elf)?;
    let target = parse_results(&log);
    let host = host_results()?;
    let mut failures = Vec::new();
    println!(
        "{:<14} {:<6} {:>8} {:>10} {:>10}  {:<16}  firmware = host",
        "scenario", "arch", "detected", "collisions", "time ms", "trace hash"
    );
    for (key, expected) in &host {
        let got = target.get(key);
        let same = got == Some(expected);
        println!(
            "{:<14} {:<6} {:>8} {:>10} {:>10}  {:<16}  {}",
            key.0,
            key.1,
            expected.detected,
            expected.collisions,
            expected.time_cost_ms,
            expected.trace_hash,
            if same { "yes" } else { "NO" }
        );
        if !same {
            failures.push(format!(
                "{} {}: host {expected:?}, firmware {got:?}",
                key.0, key.1
            ));
        }
    }
    for key in target.keys().filter(|k| !host.contains_key(*k)) {
        failures.push(format!(
            "{} {}: reported by the firmware only",
            key.0, key.1
        ));
    }
    if failures.is_empty() {
        println!("all {} runs equal on the host and the firmware", host.len());
        Ok(())
    } else {
        Err(format!(
            "{} differences:\n{}",
            failures.len(),
            failures.join("\n")
        ))
    }
}

/// The stack high-water mark the firmware logs at the end of a run.
pub fn stack_high_water(log: &str) -> Option<u64> {
    log.lines().find_map(|l| {
        l.split_once("stack high-water ")?
            .1
            .split_whitespace()
            .next()?
            .parse()
            .ok()
    })
}

//! `cargo xtask bench`: every benchmark in one run, and the markdown table the README shows.
//!
//! Runs the criterion benches of `bench/` (the plan workload in psmpa and its peers, the data
//! stores, the simulator), the `behaviortree` bench (its own package: it needs a different
//! embassy-time tick rate), and a timed 10,000-scenario sweep; reads criterion's medians from
//! `target/criterion`, writes `bench/RESULTS.md`, and puts the same table into `README.md`
//! between its `bench:start` and `bench:end` markers.
//!
//! Beside the times, counts that do not depend on the machine's load, by callgrind
//! (`bench/examples`): every implementation's instructions per plan (`profile_plan`,
//! `profile_peer`), psmpa's per action step and the floor under it, the same work with no
//! runtime around it (`profile_floor`). `cargo xtask bench --instructions` counts only those,
//! in a minute, and writes them, with where psmpa's step goes, into `docs/benchmarks.md`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use serde::Deserialize;

use crate::{callgrind, firmware};

/// Criterion options: shorter than its defaults, enough for stable medians here.
const CRITERION: &[&str] = &["--warm-up-time", "1", "--measurement-time", "4", "--noplot"];

#[derive(Deserialize)]
struct Estimate {
    point_estimate: f64,
}

#[derive(Deserialize)]
struct Estimates {
    median: Estimate,
}

#[derive(Deserialize)]
struct Benchmark {
    group_id: String,
    function_id: String,
    throughput: Option<Throughput>,
}

#[derive(Deserialize)]
enum Throughput {
    Elements(u64),
    #[allow(dead_code)]
    Bytes(u64),
}

/// One measured function: median ns per iteration and elements per iteration.
#[derive(Debug, Clone, Copy)]
struct Measured {
    ns: f64,
    elements: u64,
}

/// Every benchmark under a criterion directory: (group, function) → measurement.
fn read_criterion(dir: &Path) -> Result<BTreeMap<(String, String), Measured>, String> {
    let mut out = BTreeMap::new();
    let Ok(groups) = std::fs::read_dir(dir) else {
        return Err(format!("{}: no criterion results", dir.display()));
    };
    for group in groups.flatten() {
        let Ok(functions) = std::fs::read_dir(group.path()) else {
            continue;
        };
        for function in functions.flatten() {
            let new = function.path().join("new");
            let (Ok(b), Ok(e)) = (
                std::fs::read_to_string(new.join("benchmark.json")),
                std::fs::read_to_string(new.join("estimates.json")),
            ) else {
                continue;
            };
            let b: Benchmark = serde_json::from_str(&b).map_err(|e| e.to_string())?;
            let e: Estimates = serde_json::from_str(&e).map_err(|e| e.to_string())?;
            let elements = match b.throughput {
                Some(Throughput::Elements(n)) => n,
                _ => 1,
            };
            out.insert(
                (b.group_id, b.function_id),
                Measured {
                    ns: e.median.point_estimate,
                    elements,
                },
            );
        }
    }
    Ok(out)
}

/// Runs `cargo bench` with `args` in the package or workspace at `dir`, building into its
/// `target/` (criterion writes its results there), echoing its output; returns its stdout.
fn cargo_bench(args: &[&str], dir: &Path) -> Result<String, String> {
    let mut cmd = firmware::cargo_in(dir);
    cmd.arg("bench")
        .args(args)
        .arg("--")
        .args(CRITERION)
        .stderr(Stdio::inherit());
    let out = cmd
        .output()
        .map_err(|e| format!("cannot run cargo bench: {e}"))?;
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    print!("{text}");
    if out.status.success() {
        Ok(text)
    } else {
        Err(format!("cargo bench {} failed", args.join(" ")))
    }
}

/// `allocations per plan: NAME: N` lines.
fn allocations(text: &str) -> BTreeMap<String, u64> {
    text.lines()
        .filter_map(|l| {
            let rest = l.strip_prefix("allocations per plan: ")?;
            let (name, n) = rest.rsplit_once([':', ' '])?;
            let name = name.trim().trim_end_matches(':').trim();
            Some((name.to_owned(), n.trim().parse().ok()?))
        })
        .collect()
}

/// Wall time of a 10,000-scenario sweep of both architectures, median of 3, seconds.
fn sweep_seconds() -> Result<f64, String> {
    let sim = firmware::build_host_sim()?;
    let mut times = Vec::new();
    for _ in 0..3 {
        let started = Instant::now();
        let out = Command::new(&sim)
            .args(["sweep", "--runs", "10000", "--seed", "1"])
            .stdin(Stdio::null())
            .stderr(Stdio::null())
            .output()
            .map_err(|e| format!("cannot run psmpa-sim: {e}"))?;
        if !out.status.success() {
            return Err("the sweep failed".to_owned());
        }
        times.push(started.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    Ok(times[1])
}

/// Puts `md` between the README's `<!-- NAME:start -->` and `<!-- NAME:end -->` markers.
pub fn replace_in_readme(root: &Path, name: &str, md: &str) -> Result<(), String> {
    let path = root.join("README.md");
    let readme = std::fs::read_to_string(&path).map_err(|e| e.to_string())?;
    let (start, end) = (
        format!("<!-- {name}:start -->\n"),
        format!("<!-- {name}:end -->"),
    );
    let (Some(a), Some(b)) = (readme.find(&start), readme.find(&end)) else {
        return Err(format!(
            "README.md lacks the {name}:start / {name}:end markers"
        ));
    };
    let updated = format!("{}{start}{md}{}", &readme[..a], &readme[b..]);
    std::fs::write(&path, updated).map_err(|e| e.to_string())
}

fn fmt_ns(ns: f64) -> String {
    if ns >= 1000.0 {
        format!("{:.2} µs", ns / 1000.0)
    } else {
        format!("{ns:.1} ns")
    }
}

/// What criterion does not keep: allocation counts, the sweep's time, the instruction count.
#[derive(serde::Serialize, Deserialize)]
struct Extra {
    allocations: BTreeMap<String, u64>,
    sweep_s: f64,
    /// Absent from results written before it was measured.
    #[serde(default)]
    instructions_per_step: Option<f64>,
    /// `profile_floor`'s count; absent from results written before it was measured.
    #[serde(default)]
    floor_per_step: Option<f64>,
    /// Instructions per plan by implementation (the plan table's names), callgrind's.
    #[serde(default)]
    instructions_per_plan: BTreeMap<String, f64>,
    /// The machine's load average (1, 5 and 15 minutes) when the run began, where the system
    /// says it (`/proc/loadavg`): the times depend on it.
    #[serde(default)]
    load: Option<String>,
}

/// Plans per callgrind run of a plan profile: the difference of two runs leaves out the
/// program's start and exit.
const CALLGRIND_PLANS: [u32; 2] = [200, 400];

/// psmpa's plan workload, for callgrind (`bench/examples`).
const PROFILE_PLAN: &str = "profile_plan";

/// The same work with no runtime around it: the floor under psmpa's step on this backend.
const PROFILE_FLOOR: &str = "profile_floor";

/// The peers' plan workloads, for callgrind: `profile_peer NAME PLANS`.
const PROFILE_PEER: &str = "profile_peer";

/// The peers [`PROFILE_PEER`] runs, by their names in the plan table.
const PEERS: [&str; 3] = ["bonsai-bt", "statig", "hand-written FSM"];

/// One callgrind run of a plan profile.
struct Count {
    plans: u64,
    steps: u64,
    instructions: u64,
}

/// Builds the example `name` with the `bench` profile, so it shares every compiled crate with
/// `cargo bench` (and with `--release`: the two profiles are the same); returns its path.
fn build_profile(name: &str) -> Result<PathBuf, String> {
    firmware::build_executable(
        &["--profile", "bench", "-p", "psmpa-bench", "--example", name],
        name,
    )
}

/// Runs `exe` (the example `name`, with `args` before the plan count) for `plans` plans
/// under callgrind.
fn callgrind(
    root: &Path,
    exe: &Path,
    name: &str,
    args: &[&str],
    plans: u32,
) -> Result<Count, String> {
    let tag: String = args
        .iter()
        .flat_map(|a| a.chars())
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
        .collect();
    let out_file = root.join(format!("target/callgrind.{name}{tag}.{plans}.out"));
    let plans_arg = plans.to_string();
    let all: Vec<&str> = args.iter().copied().chain([plans_arg.as_str()]).collect();
    let stdout = callgrind::run(root, &out_file, &[], exe, &all)?;
    // "N action steps in M plans"
    let (steps, ran) = stdout
        .lines()
        .find_map(|l| {
            let (steps, rest) = l.split_once(" action steps in ")?;
            let ran = rest.strip_suffix(" plans")?;
            Some((steps.trim().parse().ok()?, ran.trim().parse().ok()?))
        })
        .ok_or_else(|| format!("{name} printed no \"N action steps in M plans\": {stdout}"))?;
    // The file's `summary:` line: the whole run's instructions (its only event).
    let text =
        std::fs::read_to_string(&out_file).map_err(|e| format!("{}: {e}", out_file.display()))?;
    let instructions = text
        .lines()
        .find_map(|l| l.strip_prefix("summary:")?.trim().parse().ok())
        .ok_or_else(|| format!("{}: no summary line", out_file.display()))?;
    Ok(Count {
        plans: ran,
        steps,
        instructions,
    })
}

/// `1383.4` as `1,383`.
fn fmt_count(n: f64) -> String {
    let digits = format!("{:.0}", n.max(0.0));
    let mut out = String::new();
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i) % 3 == 0 {
            out.push(',');
        }
        out.push(c);
    }
    out
}

/// The instruction set the count is in (`x86-64` on the usual host).
fn isa() -> &'static str {
    match std::env::consts::ARCH {
        "x86_64" => "x86-64",
        arch => arch,
    }
}

/// The sentence the table and the quick mode print: psmpa's count and, when measured, the
/// floor's.
fn instructions_line(per_step: f64, floor: Option<f64>) -> String {
    let floor = floor.map_or(String::new(), |f| {
        format!(
            "; the same work with no runtime around it (`{PROFILE_FLOOR}`): {}",
            fmt_count(f)
        )
    });
    format!(
        "psmpa: {} {} instructions per action step{floor} (callgrind, deterministic)",
        fmt_count(per_step),
        isa()
    )
}

/// The example `name`'s (with `args`) plan workload: two callgrind runs, and the difference
/// of their counts over the difference of their action steps and of their plans.
fn differences(root: &Path, exe: &Path, name: &str, args: &[&str]) -> Result<(f64, f64), String> {
    let mut counts = Vec::new();
    for plans in CALLGRIND_PLANS {
        let c = callgrind(root, exe, name, args, plans)?;
        println!(
            "{name}{}{}: {} action steps in {} plans: {} instructions",
            if args.is_empty() { "" } else { " " },
            args.join(" "),
            c.steps,
            c.plans,
            fmt_count(c.instructions as f64)
        );
        counts.push(c);
    }
    let (a, b) = (&counts[0], &counts[1]);
    if b.steps <= a.steps || b.plans <= a.plans || b.instructions < a.instructions {
        return Err(format!(
            "{name} ran {} then {} action steps: no difference to divide by",
            a.steps, b.steps
        ));
    }
    let more = (b.instructions - a.instructions) as f64;
    Ok((
        more / (b.steps - a.steps) as f64,
        more / (b.plans - a.plans) as f64,
    ))
}

/// Every count of one run: psmpa's per action step, the floor's, and per plan psmpa's and
/// each peer's, the same workload.
struct Counts {
    per_step: f64,
    floor: f64,
    per_plan: BTreeMap<String, f64>,
}

/// psmpa's counts, the floor's and the peers'.
fn instruction_counts(root: &Path) -> Result<Counts, String> {
    callgrind::check()?;
    let (per_step, psmpa_plan) =
        differences(root, &build_profile(PROFILE_PLAN)?, PROFILE_PLAN, &[])?;
    let (floor, _) = differences(root, &build_profile(PROFILE_FLOOR)?, PROFILE_FLOOR, &[])?;
    let mut per_plan = BTreeMap::from([("psmpa".to_owned(), psmpa_plan)]);
    let peer = build_profile(PROFILE_PEER)?;
    for name in PEERS {
        let (_, plan) = differences(root, &peer, PROFILE_PEER, &[name])?;
        per_plan.insert(name.to_owned(), plan);
    }
    Ok(Counts {
        per_step,
        floor,
        per_plan,
    })
}

/// One line per implementation, `NAME: N instructions per plan`, fewest first.
fn per_plan_lines(per_plan: &BTreeMap<String, f64>) -> Vec<String> {
    let mut rows: Vec<(&String, &f64)> = per_plan.iter().collect();
    rows.sort_by(|a, b| a.1.total_cmp(b.1));
    rows.into_iter()
        .map(|(name, n)| format!("{name}: {} instructions per plan", fmt_count(*n)))
        .collect()
}

/// Instructions per function of a callgrind output file, its own (callees excluded), by the
/// names callgrind gives (compressed names resolved).
fn self_costs(path: &Path) -> Result<BTreeMap<String, u64>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut names: BTreeMap<String, String> = BTreeMap::new();
    let mut costs: BTreeMap<String, u64> = BTreeMap::new();
    let (mut current, mut call_cost) = (String::new(), false);
    for line in text.lines() {
        let named = line
            .strip_prefix("fn=")
            .map(|r| (true, r))
            .or_else(|| line.strip_prefix("cfn=").map(|r| (false, r)));
        if let Some((own, rest)) = named {
            // `(id) name` defines an id, `(id)` refers to one.
            let name = match rest.strip_prefix('(').and_then(|r| r.split_once(')')) {
                Some((id, name)) if !name.trim().is_empty() => {
                    names.insert(id.to_owned(), name.trim().to_owned());
                    name.trim().to_owned()
                }
                Some((id, _)) => names.get(id).cloned().unwrap_or_default(),
                None => rest.trim().to_owned(),
            };
            if own {
                current = name;
            }
        } else if line.starts_with("calls=") {
            // The next cost line is the call's inclusive cost: not this function's own.
            call_cost = true;
        } else if line.starts_with(|c: char| c.is_ascii_digit() || "+-*".contains(c)) {
            if std::mem::take(&mut call_cost) {
                continue;
            }
            let ir: u64 = line
                .split_whitespace()
                .nth(1)
                .and_then(|v| v.parse().ok())
                .unwrap_or(0);
            *costs.entry(current.clone()).or_default() += ir;
        }
    }
    Ok(costs)
}

/// Where psmpa's step goes: per function (everything the compiler inlined into it counted
/// there), its own instructions per action step, the difference of [`CALLGRIND_PLANS`]' two
/// runs over the difference of their steps; the largest first.
fn step_breakdown(root: &Path) -> Result<Vec<(String, f64)>, String> {
    let [a, b] = CALLGRIND_PLANS
        .map(|plans| root.join(format!("target/callgrind.{PROFILE_PLAN}.{plans}.out")));
    let (a, b) = (self_costs(&a)?, self_costs(&b)?);
    let steps = f64::from(CALLGRIND_PLANS[1] - CALLGRIND_PLANS[0]) * PLAN_STEPS;
    let mut rows: Vec<(String, f64)> = b
        .iter()
        .map(|(name, n)| {
            let more = n.saturating_sub(a.get(name).copied().unwrap_or(0));
            (name.clone(), more as f64 / steps)
        })
        .filter(|(_, n)| *n >= 0.5)
        .collect();
    rows.sort_by(|x, y| y.1.total_cmp(&x.1));
    Ok(rows)
}

/// The counts as the page shows them, between `docs/benchmarks.md`'s `instructions` markers.
fn instructions_md(counts: &Counts, breakdown: &[(String, f64)]) -> String {
    let mut md = String::from("\n```text\n");
    for line in per_plan_lines(&counts.per_plan) {
        md.push_str(&line);
        md.push('\n');
    }
    md.push_str(&instructions_line(counts.per_step, Some(counts.floor)));
    md.push_str("\n```\n\n| function (callgrind's name; what the compiler inlined into it counts there) | instructions per action step |\n|---|---|\n");
    let shown = 8;
    for (name, n) in breakdown.iter().take(shown) {
        // Generic parameters shortened: the table names places, not types.
        let short = name
            .replace("<P,T,_,_,_,_,_,_,_>", "")
            .replace("<M,_,_>", "");
        md.push_str(&format!("| `{short}` | {} |\n", fmt_count(*n)));
    }
    let rest: f64 = breakdown.iter().skip(shown).map(|(_, n)| n).sum();
    md.push_str(&format!("| the rest | {} |\n", fmt_count(rest)));
    md
}

/// `cargo xtask bench --instructions`: only the instruction counts (psmpa's, the floor's, the
/// peers' per plan) and where psmpa's step goes, printed and written into `docs/benchmarks.md`.
pub fn instructions() -> Result<(), String> {
    let root = firmware::root();
    let counts = instruction_counts(&root)?;
    let breakdown = step_breakdown(&root)?;
    let md = instructions_md(&counts, &breakdown);
    println!("{md}");
    crate::hil::write_between(&root.join("docs/benchmarks.md"), "instructions", &md)?;
    println!("written to docs/benchmarks.md");
    Ok(())
}

/// Runs everything (or, with `no_run`, reuses the last run's results), writes the table.
pub fn run(no_run: bool) -> Result<(), String> {
    let root = firmware::root();
    let extra_path = root.join("target/bench-extra.json");
    let extra = if no_run {
        let text = std::fs::read_to_string(&extra_path).map_err(|e| {
            format!(
                "{}: {e} (run `cargo xtask bench` first)",
                extra_path.display()
            )
        })?;
        serde_json::from_str(&text).map_err(|e| e.to_string())?
    } else {
        let extra = measure(&root)?;
        let text = serde_json::to_string_pretty(&extra).map_err(|e| e.to_string())?;
        std::fs::write(&extra_path, text).map_err(|e| e.to_string())?;
        extra
    };
    report(&root, &extra)
}

/// Runs the benches, the sweep and the instruction count.
fn measure(root: &Path) -> Result<Extra, String> {
    // Before minutes of benches: a missing valgrind fails at once.
    callgrind::check()?;
    let load = std::fs::read_to_string("/proc/loadavg")
        .ok()
        .map(|l| l.split_whitespace().take(3).collect::<Vec<_>>().join(", "));
    let text = cargo_bench(
        &[
            "-p",
            "psmpa-bench",
            "--bench",
            "plan",
            "--bench",
            "store",
            "--bench",
            "simulator",
        ],
        root,
    )?;
    let mut allocs = allocations(&text);
    // Its own package, at its own tick rate.
    let bt = root.join("bench/behaviortree");
    let bt_text = cargo_bench(
        &[
            "--manifest-path",
            &bt.join("Cargo.toml").to_string_lossy(),
            "--bench",
            "steps",
        ],
        &bt,
    )?;
    allocs.extend(allocations(&bt_text));
    let sweep_s = sweep_seconds()?;
    let counts = instruction_counts(root)?;
    for line in per_plan_lines(&counts.per_plan) {
        println!("{line}");
    }
    println!("{}", instructions_line(counts.per_step, Some(counts.floor)));
    Ok(Extra {
        allocations: allocs,
        sweep_s,
        instructions_per_step: Some(counts.per_step),
        floor_per_step: Some(counts.floor),
        instructions_per_plan: counts.per_plan,
        load,
    })
}

/// Every action step of the plan workload (asserted by every plan bench).
const PLAN_STEPS: f64 = 30.0;

/// Where psmpa stands in instructions per plan, said plainly: the times of one run move with
/// the machine's load, the counts do not.
fn standing(per_plan: &BTreeMap<String, f64>) -> String {
    let Some(&psmpa) = per_plan.get("psmpa") else {
        return String::new();
    };
    let mut out = String::from(
        "\nThe times move with the machine's load from run to run; the instruction counts \
         (callgrind, the same workload, `cargo xtask bench --instructions`) do not. In \
         instructions per plan, psmpa executes ",
    );
    let peers: Vec<String> = PEERS
        .iter()
        .filter_map(|name| {
            let n = per_plan.get(*name)?;
            Some(format!(
                "{:.2}x {}'s ({})",
                psmpa / n,
                name,
                if psmpa < *n { "fewer" } else { "more" }
            ))
        })
        .collect();
    out.push_str(&peers.join(", "));
    out.push_str(
        ": it runs a sensor's sampler, the mutual data store, the FSM and the control loop \
         around the same work.\n",
    );
    out
}

/// Writes the table from criterion's results and `extra`.
fn report(root: &Path, extra: &Extra) -> Result<(), String> {
    let (allocs, sweep) = (&extra.allocations, extra.sweep_s);
    let mut results = read_criterion(&root.join("target/criterion"))?;
    results.extend(read_criterion(
        &root.join("bench/behaviortree/target/criterion"),
    )?);

    let get = |group: &str, name: &str| {
        results
            .get(&(group.to_owned(), name.to_owned()))
            .copied()
            .ok_or_else(|| format!("no result for {group}/{name}"))
    };
    let mut md = String::new();
    md.push_str(&format!(
        "Measured by `cargo xtask bench` in one run (criterion medians, one core of this project's \
         2-core machine, {}{}).\n\n",
        std::env::consts::ARCH,
        extra.load.as_ref().map_or(String::new(), |l| format!(
            "; load average {l} when the run began"
        ))
    ));
    md.push_str("**The plan workload**: 3 actions in sequence, 10 steps each, a sensor condition checked and one store read and one write per step (`bench/src/workload.rs`).\n\n");
    md.push_str("| implementation | per plan | per action step | vs hand-written | instructions per plan (callgrind) | heap allocations per plan |\n|---|---|---|---|---|---|\n");
    let floor = get("plan", "hand-written FSM")?;
    let floor_step = floor.ns / PLAN_STEPS;
    let mut plan_rows: Vec<(String, Measured)> = results
        .iter()
        .filter(|((g, _), _)| g == "plan")
        .map(|((_, f), m)| (f.clone(), *m))
        .collect();
    plan_rows.sort_by(|a, b| a.1.ns.total_cmp(&b.1.ns));
    for (name, m) in &plan_rows {
        let step = m.ns / PLAN_STEPS;
        md.push_str(&format!(
            "| {name} | {} | {} | {:.1}x | {} | {} |\n",
            fmt_ns(m.ns),
            fmt_ns(step),
            step / floor_step,
            extra
                .instructions_per_plan
                .get(name)
                .map_or("-".to_owned(), |n| fmt_count(*n)),
            allocs.get(name).map_or("?".to_owned(), |a| a.to_string())
        ));
    }
    md.push_str(&standing(&extra.instructions_per_plan));
    match extra.instructions_per_step {
        Some(per_step) => md.push_str(&format!(
            "\n{}. `cargo xtask bench --instructions` counts them alone: `bench/examples/profile_plan.rs` and `profile_floor.rs` under callgrind for {} and {} plans, the difference in instructions over the difference in action steps. The floor does the step's work (a timer wakes a sensing future that samples, stores, fuses and checks, then signals a deciding future that reads and writes a store) with no FSM, control loop, sensor switching or trace (psmpa runs the workload with no sink, which traces nothing).\n",
            instructions_line(per_step, extra.floor_per_step),
            CALLGRIND_PLANS[0],
            CALLGRIND_PLANS[1]
        )),
        None => md.push_str("\npsmpa's instructions per action step: not measured in this run.\n"),
    }
    md.push_str("\n**Data stores**: one get and one put of the same key, 8 keys.\n\n| store | per get + put | vs fixed array |\n|---|---|---|\n");
    let array = get("store", "fixed array")?;
    let mut store_rows: Vec<(String, Measured)> = results
        .iter()
        .filter(|((g, _), _)| g == "store")
        .map(|((_, f), m)| (f.clone(), *m))
        .collect();
    store_rows.sort_by(|a, b| a.1.ns.total_cmp(&b.1.ns));
    for (name, m) in &store_rows {
        md.push_str(&format!(
            "| {name} | {} | {:.2}x |\n",
            fmt_ns(m.ns / m.elements as f64),
            m.ns / array.ns
        ));
    }
    md.push_str("\n**Simulator**: one whole run of a paper scenario; real-time factor = simulated seconds per wall-clock second.\n\n| scenario / architecture | wall time per run | real-time factor |\n|---|---|---|\n");
    for ((_, f), m) in results.iter().filter(|((g, _), _)| g == "simulator") {
        md.push_str(&format!(
            "| {f} | {} | {:.0}x |\n",
            fmt_ns(m.ns),
            m.elements as f64 / (m.ns / 1e9)
        ));
    }
    md.push_str(&format!(
        "\n**Sweep**: `psmpa-sim sweep --runs 10000` (both architectures, so 20,000 simulations on both cores): {sweep:.2} s wall time (median of 3).\n"
    ));

    std::fs::write(
        root.join("bench/RESULTS.md"),
        format!("# Benchmark results\n\n{md}"),
    )
    .map_err(|e| e.to_string())?;
    replace_in_readme(root, "bench", &md)?;
    println!("\n{md}\nwritten to bench/RESULTS.md and README.md");
    Ok(())
}

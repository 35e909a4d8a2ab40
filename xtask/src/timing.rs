//! `cargo xtask timing`: the response-time analysis of the firmware, from step costs measured
//! in QEMU, and its check against every reaction the runs measure.
//!
//! * Costs: the firmware tells its two executors' polls apart: a sensing poll counts for the
//!   sensors whose events it emitted (sample, switch, fault); a deciding poll is control work
//!   (planning, a plan, the FSM) or a behaviour step. It logs the longest of each kind, the
//!   longest deciding poll, and the SysTick handler's longest run, in cycles, per run. Under
//!   `-icount` QEMU counts one cycle per instruction, deterministically.
//! * Model ([`psmpa_core::timing`]): each cyclic sensor is a periodic job whose processor time
//!   is its sample step and one SysTick interrupt, whose read waits the scenario's latency,
//!   and whose reaction is one behaviour step. Both sides share one thread, sensing first: a
//!   sample may wait for the deciding poll in progress, at its start and, after a read that
//!   waits, at its delivery ([`Blocking::one_executor`]). The response time `R` and the
//!   latency bound `max_lost · G + R` follow per sensor and per scenario.
//! * Check: every scenario's measured P-SMPA reactions are within its bound, and the set is
//!   schedulable; otherwise the task fails, naming why.

use std::collections::BTreeMap;
use std::path::PathBuf;

use psmpa_core::SensorId;
use psmpa_core::timing::{Blocking, Job, utilisation_ppm};
use psmpa_sim::robot::{fetch_tea, latency_bounds};
use serde::Serialize;

use crate::firmware;

/// Exception entry and exit on a Cortex-M4, cycles: outside what the handler measures.
const EXCEPTION_CYCLES: u64 = 24;

/// The worst cost of each kind of step over all runs, cycles.
#[derive(Debug, Default, Serialize)]
struct Costs {
    /// A sensing poll that worked for sensor `i`, by sensor index.
    sample: Vec<u64>,
    /// A deciding poll that planned, selected a plan or moved the FSM.
    control: u64,
    /// A deciding poll with no control work: a behaviour step.
    behaviour: u64,
    /// The SysTick handler, entry and exit included.
    systick: u64,
    /// The longest deciding poll: what a released sample may have to wait for.
    longest_deciding: u64,
    /// The longest poll of either executor.
    longest_poll: u64,
    /// Runs they were measured over.
    runs: usize,
}

#[derive(Debug, Serialize)]
struct Task {
    task: String,
    period_ns: u64,
    cost_ns: u64,
    read_latency_ns: u64,
    response_ns: u64,
    latency_bound_ns: u64,
}

#[derive(Debug, Serialize)]
struct ScenarioTiming {
    scenario: String,
    utilisation_ppm: u64,
    tasks: Vec<Task>,
    /// The longest P-SMPA reaction measured in QEMU, ms (`None`: nothing detected).
    measured_max_reaction_ms: Option<u64>,
}

#[derive(Debug, Serialize)]
struct Report {
    clock_hz: u64,
    blocking_ns: u64,
    costs_cycles: Costs,
    scenarios: Vec<ScenarioTiming>,
    host_instructions: Vec<HostCost>,
}

/// Instructions per call of one core function on the host, from callgrind.
#[derive(Debug, Serialize)]
struct HostCost {
    step: &'static str,
    function: &'static str,
    calls: u64,
    instructions: u64,
}

/// The core's steps as they appear in the host binary. The sensing side (reads, store writes,
/// fusion) is inlined into the poll of the installed sensing future; plan selection into the
/// control loop; only `locked-door` needs the planner (its cost per expansion is in
/// `psmpa_core::planner`'s docs).
const HOST_STEPS: &[(&str, &str)] = &[
    (
        "sensing side: one poll (samples)",
        "psmpa_sim::run::poll_erased",
    ),
    (
        "precondition check",
        "Runtime<M,S,A,T,_,_,_,_,_>>::check_precondition",
    ),
    (
        "behaviour step (one poll)",
        "as psmpa_core::platform::Actuator>::run::{{closure}}",
    ),
    ("store read", "as psmpa_core::store::StoreAccess>::get"),
    ("trace event (hash)", "psmpa_core::trace::TraceHash::add"),
    (
        "Algorithm 2: compile a plan",
        "psmpa_core::fsm::Fsm<_>::compile",
    ),
];

/// Runs the host simulator under callgrind on `scenarios` (P-SMPA) and sums, per function of
/// [`HOST_STEPS`], the calls and the instructions they took (inclusive).
fn host_costs(scenarios: &[&str]) -> Result<Vec<HostCost>, String> {
    let root = firmware::root();
    let sim = firmware::build_host_sim()?;
    let mut totals: BTreeMap<&str, (u64, u64)> = BTreeMap::new();
    for name in scenarios {
        let out_file = root.join(format!("target/callgrind.{name}.out"));
        let out = std::process::Command::new("valgrind")
            .current_dir(&root)
            .args([
                "--tool=callgrind",
                "--compress-strings=no",
                "--compress-pos=no",
            ])
            .arg(format!("--callgrind-out-file={}", out_file.display()))
            .arg(&sim)
            .args(["run", "--arch", "psmpa"])
            .arg(format!("scenarios/{name}.json"))
            .output()
            .map_err(|e| format!("cannot run valgrind ({e}): scripts/test.sh installs it"))?;
        if !out.status.success() {
            return Err(format!(
                "valgrind failed on {name}: {}",
                String::from_utf8_lossy(&out.stderr)
            ));
        }
        let text = std::fs::read_to_string(&out_file).map_err(|e| e.to_string())?;
        // `cfn=` names the callee, `calls=` counts the calls, and the next line holds the
        // position and the inclusive cost of those calls.
        let (mut callee, mut calls): (Option<&str>, Option<u64>) = (None, None);
        for line in text.lines() {
            if let Some(f) = line.strip_prefix("cfn=") {
                callee = Some(f);
            } else if let Some(c) = line.strip_prefix("calls=") {
                calls = c.split_whitespace().next().and_then(|n| n.parse().ok());
            } else if let (Some(f), Some(n)) = (callee, calls.take()) {
                let ir: u64 = line
                    .split_whitespace()
                    .nth(1)
                    .and_then(|v| v.parse().ok())
                    .unwrap_or(0);
                if let Some((_, pattern)) = HOST_STEPS.iter().find(|(_, p)| f.ends_with(p)) {
                    let t = totals.entry(pattern).or_default();
                    t.0 += n;
                    t.1 += ir;
                }
            }
        }
    }
    Ok(HOST_STEPS
        .iter()
        .map(|(step, function)| {
            let (calls, instructions) = totals.get(function).copied().unwrap_or_default();
            HostCost {
                step,
                function,
                calls,
                instructions,
            }
        })
        .collect())
}

fn number(fields: &BTreeMap<&str, &str>, key: &str) -> Result<u64, String> {
    fields
        .get(key)
        .and_then(|v| v.parse().ok())
        .ok_or_else(|| format!("the firmware log has no number `{key}` in {fields:?}"))
}

/// The worst cost of every kind of step in the firmware's log.
fn costs(log: &str) -> Result<Costs, String> {
    let steps = firmware::tagged(log, "steps");
    let polls = firmware::tagged(log, "polls");
    if steps.is_empty() || steps.len() != polls.len() {
        return Err("the firmware log lacks the `steps`/`polls` lines of its runs".to_owned());
    }
    let mut c = Costs {
        sample: vec![0; 4],
        runs: steps.len(),
        ..Costs::default()
    };
    for s in &steps {
        for (i, max) in c.sample.iter_mut().enumerate() {
            *max = (*max).max(number(s, &format!("sample{i}"))?);
        }
        c.control = c.control.max(number(s, "control")?);
        c.behaviour = c.behaviour.max(number(s, "behaviour")?);
        c.longest_deciding = c.longest_deciding.max(number(s, "deciding")?);
        c.systick = c.systick.max(number(s, "isr")? + EXCEPTION_CYCLES);
    }
    for p in &polls {
        c.longest_poll = c.longest_poll.max(number(p, "max_cycles")?);
    }
    Ok(c)
}

fn show_ms(ns: u64) -> String {
    format!("{:.3} ms", ns as f64 / 1e6)
}

/// Runs the firmware, analyses, checks, prints; writes the JSON report to `json`.
pub fn run(clock_hz: u64, json: Option<PathBuf>) -> Result<(), String> {
    if clock_hz == 0 {
        return Err("the clock must be at least 1 Hz".to_owned());
    }
    let ns = |cycles: u64| (cycles.saturating_mul(1_000_000_000)).div_ceil(clock_hz);
    let elf = firmware::build(&[])?;
    let log = firmware::run(&elf)?;
    let costs = costs(&log)?;
    let reactions: BTreeMap<(&str, &str), i64> = firmware::tagged(&log, "result")
        .iter()
        .filter_map(|f| {
            let r = f.get("max_reaction_ms")?.parse().ok()?;
            Some(((*f.get("scenario")?, *f.get("arch")?), r))
        })
        .collect();

    println!(
        "step costs in QEMU (-icount: one instruction a cycle), worst of {} runs, at {} MHz:",
        costs.runs,
        clock_hz as f64 / 1e6
    );
    println!("  {:<36} {:>8} {:>12}", "step", "cycles", "time");
    let mut cost_rows: Vec<(String, u64)> = Vec::new();
    let robot = psmpa_sim::robot::Robot::load(psmpa_sim::robot::FETCH_TEA)
        .map_err(|e| format!("the Fetch Tea mission: {e:?}"))?;
    for (i, c) in costs.sample.iter().enumerate().filter(|(_, c)| **c > 0) {
        let name = SensorId::new(i)
            .and_then(|id| robot.mission.domain.sensor(id))
            .map_or("?", |s| s.name);
        cost_rows.push((format!("sample step: {name} (+ others due)"), *c));
    }
    cost_rows.push(("behaviour step".to_owned(), costs.behaviour));
    cost_rows.push(("control (planning, plan, FSM)".to_owned(), costs.control));
    cost_rows.push(("SysTick handler".to_owned(), costs.systick));
    cost_rows.push((
        "longest deciding poll (blocking)".to_owned(),
        costs.longest_deciding,
    ));
    for (name, c) in &cost_rows {
        println!("  {name:<36} {c:>8} {:>12}", show_ms(ns(*c)));
    }

    let blocking_ns = ns(costs.longest_deciding);
    let blocking = Blocking::one_executor(blocking_ns);
    let mut scenarios = Vec::new();
    let mut failures = Vec::new();
    println!(
        "\n{:<13} {:<7} {:>10} {:>11} {:>10} {:>12} {:>14} {:>10}",
        "scenario", "task", "period", "job cost", "read", "response", "latency bound", "measured"
    );
    for file in firmware::scenario_files()? {
        let sc = psmpa_sim::load::load(&file).map_err(|e| e.to_string())?;
        let robot = fetch_tea(&sc).map_err(|e| format!("{}: {e:?}", sc.name))?;
        let domain = &robot.mission.domain;
        // One job per cyclic sensor: its sample step and the SysTick interrupt that releases
        // it; the behaviour step it wakes is the reaction.
        let cost = |id: SensorId| {
            let step = costs.sample.get(id.index()).copied().unwrap_or(0);
            ns(step + costs.systick)
        };
        let bounds = match latency_bounds(&robot, &sc, blocking, ns(costs.behaviour), cost) {
            Ok(bounds) => bounds,
            Err(e) => {
                failures.push(format!("{}: {e}", sc.name));
                continue;
            }
        };
        let jobs: Vec<Job> = bounds.iter().map(|b| b.job).collect();
        let utilisation = utilisation_ppm(&jobs).map_err(|e| e.to_string())?;
        let measured = reactions
            .get(&(sc.name.as_str(), "psmpa"))
            .copied()
            .ok_or_else(|| format!("{}: no P-SMPA result in the firmware log", sc.name))?;
        let measured = u64::try_from(measured).ok();
        let mut tasks = Vec::new();
        for b in &bounds {
            let name = domain.sensor(b.sensor).map_or("?", |s| s.name);
            println!(
                "{:<13} {:<7} {:>10} {:>11} {:>10} {:>12} {:>14} {:>10}",
                if tasks.is_empty() {
                    sc.name.as_str()
                } else {
                    ""
                },
                name,
                show_ms(b.job.period_ns),
                show_ms(b.job.cost_ns),
                show_ms(b.job.latency_ns),
                show_ms(b.response.response_ns),
                show_ms(b.bound_ns),
                match (tasks.is_empty(), measured) {
                    (true, Some(m)) => format!("{m} ms"),
                    (true, None) => "-".to_owned(),
                    _ => String::new(),
                }
            );
            tasks.push(Task {
                task: name.to_owned(),
                period_ns: b.job.period_ns,
                cost_ns: b.job.cost_ns,
                read_latency_ns: b.job.latency_ns,
                response_ns: b.response.response_ns,
                latency_bound_ns: b.bound_ns,
            });
        }
        // A box is perceived by the sonar and the bumper: the larger bound holds for either.
        let bound = tasks.iter().map(|t| t.latency_bound_ns).max().unwrap_or(0);
        if let Some(m) = measured.filter(|m| m * 1_000_000 > bound) {
            failures.push(format!(
                "{}: a reaction of {m} ms exceeds the bound of {}",
                sc.name,
                show_ms(bound)
            ));
        }
        scenarios.push(ScenarioTiming {
            scenario: sc.name.as_str().to_owned(),
            utilisation_ppm: utilisation,
            tasks,
            measured_max_reaction_ms: measured,
        });
    }
    let host_scenarios = ["sonar-8", "locked-door"];
    let host = host_costs(&host_scenarios)?;
    println!(
        "\non the host (x86-64), callgrind instruction counts, P-SMPA runs of {}:",
        host_scenarios.join(" and ")
    );
    println!("  {:<30} {:>9} {:>14}", "step", "calls", "instr./call");
    for h in &host {
        let per_call = h.instructions.checked_div(h.calls);
        println!(
            "  {:<30} {:>9} {:>14}",
            h.step,
            h.calls,
            per_call.map_or("-".to_owned(), |p| p.to_string())
        );
    }
    let report = Report {
        clock_hz,
        blocking_ns,
        costs_cycles: costs,
        scenarios,
        host_instructions: host,
    };
    let path = json.unwrap_or_else(|| firmware::root().join("target/timing.json"));
    let text = serde_json::to_string_pretty(&report).map_err(|e| e.to_string())?;
    std::fs::write(&path, text + "\n").map_err(|e| format!("{}: {e}", path.display()))?;
    println!("\nwritten to {}", path.display());
    if failures.is_empty() {
        let worst = report
            .scenarios
            .iter()
            .map(|s| s.utilisation_ppm)
            .max()
            .unwrap_or(0);
        println!(
            "schedulable in every scenario (utilisation at most {:.2} %); every measured reaction is within its bound",
            worst as f64 / 1e4
        );
        Ok(())
    } else {
        Err(failures.join("\n"))
    }
}

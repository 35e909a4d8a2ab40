//! `cargo xtask timing`: the response-time analysis of the firmware, from step costs measured
//! in QEMU, and its check against every reaction the runs measure, in cycles; on both cores,
//! mps2-an386's Cortex-M4F and mps2-an505's Cortex-M33, each analysed and checked on its own,
//! then their step costs side by side.
//!
//! * Costs: the firmware tells its two executors' polls apart: a sensing poll (interrupt
//!   priority) counts for the sensors whose events it emitted (sample, switch, fault); a
//!   deciding poll (thread mode) is control work (planning, a plan, the FSM) or a behaviour
//!   step. It logs, per run and in cycles, the longest of each kind, the longest deciding poll,
//!   the longest critical section the deciding side held, and the alarm handler's longest run.
//!   A poll's cost leaves out the time a preempting handler took. Under `-icount shift=5`
//!   QEMU advances virtual time 32 ns per instruction, deterministically, on both machines: a
//!   cycle of mps2-an386's 25 MHz timers (40 ns) is 1.25 instructions, one of mps2-an505's
//!   20 MHz timers (50 ns) 1.5625. Instructions are the unit in which the two cores compare.
//! * Model ([`psmpa_core::timing`]): each cyclic sensor is a periodic job on the sensing side
//!   whose processor time is its sample step and whose read waits the scenario's latency; the
//!   alarm interrupt is a job of period one tick that interferes with everything; the reaction
//!   is one deciding poll on the deciding side: a behaviour step, or the control poll that
//!   halts the robot when a violation outlasts its limit. Sensing preempts deciding, so a
//!   sample waits at most for a critical section, and the reaction for the deciding poll in
//!   progress ([`Blocking::preemptive`]). The response time `R` (release to the behaviour having
//!   reacted) and the latency bound `max_lost · G + R` follow per sensor and per scenario.
//! * Costs per scenario: the sensing side's and the alarm's are the worst of all runs; the
//!   deciding side's are the worst of the scenario's own runs and of every run that spends no
//!   planning time (`robot.plan_us` 0), so one scenario's 50 ms planning step does not inflate
//!   every other scenario's bound.
//! * Check: in every scenario the set is schedulable, each sensor's worst reaction measured in
//!   cycles (from the release of the sample that registered an obstacle to the stop being
//!   commanded) is within its `R`, and the world's measured reactions (obstacle to stop, ms)
//!   are within the latency bound; otherwise the task fails, naming why. The measurements are
//!   taken at each machine's own clock, so they are checked only there (not under
//!   `--clock-hz`).

use std::collections::BTreeMap;
use std::path::PathBuf;

use psmpa_core::SensorId;
use psmpa_core::timing::{Blocking, Job, utilisation_ppm};
use psmpa_sim::robot::{fetch_tea, latency_bounds};
use serde::Serialize;

use crate::firmware::{MACHINES, Machine};
use crate::{callgrind, firmware};

/// Exception entry and exit on a Cortex-M4 or a Cortex-M33 (12 cycles each without a
/// security state change), cycles: outside what the handler measures.
const EXCEPTION_CYCLES: u64 = 24;

/// Cycles of `machine`'s clock in ns, rounded up.
fn firmware_ns(machine: Machine, cycles: u64) -> u64 {
    cycles
        .saturating_mul(1_000_000_000)
        .div_ceil(machine.clock_hz)
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
/// fusion) is inlined into the test kit's poll of the sensing future; plan selection into the
/// control loop; only `locked-door` needs the planner (its cost per expansion is in
/// `psmpa_core::planner`'s docs).
const HOST_STEPS: &[(&str, &str)] = &[
    (
        "sensing side: one poll (samples)",
        "psmpa_testkit::sim::poll_sensing",
    ),
    // The common case (holds, held) is decided inline in the sensing poll; this is a change.
    (
        "precondition check, a change",
        "psmpa_core::runtime::sensing::check_changed",
    ),
    (
        "behaviour step (one poll)",
        // The Fetch Tea robot's, on its compiled mission.
        "as psmpa_core::platform::Actuator<psmpa_fetch_tea::fetch_tea::FetchTea>>::run::{{closure}}",
    ),
    (
        "store read, a sample",
        "as psmpa_core::store::SensorStores>::get",
    ),
    // The hash's mixing is inlined into the runtime; its encoding of the event is not.
    (
        "trace event's words (its encoding)",
        "psmpa_core::trace::TraceHash::words",
    ),
    (
        // A plan the planner made (locked-door's) runs through the run-time FSM.
        "Algorithm 2: compile a plan",
        "psmpa_core::runtime::fsm::Fsm::compile",
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
        let scenario = format!("scenarios/{name}.json");
        callgrind::run(
            &root,
            &out_file,
            &["--compress-strings=no", "--compress-pos=no"],
            &sim,
            &["run", "--arch", "psmpa", &scenario],
        )?;
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
    // A step no call reached was inlined away or renamed: its figure would be missing, not 0.
    if let Some((step, function)) = HOST_STEPS
        .iter()
        .find(|(_, f)| totals.get(f).is_none_or(|(calls, _)| *calls == 0))
    {
        return Err(format!(
            "the host's {step}: no call of a function ending in {function} (inlined, or renamed?)"
        ));
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

/// The worst cost of each kind of step, cycles.
#[derive(Clone, Debug, Default, Serialize)]
struct Costs {
    /// A sensing poll that worked for sensor `i`, by sensor index.
    sample: Vec<u64>,
    /// A deciding poll that planned, selected a plan or moved the FSM.
    control: u64,
    /// A deciding poll with no control work: a behaviour step.
    behaviour: u64,
    /// The longest deciding poll: what the reaction may wait for.
    longest_deciding: u64,
    /// The longest critical section entered below the sensing priority: what a sample may
    /// wait for.
    critical: u64,
    /// The alarm handler, entry and exit included.
    alarm: u64,
}

impl Costs {
    fn from_steps(s: &BTreeMap<&str, &str>) -> Result<Self, String> {
        Ok(Self {
            sample: (0..4)
                .map(|i| number(s, &format!("sample{i}")))
                .collect::<Result<_, _>>()?,
            control: number(s, "control")?,
            behaviour: number(s, "behaviour")?,
            longest_deciding: number(s, "deciding")?,
            critical: number(s, "critical")?,
            alarm: number(s, "isr")? + EXCEPTION_CYCLES,
        })
    }

    /// The worst of both, field by field.
    fn max(mut self, other: &Self) -> Self {
        for (a, b) in self.sample.iter_mut().zip(&other.sample) {
            *a = (*a).max(*b);
        }
        self.sample
            .resize(self.sample.len().max(other.sample.len()), 0);
        self.control = self.control.max(other.control);
        self.behaviour = self.behaviour.max(other.behaviour);
        self.longest_deciding = self.longest_deciding.max(other.longest_deciding);
        self.critical = self.critical.max(other.critical);
        self.alarm = self.alarm.max(other.alarm);
        self
    }

    /// These costs with the deciding side's taken from `deciding`.
    fn deciding_from(mut self, deciding: &Self) -> Self {
        self.control = deciding.control;
        self.behaviour = deciding.behaviour;
        self.longest_deciding = deciding.longest_deciding;
        self
    }
}

/// One run of the firmware: its costs and, for P-SMPA, its worst reactions in cycles.
struct Run {
    costs: Costs,
    /// Sonar, bumper: the worst reaction measured, cycles (0: none).
    reaction_cycles: [u64; 2],
    /// The world's longest reaction, obstacle to stop, ms (`None`: nothing detected).
    max_reaction_ms: Option<u64>,
}

/// Every run of the firmware's log, by scenario and architecture.
fn runs(log: &str) -> Result<BTreeMap<(String, String), Run>, String> {
    let key = |f: &BTreeMap<&str, &str>| -> Result<(String, String), String> {
        match (f.get("scenario"), f.get("arch")) {
            (Some(s), Some(a)) => Ok(((*s).to_owned(), (*a).to_owned())),
            _ => Err(format!("a firmware log line without its run: {f:?}")),
        }
    };
    let mut runs = BTreeMap::new();
    for s in firmware::tagged(log, "steps") {
        let run = Run {
            costs: Costs::from_steps(&s)?,
            reaction_cycles: [0; 2],
            max_reaction_ms: None,
        };
        runs.insert(key(&s)?, run);
    }
    if runs.is_empty() {
        return Err("the firmware log has no `steps` line".to_owned());
    }
    for c in firmware::tagged(log, "clock") {
        let run = runs
            .get_mut(&key(&c)?)
            .ok_or_else(|| format!("a `clock` line without `steps`: {c:?}"))?;
        run.reaction_cycles = [
            number(&c, "reaction_sonar_cycles")?,
            number(&c, "reaction_bumper_cycles")?,
        ];
    }
    for r in firmware::tagged(log, "result") {
        let run = runs
            .get_mut(&key(&r)?)
            .ok_or_else(|| format!("a `result` line without `steps`: {r:?}"))?;
        // -1: nothing detected.
        run.max_reaction_ms = r.get("max_reaction_ms").and_then(|v| v.parse().ok());
    }
    Ok(runs)
}

#[derive(Debug, Serialize)]
struct Task {
    task: String,
    period_ns: u64,
    cost_ns: u64,
    read_latency_ns: u64,
    /// Release to delivery of the sample.
    sample_ns: u64,
    /// Release to the behaviour step having reacted: `R`.
    response_ns: u64,
    latency_bound_ns: u64,
    /// The worst reaction measured in QEMU, release to stop, cycles (`None`: none registered).
    measured_reaction_cycles: Option<u64>,
}

#[derive(Debug, Serialize)]
struct ScenarioTiming {
    scenario: String,
    utilisation_ppm: u64,
    costs_cycles: Costs,
    tasks: Vec<Task>,
    /// The longest P-SMPA reaction the world measured in QEMU, obstacle to stop, ms (`None`:
    /// nothing detected).
    measured_max_reaction_ms: Option<u64>,
}

/// One machine's analysis.
#[derive(Debug, Serialize)]
struct MachineReport {
    machine: &'static str,
    core: &'static str,
    /// The clock its timers count: the unit of its cycles.
    firmware_clock_hz: u64,
    /// The clock the cycles are converted to time at (`--clock-hz`, or the firmware's own).
    clock_hz: u64,
    /// The worst costs of all runs, cycles.
    costs_cycles: Costs,
    runs: usize,
    scenarios: Vec<ScenarioTiming>,
}

#[derive(Debug, Serialize)]
struct Report {
    machines: Vec<MachineReport>,
    host_instructions: Vec<HostCost>,
}

fn show_ms(ns: u64) -> String {
    format!("{:.3} ms", ns as f64 / 1e6)
}

/// The sensors whose reactions the firmware measures, as `clock` names them.
const MEASURED: [&str; 2] = ["sonar", "bumper"];

/// What one machine's analysis found: its report, the step costs' rows (name, cycles) and
/// what failed.
struct Analysis {
    report: MachineReport,
    rows: Vec<(String, u64)>,
    failures: Vec<String>,
}

/// Analyses one machine's log with its cycles converted at `clock_hz`, checks and prints.
fn analyse(
    machine: Machine,
    clock_hz: u64,
    log: &str,
    scenarios_loaded: &[psmpa_sim::scenario::Scenario],
) -> Result<Analysis, String> {
    let ns = |cycles: u64| (cycles.saturating_mul(1_000_000_000)).div_ceil(clock_hz);
    // The measurements are taken at the machine's own clock: checked only there.
    let own_clock = clock_hz == machine.clock_hz;
    let runs = runs(log)?;
    let plans = |name: &str| {
        scenarios_loaded
            .iter()
            .find(|s| s.name.as_str() == name)
            .is_some_and(|s| s.plan_us > 0)
    };
    let all = runs
        .values()
        .fold(Costs::default(), |acc, r| acc.max(&r.costs));
    let plan_free = runs
        .iter()
        .filter(|((scenario, _), _)| !plans(scenario))
        .fold(Costs::default(), |acc, (_, r)| acc.max(&r.costs));

    println!(
        "\n{} ({}): step costs in QEMU (-icount: {} instructions a {} MHz cycle), worst of {} runs, at {} MHz:",
        machine.name,
        machine.core,
        machine.instructions(1_000_000) as f64 / 1e6,
        machine.clock_hz as f64 / 1e6,
        runs.len(),
        clock_hz as f64 / 1e6
    );
    println!("  {:<40} {:>9} {:>12}", "step", "cycles", "time");
    let robot = psmpa_sim::robot::Robot::load(psmpa_sim::robot::FETCH_TEA)
        .map_err(|e| format!("the Fetch Tea mission: {e:?}"))?;
    let sensor_name = |i: usize| {
        SensorId::new(i)
            .and_then(|id| robot.mission.domain.sensor(id))
            .map_or("?", |s| s.name)
    };
    let mut rows: Vec<(String, u64)> = Vec::new();
    for (i, c) in all.sample.iter().enumerate().filter(|(_, c)| **c > 0) {
        rows.push((
            format!("sample step: {} (+ others due)", sensor_name(i)),
            *c,
        ));
    }
    rows.push((
        "alarm interrupt (entry and exit incl.)".to_owned(),
        all.alarm,
    ));
    rows.push(("critical section below sensing".to_owned(), all.critical));
    rows.push((
        "behaviour step, no planning".to_owned(),
        plan_free.behaviour,
    ));
    rows.push((
        "control (planning, plan, FSM)".to_owned(),
        plan_free.control,
    ));
    rows.push((
        "longest deciding poll, no planning".to_owned(),
        plan_free.longest_deciding,
    ));
    rows.push((
        "longest deciding poll, any".to_owned(),
        all.longest_deciding,
    ));
    for (name, c) in &rows {
        println!("  {name:<40} {c:>9} {:>12}", show_ms(ns(*c)));
    }

    let mut scenarios = Vec::new();
    let mut failures = Vec::new();
    println!(
        "\n{:<12} {:<7} {:>10} {:>10} {:>10} {:>10} {:>10} {:>14} {:>11} {:>9}",
        "scenario",
        "task",
        "period",
        "job cost",
        "read",
        "sample S",
        "response R",
        "measured (cyc)",
        "bound",
        "measured"
    );
    for sc in scenarios_loaded {
        let robot = fetch_tea(sc).map_err(|e| format!("{}: {e:?}", sc.name))?;
        let domain = &robot.mission.domain;
        let own = runs
            .iter()
            .filter(|((s, _), _)| s == sc.name.as_str())
            .fold(plan_free.clone(), |acc, (_, r)| acc.max(&r.costs));
        let costs = all.clone().deciding_from(&own);
        let psmpa = runs
            .get(&(sc.name.as_str().to_owned(), "psmpa".to_owned()))
            .ok_or_else(|| format!("{}: no P-SMPA run in the firmware log", sc.name))?;
        let blocking = Blocking::preemptive(ns(costs.longest_deciding), ns(costs.critical));
        // The alarm releases the samples; it fires at most once a tick (1 ms).
        let alarm = Job {
            period_ns: 1_000_000,
            cost_ns: ns(costs.alarm),
            latency_ns: 0,
        };
        // A sample step is a poll of the sensing executor, in its interrupt: add the entry and
        // exit.
        let cost = |id: SensorId| {
            ns(costs.sample.get(id.index()).copied().unwrap_or(0) + EXCEPTION_CYCLES)
        };
        // The reaction is the behaviour step that stops, or the control poll that halts the
        // robot when a violation outlasts its limit: the longer of the two.
        let reaction = ns(costs.behaviour.max(costs.control));
        let bounds = match latency_bounds(&robot, sc, blocking, reaction, cost, &[alarm]) {
            Ok(bounds) => bounds,
            Err(e) => {
                failures.push(format!("{}: {e}", sc.name));
                continue;
            }
        };
        let jobs: Vec<Job> = bounds
            .iter()
            .map(|b| b.job)
            .chain(std::iter::once(alarm))
            .collect();
        let utilisation = utilisation_ppm(&jobs).map_err(|e| e.to_string())?;
        let measured_ms = psmpa.max_reaction_ms;
        let mut tasks = Vec::new();
        for b in &bounds {
            let name = domain.sensor(b.sensor).map_or("?", |s| s.name);
            let measured = MEASURED
                .iter()
                .position(|m| *m == name)
                .and_then(|i| psmpa.reaction_cycles.get(i).copied())
                .filter(|c| *c > 0);
            // Measured at the firmware's clock; under another `--clock-hz` the reads and the
            // tick grid would not scale with it, so the comparison is made at its own only.
            if let Some(c) =
                measured.filter(|c| own_clock && firmware_ns(machine, *c) > b.response.response_ns)
            {
                failures.push(format!(
                    "{}: a {name} reaction of {c} cycles ({}) exceeds its response time of {}",
                    sc.name,
                    show_ms(firmware_ns(machine, c)),
                    show_ms(b.response.response_ns)
                ));
            }
            println!(
                "{:<12} {:<7} {:>10} {:>10} {:>10} {:>10} {:>10} {:>14} {:>11} {:>9}",
                if tasks.is_empty() {
                    sc.name.as_str()
                } else {
                    ""
                },
                name,
                show_ms(b.job.period_ns),
                show_ms(b.job.cost_ns),
                show_ms(b.job.latency_ns),
                show_ms(b.response.sample_ns),
                show_ms(b.response.response_ns),
                measured.map_or("-".to_owned(), |c| c.to_string()),
                show_ms(b.bound_ns),
                match (tasks.is_empty(), measured_ms) {
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
                sample_ns: b.response.sample_ns,
                response_ns: b.response.response_ns,
                latency_bound_ns: b.bound_ns,
                measured_reaction_cycles: measured,
            });
        }
        // A box is perceived by the sonar and the bumper: the larger bound holds for either.
        let bound = tasks.iter().map(|t| t.latency_bound_ns).max().unwrap_or(0);
        if let Some(m) = measured_ms.filter(|m| own_clock && m * 1_000_000 > bound) {
            failures.push(format!(
                "{}: a reaction of {m} ms exceeds the bound of {}",
                sc.name,
                show_ms(bound)
            ));
        }
        scenarios.push(ScenarioTiming {
            scenario: sc.name.as_str().to_owned(),
            utilisation_ppm: utilisation,
            costs_cycles: costs,
            tasks,
            measured_max_reaction_ms: measured_ms,
        });
    }
    if !own_clock {
        println!(
            "(the measured reactions were taken at the firmware's {} MHz: they are shown, not checked, against bounds at another clock)",
            machine.clock_hz as f64 / 1e6
        );
    }
    if failures.is_empty() {
        let worst = scenarios
            .iter()
            .map(|s| s.utilisation_ppm)
            .max()
            .unwrap_or(0);
        println!(
            "{}: schedulable in every scenario (utilisation at most {:.2} %); every measured reaction is within its bound",
            machine.name,
            worst as f64 / 1e4
        );
    }
    Ok(Analysis {
        report: MachineReport {
            machine: machine.name,
            core: machine.core,
            firmware_clock_hz: machine.clock_hz,
            clock_hz,
            costs_cycles: all,
            runs: runs.len(),
            scenarios,
        },
        rows,
        failures: failures
            .into_iter()
            .map(|f| format!("{}: {f}", machine.name))
            .collect(),
    })
}

/// The step costs of every machine side by side: cycles of each machine's timers, and the
/// instructions they are under `-icount`, the unit in which the cores compare.
fn print_comparison(analyses: &[(Machine, Analysis)]) {
    let Some((_, first)) = analyses.first() else {
        return;
    };
    println!(
        "\nstep costs side by side (cycles of each machine's timers; instructions: QEMU runs 32 ns an instruction on both):"
    );
    print!("  {:<40}", "step");
    for (m, _) in analyses {
        print!(" {:>20} {:>8}", format!("{} cycles", m.name), "instr.");
    }
    println!();
    for (name, _) in &first.rows {
        print!("  {name:<40}");
        for (m, a) in analyses {
            match a.rows.iter().find(|(n, _)| n == name) {
                Some((_, c)) => print!(" {c:>20} {:>8}", m.instructions(*c)),
                None => print!(" {:>20} {:>8}", "-", "-"),
            }
        }
        println!();
    }
}

/// Nanoseconds as milliseconds to a tenth, thousands grouped: `1,003.0`.
fn tenths(ns: u64) -> String {
    let tenths = ns.div_ceil(100_000);
    format!("{}.{}", crate::hil::thousands(tenths / 10), tenths % 10)
}

/// The figures of a run at the machines' own clocks, for the pages: the step costs side by
/// side, each machine's reaction bounds (one row for the scenarios that share them), the
/// utilisation, the host's callgrind counts, and the README's cell.
fn pages(
    analyses: &[(Machine, Analysis)],
    host: &[HostCost],
) -> Vec<(&'static str, &'static str, String)> {
    let group = crate::hil::thousands;
    let mut steps = String::from("\n| step |");
    for (m, _) in analyses {
        steps += &format!(" {} cycles |", m.core);
    }
    steps += " time |";
    for (m, _) in analyses {
        steps += &format!(" {} instructions |", m.core);
    }
    steps += "\n|---|";
    for _ in 0..analyses.len() * 2 + 1 {
        steps += "---|";
    }
    steps += "\n";
    let Some((_, first)) = analyses.first() else {
        return Vec::new();
    };
    for (name, _) in &first.rows {
        let found: Vec<(Machine, u64)> = analyses
            .iter()
            .filter_map(|(m, a)| {
                a.rows
                    .iter()
                    .find(|(n, _)| n == name)
                    .map(|(_, c)| (*m, *c))
            })
            .collect();
        steps += &format!("| {name} |");
        for (_, c) in &found {
            steps += &format!(" {} |", group(*c));
        }
        let times: Vec<String> = found
            .iter()
            .map(|(m, c)| format!("{:.3}", *c as f64 * 1e3 / m.clock_hz as f64))
            .collect();
        steps += &format!(" {} ms |", times.join(" / "));
        for (m, c) in &found {
            steps += &format!(" {} |", group(m.instructions(*c)));
        }
        steps += "\n";
    }
    let ms = |ns: u64| format!("{:.3} ms", ns as f64 / 1e6);
    let mut tasks = String::new();
    let mut utilisation = Vec::new();
    for (m, a) in analyses {
        tasks += &format!(
            "\nOn `{}` (at {} MHz):\n\n| task | scenarios | period | job cost | read `L` | sample `S` | response `R` | worst measured reaction | latency bound |\n|---|---|---|---|---|---|---|---|---|\n",
            m.name,
            m.clock_hz / 1_000_000
        );
        // One row for the scenarios whose figures agree.
        // The scenarios, their figures, the worst reaction measured in them and where.
        type Row<'t> = (Vec<String>, &'t Task, Option<(u64, String)>);
        let mut rows: Vec<Row<'_>> = Vec::new();
        for sc in &a.report.scenarios {
            for t in &sc.tasks {
                let key = |x: &Task| {
                    (
                        x.task.clone(),
                        x.period_ns,
                        x.cost_ns,
                        x.read_latency_ns,
                        x.sample_ns,
                        x.response_ns,
                        x.latency_bound_ns,
                    )
                };
                let measured = t.measured_reaction_cycles.map(|c| (c, sc.scenario.clone()));
                match rows.iter_mut().find(|(_, r, _)| key(r) == key(t)) {
                    Some((names, _, worst)) => {
                        names.push(sc.scenario.clone());
                        if measured.as_ref().map(|(c, _)| *c) > worst.as_ref().map(|(c, _)| *c) {
                            *worst = measured;
                        }
                    }
                    None => rows.push((vec![sc.scenario.clone()], t, measured)),
                }
            }
        }
        rows.sort_by(|x, y| {
            (x.1.task.as_str(), x.1.latency_bound_ns)
                .cmp(&(y.1.task.as_str(), y.1.latency_bound_ns))
        });
        for (names, t, worst) in rows {
            let scenarios = if names.len() > 3 {
                format!("{} scenarios", names.len())
            } else {
                names
                    .iter()
                    .map(|n| format!("`{n}`"))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            // To 10 µs: a run's worst reaction has moved by tens of cycles from one clean
            // checkout to another (the worst of a group, and where, with it).
            let measured = worst.map_or("-".to_owned(), |(c, _)| {
                format!("{:.2} ms", c as f64 * 1e3 / m.clock_hz as f64)
            });
            tasks += &format!(
                "| {} | {scenarios} | {} ms | {} | {} | {} | {} | {measured} | {} ms |\n",
                t.task,
                t.period_ns / 1_000_000,
                ms(t.cost_ns),
                ms(t.read_latency_ns),
                ms(t.sample_ns),
                ms(t.response_ns),
                tenths(t.latency_bound_ns)
            );
        }
        let most = a
            .report
            .scenarios
            .iter()
            .map(|s| s.utilisation_ppm)
            .max()
            .unwrap_or(0);
        utilisation.push(format!("{:.2} % on the {}", most as f64 / 1e4, m.core));
    }
    let host_text = host
        .iter()
        .map(|h| {
            format!(
                "{} {}",
                h.step,
                h.instructions
                    .checked_div(h.calls)
                    .map_or("-".to_owned(), group)
            )
        })
        .collect::<Vec<_>>()
        .join(", ");
    // The README: each measured sensor's largest bound, and the utilisation.
    let bounds: Vec<String> = MEASURED
        .iter()
        .filter_map(|sensor| {
            analyses
                .iter()
                .flat_map(|(_, a)| a.report.scenarios.iter())
                .flat_map(|sc| {
                    sc.tasks
                        .iter()
                        .filter(|t| t.task == *sensor)
                        .map(move |t| (t.latency_bound_ns, sc.scenario.as_str()))
                })
                .max()
                .map(|(b, sc)| format!("{sensor} {} ms (`{sc}`)", tenths(b)))
        })
        .collect();
    let cell = format!(
        "latency bounds at most: {}; utilisation at most {}",
        bounds.join(", "),
        utilisation.join(", ")
    );
    vec![
        ("README.md", "timing", cell),
        ("docs/firmware.md", "timing-steps", steps),
        ("docs/firmware.md", "timing-tasks", tasks),
        (
            "docs/firmware.md",
            "timing-utilisation",
            utilisation.join(", "),
        ),
        ("docs/firmware.md", "timing-host", host_text),
    ]
}

/// Runs the firmware on every machine, analyses, checks, prints; writes the JSON report to
/// `json`. `clock_hz` converts every machine's cycles at that clock instead of its own.
pub fn run(clock_hz: Option<u64>, json: Option<PathBuf>) -> Result<(), String> {
    if clock_hz == Some(0) {
        return Err("the clock must be at least 1 Hz".to_owned());
    }
    let elfs = firmware::build_for(&MACHINES, &[])?;
    let runs: Vec<(Machine, PathBuf)> = MACHINES.iter().copied().zip(elfs).collect();
    let logs = firmware::run_all(&runs);
    let files = firmware::scenario_files()?;
    let scenarios_loaded = files
        .iter()
        .map(|f| psmpa_sim::load::load(f).map_err(|e| e.to_string()))
        .collect::<Result<Vec<_>, _>>()?;
    let mut analyses = Vec::new();
    for ((machine, _), log) in runs.iter().zip(logs) {
        let machine = *machine;
        let a = analyse(
            machine,
            clock_hz.unwrap_or(machine.clock_hz),
            &log?,
            &scenarios_loaded,
        )?;
        analyses.push((machine, a));
    }
    print_comparison(&analyses);
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
    let failures: Vec<String> = analyses
        .iter()
        .flat_map(|(_, a)| a.failures.iter().cloned())
        .collect();
    // The pages carry the figures at the machines' own clocks only.
    if clock_hz.is_none() && failures.is_empty() {
        let regions: Vec<_> = pages(&analyses, &host)
            .into_iter()
            .map(|(page, marker, text)| (firmware::root().join(page), marker, text))
            .collect();
        crate::pages::write_pages(&regions)?;
    }
    let report = Report {
        machines: analyses.into_iter().map(|(_, a)| a.report).collect(),
        host_instructions: host,
    };
    let path = json.unwrap_or_else(|| firmware::root().join("target/timing.json"));
    let text = serde_json::to_string_pretty(&report).map_err(|e| e.to_string())?;
    crate::pages::write_file(&path, (text + "\n").as_bytes())?;
    println!("\nwritten to {}", path.display());
    if failures.is_empty() {
        println!(
            "on every machine ({}): schedulable in every scenario; every measured reaction is within its bound",
            report
                .machines
                .iter()
                .map(|m| m.machine)
                .collect::<Vec<_>>()
                .join(", ")
        );
        Ok(())
    } else {
        Err(failures.join("\n"))
    }
}

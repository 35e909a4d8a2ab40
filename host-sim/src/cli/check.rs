//! `psmpa-sim check`: validates a mission file for this robot and shows what Algorithm 2 makes
//! of it: each plan's FSM with the sensors that run beside every action state.

use std::fmt::Write as _;
use std::path::Path;

use psmpa_core::mission::{self, AnyBehaviour};
use psmpa_core::planner::{Planner, PlanningError, Strategy};
use psmpa_core::{Fsm, PlanId, SensorSet, Tables, Target};

use crate::json;
use crate::robot::{self, NaoAction, NaoRegistry, NaoSensor};

pub use psmpa_model::check::{error_line, unreachable_goal};

/// Capacities used when the mission is checked without this robot: the largest the core
/// supports in a sensor set and a plan set.
type Large<'a> = psmpa_model::check::Large<'a>;

fn names<const NS: usize, const NA: usize>(
    d: &psmpa_core::Domain<'_, NS, NA>,
    set: psmpa_core::FactSet,
) -> String {
    d.names(set).to_string()
}

fn sensors<'a, const NS: usize, const NA: usize>(
    d: &psmpa_core::Domain<'a, NS, NA>,
    set: SensorSet,
) -> Vec<&'a str> {
    set.iter()
        .filter_map(|s| d.sensor(s).map(|s| s.name))
        .collect()
}

fn target(t: Target) -> String {
    match t {
        Target::State(i) => format!("δ{i}"),
        Target::Done => "done".to_owned(),
        Target::Failed => "failed".to_owned(),
    }
}

/// The report of a valid mission, and its Graphviz graph.
pub fn describe<const NS: usize, const NA: usize, const NP: usize, const L: usize>(
    m: &Tables<'_, NS, NA, NP, L>,
) -> (String, String) {
    let d = &m.domain;
    let mut out = String::new();
    let mut dot = String::from(
        "digraph mission {\n  rankdir=LR;\n  node [shape=box, fontname=\"sans-serif\"];\n",
    );
    let count = |n: usize, what: &str| format!("{n} {what}{}", if n == 1 { "" } else { "s" });
    let _ = writeln!(
        out,
        "mission {}: {}, {}, {}, {}, {}",
        m.name,
        count(d.fact_names().len(), "fact"),
        count(d.event_names().len(), "event"),
        count(d.sensors().len(), "sensor"),
        count(d.actions().len(), "action"),
        count(m.library.plans().len(), "plan")
    );
    let _ = writeln!(
        out,
        "task: {} from {} to {}",
        d.event_name(m.task.event).unwrap_or("?"),
        names(d, m.task.init),
        names(d, m.task.goal)
    );
    for (i, plan) in m.library.plans().iter().enumerate() {
        let Some(id) = PlanId::new(i) else { break };
        let not = if plan.context_not.is_empty() {
            String::new()
        } else {
            format!(", context_not {}", names(d, plan.context_not))
        };
        let _ = writeln!(
            out,
            "\nplan \"{}\" (trigger {}, context {}{not})",
            plan.name,
            d.event_name(plan.trigger).unwrap_or("?"),
            names(d, plan.context)
        );
        let _ = writeln!(
            dot,
            "  subgraph cluster_{i} {{\n    label=\"{}\";",
            plan.name.replace('"', "'")
        );
        let _ = writeln!(
            dot,
            "    p{i}_done [label=\"done\", shape=doublecircle];\n    p{i}_failed [label=\"failed\", shape=circle, color=red];"
        );
        match Fsm::compile(id, &plan.body, d.actions()) {
            Ok(fsm) => {
                for (k, state) in fsm.states(d.actions(), d.sensors()).enumerate() {
                    let action = d.action(state.action).map_or("?", |a| a.name);
                    let par = sensors(d, state.sensors);
                    let kind = if state.is_parallel() {
                        format!("δ'{k} = {action} ∥ {{{}}}", par.join(", "))
                    } else {
                        format!("δ{k}  = {action}")
                    };
                    let tolerance = d
                        .action(state.action)
                        .and_then(|a| a.max_violation)
                        .map(|t| format!(", max_violation {} ms", t.as_millis()))
                        .unwrap_or_default();
                    let _ = writeln!(
                        out,
                        "  {kind:<48} success → {}, failure → {}{tolerance}",
                        target(state.on_success),
                        target(state.on_failure)
                    );
                    let label = if par.is_empty() {
                        action.to_owned()
                    } else {
                        format!("{action}\\n∥ {}", par.join(", "))
                    };
                    let peripheries = if state.is_parallel() { 2 } else { 1 };
                    let _ = writeln!(
                        dot,
                        "    p{i}_s{k} [label=\"{}\", peripheries={peripheries}];",
                        label.replace('"', "'")
                    );
                    for (t, style) in [
                        (state.on_success, "color=black"),
                        (state.on_failure, "color=red, style=dashed"),
                    ] {
                        let to = match t {
                            Target::State(j) => format!("p{i}_s{j}"),
                            Target::Done => format!("p{i}_done"),
                            Target::Failed => format!("p{i}_failed"),
                        };
                        let _ = writeln!(dot, "    p{i}_s{k} -> {to} [{style}];");
                    }
                }
            }
            Err(e) => {
                let _ = writeln!(out, "  does not compile: {e}");
            }
        }
        let _ = writeln!(dot, "  }}");
    }
    dot.push_str("}\n");
    let actions = d.actions();
    match Planner::<4096>::new(Strategy::BreadthFirst).plan::<16>(
        actions,
        m.task
            .init
            .union(d.perception_of(SensorSet::from_bits(u32::MAX))),
        m.task.goal,
    ) {
        Ok(found) => {
            let steps: Vec<&str> = found
                .body
                .iter()
                .filter_map(|a| d.action(*a).map(|a| a.name))
                .collect();
            let _ = if steps.is_empty() {
                writeln!(
                    out,
                    "\nplanner, from the initial state with every percept holding: the goal already holds"
                )
            } else {
                writeln!(
                    out,
                    "\nplanner, from the initial state with every percept holding: {} ({} action{}, {} node{} expanded)",
                    steps.join(" → "),
                    steps.len(),
                    if steps.len() == 1 { "" } else { "s" },
                    found.expanded,
                    if found.expanded == 1 { "" } else { "s" }
                )
            };
        }
        Err(e) => {
            let why = match e {
                PlanningError::Unsolvable { expanded } => {
                    format!("no plan exists ({expanded} states searched)")
                }
                PlanningError::Budget { limit, .. } => {
                    format!("none found within the budget of {limit} nodes")
                }
                PlanningError::TooLong { limit } => {
                    format!("the shortest plan is longer than {limit} actions")
                }
                _ => e.to_string(),
            };
            let _ = writeln!(
                out,
                "\nplanner, from the initial state with every percept holding: {why}"
            );
        }
    }
    (out, dot)
}

/// A valid mission's report, its Graphviz graph and what in it is most likely a mistake
/// ([`psmpa_model::check::warnings`], each a line naming the file and the field).
pub type Checked = (String, String, Vec<String>);

/// The description of a loaded mission and its warnings, or the one line saying its goal is
/// unreachable.
fn reachable_then_describe<const NS: usize, const NA: usize, const NP: usize, const L: usize>(
    file: &Path,
    m: &Tables<'_, NS, NA, NP, L>,
) -> Result<Checked, String> {
    match unreachable_goal(m) {
        Some(why) => Err(format!("{}: {why}", file.display())),
        None => {
            let (report, graph) = describe(m);
            let warnings = psmpa_model::check::warnings(m)
                .into_iter()
                .map(|w| format!("{}: {}", file.display(), json::printable(&w)))
                .collect();
            Ok((report, graph, warnings))
        }
    }
}

/// Loads `bytes` for this robot (or for any platform) and describes it. The `'static` bound is
/// the command line's (it leaks the file); [`check_bytes`] takes any lifetime.
pub fn check(file: &Path, bytes: &'static [u8], any_platform: bool) -> Result<Checked, String> {
    check_bytes(file, bytes, any_platform)
}

/// [`check`] for bytes of any lifetime: the file must be strict JSON ([`json::strict`]); its
/// decoded text is loaded, and only owned text comes out.
pub fn check_bytes(file: &Path, bytes: &[u8], any_platform: bool) -> Result<Checked, String> {
    let doc = json::strict_file(file, bytes)?;
    if any_platform {
        let loaded: mission::Loaded<'_, (), (), 32, 64, 32, 16> =
            mission::load(&doc, &AnyBehaviour).map_err(|e| error_line(file, &e))?;
        let m: Large<'_> = loaded.mission;
        // What include_mission! refuses, refused here too: one verdict.
        psmpa_model::check::as_the_macro_reads_it(file, &doc, &m)?;
        reachable_then_describe(file, &m)
    } else {
        let loaded: mission::Loaded<'_, NaoSensor, NaoAction, 4, 8, 4, 6> =
            mission::load(&doc, &NaoRegistry).map_err(|e| error_line(file, &e))?;
        // What the simulated robot needs besides its behaviours' names, as `run` would find.
        robot::requirements(&loaded.mission.domain, &loaded.bindings)
            .map_err(|e| format!("{}: {}", file.display(), json::printable(&e.to_string())))?;
        psmpa_model::check::as_the_macro_reads_it(file, &doc, &loaded.mission)?;
        reachable_then_describe(file, &loaded.mission)
    }
}

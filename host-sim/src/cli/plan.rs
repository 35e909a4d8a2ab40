//! `psmpa-sim plan`: the embedded planner on a mission file, from the task's `init` to its
//! `goal` with the mission's actions (sensors and library plans play no part), at capacities
//! larger than a robot's: [`FACTS`] facts, [`ACTIONS`] actions, [`BUDGET`] search nodes.

use std::path::Path;

use psmpa_core::mission::{self, AnyBehaviour, Loaded, Problem};
use psmpa_core::planner::{Found, Heuristic, Planner, PlanningError, Search, Strategy};
use serde::Serialize;

use crate::cli::check::error_line;
use crate::cli::files::Stop;

/// Fact-set words of the command's missions.
const WORDS: usize = 4;
/// Facts a mission may declare: `64 · WORDS`.
pub const FACTS: usize = 64 * WORDS;
/// Actions a mission may declare.
pub const ACTIONS: usize = 4096;
/// Search nodes of space: a search generates at most 7/8 of them ([`BUDGET`]).
pub const NODES: usize = 1 << 20;
/// The largest node budget (`--budget`): 917,503.
pub const BUDGET: u32 = Planner::<NODES, WORDS>::capacity();
/// The default of `--time-limit`, seconds: with a mission's load and the start's estimate
/// the command ends well within a minute.
pub const TIME_LIMIT_S: u32 = 30;
/// The longest plan reported: as long as a plan can be (a node's depth is 16 bits).
const LENGTH: usize = 1 << 16;

/// A mission at the command's capacities (sensors and plans as a robot's).
type Wide<'a> = Loaded<'a, (), (), 32, ACTIONS, 32, 16, WORDS, FACTS>;

/// How to search, as the command line names it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Method {
    /// Breadth-first: shortest plans.
    Bfs,
    /// A* with h_max: shortest plans, fewer nodes.
    AstarHmax,
    /// A* with h_add: not always shortest.
    AstarHadd,
    /// Greedy best-first with h_add: fast, not always shortest.
    GreedyHadd,
    /// A* with the number of goal facts missing: not always shortest.
    AstarGoalCount,
}

impl Method {
    /// Its name on the command line and in the JSON.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Bfs => "bfs",
            Self::AstarHmax => "astar-hmax",
            Self::AstarHadd => "astar-hadd",
            Self::GreedyHadd => "greedy-hadd",
            Self::AstarGoalCount => "astar-goal-count",
        }
    }

    const fn strategy(self) -> Strategy {
        match self {
            Self::Bfs => Strategy::BreadthFirst,
            Self::AstarHmax => Strategy::AStar(Heuristic::Max),
            Self::AstarHadd => Strategy::AStar(Heuristic::Add),
            Self::GreedyHadd => Strategy::Greedy(Heuristic::Add),
            Self::AstarGoalCount => Strategy::AStar(Heuristic::GoalCount),
        }
    }
}

/// The command's result: a plan, or why there is none.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Outcome {
    /// The search used.
    pub search: &'static str,
    /// Plan length, `None` without a plan.
    pub length: Option<usize>,
    /// The actions by name, in order (with a plan).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plan: Option<Vec<String>>,
    /// `unsolvable` or `budget` (without a plan).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<&'static str>,
    /// Which budget ran out, `nodes` or `time` (with `budget`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ran_out: Option<&'static str>,
    /// Nodes expanded.
    pub expanded: u32,
    /// Nodes generated (with a plan).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub generated: Option<u32>,
    /// Wall time of the search, ms (with a plan).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub time_ms: Option<f64>,
}

impl Outcome {
    /// The outcome as text.
    pub fn text(&self) -> String {
        match (&self.plan, self.error) {
            (Some(plan), _) => {
                let mut out = format!(
                    "plan of {} actions ({}, {} nodes expanded, {} generated, {:.1} ms)\n",
                    plan.len(),
                    self.search,
                    self.expanded,
                    self.generated.unwrap_or(0),
                    self.time_ms.unwrap_or(0.0)
                );
                for (i, a) in plan.iter().enumerate() {
                    out.push_str(&format!("{:>4}. {a}\n", i + 1));
                }
                out
            }
            (None, error) => format!(
                "no plan ({}): {} after {} nodes expanded\n",
                self.search,
                match (error, self.ran_out) {
                    (Some("budget"), Some("time")) => "the time limit ran out",
                    (Some("budget"), _) => "the node budget ran out",
                    _ => "the goal cannot be reached",
                },
                self.expanded
            ),
        }
    }
}

/// What bounds a search: nodes and wall time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Most nodes to generate (`None`: [`BUDGET`]).
    pub budget: Option<u32>,
    /// Most wall time for the search.
    pub time: std::time::Duration,
}

/// The planner thread's stack: the search space, once more for a debug build's moves of it,
/// and 16 MiB for the rest (the plan found, the frames). About 130 MiB of address space,
/// touched only as used.
pub const STACK: usize = 2 * std::mem::size_of::<Search<NODES, WORDS>>() + (16 << 20);

/// Plans on the mission in `bytes` (from `file`) with `search` within `limits`. `Err` is bad
/// input ([`Stop::Bad`]) or a thread the machine would not start ([`Stop::Resource`]), as one
/// line.
pub fn plan(file: &Path, bytes: &[u8], search: Method, limits: Limits) -> Result<Outcome, Stop> {
    // Tens of MB of capacity: built on a thread whose stack holds them (touched as used).
    std::thread::scope(|scope| {
        std::thread::Builder::new()
            .stack_size(STACK)
            .spawn_scoped(scope, || plan_here(file, bytes, search, limits))
            .map_err(|e| {
                Stop::Resource(format!(
                    "cannot start the planner (a thread with {} MiB of stack): {e}",
                    STACK >> 20
                ))
            })?
            .join()
            .map_err(|_| Stop::internal("the planner stopped unexpectedly"))?
            .map_err(Stop::Bad)
    })
}

fn plan_here(file: &Path, bytes: &[u8], search: Method, limits: Limits) -> Result<Outcome, String> {
    let decoded = crate::json::strict_file(file, bytes)?;
    let mut loaded: Box<Wide<'_>> = Box::new(Loaded::empty());
    let loaded = &mut *loaded;
    let unsolvable = |expanded| Outcome {
        search: search.name(),
        length: None,
        plan: None,
        error: Some("unsolvable"),
        ran_out: None,
        expanded,
        generated: None,
        time_ms: None,
    };
    match mission::load_into(
        &decoded,
        &AnyBehaviour,
        &mut loaded.mission,
        &mut loaded.bindings,
    ) {
        Ok(()) => {}
        // Not even the relaxed problem reaches the goal: no plan, a result rather than bad input.
        Err(e) if matches!(e.problem, Problem::UnreachableGoal(_)) => return Ok(unsolvable(0)),
        Err(e) => return Err(error_line(file, &e)),
    }
    let m = &loaded.mission;
    let mut planner = Planner::<NODES, WORDS>::new(search.strategy());
    if let Some(b) = limits.budget {
        planner.budget = b;
    }
    let mut space: Search<NODES, WORDS> = Search::new();
    let actions = m.domain.actions();
    let started = std::time::Instant::now();
    let mut timed_out = false;
    // Asked before every node: a clock read is tens of nanoseconds, a node at least as much.
    let mut out_of_time = || {
        timed_out = timed_out || started.elapsed() >= limits.time;
        timed_out
    };
    space.start(&planner, actions, m.task.init, m.task.goal);
    let result: Result<Found<LENGTH>, PlanningError> = loop {
        if let Some(r) = space.step_until(actions, u32::MAX, &mut out_of_time) {
            break r;
        }
    };
    // Microseconds are what a wall clock here resolves.
    let time_ms = (started.elapsed().as_secs_f64() * 1e6).round() / 1000.0;
    match result {
        Ok(found) => Ok(Outcome {
            search: search.name(),
            length: Some(found.body.len()),
            plan: Some(
                found
                    .body
                    .iter()
                    .map(|a| m.domain.action(*a).map_or("?", |a| a.name).to_owned())
                    .collect(),
            ),
            error: None,
            ran_out: None,
            expanded: found.expanded,
            generated: Some(found.generated),
            time_ms: Some(time_ms),
        }),
        Err(PlanningError::Unsolvable { expanded }) => Ok(unsolvable(expanded)),
        Err(PlanningError::Budget { expanded, .. }) => Ok(Outcome {
            error: Some("budget"),
            ran_out: Some(if timed_out { "time" } else { "nodes" }),
            ..unsolvable(expanded)
        }),
        Err(PlanningError::TooLong { limit }) => Err(format!(
            "{}: the plan is longer than {limit} actions, the most this command reports",
            file.display()
        )),
        Err(e) => Err(format!("{}: {e}", file.display())),
    }
}

//! `cargo xtask bench --planning`: the embedded planner (`psmpa-sim plan`, A* with h_max) on
//! generated classic problems, beside pyperplan (A* with h_max, `pip install pyperplan==2.1`)
//! on the same problems as PDDL when `pyperplan` is on the `PATH`. Search time only, median of
//! three runs each; written to `bench/PLANNING.md` and the README.

use std::path::Path;
use std::process::{Command, Stdio};

use psmpa_sim::planning::{Problem, suite};

use crate::firmware;

/// One planner's result on one problem.
struct Run {
    length: Option<u64>,
    expanded: u64,
    search_ms: f64,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

fn psmpa(sim: &Path, mission: &Path) -> Result<(Run, u64), String> {
    let mut times = Vec::new();
    let mut last = None;
    for _ in 0..3 {
        let out = Command::new(sim)
            .args(["plan", "--search", "astar-hmax", "--json"])
            .arg(mission)
            .stderr(Stdio::inherit())
            .output()
            .map_err(|e| format!("cannot run psmpa-sim: {e}"))?;
        let v: serde_json::Value = serde_json::from_slice(&out.stdout)
            .map_err(|e| format!("{}: {e}", mission.display()))?;
        times.push(v["time_ms"].as_f64().unwrap_or(f64::NAN));
        last = Some(v);
    }
    let v = last.ok_or("no run")?;
    Ok((
        Run {
            length: v["length"].as_u64(),
            expanded: v["expanded"].as_u64().unwrap_or(0),
            search_ms: median(times),
        },
        v["generated"].as_u64().unwrap_or(0),
    ))
}

/// pyperplan's own "Search time" (grounding and Python's start left out), median of 3.
fn pyperplan(domain: &Path, problem: &Path) -> Result<Run, String> {
    let mut times = Vec::new();
    let (mut length, mut expanded) = (None, 0);
    for _ in 0..3 {
        let out = Command::new("pyperplan")
            .args(["-s", "astar", "-H", "hmax"])
            .arg(domain)
            .arg(problem)
            .output()
            .map_err(|e| format!("cannot run pyperplan: {e}"))?;
        let log = String::from_utf8_lossy(&out.stdout).into_owned()
            + &String::from_utf8_lossy(&out.stderr);
        for line in log.lines() {
            let field = |key: &str| line.split_once(key).map(|(_, v)| v.trim().to_owned());
            if let Some(t) = field("Search time:") {
                times.push(t.parse::<f64>().unwrap_or(f64::NAN) * 1000.0);
            }
            if let Some(n) = field("Plan length:") {
                length = n.parse().ok();
            }
            if line.ends_with("Nodes expanded") {
                expanded = line
                    .split_whitespace()
                    .rev()
                    .nth(2)
                    .and_then(|n| n.parse().ok())
                    .unwrap_or(0);
            }
        }
    }
    // The solution file pyperplan writes beside the problem.
    let _ = std::fs::remove_file(problem.with_extension("pddl.soln"));
    Ok(Run {
        length,
        expanded,
        search_ms: median(times),
    })
}

fn write(dir: &Path, p: &Problem) -> Result<[std::path::PathBuf; 3], String> {
    let paths = [
        dir.join(format!("{}.json", p.name)),
        dir.join(format!("{}-domain.pddl", p.name)),
        dir.join(format!("{}.pddl", p.name)),
    ];
    for (path, text) in
        paths
            .iter()
            .zip([p.mission_json().as_str(), p.pddl_domain, &p.pddl_problem])
    {
        std::fs::write(path, text).map_err(|e| format!("{}: {e}", path.display()))?;
    }
    Ok(paths)
}

/// Runs the comparison and writes `bench/PLANNING.md` and README's table; without pyperplan,
/// prints psmpa's figures and writes nothing.
pub fn run() -> Result<(), String> {
    let root = firmware::root();
    let sim = firmware::build_host_sim()?;
    let dir = root.join("target/planning");
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let peer = Command::new("pyperplan")
        .arg("--help")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    let mut md = String::from(
        "Measured by `cargo xtask bench --planning` in one run: A* with h_max, search time only \
         (median of 3), on this project's 2-core machine. psmpa: `psmpa-sim plan` (the \
         embedded planner at 4-word fact sets); pyperplan 2.1 (Python) on the same problems \
         as PDDL.\n\n\
         | problem | facts | actions | optimal | psmpa length | psmpa expanded | psmpa ms | psmpa nodes/s | pyperplan length | pyperplan expanded | pyperplan ms | ratio |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for p in suite() {
        let [mission, domain, problem] = write(&dir, &p)?;
        let (ours, generated) = psmpa(&sim, &mission)?;
        let nodes_per_s = generated as f64 / (ours.search_ms / 1000.0);
        let theirs = if peer {
            Some(pyperplan(&domain, &problem)?)
        } else {
            None
        };
        let show = |l: Option<u64>| l.map_or("-".to_owned(), |l| l.to_string());
        md.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} | {:.2} | {:.0} | {} | {} | {} | {} |\n",
            p.name,
            p.facts.len(),
            p.actions.len(),
            p.optimal,
            show(ours.length),
            ours.expanded,
            ours.search_ms,
            nodes_per_s,
            theirs.as_ref().map_or("-".into(), |t| show(t.length)),
            theirs
                .as_ref()
                .map_or("-".into(), |t| t.expanded.to_string()),
            theirs
                .as_ref()
                .map_or("-".into(), |t| format!("{:.1}", t.search_ms)),
            theirs.as_ref().map_or("-".into(), |t| format!(
                "{:.0}x",
                t.search_ms / ours.search_ms
            )),
        ));
    }
    if !peer {
        // The files hold a comparison: psmpa's figures alone would replace it with less.
        println!(
            "{md}\npyperplan is not installed (`pip install pyperplan==2.1`), so its columns are \
             empty: printed only; README.md and bench/PLANNING.md keep their comparison"
        );
        return Ok(());
    }
    std::fs::write(
        root.join("bench/PLANNING.md"),
        format!("# Planning benchmark\n\n{md}"),
    )
    .map_err(|e| e.to_string())?;
    crate::bench::replace_in_readme(&root, "planning", &md)?;
    println!("{md}\nwritten to bench/PLANNING.md and README.md");
    Ok(())
}

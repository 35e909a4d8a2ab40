//! `psmpa-sim plan` on generated classic problems (issue 17): optimal plans where the search
//! is optimal, valid plans always, the JSON contract, and no plan or bad input told apart.

mod common;

use common::{assert_success, bin, file};

use psmpa_sim::planning::{Problem, blocks, gripper, logistics};
use serde_json::Value;

fn plan(problem: &Problem, search: &str, extra: &[&str]) -> (Option<i32>, Value) {
    let path = file(&format!("{}.json", problem.name), &problem.mission_json());
    let out = bin()
        .arg("plan")
        .arg(&path)
        .args(["--search", search, "--json"])
        .args(extra)
        .output()
        .unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    assert_eq!(text.lines().count(), 1, "one JSON object: {text}");
    (out.status.code(), serde_json::from_str(&text).unwrap())
}

/// The plan's actions applied in order from `init`: each applicable, the goal at the end.
fn assert_valid(problem: &Problem, names: &[Value]) {
    let mut state: std::collections::BTreeSet<&str> =
        problem.init.iter().map(String::as_str).collect();
    for (i, name) in names.iter().enumerate() {
        let name = name.as_str().unwrap();
        let a = problem.actions.iter().find(|a| a.name == name).unwrap();
        for p in &a.pre {
            assert!(state.contains(p.as_str()), "step {i}: {name} needs {p}");
        }
        for d in &a.del {
            state.remove(d.as_str());
        }
        state.extend(a.add.iter().map(String::as_str));
    }
    for g in &problem.goal {
        assert!(state.contains(g.as_str()), "goal {g} not reached");
    }
}

#[test]
fn optimal_searches_find_the_known_optimal_lengths() {
    for (problem, searches) in [
        (gripper(4), &["bfs", "astar-hmax"][..]),
        (gripper(5), &["astar-hmax"][..]),
        (blocks(4, true), &["bfs", "astar-hmax"][..]),
        (blocks(6, true), &["astar-hmax"][..]),
        (logistics(1), &["bfs", "astar-hmax"][..]),
        (logistics(2), &["astar-hmax"][..]),
    ] {
        for search in searches {
            let started = std::time::Instant::now();
            let (status, v) = plan(&problem, search, &[]);
            let lifetime_ms = started.elapsed().as_secs_f64() * 1e3;
            assert_eq!(status, Some(0), "{}: {v}", problem.name);
            assert_eq!(v["search"], *search);
            assert_eq!(v["length"], problem.optimal, "{} by {search}", problem.name);
            let names = v["plan"].as_array().unwrap();
            assert_eq!(names.len(), problem.optimal);
            assert_valid(&problem, names);
            assert!(v["expanded"].as_u64().unwrap() > 0);
            assert!(v["generated"].as_u64().unwrap() >= v["expanded"].as_u64().unwrap());
            // The search's own time, within the process's lifetime: not a total, not
            // seconds, not a constant.
            let time_ms = v["time_ms"].as_f64().unwrap();
            assert!(
                time_ms > 0.0 && time_ms <= lifetime_ms,
                "{}: time_ms {time_ms} outside the command's {lifetime_ms:.1} ms",
                problem.name
            );
        }
    }
}

#[test]
fn more_than_64_facts_are_planned_optimally() {
    // 121 and 169 facts, 200 and 288 actions: past one fact word and 256 actions.
    for n in [10, 12] {
        let problem = blocks(n, false);
        assert!(problem.facts.len() > 64 && problem.facts.len() <= 256);
        let (status, v) = plan(&problem, "astar-hmax", &[]);
        assert_eq!(status, Some(0), "{v}");
        assert_eq!(v["length"], problem.optimal, "{}", problem.name);
        assert_valid(&problem, v["plan"].as_array().unwrap());
    }
    // Gripper with 30 balls (124 facts, 242 actions): greedy finds a valid plan fast.
    let problem = gripper(30);
    let (status, v) = plan(&problem, "greedy-hadd", &[]);
    assert_eq!(status, Some(0), "{v}");
    assert!(v["length"].as_u64().unwrap() >= problem.optimal as u64);
    assert_valid(&problem, v["plan"].as_array().unwrap());
}

#[test]
fn every_search_gives_a_valid_plan() {
    let problem = gripper(6);
    for search in [
        "bfs",
        "astar-hmax",
        "astar-hadd",
        "greedy-hadd",
        "astar-goal-count",
    ] {
        let (status, v) = plan(&problem, search, &[]);
        assert_eq!(status, Some(0), "{search}: {v}");
        assert!(v["length"].as_u64().unwrap() >= problem.optimal as u64);
        assert_valid(&problem, v["plan"].as_array().unwrap());
    }
}

#[test]
fn no_plan_is_status_1_with_the_reason() {
    // The budget runs out.
    let (status, v) = plan(&gripper(6), "bfs", &["--budget", "10"]);
    assert_eq!(status, Some(1));
    assert_eq!(v["length"], Value::Null);
    assert_eq!(v["error"], "budget");
    assert!(v.get("plan").is_none());
    // Unsolvable: the ball needs a hand, and both are taken by balls that cannot be dropped.
    let mut problem = gripper(1);
    problem.actions.retain(|a| !a.name.starts_with("drop"));
    problem.name = "gripper-no-drop".into();
    let (status, v) = plan(&problem, "bfs", &[]);
    assert_eq!(status, Some(1));
    assert_eq!(v["error"], "unsolvable");
    assert_eq!(v["length"], Value::Null);
    // The Fetch Tea mission without its sensors: `path_clear` never holds.
    let out = bin()
        .args(["plan", "--json"])
        .arg(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../missions/fetch-tea.json"
        ))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
}

#[test]
fn bad_input_is_status_2_and_one_line() {
    let path = file("not-a-mission.json", r#"{"name": "x"}"#);
    let out = bin().arg("plan").arg(&path).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(stderr.contains("not-a-mission.json"), "{stderr}");
    // More facts than the command's 256.
    let mut problem = gripper(70);
    problem.name = "too-many-facts".into();
    let path = file("too-many-facts.json", &problem.mission_json());
    let out = bin().arg("plan").arg(&path).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert!(stderr.contains("256"), "names the limit: {stderr}");
    // The same kind of problem within the limit plans (text output).
    let path = file("gripper-2.json", &gripper(2).mission_json());
    let out = bin().arg("plan").arg(&path).output().unwrap();
    assert_success(&out);
    assert!(String::from_utf8_lossy(&out.stdout).starts_with("plan of 5 actions"));
    let out = bin()
        .args(["plan", "--budget", "0"])
        .arg(&path)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
}

/// A binary counter of `bits` bits: its shortest plan counts to `2^bits - 1`.
fn counter(bits: usize) -> Problem {
    use psmpa_sim::planning::Action;
    let b = |i: usize| format!("b{i}");
    let nb = |i: usize| format!("nb{i}");
    let facts: Vec<String> = (0..bits).flat_map(|i| [b(i), nb(i)]).collect();
    // inc_i: bit i off and every lower bit on -> bit i on, every lower bit off.
    let actions = (0..bits)
        .map(|i| Action {
            name: format!("inc{i}"),
            pre: std::iter::once(nb(i)).chain((0..i).map(b)).collect(),
            add: std::iter::once(b(i)).chain((0..i).map(nb)).collect(),
            del: std::iter::once(nb(i)).chain((0..i).map(b)).collect(),
        })
        .collect();
    Problem {
        name: format!("counter-{bits}"),
        facts,
        actions,
        init: (0..bits).map(nb).collect(),
        goal: (0..bits).map(b).collect(),
        optimal: (1 << bits) - 1,
        pddl_domain: "",
        pddl_problem: String::new(),
    }
}

#[test]
fn a_plan_longer_than_256_actions_is_reported() {
    let problem = counter(9);
    let (status, v) = plan(&problem, "bfs", &[]);
    assert_eq!(status, Some(0), "{v}");
    assert_eq!(v["length"], 511);
    assert_valid(&problem, v["plan"].as_array().unwrap());
}

#[test]
fn no_plan_stays_status_1_when_the_reader_has_gone() {
    let path = file("gripper-no-plan.json", &gripper(6).mission_json());
    let mut child = bin()
        .args(["plan", "--budget", "10", "--json"])
        .arg(&path)
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    assert_eq!(child.wait().unwrap().code(), Some(1));
}

/// `--time-limit` ends a search whose nodes are costly (4,000 actions in every heuristic
/// estimate, a 2^40-step counter) as a node budget does, and says it was the time; at the
/// default node budget the search would take about a minute on this machine.
#[test]
fn a_time_limit_ends_a_search_as_a_budget() {
    use psmpa_sim::planning::Action;
    let mut problem = counter(40);
    problem.name = "counter-slow".into();
    problem.facts.push("never".into());
    problem.actions.extend((0..4000).map(|i| Action {
        name: format!("idle{i}"),
        pre: vec!["never".into()],
        add: vec!["b0".into()],
        del: vec![],
    }));
    let (status, v) = plan(&problem, "astar-hmax", &["--time-limit", "1"]);
    assert_eq!(status, Some(1), "{v}");
    assert_eq!(v["error"], "budget");
    assert_eq!(v["ran_out"], "time");
    assert!(v["expanded"].as_u64().unwrap() > 0);
    // The node budget says so too.
    let (_, v) = plan(&problem, "astar-hmax", &["--budget", "50"]);
    assert_eq!(
        (&v["error"], &v["ran_out"]),
        (&"budget".into(), &"nodes".into())
    );
    // Out of range: named.
    let out = bin()
        .args(["plan", "--time-limit", "0", "x.json"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--time-limit"));
}

/// `plan`'s text escapes what `check` escapes: a name's bidi override, CSI and DEL would
/// otherwise act on the terminal.
#[test]
fn plan_text_escapes_hidden_characters() {
    use psmpa_sim::planning::Action;
    let mut problem = counter(1);
    problem.name = "counter-names".into();
    problem.actions.push(Action {
        name: "evil\u{202e}\u{9b}\u{7f}".into(),
        pre: vec!["nb0".into()],
        add: vec!["b0".into()],
        del: vec!["nb0".into()],
    });
    problem.actions.remove(0);
    let path = file("counter-names.json", &problem.mission_json());
    let out = bin().arg("plan").arg(&path).output().unwrap();
    assert_eq!(out.status.code(), Some(0));
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains(r"evil\u202e\u009b\u007f"), "{text}");
    assert!(!text.contains('\u{202e}') && !text.contains('\u{9b}') && !text.contains('\u{7f}'));
}

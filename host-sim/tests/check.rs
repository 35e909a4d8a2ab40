//! `psmpa-sim check`: valid missions are described, bad ones rejected with status 2 and one
//! clear line.

mod common;

use common::{assert_success, bin, file};

use std::path::PathBuf;

fn fetch_tea() -> String {
    std::fs::read_to_string(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../missions/fetch-tea.json"),
    )
    .unwrap()
}

#[test]
fn the_fetch_tea_mission_checks_and_shows_its_parallel_states() {
    let dot = std::env::temp_dir().join(format!("psmpa-check-{}.dot", std::process::id()));
    let out = bin()
        .arg("check")
        .arg(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../missions/fetch-tea.json"))
        .arg("--dot")
        .arg(&dot)
        .output()
        .unwrap();
    assert_success(&out);
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.contains("δ'0 = go to door ∥ {sonar, bumper}"),
        "{text}"
    );
    assert!(
        text.contains("δ'1 = open door ∥ {camera, handle}"),
        "{text}"
    );
    assert!(text.contains("δ2  = enter kitchen"), "{text}");
    // Per-action tolerances are shown where a mission sets them: the walks wait a minute.
    assert!(
        text.contains("failure → failed, max_violation 60000 ms"),
        "{text}"
    );
    assert!(!text.contains("context_not"), "{text}");
    assert!(
        text.contains("go to door → open door → enter kitchen (3 actions"),
        "{text}"
    );
    let graph = std::fs::read_to_string(dot).unwrap();
    assert!(graph.starts_with("digraph mission {"));
    assert!(graph.contains("p0_s0 [label=\"go to door\\n∥ sonar, bumper\", peripheries=2];"));
    assert!(graph.contains("p0_s2 -> p0_done"));
}

/// Each broken copy of fetch-tea.json: what to replace, and what the one line must say.
#[test]
fn bad_missions_are_rejected_with_one_clear_line() {
    let good = fetch_tea();
    let cases: [(&str, &str, &[&str]); 19] = [
        (
            r#""pre": ["door_open", "at_door"]"#,
            r#""pre": ["door_opened", "at_door"]"#,
            &["actions[2].pre", "unknown fact `door_opened`"],
        ),
        (
            r#""events": ["fetch_tea"]"#,
            r#""events": ["fetch_tea", "fetch_tea"]"#,
            &["events[1]", "duplicate name `fetch_tea`"],
        ),
        (
            r#""body": ["go to door", "open door", "enter kitchen"]"#,
            r#""body": ["go to door", "open the door", "enter kitchen"]"#,
            &["plans[0].body", "unknown action `open the door`"],
        ),
        (
            r#""body": ["go to door", "open door", "enter kitchen"]"#,
            r#""body": []"#,
            &["plans[0].body", "empty"],
        ),
        (
            r#"{ "name": "go to door","#,
            r#"{ "name": "go to door", "speed": 2,"#,
            &["actions[0]", "unknown field `speed`"],
        ),
        (
            r#""name": "camera""#,
            r#""name": "lidar""#,
            &["sensors[2].name", "no behaviour called `lidar`"],
        ),
        (
            r#""mode": "one-shot""#,
            r#""mode": "once""#,
            &["sensors[2].mode", "unknown sensor mode `once`"],
        ),
        (r#""task": {"#, r#""task": ["#, &["malformed JSON", "line"]),
        (
            r#""name": "fetch-tea""#,
            r#""name": "  ""#,
            &["name", "the name is empty"],
        ),
        (
            r#""period_ms": 100"#,
            r#""period_ms": -5"#,
            &["sensors[0].period_ms", "not a whole number"],
        ),
        (
            r#""period_ms": 100"#,
            r#""period_ms": 1e30"#,
            &["sensors[0].period_ms", "not a whole number"],
        ),
        // "go to door" deletes at_back_door and "go to back door" deletes at_door: never both.
        (
            r#""goal": ["in_kitchen"]"#,
            r#""goal": ["at_door", "at_back_door"]"#,
            &[
                "task.goal",
                "no sequence of actions reaches {at_door, at_back_door}",
            ],
        ),
        (
            r#""events": ["fetch_tea"]"#,
            r#""events": [[[[[[[[["fetch_tea"]]]]]]]]]"#,
            &["nested deeper than 8 levels"],
        ),
        (
            r#""context": ["door_unlocked"],"#,
            r#""context": ["door_unlocked"], "context_not": ["door_unlocked"],"#,
            &[
                "plans[0].context_not",
                "fact `door_unlocked` is in both `context` and `context_not`",
            ],
        ),
        (
            r#""max_violation_ms": 60000"#,
            r#""max_violation_ms": 5000000000"#,
            &[
                "actions[0].max_violation_ms",
                "more than 4294967295 milliseconds",
            ],
        ),
        (
            r#""max_violation_ms": 60000"#,
            r#""max_violation_ms": "soon""#,
            &["actions[0].max_violation_ms", "wrong type"],
        ),
        // The simulated NAO samples its sonar on the scenario's period: a mission that says
        // otherwise would be overridden, so it is refused.
        (
            r#""mode": "cyclic", "period_ms": 100, "timeout_ms": 100"#,
            r#""mode": "one-shot", "timeout_ms": 100"#,
            &["sensor `sonar` must be `cyclic`"],
        ),
        (
            r#""mode": "cyclic", "period_ms": 100"#,
            r#""mode": "on-demand", "period_ms": 100"#,
            &["sensors[0].period_ms", "only for a `cyclic` sensor"],
        ),
        (
            r#""name": "sonar""#,
            r#""name": "so\\nar""#,
            &[
                "sensors[0].name",
                "escape sequences are not allowed in names",
            ],
        ),
    ];
    for (i, (from, to, expected)) in cases.iter().enumerate() {
        assert!(good.contains(from), "case {i}: `{from}` not in the mission");
        let path = file(&format!("bad-{i}.json"), &good.replacen(from, to, 1));
        // With the NAO's behaviours required, so that an unknown one is an error too.
        let out = bin()
            .args(["check", "--platform", "nao"])
            .arg(&path)
            .output()
            .unwrap();
        let stderr = String::from_utf8(out.stderr).unwrap();
        assert_eq!(out.status.code(), Some(2), "case {i}: {stderr}");
        assert_eq!(stderr.lines().count(), 1, "case {i}: {stderr}");
        assert!(
            stderr.contains(&path.display().to_string()),
            "case {i}: {stderr}"
        );
        for fragment in *expected {
            assert!(
                stderr.contains(fragment),
                "case {i}: expected `{fragment}` in {stderr}"
            );
        }
        assert!(!stderr.contains("panicked"));
    }
}

#[test]
fn an_unreachable_goal_and_an_unbound_behaviour_name_their_cause() {
    let good = fetch_tea();
    // Nothing adds back_door_open any more: entering by the back door can never happen, and with
    // the goal requiring it the mission is rejected.
    let unreachable = good
        .replacen(r#""add": ["back_door_open"]"#, r#""add": []"#, 1)
        .replacen(
            r#""goal": ["in_kitchen"]"#,
            r#""goal": ["back_door_open"]"#,
            1,
        );
    let out = bin()
        .arg("check")
        .arg(file("unreachable.json", &unreachable))
        .output()
        .unwrap();
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr.contains("task.goal: goal fact `back_door_open` can never hold"),
        "{stderr}"
    );

    // Behaviours the robot does not have: fine for the logic alone, rejected for the robot.
    let many = good.replacen(
        r#"    { "name": "go to door","#,
        r#"    { "name": "a1" }, { "name": "a2" }, { "name": "a3" },
    { "name": "go to door","#,
        1,
    );
    let out = bin()
        .arg("check")
        .arg(file("many-any.json", &many))
        .output()
        .unwrap();
    assert_success(&out);
    // The old flag still means the default.
    let out = bin()
        .args(["check", "--any-platform"])
        .arg(file("many-any.json", &many))
        .output()
        .unwrap();
    assert_success(&out);
    let out = bin()
        .args(["check", "--platform", "nao"])
        .arg(file("many.json", &many))
        .output()
        .unwrap();
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr.contains("no behaviour called `a1`"), "{stderr}");
}

/// An action's own `max_violation_ms` and a plan's `context_not` are read and shown.
#[test]
fn per_action_tolerance_and_negative_context_are_shown() {
    let mission = fetch_tea()
        .replacen(
            r#""max_violation_ms": 60000"#,
            r#""max_violation_ms": 0"#,
            1,
        )
        .replacen(
            r#""context": ["door_unlocked"],"#,
            r#""context": ["door_unlocked"], "context_not": ["door_open"],"#,
            1,
        );
    let path = file("tolerance.json", &mission);
    let out = bin().arg("check").arg(&path).output().unwrap();
    assert_success(&out);
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.contains("(trigger fetch_tea, context {door_unlocked}, context_not {door_open})"),
        "{text}"
    );
    assert!(
        text.contains("failure → failed, max_violation 0 ms"),
        "{text}"
    );
}

/// `--platform nao` finds what `run` would: a mission without a fact the robot's sensors
/// decide is refused, though any robot's mission may lack it.
#[test]
fn the_nao_platform_needs_the_facts_its_sensors_decide() {
    let path = file(
        "no-path-clear.json",
        &fetch_tea().replace("path_clear", "way_clear"),
    );
    let out = bin().arg("check").arg(&path).output().unwrap();
    assert_success(&out);
    let out = bin()
        .args(["check", "--platform", "nao"])
        .arg(&path)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert!(stderr.contains("no fact `path_clear`"), "{stderr}");
}

/// Another robot's mission checks by default; `--platform nao` asks for the NAO's behaviours.
#[test]
fn any_robots_mission_checks_by_default() {
    let dock = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/dock/mission.json");
    let out = bin().arg("check").arg(dock).output().unwrap();
    assert_success(&out);
    assert!(
        String::from_utf8(out.stdout)
            .unwrap()
            .contains("drive ∥ {tof, cliff}")
    );
    let out = bin()
        .args(["check", "--platform", "nao", dock])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert!(stderr.contains("no behaviour called `tof`"), "{stderr}");
}

/// A task whose goal holds at the start: the planner's line says so, not an empty plan.
#[test]
fn a_goal_that_already_holds_is_said_in_words() {
    let mission = r#"{"name": "m", "facts": ["a"], "events": ["go"], "sensors": [],
        "actions": [{"name": "x", "add": ["a"]}],
        "plans": [{"name": "p", "trigger": "go", "body": ["x"]}],
        "task": {"event": "go", "init": ["a"], "goal": ["a"]}}"#;
    let path = file("goal-holds.json", mission);
    let out = bin().arg("check").arg(&path).output().unwrap();
    assert_success(&out);
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.contains("every percept holding: the goal already holds"),
        "{text}"
    );
}

/// One rule for names, in missions and scenarios: two facts, actions or plans that read alike
/// are duplicates, and a name of invisible characters is blank. Each was accepted.
#[test]
fn names_that_read_alike_are_refused() {
    let mission = fetch_tea();
    for (from, to) in [
        ("\"in_kitchen\"\n", "\"in_kitchen\", \"In_Kitchen\"\n"),
        ("\"in_kitchen\"\n", "\"in_kitchen\", \"in_kitchen\u{a0}\"\n"),
        (
            "\"in_kitchen\"\n",
            "\"in_kitchen\", \"in\u{200b}_kitchen\"\n",
        ),
    ] {
        assert_eq!(mission.matches(from).count(), 1, "{from}");
        let path = file("alike.json", &mission.replacen(from, to, 1));
        let out = bin().arg("check").arg(&path).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{to}: {stderr}");
        assert!(stderr.contains("duplicate name"), "{stderr}");
    }
    let path = file(
        "blank.json",
        &mission.replacen(
            "\"name\": \"fetch-tea\"",
            "\"name\": \"\u{200b}\u{200b}\"",
            1,
        ),
    );
    let out = bin().arg("check").arg(&path).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    // A scenario's name too.
    let scenario = std::fs::read_to_string(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenarios/sonar-8.json"),
    )
    .unwrap()
    .replacen("\"sonar-8\"", "\"\u{200b}\u{feff}\"", 1);
    let path = file("blank-scenario.json", &scenario);
    let out = bin()
        .args(["run", "--arch", "psmpa"])
        .arg(&path)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("name: must not be empty or only spaces"),
        "{stderr}"
    );
}

/// `check --platform nao` refuses a sensor that perceives nothing or a fact its device cannot
/// give (the sonar deciding `door_open` from an echo); both were accepted.
#[test]
fn a_nao_sensor_perceives_only_what_its_device_gives() {
    let mission = fetch_tea();
    let sonar = r#""name": "sonar",  "per": ["path_clear"]"#;
    assert_eq!(mission.matches(sonar).count(), 1);
    for (per, says) in [
        (
            r#""name": "sonar",  "per": []"#,
            "sensor `sonar` perceives nothing",
        ),
        (
            r#""name": "sonar",  "per": ["path_clear", "door_open"]"#,
            "sensor `sonar` perceives a fact its device cannot give",
        ),
    ] {
        let path = file("per.json", &mission.replacen(sonar, per, 1));
        let out = bin()
            .args(["check", "--platform", "nao"])
            .arg(&path)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{per}: {stderr}");
        assert!(stderr.contains(says), "{stderr}");
        assert_eq!(stderr.lines().count(), 1);
    }
}

/// Valid missions that are most likely mistakes (each accepted with no word before): a body in
/// an order its preconditions cannot run, a context that can never hold, a sensor timeout of a
/// day. Each is a warning on stderr naming the file, the field and why; status 0, the report
/// as ever. The shipped mission has none.
#[test]
fn likely_mistakes_are_warnings_that_say_why() {
    let m = fetch_tea();
    let cases = [
        (
            "order.json",
            m.replace(
                r#""body": ["go to door", "open door", "enter kitchen"]"#,
                r#""body": ["open door", "go to door", "enter kitchen"]"#,
            ),
            r#"plans[0].body: "open door" needs {at_door}, which only "go to door", later in the body, adds"#,
        ),
        (
            "never.json",
            m.replace(
                r#""context": ["door_unlocked"]"#,
                r#""context": ["door_unlocked", "chef"]"#,
            )
            .replace(
                r#""back_door_open", "in_kitchen""#,
                r#""back_door_open", "in_kitchen", "chef""#,
            ),
            "plans[0].context: {chef} can never hold",
        ),
        (
            "timeout.json",
            m.replace(r#""timeout_ms": 100"#, r#""timeout_ms": 86400000"#),
            "sensors[0].timeout_ms: 86400000 ms: a sensor that stops answering goes unnoticed",
        ),
    ];
    for (name, text, warning) in cases {
        let out = bin().arg("check").arg(file(name, &text)).output().unwrap();
        assert_success(&out);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(stderr.lines().count(), 1, "{name}: {stderr}");
        assert!(stderr.starts_with("psmpa-sim: warning: "), "{stderr}");
        assert!(
            stderr.contains(name) && stderr.contains(warning),
            "{name}: {stderr}"
        );
        assert!(String::from_utf8_lossy(&out.stdout).starts_with("mission fetch-tea"));
    }
    let out = bin()
        .arg("check")
        .arg(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../missions/fetch-tea.json"))
        .output()
        .unwrap();
    assert!(
        out.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Issue 59, items 18 and 19: what `include_mission!` refuses, `check` refuses with the same
/// line, on any platform and on the NAO: a name whose variant would be `ALL` (hiding the
/// generated `Fact::ALL`), a description of a fact the mission lacks, descriptions as an array.
#[test]
fn what_the_macro_refuses_check_refuses() {
    let good = fetch_tea();
    for (i, (from, to, says)) in [
        (
            r#""in_kitchen"
  ]"#,
            r#""in_kitchen", "ALL"
  ]"#,
            r#"facts "ALL" would be the variant ALL"#,
        ),
        (
            r#""name": "fetch-tea","#,
            r#""name": "fetch-tea", "fact_descriptions": {"at_dor": "x"},"#,
            "fact_descriptions: `at_dor` is not a fact of the mission",
        ),
        (
            r#""name": "fetch-tea","#,
            r#""name": "fetch-tea", "fact_descriptions": ["at_door"],"#,
            "fact_descriptions: an object from a fact's name to its description",
        ),
    ]
    .into_iter()
    .enumerate()
    {
        assert!(good.contains(from), "case {i}: `{from}` not in the mission");
        let path = file(&format!("macro-{i}.json"), &good.replacen(from, to, 1));
        for platform in [&[][..], &["--platform", "nao"][..]] {
            let out = bin()
                .arg("check")
                .args(platform)
                .arg(&path)
                .output()
                .unwrap();
            let stderr = String::from_utf8(out.stderr).unwrap();
            assert_eq!(
                out.status.code(),
                Some(2),
                "case {i} {platform:?}: {stderr}"
            );
            assert_eq!(stderr.lines().count(), 1, "case {i} {platform:?}: {stderr}");
            assert!(stderr.contains(says), "case {i} {platform:?}: {stderr}");
        }
    }
}

//! The command-line contract (docs/simulator.md), checked on the real binary.

mod common;

use common::{assert_success, bin, file};

use std::path::PathBuf;
use std::process::Output;

fn scenarios() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenarios")
}

fn run(path: &std::path::Path, arch: &str, json: bool) -> Output {
    let mut cmd = bin();
    cmd.arg("run").arg(path).args(["--arch", arch]);
    if json {
        cmd.arg("--json");
    }
    cmd.output().unwrap()
}

/// Status 2, nothing on stdout, exactly one line on stderr that names the file and contains
/// every `expected` fragment, and no panic.
fn assert_bad_input(path: &std::path::Path, expected: &[&str]) {
    let out = run(path, "psmpa", true);
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert_eq!(out.status.code(), Some(2), "stderr: {stderr}");
    assert!(out.stdout.is_empty());
    assert_eq!(stderr.lines().count(), 1, "one line, got: {stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(
        stderr.contains(&path.display().to_string()),
        "names the file: {stderr}"
    );
    for fragment in expected {
        assert!(
            stderr.contains(fragment),
            "expected `{fragment}` in: {stderr}"
        );
    }
}

const GOOD_TAIL: &str = r#""interferences": [{"kind": "box", "at_s": 1.0}]}"#;

#[test]
fn missing_file() {
    let path = std::env::temp_dir().join("psmpa-no-such-scenario.json");
    assert_bad_input(&path, &["cannot read"]);
}

#[test]
fn malformed_json_names_line_and_column() {
    let path = file(
        "malformed.json",
        "{\n  \"name\": \"x\",\n  \"interferences\": [\n",
    );
    assert_bad_input(&path, &["line 4", "column"]);
    let path = file("malformed2.json", "{\"name\": \"x\" \"interferences\": []}");
    assert_bad_input(&path, &["line 1 column 14"]);
}

#[test]
fn wrong_type_names_the_field() {
    let path = file(
        "wrong-type.json",
        &format!(r#"{{"name": "x", "door_m": "far", {GOOD_TAIL}"#),
    );
    assert_bad_input(&path, &["door_m", "invalid type"]);
    let path = file(
        "wrong-type-nested.json",
        r#"{"name": "x", "interferences": [{"kind": "box", "at_s": true}]}"#,
    );
    assert_bad_input(&path, &["interferences[0].at_s", "invalid type"]);
}

#[test]
fn unknown_field() {
    let path = file(
        "unknown-field.json",
        &format!(r#"{{"name": "x", "colour": "red", {GOOD_TAIL}"#),
    );
    assert_bad_input(&path, &["unknown field `colour`"]);
    let path = file(
        "unknown-field-nested.json",
        &format!(r#"{{"name": "x", "sonar": {{"range_m": 3}}, {GOOD_TAIL}"#),
    );
    assert_bad_input(&path, &["sonar", "unknown field `range_m`"]);
}

#[test]
fn negative_time() {
    let path = file(
        "negative.json",
        r#"{"name": "x", "interferences": [{"kind": "box", "at_s": 1.0}, {"kind": "ball", "at_s": -3.5}]}"#,
    );
    assert_bad_input(&path, &["interferences[1].at_s", "negative", "-3.5"]);
    let path = file(
        "negative-hold.json",
        r#"{"name": "x", "interferences": [{"kind": "box", "at_s": 1, "hold_s": -1}]}"#,
    );
    assert_bad_input(&path, &["interferences[0].hold_s", "negative"]);
    let path = file(
        "negative-distance.json",
        &format!(r#"{{"name": "x", "door_m": -2, {GOOD_TAIL}"#),
    );
    assert_bad_input(&path, &["door_m", "negative"]);
}

#[test]
fn unknown_kind() {
    let path = file(
        "kind.json",
        r#"{"name": "x", "interferences": [{"kind": "chair", "at_s": 1.0}]}"#,
    );
    assert_bad_input(&path, &["interferences[0].kind", "unknown variant `chair`"]);
}

#[test]
fn a_wrong_type_where_a_name_or_an_object_belongs_names_the_field() {
    let path = file(
        "kind-number.json",
        r#"{"name": "x", "interferences": [{"kind": 1, "at_s": 1.0}]}"#,
    );
    assert_bad_input(&path, &["interferences[0].kind", "\"box\" or \"ball\""]);
    let path = file(
        "robot-array.json",
        &format!(r#"{{"name": "x", "robot": [0.1, 1.0], {GOOD_TAIL}"#),
    );
    assert_bad_input(&path, &["robot: invalid type: array, expected an object"]);
    let path = file(
        "item-array.json",
        r#"{"name": "x", "interferences": [{"kind": "box"}, ["box", 1.0]]}"#,
    );
    assert_bad_input(&path, &["interferences[1]: invalid type: array"]);
    let path = file("positional.json", r#"["x", 42, 1.5, 600, [], []]"#);
    assert_bad_input(&path, &["the top level: expected a JSON object"]);
    let path = file("brackets.json", &"[".repeat(1 << 20));
    assert_bad_input(&path, &["the top level: expected a JSON object"]);
}

#[test]
fn empty_name() {
    let path = file("empty-name.json", &format!(r#"{{"name": "", {GOOD_TAIL}"#));
    assert_bad_input(&path, &["name", "empty"]);
}

#[test]
fn missing_required_field() {
    let path = file("no-interferences.json", r#"{"name": "x"}"#);
    assert_bad_input(&path, &["missing field `interferences`"]);
}

#[test]
fn out_of_range_values() {
    let path = file(
        "period.json",
        &format!(r#"{{"name": "x", "sonar": {{"period_ms": 0}}, {GOOD_TAIL}"#),
    );
    assert_bad_input(&path, &["sonar.period_ms"]);
    let path = file(
        "dropout.json",
        &format!(r#"{{"name": "x", "sonar": {{"dropout": 2}}, {GOOD_TAIL}"#),
    );
    assert_bad_input(&path, &["sonar.dropout"]);
    let many: Vec<String> = (0..40)
        .map(|i| format!(r#"{{"kind": "box", "at_s": {i}}}"#))
        .collect();
    let path = file(
        "too-many.json",
        &format!(r#"{{"name": "x", "interferences": [{}]}}"#, many.join(",")),
    );
    assert_bad_input(&path, &["interferences", "at most 32 interferences"]);
}

#[test]
fn run_json_prints_exactly_the_contract_object() {
    let out = run(&scenarios().join("sonar-6.json"), "psmpa", true);
    assert_eq!(out.status.code(), Some(0));
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert_eq!(stdout.trim().lines().count(), 1);
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let obj = v.as_object().unwrap();
    let keys: Vec<&str> = obj.keys().map(String::as_str).collect();
    let mut expected = vec![
        "scenario",
        "arch",
        "interferences",
        "detected",
        "detection_rate",
        "collisions",
        "reached_door",
        "time_cost_s",
        "max_reaction_ms",
        "sensor_on_s",
        "sample_gap_max_ms",
        "trace_hash",
    ];
    // In the contract's order, too.
    let at = |key: &str| stdout.find(&format!("\"{key}\":")).unwrap();
    assert!(expected.windows(2).all(|w| at(w[0]) < at(w[1])), "{stdout}");
    let mut sorted = keys.clone();
    sorted.sort_unstable();
    expected.sort_unstable();
    assert_eq!(sorted, expected);
    assert_eq!(v["scenario"], "sonar-6");
    assert_eq!(v["arch"], "psmpa");
    assert_eq!(v["interferences"], 6);
    assert_eq!(v["detected"], 6);
    assert_eq!(v["detection_rate"], 1.0);
    assert_eq!(v["collisions"], 0);
    assert_eq!(v["reached_door"], true);
    assert!(v["time_cost_s"].as_f64().unwrap() > 0.0);
    assert!(v["max_reaction_ms"].as_u64().unwrap() <= 100);
    let on = v["sensor_on_s"].as_object().unwrap();
    assert_eq!(on.keys().collect::<Vec<_>>(), ["bumper", "sonar"]);
    // Each sensor samples on its own period, whatever the other does. A sonar sample is
    // delivered when its echo ends: up to the 38 ms of "nothing in range" past its period.
    let sonar_gap = v["sample_gap_max_ms"]["sonar"].as_u64().unwrap();
    assert!((100..=138).contains(&sonar_gap), "{sonar_gap}");
    assert_eq!(v["sample_gap_max_ms"]["bumper"], 20);
    let hash = v["trace_hash"].as_str().unwrap();
    assert_eq!(hash.len(), 16);
    assert!(
        hash.chars()
            .all(|c| c.is_ascii_hexdigit() && !c.is_ascii_uppercase())
    );
}

#[test]
fn a_sample_gap_is_null_for_a_sensor_with_fewer_than_two_samples() {
    // A sonar period longer than the walk: one sample when the walk starts, then no more.
    let path = file(
        "slow-sonar.json",
        r#"{"name":"slow-sonar","sonar":{"period_ms":60000},"interferences":[]}"#,
    );
    let out = run(&path, "psmpa", true);
    assert_success(&out);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["sample_gap_max_ms"]["sonar"], serde_json::Value::Null);
    assert_eq!(v["sample_gap_max_ms"]["bumper"], 20);
}

#[test]
fn an_interference_never_put_down_is_not_counted_or_missed() {
    // The second box is due a day in, long after the run ends; with `max_s` 2 the first is
    // never put down either. Neither existed, so neither counts against the detection rate.
    for (name, body, counted) in [
        (
            "late.json",
            r#"{"name":"late","interferences":[{},{"at_s":86400}]}"#,
            1,
        ),
        (
            "short.json",
            r#"{"name":"short","max_s":2,"interferences":[{}]}"#,
            0,
        ),
    ] {
        let out = run(&file(name, body), "psmpa", true);
        assert_success(&out);
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(v["interferences"], counted, "{name}");
        assert_eq!(v["detected"], counted, "{name}");
        assert_eq!(v["detection_rate"], 1.0, "{name}");
    }
}

#[test]
fn max_reaction_is_null_when_nothing_was_detected() {
    let out = run(&scenarios().join("quiet.json"), "smpa", true);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(v["max_reaction_ms"].is_null());
    assert_eq!(v["detection_rate"], 1.0);
}

#[test]
fn outcome_never_changes_the_exit_status() {
    // SMPA collides here; the simulation still ran.
    let out = run(&scenarios().join("blind-box.json"), "smpa", true);
    assert_eq!(out.status.code(), Some(0));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(v["collisions"].as_u64().unwrap() > 0);
}

#[test]
fn text_output_without_json() {
    let out = run(&scenarios().join("mixed.json"), "smpa", false);
    assert_eq!(out.status.code(), Some(0));
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.starts_with("scenario mixed under SMPA"));
    assert!(text.contains("collisions"));
    assert!(serde_json::from_str::<serde_json::Value>(&text).is_err());
}

#[test]
fn outputs_are_written() {
    let dir = std::env::temp_dir().join(format!("psmpa-out-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (csv, svg, timeline) = (dir.join("t.csv"), dir.join("p.svg"), dir.join("t.json"));
    let out = bin()
        .arg("run")
        .arg(scenarios().join("bumper-4.json"))
        .args(["--arch", "smpa", "--json", "--trace"])
        .arg(&csv)
        .arg("--plot")
        .arg(&svg)
        .arg("--timeline")
        .arg(&timeline)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0));
    let csv = std::fs::read_to_string(csv).unwrap();
    assert!(csv.starts_with("time_s,sonar_m,bumper,position_m,source,event\n"));
    assert!(csv.contains("collision"));
    assert!(csv.lines().count() > 100);
    let svg = std::fs::read_to_string(svg).unwrap();
    assert!(
        svg.starts_with("<svg") && svg.contains("P-SMPA") && svg.contains("SMPA: bumper readings")
    );
    let doc: serde_json::Value = serde_json::from_slice(&std::fs::read(timeline).unwrap()).unwrap();
    let events = doc["traceEvents"].as_array().unwrap();
    // Behaviours that ran side by side: the walk and the sensors in sense phases.
    assert!(
        events
            .iter()
            .any(|e| e["name"] == "go to door" && e["ph"] == "X")
    );
    assert!(
        events
            .iter()
            .any(|e| e["name"] == "bumper on" && e["ph"] == "X")
    );
    assert!(
        events
            .iter()
            .any(|e| e["name"] == "sense" && e["ph"] == "X")
    );
}

#[test]
fn unwritable_output_is_bad_input() {
    let out = bin()
        .arg("run")
        .arg(scenarios().join("quiet.json"))
        .args([
            "--arch",
            "psmpa",
            "--json",
            "--trace",
            "/nonexistent-dir/t.csv",
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert_eq!(stderr.lines().count(), 1);
    assert!(stderr.contains("/nonexistent-dir/t.csv"));
}

#[test]
fn a_sweep_too_large_to_hold_is_refused() {
    for runs in ["0", "1000001", "18446744073709551615"] {
        let out = bin()
            .args(["sweep", "--runs", runs, "--json"])
            .output()
            .unwrap();
        let stderr = String::from_utf8(out.stderr).unwrap();
        assert_eq!(out.status.code(), Some(2), "{runs}: {stderr}");
        assert!(stderr.contains("--runs"), "{stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}

#[test]
fn a_plot_stays_well_formed_xml_whatever_the_scenario_name() {
    let path = file(
        "odd-name.json",
        r#"{"name": "<a&b>\"c'\u0001", "interferences": [{"kind": "box", "at_s": 1.0}]}"#,
    );
    let svg = std::env::temp_dir().join(format!("psmpa-odd-{}.svg", std::process::id()));
    let out = bin()
        .arg("run")
        .arg(&path)
        .args(["--arch", "psmpa", "--plot"])
        .arg(&svg)
        .output()
        .unwrap();
    assert_success(&out);
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(
        !text
            .chars()
            .any(|c| c.is_control() && !"\t\n\r".contains(c)),
        "a control character XML forbids"
    );
    assert!(text.contains("&lt;a&amp;b&gt;"), "the name, escaped");
}

/// docs/simulator.md shows what `sweep` prints with its defaults, byte for byte: the page's
/// sample is the command's output, not a copy that can drift.
#[test]
fn the_sweep_sample_on_the_page_is_what_the_sweep_prints() {
    let out = bin()
        .args(["sweep", "--runs", "1000", "--seed", "1"])
        .output()
        .unwrap();
    assert_success(&out);
    let page = std::fs::read_to_string(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../docs/simulator.md"),
    )
    .unwrap();
    let start = "```text\nsweep: 1000 random scenarios, seed 1\n";
    let (_, after) = page.split_once(start).expect("the page's sweep sample");
    let (rest, _) = after.split_once("```").unwrap();
    let shown = format!("sweep: 1000 random scenarios, seed 1\n{rest}");
    assert_eq!(
        String::from_utf8(out.stdout).unwrap(),
        shown,
        "docs/simulator.md's sweep sample: paste what psmpa-sim sweep prints"
    );
}

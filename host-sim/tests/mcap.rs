//! `--mcap` (issue 15, item 5): the run as an MCAP log for Foxglove, read back with the `mcap`
//! crate and checked against the trace CSV of the same run.

mod common;

use common::{assert_refused, assert_success, bin, file, folder, names_in, repo};

use std::cell::RefCell;
use std::collections::{BTreeMap, BTreeSet};
use std::process::Output;

use embassy_time::Instant;
use psmpa_core::{TraceEvent, TraceSink};
use psmpa_sim::cli::foxglove::McapLog;
use psmpa_sim::cli::sweep;
use psmpa_sim::robot::Arch;
use psmpa_sim::sim::run_logged;
use psmpa_sim::world::{WorldEvent, WorldLog};
use serde_json::Value;

/// One message read back: topic, log time (ns), sequence and JSON.
struct Msg {
    topic: String,
    log_ns: u64,
    sequence: u32,
    json: Value,
}

/// The channels (topic -> schema name and JSON schema) and the messages of a log, in file
/// order; checks the encodings on the way.
fn read(bytes: &[u8]) -> (BTreeMap<String, (String, Value)>, Vec<Msg>) {
    let summary = mcap::Summary::read(bytes)
        .unwrap()
        .expect("a summary section");
    // Chunked and indexed, so that Foxglove can seek in a long log.
    assert!(!summary.chunk_indexes.is_empty(), "chunk indexes");
    for chunk in &summary.chunk_indexes {
        assert_eq!(chunk.compression, "", "uncompressed");
        assert!(!chunk.message_index_offsets.is_empty(), "message indexes");
    }
    let mut channels = BTreeMap::new();
    for c in summary.channels.values() {
        assert_eq!(c.message_encoding, "json", "{}", c.topic);
        let schema = c.schema.as_ref().expect("every channel has a schema");
        assert_eq!(schema.encoding, "jsonschema", "{}", c.topic);
        let json: Value = serde_json::from_slice(&schema.data).unwrap();
        let old = channels.insert(c.topic.clone(), (schema.name.clone(), json));
        assert!(old.is_none(), "one channel per topic: {}", c.topic);
    }
    let messages = mcap::MessageStream::new(bytes)
        .unwrap()
        .map(|m| {
            let m = m.unwrap();
            Msg {
                topic: m.channel.topic.clone(),
                log_ns: m.log_time,
                sequence: m.sequence,
                json: serde_json::from_slice(&m.data)
                    .unwrap_or_else(|e| panic!("{}: not JSON: {e}", m.channel.topic)),
            }
        })
        .collect();
    (channels, messages)
}

/// Whether `v` matches `schema` (the subset of JSON Schema the log's schemas use: object with
/// properties, required and additionalProperties, string with enum, integer with minimum,
/// number, boolean).
fn check(schema: &Value, v: &Value, at: &str) {
    let ty = schema["type"]
        .as_str()
        .unwrap_or_else(|| panic!("{at}: no type"));
    match ty {
        "object" => {
            let obj = v
                .as_object()
                .unwrap_or_else(|| panic!("{at}: not an object"));
            let props = schema["properties"].as_object().unwrap();
            for r in schema["required"].as_array().into_iter().flatten() {
                let r = r.as_str().unwrap();
                assert!(obj.contains_key(r), "{at}: `{r}` missing in {v}");
            }
            for (k, val) in obj {
                match props.get(k) {
                    Some(s) => check(s, val, &format!("{at}.{k}")),
                    None => assert_ne!(
                        schema["additionalProperties"],
                        Value::Bool(false),
                        "{at}: `{k}` is not in the schema"
                    ),
                }
            }
        }
        "string" => {
            let s = v
                .as_str()
                .unwrap_or_else(|| panic!("{at}: not a string: {v}"));
            if let Some(allowed) = schema["enum"].as_array() {
                assert!(allowed.iter().any(|a| a == s), "{at}: `{s}` not allowed");
            }
        }
        "integer" => {
            assert!(v.is_i64() || v.is_u64(), "{at}: not an integer: {v}");
            if let Some(min) = schema["minimum"].as_i64() {
                assert!(v.as_i64().is_none_or(|x| x >= min), "{at}: below {min}");
            }
        }
        "number" => assert!(v.is_number(), "{at}: not a number: {v}"),
        "boolean" => assert!(v.is_boolean(), "{at}: not a boolean: {v}"),
        other => panic!("{at}: type {other} not expected"),
    }
}

/// Every message matches its channel's schema; log times never decrease; each channel's
/// sequence counts from 0.
fn check_all(channels: &BTreeMap<String, (String, Value)>, messages: &[Msg]) {
    let mut next: BTreeMap<&str, u32> = BTreeMap::new();
    for (i, m) in messages.iter().enumerate() {
        let (_, schema) = &channels[&m.topic];
        check(schema, &m.json, &m.topic);
        let seq = next.entry(&m.topic).or_insert(0);
        assert_eq!(m.sequence, *seq, "{} sequence", m.topic);
        *seq += 1;
        if i > 0 {
            assert!(
                messages[i - 1].log_ns <= m.log_ns,
                "log time decreases at message {i} ({})",
                m.topic
            );
        }
    }
}

/// A row of the trace CSV: time (ms), sonar (m), position (m), source, event text.
struct Row {
    ms: u64,
    sonar_m: String,
    position_m: String,
    source: String,
    text: String,
}

fn rows(csv: &str) -> Vec<Row> {
    csv.lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.splitn(6, ',').collect();
            let secs: f64 = f[0].parse().unwrap();
            Row {
                ms: (secs * 1000.0).round() as u64,
                sonar_m: f[1].to_owned(),
                position_m: f[3].to_owned(),
                source: f[4].to_owned(),
                text: f[5].trim_matches('"').to_owned(),
            }
        })
        .collect()
}

/// The device of a world sample row (`Sample(Sonar, 2550)`).
fn sample_of(row: &Row) -> Option<String> {
    let rest = row.text.strip_prefix("Sample(")?;
    (row.source == "world").then(|| rest.split(',').next().unwrap_or("").to_lowercase())
}

/// A runtime sample row (`sonar sample Mm(480), holds {}`): left out of `/events`.
fn runtime_sample(row: &Row) -> bool {
    row.source == "runtime" && row.text.contains(" sample ") && row.text.contains(", holds ")
}

#[test]
fn a_run_logs_each_sensor_the_pose_and_the_events_as_the_trace_has_them() {
    let dir = folder("run");
    let scenario = repo("scenarios/sonar-8.json");
    let out = bin()
        .current_dir(&dir)
        .arg("run")
        .arg(&scenario)
        .args(["--arch", "psmpa", "--mcap", "out.mcap", "--trace", "t.csv"])
        .output()
        .unwrap();
    assert_success(&out);
    assert_eq!(
        names_in(&dir),
        ["out.mcap", "t.csv"],
        "no temporary file left"
    );
    let bytes = std::fs::read(dir.join("out.mcap")).unwrap();
    let csv = std::fs::read_to_string(dir.join("t.csv")).unwrap();
    let (channels, messages) = read(&bytes);

    // Topics: one per sensor of the mission, the pose, the events.
    let mission: Value =
        serde_json::from_str(&std::fs::read_to_string(repo("missions/fetch-tea.json")).unwrap())
            .unwrap();
    let mut expected: BTreeSet<String> = mission["sensors"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| format!("/sensor/{}", s["name"].as_str().unwrap()))
        .collect();
    expected.extend(["/robot/pose".to_owned(), "/events".to_owned()]);
    assert_eq!(channels.keys().cloned().collect::<BTreeSet<_>>(), expected);
    assert_eq!(channels["/robot/pose"].0, "foxglove.PoseInFrame");
    check_all(&channels, &messages);
    let on = |topic: &str| -> Vec<&Msg> { messages.iter().filter(|m| m.topic == topic).collect() };

    // Each sensor's messages are the trace's samples of it: same instants, same readings.
    let rows = rows(&csv);
    for (name, _) in channels.iter().filter(|(t, _)| t.starts_with("/sensor/")) {
        let device = name.trim_start_matches("/sensor/");
        let samples: Vec<&Row> = rows
            .iter()
            .filter(|r| sample_of(r).as_deref() == Some(device))
            .collect();
        let logged = on(name);
        assert_eq!(logged.len(), samples.len(), "{name}: one message a sample");
        for (m, r) in logged.iter().zip(&samples) {
            assert_eq!(m.log_ns, r.ms * 1_000_000, "{name} at {} ms", r.ms);
            if device == "sonar" {
                let value_m = m.json["value_m"].as_f64().unwrap();
                assert_eq!(format!("{value_m:.3}"), r.sonar_m, "{name} at {} ms", r.ms);
            }
        }
    }
    assert!(on("/sensor/sonar").len() > 100 && on("/sensor/bumper").len() > 100);

    // The events are the trace's other rows, in the same order, at the same instants.
    let other: Vec<&Row> = rows
        .iter()
        .filter(|r| sample_of(r).is_none() && !runtime_sample(r))
        .collect();
    let events = on("/events");
    assert_eq!(events.len(), other.len(), "one event a row");
    for (m, r) in events.iter().zip(&other) {
        assert_eq!(m.log_ns, r.ms * 1_000_000, "{}", r.text);
        assert_eq!(m.json["source"], r.source.as_str(), "{}", r.text);
        assert_eq!(m.json["text"].as_str().unwrap().replace('"', "'"), r.text);
    }
    let kinds: BTreeSet<&str> = events
        .iter()
        .map(|m| m.json["kind"].as_str().unwrap())
        .collect();
    for k in [
        "plan_selected",
        "state_entered",
        "state_left",
        "sensor_on",
        "sensor_off",
        "precondition_violated",
        "precondition_restored",
        "effects_applied",
        "goal_reached",
        "detected",
        "box_put_down",
    ] {
        assert!(kinds.contains(k), "no {k} event in {kinds:?}");
    }

    // The pose: at world rows, where the position is the row's, starting at 0.
    let poses = on("/robot/pose");
    assert!(poses.len() > 10);
    for p in &poses {
        let ms = p.log_ns / 1_000_000;
        let x = p.json["pose"]["position"]["x"].as_f64().unwrap();
        assert!(
            rows.iter()
                .any(|r| r.ms == ms && r.source == "world" && r.position_m == format!("{x:.4}")),
            "pose {x} m at {ms} ms is on no world row"
        );
        let stamp = &p.json["timestamp"];
        let ns = stamp["sec"].as_u64().unwrap() * 1_000_000_000 + stamp["nsec"].as_u64().unwrap();
        assert_eq!(ns, p.log_ns);
        assert_eq!(p.json["frame_id"], "corridor");
    }
    let last = rows.iter().rev().find(|r| r.source == "world").unwrap();
    let x = poses.last().unwrap().json["pose"]["position"]["x"]
        .as_f64()
        .unwrap();
    assert_eq!(
        format!("{x:.4}"),
        last.position_m,
        "the last pose is where the run ended"
    );

    // The same run without the trace writes the same bytes.
    let alone = bin()
        .current_dir(&dir)
        .arg("run")
        .arg(&scenario)
        .args(["--arch", "psmpa", "--mcap", "again.mcap", "--json"])
        .output()
        .unwrap();
    assert_success(&alone);
    assert_eq!(std::fs::read(dir.join("again.mcap")).unwrap(), bytes);
}

/// Streams a run into an MCAP log in memory, as `--mcap` does.
struct Log<'a>(&'a RefCell<Option<McapLog<Vec<u8>>>>);

impl WorldLog for Log<'_> {
    fn log(&mut self, at_ms: u64, pos_um: i64, event: WorldEvent) {
        if let Some(l) = self.0.borrow_mut().as_mut() {
            l.world(at_ms, pos_um, event);
        }
    }
}

impl<Ms: psmpa_core::Mission<Facts = psmpa_core::FactSet>> TraceSink<Ms> for Log<'_> {
    fn record(&mut self, at: Instant, event: &TraceEvent) {
        if let Some(l) = self.0.borrow_mut().as_mut() {
            l.runtime(at, event);
        }
    }
}

fn sweep_cmd(extra: &[&str]) -> Output {
    bin()
        .args(["sweep", "--runs", "3", "--seed", "7", "--json"])
        .args(extra)
        .output()
        .unwrap()
}

#[test]
fn a_sweep_logs_the_chosen_run_and_prints_what_it_printed() {
    let dir = folder("sweep");
    let file = dir.join("s.mcap");
    let f = file.to_str().unwrap();
    let plain = sweep_cmd(&[]);
    assert_success(&plain);
    for (arch, extra) in [
        (Arch::PSmpa, vec!["--mcap", f, "--mcap-run", "2"]),
        (
            Arch::Smpa,
            vec!["--mcap", f, "--mcap-run", "2", "--mcap-arch", "smpa"],
        ),
        (
            Arch::Smpa,
            vec!["--arch", "smpa", "--mcap", f, "--mcap-run", "2"],
        ),
    ] {
        let out = sweep_cmd(&extra);
        assert_success(&out);
        if !extra.contains(&"--arch") {
            assert_eq!(out.stdout, plain.stdout, "the statistics are unchanged");
        }
        // The file is run 2 of the sweep under `arch`, as the library streams it.
        let sc = sweep::scenario(7, 2);
        let log = RefCell::new(Some(McapLog::new(Vec::new(), &sc).unwrap()));
        run_logged(&sc, arch, Log(&log), Log(&log)).unwrap();
        let expected = log.into_inner().unwrap().finish().unwrap();
        let bytes = std::fs::read(&file).unwrap();
        assert_eq!(bytes, expected, "{extra:?}");
        let (channels, messages) = read(&bytes);
        check_all(&channels, &messages);
        assert!(messages.iter().any(|m| m.topic == "/events"));
    }
    // A run the sweep does not have, or an architecture it does not run: nothing written.
    std::fs::remove_file(&file).unwrap();
    let out = sweep_cmd(&["--mcap", f, "--mcap-run", "3"]);
    assert_refused(&out, &["--mcap-run 3", "0 to 2"]);
    let out = sweep_cmd(&["--arch", "psmpa", "--mcap", f, "--mcap-arch", "smpa"]);
    assert_refused(&out, &["--mcap-arch smpa"]);
    let out = sweep_cmd(&["--mcap-run", "1"]);
    assert_eq!(out.status.code(), Some(2), "--mcap-run needs --mcap");
    assert!(names_in(&dir).is_empty());
}

#[test]
fn a_log_that_cannot_be_written_is_one_line_and_no_file() {
    let dir = folder("bad");
    let scenario = file("empty.json", r#"{"name": "empty", "interferences": []}"#);
    let run = |extra: &[&str]| {
        bin()
            .current_dir(&dir)
            .arg("run")
            .arg(&scenario)
            .args(["--arch", "psmpa"])
            .args(extra)
            .output()
            .unwrap()
    };
    let out = run(&["--mcap", "missing/out.mcap"]);
    assert_refused(&out, &["missing/out.mcap", "No such file"]);
    let out = run(&["--mcap", "x.mcap", "--trace", "./x.mcap"]);
    assert_refused(&out, &["--mcap", "--trace"]);
    let out = run(&["--trace", "t.csv", "--mcap", "/dev/full"]);
    assert_refused(&out, &["/dev/full", "No space left"]);
    let out = bin()
        .current_dir(&dir)
        .args(["sweep", "--runs", "2", "--mcap", "missing/s.mcap"])
        .output()
        .unwrap();
    assert_refused(&out, &["missing/s.mcap", "No such file"]);
    assert!(names_in(&dir).is_empty(), "{:?}", names_in(&dir));
}

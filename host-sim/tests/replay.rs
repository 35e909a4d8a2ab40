//! `psmpa-sim run --record` and `psmpa-sim replay` (issue 39): every shipped scenario's
//! recording replays with every decision as recorded; a changed reading diverges where it
//! changes a decision; a file that is not a whole recording of this mission is refused in one
//! line.

mod common;

use common::{assert_success, bin, folder, repo};

use psmpa_core::record::{self, Frame, Input};
use psmpa_core::{FactSet, TraceEvent};
use serde_json::Value;
use std::path::{Path, PathBuf};

fn record(scenario: &Path, arch: &str, dir: &Path) -> PathBuf {
    let out = dir.join(format!(
        "{}.{arch}.rec",
        scenario.file_stem().unwrap().to_string_lossy()
    ));
    let run = bin()
        .arg("run")
        .arg(scenario)
        .args(["--arch", arch, "--record"])
        .arg(&out)
        .output()
        .unwrap();
    assert_success(&run);
    out
}

fn replay(file: &Path) -> (Option<i32>, Value, String) {
    let out = bin()
        .arg("replay")
        .arg(file)
        .arg("--json")
        .output()
        .unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    let stderr = String::from_utf8(out.stderr).unwrap();
    let json = serde_json::from_str(&text).unwrap_or(Value::Null);
    (out.status.code(), json, stderr)
}

#[test]
fn every_shipped_scenario_replays_as_recorded() {
    let dir = folder("replay-all");
    let mut scenarios: Vec<PathBuf> = std::fs::read_dir(repo("scenarios"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    scenarios.sort();
    assert!(scenarios.len() >= 16);
    for scenario in &scenarios {
        for arch in ["psmpa", "smpa"] {
            let rec = record(scenario, arch, &dir);
            let (status, v, stderr) = replay(&rec);
            assert_eq!(status, Some(0), "{}: {v} {stderr}", scenario.display());
            assert_eq!(v["diverged"], false, "{}", scenario.display());
            assert!(v["decisions"].as_u64().unwrap() > 100, "{v}");
        }
    }
}

/// The frames after a recording's header and prologue, and where they start.
fn frames(bytes: &[u8]) -> (usize, Vec<Frame<1>>) {
    let at = record::HEADER_LEN;
    let len = u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
    let start = record::HEADER_LEN + 4 + len + 1 + 4;
    let frames = bytes[start..]
        .chunks(record::frame_len(1))
        .enumerate()
        .map(|(i, c)| {
            Frame::decode(c, start + i * record::frame_len(1))
                .unwrap()
                .0
        })
        .collect();
    (start, frames)
}

/// A sonar reading changed at one instant, its CRC made good: the replay diverges at that
/// instant, where the changed reading makes the runtime see the path blocked.
#[test]
fn a_changed_reading_diverges_at_its_instant() {
    let dir = folder("replay-changed");
    let rec = record(&repo("scenarios/quiet.json"), "psmpa", &dir);
    let mut bytes = std::fs::read(&rec).unwrap();
    let (start, frames) = frames(&bytes);
    // The first sonar sample of the walk that shows the path clear (quiet has no obstacle).
    let entered = frames
        .iter()
        .position(|f| matches!(f.input(), Some(Input::Entered { .. })))
        .unwrap();
    let (index, sample) = frames
        .iter()
        .enumerate()
        .skip(entered + 5)
        .find_map(|(i, f)| match f.input() {
            Some(Input::Sample {
                sensor,
                value,
                holds,
            }) if !holds.is_empty() && sensor.index() == 0 => Some((i, (sensor, value, f.ticks))),
            _ => None,
        })
        .unwrap();
    let (sensor, value, ticks) = sample;
    let blocked = Frame::of(
        embassy_time::Instant::from_ticks(ticks),
        &TraceEvent::Sample {
            sensor,
            value,
            holds: FactSet::EMPTY,
        },
    );
    let at = start + index * record::frame_len(1);
    blocked.encode(&mut bytes[at..]).unwrap();
    let changed = dir.join("changed.rec");
    std::fs::write(&changed, &bytes).unwrap();
    let (status, v, _) = replay(&changed);
    assert_eq!(status, Some(1), "{v}");
    assert_eq!(v["diverged"], true);
    let d = &v["divergence"];
    let seconds = embassy_time::Instant::from_ticks(ticks).as_micros() as f64 / 1e6;
    assert_eq!(d["at_s"].as_f64().unwrap(), seconds, "{v}");
    // The changed sample itself is fed as recorded; the decision after it differs.
    assert!(d["event"].as_u64().unwrap() as usize > index, "{v}");
    assert_eq!(v["decisions"], d["event"]);
    // The text form says where, what was recorded and what the replay decided, in one line.
    let out = bin().arg("replay").arg(&changed).output().unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    assert_eq!(text.lines().count(), 1, "{text}");
    assert!(
        text.starts_with(&format!("replay diverged at {seconds:.3} s")),
        "{text}"
    );
}

/// Not a recording, a changed byte, a cut, an older format, another mission: status 2, one
/// line, never a panic.
#[test]
fn a_file_that_is_not_a_whole_recording_is_refused() {
    let dir = folder("replay-bad");
    let rec = record(&repo("scenarios/sonar-6.json"), "psmpa", &dir);
    let bytes = std::fs::read(&rec).unwrap();
    let (start, _) = frames(&bytes);
    let write = |name: &str, bytes: &[u8]| {
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap();
        path
    };
    let mut flipped = bytes.clone();
    flipped[start + 3 * record::frame_len(1) + 12] ^= 4;
    // Version 1, before the header carried its tick rate: 4 bytes shorter.
    let mut older = bytes[..19].to_vec();
    older[8] = 1;
    older.extend_from_slice(&bytes[record::HEADER_LEN..]);
    // The first frame at the largest instant, its checksum made good.
    let mut late = bytes.clone();
    late[start + 1..start + 9].copy_from_slice(&u64::MAX.to_le_bytes());
    let body = record::frame_len(1) - 4;
    let crc = record::crc32(&late[start..start + body]);
    late[start + body..start + body + 4].copy_from_slice(&crc.to_le_bytes());
    // A header whose tick rate is 0: its instants have no unit.
    let mut no_ticks = bytes.clone();
    no_ticks[19..23].copy_from_slice(&0u32.to_le_bytes());
    let mut other = bytes.clone();
    // The prologue's scenario, changed, its checksum made good: another run's recording.
    let name_at = bytes.windows(7).position(|w| w == b"sonar-6").unwrap();
    other[name_at + 6] = b'7';
    let prologue_end = start - 4;
    let crc = record::crc32(&other[record::HEADER_LEN..prologue_end]);
    other[prologue_end..start].copy_from_slice(&crc.to_le_bytes());
    for (path, says) in [
        (repo("scenarios/sonar-6.json"), "not a recording"),
        (write("flipped.rec", &flipped), "fails its checksum"),
        (write("cut.rec", &bytes[..bytes.len() - 7]), "cut short"),
        (
            write("cut-prologue.rec", &bytes[..34]),
            "cut short in its prologue",
        ),
        (
            write("older.rec", &older),
            "format version 1, this reads version 2",
        ),
        (write("other.rec", &other), "another mission"),
        (write("empty.rec", b""), "cut short"),
        (write("no-ticks.rec", &no_ticks), "a tick rate of 0 Hz"),
        (write("late.rec", &late), "after a day, the longest run"),
    ] {
        let (status, _, stderr) = replay(&path);
        assert_eq!(status, Some(2), "{}: {stderr}", path.display());
        assert_eq!(stderr.lines().count(), 1, "{stderr}");
        assert!(stderr.contains(says), "{}: {stderr}", path.display());
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}

/// `replay --mcap` logs the replay's decisions for Foxglove: a readable MCAP whose /events
/// channel holds them.
#[test]
fn a_replay_opens_in_foxglove() {
    let dir = folder("replay-mcap");
    let rec = record(&repo("scenarios/sonar-6.json"), "psmpa", &dir);
    let log = dir.join("replay.mcap");
    let out = bin()
        .arg("replay")
        .arg(&rec)
        .arg("--mcap")
        .arg(&log)
        .output()
        .unwrap();
    assert_success(&out);
    let bytes = std::fs::read(&log).unwrap();
    let topics: Vec<String> = mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| m.unwrap().channel.topic.clone())
        .collect();
    assert!(
        topics.iter().filter(|t| *t == "/events").count() > 10,
        "{}",
        topics.len()
    );
}

/// A chip's recording (`cargo xtask qemu` on mps2-an386, kept in `tests/data`): its events
/// come a tick or so later than the host's, where the chip computed. Bit for bit it diverges
/// at the first of them; with the lag allowed (the replay's clock then follows the recording
/// across such gaps) every decision is equal, in order, and the skew is said.
#[test]
fn a_chips_recording_replays_within_the_lag_it_is_given() {
    let file = repo("host-sim/tests/data/quiet.smpa.mps2-an386.rec");
    let (status, v, stderr) = replay(&file);
    assert_eq!(status, Some(1), "{v} {stderr}");
    assert_eq!(v["diverged"], true);
    let out = bin()
        .arg("replay")
        .arg(&file)
        .args(["--json", "--lag-ms", "2"])
        .output()
        .unwrap();
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(out.status.code(), Some(0), "{v}");
    assert_eq!(v["diverged"], false);
    // Every recorded event is a decision the replay made again.
    let bytes = std::fs::read(&file).unwrap();
    let frames = psmpa_sim::replay::read(&file, &bytes).unwrap().frames.len();
    assert_eq!(v["decisions"], frames);
    assert!(v["skew_ms"].as_u64().unwrap() <= 2, "{v}");
    // A lag is a number of ms, from 0 to a minute.
    let bad = bin()
        .arg("replay")
        .arg(&file)
        .args(["--lag-ms", "-1"])
        .output()
        .unwrap();
    assert_eq!(bad.status.code(), Some(2));
}

/// A firmware's decoded log (`probe-rs run`, `defmt-print`) replays as its recording: the
/// `rec [bytes]` lines gathered, whatever else the log says.
#[test]
fn a_decoded_log_replays_as_its_recording() {
    let dir = folder("replay-log");
    let rec = record(&repo("scenarios/sonar-6.json"), "psmpa", &dir);
    let bytes = std::fs::read(&rec).unwrap();
    let mut log = String::from("0.000 INFO  calibration from flash: ...\n");
    for (i, piece) in bytes.chunks(29).enumerate() {
        let list: Vec<String> = piece.iter().map(u8::to_string).collect();
        // Some viewers add where the message was logged.
        let at = if i % 2 == 1 {
            " (psmpa_board_rp rp/src/record.rs:57)"
        } else {
            ""
        };
        log += &format!("{}.{i:03} INFO  rec [{}]{at}\n", i / 1000, list.join(", "));
        if i % 50 == 0 {
            log += "1.000 WARN  go to door: precondition violated, {path_clear} false\n";
        }
    }
    let file = dir.join("robot.log");
    std::fs::write(&file, &log).unwrap();
    let (status, v, stderr) = replay(&file);
    assert_eq!(status, Some(0), "{v} {stderr}");
    assert!(v["decisions"].as_u64().unwrap() > 100, "{v}");
    // A byte that is not UTF-8 on a line of its own (a serial port's noise) is no matter: it
    // made the whole log "not a recording".
    let mut noisy = b"0.000 INFO  boot \xff\xfe garbage\n".to_vec();
    noisy.extend_from_slice(log.as_bytes());
    std::fs::write(&file, &noisy).unwrap();
    let (status, again, stderr) = replay(&file);
    assert_eq!(status, Some(0), "{stderr}");
    assert_eq!(again["decisions"], v["decisions"]);
    // A frame before any header is no recording.
    std::fs::write(&file, "0.1 INFO  rec [24, 0, 0]\n").unwrap();
    let (status, _, stderr) = replay(&file);
    assert_eq!(status, Some(2));
    assert!(stderr.contains("before any header"), "{stderr}");
}

/// A chip's recording whose prologue carries `scenario` (canonical form) instead, with its
/// length, the header's mission hash and the prologue's checksum made good: what a hostile
/// file can hold past every integrity check.
fn with_scenario(bytes: &[u8], scenario: &[u8]) -> Vec<u8> {
    use psmpa_sim::robot::{Arch, mission_hash};
    let at = record::HEADER_LEN;
    let len = u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
    let arch_byte = bytes[at + 4 + len];
    let arch = if arch_byte == 0 {
        Arch::PSmpa
    } else {
        Arch::Smpa
    };
    let mut header = record::Header::decode(bytes).unwrap();
    header.mission = mission_hash(scenario, arch);
    let mut out = header.encode().to_vec();
    out.extend_from_slice(&(scenario.len() as u32).to_le_bytes());
    out.extend_from_slice(scenario);
    out.push(arch_byte);
    let crc = record::crc32(&out[at..]);
    out.extend_from_slice(&crc.to_le_bytes());
    out.extend_from_slice(&bytes[at + 4 + len + 1 + 4..]);
    out
}

/// A chip's recording carries its scenario in canonical form: one a file could not give is
/// refused in one line naming the field, exit 2, before any replay (a run of u64::MAX ms used
/// to overflow the replay's clock, a sampling period of 0 to print a type's name).
#[test]
fn a_prologue_scenario_out_of_a_files_range_is_refused_naming_its_field() {
    let dir = folder("replay-prologue");
    let bytes = std::fs::read(repo("host-sim/tests/data/quiet.smpa.mps2-an386.rec")).unwrap();
    let at = record::HEADER_LEN;
    let len = u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
    let scenario = String::from_utf8(bytes[at + 4..at + 4 + len].to_vec()).unwrap();
    assert!(scenario.contains(",600000,"), "{scenario}");
    // The same recording rebuilt unchanged still replays: the rebuilding is sound.
    let same = dir.join("same.rec");
    std::fs::write(&same, with_scenario(&bytes, scenario.as_bytes())).unwrap();
    let out = bin()
        .arg("replay")
        .arg(&same)
        .args(["--lag-ms", "2"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{out:?}");
    for (name, from, to, says) in [
        ("forever", ",600000,", ",18446744073709551615,", "max_s"),
        ("no-period", ",[100,", ",[0,", "sonar.period_ms"),
        (
            "no-door",
            "\"quiet\",7,2000000,",
            "\"quiet\",7,0,",
            "door_m",
        ),
    ] {
        let changed = scenario.replacen(from, to, 1);
        assert_ne!(changed, scenario, "{name}");
        let path = dir.join(format!("{name}.rec"));
        std::fs::write(&path, with_scenario(&bytes, changed.as_bytes())).unwrap();
        let (status, _, stderr) = replay(&path);
        assert_eq!(status, Some(2), "{name}: {stderr}");
        assert_eq!(stderr.lines().count(), 1, "{name}: {stderr}");
        assert!(stderr.contains(says), "{name}: {stderr}");
        assert!(stderr.contains(&path.display().to_string()), "{stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}

/// A prologue larger than a scenario file may be (1 MiB) is refused before it is read.
#[test]
fn a_prologue_larger_than_a_scenario_file_is_refused() {
    let dir = folder("replay-large-prologue");
    let bytes = std::fs::read(repo("host-sim/tests/data/quiet.smpa.mps2-an386.rec")).unwrap();
    let mut scenario = b"[\"quiet\"".to_vec();
    scenario.resize((1 << 20) + 10, b' ');
    let path = dir.join("large.rec");
    std::fs::write(&path, with_scenario(&bytes, &scenario)).unwrap();
    let (status, _, stderr) = replay(&path);
    assert_eq!(status, Some(2), "{stderr}");
    assert!(stderr.contains("more than a scenario file may"), "{stderr}");
}

/// A host's recording cut at a frame boundary replays no longer than it lasted: its replay
/// ends a second past its last frame, not at the scenario's longest run (SMPA's sense and act
/// phases go on by their timers where a recording stops).
#[test]
fn a_cut_recording_replays_no_longer_than_it_lasted() {
    let dir = folder("replay-cut");
    let rec = record(&repo("scenarios/locked-door.json"), "smpa", &dir);
    let bytes = std::fs::read(&rec).unwrap();
    let (start, all) = frames(&bytes);
    let half = all.len() / 2;
    let cut = dir.join("cut-at-frame.rec");
    std::fs::write(&cut, &bytes[..start + half * record::frame_len(1)]).unwrap();
    let last_s = all[half - 1].ticks as f64 / embassy_time::TICK_HZ as f64;
    let (status, v, stderr) = replay(&cut);
    // The replay goes on deciding where the recording stopped: a divergence.
    assert_eq!(status, Some(1), "{v} {stderr}");
    let ran = v["replayed_s"].as_f64().unwrap_or(f64::MAX);
    assert!(
        ran <= last_s + 1.0 + 1e-6,
        "replayed to {ran} s, the recording ends at {last_s} s: {v}"
    );
}

/// A wider lag accepts whatever a narrower one does: an exact host recording replayed equal
/// at 0 to 10 ms and diverged from 20 ms (the clock followed the recording across a sensor's
/// wait, past its timeout); a chip's, from the lag its computing needs upwards.
#[test]
fn a_wider_lag_accepts_what_a_narrower_one_does() {
    let dir = folder("replay-lags");
    let host = record(&repo("scenarios/person.json"), "psmpa", &dir);
    let chip = repo("host-sim/tests/data/quiet.smpa.mps2-an386.rec");
    for (file, lags) in [
        (&host, &[0, 10, 20, 100, 60_000][..]),
        (&chip, &[1, 2, 20, 60_000]),
    ] {
        for lag in lags {
            let out = bin()
                .arg("replay")
                .arg(file)
                .args(["--json", "--lag-ms", &lag.to_string()])
                .output()
                .unwrap();
            let v: Value = serde_json::from_slice(&out.stdout).unwrap();
            assert_eq!(v["diverged"], false, "{} at {lag} ms: {v}", file.display());
            assert_eq!(out.status.code(), Some(0));
        }
    }
}

//! Scenario and mission files are strict JSON (issue 16, reproductions 7 to 10): each case runs
//! the real binary on a file in a scratch directory.

mod common;

use common::{assert_success, bin, file};

use std::path::{Path, PathBuf};
use std::process::Output;

fn read(relative: &str) -> String {
    std::fs::read_to_string(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(relative)).unwrap()
}

fn sonar8() -> String {
    read("../scenarios/sonar-8.json")
}

fn fetch_tea() -> String {
    read("../missions/fetch-tea.json")
}

/// `text` with its first `from` replaced by the bytes `to`, written to a scratch file.
fn edited(name: &str, text: &str, from: &str, to: &[u8]) -> PathBuf {
    let at = text
        .find(from)
        .unwrap_or_else(|| panic!("`{from}` not in {name}"));
    let mut bytes = text.as_bytes()[..at].to_vec();
    bytes.extend_from_slice(to);
    bytes.extend_from_slice(&text.as_bytes()[at + from.len()..]);
    let path = file(name, "");
    std::fs::write(&path, bytes).unwrap();
    path
}

fn scenario(path: &Path) -> Output {
    bin()
        .arg("run")
        .arg(path)
        .args(["--arch", "psmpa"])
        .output()
        .unwrap()
}

fn mission(path: &Path) -> Output {
    bin().arg("check").arg(path).output().unwrap()
}

/// Status 2, nothing on stdout, one line on stderr naming the file, free of control characters
/// and panics; the line after the file name.
fn rejected(path: &Path, out: &Output) -> String {
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(out.stdout.is_empty(), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    let line = stderr.trim_end_matches('\n');
    assert!(!line.chars().any(char::is_control), "raw: {line:?}");
    assert!(!line.contains("panicked"), "{line}");
    let prefix = format!("psmpa-sim: {}: ", path.display());
    line.strip_prefix(&prefix)
        .unwrap_or_else(|| panic!("names the file: {line}"))
        .to_owned()
}

/// `line` starts with `field: ` and holds every fragment.
fn names(line: &str, field: &str, fragments: &[&str]) {
    assert!(
        line.starts_with(&format!("{field}: ")),
        "field `{field}`: {line}"
    );
    for f in fragments {
        assert!(line.contains(f), "`{f}` in: {line}");
    }
    assert!(line.contains(" (line "), "position: {line}");
}

const SCENARIO_NAME: &str = r#""name": "sonar-8""#;
const MISSION_NAME: &str = r#""name": "fetch-tea""#;

/// Reproduction 7: a surrogate pair is one character, in a scenario and in a mission.
#[test]
fn a_surrogate_pair_is_read_as_one_character() {
    let pair = br#""name": "robot \ud83d\ude00""#;
    let path = edited("pair.json", &sonar8(), SCENARIO_NAME, pair);
    let out = scenario(&path);
    assert_success(&out);
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert!(stdout.starts_with("scenario robot 😀 under"), "{stdout}");

    let path = edited("pair-mission.json", &fetch_tea(), MISSION_NAME, pair);
    let out = mission(&path);
    assert_success(&out);
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert!(stdout.starts_with("mission robot 😀:"), "{stdout}");

    // Half a pair is no character.
    let lone = br#""name": "robot \ud83d""#;
    let path = edited("lone.json", &sonar8(), SCENARIO_NAME, lone);
    names(&rejected(&path, &scenario(&path)), "name", &["surrogate"]);
    let path = edited("lone-mission.json", &fetch_tea(), MISSION_NAME, lone);
    names(&rejected(&path, &mission(&path)), "name", &["surrogate"]);

    // The 64-byte limit counts UTF-8 bytes: 16 four-byte characters fit, 17 do not.
    let name = |n| format!(r#""name": "{}""#, r"\ud83d\ude00".repeat(n));
    let path = edited(
        "pair-16.json",
        &sonar8(),
        SCENARIO_NAME,
        name(16).as_bytes(),
    );
    assert_success(&scenario(&path));
    let path = edited(
        "pair-17.json",
        &sonar8(),
        SCENARIO_NAME,
        name(17).as_bytes(),
    );
    let line = rejected(&path, &scenario(&path));
    assert!(line.starts_with("name: ") && line.contains("68"), "{line}");
    assert!(line.contains("64 bytes"), "{line}");
}

/// Reproduction 8: a number with a leading `+` is not JSON.
#[test]
fn a_leading_plus_is_rejected_with_its_field() {
    let path = edited(
        "plus.json",
        &sonar8(),
        r#""door_m": 5.3"#,
        br#""door_m": +1"#,
    );
    names(
        &rejected(&path, &scenario(&path)),
        "door_m",
        &["cannot start with \"+\""],
    );
    let path = edited(
        "plus-mission.json",
        &fetch_tea(),
        r#""period_ms": 100"#,
        br#""period_ms": +100"#,
    );
    names(
        &rejected(&path, &mission(&path)),
        "sensors[0].period_ms",
        &["cannot start with \"+\""],
    );
}

/// Reproduction 8: raw control characters in a name are not JSON, and never reach stderr raw.
#[test]
fn raw_control_characters_in_a_name_are_rejected() {
    for (byte, code) in [
        (1u8, "U+0001"),
        (0x1b, "U+001B"),
        (b'\n', "U+000A"),
        (0, "U+0000"),
    ] {
        let to = [b"\"name\": \"a".as_slice(), &[byte], b"b\""].concat();
        let path = edited(&format!("ctl-{byte}.json"), &sonar8(), SCENARIO_NAME, &to);
        let line = rejected(&path, &scenario(&path));
        names(&line, "name", &["control character", code]);
        // Where the character is, even for a newline (serde_json counts it on the next line).
        assert!(line.ends_with("(line 2 column 13)"), "{line}");

        let path = edited(
            &format!("ctl-m-{byte}.json"),
            &fetch_tea(),
            MISSION_NAME,
            &to,
        );
        names(
            &rejected(&path, &mission(&path)),
            "name",
            &["control character", code],
        );
    }
    // Inside a sensor's name, the path names the sensor.
    let path = edited(
        "ctl-sensor.json",
        &fetch_tea(),
        r#""name": "bumper""#,
        b"\"name\": \"bump\x01er\"",
    );
    names(
        &rejected(&path, &mission(&path)),
        "sensors[1].name",
        &["control character", "U+0001"],
    );
}

/// Escaped control characters are JSON: accepted, and shown escaped.
#[test]
fn escaped_control_characters_never_reach_the_terminal_raw() {
    let escaped = br#""name": "a\u001b[31mb""#;
    let path = edited("esc-ok.json", &sonar8(), SCENARIO_NAME, escaped);
    let out = scenario(&path);
    assert_success(&out);
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert!(!stdout.contains('\u{1b}'), "{stdout:?}");
    assert!(
        stdout.starts_with(r"scenario a\u001b[31mb under"),
        "{stdout}"
    );

    let path = edited("esc-ok-mission.json", &fetch_tea(), MISSION_NAME, escaped);
    let out = mission(&path);
    assert_success(&out);
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert!(!stdout.contains('\u{1b}'), "{stdout:?}");
}

/// Reproduction 9: a name that is not UTF-8 says so, not "milliseconds".
#[test]
fn a_name_that_is_not_utf8_says_so() {
    let to = b"\"name\": \"fetch\xFFtea\"";
    let path = edited("ff-mission.json", &fetch_tea(), MISSION_NAME, to);
    let line = rejected(&path, &mission(&path));
    names(&line, "name", &["not valid UTF-8", "0xFF"]);
    assert!(!line.contains("milliseconds"), "{line}");
    let path = edited("ff.json", &sonar8(), SCENARIO_NAME, to);
    names(
        &rejected(&path, &scenario(&path)),
        "name",
        &["not valid UTF-8"],
    );
}

/// Reproduction 10: a key twice is an error at every level, naming the path and the key.
#[test]
fn duplicate_keys_are_rejected_at_every_level() {
    let missions = [
        (
            MISSION_NAME,
            r#""name": "fetch-tea", "name": "other""#,
            "name",
        ),
        (
            r#""mode": "one-shot""#,
            r#""mode": "one-shot", "mode": "cyclic""#,
            "sensors[2].mode",
        ),
        (
            r#""add": ["door_open"]"#,
            r#""add": ["door_open"], "pre": []"#,
            "actions[1].pre",
        ),
        (
            r#""trigger": "fetch_tea""#,
            r#""trigger": "fetch_tea", "trigger": "fetch_tea""#,
            "plans[0].trigger",
        ),
        (
            r#""goal": ["in_kitchen"]"#,
            r#""goal": ["in_kitchen"], "goal": []"#,
            "task.goal",
        ),
    ];
    for (i, (from, to, field)) in missions.iter().enumerate() {
        let path = edited(&format!("dup-m{i}.json"), &fetch_tea(), from, to.as_bytes());
        let key = field.rsplit('.').next().unwrap();
        let key = key.rsplit(']').next().unwrap();
        names(
            &rejected(&path, &mission(&path)),
            field,
            &[&format!("the key \"{key}\" appears twice")],
        );
    }
    let scenarios = [
        (SCENARIO_NAME, r#""name": "a", "name": "b""#, "name"),
        (
            r#""hold_s": 8.0}"#,
            r#""hold_s": 8.0, "kind": "ball"}"#,
            "interferences[3].kind",
        ),
        (
            r#""avoid_s": 1.0"#,
            r#""avoid_s": 1.0, "speed_mps": 0.2"#,
            "robot.speed_mps",
        ),
    ];
    for (i, (from, to, field)) in scenarios.iter().enumerate() {
        let path = edited(&format!("dup-s{i}.json"), &sonar8(), from, to.as_bytes());
        let key = field.rsplit('.').next().unwrap();
        names(
            &rejected(&path, &scenario(&path)),
            field,
            &[&format!("the key \"{key}\" appears twice")],
        );
    }
}

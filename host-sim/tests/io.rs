//! The command line's reading and writing under hostile conditions (issue 16): closed pipes,
//! full disks, devices and FIFOs as inputs, outputs that collide or fail. Each ends in exit
//! status 0 (a closed pipe) or 2 with one line, and leaves no partial file.

mod common;

use common::{assert_refused, assert_success, bin, file, folder, names_in, repo};

use std::io::Read as _;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

fn sonar8() -> PathBuf {
    repo("scenarios/sonar-8.json")
}

/// `psmpa-sim run SCENARIO --arch psmpa`, to add to.
fn psmpa(scenario: impl AsRef<std::ffi::OsStr>) -> Command {
    let mut cmd = bin();
    cmd.arg("run").arg(scenario).args(["--arch", "psmpa"]);
    cmd
}

/// `dir/long.json`: 1 ms sonar and bumper samples for `max_s`, the door out of reach.
fn long_scenario(dir: &Path, max_s: u32) -> PathBuf {
    let path = dir.join("long.json");
    let text = format!(
        r#"{{"name": "long", "door_m": 1000, "max_s": {max_s}, "robot": {{"speed_mps": 0.001}},
            "sonar": {{"period_ms": 1}}, "bumper": {{"period_ms": 1}}, "interferences": []}}"#
    );
    std::fs::write(&path, text).unwrap();
    path
}

/// How long a test waits for what it awaits before it calls it a hang: generous, so that a
/// loaded two-core machine never fails a test that would pass (the commands take well under a
/// second alone); the CPU limits (`ulimit -t`) are what bound a command's own work.
const PATIENCE: Duration = Duration::from_secs(300);

/// Waits for `child` to end (a hang fails the test, saying so, instead of stalling it).
fn finish(mut child: Child) -> Output {
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > PATIENCE {
            let _ = child.kill();
            panic!("the command did not end within {PATIENCE:?}: it hangs");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

/// The commands that print something, each with the arguments to print a lot or a little.
fn printing_commands() -> Vec<Vec<String>> {
    let s = sonar8().display().to_string();
    let m = repo("missions/fetch-tea.json").display().to_string();
    let args = |a: &[&str]| a.iter().map(|x| (*x).to_owned()).collect::<Vec<_>>();
    vec![
        args(&["run", &s, "--arch", "psmpa"]),
        args(&["run", &s, "--arch", "psmpa", "--json"]),
        args(&["table1", "--shifts", "20"]),
        args(&["table1", "--json", "--shifts", "20"]),
        args(&["sweep", "--runs", "4"]),
        args(&["check", &m]),
    ]
}

#[test]
fn a_closed_pipe_ends_the_command_quietly() {
    for args in printing_commands() {
        // The reader goes away before anything is written ...
        let mut child = bin()
            .args(&args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        drop(child.stdout.take());
        let out = finish(child);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(0), "{args:?}: {stderr}");
        assert!(stderr.is_empty(), "{args:?}: {stderr}");
        // ... or after one byte (`| head -c1`).
        let mut child = bin()
            .args(&args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let mut stdout = child.stdout.take().unwrap();
        let mut byte = [0u8];
        stdout.read_exact(&mut byte).unwrap();
        drop(stdout);
        let out = finish(child);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(0), "{args:?}: {stderr}");
        assert!(stderr.is_empty(), "{args:?}: {stderr}");
    }
}

#[test]
fn a_full_standard_output_is_one_line_and_status_2() {
    for args in printing_commands() {
        let full = std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/full")
            .unwrap();
        let out = bin().args(&args).stdout(full).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert_eq!(stderr.lines().count(), 1, "{args:?}: {stderr}");
        assert!(stderr.contains("standard output"), "{stderr}");
        assert!(stderr.contains("No space left"), "{stderr}");
    }
}

#[test]
fn devices_and_folders_are_refused_before_they_are_read() {
    for (input, what) in [
        ("/dev/zero", "a device"),
        ("/dev/urandom", "a device"),
        ("/tmp", "a directory"),
    ] {
        let out = finish(
            bin()
                .args(["run", input, "--arch", "psmpa"])
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap(),
        );
        assert_refused(&out, &[input, what, "scenario"]);
        let out = finish(
            bin()
                .args(["check", input])
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap(),
        );
        assert_refused(&out, &[input, what, "mission"]);
    }
}

#[test]
fn a_file_larger_than_the_limit_is_refused_unread() {
    // Valid JSON up to the limit (leading spaces), so only the size is at fault.
    let mut big = " ".repeat(1 << 20);
    big.push_str(r#"{"name": "x", "interferences": []}"#);
    let path = file("big.json", &big);
    let out = psmpa(&path).output().unwrap();
    assert_refused(&out, &["big.json", "larger than 1 MiB"]);
    let out = bin().arg("check").arg(&path).output().unwrap();
    assert_refused(&out, &["big.json", "larger than 1 MiB", "mission"]);
}

#[test]
fn a_fifo_is_refused_without_waiting_for_a_writer() {
    let dir = folder("fifo");
    let fifo = dir.join("f");
    let made = Command::new("mkfifo").arg(&fifo).status().unwrap();
    assert!(made.success());
    for args in [vec!["run", "f", "--arch", "psmpa"], vec!["check", "f"]] {
        let child = bin()
            .current_dir(&dir)
            .args(&args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        assert_refused(&finish(child), &["f: is a FIFO"]);
    }
}

/// Runs `sonar-8` under P-SMPA with `extra` arguments, in `dir`.
fn run_in(dir: &Path, extra: &[&str]) -> Output {
    psmpa(sonar8())
        .current_dir(dir)
        .args(extra)
        .output()
        .unwrap()
}

#[test]
fn two_outputs_naming_one_file_are_refused_before_the_run() {
    let dir = folder("same");
    let out = run_in(
        dir.as_path(),
        &["--trace", "same.out", "--timeline", "same.out"],
    );
    assert_refused(&out, &["same.out", "--trace", "--timeline"]);
    // Another spelling of the same file, and the plot.
    std::fs::write(dir.join("x"), "keep").unwrap();
    let out = run_in(dir.as_path(), &["--trace", "x", "--plot", "./x"]);
    assert_refused(&out, &["--trace", "--plot"]);
    assert_eq!(std::fs::read_to_string(dir.join("x")).unwrap(), "keep");
    assert_eq!(names_in(&dir), ["x"], "nothing else written");
    // An output over the input.
    let copy = dir.join("s.json");
    std::fs::copy(sonar8(), &copy).unwrap();
    let before = std::fs::read(&copy).unwrap();
    let out = psmpa(&copy).args(["--trace"]).arg(&copy).output().unwrap();
    assert_refused(&out, &["the scenario", "--trace"]);
    assert_eq!(std::fs::read(&copy).unwrap(), before);
    let mission = dir.join("m.json");
    std::fs::copy(repo("missions/fetch-tea.json"), &mission).unwrap();
    let out = bin()
        .arg("check")
        .arg(&mission)
        .arg("--dot")
        .arg(&mission)
        .output()
        .unwrap();
    assert_refused(&out, &["the mission", "--dot"]);
}

#[test]
fn a_failing_output_leaves_every_other_file_as_it_was() {
    let dir = folder("partial");
    std::fs::write(dir.join("left.csv"), "keep").unwrap();
    let out = run_in(&dir, &["--trace", "left.csv", "--plot", "nodir/p.svg"]);
    assert_refused(&out, &["nodir/p.svg", "No such file"]);
    assert_eq!(
        std::fs::read_to_string(dir.join("left.csv")).unwrap(),
        "keep"
    );
    // A device that fills up: the failure, and no report before it.
    let out = run_in(&dir, &["--trace", "left.csv", "--timeline", "/dev/full"]);
    assert_refused(&out, &["/dev/full", "No space left"]);
    assert_eq!(
        std::fs::read_to_string(dir.join("left.csv")).unwrap(),
        "keep"
    );
    assert_eq!(names_in(&dir), ["left.csv"], "no temporary file left");
    // A plot folder that is a file.
    let out = bin()
        .args(["table1", "--plots"])
        .arg(dir.join("left.csv"))
        .output()
        .unwrap();
    assert_refused(&out, &["left.csv", "not a folder"]);
}

/// A report that cannot be printed fails the command, and a failed command writes no file: the
/// run's trace and `check`'s graph are put in place only once standard output took the report.
#[test]
fn a_full_standard_output_leaves_every_file_as_it_was() {
    let dir = folder("fullout");
    std::fs::write(dir.join("t.csv"), "keep").unwrap();
    let full = || {
        std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/full")
            .unwrap()
    };
    let out = psmpa(sonar8())
        .current_dir(&dir)
        .args(["--trace", "t.csv"])
        .stdout(full())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let kept = std::fs::read_to_string(dir.join("t.csv")).unwrap() == "keep";
    assert!(
        kept,
        "t.csv was replaced by the trace of a run whose report failed"
    );
    let out = bin()
        .current_dir(&dir)
        .arg("check")
        .arg(repo("missions/fetch-tea.json"))
        .args(["--dot", "g.dot"])
        .stdout(full())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("wrote"), "{stderr}");
    assert_eq!(names_in(&dir), ["t.csv"], "no graph, no temporary file");
    // With room to print, both are written.
    let out = bin()
        .current_dir(&dir)
        .arg("check")
        .arg(repo("missions/fetch-tea.json"))
        .args(["--dot", "g.dot"])
        .output()
        .unwrap();
    assert_success(&out);
    assert_eq!(names_in(&dir), ["g.dot", "t.csv"]);
}

#[test]
fn outputs_appear_complete_and_a_device_takes_them_in_place() {
    let dir = folder("complete");
    let out = run_in(
        &dir,
        &[
            "--trace",
            "t.csv",
            "--timeline",
            "/dev/null",
            "--plot",
            "/dev/null",
        ],
    );
    assert_success(&out);
    assert_eq!(names_in(&dir), ["t.csv"]);
    let csv = std::fs::read_to_string(dir.join("t.csv")).unwrap();
    // Rows in time order, world and runtime merged.
    let times: Vec<f64> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect();
    assert!(times.windows(2).all(|w| w[0] <= w[1]), "time order");
    assert!(csv.contains(",world,") && csv.contains(",runtime,"));
}

#[test]
fn a_long_run_streams_its_trace() {
    // 120 s of 1 ms samples of two sensors: about 240,000 rows, each written as it happens.
    let dir = folder("long");
    let scenario = long_scenario(&dir, 120);
    let out = psmpa(&scenario)
        .arg("--trace")
        .arg(dir.join("t.csv"))
        .arg("--timeline")
        .arg(dir.join("t.json"))
        .output()
        .unwrap();
    assert_success(&out);
    let csv = std::fs::read_to_string(dir.join("t.csv")).unwrap();
    assert!(
        csv.lines().count() > 200_000,
        "{} rows",
        csv.lines().count()
    );
    let last = csv.lines().last().unwrap();
    assert!(last.starts_with("120.000,"), "the run's end: {last}");
    let doc: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("t.json")).unwrap()).unwrap();
    let events = doc["traceEvents"].as_array().unwrap();
    // The sonar is on from its first state's start to the run's end.
    assert!(events.iter().any(|e| e["name"] == "sonar on"
        && e["ts"].as_u64().unwrap() + e["dur"].as_u64().unwrap() == 120_000_000
        && e["dur"].as_u64().unwrap() > 119_000_000));
    // The plot keeps every sample, so it is refused up front for a run that may be long:
    // within a second of CPU time (the day's run takes more than ten).
    let longer = long_scenario(&folder("longer"), 86400);
    let out = limited(
        "ulimit -t 1",
        &format!(
            "run '{}' --arch psmpa --plot '{}'",
            longer.display(),
            dir.join("p.svg").display()
        ),
    );
    assert_refused(&out, &["--plot", "172800000 sensor samples"]);
}

#[test]
fn an_interference_due_after_the_run_says_so() {
    let short = file(
        "short.json",
        &std::fs::read_to_string(repo("scenarios/sonar-6.json"))
            .unwrap()
            .replace("\"max_s\": 600", "\"max_s\": 0.001"),
    );
    let out = psmpa(&short).output().unwrap();
    assert_success(&out);
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.contains("not put down (the run ended before it was due)"),
        "{text}"
    );
    assert!(!text.contains("reached the door"), "{text}");
    // Due while the robot stands at the door (it arrives at 5 s and opens the door until
    // 7 s): that reason, not the run's end.
    let late = file(
        "late.json",
        r#"{"name": "late", "door_m": 0.5, "interferences": [{"kind": "box", "at_s": 6}]}"#,
    );
    let out = psmpa(&late).output().unwrap();
    assert_success(&out);
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.contains("not put down (due after the robot reached the door)"),
        "{text}"
    );
}

#[test]
fn a_bad_command_line_is_one_line() {
    let s = sonar8().display().to_string();
    for args in [
        vec!["run"],
        vec!["--bogus"],
        vec!["run", &s, "--arch", "foo"],
        vec![],
        vec!["sweep", "--runs", "0"],
        vec!["run", &s, "--arch", "psmpa", "--tarce", "x"],
    ] {
        let out = bin().args(&args).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert_eq!(stderr.lines().count(), 1, "{args:?}: {stderr}");
        assert!(stderr.contains("--help"), "{stderr}");
    }
    // Help still prints in full, on stdout.
    let out = bin().args(["run", "--help"]).output().unwrap();
    assert_success(&out);
    assert!(String::from_utf8_lossy(&out.stdout).contains("--timeline"));
}

#[test]
fn control_characters_never_reach_the_terminal() {
    let odd = file(
        "odd.json",
        r#"{"name": "a\u001b[31mred", "interferences": []}"#,
    );
    let out = psmpa(&odd).output().unwrap();
    assert_success(&out);
    assert!(!out.stdout.contains(&0x1b), "ESC printed raw");
    assert!(String::from_utf8_lossy(&out.stdout).contains("a\\u001b[31mred"));
    let out = bin()
        .args(["run", "no\u{1b}[31mfile", "--arch", "psmpa"])
        .output()
        .unwrap();
    assert_refused(&out, &["no\\u001b[31mfile", "cannot read"]);
}

#[test]
fn a_huge_value_is_shown_short() {
    let path = file(
        "huge.json",
        r#"{"name": "x", "door_m": 1e308, "interferences": []}"#,
    );
    let out = psmpa(&path).output().unwrap();
    assert_refused(&out, &["door_m", "got 1e308"]);
    assert!(
        out.stderr.len() < 200,
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn an_output_on_standard_output_appends_to_its_file() {
    // `--trace /dev/stdout >> log`: written in place and appended, never renamed over `log`;
    // the report goes to stderr, so the log holds the trace alone.
    let dir = folder("stdout");
    let log = dir.join("log.txt");
    std::fs::write(&log, "IMPORTANT\n").unwrap();
    let appended = std::fs::OpenOptions::new().append(true).open(&log).unwrap();
    let out = psmpa(sonar8())
        .args(["--trace", "/dev/stdout"])
        .stdout(appended)
        .output()
        .unwrap();
    assert_success(&out);
    let text = std::fs::read_to_string(&log).unwrap();
    assert!(text.starts_with("IMPORTANT\ntime_s,"), "{}", &text[..40]);
    assert!(
        text.trim_end()
            .lines()
            .last()
            .unwrap()
            .contains(",runtime,")
    );
    assert!(String::from_utf8_lossy(&out.stderr).contains("trace hash"));
    assert_eq!(names_in(&dir), ["log.txt"]);
}

#[test]
fn two_names_of_one_file_by_hard_link_are_refused() {
    let dir = folder("hardlink");
    std::fs::write(dir.join("t.csv"), "keep").unwrap();
    std::fs::hard_link(dir.join("t.csv"), dir.join("h.csv")).unwrap();
    let out = run_in(&dir, &["--trace", "t.csv", "--timeline", "h.csv"]);
    assert_refused(&out, &["--trace", "--timeline"]);
    assert_eq!(std::fs::read_to_string(dir.join("h.csv")).unwrap(), "keep");
}

#[test]
fn an_interrupted_run_leaves_no_temporary_file() {
    let dir = folder("interrupt");
    std::fs::write(dir.join("t.csv"), "keep").unwrap();
    long_scenario(&dir, 86400);
    let child = psmpa("long.json")
        .current_dir(&dir)
        .args(["--trace", "t.csv", "--timeline", "t.json"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until the run is writing its temporary files, then interrupt it as Ctrl-C does.
    let start = Instant::now();
    while !names_in(&dir).iter().any(|n| n.ends_with(".part")) {
        assert!(
            start.elapsed() < PATIENCE,
            "awaited the run's temporary .part files for {PATIENCE:?}: none appeared"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    let sent = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let out = finish(child);
    assert_eq!(out.status.code(), Some(130));
    assert_eq!(names_in(&dir), ["long.json", "t.csv"], "no .part left");
    assert_eq!(std::fs::read_to_string(dir.join("t.csv")).unwrap(), "keep");
}

#[test]
fn each_file_written_is_named_once_on_stderr() {
    let dir = folder("wrote");
    let (trace, plot) = (dir.join("t.csv"), dir.join("p.svg"));
    let out = psmpa(sonar8())
        .arg("--trace")
        .arg(&trace)
        .arg("--plot")
        .arg(&plot)
        .args(["--timeline", "/dev/null"])
        .output()
        .unwrap();
    assert_success(&out);
    let stderr = String::from_utf8_lossy(&out.stderr);
    // The files as given, in the order of the outputs; nothing for a device.
    assert_eq!(
        stderr,
        format!(
            "psmpa-sim: wrote {}\npsmpa-sim: wrote {}\n",
            trace.display(),
            plot.display()
        )
    );
    assert!(trace.is_file() && plot.is_file());
}

/// A run that ends in an error says why in the mission's words, not as a debug dump of ids.
#[test]
fn a_run_that_gives_up_says_why_in_words() {
    let path = file(
        "dead-sonar.json",
        r#"{"name":"dead","fault":{"kind":"silent","at_s":3.0},"interferences":[]}"#,
    );
    let out = psmpa(&path).output().unwrap();
    assert_success(&out);
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert!(
        stdout.contains("; sensors out of service [sonar]"),
        "{stdout}"
    );
    assert!(!stdout.contains("PlanSet"), "{stdout}");
}

#[cfg(unix)]
#[test]
fn an_output_through_a_link_keeps_the_link() {
    use std::os::unix::fs::symlink;
    let dir = folder("links");
    // A link to a file not made yet (a dangling link): written through, as `>` does.
    symlink("made/t.csv", dir.join("t.csv")).unwrap();
    std::fs::create_dir(dir.join("made")).unwrap();
    assert_success(&run_in(&dir, &["--trace", "t.csv"]));
    let link = std::fs::symlink_metadata(dir.join("t.csv")).unwrap();
    assert!(link.file_type().is_symlink(), "the link is kept");
    let text = std::fs::read_to_string(dir.join("made/t.csv")).unwrap();
    assert!(text.starts_with("time_s,"), "{text:.40}");
    // The same file by its link and by its own name.
    let out = run_in(&dir, &["--trace", "t.csv", "--timeline", "made/t.csv"]);
    assert_refused(&out, &["--trace", "--timeline"]);
    // A loop of links: refused, and both links kept.
    symlink("b", dir.join("a")).unwrap();
    symlink("a", dir.join("b")).unwrap();
    let out = run_in(&dir, &["--trace", "a"]);
    assert_refused(&out, &["a: cannot write", "symbolic links"]);
    for name in ["a", "b"] {
        let meta = std::fs::symlink_metadata(dir.join(name)).unwrap();
        assert!(meta.file_type().is_symlink(), "{name} is still a link");
    }
    assert_eq!(names_in(&dir), ["a", "b", "made", "t.csv"]);
}

/// An output sent to standard output (`--record /dev/stdout > r.rec`, or into a pipe) arrives
/// whole: the report goes to stderr. A recording had the report appended to it, and failed its
/// checksum.
#[test]
fn an_output_on_standard_output_takes_it_whole() {
    let dir = folder("stdout-whole");
    let rec = dir.join("r.rec");
    let out = psmpa(sonar8())
        .args(["--record", "/dev/stdout"])
        .stdout(std::fs::File::create(&rec).unwrap())
        .output()
        .unwrap();
    assert_success(&out);
    assert!(String::from_utf8_lossy(&out.stderr).contains("trace hash"));
    let replayed = bin().arg("replay").arg(&rec).output().unwrap();
    assert_success(&replayed);
}

/// `--trace same.csv > same.csv`: the shell has emptied the file for standard output, and the
/// report would be lost in it or break it: refused, exit 2, the file named.
#[test]
fn an_output_that_is_also_standard_output_s_file_is_refused() {
    let dir = folder("stdout-same");
    let log = dir.join("same.csv");
    let out = psmpa(sonar8())
        .current_dir(&dir)
        .args(["--trace", "same.csv"])
        .stdout(std::fs::File::create(&log).unwrap())
        .output()
        .unwrap();
    assert_refused(&out, &["same.csv", "standard output's file too"]);
}

/// With `--json`, standard output is one JSON object: an output into it is refused before the
/// run, whether standard output is a file or a pipe.
#[test]
fn an_output_into_the_json_report_is_refused() {
    let dir = folder("stdout-json");
    for (option, args) in [
        (
            "--record",
            vec![
                "run",
                "--arch",
                "psmpa",
                "--json",
                "--record",
                "/dev/stdout",
            ],
        ),
        (
            "--trace",
            vec!["run", "--arch", "psmpa", "--json", "--trace", "/dev/stdout"],
        ),
    ] {
        let file = std::fs::File::create(dir.join("out")).unwrap();
        let out = bin()
            .args(&args)
            .arg(sonar8())
            .stdout(file)
            .output()
            .unwrap();
        assert_refused(&out, &[option, "--json"]);
        let piped = bin()
            .args(&args)
            .arg(sonar8())
            .stdout(Stdio::piped())
            .output()
            .unwrap();
        assert_refused(&piped, &[option, "--json"]);
    }
}

/// A read-only file is not replaced, as `>` and `cp` refuse to write it: it was, silently.
#[cfg(unix)]
#[test]
fn a_read_only_output_is_refused_and_kept() {
    use std::os::unix::fs::PermissionsExt as _;
    let dir = folder("read-only");
    let path = dir.join("t.csv");
    std::fs::write(&path, "keep").unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o444)).unwrap();
    let out = psmpa(sonar8()).arg("--trace").arg(&path).output().unwrap();
    assert_refused(&out, &["t.csv", "read-only"]);
    assert_eq!(std::fs::read_to_string(&path).unwrap(), "keep");
}

/// An output sent through standard output into a pipe whose reader goes away (`| head`) ends
/// quietly with status 0, as the report does: it was status 2, or 0 or 2 from run to run.
#[test]
fn an_output_into_a_closed_pipe_ends_quietly() {
    // Five seconds of 1 ms samples: the replay's MCAP is larger than a pipe holds too.
    let dir = folder("closed-output");
    let rec = dir.join("r.rec");
    let long = long_scenario(&dir, 5);
    assert_success(&psmpa(&long).arg("--record").arg(&rec).output().unwrap());
    let replay = |o: &str| {
        let mut c = bin();
        c.arg("replay").arg(&rec).args([o, "/dev/stdout"]);
        c
    };
    for (what, mut cmd) in [
        ("--trace", {
            let mut c = psmpa(sonar8());
            c.args(["--trace", "/dev/stdout"]);
            c
        }),
        ("--mcap", {
            let mut c = psmpa(sonar8());
            c.args(["--mcap", "/dev/stdout"]);
            c
        }),
        ("--record", {
            let mut c = psmpa(sonar8());
            c.args(["--record", "/dev/stdout"]);
            c
        }),
        ("replay --mcap", replay("--mcap")),
    ] {
        // More than a pipe holds (64 KiB) is written, so the writer meets the closed end.
        let mut child = cmd
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let mut stdout = child.stdout.take().unwrap();
        let mut head = [0u8; 100];
        stdout.read_exact(&mut head).unwrap();
        drop(stdout);
        let out = finish(child);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(0), "{what}: {stderr}");
        assert!(!stderr.contains("cannot write"), "{what}: {stderr}");
    }
}

/// A regular file named through `/proc` is replaced whole, as any other path to it: it was
/// appended to (two headers), even by a run that then failed.
#[test]
fn a_regular_file_named_through_proc_is_replaced_not_appended() {
    let dir = folder("proc-path");
    std::fs::write(dir.join("t.csv"), "OLD\n").unwrap();
    let out = psmpa(sonar8())
        .current_dir(&dir)
        .args(["--trace", "/proc/self/cwd/t.csv"])
        .output()
        .unwrap();
    assert_success(&out);
    let text = std::fs::read_to_string(dir.join("t.csv")).unwrap();
    assert!(text.starts_with("time_s,"), "{}", &text[..20]);
    assert_eq!(text.matches("time_s,").count(), 1);
    // A failing run leaves it as it was.
    std::fs::write(dir.join("t.csv"), "OLD\n").unwrap();
    let out = psmpa(sonar8())
        .current_dir(&dir)
        .args(["--trace", "/proc/self/cwd/t.csv"])
        .stdout(
            std::fs::OpenOptions::new()
                .write(true)
                .open("/dev/full")
                .unwrap(),
        )
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert_eq!(std::fs::read_to_string(dir.join("t.csv")).unwrap(), "OLD\n");
}

/// A process substitution (`--trace >(wc -c)`, a pipe named `/dev/fd/63`) is written as a pipe;
/// it was refused.
#[test]
fn a_process_substitution_takes_an_output() {
    let dir = folder("procsub");
    let out = Command::new("bash")
        .current_dir(&dir)
        .arg("-c")
        .arg(format!(
            "'{}' run '{}' --arch psmpa --trace >(wc -l > lines) >/dev/null; s=$?; wait; exit $s",
            env!("CARGO_BIN_EXE_psmpa-sim"),
            sonar8().display()
        ))
        .output()
        .unwrap();
    assert_success(&out);
    // The substitution may finish after bash does: wait for its count.
    let lines = (0..100)
        .find_map(|_| {
            let text = std::fs::read_to_string(dir.join("lines")).unwrap_or_default();
            if text.ends_with('\n') {
                return Some(text);
            }
            std::thread::sleep(Duration::from_millis(50));
            None
        })
        .unwrap();
    assert!(lines.trim().parse::<u64>().unwrap() > 100, "{lines}");
}

/// A file replaced keeps its mode, as `>` keeps it: a 0600 trace stayed private; it came out
/// 0644.
#[cfg(unix)]
#[test]
fn a_replaced_file_keeps_its_mode() {
    use std::os::unix::fs::PermissionsExt as _;
    let dir = folder("mode");
    let path = dir.join("t.csv");
    std::fs::write(&path, "x").unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
    assert_success(&psmpa(sonar8()).arg("--trace").arg(&path).output().unwrap());
    let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, 0o600);
}

/// A planner thread the machine will not start (too little address space) is status 3, one
/// line: a resource, not bad input (it was status 2, or an abort).
#[test]
fn a_planner_the_machine_cannot_start_is_status_3() {
    let mission = repo("missions/fetch-tea.json");
    let out = limited("ulimit -v 100000", &format!("plan '{}'", mission.display()));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(3), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(stderr.contains("cannot start the planner"), "{stderr}");
}

/// A day of 1 ms samples whose trace goes to a full device: a warning of the size asked for,
/// then the write error, at once (under a 2 s CPU limit; the whole day took about 12 s).
#[test]
fn a_write_error_stops_the_run_at_once() {
    let dir = folder("full-at-once");
    let day = long_scenario(&dir, 86_400);
    // (The timeline grows with events, not samples: this day's fits in its buffer.)
    for output in ["--trace", "--mcap"] {
        let out = limited(
            "ulimit -t 2",
            &format!("run '{}' --arch psmpa {output} /dev/full", day.display()),
        );
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{output}: {stderr}");
        assert!(
            stderr
                .trim_end()
                .ends_with("/dev/full: cannot write: No space left on device (os error 28)"),
            "{output}: {stderr}"
        );
        assert!(
            stderr.starts_with("psmpa-sim: warning: the outputs may take up to about"),
            "{stderr}"
        );
    }
}

/// A box still standing when the run ends was never "taken away before the robot came near".
#[test]
fn an_interference_that_outlives_the_run_says_so() {
    let held = file(
        "held.json",
        r#"{"name": "held", "door_m": 1000, "max_s": 10,
            "interferences": [{"kind": "box", "at_s": 1, "ahead_m": 900, "hold_s": 60}]}"#,
    );
    let out = psmpa(&held).output().unwrap();
    assert_success(&out);
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.contains("not met (still there when the run ended)"),
        "{text}"
    );
}

/// `table1 --plots`: a folder that cannot be written is refused before the work (under a 2 s
/// CPU limit; 100,000 shifts take minutes), and folders made for a command that then fails are
/// removed (they were left behind).
#[test]
fn table1_plots_are_checked_first_and_leave_no_folders() {
    let out = limited("ulimit -t 2", "table1 --shifts 100000 --plots /proc/self");
    assert_refused(&out, &["/proc/self: cannot write"]);
    let dir = folder("plots-left");
    let out = bin()
        .current_dir(&dir)
        .args(["table1", "--shifts", "1", "--plots", "a/b/c"])
        .stdout(
            std::fs::OpenOptions::new()
                .write(true)
                .open("/dev/full")
                .unwrap(),
        )
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(names_in(&dir).is_empty(), "{:?}", names_in(&dir));
}

/// Messages: a negative number names its option and the range; a megabyte key is quoted
/// short; no program type names; max_s to the millisecond it was given.
#[test]
fn messages_name_options_quote_short_and_hide_internals() {
    for (args, says) in [
        (
            &["sweep", "--seed", "-1"][..],
            "'--seed <SEED>': must not be negative",
        ),
        (
            &["sweep", "--runs", "-3"][..],
            "'--runs <RUNS>': must be a whole number from 1 to",
        ),
        (
            &["plan", "x.json", "--budget", "-5"][..],
            "'--budget <BUDGET>': -5 is not in 1..=",
        ),
        (
            &["sweep", "--seed", "18446744073709551616"][..],
            "must be a whole number from 0 to 18446744073709551615",
        ),
    ] {
        let out = bin().args(args).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(says), "{args:?}: {stderr}");
    }
    let key = "k".repeat(300_000);
    let path = file("long-key.json", &format!(r#"{{"name": "x", "{key}": 1}}"#));
    let out = psmpa(&path).output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr.len() < 1_000, "{} bytes", stderr.len());
    assert!(stderr.contains("...(299937 bytes)..."), "{stderr}");
    let path = file(
        "fault-5.json",
        r#"{"name": "x", "fault": 5, "interferences": []}"#,
    );
    let stderr = String::from_utf8(psmpa(&path).output().unwrap().stderr).unwrap();
    assert!(
        stderr.contains("fault: invalid type: integer `5`, expected an object"),
        "{stderr}"
    );
    let text = std::fs::read_to_string(repo("scenarios/sonar-6.json"))
        .unwrap()
        .replace("\"seed\": 42", "\"seed\": 18446744073709551616");
    let stderr =
        String::from_utf8(psmpa(file("seed.json", &text)).output().unwrap().stderr).unwrap();
    assert!(
        stderr.contains("seed: must be a whole number from 0 to 18446744073709551615"),
        "{stderr}"
    );
    assert!(!stderr.contains("e+19"), "{stderr}");
    let long = file(
        "plot-long.json",
        r#"{"name": "l", "door_m": 1000, "max_s": 500.001, "robot": {"speed_mps": 0.001},
            "sonar": {"period_ms": 1}, "bumper": {"period_ms": 1}, "interferences": []}"#,
    );
    let stderr = String::from_utf8(
        psmpa(&long)
            .args(["--plot", "p.svg"])
            .output()
            .unwrap()
            .stderr,
    )
    .unwrap();
    assert!(stderr.contains("in 500.001 s"), "{stderr}");
}

/// Worker threads the machine will not start (100 of them under 60 MB of address space): one
/// line and status 3 for sweep, table1 and sensitivity; they panicked ("The global thread pool
/// has not been initialized").
#[test]
fn workers_the_machine_cannot_start_are_status_3() {
    for command in [
        "sweep --runs 10",
        "table1 --shifts 1",
        "sensitivity --runs 1",
    ] {
        let out = limited("ulimit -v 60000; export RAYON_NUM_THREADS=100", command);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(3), "{command}: {stderr}");
        assert_eq!(stderr.lines().count(), 1, "{stderr}");
        assert!(
            stderr.contains("cannot start the worker threads"),
            "{stderr}"
        );
    }
}

/// `psmpa-sim ARGS` (a shell word list) run by bash after `limits` (`ulimit -t 2`, ...), cut
/// at 60 s.
fn limited(limits: &str, args: &str) -> Output {
    Command::new("bash")
        .arg("-c")
        .arg(format!(
            "{limits}; exec timeout 60 '{}' {args}",
            env!("CARGO_BIN_EXE_psmpa-sim")
        ))
        .output()
        .unwrap()
}

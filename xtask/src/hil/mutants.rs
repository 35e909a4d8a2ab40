//! `cargo xtask hil --mutants`: the bench must be able to fail. Each mutant is a bug a robot
//! builder could plant, patched into a scratch copy of the sources (`target/mutants/tree`,
//! never the shipped code path), built as the Pico's image, and played on the scenarios that
//! exercise it; a mutant is caught when at least one of its runs fails a check. The scratch
//! copy's target folder starts as a copy of the boards' own, so only the patched crate and
//! what depends on it build again.
//!
//! A patch names its file and the exact text it replaces, which must occur once: a change to
//! that code makes the mutant fail to apply, loudly, instead of passing unplanted.
//!
//! The bench must catch the worst of them on scenarios the project does not ship too:
//! [`UNSHIPPED`] scenarios are generated from seeds ([`unshipped`]), played first on the
//! clean image (where every check must hold: the control), then by the mutants marked
//! `everywhere`, each of whose runs must fail.

use std::path::{Path, PathBuf};
use std::process::Command;

use super::{Budget, Ending, Firmware, Played, play_all, plays};
use crate::firmware;

/// A planted bug.
struct Mutant {
    name: &'static str,
    what: &'static str,
    file: &'static str,
    find: &'static str,
    replace: &'static str,
    /// Scenario or fault files (from the repository's root) that exercise it.
    plays: &'static [&'static str],
    /// Also played on the [`UNSHIPPED`] scenarios, and caught only when every run fails.
    everywhere: bool,
}

/// The static timing analysis's loop annotations: a mutant of this file plants a bound the
/// bench's count of back edges must refute, on the clean image.
const ANNOTATIONS: &str = "boards/pico/wcet-loops.json";

/// Seeds of the generated scenarios the project does not ship.
const UNSHIPPED: [u64; 2] = [11, 29];

/// A scenario the project does not ship, from `seed` (SplitMix64): a walk of 1.6 to 2.5 m at
/// 0.10 to 0.15 m/s, and four obstacles, boxes and balls at random instants and distances in
/// its first ten seconds, each held 1 to 6 s.
pub fn unshipped(seed: u64) -> String {
    let mut state = seed;
    let mut draw = |below: u64| crate::splitmix::next(&mut state) % below;
    let door = 1.6 + draw(10) as f64 / 10.0;
    let speed = 0.10 + draw(6) as f64 / 100.0;
    let mut at = 1.0;
    let mut items = Vec::new();
    for _ in 0..4 {
        at += 0.5 + draw(20) as f64 / 10.0;
        let (kind, ahead) = if draw(2) == 0 {
            ("box", 0.30 + draw(16) as f64 / 100.0)
        } else {
            ("ball", 0.01 + draw(8) as f64 / 100.0)
        };
        let hold = 1.0 + draw(50) as f64 / 10.0;
        items.push(format!(
            r#"{{"kind": "{kind}", "at_s": {at:.1}, "ahead_m": {ahead:.2}, "hold_s": {hold:.1}}}"#
        ));
    }
    format!(
        r#"{{"name": "unshipped-{seed}", "seed": {seed}, "door_m": {door:.1}, "robot": {{"speed_mps": {speed:.2}, "avoid_s": 1.0}}, "interferences": [{}]}}"#,
        items.join(", ")
    )
}

/// The walk's brake when its precondition turns false (`fetch-tea/src/lib.rs`).
const BRAKE: &str = "                } else {
                    // The precondition turned false: brake at once.
                    self.brake()
                };";

/// The panic handler's first lines (`boards/rp/src/lib.rs`).
const PANIC: &str = "    motors_off();
    cortex_m::interrupt::disable();
    static PANICKED: AtomicBool = AtomicBool::new(false);
    if !PANICKED.swap(true, Ordering::Relaxed) {
        error!(\"{}\", defmt::Display2Format(info));
    }";

const MUTANTS: &[Mutant] = &[
    Mutant {
        name: "deaf-sonar",
        what: "the HC-SR04 driver ignores the echo's width: every read is nothing in range",
        file: "drivers/src/hcsr04.rs",
        find: "        range_from_echo_us(width.as_micros())",
        replace: "        let _ = width;\n        Ok(Range::NothingInRange)",
        plays: &["scenarios/sonar-6.json"],
        everywhere: true,
    },
    Mutant {
        name: "no-pull-up",
        what: "the bump switch's input has no pull-up: open, it floats",
        file: "boards/rp/src/lib.rs",
        find: "Switch::new(Input::new(p.PIN_4, Pull::Up)",
        replace: "Switch::new(Input::new(p.PIN_4, Pull::None)",
        plays: &["scenarios/quiet.json", "scenarios/bumper-4.json"],
        everywhere: true,
    },
    Mutant {
        name: "busy-brake",
        what: "the walk computes for 20 ms before it brakes",
        file: "fetch-tea/src/lib.rs",
        find: BRAKE,
        replace: "                } else {
                    embassy_time::block_for(Duration::from_millis(20));
                    self.brake()
                };",
        plays: &["scenarios/sonar-6.json", "scenarios/bumper-4.json"],
        everywhere: true,
    },
    Mutant {
        name: "sleepy-brake",
        what: "the walk sleeps 20 ms before it brakes",
        file: "fetch-tea/src/lib.rs",
        find: BRAKE,
        replace: "                } else {
                    Timer::after(Duration::from_millis(20)).await;
                    self.brake()
                };",
        plays: &["scenarios/sonar-6.json", "scenarios/bumper-4.json"],
        // The bumper's bound holds its period and a debounce time: a sleep of 20 ms fits in
        // it where only the bumper detects; the sonar's bound does not hold it.
        everywhere: false,
    },
    Mutant {
        name: "slow-sonar",
        what: "the sonar samples at twice its period",
        file: "boards/rp/src/lib.rs",
        find: "(fetch_tea::Sensor::Sonar, settings.sonar_period),",
        replace: "(fetch_tea::Sensor::Sonar, settings.sonar_period.map(|p| p * 2)),",
        plays: &["scenarios/sonar-6.json"],
        everywhere: false,
    },
    Mutant {
        name: "unfed-watchdog",
        what: "the watchdog is started and never fed",
        file: "boards/rp/src/lib.rs",
        find: "        watchdog.feed(WATCHDOG_TIMEOUT);",
        replace: "        let _ = &mut watchdog;",
        plays: &["boards/faults/hang.json", "scenarios/quiet.json"],
        everywhere: false,
    },
    Mutant {
        name: "panic-logs-first",
        what: "the panic handler logs before it stops the motors",
        file: "boards/rp/src/lib.rs",
        find: PANIC,
        replace: "    cortex_m::interrupt::disable();
    static PANICKED: AtomicBool = AtomicBool::new(false);
    if !PANICKED.swap(true, Ordering::Relaxed) {
        error!(\"{}\", defmt::Display2Format(info));
    }
    motors_off();",
        plays: &["boards/faults/panic.json"],
        everywhere: false,
    },
    Mutant {
        name: "stray-read",
        what: "the firmware reads an address where nothing is mapped (a bus fault on silicon)",
        file: "boards/rp/src/lib.rs",
        find: "    let p = embassy_rp::init(Default::default());",
        replace: "    let p = embassy_rp::init(Default::default());
    // SAFETY: none: the bug planted.
    let _ = unsafe { core::ptr::read_volatile(0x3000_0000 as *const u32) };",
        plays: &["scenarios/quiet.json"],
        everywhere: false,
    },
    Mutant {
        name: "short-loop-bound",
        what: "a loop annotation of the static timing analysis bounds the ring's copy by a frame (53 bytes), missing the recording's 68-byte prologue",
        file: ANNOTATIONS,
        find: "      \"bound\": 68,\n      \"why\": \"copies one write into the ring",
        replace: "      \"bound\": 53,\n      \"why\": \"copies one write into the ring",
        plays: &["scenarios/quiet.json"],
        everywhere: false,
    },
    Mutant {
        name: "empty-run-queue",
        what: "a loop annotation of the static timing analysis lets the sensing executor poll no task a run, where it has one: a loop whose latch is a call, bounded for one job",
        file: ANNOTATIONS,
        find: "      \"bound\": 1,\n      \"jobs\": [\"sensing_poll\"],\n      \"why\": \"polls each task taken from the run queue once",
        replace: "      \"bound\": 0,\n      \"jobs\": [\"sensing_poll\"],\n      \"why\": \"polls each task taken from the run queue once",
        plays: &["scenarios/quiet.json"],
        everywhere: false,
    },
    Mutant {
        name: "bumper-ignored",
        what: "a pressed bumper still says the path is clear",
        file: "fetch-tea/src/lib.rs",
        find: "Reading::of(Value::Bool(pressed), !pressed)",
        replace: "Reading::of(Value::Bool(pressed), true)",
        plays: &["scenarios/bumper-4.json"],
        everywhere: false,
    },
    Mutant {
        name: "no-planner",
        what: "the board's control loop runs the library's plans only: no plan past a locked door",
        file: "boards/rp/src/lib.rs",
        find: "side.run_planning(&PLANNER, space).await",
        replace: "{ let _ = (&PLANNER, space); side.run().await }",
        plays: &["scenarios/locked-door.json"],
        everywhere: false,
    },
    Mutant {
        name: "no-entry",
        what: "entering the kitchen succeeds without driving: the chip says its goal is reached where its wheels never carried it through",
        file: "fetch-tea/src/lib.rs",
        find: "                let s = &self.settings;
                self.timed(s.enter_permille, s.enter).await",
        replace: "                Outcome::Success",
        plays: &["scenarios/quiet.json"],
        everywhere: true,
    },
    Mutant {
        name: "no-halt",
        what: "the halt after a failure does nothing: the wheels keep the walk's command and the robot drives on blind",
        file: "fetch-tea/src/lib.rs",
        find: "        // Nothing more to do if even braking fails.
        let _ = self.brake();",
        replace: "        // Planted: nothing stops the wheels.",
        plays: &[
            "boards/faults/no-echo.json",
            "boards/faults/echo-stuck-high.json",
        ],
        everywhere: false,
    },
    Mutant {
        name: "too-near-clear",
        what: "the HC-SR04 driver reads an echo too short to time (an obstacle inside 20 mm) as nothing in range",
        file: "drivers/src/hcsr04.rs",
        find: "    if mm < MIN_MM as u64 {
        Err(Hcsr04Error::OutOfRange)",
        replace: "    if mm < MIN_MM as u64 {
        Ok(Range::NothingInRange)",
        plays: &["boards/faults/too-near.json"],
        everywhere: false,
    },
    Mutant {
        name: "slow-bumper",
        what: "the board lengthens the bumper's period by 5 ms when it reads its calibration (25 ms for 20 ms: a fifth fewer samples, each gap within the sampling check's period and debounce)",
        file: "boards/rp/src/calibration.rs",
        find: "    Settings::from_record(&record)
}",
        replace: "    Settings::from_record(&record).map(|mut s| {
        s.bumper_period = s
            .bumper_period
            .map(|p| p + embassy_time::Duration::from_millis(5));
        s
    })
}",
        plays: &["scenarios/bumper-4.json"],
        everywhere: false,
    },
    Mutant {
        name: "coasting-stop",
        what: "the H-bridge's brake lets the motors coast (IN1 and IN2 low) instead of shorting them: the robot rolls on after it stops",
        file: "drivers/src/hbridge.rs",
        find: "    pub fn brake(&mut self) -> Result<(), PinError> {
        self.wake()?;
        self.left.brake()?;
        self.right.brake()
    }",
        replace: "    pub fn brake(&mut self) -> Result<(), PinError> {
        self.wake()?;
        self.coast()
    }",
        plays: &["scenarios/sonar-6.json", "scenarios/bumper-4.json"],
        everywhere: true,
    },
    Mutant {
        name: "same-way-side-step",
        what: "the side step turns back the way it turned away: the robot walks on facing off its way",
        file: "fetch-tea/src/lib.rs",
        find: "[(back, d, turn), (d, d, pass), (d, back, turn)]",
        replace: "[(back, d, turn), (d, d, pass), (back, d, turn)]",
        plays: &["scenarios/sonar-6.json", "scenarios/bumper-4.json"],
        everywhere: true,
    },
    Mutant {
        name: "floating-marker",
        what: "the marker sensor's input has no pull-up: its open-drain output, open where no marker is in view, floats",
        file: "boards/rp/src/lib.rs",
        find: "Marker::new(Input::new(p.PIN_5, Pull::Up)",
        replace: "Marker::new(Input::new(p.PIN_5, Pull::None)",
        plays: &["boards/faults/marker-gone.json"],
        everywhere: false,
    },
    Mutant {
        name: "time-bomb",
        what: "a guard against a clock running backwards, kept in 16-bit milliseconds: from 65.536 s of uptime every sonar read is skipped",
        file: "fetch-tea/src/lib.rs",
        find: "            Sonar => {
                let read = self.sonar.lock().await.measure().await;",
        replace: "            Sonar => {
                use core::sync::atomic::{AtomicU16, Ordering::Relaxed};
                static LAST_MS: AtomicU16 = AtomicU16::new(0);
                let now_ms = Instant::now().as_millis() as u16;
                if now_ms < LAST_MS.load(Relaxed) {
                    return Ok(None);
                }
                LAST_MS.store(now_ms, Relaxed);
                let read = self.sonar.lock().await.measure().await;",
        plays: &["boards/soak/long-hall.json"],
        everywhere: false,
    },
    Mutant {
        name: "stale-vtor",
        what: "the boot's copy into SRAM leaves VTOR at the boot vectors in flash: each interrupt takes a word of the copied image for its handler",
        file: "boards/pico/src/main.rs",
        find: "    \"    str r1, [r0]\",\n",
        replace: "",
        plays: &["scenarios/sonar-6.json"],
        everywhere: false,
    },
];

/// What became of one mutant.
#[derive(serde::Serialize)]
struct Verdict {
    mutant: &'static str,
    what: &'static str,
    /// The check that caught it (`None`: it passed the bench, or some run of one that must
    /// fail everywhere did not fail).
    caught_by: Option<String>,
    /// The first run that failed, and its first failure.
    run: Option<String>,
    failure: Option<String>,
    /// Runs that failed, of those played.
    failed: usize,
    played: usize,
}

/// Copies the repository's files (tracked, and new ones not ignored) to `tree`.
pub(crate) fn copy_tree(root: &Path, tree: &Path) -> Result<(), String> {
    let out = Command::new("git")
        .args(["ls-files", "-co", "--exclude-standard", "-z"])
        .current_dir(root)
        .output()
        .map_err(|e| format!("cannot run git: {e}"))?;
    if !out.status.success() {
        return Err("git ls-files failed: the mutants copy the repository's files".to_owned());
    }
    for name in out.stdout.split(|b| *b == 0).filter(|n| !n.is_empty()) {
        let name = String::from_utf8_lossy(name);
        let (from, to) = (root.join(&*name), tree.join(&*name));
        let Ok(meta) = std::fs::symlink_metadata(&from) else {
            continue; // deleted in the work tree
        };
        if let Some(dir) = to.parent() {
            std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        }
        let _ = std::fs::remove_file(&to);
        if meta.file_type().is_symlink() {
            let link = std::fs::read_link(&from).map_err(|e| format!("{}: {e}", from.display()))?;
            std::os::unix::fs::symlink(link, &to).map_err(|e| format!("{}: {e}", to.display()))?;
        } else {
            std::fs::copy(&from, &to).map_err(|e| format!("{}: {e}", to.display()))?;
        }
    }
    Ok(())
}

/// Copies the boards' target folder to `to` once, so that the scratch builds start warm.
pub(crate) fn warm_target(from: &Path, to: &Path) -> Result<(), String> {
    if to.exists() || !from.exists() {
        return Ok(());
    }
    let status = Command::new("cp")
        .arg("-r")
        .arg(from)
        .arg(to)
        .status()
        .map_err(|e| format!("cannot run cp: {e}"))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!(
            "cannot copy {} to {}",
            from.display(),
            to.display()
        ))
    }
}

/// Builds the Pico's image in `tree` into `target`.
fn build(tree: &Path, target: &Path) -> Result<PathBuf, String> {
    let status = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_owned()))
        .args(["build", "--quiet", "--release"])
        .current_dir(tree.join("boards/pico"))
        .env("CARGO_TARGET_DIR", target)
        .env_remove("RUSTFLAGS")
        .env_remove("CARGO_ENCODED_RUSTFLAGS")
        .status()
        .map_err(|e| format!("cannot run cargo: {e}"))?;
    if !status.success() {
        return Err("the mutant does not build".to_owned());
    }
    Ok(target.join("thumbv6m-none-eabi/release/psmpa-pico"))
}

/// `file` (read from `root`) with `find`, which must occur in it once, replaced by `replace`;
/// why not, naming mutant `name`, when the code changed.
pub(crate) fn patched(
    name: &str,
    root: &Path,
    file: &str,
    find: &str,
    replace: &str,
) -> Result<String, String> {
    let original = std::fs::read_to_string(root.join(file)).map_err(|e| format!("{file}: {e}"))?;
    let found = original.matches(find).count();
    if found != 1 {
        return Err(format!(
            "mutant {name}: {file} holds its text {found} times, not once: the code changed, update the mutant"
        ));
    }
    Ok(original.replacen(find, replace, 1))
}

/// Writes [`patched`] `file` into `tree`.
pub(crate) fn plant_in(
    name: &str,
    root: &Path,
    tree: &Path,
    file: &str,
    find: &str,
    replace: &str,
) -> Result<(), String> {
    let text = patched(name, root, file, find, replace)?;
    std::fs::write(tree.join(file), text).map_err(|e| format!("{file}: {e}"))
}

/// Restores `file` in `tree` from `root`.
pub(crate) fn restore(root: &Path, tree: &Path, file: &str) -> Result<(), String> {
    std::fs::copy(root.join(file), tree.join(file))
        .map(|_| ())
        .map_err(|e| format!("{file}: {e}"))
}

/// The verdict of one mutant's runs: caught when one failed, or, for one that must fail
/// everywhere, when every one did.
fn verdict(m: &'static Mutant, played: &[Played], names: &[String]) -> Verdict {
    let failures: Vec<Option<String>> = played
        .iter()
        .map(|result| match result {
            Ok((report, _)) => report.failures.first().cloned(),
            Err(e) => Some(format!("run: {e}")),
        })
        .collect();
    let failed = failures.iter().filter(|f| f.is_some()).count();
    let first = failures
        .iter()
        .zip(names)
        .find_map(|(f, name)| f.clone().map(|f| (f, name.clone())));
    let caught = if m.everywhere {
        failed == played.len()
    } else {
        failed > 0
    };
    Verdict {
        mutant: m.name,
        what: m.what,
        caught_by: first
            .as_ref()
            .filter(|_| caught)
            .map(|(f, _)| f.split_once(':').map_or("run", |(c, _)| c).to_owned()),
        run: first.as_ref().map(|(_, n)| n.clone()),
        failure: first.map(|(f, _)| f),
        failed,
        played: played.len(),
    }
}

/// Writes the [`UNSHIPPED`] scenarios into `dir`; their files.
fn write_unshipped(dir: &Path) -> Result<Vec<PathBuf>, String> {
    UNSHIPPED
        .iter()
        .map(|&seed| {
            let path = dir.join(format!("unshipped-{seed}.json"));
            std::fs::write(&path, unshipped(seed))
                .map(|()| path.clone())
                .map_err(|e| format!("{}: {e}", path.display()))
        })
        .collect()
}

/// The control: the clean image plays the [`UNSHIPPED`] scenarios, and every check holds.
/// The clean image, its annotated loops counted on every run.
fn clean(annotations: &crate::wcet::Annotations) -> Result<Firmware, String> {
    let fw = super::build().and_then(|elf| Firmware::read(&elf))?;
    Ok(fw.watching(crate::wcet::bench_watch_with(annotations)?))
}

/// The clean image with `m`, a mutant of the annotations, planted in them.
fn with_annotations(m: &Mutant, root: &Path) -> Result<Firmware, String> {
    let text = patched(m.name, root, m.file, m.find, m.replace)?;
    clean(&crate::wcet::Annotations::parse(&text)?)
}

fn control(files: &[PathBuf], budget: &Budget, out: &Path) -> Result<(), String> {
    let fw = clean(&crate::wcet::Annotations::parse(
        &std::fs::read_to_string(firmware::root().join(ANNOTATIONS))
            .map_err(|e| format!("{ANNOTATIONS}: {e}"))?,
    )?)?;
    let (list, _) = plays(files)?;
    let recordings = out.join("recordings");
    for (p, result) in list
        .iter()
        .zip(play_all(&fw, &list, budget, out, &recordings))
    {
        let failures = match result {
            Ok((report, _)) => report.failures,
            Err(e) => vec![e],
        };
        if let Some(f) = failures.first() {
            return Err(format!(
                "the control: the clean image fails {} ({f}): a mutant failing it proves nothing",
                p.name()
            ));
        }
    }
    Ok(())
}

/// `cargo xtask hil --mutants`.
pub fn run(json: bool) -> Ending {
    if let Err(e) = super::harness::check_tools() {
        return Ending::Failed(e);
    }
    let budget = match Budget::load() {
        Ok(b) => b,
        Err(e) => return Ending::Failed(e),
    };
    let root = firmware::root();
    let scratch = root.join("target/mutants");
    let (tree, target) = (scratch.join("tree"), scratch.join("target"));
    let out = scratch.join("runs");
    let prepared = std::fs::create_dir_all(&out)
        .map_err(|e| format!("{}: {e}", out.display()))
        .and_then(|()| copy_tree(&root, &tree))
        .and_then(|()| warm_target(&root.join("boards/target"), &target));
    if let Err(e) = prepared {
        return Ending::Failed(e);
    }
    eprintln!(
        "xtask hil --mutants: the control, the clean image on scenarios the project does not ship"
    );
    let unshipped = match write_unshipped(&scratch).and_then(|files| {
        control(&files, &budget, &out)?;
        Ok(files)
    }) {
        Ok(files) => files,
        Err(e) => return Ending::Failed(e),
    };
    let mut verdicts = Vec::new();
    for m in MUTANTS {
        eprintln!("xtask hil --mutants: {} ({})", m.name, m.what);
        let mut files: Vec<PathBuf> = m.plays.iter().map(|p| root.join(p)).collect();
        if m.everywhere {
            files.extend(unshipped.iter().cloned());
        }
        let (built, restored) = if m.file == ANNOTATIONS {
            (with_annotations(m, &root), Ok(()))
        } else {
            let built = plant_in(m.name, &root, &tree, m.file, m.find, m.replace)
                .and_then(|()| build(&tree, &target))
                .and_then(|elf| Firmware::read(&elf));
            (built, restore(&root, &tree, m.file))
        };
        let fw = match (built, restored) {
            (Ok(fw), Ok(())) => fw,
            (Err(e), _) | (_, Err(e)) => return Ending::Failed(format!("mutant {}: {e}", m.name)),
        };
        let (mut list, _) = match plays(&files) {
            Ok(p) => p,
            Err(e) => return Ending::Failed(e),
        };
        for p in &mut list {
            p.stop_at_failure = true;
        }
        let played = play_all(&fw, &list, &budget, &out, &out.join("recordings"));
        let names: Vec<String> = list.iter().map(super::Play::name).collect();
        let v = verdict(m, &played, &names);
        if json {
            println!("{}", serde_json::to_string(&v).unwrap_or_default());
        }
        verdicts.push(v);
    }
    let caught = verdicts.iter().filter(|v| v.caught_by.is_some()).count();
    let mut table = String::from(
        "\n| planted bug | mutant | caught by | runs failed | first failing run | its first failure |\n|---|---|---|---|---|---|\n",
    );
    for v in &verdicts {
        table.push_str(&format!(
            "| {} | `{}` | {} | {} of {} | {} | {} |\n",
            v.what,
            v.mutant,
            v.caught_by.as_deref().unwrap_or("**not caught**"),
            v.failed,
            v.played,
            v.run.as_deref().unwrap_or("-"),
            v.failure.as_deref().unwrap_or("every run held its checks")
        ));
    }
    if !json {
        print!("{table}");
    }
    let cell = format!("{caught} of {} planted bugs caught", verdicts.len());
    if let Err(e) = crate::pages::write_pages(&[
        (
            root.join("boards/README.md"),
            "bench-mutants",
            table.clone(),
        ),
        (root.join("README.md"), "mutants", cell),
    ]) {
        return Ending::Failed(e);
    }
    let missed: Vec<&str> = verdicts
        .iter()
        .filter(|v| v.caught_by.is_none())
        .map(|v| v.mutant)
        .collect();
    if missed.is_empty() {
        if !json {
            println!(
                "\nevery one of {} planted bugs failed the bench",
                verdicts.len()
            );
        }
        Ending::Passed
    } else {
        Ending::Failed(format!(
            "planted bugs the bench did not catch: {}",
            missed.join(", ")
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unshipped_scenario_is_valid_and_the_same_for_its_seed() {
        for seed in UNSHIPPED {
            let text = unshipped(seed);
            assert_eq!(text, unshipped(seed));
            let sc = psmpa_sim::load::parse(Path::new("u.json"), text.as_bytes()).unwrap();
            assert_eq!(sc.interferences.len(), 4);
        }
        assert_ne!(unshipped(1), unshipped(2));
    }

    #[test]
    fn every_mutant_names_one_place_in_the_code() {
        let root = firmware::root();
        for m in MUTANTS {
            let code = std::fs::read_to_string(root.join(m.file)).unwrap();
            assert_eq!(code.matches(m.find).count(), 1, "{}", m.name);
            assert!(!m.plays.is_empty(), "{}", m.name);
        }
    }
}

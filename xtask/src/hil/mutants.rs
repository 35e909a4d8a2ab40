//! `cargo xtask hil --mutants`: the bench must be able to fail. Each mutant is a bug a robot
//! builder could plant, patched into a scratch copy of the sources (`target/mutants/tree`,
//! never the shipped code path), built as the Pico's image, and played on the scenarios that
//! exercise it; a mutant is caught when at least one of its runs fails a check. The scratch
//! copy's target folder starts as a copy of the boards' own, so only the patched crate and
//! what depends on it build again.
//!
//! A patch names its file and the exact text it replaces, which must occur once: a change to
//! that code makes the mutant fail to apply, loudly, instead of passing unplanted.

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
}

/// The walk's brake when its precondition turns false (`drivers/src/robot.rs`).
const BRAKE: &str = "                } else {
                    // The precondition turned false: brake at once.
                    self.wheels(Drive::brake)
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
    },
    Mutant {
        name: "no-pull-up",
        what: "the bump switch's input has no pull-up: open, it floats",
        file: "boards/rp/src/lib.rs",
        find: "Switch::new(Input::new(p.PIN_4, Pull::Up)",
        replace: "Switch::new(Input::new(p.PIN_4, Pull::None)",
        plays: &["scenarios/quiet.json", "scenarios/bumper-4.json"],
    },
    Mutant {
        name: "busy-brake",
        what: "the walk computes for 20 ms before it brakes",
        file: "drivers/src/robot.rs",
        find: BRAKE,
        replace: "                } else {
                    embassy_time::block_for(Duration::from_millis(20));
                    self.wheels(Drive::brake)
                };",
        plays: &["scenarios/sonar-6.json", "scenarios/bumper-4.json"],
    },
    Mutant {
        name: "sleepy-brake",
        what: "the walk sleeps 20 ms before it brakes",
        file: "drivers/src/robot.rs",
        find: BRAKE,
        replace: "                } else {
                    Timer::after(Duration::from_millis(20)).await;
                    self.wheels(Drive::brake)
                };",
        plays: &["scenarios/sonar-6.json", "scenarios/bumper-4.json"],
    },
    Mutant {
        name: "slow-sonar",
        what: "the sonar samples at twice its period",
        file: "boards/rp/src/lib.rs",
        find: "(fetch_tea::Sensor::Sonar, settings.sonar_period),",
        replace: "(fetch_tea::Sensor::Sonar, settings.sonar_period.map(|p| p * 2)),",
        plays: &["scenarios/sonar-6.json"],
    },
    Mutant {
        name: "unfed-watchdog",
        what: "the watchdog is started and never fed",
        file: "boards/rp/src/lib.rs",
        find: "        watchdog.feed(WATCHDOG_TIMEOUT);",
        replace: "        let _ = &mut watchdog;",
        plays: &["boards/faults/hang.json", "scenarios/quiet.json"],
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
    },
    Mutant {
        name: "bumper-ignored",
        what: "a pressed bumper still says the path is clear",
        file: "drivers/src/robot.rs",
        find: "Reading::of(Value::Bool(pressed), !pressed)",
        replace: "Reading::of(Value::Bool(pressed), true)",
        plays: &["scenarios/bumper-4.json"],
    },
];

/// What became of one mutant.
#[derive(serde::Serialize)]
struct Verdict {
    mutant: &'static str,
    what: &'static str,
    /// The check that caught it (`None`: it passed the bench).
    caught_by: Option<String>,
    /// The run that failed, and its first failure.
    run: Option<String>,
    failure: Option<String>,
}

/// Copies the repository's files (tracked, and new ones not ignored) to `tree`.
fn copy_tree(root: &Path, tree: &Path) -> Result<(), String> {
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
fn warm_target(from: &Path, to: &Path) -> Result<(), String> {
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

/// Plants `m` in `tree` (its file restored from `root` first); why not, if it cannot be.
fn plant(m: &Mutant, root: &Path, tree: &Path) -> Result<(), String> {
    let original =
        std::fs::read_to_string(root.join(m.file)).map_err(|e| format!("{}: {e}", m.file))?;
    let found = original.matches(m.find).count();
    if found != 1 {
        return Err(format!(
            "mutant {}: {} holds its text {found} times, not once: the code changed, update the mutant",
            m.name, m.file
        ));
    }
    std::fs::write(tree.join(m.file), original.replacen(m.find, m.replace, 1))
        .map_err(|e| format!("{}: {e}", m.file))
}

/// Restores `m`'s file in `tree`.
fn unplant(m: &Mutant, root: &Path, tree: &Path) -> Result<(), String> {
    std::fs::copy(root.join(m.file), tree.join(m.file))
        .map(|_| ())
        .map_err(|e| format!("{}: {e}", m.file))
}

/// The verdict of one mutant's runs.
fn verdict(m: &'static Mutant, played: &[Played], names: &[String]) -> Verdict {
    let mut v = Verdict {
        mutant: m.name,
        what: m.what,
        caught_by: None,
        run: None,
        failure: None,
    };
    for (result, name) in played.iter().zip(names) {
        let failure = match result {
            Ok((report, _)) => report.failures.first().cloned(),
            Err(e) => Some(format!("run: {e}")),
        };
        if let Some(f) = failure {
            v.caught_by = Some(f.split_once(':').map_or("run", |(c, _)| c).to_owned());
            v.run = Some(name.clone());
            v.failure = Some(f);
            break;
        }
    }
    v
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
    let mut verdicts = Vec::new();
    for m in MUTANTS {
        eprintln!("xtask hil --mutants: {} ({})", m.name, m.what);
        let files: Vec<PathBuf> = m.plays.iter().map(|p| root.join(p)).collect();
        let built = plant(m, &root, &tree)
            .and_then(|()| build(&tree, &target))
            .and_then(|elf| Firmware::read(&elf));
        let restored = unplant(m, &root, &tree);
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
        let played = play_all(&fw, &list, &budget, &out);
        let names: Vec<String> = list.iter().map(super::Play::name).collect();
        let v = verdict(m, &played, &names);
        if json {
            println!("{}", serde_json::to_string(&v).unwrap_or_default());
        }
        verdicts.push(v);
    }
    if !json {
        println!("\n| mutant | planted bug | caught by | run | its first failure |");
        println!("|---|---|---|---|---|");
        for v in &verdicts {
            println!(
                "| {} | {} | {} | {} | {} |",
                v.mutant,
                v.what,
                v.caught_by.as_deref().unwrap_or("NOT CAUGHT"),
                v.run.as_deref().unwrap_or("-"),
                v.failure.as_deref().unwrap_or("every run held its checks")
            );
        }
    }
    let caught = verdicts.iter().filter(|v| v.caught_by.is_some()).count();
    let mut table = String::from(
        "\n| planted bug | mutant | caught by | run | its first failure |\n|---|---|---|---|---|\n",
    );
    for v in &verdicts {
        table.push_str(&format!(
            "| {} | `{}` | {} | {} | {} |\n",
            v.what,
            v.mutant,
            v.caught_by.as_deref().unwrap_or("**not caught**"),
            v.run.as_deref().unwrap_or("-"),
            v.failure.as_deref().unwrap_or("every run held its checks")
        ));
    }
    let cell = format!("{caught} of {} planted bugs caught", verdicts.len());
    for (file, name, text) in [
        ("boards/README.md", "bench-mutants", table.as_str()),
        ("README.md", "mutants", cell.as_str()),
    ] {
        if let Err(e) = super::write_between(&root.join(file), name, text) {
            return Ending::Failed(e);
        }
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

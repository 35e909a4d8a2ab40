//! Firmware size against the budget and the committed snapshot (RTIC style).

use std::path::Path;

use object::{Object, ObjectSection};
use serde::{Deserialize, Serialize};

use crate::firmware;

/// The limits the firmware must hold (issue: a small real part's share for the mission).
const FLASH_BUDGET: u64 = 64 * 1024;
const RAM_BUDGET: u64 = 16 * 1024;
/// Growth over the snapshot that fails the check.
const GROWTH_PERCENT: u64 = 2;

/// What `firmware/size.json` holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Sizes {
    /// `.vector_table + .text + .rodata`, bytes.
    pub flash: u64,
    /// `.data + .bss`, bytes.
    pub static_ram: u64,
    /// Stack high-water mark measured in QEMU, bytes.
    pub stack: u64,
}

fn sections(elf: &Path) -> Result<(u64, u64), String> {
    let data = std::fs::read(elf).map_err(|e| format!("{}: {e}", elf.display()))?;
    let file = object::File::parse(&*data).map_err(|e| format!("{}: {e}", elf.display()))?;
    let size = |names: &[&str]| -> u64 {
        file.sections()
            .filter(|s| s.name().is_ok_and(|n| names.contains(&n)))
            .map(|s| s.size())
            .sum()
    };
    Ok((
        size(&[".vector_table", ".text", ".rodata"]),
        size(&[".data", ".bss"]),
    ))
}

/// Measures, compares, and with `bless` writes the snapshot.
pub fn run(bless: bool) -> Result<(), String> {
    let elf = firmware::build(&[])?;
    let (flash, static_ram) = sections(&elf)?;
    let log = firmware::run(&elf)?;
    let stack = firmware::stack_high_water(&log)
        .ok_or("the firmware did not report its stack high-water mark")?;
    let now = Sizes {
        flash,
        static_ram,
        stack,
    };
    let path = firmware::root().join("firmware/size.json");
    let snapshot: Option<Sizes> = std::fs::read(&path)
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok());

    let row = |name: &str, value: u64, old: Option<u64>, budget: &str| {
        let delta = old.map_or(String::new(), |o| format!("{:+}", value as i64 - o as i64));
        println!("{name:<28} {value:>8} B  {delta:>8}  {budget}");
    };
    println!("{:<28} {:>10}  {:>8}  budget", "", "measured", "vs snap");
    row(
        "flash (.vector_table+.text+.rodata)",
        flash,
        snapshot.map(|s| s.flash),
        "64 KiB",
    );
    row(
        "static RAM (.data+.bss)",
        static_ram,
        snapshot.map(|s| s.static_ram),
        "",
    );
    row(
        "stack high-water (QEMU)",
        stack,
        snapshot.map(|s| s.stack),
        "",
    );
    row(
        "static RAM + stack",
        static_ram + stack,
        snapshot.map(|s| s.static_ram + s.stack),
        "16 KiB",
    );

    if bless {
        let text = serde_json::to_string_pretty(&now).map_err(|e| e.to_string())? + "\n";
        std::fs::write(&path, text).map_err(|e| format!("{}: {e}", path.display()))?;
        println!("wrote {}", path.display());
    }
    let mut failures = Vec::new();
    if flash > FLASH_BUDGET {
        failures.push(format!(
            "flash {flash} B is over the budget of {FLASH_BUDGET} B"
        ));
    }
    if static_ram + stack > RAM_BUDGET {
        failures.push(format!(
            "static RAM + stack {} B is over the budget of {RAM_BUDGET} B",
            static_ram + stack
        ));
    }
    match snapshot {
        Some(old) if !bless => {
            for (name, new, old) in [
                ("flash", flash, old.flash),
                ("static RAM", static_ram, old.static_ram),
                ("stack", stack, old.stack),
            ] {
                if new * 100 > old * (100 + GROWTH_PERCENT) {
                    failures.push(format!("{name} grew from {old} B to {new} B (more than {GROWTH_PERCENT} %); if intended, run cargo xtask size --bless"));
                }
            }
        }
        None if !bless => failures.push(format!(
            "no snapshot at {}: run cargo xtask size --bless",
            path.display()
        )),
        _ => {}
    }
    if failures.is_empty() {
        Ok(())
    } else {
        Err(failures.join("\n"))
    }
}

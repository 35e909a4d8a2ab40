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

/// Flash bytes by crate, from the size of every function and constant symbol in the flash
/// sections, named by the first path segment of its demangled name (for `<T as Trait>::f`, the
/// crate of `T`). Code inlined into another function counts for that function's crate, so the
/// core's control loop, inlined into the executor's poll of the mission task, counts partly
/// for `embassy_executor`. Bytes in no symbol (padding, the vector table) are `(other)`.
fn flash_by_crate(elf: &Path, flash: u64) -> Result<Vec<(String, u64)>, String> {
    use object::{ObjectSymbol, SectionIndex};
    let data = std::fs::read(elf).map_err(|e| format!("{}: {e}", elf.display()))?;
    let file = object::File::parse(&*data).map_err(|e| format!("{}: {e}", elf.display()))?;
    let flash_sections: Vec<SectionIndex> = file
        .sections()
        .filter(|s| {
            s.name()
                .is_ok_and(|n| [".vector_table", ".text", ".rodata"].contains(&n))
        })
        .map(|s| s.index())
        .collect();
    let mut by_crate = std::collections::BTreeMap::<String, u64>::new();
    for sym in file.symbols() {
        let in_flash = sym
            .section_index()
            .is_some_and(|i| flash_sections.contains(&i));
        if !in_flash || sym.size() == 0 {
            continue;
        }
        let name = rustc_demangle::demangle(sym.name().unwrap_or("")).to_string();
        *by_crate.entry(crate_of(&name)).or_default() += sym.size();
    }
    let named: u64 = by_crate.values().sum();
    *by_crate
        .entry("(in no symbol: vector table, literals, padding)".into())
        .or_default() += flash.saturating_sub(named);
    let mut rows: Vec<(String, u64)> = by_crate.into_iter().collect();
    rows.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
    Ok(rows)
}

/// The crate a demangled symbol belongs to: the first segment of its path, for `<T as
/// Trait>::f` the crate of `T`, or of `Trait` when `T` is a primitive (`[char]`). The `[hash]`
/// v0 mangling adds is dropped. Compiler-made constants (`.Lanon...`) and C names are
/// `(unnamed)`.
fn crate_of(name: &str) -> String {
    let first_segment = |path: &str| -> Option<String> {
        let path = path.trim_start_matches(['<', '&', '[', '*']);
        let path = path
            .trim_start_matches("mut ")
            .trim_start_matches("const ")
            .trim_start_matches("dyn ");
        let (krate, _) = path.split_once("::")?;
        let krate = krate.split('[').next().unwrap_or(krate);
        let ident =
            !krate.is_empty() && krate.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
        ident.then(|| krate.to_string())
    };
    first_segment(name)
        .or_else(|| name.split_once(" as ").and_then(|(_, t)| first_segment(t)))
        .unwrap_or_else(|| "(unnamed)".into())
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

    println!();
    println!("flash by crate (by symbol name; inlined code counts where it was inlined):");
    for (krate, bytes) in flash_by_crate(&elf, flash)? {
        println!("  {krate:<48} {bytes:>6} B");
    }

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

#[cfg(test)]
mod tests {
    use super::crate_of;

    #[test]
    fn symbols_are_attributed_to_the_crate_of_their_path() {
        assert_eq!(crate_of("psmpa_core::exec::run"), "psmpa_core");
        assert_eq!(
            crate_of("<&mut serde_json_core::de::Deserializer as serde::de::Deserializer>::f"),
            "serde_json_core"
        );
        assert_eq!(
            crate_of("<psmpa_core::store::DataStore<K> as Foo>::bar"),
            "psmpa_core"
        );
        assert_eq!(crate_of("core[5585419f9effd512]::fmt::write"), "core");
        assert_eq!(
            crate_of("<[char] as core::str::pattern::Pattern>::f"),
            "core"
        );
        assert_eq!(crate_of(".Lanon.88b94e.185"), "(unnamed)");
        assert_eq!(crate_of("SysTick"), "(unnamed)");
    }
}

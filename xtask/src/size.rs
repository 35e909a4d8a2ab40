//! Flash and RAM of the two QEMU firmware images and the Pico 2 board's image against their
//! budgets and the committed snapshot (RTIC style).
//!
//! * Flash is what is written to the chip: `.vector_table + .text + .rodata + .data` (the
//!   initial values of `.data` are flashed and copied at boot), and the board's boot block.
//! * RAM is `.data + .bss + .uninit` and, for the QEMU images, the stack's high-water mark
//!   measured in QEMU (the board's stack: `cargo xtask stack`).

use std::path::Path;

use object::{Object, ObjectSection};
use serde::{Deserialize, Serialize};

use crate::firmware::{self, Board, PICO, PICO2};

/// What an image may take, bytes.
struct Budget {
    flash: u64,
    ram_with_stack: u64,
}

/// The simulator-carrying firmware, a QEMU harness (its board has 4 MiB): a small real part's
/// share for the mission and the simulated world. 64 KiB until the 0.2 API rework: per-action
/// tolerances, negative contexts and the one-lock sensing side took 0.8 KB, the world's event
/// index (which halves a host simulation's instructions) 1 KB. RAM and stack 20 KiB since
/// the image records every run: the flight recorder's queue (64 frames, 1.5 KB), its send
/// buffer (256 B) and its encoding's stack. 80 KiB since it runs the boards' Fetch Tea robot
/// on simulated devices: the robot (5.9 KB), its compiled mission's runtime (core +6.9 KB, a
/// sampler per sensor) and the devices (+3.4 KB), less the run-time loader (serde-json-core
/// and the model's parser, -7.2 KB): 78.8 KB measured. The product image's budgets are
/// unchanged.
const FIRMWARE: Budget = Budget {
    flash: 80 * 1024,
    ram_with_stack: 20 * 1024,
};

/// The product-shaped image: the core, the Fetch Tea mission compiled in (`include_mission!`,
/// no JSON parser) and stub drivers. 24 KiB since the mission is compiled in (21.8 KB
/// measured; it was 33 KiB with the run-time loader, whose parser took about 10 KB with the
/// formatting and unicode tables its string slicing pulled in). Measured, like every budget
/// here, on the Cortex-M4F's build (the M33's is a little larger, inside it too).
const PRODUCT: Budget = Budget {
    flash: 24 * 1024,
    ram_with_stack: 8 * 1024,
};

/// The Fetch Tea robot on a Pico 2 or a Pico (`boards/pico2`, `boards/pico`, `cargo build
/// --release` there), the same for both chips, with the flight recorder (their default) and
/// the planner: 64 KiB of flash (3 % of the Pico's 2 MiB; about 57.7 KB measured on the
/// Pico, 4.3 KB of it the recorder and 4.0 KB the planner: its search, 2.3 KB, and the control
/// loop's planning path). Their stacks: `cargo xtask stack`.
const BOARD_FLASH: u64 = 64 * 1024;
/// Static RAM budget of a board image (the Pico has 264 KiB, the Pico 2 520 KiB): 16 KiB with
/// the flight recorder's 4 KiB ring and 64-frame queue and the planner's 1.1 KB search space
/// (12.7 KB measured).
const BOARD_STATIC_RAM: u64 = 16 * 1024;

/// Growth over the snapshot that fails the check.
const GROWTH_PERCENT: u64 = 2;

/// The sizes of one image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Sizes {
    /// `.vector_table + .text + .rodata + .data`, bytes.
    pub flash: u64,
    /// `.data + .bss`, bytes.
    pub static_ram: u64,
    /// Stack high-water mark measured in QEMU, bytes.
    pub stack: u64,
}

/// The sizes of the board image, which no emulator runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct BoardSizes {
    /// `.vector_table + .start_block + .text + .rodata + .data`, bytes.
    pub flash: u64,
    /// `.data + .bss + .uninit`, bytes.
    pub static_ram: u64,
    /// Of `flash`, what the boot copies into SRAM and runs there (`.vector_table + .text +
    /// .rodata` linked in SRAM: the Pico's), bytes.
    #[serde(default)]
    pub code_in_sram: u64,
}

/// The SRAM a board image's code may take: the Pico's `memory.x` links it in the last 80 KiB.
const BOARD_CODE_IN_SRAM: u64 = 80 * 1024;

/// What `firmware/size.json` holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Snapshot {
    /// `psmpa-firmware`: the core, the simulated world and the embedded scenarios.
    pub firmware: Sizes,
    /// `psmpa-product`: the core, the compiled-in mission and stub drivers.
    pub product: Sizes,
    /// `psmpa-pico2`: the Fetch Tea robot on a Raspberry Pi Pico 2.
    pub pico2: BoardSizes,
    /// `psmpa-pico`: the Fetch Tea robot on a Raspberry Pi Pico.
    pub pico: BoardSizes,
}

const FLASH_SECTIONS: [&str; 8] = [
    // The RP2040's second-stage bootloader, and the boot vectors that copy the code to SRAM.
    ".boot2",
    ".psmpa_boot",
    ".vector_table",
    // The RP2350's boot block (the QEMU images have none).
    ".start_block",
    ".text",
    // The boards' test points.
    ".psmpa_test",
    ".rodata",
    ".data",
];

/// Flash and static RAM (`.data + .bss`, and `.uninit`: RAM left uninitialised, such as RTT's
/// buffer), bytes.
fn sections(elf: &Path) -> Result<(u64, u64, u64), String> {
    let data = std::fs::read(elf).map_err(|e| format!("{}: {e}", elf.display()))?;
    let file = object::File::parse(&*data).map_err(|e| format!("{}: {e}", elf.display()))?;
    let size = |names: &[&str], in_sram: bool| -> u64 {
        file.sections()
            .filter(|s| s.name().is_ok_and(|n| names.contains(&n)))
            .filter(|s| !in_sram || SRAM.contains(&s.address()))
            .map(|s| s.size())
            .sum()
    };
    Ok((
        size(&FLASH_SECTIONS, false),
        size(&[".data", ".bss", ".uninit"], false),
        size(&[".vector_table", ".text", ".rodata"], true),
    ))
}

/// The Cortex-M's SRAM region of the address map.
const SRAM: std::ops::Range<u64> = 0x2000_0000..0x4000_0000;

/// Flash bytes by crate, from the size of every function and constant symbol in the flash
/// sections, named by the first path segment of its demangled name (for `<T as Trait>::f`, the
/// crate of `T`). Code inlined into another function counts for that function's crate, so the
/// core's control loop, inlined into the executor's poll of the mission task, counts partly
/// for `embassy_executor`. Symbols without a Rust path are grouped by what they are
/// ([`unnamed`]); bytes in no symbol at all count as [`CONSTANTS`].
fn flash_by_crate(elf: &Path, flash: u64) -> Result<Vec<(String, u64)>, String> {
    use object::{ObjectSymbol, SectionIndex};
    let data = std::fs::read(elf).map_err(|e| format!("{}: {e}", elf.display()))?;
    let file = object::File::parse(&*data).map_err(|e| format!("{}: {e}", elf.display()))?;
    let flash_sections: Vec<SectionIndex> = file
        .sections()
        .filter(|s| s.name().is_ok_and(|n| FLASH_SECTIONS.contains(&n)))
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
    *by_crate.entry(CONSTANTS.into()).or_default() += flash.saturating_sub(named);
    let mut rows: Vec<(String, u64)> = by_crate.into_iter().collect();
    rows.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
    Ok(rows)
}

/// The crate a demangled symbol belongs to: the first segment of its path, for `<T as
/// Trait>::f` the crate of `T`, or of `Trait` when `T` is a primitive (`[char]`). The `[hash]`
/// v0 mangling adds is dropped. A symbol without a path is put in a bucket that says what it
/// is (see [`unnamed`]).
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
        .unwrap_or_else(|| unnamed(name).into())
}

/// Constants that name no crate: LLVM's anonymous constants (`.Lanon.*`) and the bytes in no
/// symbol at all (merged constants, padding). In these images: the source file names and
/// messages of panic locations, string literals, `core::fmt`'s Unicode tables.
const CONSTANTS: &str = "(constants of no crate: panic locations, tables)";

/// What a symbol without a Rust path is: an anonymous constant ([`CONSTANTS`]); code LLVM's
/// machine outliner (`opt-level = "z"`) moved out of several functions into one
/// (`OUTLINED_FUNCTION_n`); a C-named routine of compiler_builtins (`__aeabi_*`, `mem*`,
/// 64-bit division), counted with that crate; or another C name: cortex-m-rt's entry point
/// and vector tables (`Reset`, `__EXCEPTIONS`, `__INTERRUPTS`, `HardFault`), defmt's logger
/// and timestamp hooks (`_defmt_*`), the embassy hooks of the time driver and the executor
/// (`_embassy_time_*`, `__embassy_time_queue_item_from_waker`) and `main`.
fn unnamed(name: &str) -> &'static str {
    let builtin = name.starts_with("__aeabi_")
        || ["memcpy", "memmove", "memset", "memcmp", "bcmp"].contains(&name)
        || (name.starts_with("__") && name.ends_with(|c: char| c.is_ascii_digit()));
    if name.starts_with(".L") {
        CONSTANTS
    } else if name.starts_with("OUTLINED_FUNCTION_") {
        "(outlined: code LLVM shares between functions)"
    } else if builtin {
        "compiler_builtins"
    } else {
        "(C names: entry, vectors, defmt and embassy hooks)"
    }
}

/// Measures one image: sizes from its ELF, the stack from its run in QEMU.
fn measure(elf: &Path) -> Result<Sizes, String> {
    let (flash, static_ram, _) = sections(elf)?;
    let log = firmware::run(elf)?;
    let stack = firmware::stack_high_water(&log)
        .ok_or_else(|| format!("{} did not report its stack high-water mark", elf.display()))?;
    Ok(Sizes {
        flash,
        static_ram,
        stack,
    })
}

/// Prints one image's rows and returns what breaks its budget or grew past the snapshot.
fn report(
    name: &str,
    now: Sizes,
    old: Option<Sizes>,
    budget: &Budget,
    check_growth: bool,
) -> Vec<String> {
    let row = |what: &str, value: u64, old: Option<u64>, budget: String| {
        let delta = old.map_or(String::new(), |o| {
            format!("{:+}", i128::from(value) - i128::from(o))
        });
        println!("  {what:<42} {value:>8} B  {delta:>8}  {budget}");
    };
    let ram = now.static_ram.saturating_add(now.stack);
    let over = |value: u64, limit: u64| {
        if value <= limit {
            format!("{} KiB", limit / 1024)
        } else {
            format!("{} KiB: over by {} B", limit / 1024, value - limit)
        }
    };
    println!("{name}:");
    row(
        "flash (.vector_table+.text+.rodata+.data)",
        now.flash,
        old.map(|s| s.flash),
        over(now.flash, budget.flash),
    );
    row(
        "static RAM (.data+.bss+.uninit)",
        now.static_ram,
        old.map(|s| s.static_ram),
        String::new(),
    );
    row(
        "stack high-water (QEMU)",
        now.stack,
        old.map(|s| s.stack),
        String::new(),
    );
    row(
        "static RAM + stack",
        ram,
        old.map(|s| s.static_ram.saturating_add(s.stack)),
        over(ram, budget.ram_with_stack),
    );
    let mut failures = Vec::new();
    if now.flash > budget.flash {
        failures.push(format!(
            "{name}: flash {} B is over the budget of {} B",
            now.flash, budget.flash
        ));
    }
    if ram > budget.ram_with_stack {
        failures.push(format!(
            "{name}: static RAM + stack {ram} B is over the budget of {} B",
            budget.ram_with_stack
        ));
    }
    if let Some(old) = old.filter(|_| check_growth) {
        for (what, new, old) in [
            ("flash", now.flash, old.flash),
            ("static RAM", now.static_ram, old.static_ram),
            ("stack", now.stack, old.stack),
        ] {
            if grew(new, old) {
                failures.push(format!("{name}: {what} grew from {old} B to {new} B (more than {GROWTH_PERCENT} %); if intended, run cargo xtask size --bless"));
            }
        }
    }
    failures
}

/// Whether `new` is more than [`GROWTH_PERCENT`] over `old` (in 128 bits: any two figures).
fn grew(new: u64, old: u64) -> bool {
    u128::from(new) * 100 > u128::from(old) * u128::from(100 + GROWTH_PERCENT)
}

/// Prints a board image's rows and returns what breaks its budget or grew past the snapshot.
fn report_board(
    board: Board,
    now: BoardSizes,
    old: Option<BoardSizes>,
    check_growth: bool,
) -> Vec<String> {
    let name = board.name;
    println!(
        "{name} (Fetch Tea robot on a {}: core, compiled mission, drivers, embassy-rp):",
        board.what
    );
    let mut failures = Vec::new();
    for (what, value, old, budget) in [
        (
            "flash (boot block+.vector_table+.text+..)",
            now.flash,
            old.map(|s| s.flash),
            BOARD_FLASH,
        ),
        (
            "static RAM (.data+.bss+.uninit)",
            now.static_ram,
            old.map(|s| s.static_ram),
            BOARD_STATIC_RAM,
        ),
        (
            "code in SRAM (copied from flash at boot)",
            now.code_in_sram,
            old.map(|s| s.code_in_sram),
            BOARD_CODE_IN_SRAM,
        ),
    ]
    .into_iter()
    // An image that runs from flash has no row of code in SRAM.
    .filter(|(_, value, old, _)| *value > 0 || old.is_some_and(|o| o > 0))
    {
        let delta = old.map_or(String::new(), |o| {
            format!("{:+}", i128::from(value) - i128::from(o))
        });
        println!(
            "  {what:<42} {value:>8} B  {delta:>8}  {} KiB",
            budget / 1024
        );
        if value > budget {
            failures.push(format!(
                "{name}: {what} {value} B is over the budget of {budget} B"
            ));
        }
        if let Some(old) = old.filter(|_| check_growth)
            && grew(value, old)
        {
            failures.push(format!("{name}: {what} grew from {old} B to {value} B (more than {GROWTH_PERCENT} %); if intended, run cargo xtask size --bless"));
        }
    }
    failures
}

/// What the pages say of `snapshot`: `(file, marker, text)`, written by `cargo xtask size`
/// and checked by a test against the committed snapshot (a figure edited by hand fails it).
pub fn pages(s: &Snapshot) -> Vec<(&'static str, &'static str, String)> {
    let b = |n: u64| format!("{} B", crate::hil::thousands(n));
    let kib = |n: u64| format!("{} KiB", n / 1024);
    let (fw, pr) = (s.firmware, s.product);
    let table = format!(
        "
| | firmware (simulator) | budget | product | target | Pico 2 board (`opt-level = \"s\"`) | Pico board | budget |
|---|---|---|---|---|---|---|---|
| flash | {} | {} | {} | {} | {} | {} | {} |
| static RAM (`.data` + `.bss` + `.uninit`) | {} | | {} | | {} | {} | {} |
| stack high-water (`paint-stack`) | {} (QEMU) | | {} (QEMU) | | (`cargo xtask stack`) | (`cargo xtask stack`) | |
| static RAM + stack | {} | {} | {} | {} | | | |
",
        b(fw.flash),
        b(FIRMWARE.flash),
        b(pr.flash),
        b(PRODUCT.flash),
        b(s.pico2.flash),
        b(s.pico.flash),
        b(BOARD_FLASH),
        b(fw.static_ram),
        b(pr.static_ram),
        b(s.pico2.static_ram),
        b(s.pico.static_ram),
        b(BOARD_STATIC_RAM),
        b(fw.stack),
        b(pr.stack),
        b(fw.static_ram.saturating_add(fw.stack)),
        b(FIRMWARE.ram_with_stack),
        b(pr.static_ram.saturating_add(pr.stack)),
        b(PRODUCT.ram_with_stack),
    );
    let cell = format!(
        "product image {} of {} flash, {} of {} RAM + stack",
        b(pr.flash),
        kib(PRODUCT.flash),
        b(pr.static_ram.saturating_add(pr.stack)),
        kib(PRODUCT.ram_with_stack)
    );
    let boards = format!(
        "Pico 2: {} and {}; Pico: {} and {}",
        b(s.pico2.flash),
        b(s.pico2.static_ram),
        b(s.pico.flash),
        b(s.pico.static_ram)
    );
    vec![
        ("README.md", "size", cell),
        ("docs/firmware.md", "size-table", table),
        ("docs/firmware.md", "board-sizes", boards),
    ]
}

/// The committed snapshot.
pub fn snapshot() -> Result<Snapshot, String> {
    let path = firmware::root().join("firmware/size.json");
    let bytes = std::fs::read(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    parse_snapshot(&path, &bytes)
}

/// The most any figure of the snapshot may be, bytes: the address space of the chips'
/// flash (16 MiB on both Picos), far beyond any image of the project.
const MAX_FIGURE: u64 = 16 << 20;

/// A snapshot's text, each figure at most [`MAX_FIGURE`].
fn parse_snapshot(path: &Path, bytes: &[u8]) -> Result<Snapshot, String> {
    let bytes = psmpa_sim::json::strict_file(path, bytes)?;
    let s: Snapshot =
        serde_json::from_slice(&bytes).map_err(|e| format!("{}: {e}", path.display()))?;
    let figures = [
        ("firmware.flash", s.firmware.flash),
        ("firmware.static_ram", s.firmware.static_ram),
        ("firmware.stack", s.firmware.stack),
        ("product.flash", s.product.flash),
        ("product.static_ram", s.product.static_ram),
        ("product.stack", s.product.stack),
        ("pico2.flash", s.pico2.flash),
        ("pico2.static_ram", s.pico2.static_ram),
        ("pico.flash", s.pico.flash),
        ("pico.static_ram", s.pico.static_ram),
    ];
    match figures.iter().find(|(_, v)| *v > MAX_FIGURE) {
        Some((name, v)) => Err(format!(
            "{}: {name} {v} B: no image of the project is that large (at most {MAX_FIGURE} B): run cargo xtask size --bless",
            path.display()
        )),
        None => Ok(s),
    }
}

/// Measures the three images, compares, and with `bless` writes the snapshot.
pub fn run(bless: bool) -> Result<(), String> {
    let elf = firmware::build(&[])?;
    let product_elf = firmware::product(&elf);
    let board_elf = firmware::build_board(PICO2)?;
    let pico_elf = firmware::build_board(PICO)?;
    let board = |elf: &Path| {
        sections(elf).map(|(flash, static_ram, code_in_sram)| BoardSizes {
            flash,
            static_ram,
            code_in_sram,
        })
    };
    let now = Snapshot {
        firmware: measure(&elf)?,
        product: measure(&product_elf)?,
        pico2: board(&board_elf)?,
        pico: board(&pico_elf)?,
    };
    let path = firmware::root().join("firmware/size.json");
    let snapshot: Option<Snapshot> = match std::fs::read(&path) {
        Ok(b) => match parse_snapshot(&path, &b) {
            Ok(s) => Some(s),
            Err(e) if bless => {
                eprintln!("{e}: replaced");
                None
            }
            Err(e) => return Err(e),
        },
        Err(_) => None,
    };

    println!("{:<44} {:>10}  {:>8}  budget", "", "measured", "vs snap");
    let mut failures = report(
        "psmpa-firmware (core, simulated world, the scenarios)",
        now.firmware,
        snapshot.map(|s| s.firmware),
        &FIRMWARE,
        !bless,
    );
    failures.extend(report(
        "psmpa-product (core, compiled mission, stub drivers)",
        now.product,
        snapshot.map(|s| s.product),
        &PRODUCT,
        !bless,
    ));
    failures.extend(report_board(
        PICO2,
        now.pico2,
        snapshot.map(|s| s.pico2),
        !bless,
    ));
    failures.extend(report_board(
        PICO,
        now.pico,
        snapshot.map(|s| s.pico),
        !bless,
    ));
    for (name, elf, flash) in [
        ("psmpa-firmware", &elf, now.firmware.flash),
        ("psmpa-product", &product_elf, now.product.flash),
        ("psmpa-pico2", &board_elf, now.pico2.flash),
        ("psmpa-pico", &pico_elf, now.pico.flash),
    ] {
        println!();
        println!(
            "{name}: flash by crate (by symbol name; inlined code counts where it was inlined):"
        );
        for (krate, bytes) in flash_by_crate(elf, flash)? {
            println!("  {krate:<52} {bytes:>6} B");
        }
    }
    // The product carries neither the simulated world nor a JSON parser: its mission is
    // compiled in.
    let data = std::fs::read(&product_elf).map_err(|e| e.to_string())?;
    let file = object::File::parse(&*data).map_err(|e| e.to_string())?;
    let names: Vec<String> = object::Object::symbols(&file)
        .filter_map(|s| object::ObjectSymbol::name(&s).ok().map(str::to_owned))
        .map(|n| rustc_demangle::demangle(&n).to_string())
        .collect();
    for (marker, what) in [
        ("psmpa_sim::", "the simulator"),
        ("serde_json_core::", "a JSON parser"),
    ] {
        if let Some(name) = names.iter().find(|n| n.contains(marker)) {
            failures.push(format!("psmpa-product links {what}: {name}"));
        }
    }

    if bless {
        let text = serde_json::to_string_pretty(&now).map_err(|e| e.to_string())? + "\n";
        crate::pages::write_file(&path, text.as_bytes())?;
        println!("wrote {}", path.display());
    } else if snapshot.is_none() {
        failures.push(format!(
            "no snapshot (or an old one) at {}: run cargo xtask size --bless",
            path.display()
        ));
    }
    // The pages show the snapshot (the committed figures), blessed or not.
    if let Ok(shown) = self::snapshot() {
        let regions: Vec<_> = pages(&shown)
            .into_iter()
            .map(|(page, marker, text)| (firmware::root().join(page), marker, text))
            .collect();
        crate::pages::write_pages(&regions)?;
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
    fn a_snapshot_with_a_huge_figure_is_refused_and_growth_never_overflows() {
        let path = std::path::Path::new("firmware/size.json");
        let good = std::fs::read(super::firmware::root().join(path)).unwrap();
        assert!(super::parse_snapshot(path, &good).is_ok());
        let text = String::from_utf8(good).unwrap();
        let huge = text.replacen(
            &format!("\"flash\": {}", super::snapshot().unwrap().firmware.flash),
            "\"flash\": 18446744073709551615",
            1,
        );
        assert_ne!(huge, text);
        let e = super::parse_snapshot(path, huge.as_bytes()).unwrap_err();
        assert!(
            e.starts_with("firmware/size.json: firmware.flash 18446744073709551615 B"),
            "{e}"
        );
        // The comparisons themselves hold for any figures.
        assert!(!super::grew(u64::MAX, u64::MAX));
        assert!(super::grew(u64::MAX, 1));
        assert!(!super::grew(102, 100));
        assert!(super::grew(103, 100));
        let sizes = super::Sizes {
            flash: u64::MAX,
            static_ram: u64::MAX,
            stack: u64::MAX,
        };
        let budget = super::FIRMWARE;
        let failures = super::report("x", sizes, Some(sizes), &budget, true);
        assert!(failures.iter().any(|f| f.contains("over the budget")));
    }

    /// The text between a page's markers.
    fn between(page: &str, marker: &str) -> Option<String> {
        let (_, after) = page.split_once(&format!("<!-- {marker}:start -->"))?;
        let (inside, _) = after.split_once(&format!("<!-- {marker}:end -->"))?;
        Some(inside.to_owned())
    }

    #[test]
    fn the_pages_show_the_committed_size_snapshot() {
        let snapshot = super::snapshot().unwrap();
        for (page, marker, text) in super::pages(&snapshot) {
            let path = crate::firmware::root().join(page);
            let shown = std::fs::read_to_string(&path).unwrap();
            assert_eq!(
                between(&shown, marker).as_deref(),
                Some(text.as_str()),
                "{page}: the {marker} figures are not firmware/size.json's: run cargo xtask size"
            );
        }
    }

    #[test]
    fn symbols_are_attributed_to_the_crate_of_their_path() {
        assert_eq!(crate_of("psmpa_core::runtime::engine::run"), "psmpa_core");
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
        assert_eq!(crate_of(".Lanon.88b94e.185"), super::CONSTANTS);
        assert!(crate_of("OUTLINED_FUNCTION_12").starts_with("(outlined"));
        assert_eq!(crate_of("__aeabi_memcpy4"), "compiler_builtins");
        assert_eq!(crate_of("__udivmoddi4"), "compiler_builtins");
        assert_eq!(crate_of("memcmp"), "compiler_builtins");
        assert!(crate_of("_defmt_write").starts_with("(C names"));
        assert!(crate_of("__INTERRUPTS").starts_with("(C names"));
        assert!(crate_of("Reset").starts_with("(C names"));
    }
}

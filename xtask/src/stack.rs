//! `cargo xtask stack`: the worst-case stack of the firmware, computed from its binary.
//!
//! * Frames: LLVM's, from a build with `-Z emit-stack-sizes`; for functions compiled without
//!   it (the precompiled `compiler_builtins`), from the prologue (`push`, `vpush`, `sub sp`).
//! * Call graph, from `arm-none-eabi-objdump -d`: `bl`/`blx` targets and branches out of a
//!   function (tail calls). A call through a register is resolved by looking back, inside its
//!   basic block, for the load that set the register:
//!   - from a literal pool: a direct call (size-optimised code hoists addresses so);
//!   - from `[rN, #k]`: slot `k` of a table (trait-object vtables, `RawWakerVTable`): any
//!     function stored `k` bytes into a table whose address the program uses;
//!   - otherwise: any function whose address is taken.
//!
//!   Addresses come from the relocations the linker keeps (`--emit-relocs`), never from
//!   guessing which words look like pointers. Function pointers the code stores at run time
//!   (not in a table) join every indirect call, unless [`ONLY_FROM`] names their one caller.
//! * Bound: `worst(f) = frame(f) + max(worst(callee))`. A cycle is an error unless
//!   [`BOUNDED_RECURSION`] says why the code bounds it. The firmware's bound adds the exceptions
//!   that preempt thread mode (SysTick, then HardFault) with their hardware frames.
//! * Check: the analysed code is byte for byte the shipped firmware, and the bound is at least
//!   the high-water mark the same code measures in QEMU over every scenario.
//!
//! What it cannot see: a jump table landing between a load and its call (the look-back would
//! then pick one of two loads); stack used by inline assembly outside the frame.
//!
//! Only [`program`] and [`analyse`] run tools and read files; [`Program::new`] and
//! [`Analysis`] are pure, so `stack/tests.rs` checks the rules on hand-written images.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::process::Command;

use object::{
    Object, ObjectSection, ObjectSymbol, RelocationFlags, RelocationKind, SectionFlags, SymbolKind,
};

use crate::firmware;

/// A cycle in the call graph that the code bounds: a cycle through a function whose name
/// contains the pattern repeats at most `depth` times, for the reason given.
type Recursion = (&'static str, u64, &'static str);

/// A function pointer stored at run time that only its callers call: (callee pattern, caller
/// patterns, why).
type OnlyFrom = (&'static str, &'static [&'static str], &'static str);

/// Callers whose calls through a vtable reach only some functions: (caller patterns, callee
/// patterns, why). Without it a call at a vtable's slot may reach whatever any vtable holds
/// at that slot.
type OnlyTo = (
    &'static [&'static str],
    &'static [&'static str],
    &'static str,
);

/// core's own formatting code holds one kind of trait object, the formatter's output.
const FORMATTER_OUTPUT: OnlyTo = (
    &["<char as core::fmt::", "core::fmt::Formatter::"],
    &[" as core::fmt::Write>::", "core::fmt::Write::"],
    "a char's and the formatter's code call through a vtable only the formatter's output, a \
     `&mut dyn core::fmt::Write` (without this, a char's Debug reached the runtime's \
     Monitor::user, at the same slot of another vtable, and through it the trace)",
);

/// The mission loader's JSON recursion, in the simulator-carrying image (which loads its
/// scenarios' missions; the boards and the product have theirs compiled in).
const MISSION_DEPTH: Recursion = (
    "deserialize_ignored_any",
    psmpa_core::mission::MAX_DEPTH as u64,
    "skipping a JSON value recurses per level; the mission loader refuses nesting deeper \
     than psmpa_core::mission::MAX_DEPTH before it parses",
);

/// core's string-slicing panic, in both images.
const SLICE_ERROR: Recursion = (
    "core::str::slice_error_fail",
    2,
    "core's string-slicing panic slices its message at a char boundary it has just found, \
     which cannot fail again",
);

/// core's formatting, in both images.
const FORMATTING: OnlyFrom = (
    " as core::fmt::",
    &["core::fmt::write"],
    "the formatting functions in fmt::Arguments are called by core::fmt::write only",
);

/// The firmware's bounded cycles.
const BOUNDED_RECURSION: &[Recursion] = &[
    MISSION_DEPTH,
    (
        "core::panicking::panic_fmt",
        2,
        "the panic handler logs on its first entry only, so a panic while logging ends there",
    ),
    SLICE_ERROR,
];

/// The firmware's function pointers stored at run time that only one caller calls.
const ONLY_FROM: &[OnlyFrom] = &[
    (
        "embassy_executor::raw::TaskStorage<",
        &["<embassy_executor::raw::Executor>::poll"],
        "embassy's poll loop is the only caller of a task's poll function",
    ),
    FORMATTING,
];

/// A task's poll function: its name contains `name` and, if `calls` is not empty, it calls a
/// function whose name contains `calls` (legacy symbol names drop generic arguments, so every
/// task's poll function is `TaskStorage<F>::poll`: what it polls tells them apart).
#[derive(Debug, Clone, Copy)]
struct Task {
    name: &'static str,
    /// Any of these, called directly: LLVM inlines a task's body into its poll function or not.
    calls: &'static [&'static str],
}

/// No task.
const NO_TASK: Task = Task {
    name: "",
    calls: &[],
};

/// A level of preemption: its entry symbol, a task it never polls (and why), and whether the
/// report shows its deepest path.
struct Level {
    label: &'static str,
    entry: &'static str,
    excluded: Task,
    why: &'static str,
    show_path: bool,
}

/// The levels of preemption, least urgent first: each may interrupt those before it, so the
/// bound stacks them all. The two executors share embassy's poll loop, and their tasks' poll
/// functions are stored at run time: which task a level polls follows from where it was
/// spawned, not from the code.
const LEVELS: &[Level] = &[
    Level {
        label: "thread mode (main, deciding executor)",
        entry: "Reset",
        excluded: Task {
            name: "TaskStorage<psmpa_firmware::firmware::__sense_task",
            calls: &[],
        },
        why: "the sensing task is spawned on the sensing executor, which interrupt 14 polls",
        show_path: true,
    },
    Level {
        label: "interrupt 15 (deciding wake)",
        entry: "psmpa_firmware::executor::deciding_interrupt",
        excluded: NO_TASK,
        why: "",
        show_path: false,
    },
    Level {
        label: "interrupt 14 (sensing executor)",
        entry: "psmpa_firmware::executor::sensing_interrupt",
        excluded: Task {
            name: "TaskStorage<psmpa_firmware::firmware::__one_run_task",
            calls: &[],
        },
        why: "the run task is spawned on the deciding executor, which thread mode polls",
        show_path: true,
    },
    Level {
        label: "interrupt 9 (alarm, time driver)",
        entry: "psmpa_firmware::time_driver::alarm_interrupt",
        excluded: NO_TASK,
        why: "",
        show_path: false,
    },
    Level {
        label: "HardFault",
        entry: "HardFault",
        excluded: NO_TASK,
        why: "",
        show_path: false,
    },
];

/// The Pico 2 board's bounded cycles. Its panic handler is its own (`boards/pico2`'s `panic`).
const PICO2_RECURSION: &[Recursion] = &[
    (
        "core::panicking::panic_fmt",
        2,
        "the board's panic handler stops the motors, masks interrupts and logs on its first \
         entry only (its PANICKED flag), then raises a HardFault, so a panic while logging ends \
         there",
    ),
    SLICE_ERROR,
    (
        "core::fmt::write",
        4,
        "the board formats with core::fmt only in its panic handler's message (its own errors \
         go through defmt::Format): write(the PanicInfo) -> write(its message) -> write(the \
         message's arguments: str, u32, char, Range<usize>, core's and embassy's errors) -> \
         write(a char's escape or a range's \"..\"), none of them recursive types",
    ),
];

/// The Pico 2 board's function pointers stored at run time that only their callers call.
const PICO2_ONLY_FROM: &[OnlyFrom] = &[
    (
        "embassy_executor::raw::TaskStorage<",
        &[
            "embassy_rp::executor::thread::Executor::run",
            "embassy_executor::raw::Executor::poll",
            "SWI_IRQ_1",
        ],
        "embassy's poll loop is the only caller of a task's poll function; on the Cortex-M33 it \
         is inlined into the thread-mode executor's run loop and the interrupt executor's \
         handler, on the Cortex-M0+ it stays `raw::Executor::poll`",
    ),
    FORMATTING,
];

/// The tasks of thread mode that the sensing executor never polls: `main`
/// (`#[embassy_executor::main]`) and `control`, whose poll runs the control loop.
const PICO2_MAIN_TASK: Task = Task {
    name: "embassy_executor::raw::TaskStorage<",
    // Their bodies, or, inlined into the poll, the behaviours the control loop runs (only the
    // deciding side runs an action).
    calls: &[
        "psmpa_board_rp::____embassy_main_task",
        "psmpa_board_rp::__control_task",
        " as psmpa_core::platform::Actuator<psmpa_fetch_tea::fetch_tea::FetchTea>>::run",
    ],
};

/// The task `psmpa_board_rp::sensing`: its poll function runs the runtime's sensing side.
const PICO2_SENSING_TASK: Task = Task {
    name: "embassy_executor::raw::TaskStorage<",
    calls: &[">>::sensing"],
};

/// The Pico 2 board's levels of preemption, least urgent first. On the Cortex-M33 a lower
/// priority number is more urgent; an interrupt preempts only a less urgent one, so handlers
/// of one priority never nest, and each priority is one level. What embassy-rp 0.10 and the
/// board enable (embassy-rp's `init`, `time_driver::init`, `gpio::init`, `dma::init`):
/// * `IO_IRQ_BANK0` at priority 3 (`gpio::init`): wakes the tasks waiting on a pin's edge;
/// * `SWI_IRQ_1` at priority 2 (the board's `main`): polls the sensing executor;
/// * `TIMER0_IRQ_0`, enabled by `time_driver::init` without a priority, so at the reset
///   value 0, the most urgent: the alarm wakes the timers' tasks;
/// * HardFault above them all (the panic handler ends a panic in one; its handler stops the
///   motors and waits for the watchdog).
///
/// The watchdog's feeding task runs on the thread-mode executor; the analysis counts its poll
/// at `SWI_IRQ_1` too (it tells tasks apart by what they call, and excludes only the two
/// named), which can only over-count.
///
/// Not levels: `DMA_IRQ_0` (given priority 3 by `dma::init`, never enabled: the board uses no
/// DMA, and its vector is the default handler), `IO_IRQ_QSPI` (feature `qspi-as-gpio` off),
/// `SIO_IRQ_FIFO` (enabled by `multicore::spawn_core1`, which the board never calls); SysTick,
/// PendSV and SVCall are unused (the time driver is TIMER0), NMI is not routed (the RP2350's
/// NMI mask is zero at reset). Every other vector is cortex-m-rt's `DefaultHandler`, never
/// enabled.
const fn board_levels(alarm: &'static str, alarm_label: &'static str) -> [Level; 5] {
    [
        Level {
            label: "thread mode (main, deciding executor)",
            entry: "Reset",
            excluded: PICO2_SENSING_TASK,
            why: "the sensing task is spawned on the interrupt executor, which SWI_IRQ_1 polls",
            show_path: true,
        },
        Level {
            label: "IO_IRQ_BANK0, priority 3 (GPIO edges)",
            entry: "IO_IRQ_BANK0",
            excluded: NO_TASK,
            why: "",
            show_path: true,
        },
        Level {
            label: "SWI_IRQ_1, priority 2 (sensing executor)",
            entry: "SWI_IRQ_1",
            excluded: PICO2_MAIN_TASK,
            why: "main's task is spawned on the thread-mode executor, which thread mode polls",
            show_path: true,
        },
        Level {
            label: alarm_label,
            entry: alarm,
            excluded: NO_TASK,
            why: "",
            show_path: true,
        },
        Level {
            label: "HardFault",
            entry: "HardFault",
            excluded: NO_TASK,
            why: "",
            show_path: true,
        },
    ]
}

/// The Pico 2's levels: its alarm is `TIMER0_IRQ_0`.
const PICO2_LEVELS: &[Level] = &board_levels(
    "TIMER0_IRQ_0",
    "TIMER0_IRQ_0, priority 0 (alarm, time driver)",
);

/// The Pico's levels: the same on the RP2040, whose alarm is `TIMER_IRQ_0`.
const PICO_LEVELS: &[Level] = &board_levels(
    "TIMER_IRQ_0",
    "TIMER_IRQ_0, priority 0 (alarm, time driver)",
);

/// A board's stack budget, set from the Pico 2's first bound (14,888 B) with 10 % to spare:
/// 16 KiB, 3 % of the Pico 2's RAM, 6 % of the Pico's.
const BOARD_BUDGET: u64 = 16 * 1024;

/// Hardware exception frame with the floating-point context, plus the alignment word. The
/// same on the RP2350's Cortex-M33: its image runs Secure and leaves FPCCR.TS at 0, so no
/// extra Secure context is stacked.
const EXCEPTION_FRAME: u64 = 108;

/// The Cortex-M0+'s exception frame (no floating-point context), plus the alignment word.
const EXCEPTION_FRAME_M0: u64 = 36;

/// An image to analyse: how to build it (as shipped, and for the analysis), the sections that
/// must be equal, its task line, levels and rules.
struct Image {
    /// What the image is, for messages.
    what: &'static str,
    shipped: fn() -> Result<PathBuf, String>,
    analysed: fn() -> Result<PathBuf, String>,
    sections: &'static [&'static str],
    /// The label and poll function of the task reported on its own.
    task: (&'static str, Task),
    levels: &'static [Level],
    rules: Rules,
    /// What an exception stacks.
    exception_frame: u64,
}

/// An image's rules: what the code bounds or guarantees that the call graph cannot show.
struct Rules {
    only_from: &'static [OnlyFrom],
    only_to: &'static [OnlyTo],
    recursion: &'static [Recursion],
}

/// The QEMU firmware (mps2-an386).
const FIRMWARE: Image = Image {
    what: "firmware",
    shipped: || firmware::build(&[]),
    analysed: build,
    sections: &[".vector_table", ".text", ".rodata", ".data"],
    task: (
        "run task (one deciding poll)",
        Task {
            name: "TaskStorage<psmpa_firmware::firmware::__one_run_task",
            calls: &[],
        },
    ),
    levels: LEVELS,
    rules: Rules {
        only_from: ONLY_FROM,
        only_to: &[FORMATTER_OUTPUT],
        recursion: BOUNDED_RECURSION,
    },
    exception_frame: EXCEPTION_FRAME,
};

/// The Fetch Tea robot on a Pico 2 (`boards/pico2`).
const PICO2: Image = Image {
    what: "Pico 2 image",
    shipped: || firmware::build_board(firmware::PICO2),
    analysed: || build_board(firmware::PICO2),
    sections: &[
        ".vector_table",
        ".start_block",
        ".text",
        ".psmpa_test",
        ".rodata",
        ".data",
    ],
    task: ("main task (one deciding poll)", PICO2_MAIN_TASK),
    levels: PICO2_LEVELS,
    rules: Rules {
        only_from: PICO2_ONLY_FROM,
        only_to: &[FORMATTER_OUTPUT],
        recursion: PICO2_RECURSION,
    },
    exception_frame: EXCEPTION_FRAME,
};

/// The Fetch Tea robot on a Pico (`boards/pico`): the same code on the RP2040's Cortex-M0+.
const PICO: Image = Image {
    what: "Pico image",
    shipped: || firmware::build_board(firmware::PICO),
    analysed: || build_board(firmware::PICO),
    sections: &[
        ".boot2",
        ".vector_table",
        ".text",
        ".psmpa_test",
        ".rodata",
        ".data",
    ],
    task: ("main task (one deciding poll)", PICO2_MAIN_TASK),
    levels: PICO_LEVELS,
    rules: Rules {
        only_from: PICO2_ONLY_FROM,
        only_to: &[FORMATTER_OUTPUT],
        recursion: PICO2_RECURSION,
    },
    exception_frame: EXCEPTION_FRAME_M0,
};

/// One disassembled instruction.
#[derive(Debug, Clone)]
struct Insn {
    addr: u64,
    mnemonic: String,
    args: String,
}

/// How a call through a register was resolved.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Site {
    /// Slot at this byte offset of a table.
    Slot(u64),
    /// Anything whose address is taken (the call's address, for the report).
    Unknown(u64),
}

#[derive(Debug, Default, Clone)]
struct Function {
    name: String,
    /// LLVM's frame size, or the prologue's.
    frame: Option<u64>,
    from_prologue: bool,
    /// Direct callees (start addresses), including calls resolved through literal pools.
    calls: BTreeSet<u64>,
    /// Calls through registers not resolved to one target.
    sites: BTreeSet<Site>,
    /// What each call or jump through a register resolved to, by the instruction's address.
    at: BTreeMap<u64, BTreeSet<Resolved>>,
}

/// The firmware's functions and what its pointers may reach.
struct Program {
    funcs: BTreeMap<u64, Function>,
    /// Every function symbol's address by name: a function may have several (`HardFault` and
    /// cortex-m-rt's `HardFault_`), `funcs` keeps one.
    names: BTreeMap<String, u64>,
    /// Functions stored in an allocated section (a vtable, a waker vtable) by the address of
    /// the word.
    table_words: BTreeMap<u64, u64>,
    /// Every address a relocated word holds: candidate table starts.
    referenced: BTreeSet<u64>,
    /// Relocated words of allocated sections other than the code, by address.
    relocated: BTreeMap<u64, u64>,
    /// Addresses of zero words that are referenced (a vtable without a drop function).
    zero: BTreeSet<u64>,
    /// Functions whose address is loaded from a literal pool and not just called: stored
    /// somewhere at run time.
    stored: BTreeSet<u64>,
}

impl Program {
    /// Whether a table of function pointers that the program refers to starts at `start` and
    /// reaches slot `k`: a trait-object vtable (drop function or 0, size, align, methods) or a
    /// table of pointers only (`RawWakerVTable`). Every word up to the slot must fit, and no
    /// other table may start before it.
    fn is_table(&self, start: u64, k: u64) -> bool {
        if !self.referenced.contains(&start) {
            return false;
        }
        // A table ends where the next one the program refers to begins.
        if (4..=k)
            .step_by(4)
            .any(|o| self.referenced.contains(&(start + o)))
        {
            return false;
        }
        let function = |at: u64| self.table_words.contains_key(&at);
        let plain = |at: u64| !self.relocated.contains_key(&at);
        let vtable = (function(start) || self.zero.contains(&start))
            && plain(start + 4)
            && plain(start + 8)
            && (12..=k).step_by(4).all(|o| function(start + o));
        let pointers = (0..=k).step_by(4).all(|o| function(start + o));
        vtable || pointers
    }
}

fn demangle(name: &str) -> String {
    format!("{:#}", rustc_demangle::demangle(name))
}

/// Builds the firmware for analysis: the same compiler and flags as the shipped firmware, plus
/// `-Z emit-stack-sizes` (a section beside the code) and `--emit-relocs` (which words are
/// addresses). `RUSTC_BOOTSTRAP` unlocks the `-Z` flag on the stable compiler, so the code
/// analysed is the code shipped; [`run`] checks that byte for byte (both use v0 mangling, so
/// the names are the same too).
fn build() -> Result<PathBuf, String> {
    let target_dir = firmware::root().join("target/stack");
    let flags = [
        firmware::rustflags().as_str(),
        "-Zemit-stack-sizes",
        "-Clink-arg=--emit-relocs",
    ]
    .join("\x1f");
    let mut cmd = firmware::cargo();
    cmd.args([
        "build",
        "--quiet",
        "-p",
        "psmpa-firmware",
        "--bin",
        "psmpa-firmware",
    ])
    .arg("--target")
    .args([firmware::TARGET, "--profile", firmware::PROFILE]);
    build_with(cmd, &flags, &target_dir, "the firmware")?;
    Ok(target_dir
        .join(firmware::TARGET)
        .join(firmware::PROFILE)
        .join("psmpa-firmware"))
}

/// Builds a board for analysis, from its folder so that its `.cargo/config.toml` applies
/// (target, linker), into `boards/target/stack`: the shipped image's build (a plain `cargo
/// build --release`, no flags) plus `-Z emit-stack-sizes` and `--emit-relocs`.
/// `RUSTC_BOOTSTRAP` makes the compiler mangle with v0 as a nightly one does, which reorders
/// the code and constants; `-C symbol-mangling-version=legacy` (unstable, hence
/// `-Z unstable-options`) keeps the stable compiler's names, so [`run`] finds the same bytes.
fn build_board(board: firmware::Board) -> Result<PathBuf, String> {
    let dir = firmware::boards().join(board.dir);
    let target_dir = firmware::boards().join("target/stack");
    build_board_at(&dir, &target_dir, board)
}

/// [`build_board`] from the board's folder `dir` into `target_dir`.
fn build_board_at(
    dir: &Path,
    target_dir: &Path,
    board: firmware::Board,
) -> Result<PathBuf, String> {
    let flags = [
        "-Zemit-stack-sizes",
        "-Clink-arg=--emit-relocs",
        "-Zunstable-options",
        "-Csymbol-mangling-version=legacy",
    ]
    .join("\x1f");
    let mut cmd = firmware::cargo_in(dir);
    cmd.args(["build", "--quiet", "--release"]);
    build_with(cmd, &flags, target_dir, board.what)?;
    Ok(target_dir
        .join(board.target)
        .join("release")
        .join(board.name))
}

/// Runs the cargo build `cmd` with `flags` (unit-separated) into `target_dir`, the `-Z` flags
/// unlocked on the stable compiler; `what` names the image in the error.
fn build_with(
    mut cmd: std::process::Command,
    flags: &str,
    target_dir: &std::path::Path,
    what: &str,
) -> Result<(), String> {
    let status = cmd
        .env("CARGO_ENCODED_RUSTFLAGS", flags)
        .env("CARGO_TARGET_DIR", target_dir)
        .env("RUSTC_BOOTSTRAP", "1")
        .status()
        .map_err(|e| format!("cannot run cargo: {e}"))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("{what} does not build with -Z emit-stack-sizes"))
    }
}

/// LLVM's frame sizes by function address: `(u32 address, ULEB128 size)` records.
fn stack_sizes(elf: &object::File<'_>) -> Result<HashMap<u64, u64>, String> {
    let section = elf
        .section_by_name(".stack_sizes")
        .ok_or("no .stack_sizes section: was the firmware built with -Z emit-stack-sizes?")?;
    let data = section.uncompressed_data().map_err(|e| e.to_string())?;
    let mut out = HashMap::new();
    let mut rest: &[u8] = &data;
    while let Some((addr, tail)) = rest.split_first_chunk::<4>() {
        let (mut size, mut shift, mut used) = (0u64, 0, 0);
        for &b in tail {
            used += 1;
            size |= u64::from(b & 0x7f) << shift;
            shift += 7;
            if b < 0x80 {
                break;
            }
        }
        out.insert(u64::from(u32::from_le_bytes(*addr)) & !1, size);
        rest = tail.get(used..).unwrap_or_default();
    }
    Ok(out)
}

/// Number of registers in a list such as `{r4, r5, lr}` or `{d8-d11}`.
fn register_count(list: &str) -> u64 {
    let list = list.split_once('{').map_or(list, |(_, l)| l);
    let list = list.split('}').next().unwrap_or("");
    let number = |r: &str| {
        r.trim_start_matches(|c: char| c.is_ascii_alphabetic())
            .parse::<u64>()
            .ok()
    };
    list.split(',')
        .map(str::trim)
        .filter(|r| !r.is_empty())
        .map(|r| match r.split_once('-') {
            Some((a, b)) => number(b)
                .zip(number(a))
                .map_or(1, |(b, a)| b.saturating_sub(a) + 1),
            None => 1,
        })
        .sum()
}

/// Frame size from the prologue: pushes, vpushes and `sub sp` before the first branch.
/// `None` if the stack pointer moves in a way it does not understand.
fn prologue(code: &[Insn]) -> Option<u64> {
    let mut size = 0u64;
    let mut pending_imm: Option<u64> = None;
    for Insn { mnemonic, args, .. } in code.iter().take(16) {
        match mnemonic.as_str() {
            "push" | "push.w" => size += 4 * register_count(args),
            "stmdb" | "stmdb.w" if args.starts_with("sp!") => size += 4 * register_count(args),
            "vpush" | "vstmdb" => {
                let list = args.split_once('{').map_or(args.as_str(), |(_, l)| l);
                let width = if list.trim_start().starts_with('d') {
                    8
                } else {
                    4
                };
                size += width * register_count(args);
            }
            "sub" | "sub.w" | "subw" if args.starts_with("sp") => {
                let last = args.split('@').next().unwrap_or("").rsplit(',').next()?;
                match last.trim().strip_prefix('#') {
                    Some(imm) => size += parse_imm(imm)?,
                    None => size += pending_imm?,
                }
            }
            "movw" | "mov.w" | "mov" if !args.starts_with("sp") && !args.starts_with("r7") => {
                pending_imm = args.rsplit('#').next().and_then(parse_imm);
            }
            "movt" => {}
            m if m.starts_with('b') || m == "cbz" || m == "cbnz" => break,
            _ if args.starts_with("sp,") && !mnemonic.starts_with("add") => return None,
            _ => {}
        }
    }
    Some(size)
}

fn parse_imm(s: &str) -> Option<u64> {
    // objdump appends comments (`#48\t@ 0x30`): the number is the first word.
    let s = s
        .split_whitespace()
        .next()?
        .trim_end_matches(|c: char| !c.is_ascii_alphanumeric());
    match s.strip_prefix("0x") {
        Some(hex) => u64::from_str_radix(hex, 16).ok(),
        None => s.parse().ok(),
    }
}

/// The address an instruction's comment names: `@ (d0 <Reset+0x50>)` or `@ 4ac <...>`.
fn comment_address(args: &str) -> Option<u64> {
    let (_, comment) = args.split_once('@')?;
    let hex = comment
        .trim()
        .trim_start_matches('(')
        .split_whitespace()
        .next()?;
    u64::from_str_radix(hex, 16).ok()
}

/// Whether `mov pc, rY` at `code[i]` dispatches through a jump table of the function itself
/// (`range`): Thumb-1 has no `tbb`, so LLVM's switches on the Cortex-M0+ are `adr rX, table;
/// ldr rY, [rX, rZ]; mov pc, rY` with the table inside the function. A branch, not a call.
fn jump_table(code: &[Insn], i: usize, range: std::ops::Range<u64>) -> bool {
    let Some(insn) = code.get(i) else {
        return false;
    };
    let target = insn.args.trim_start_matches("pc,").trim().to_owned();
    let before = code.get(i.saturating_sub(6)..i).unwrap_or(&[]);
    // `ldr rY, [rX, rZ]` loads the entry; rX is the table.
    let Some(table) = before.iter().rev().find_map(|l| {
        let m = l.mnemonic.split('.').next().unwrap_or("");
        let rest = l.args.strip_prefix(&format!("{target}, ["))?;
        (m == "ldr").then(|| rest.split(',').next().unwrap_or("").trim().to_owned())
    }) else {
        return false;
    };
    // `add rX, pc, #imm` (objdump: `@ (adr rX, ADDRESS <...>)`) inside the function.
    let prefix = format!("(adr {table}, ");
    code.get(i.saturating_sub(8)..i)
        .unwrap_or(&[])
        .iter()
        .filter_map(|l| l.args.split_once(prefix.as_str()))
        .filter_map(|(_, rest)| u64::from_str_radix(rest.split_whitespace().next()?, 16).ok())
        .any(|at| range.contains(&at))
}

/// Registers an instruction writes (those the look-back needs: general registers).
fn writes(insn: &Insn) -> Vec<String> {
    let m = insn.mnemonic.split('.').next().unwrap_or("");
    let ops: Vec<String> = insn
        .args
        .split('@')
        .next()
        .unwrap_or("")
        .split(',')
        .map(|o| o.trim().to_owned())
        .collect();
    let first = || ops.first().cloned().into_iter().collect::<Vec<_>>();
    let list = || {
        let args = insn.args.split_once('{').map_or("", |(_, l)| l);
        let args = args.split('}').next().unwrap_or("");
        args.split(',')
            .map(|r| r.trim().to_owned())
            .collect::<Vec<_>>()
    };
    let base_written = insn.args.contains('!') || insn.args.contains("],");
    let base = || {
        insn.args
            .split_once('[')
            .and_then(|(_, b)| b.split([',', ']']).next())
            .map(|b| b.trim().to_owned())
    };
    let mut out = match m {
        _ if m.starts_with("str") || m.starts_with("stm") || m.starts_with("vst") => vec![],
        "cmp" | "cmn" | "tst" | "teq" | "cbz" | "cbnz" | "push" | "vpush" | "dmb" | "dsb"
        | "isb" | "nop" | "bkpt" | "svc" | "msr" | "cpsid" | "cpsie" | "wfi" | "wfe" | "sev"
        | "vcmp" | "vcmpe" | "vmsr" => vec![],
        _ if m.starts_with("it")
            || (m.starts_with('b') && !m.starts_with("bic") && !m.starts_with("bf")) =>
        {
            // A call clobbers the argument registers; a branch writes nothing.
            if m == "bl" || m == "blx" {
                ["r0", "r1", "r2", "r3", "ip", "lr"]
                    .map(String::from)
                    .to_vec()
            } else {
                vec![]
            }
        }
        "pop" | "ldm" | "ldmia" | "ldmdb" => list(),
        "ldrd" | "ldrexd" | "umull" | "smull" | "umlal" | "smlal" | "vmov" if ops.len() >= 3 => {
            ops.iter().take(2).cloned().collect()
        }
        _ => first(),
    };
    if base_written && let Some(b) = base() {
        out.push(b);
    }
    out
}

/// Whether a mnemonic carries a condition (inside an IT block): its write may not happen.
fn conditional(mnemonic: &str) -> bool {
    const CONDITIONS: [&str; 14] = [
        "eq", "ne", "cs", "cc", "mi", "pl", "vs", "vc", "hi", "ls", "ge", "lt", "gt", "le",
    ];
    let m = mnemonic.split('.').next().unwrap_or("");
    // `bls`, `bne`, ... are branches; `movs`/`adds` set flags and end in `s`, not a condition.
    !m.starts_with('b')
        && CONDITIONS
            .iter()
            .any(|c| m.len() > c.len() + 1 && m.ends_with(c) && m != "vmls" && m != "smulls")
}

/// What a call through a register reaches.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Resolved {
    Direct(u64),
    Site(Site),
    /// Loaded from the stack slot at this offset (only while resolving).
    Spill(u64),
}

/// What an instruction does to the stack slot at `k` (a spill), looking back.
enum Spill {
    /// Stores this register there.
    Stored(String),
    Untouched,
    /// Moves the stack pointer, writes part of the slot, or may write it through a pointer.
    Unknown,
}

/// What `insn` does to the stack slot at offset `k`; `aliased`: a pointer the function made
/// into its frame may reach the slot, so calls and stores through registers may write it.
fn spill_store(insn: &Insn, k: u64, aliased: bool) -> Spill {
    let m = insn.mnemonic.split('.').next().unwrap_or("");
    let args = insn.args.split('@').next().unwrap_or("");
    let moves_sp = matches!(m, "push" | "pop" | "vpush" | "vpop")
        || args.starts_with("sp,")
        || args.contains("sp!")
        || (m.starts_with("ldm") || m.starts_with("stm")) && args.starts_with("sp");
    if moves_sp || conditional(&insn.mnemonic) && m.starts_with("str") {
        return Spill::Unknown;
    }
    let call = m == "bl" || m == "blx";
    if !(m.starts_with("str") || m.starts_with("stm") || m.starts_with("vst") || call) {
        return Spill::Untouched;
    }
    let Some((regs, addr)) = args.split_once('[') else {
        return if call && aliased {
            Spill::Unknown
        } else {
            Spill::Untouched
        };
    };
    let (base, rest) = addr.split_once(']').unwrap_or((addr, ""));
    if base.split(',').next().map(str::trim) != Some("sp") {
        return if aliased {
            Spill::Unknown
        } else {
            Spill::Untouched
        };
    }
    let offset = match base.split_once('#') {
        Some((_, o)) => parse_imm(o),
        None => Some(0),
    };
    let width = match m {
        "str" => 4,
        "strd" => 8,
        "strb" => 1,
        "strh" => 2,
        _ => return Spill::Unknown,
    };
    let Some(offset) = offset.filter(|_| rest.trim().is_empty()) else {
        return Spill::Unknown;
    };
    if offset + width <= k || k + 4 <= offset {
        return Spill::Untouched;
    }
    let regs: Vec<&str> = regs
        .split(',')
        .map(str::trim)
        .filter(|r| !r.is_empty())
        .collect();
    match (width, k - offset.min(k)) {
        (4, 0) if offset == k => regs
            .first()
            .map_or(Spill::Unknown, |r| Spill::Stored((*r).to_owned())),
        (8, d) if offset <= k && (d == 0 || d == 4) => regs
            .get(d as usize / 4)
            .map_or(Spill::Unknown, |r| Spill::Stored((*r).to_owned())),
        _ => Spill::Unknown,
    }
}

/// Whether control never falls through to the next instruction.
fn ends_flow(insn: &Insn) -> bool {
    let m = insn.mnemonic.split('.').next().unwrap_or("");
    let returns = insn.args.contains("pc}") || insn.args.starts_with("pc,");
    matches!(m, "b" | "bx" | "tbb" | "tbh" | "udf")
        || (returns && (m == "pop" || m.starts_with("ldm")))
}

/// What a call through `reg` at `code[i]` reaches: the loads that set the register, found by
/// walking back along every path into the call (fall-through and branches) until each one
/// meets its load. A path that starts at the function's entry (an argument), meets a spill
/// or an arithmetic result, is unknown; a conditional write adds its value to the one before.
fn resolve(
    code: &[Insn],
    i: usize,
    reg: &str,
    branches_to: &BTreeMap<u64, Vec<usize>>,
    word: &dyn Fn(u64) -> Option<u64>,
    used_literals: &mut BTreeSet<u64>,
) -> BTreeSet<Resolved> {
    let unknown = Resolved::Site(Site::Unknown(code.get(i).map_or(0, |c| c.addr)));
    // The lowest stack offset a pointer the function makes into its frame may reach
    // (`add rN, sp, #j`); anything made from the frame pointer may reach all of it.
    let aliased_from = code
        .iter()
        .filter_map(|c| {
            let m = c.mnemonic.split('.').next().unwrap_or("");
            let mut ops = c.args.split('@').next().unwrap_or("").split(',');
            let (dst, src) = (ops.next()?.trim(), ops.next()?.trim());
            let arithmetic = matches!(m, "add" | "addw" | "sub" | "subw" | "mov");
            if !arithmetic || dst == "sp" || dst == "r7" || (src != "sp" && src != "r7") {
                return None;
            }
            let imm = ops
                .next()
                .and_then(|k| parse_imm(k.trim().trim_start_matches('#')));
            Some(if src == "sp" && m.starts_with("add") || m == "mov" {
                imm.unwrap_or(0)
            } else {
                0
            })
        })
        .min();
    let mut out = BTreeSet::new();
    let mut seen = BTreeSet::new();
    let mut work = vec![(i, reg.to_owned())];
    while let Some((j, reg)) = work.pop() {
        if !seen.insert((j, reg.clone())) {
            continue;
        }
        if seen.len() > 512 {
            out.insert(unknown);
            break;
        }
        let Some(here) = code.get(j) else { continue };
        let mut preds: Vec<usize> = branches_to.get(&here.addr).cloned().unwrap_or_default();
        if let Some(p) = j.checked_sub(1)
            && code.get(p).is_some_and(|p| !ends_flow(p))
        {
            preds.push(p);
        }
        if preds.is_empty() {
            out.insert(unknown);
        }
        for p in preds {
            let Some(insn) = code.get(p) else { continue };
            if let Some(slot) = reg.strip_prefix("[sp+").and_then(|k| k.strip_suffix(']')) {
                // A spilled value: back to the store of its stack slot.
                let k: u64 = slot.parse().unwrap_or(u64::MAX);
                match spill_store(insn, k, aliased_from.is_some_and(|a| a <= k)) {
                    Spill::Stored(r) => work.push((p, r)),
                    Spill::Untouched => work.push((p, reg.clone())),
                    Spill::Unknown => {
                        out.insert(unknown);
                    }
                }
                continue;
            }
            let written = writes(insn);
            let Some(pos) = written.iter().position(|w| *w == reg) else {
                work.push((p, reg.clone()));
                continue;
            };
            let m = insn.mnemonic.split('.').next().unwrap_or("");
            let src = insn.args.split_once('[').map(|(_, s)| s);
            let m = if conditional(&insn.mnemonic) {
                // The write may not happen: the value before it may reach the call too.
                work.push((p, reg.clone()));
                m.get(..m.len() - 2).unwrap_or(m)
            } else {
                m
            };
            let found = if m == "ldr" && src.is_some_and(|s| s.starts_with("pc")) {
                comment_address(&insn.args)
                    .and_then(word)
                    .filter(|t| t & 1 == 1)
                    .map(|t| {
                        used_literals.insert(insn.addr);
                        Resolved::Direct(t & !1)
                    })
            } else if m == "movt" {
                word(insn.addr).filter(|t| t & 1 == 1).map(|t| {
                    used_literals.insert(insn.addr);
                    Resolved::Direct(t & !1)
                })
            } else if m == "ldr" || m == "ldrd" {
                src.and_then(|src| {
                    let (base, rest) = src.split_once(']').unwrap_or((src, ""));
                    if base.trim() == "sp" || base.trim_start().starts_with("sp,") {
                        // A spill (`[sp]`, `[sp, #k]`): follow the slot back to its store.
                        let k = match base.split_once('#') {
                            Some((_, k)) => parse_imm(k)?,
                            None => 0,
                        };
                        let plain = rest.trim().is_empty() && !insn.args.contains('!');
                        return plain.then(|| Resolved::Spill(k + 4 * pos as u64));
                    }
                    // `[rN, #k]`, or `[rN], #k` post-indexed (slot 0).
                    let offset = if rest.starts_with(',') {
                        0
                    } else {
                        match base.split_once('#') {
                            Some((_, k)) => parse_imm(k)?,
                            None => 0,
                        }
                    };
                    Some(Resolved::Site(Site::Slot(offset + 4 * pos as u64)))
                })
            } else if m == "mov" {
                if let Some(from) = insn.args.split(',').nth(1) {
                    work.push((p, from.trim().to_owned()));
                    continue;
                }
                None
            } else {
                None
            };
            match found {
                Some(Resolved::Spill(k)) => work.push((p, format!("[sp+{k}]"))),
                found => {
                    out.insert(found.unwrap_or(unknown));
                }
            }
        }
    }
    out
}

/// What the analysis reads from an image and its disassembly, before it interprets any of it
/// (the tests build one by hand).
struct Binary<'a> {
    /// Function symbols in the ELF's order: (demangled name, address, size). A symbol of size
    /// 0 only names an address (cortex-m-rt's `HardFault`).
    symbols: Vec<(String, u64, u64)>,
    /// LLVM's frame sizes by function address.
    frames: HashMap<u64, u64>,
    /// Relocated words of allocated sections other than the code, by address (the vector
    /// table aside: only the hardware calls through it).
    relocated: BTreeMap<u64, u64>,
    /// Relocated words in the code (literal pools), by address.
    text_words: BTreeMap<u64, u64>,
    /// `movw`/`movt` instructions that the linker filled with an address's halves (Armv8-M
    /// code builds addresses so, where Armv7-M code loads them from literal pools).
    movw: BTreeSet<u64>,
    movt: BTreeSet<u64>,
    /// Every section but the code, (address, bytes): where a referenced word may be zero.
    data: Vec<(u64, &'a [u8])>,
    /// The disassembly, in address order.
    code: Vec<Insn>,
}

/// Reads the ELF: functions, frames, tables of function pointers and the disassembly.
fn program(elf_path: &Path) -> Result<Program, String> {
    let data = std::fs::read(elf_path).map_err(|e| e.to_string())?;
    let elf = object::File::parse(&*data).map_err(|e| e.to_string())?;
    let frames = stack_sizes(&elf)?;
    // Aliases without a size of their own too (cortex-m-rt's `HardFault`).
    let symbols = elf
        .symbols()
        .filter(|s| s.kind() == SymbolKind::Text)
        .map(|s| (demangle(s.name().unwrap_or("?")), s.address(), s.size()))
        .collect();

    let mut relocated: BTreeMap<u64, u64> = BTreeMap::new();
    let mut text_words: BTreeMap<u64, u64> = BTreeMap::new();
    let (mut movw, mut movt) = (BTreeSet::new(), BTreeSet::new());
    for section in elf.sections() {
        let allocated = matches!(
            section.flags(),
            SectionFlags::Elf { sh_flags, .. } if sh_flags.0 & object::elf::SHF_ALLOC.0 != 0
        );
        if !allocated || section.name() == Ok(".vector_table") {
            continue;
        }
        let is_text = section.name() == Ok(".text");
        let bytes = section.data().map_err(|e| e.to_string())?;
        for (offset, reloc) in section.relocations() {
            if let RelocationFlags::Elf { r_type } = reloc.flags()
                && is_text
            {
                match r_type {
                    object::elf::R_ARM_THM_MOVW_ABS_NC => movw.insert(offset),
                    object::elf::R_ARM_THM_MOVT_ABS => movt.insert(offset),
                    _ => false,
                };
            }
            if reloc.kind() != RelocationKind::Absolute || reloc.size() != 32 {
                continue;
            }
            // In a linked file the offset is an address; the word there is the final value.
            let at = offset.checked_sub(section.address()).unwrap_or(offset);
            let value = usize::try_from(at)
                .ok()
                .and_then(|at| bytes.get(at..at.checked_add(4)?))
                .and_then(|w| <[u8; 4]>::try_from(w).ok())
                .map(|w| u64::from(u32::from_le_bytes(w)));
            if let Some(value) = value {
                if is_text {
                    text_words.insert(offset, value);
                } else {
                    relocated.insert(offset, value);
                }
            }
        }
    }
    if relocated.is_empty() && text_words.is_empty() {
        return Err("no relocations in the ELF: was it linked with --emit-relocs?".to_owned());
    }
    let out = Command::new("arm-none-eabi-objdump")
        .args(["-d", "--no-show-raw-insn"])
        .arg(elf_path)
        .output()
        .map_err(|e| format!("cannot run arm-none-eabi-objdump: {e}"))?;
    if !out.status.success() {
        return Err("arm-none-eabi-objdump failed".to_owned());
    }
    let sections = elf
        .sections()
        .filter(|s| s.name() != Ok(".text"))
        .map(|s| (s.address(), s.data().unwrap_or_default()))
        .collect();
    Program::new(Binary {
        symbols,
        frames,
        relocated,
        text_words,
        movw,
        movt,
        data: sections,
        code: disassembly(&String::from_utf8_lossy(&out.stdout)),
    })
}

/// The instructions of `objdump -d --no-show-raw-insn`'s output (`  addr:\tmnemonic\targs`).
fn disassembly(text: &str) -> Vec<Insn> {
    let mut code = Vec::new();
    for line in text.lines() {
        let Some((addr, rest)) = line.trim_start().split_once(":\t") else {
            continue;
        };
        let Ok(addr) = u64::from_str_radix(addr.trim(), 16) else {
            continue;
        };
        let mut parts = rest.trim().splitn(2, char::is_whitespace);
        let mnemonic = parts.next().unwrap_or("").to_owned();
        let args = parts.next().unwrap_or("").trim().to_owned();
        code.push(Insn {
            addr,
            mnemonic,
            args,
        });
    }
    code
}

impl Program {
    /// The call graph and the tables of a binary: no tool runs, no file is read.
    fn new(binary: Binary<'_>) -> Result<Program, String> {
        let Binary {
            symbols,
            frames,
            relocated,
            mut text_words,
            movw,
            movt,
            data,
            code,
        } = binary;
        let mut funcs: BTreeMap<u64, Function> = BTreeMap::new();
        let mut names = BTreeMap::new();
        for (name, addr, _) in &symbols {
            names.insert(name.clone(), addr & !1);
        }
        for (name, addr, size) in &symbols {
            if *size > 0 {
                let addr = addr & !1;
                funcs.entry(addr).or_insert_with(|| Function {
                    name: name.clone(),
                    frame: frames.get(&addr).copied(),
                    ..Function::default()
                });
            }
        }
        let starts: BTreeSet<u64> = funcs.keys().copied().collect();
        let owner = |addr: u64| starts.range(..=addr).next_back().copied();
        let mut bodies: BTreeMap<u64, Vec<Insn>> = BTreeMap::new();
        for insn in code {
            if let Some(f) = owner(insn.addr) {
                bodies.entry(f).or_default().push(insn);
            }
        }

        // An address built by a relocated `movw` and `movt` pair, as a word at the `movt`: the
        // pair's `movw` is the last write of the register before it.
        for code in bodies.values() {
            for (j, insn) in code.iter().enumerate() {
                if !movt.contains(&insn.addr) {
                    continue;
                }
                let reg = insn.args.split(',').next().unwrap_or("").trim();
                let imm = |i: &Insn| i.args.split('#').nth(1).and_then(parse_imm);
                let low = code
                    .get(..j)
                    .unwrap_or_default()
                    .iter()
                    .rev()
                    .find(|i| writes(i).iter().any(|w| w == reg))
                    .filter(|i| movw.contains(&i.addr))
                    .and_then(imm);
                if let Some((low, high)) = low.zip(imm(insn)) {
                    text_words.insert(insn.addr, high << 16 | low);
                }
            }
        }
        let is_function = |v: u64| v & 1 == 1 && starts.contains(&(v & !1));
        let table_words = relocated
            .iter()
            .filter(|(_, v)| is_function(**v))
            .map(|(at, v)| (*at, *v & !1))
            .collect();
        let referenced: BTreeSet<u64> = relocated
            .values()
            .chain(text_words.values())
            .copied()
            .collect();
        let zero = data
            .iter()
            .flat_map(|&(base, bytes)| {
                referenced
                    .iter()
                    .filter(move |r| (base..base + bytes.len() as u64).contains(r))
                    .filter(move |r| {
                        let at = (*r - base) as usize;
                        bytes.get(at..at + 4) == Some(&[0u8; 4][..])
                    })
                    .copied()
                    .collect::<Vec<_>>()
            })
            .collect();

        let word = |addr: u64| text_words.get(&addr).copied();
        let mut literal_loads: BTreeMap<u64, u64> = BTreeMap::new();
        let mut used_literals = BTreeSet::new();
        for (start, code) in &bodies {
            let end = funcs
                .range(start + 1..)
                .next()
                .map_or(u64::MAX, |(a, _)| *a);
            let target_of = |insn: &Insn| {
                let args = insn.args.split('@').next().unwrap_or("");
                let last = args.rsplit(',').next().unwrap_or("").trim();
                let hex = last.split_whitespace().next().unwrap_or("");
                u64::from_str_radix(hex, 16).ok().map(|t| t & !1)
            };
            let is_branch = |m: &str| {
                let m = m.split('.').next().unwrap_or("");
                m == "cbz"
                    || m == "cbnz"
                    || (m.starts_with('b') && m.len() <= 3 && m != "bic" && m != "bl")
            };
            let mut branches_to: BTreeMap<u64, Vec<usize>> = BTreeMap::new();
            for (i, c) in code.iter().enumerate() {
                if is_branch(&c.mnemonic)
                    && let Some(t) = target_of(c)
                {
                    branches_to.entry(t).or_default().push(i);
                }
            }
            let f = funcs.get_mut(start).ok_or("function vanished")?;
            if f.frame.is_none() {
                f.frame = prologue(code);
                f.from_prologue = f.frame.is_some();
            }
            for (i, insn) in code.iter().enumerate() {
                let m = insn.mnemonic.split('.').next().unwrap_or("");
                if m == "ldr"
                    && insn.args.contains("[pc")
                    && let Some(v) = comment_address(&insn.args).and_then(word)
                    && is_function(v)
                {
                    literal_loads.insert(insn.addr, v & !1);
                }
                if m == "movt"
                    && let Some(v) = word(insn.addr)
                    && is_function(v)
                {
                    literal_loads.insert(insn.addr, v & !1);
                }
                let reg = insn.args.split_whitespace().next().unwrap_or("");
                let through_register =
                    (m == "blx" || m == "bx") && reg != "lr" && target_of(insn).is_none();
                let loads_pc = m.starts_with("ldr") && insn.args.starts_with("pc,");
                let call = m == "bl" || m == "blx";
                // A call, or a branch out of the function: a tail call.
                let leaves = |t: &u64| call || !(*start..end).contains(t);
                if (call || is_branch(m))
                    && let Some(t) = target_of(insn).filter(leaves)
                {
                    f.calls.insert(t);
                    continue;
                }
                if through_register {
                    let resolved = resolve(code, i, reg, &branches_to, &word, &mut used_literals);
                    f.at.insert(insn.addr, resolved.clone());
                    for r in resolved {
                        match r {
                            Resolved::Direct(t) => {
                                f.calls.insert(t);
                            }
                            Resolved::Site(site) => {
                                f.sites.insert(site);
                            }
                            // `resolve` follows every spill to its store.
                            Resolved::Spill(_) => {
                                f.sites.insert(Site::Unknown(insn.addr));
                            }
                        }
                    }
                } else if (loads_pc || (m == "mov" && insn.args.starts_with("pc,")))
                    && !jump_table(code, i, *start..end)
                {
                    f.sites.insert(Site::Unknown(insn.addr));
                    f.at.insert(
                        insn.addr,
                        BTreeSet::from([Resolved::Site(Site::Unknown(insn.addr))]),
                    );
                }
            }
        }
        let stored = literal_loads
            .iter()
            .filter(|(at, _)| !used_literals.contains(*at))
            .map(|(_, f)| *f)
            .collect();
        Ok(Program {
            funcs,
            names,
            table_words,
            referenced,
            relocated,
            zero,
            stored,
        })
    }
}

/// The worst stack below each function.
struct Analysis<'a> {
    program: &'a Program,
    memo: HashMap<u64, Option<u64>>,
    /// The call path being explored.
    path: Vec<u64>,
    recursion: BTreeSet<String>,
    unknown_frame: BTreeSet<String>,
    /// Calls through registers: caller, site, number of targets.
    indirect: BTreeMap<(String, Site), usize>,
    /// A task this level never calls through a pointer.
    excluded: Task,
    /// The image's rules.
    rules: &'a Rules,
}

impl<'a> Analysis<'a> {
    fn new(program: &'a Program, rules: &'a Rules, excluded: Task) -> Self {
        Analysis {
            program,
            memo: HashMap::new(),
            path: Vec::new(),
            recursion: BTreeSet::new(),
            unknown_frame: BTreeSet::new(),
            indirect: BTreeMap::new(),
            excluded,
            rules,
        }
    }
}

impl Analysis<'_> {
    /// Whether the function at `addr` is `task`'s poll function (never, for [`NO_TASK`]).
    fn is_task(&self, addr: u64, task: Task) -> bool {
        let Some(f) = self.program.funcs.get(&addr) else {
            return false;
        };
        !task.name.is_empty()
            && f.name.contains(task.name)
            && (task.calls.is_empty()
                || f.calls
                    .iter()
                    .any(|c| task.calls.iter().any(|n| self.name(*c).contains(n))))
    }

    fn name(&self, addr: u64) -> &str {
        self.program
            .funcs
            .get(&addr)
            .map_or("?", |f| f.name.as_str())
    }

    /// What a call through a pointer at `site` in `caller` may reach.
    fn targets(&self, caller: &str, site: Site) -> BTreeSet<u64> {
        let p = self.program;
        let allowed = |t: &u64| {
            let name = self.name(*t);
            !self.is_task(*t, self.excluded)
                && self.rules.only_from.iter().all(|(callee, only, _)| {
                    !name.contains(callee) || only.iter().any(|o| caller.contains(o))
                })
                && self.rules.only_to.iter().all(|(callers, to, _)| {
                    !callers.iter().any(|c| caller.contains(c))
                        || to.iter().any(|t| name.contains(t))
                })
        };
        let tables = p.table_words.iter().filter(|(at, _)| match site {
            Site::Slot(k) => at.checked_sub(k).is_some_and(|start| p.is_table(start, k)),
            Site::Unknown(_) => true,
        });
        tables
            .map(|(_, f)| *f)
            .chain(p.stored.iter().copied())
            .filter(allowed)
            .collect()
    }

    /// The worst stack of a call to `addr`, and whether a bounded cycle was cut below it
    /// (then the result depends on the path, and is not memoized).
    fn worst(&mut self, addr: u64) -> (Option<u64>, bool) {
        if let Some(w) = self.memo.get(&addr) {
            return (*w, false);
        }
        let Some(f) = self.program.funcs.get(&addr) else {
            // Not a function symbol (a branch into the middle of one): nothing of its own.
            return (Some(0), false);
        };
        if let Some(i) = self.path.iter().position(|a| *a == addr) {
            let bounded = self.path.get(i..).unwrap_or_default().iter().any(|a| {
                let n = self.name(*a);
                self.rules.recursion.iter().any(|(p, _, _)| n.contains(p))
            });
            if bounded {
                // The repetitions are paid for where the bounded function multiplies.
                return (Some(0), true);
            }
            let cycle: Vec<&str> = self
                .path
                .get(i..)
                .unwrap_or_default()
                .iter()
                .map(|a| self.name(*a))
                .collect();
            self.recursion.insert(cycle.join("\n    -> "));
            return (None, false);
        }
        if f.frame.is_none() {
            self.unknown_frame.insert(f.name.clone());
        }
        let mut callees: BTreeSet<u64> = f.calls.clone();
        for site in &f.sites {
            let targets = self.targets(&f.name, *site);
            self.indirect.insert((f.name.clone(), *site), targets.len());
            callees.extend(targets);
        }
        self.path.push(addr);
        let (mut deepest, mut cut) = (Some(0u64), false);
        for c in callees {
            let (w, c_cut) = self.worst(c);
            cut |= c_cut;
            deepest = deepest.zip(w).map(|(a, b)| a.max(b));
        }
        self.path.pop();
        let mut w = f.frame.zip(deepest).map(|(a, b)| a + b);
        if let Some((_, depth, _)) = self
            .rules
            .recursion
            .iter()
            .find(|(p, _, _)| f.name.contains(p))
        {
            // `depth - 1` times around the costliest cycle, then the deepest way out.
            let cycle = self.cycle_cost(addr);
            w = w.zip(cycle).map(|(w, c)| w + (depth - 1) * c);
        }
        if !cut {
            self.memo.insert(addr, w);
        }
        (w, cut)
    }
}

impl Analysis<'_> {
    fn callees(&self, f: &Function) -> BTreeSet<u64> {
        let mut callees = f.calls.clone();
        for site in &f.sites {
            callees.extend(self.targets(&f.name, *site));
        }
        callees
    }

    /// The costliest way from `root` back to itself: the stack one more level of its
    /// recursion takes. `Some(0)` if it cannot come back.
    fn cycle_cost(&self, root: u64) -> Option<u64> {
        fn to_root(
            a: &Analysis<'_>,
            at: u64,
            root: u64,
            path: &mut Vec<u64>,
            memo: &mut HashMap<u64, Option<u64>>,
        ) -> Option<u64> {
            if at == root {
                return Some(0);
            }
            if let Some(m) = memo.get(&at) {
                return *m;
            }
            let f = a.program.funcs.get(&at)?;
            if path.contains(&at) {
                return None; // another cycle: bounded, or reported, elsewhere
            }
            path.push(at);
            let best = a
                .callees(f)
                .into_iter()
                .filter_map(|c| to_root(a, c, root, path, memo))
                .max();
            path.pop();
            let cost = best.and_then(|b| f.frame.map(|fr| fr + b));
            memo.insert(at, cost);
            cost
        }
        let f = self.program.funcs.get(&root)?;
        let mut memo = HashMap::new();
        let back = self
            .callees(f)
            .into_iter()
            .filter_map(|c| to_root(self, c, root, &mut vec![root], &mut memo))
            .max();
        Some(back.map_or(0, |b| f.frame.unwrap_or(0) + b))
    }

    /// The deepest call chain under `addr`: (frame, name) per function.
    fn deepest_path(&mut self, addr: u64) -> Vec<(Option<u64>, String)> {
        let mut out = Vec::new();
        let mut at = Some(addr);
        let mut visited = BTreeSet::new();
        while let Some(a) = at.filter(|a| visited.insert(*a)) {
            let Some(f) = self.program.funcs.get(&a) else {
                break;
            };
            out.push((f.frame, f.name.clone()));
            at = self
                .callees(f)
                .into_iter()
                .filter(|c| !visited.contains(c))
                .max_by_key(|c| self.worst(*c).0.unwrap_or(u64::MAX));
        }
        out
    }
}

/// The function named `name`, or one of whose other names it is.
fn by_name(program: &Program, name: &str) -> Option<u64> {
    let funcs = &program.funcs;
    let own = funcs.iter().find(|(_, f)| f.name == name).map(|(a, _)| *a);
    own.or_else(|| program.names.get(name).copied())
}

/// The bytes of the code and constants, to check that the analysed binary is the shipped one.
fn code(elf: &Path, sections: &[&str]) -> Result<Vec<u8>, String> {
    let data = std::fs::read(elf).map_err(|e| format!("{}: {e}", elf.display()))?;
    code_of(&data, sections).map_err(|e| format!("{}: {e}", elf.display()))
}

/// [`code`] of an ELF's bytes.
fn code_of(data: &[u8], sections: &[&str]) -> Result<Vec<u8>, String> {
    let file = object::File::parse(data).map_err(|e| e.to_string())?;
    let mut out = Vec::new();
    for name in sections {
        let section = file
            .section_by_name(name)
            .ok_or_else(|| format!("no {name} section"))?;
        out.extend_from_slice(section.data().map_err(|e| e.to_string())?);
    }
    Ok(out)
}

fn show(w: Option<u64>) -> String {
    w.map_or("unbounded".to_owned(), |w| format!("{w} B"))
}

/// Each level's label and worst stack, bytes (`None`: unbounded).
type Levels = Vec<(&'static str, Option<u64>)>;

/// Builds an image twice (shipped, analysed), checks they are the same code, and prints its
/// bound per level, deepest paths, indirect calls and rules. Returns the analysed ELF, the
/// bound (`None`: unbounded) and each level's worst stack.
fn analyse(image: &'static Image) -> Result<(PathBuf, Option<u64>, Levels), String> {
    let mut levels = Levels::new();
    let shipped = (image.shipped)()?;
    let elf = (image.analysed)()?;
    if code(&elf, image.sections)? != code(&shipped, image.sections)? {
        return Err(format!(
            "the analysed build's code differs from the shipped {}'s",
            image.what
        ));
    }
    let program = program(&elf)?;
    let funcs = &program.funcs;
    let analysis = |excluded: Task| Analysis::new(&program, &image.rules, excluded);
    println!("{:<46} {:>10}", "entry", "worst stack");
    let (task_label, task) = image.task;
    let task = funcs
        .keys()
        .find(|a| analysis(NO_TASK).is_task(**a, task))
        .copied();
    let w = task.and_then(|t| analysis(NO_TASK).worst(t).0);
    println!("{task_label:<46} {:>10}", show(w));
    let (mut recursion, mut unknown_frame, mut indirect) =
        (BTreeSet::new(), BTreeSet::new(), BTreeMap::new());
    let mut missing = BTreeSet::new();
    let mut deepest = Vec::new();
    let mut total = Some(0);
    for (i, level) in image.levels.iter().enumerate() {
        let mut a = analysis(level.excluded);
        let addr = by_name(&program, level.entry);
        if addr.is_none() {
            missing.insert(level.entry.to_owned());
        }
        let w = addr.and_then(|addr| a.worst(addr).0);
        println!("{:<46} {:>10}", level.label, show(w));
        levels.push((level.label, w));
        // A preempting level adds its hardware frame.
        let frame = if i == 0 { 0 } else { image.exception_frame };
        total = total.zip(w).map(|(t, w)| t + w + frame);
        if let Some(addr) = addr.filter(|_| level.show_path) {
            deepest.push((level.label, a.deepest_path(addr)));
        }
        recursion.append(&mut a.recursion);
        unknown_frame.append(&mut a.unknown_frame);
        indirect.append(&mut a.indirect);
    }
    println!(
        "{:<46} {:>10}",
        "bound (every level nested, with its frame)",
        show(total)
    );
    for (label, path) in deepest {
        println!("\ndeepest path in {label} (frame, function):");
        for (frame, name) in path {
            println!("  {:>6}  {name}", show(frame));
        }
    }
    let unknown = funcs.values().filter(|f| f.frame.is_none()).count();
    let prologue_count = funcs.values().filter(|f| f.from_prologue).count();
    println!(
        "\n{} functions: frames from LLVM for {}, from the prologue for {prologue_count}, unknown for {unknown}",
        funcs.len(),
        funcs.len() - prologue_count - unknown,
    );
    println!(
        "{} function pointers in tables, {} stored at run time; calls through pointers:",
        program.table_words.len(),
        program.stored.len()
    );
    for ((caller, site), n) in &indirect {
        let site = match site {
            Site::Slot(k) => format!("slot {k}"),
            Site::Unknown(at) => format!("{at:#x}"),
        };
        println!("  {n:>3} targets  {site:<8}  {caller}");
    }
    for f in &program.stored {
        println!(
            "stored at run time: {}",
            funcs.get(f).map_or("?", |f| f.name.as_str())
        );
    }
    for (pattern, depth, why) in image.rules.recursion {
        println!("recursion through `{pattern}` bounded by {depth}: {why}");
    }
    for (callee, only, why) in image.rules.only_from {
        let only = only.join("` or `");
        println!("`{callee}` is called through a pointer from `{only}` only: {why}");
    }
    for (callers, to, why) in image.rules.only_to {
        let (callers, to) = (callers.join("` or `"), to.join("` or `"));
        println!("`{callers}` calls through a vtable only `{to}`: {why}");
    }
    for level in image.levels.iter().filter(|l| !l.excluded.name.is_empty()) {
        let Task { name, calls } = level.excluded;
        let (label, why) = (level.label, level.why);
        if calls.is_empty() {
            println!("{label} never calls `{name}`: {why}");
        } else {
            let calls = calls.join("` or `");
            println!("{label} never calls the `{name}` that calls `{calls}`: {why}");
        }
    }
    let report = |title: &str, set: &BTreeSet<String>| {
        if !set.is_empty() {
            println!("{title}:");
            for n in set {
                println!("  {n}");
            }
        }
    };
    report("unbounded recursion", &recursion);
    report("reachable functions without a known frame", &unknown_frame);
    report("entry symbols not in the image", &missing);
    Ok((elf, total, levels))
}

/// The firmware's bound against the high-water mark it measures in QEMU.
fn check_firmware(elf: &Path, total: Option<u64>) -> Result<u64, String> {
    let log = firmware::run(elf)?;
    let measured = firmware::stack_high_water(&log)
        .ok_or("the firmware did not report its stack high-water mark")?;
    println!("\nmeasured in QEMU (same code, every scenario): {measured} B");
    match total {
        Some(bound) if bound >= measured => {
            println!(
                "bound {bound} B >= measured {measured} B ({:.2}x)",
                bound as f64 / measured as f64
            );
            Ok(measured)
        }
        Some(bound) => Err(format!(
            "the bound {bound} B is below the measured {measured} B: the analysis is wrong"
        )),
        None => Err("the stack is unbounded (see above)".to_owned()),
    }
}

/// A board's bound against its budget and its RAM, and against the high-water mark measured
/// where the board runs (the Pico's, on the bench).
fn check_board(
    board: firmware::Board,
    ram: u64,
    total: Option<u64>,
    measured: Option<u64>,
) -> Result<(), String> {
    let name = board.name;
    let Some(bound) = total else {
        return Err(format!("{name}: the stack is unbounded (see above)"));
    };
    println!(
        "\nbound {bound} B: {:.1} % of the budget of {BOARD_BUDGET} B, {:.1} % of the {}'s {} KiB of RAM",
        100.0 * bound as f64 / BOARD_BUDGET as f64,
        100.0 * bound as f64 / ram as f64,
        board.what,
        ram / 1024
    );
    if bound > BOARD_BUDGET {
        return Err(format!(
            "{name}: the stack bound {bound} B is over the budget of {BOARD_BUDGET} B"
        ));
    }
    if let Some(measured) = measured {
        println!(
            "measured on the bench (the emulated Pico, every scenario): {measured} B; bound {bound} B ({:.2}x)",
            bound as f64 / measured.max(1) as f64
        );
        if bound < measured {
            return Err(format!(
                "{name}: the bound {bound} B is below the {measured} B measured on the bench: the analysis is wrong"
            ));
        }
    }
    Ok(())
}

/// Which executor's tasks a job may poll through a task pointer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Side {
    /// The sensing executor's (`SWI_IRQ_1`): never the main task.
    Sensing,
    /// Thread mode's: never the sensing task.
    Deciding,
    /// A handler that polls no task.
    Any,
}

/// The Pico image's call graph, for the static timing analysis: what a call or jump through
/// a register may reach, by the same rules as the stack bound.
pub(crate) struct CallGraph {
    program: Program,
}

impl CallGraph {
    /// Reads the image built for analysis (`--emit-relocs`) at `elf`.
    pub(crate) fn of(elf: &Path) -> Result<Self, String> {
        Ok(Self {
            program: program(elf)?,
        })
    }

    /// Builds the Pico's image for analysis (the shipped code, with relocations kept) and
    /// returns its path.
    pub(crate) fn build_pico() -> Result<PathBuf, String> {
        (PICO.analysed)()
    }

    /// Builds the Pico's image for analysis from the sources at `root` into `target_dir`.
    pub(crate) fn build_pico_in(root: &Path, target_dir: &Path) -> Result<PathBuf, String> {
        build_board_at(
            &root.join("boards").join(firmware::PICO.dir),
            target_dir,
            firmware::PICO,
        )
    }

    /// The shipped Pico image's path, built.
    pub(crate) fn shipped_pico() -> Result<PathBuf, String> {
        (PICO.shipped)()
    }

    /// Whether the analysed image's code and constants are the shipped image's, byte for byte.
    pub(crate) fn same_code(analysed: &Path, shipped: &Path) -> Result<bool, String> {
        Ok(code(analysed, PICO.sections)? == code(shipped, PICO.sections)?)
    }

    /// The functions a call or jump through a register at `site`, in the function starting
    /// at `caller`, may reach; `None` if the call graph has no such site.
    pub(crate) fn targets(&self, caller: u64, site: u64, side: Side) -> Option<BTreeSet<u64>> {
        let f = self.program.funcs.get(&caller)?;
        let resolved = f.at.get(&site)?;
        let excluded = match side {
            Side::Sensing => PICO2_MAIN_TASK,
            Side::Deciding => PICO2_SENSING_TASK,
            Side::Any => NO_TASK,
        };
        let analysis = Analysis::new(&self.program, &PICO.rules, excluded);
        let mut out = BTreeSet::new();
        for r in resolved {
            match r {
                Resolved::Direct(t) => {
                    out.insert(*t);
                }
                Resolved::Site(s) => out.extend(analysis.targets(&f.name, *s)),
                Resolved::Spill(_) => {
                    out.extend(analysis.targets(&f.name, Site::Unknown(site)));
                }
            }
        }
        Some(out)
    }

    /// The start of the function named `name` (or one of its other names).
    pub(crate) fn by_name(&self, name: &str) -> Option<u64> {
        by_name(&self.program, name)
    }
}

/// Analyses the firmware (and runs it in QEMU), then the boards; prints, compares.
pub fn run() -> Result<(), String> {
    let (elf, total, qemu_levels) = analyse(&FIRMWARE)?;
    let mut failures = Vec::new();
    let mut board_levels: Vec<Levels> = Vec::new();
    let qemu = check_firmware(&elf, total)
        .map_err(|e| failures.push(e))
        .ok();
    println!("\npsmpa-pico2 (the Fetch Tea robot on a Raspberry Pi Pico 2, embassy-rp):");
    let pico2 = analyse(&PICO2)
        .and_then(|(_, total, levels)| {
            board_levels.push(levels);
            check_board(firmware::PICO2, 512 * 1024, total, None)?;
            Ok(total)
        })
        .map_err(|e| failures.push(e))
        .ok()
        .flatten();
    println!("\npsmpa-pico (the same robot on a Raspberry Pi Pico, RP2040, Cortex-M0+):");
    let pico = analyse(&PICO)
        .and_then(|(_, total, levels)| {
            board_levels.push(levels);
            let measured = pico_measured()?;
            check_board(firmware::PICO, 256 * 1024, total, Some(measured))?;
            Ok((total, measured))
        })
        .map_err(|e| failures.push(e))
        .ok();
    if !failures.is_empty() {
        return Err(failures.join("\n"));
    }
    // The figures, written where the pages show them: what was measured, never by hand.
    let b = |n: Option<u64>| n.map_or_else(|| "?".to_owned(), crate::hil::thousands);
    let cell = format!(
        "QEMU {} B ({} B measured); Pico 2 {} B; Pico {} B ({} B measured on the bench)",
        b(total),
        b(qemu),
        b(pico2),
        b(pico.and_then(|p| p.0)),
        b(pico.map(|p| p.1)),
    );
    let pico_cell = format!(
        "{} B (the bench; bound {} B)",
        b(pico.map(|p| p.1)),
        b(pico.and_then(|p| p.0))
    );
    let doc = firmware::root().join("docs/firmware.md");
    let mut qemu_table = String::from("\n| level | worst stack |\n|---|---|\n");
    for (label, w) in &qemu_levels {
        qemu_table += &format!("| {label} | {} B |\n", b(*w));
    }
    qemu_table += &format!(
        "| **bound**: every level nested, with its frame | **{} B** |\n| high-water mark measured in QEMU over all runs | {} B (bound {}) |\n",
        b(total),
        b(qemu),
        match (total, qemu) {
            (Some(t), Some(q)) if q > 0 => format!("{:.2}x", t as f64 / q as f64),
            _ => "?".to_owned(),
        }
    );
    let mut boards = String::from("\n| level | Pico 2 (RP2350) | Pico (RP2040) |\n|---|---|---|\n");
    if let [p2, p] = board_levels.as_slice() {
        for ((label, a), (other, c)) in p2.iter().zip(p) {
            let label = if label == other {
                (*label).to_owned()
            } else {
                format!("{label} / {other}")
            };
            boards += &format!("| {label} | {} B | {} B |\n", b(*a), b(*c));
        }
    }
    let share = |bound: Option<u64>, ram: u64| {
        bound.map_or("?".to_owned(), |v| {
            format!("{:.1} %", v as f64 * 100.0 / ram as f64)
        })
    };
    boards += &format!(
        "| **bound**: every level nested, with its frame | **{} B** ({} of the RP2350's 512 KiB) | **{} B** ({} of the RP2040's 256 KiB) |\n",
        b(pico2),
        share(pico2, 512 * 1024),
        b(pico.and_then(|p| p.0)),
        share(pico.and_then(|p| p.0), 256 * 1024)
    );
    // Every page's markers checked before any is written.
    crate::pages::write_pages(&[
        (firmware::root().join("README.md"), "stack", cell),
        (doc.clone(), "pico-stack", pico_cell),
        (doc.clone(), "stack-qemu", qemu_table),
        (doc, "stack-boards", boards),
    ])
}

/// The Pico image's code (its flash sections, from the ELF's bytes), hashed: which image a
/// bench measurement is of.
pub fn pico_code_hash(elf: &[u8]) -> Result<u64, String> {
    Ok(psmpa_core::record::mission_hash(&code_of(
        elf,
        PICO.sections,
    )?))
}

/// The deepest stack the bench measured on the Pico image as built now: an error, saying what
/// to run, when it never ran or ran another image (the check would be skipped or trust a
/// stale figure).
fn pico_measured() -> Result<u64, String> {
    let elf = firmware::build_board(firmware::PICO)?;
    let bytes = std::fs::read(&elf).map_err(|e| format!("{}: {e}", elf.display()))?;
    measured_on(crate::hil::stack_high_water(), pico_code_hash(&bytes)?)
}

/// The bench's measurement `stored` (bytes, the code hash it ran) if it is of the image whose
/// code hash is `now`.
fn measured_on(stored: Option<(u64, Option<u64>)>, now: u64) -> Result<u64, String> {
    match stored {
        None => Err(
            "psmpa-pico: no stack measured on the bench (target/hil/stack.json): run `cargo xtask hil` first"
                .to_owned(),
        ),
        Some((_, hash)) if hash != Some(now) => Err(
            "psmpa-pico: target/hil/stack.json was measured on another build of the image: run `cargo xtask hil` again"
                .to_owned(),
        ),
        Some((bytes, _)) => Ok(bytes),
    }
}

#[cfg(test)]
mod tests;

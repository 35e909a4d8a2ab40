//! `cargo xtask wcet`: static worst-case execution times of the Pico image's jobs, in cycles of
//! the RP2040's Cortex-M0+, from the binary alone.
//!
//! * Code: the image built for the stack analysis (the shipped code, relocations kept; checked
//!   byte for byte against the shipped image), decoded by `yaxpeax-arm` from each function's
//!   entry ([`cfg`](mod@cfg)), costed by the Cortex-M0+ TRM's cycle table ([`thumb`]).
//! * Calls: direct calls by their target's worst case; calls through registers by the worst of
//!   what the stack analyser's call graph says they may reach (the sensing executor never polls
//!   the main task, and the thread-mode executor never the sensing task). Recursion is refused.
//! * Loops: counted loops are bounded from the code; any other needs an annotation in
//!   `boards/pico/wcet-loops.json`, keyed by the source function the loop is written in (as the
//!   debug information names it) and checked on the bench. A loop with neither fails, naming
//!   its function and address.
//! * Memory: the stack, SRAM and peripherals as the TRM and the RP2040 datasheet give them;
//!   the Pico's image runs from SRAM (its `memory.x`), so code and constants cost the cycle
//!   table alone. Code or constants in flash ([`XIP`]) would be charged the XIP cache's misses
//!   ([`XIP_FILL`]).
//!
//! Jobs: the three handlers that release or run sensing work (exception entry and return
//! included), the longest critical section, and one poll of the main task (the deciding side).

mod cfg;
pub mod emulated;
pub mod mutants;
pub mod thumb;

#[cfg(test)]
mod tests;

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::process::Command;

use object::{Object, ObjectSection, ObjectSymbol, RelocationKind, SymbolKind};
use serde::{Deserialize, Serialize};

use crate::hil::Ending;
use crate::hil::bound::{self, Costs};
use crate::stack::{CallGraph, Side};

/// Exception entry on the Cortex-M0+, cycles: the TRM's interrupt latency with zero wait
/// states (stacking eight registers, fetching the vector).
pub const EXCEPTION_ENTRY: u64 = 15;
/// Exception return, cycles: unstacking the same eight registers; taken as long as the entry.
pub const EXCEPTION_RETURN: u64 = 15;

// The memory model of the RP2040 as the analysis charges it.
//
/// Code and constants run from flash through the XIP cache: 16 KiB, two-way set-associative,
/// 8-byte lines (RP2040 datasheet 2.6.3.1). A miss reads the line over QSPI: boot2 (W25Q080,
/// `PICO_FLASH_SPI_CLKDIV` 2) keeps the flash in quad continuous-read mode, so a line costs 8
/// clocks of address and mode, 4 dummy clocks and 16 of data, 28 SPI clocks at half the system
/// clock: 56 cycles, plus [`XIP_OVERHEAD`] for the SSI's chip select and the bus. A job starts
/// with a cold cache: each line of code (and of its literal pools and jump tables) it may touch
/// misses once, as long as no cache set holds more of those lines than the cache's two ways;
/// a line of a set that does misses every time control enters it. A load the analysis cannot
/// place may read a constant: it is charged a miss.
pub const XIP_FILL: u64 = 56;
/// The SSI's chip-select and the AHB's hops around a fill: an allowance, not a measurement.
pub const XIP_OVERHEAD: u64 = 8;
/// A miss.
pub const XIP_MISS: u64 = XIP_FILL + XIP_OVERHEAD;
/// Where flash is read through the XIP cache (its four aliases, RP2040 datasheet 2.6.3.1):
/// code and constants anywhere else (SRAM, where the Pico's image runs) cost the cycle table
/// alone, with no wait state (the Cortex-M0+ is SRAM's only master: one core, no DMA).
pub const XIP: std::ops::Range<u64> = 0x1000_0000..0x1400_0000;
/// An XIP cache line, bytes.
const LINE: u64 = 8;
/// Sets of the XIP cache (16 KiB / 2 ways / 8 bytes).
const SETS: u64 = 1024;
/// Ways.
const WAYS: usize = 2;

/// Functions that never return, taken as such without analysis: the panic machinery (which
/// logs through defmt, whose lock may panic again: a cycle the stack bound counts twice). A
/// job that panics does not complete: the handler stops the motors and the watchdog resets.
const DIVERGES: &[&str] = &["core::panicking::panic_fmt", "__rustc::rust_begin_unwind"];

/// The memory functions of core's builtins, and the register their length is in: their loops
/// move at least one byte an iteration, so the length bounds each.
const LENGTHS: &[(&str, u8)] = &[
    ("__aeabi_memcpy", 2),
    ("__aeabi_memcpy4", 2),
    ("__aeabi_memcpy8", 2),
    ("__aeabi_memmove", 2),
    ("__aeabi_memmove4", 2),
    ("__aeabi_memmove8", 2),
    ("__aeabi_memset", 1),
    ("__aeabi_memset4", 1),
    ("__aeabi_memset8", 1),
    ("__aeabi_memclr", 1),
    ("__aeabi_memclr4", 1),
    ("__aeabi_memclr8", 1),
    ("compiler_builtins::mem::memcpy", 2),
    ("compiler_builtins::mem::memmove", 2),
    ("compiler_builtins::mem::memset", 2),
    ("memcpy", 2),
    ("memmove", 2),
    ("memset", 2),
];

/// Where a call through a register is a waker's: the inline frames of `core::task::Waker`'s
/// methods and trait implementations.
const WAKER_CALLS: &[&str] = &[
    "<core::task::wake::Waker>::",
    "<core::task::wake::Waker as ",
];

/// The functions of the image's waker vtables: embassy's executor's (and core's no-op waker).
const WAKER_FNS: &[&str] = &["embassy_executor::raw::waker::", "core::task::wake::"];

/// Core's formatting traits and their implementations.
const FORMATTING: &[&str] = &["core::fmt::", "<core::fmt::"];

/// Code that writes to a formatter's output.
const FORMATTERS: &[&str] = &[
    "<core::fmt::Formatter>::",
    "<char as core::fmt::",
    "PadAdapter",
];

/// Implementations of `fmt::Write` (and its provided methods).
const FMT_WRITERS: &[&str] = &[" as core::fmt::Write>::", "core::fmt::Write::"];

/// Implementations of `Display` and `Debug`.
const FMT_IMPLS: &[&str] = &[" as core::fmt::Display>::fmt", " as core::fmt::Debug>::fmt"];

/// Embassy's executor, the only caller of a task's entry points.
const EXECUTOR: &[&str] = &[
    "embassy_executor::raw::Executor::",
    "embassy_executor::raw::SyncExecutor::",
];

/// A task's entry points: its poll function, and the one a finished task's header holds.
const TASKS: &[&str] = &[TASK_POLL, "embassy_executor::raw::poll_exited"];

/// A task's poll function.
const TASK_POLL: &str = "embassy_executor::raw::TaskStorage<";
/// The body of the task the sensing executor polls.
const SENSING_TASK: &str = "psmpa_board_rp::__sensing_task::";

thread_local! {
    /// The annotations that matched a loop or a call: `(false, i)` for `loops[i]`, `(true, i)`
    /// for `lengths[i]`.
    static USED: std::cell::RefCell<BTreeSet<(bool, usize)>> = const {
        std::cell::RefCell::new(BTreeSet::new())
    };
}

/// The committed loop annotations.
#[derive(Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Annotations {
    /// What the file is.
    pub about: String,
    pub loops: Vec<Annotation>,
    /// Lengths passed to `memcpy`, `memset` ... that the code before a call does not show.
    #[serde(default)]
    pub lengths: Vec<Annotation>,
}

/// One loop the code cannot bound by itself.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Annotation {
    /// The source function the loop is written in, as the debug information names it.
    pub function: String,
    /// Rounds of the loop as written per entry into it (a round is one back edge for each of
    /// the machine loop's entries); for a length, bytes.
    pub bound: u64,
    /// Why the code bounds it so.
    pub why: String,
    /// The jobs it holds for (all if empty): a loop shared by two executors may have a
    /// different bound in each.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub jobs: Vec<String>,
    /// Other functions the debug information may say the same loop is written in: where a
    /// loop of an inlined function shares the caller's glue (a spill, a state store), one
    /// build puts it in the caller and the next in the callee.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub also: Vec<String>,
    /// A function the loop must be inlined into for the annotation to hold (a busy wait the
    /// design declares, and no other use of the same helper).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub within: Option<String>,
    /// A busy wait on time the design declares: bounded by its duration (which the bound adds
    /// elsewhere), not by a count, so the bench does not count its back edges.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub timed: bool,
}

impl Annotation {
    fn applies_to(&self, job: &str) -> bool {
        self.jobs.is_empty() || self.jobs.iter().any(|j| j == job)
    }

    /// How narrowly it applies: an entry of a function inlined into a given one (`within`)
    /// before one of given jobs, before a general one. Of the annotations that match a loop,
    /// the narrowest bounds it, whatever their order in the file.
    fn narrowness(&self) -> u8 {
        u8::from(self.within.is_some()) * 2 + u8::from(!self.jobs.is_empty())
    }

    /// What tells it from another of the same function.
    fn key(&self) -> String {
        let mut jobs = self.jobs.clone();
        jobs.sort();
        format!(
            "{} (jobs [{}]{})",
            self.function,
            jobs.join(", "),
            self.within
                .as_ref()
                .map_or(String::new(), |w| format!(", within {w}"))
        )
    }

    /// Why it does not apply to a loop of `job` written in a function inlined into `chain`
    /// (outermost first), if it names the loop's function.
    fn mismatch(&self, function: &str, job: &str, chain: &[String]) -> Option<String> {
        if self.function != function && !self.also.iter().any(|a| a == function) {
            return None;
        }
        if !self.applies_to(job) {
            return Some(format!(
                "its annotation of {} is for the jobs {:?}, not {job}",
                self.function, self.jobs
            ));
        }
        let w = self.within.as_ref()?;
        (!chain.contains(w)).then(|| {
            format!(
                "its annotation of {} holds within {w:?}, which is not among the functions the loop is inlined into ({})",
                self.function,
                chain.join(", ")
            )
        })
    }
}

/// The annotation of `loops` that bounds a loop of `job` written in `function`, inlined into
/// `chain` (outermost first): of those that match, the narrowest, whatever their order.
fn pick<'a>(
    loops: &'a [Annotation],
    function: &str,
    job: &str,
    chain: &[String],
) -> Option<(usize, &'a Annotation)> {
    loops
        .iter()
        .enumerate()
        .filter(|(_, a)| {
            (a.function == function || a.also.iter().any(|f| f == function))
                && a.applies_to(job)
                && a.within.as_ref().is_none_or(|w| chain.contains(w))
        })
        .max_by_key(|(i, a)| (a.narrowness(), std::cmp::Reverse(*i)))
}

/// The jobs an annotation may name (`jobs`).
const JOB_NAMES: [&str; 5] = ["sensing_poll", "alarm", "gpio", "deciding", "critical"];

impl Annotations {
    /// The file.
    pub fn path() -> PathBuf {
        crate::firmware::root().join("boards/pico/wcet-loops.json")
    }

    fn load() -> Result<Self, String> {
        let path = Self::path();
        // A regular file of at most 1 MiB: a FIFO would block the analysis for ever.
        let bytes = psmpa_sim::cli::files::read_input(&path, "loop annotations")?;
        let text = String::from_utf8(bytes).map_err(|e| {
            format!(
                "{}: not UTF-8 text (byte {}): a JSON file of loop annotations",
                path.display(),
                e.utf8_error().valid_up_to()
            )
        })?;
        Self::parse(&text)
    }

    /// The annotations in `text` (the file's).
    pub fn parse(text: &str) -> Result<Self, String> {
        let path = Self::path();
        // Strict JSON first: a duplicate key (a second `bound` that serde_json would take
        // silently), a byte order mark, a file that is not JSON, named as such.
        let text = psmpa_sim::json::strict_file(&path, text.as_bytes())?;
        let a: Self =
            serde_json::from_slice(&text).map_err(|e| format!("{}: {e}", path.display()))?;
        for (list, entries) in [("loops", &a.loops), ("lengths", &a.lengths)] {
            let mut seen = BTreeSet::new();
            for l in entries {
                if l.function.trim().is_empty() || l.why.trim().is_empty() {
                    return Err(format!(
                        "{}: every entry of {list} needs a function and a reason (why)",
                        path.display()
                    ));
                }
                if let Some(j) = l.jobs.iter().find(|j| !JOB_NAMES.contains(&j.as_str())) {
                    return Err(format!(
                        "{}: {list}: the annotation of {} names the job {j:?}: no such job ({})",
                        path.display(),
                        l.function,
                        JOB_NAMES.join(", ")
                    ));
                }
                if l.within.as_ref().is_some_and(|w| w.trim().is_empty()) {
                    return Err(format!(
                        "{}: {list}: the annotation of {} has an empty within",
                        path.display(),
                        l.function
                    ));
                }
                if !seen.insert(l.key()) {
                    return Err(format!(
                        "{}: {list}: two annotations of {}: one each",
                        path.display(),
                        l.key()
                    ));
                }
            }
        }
        Ok(a)
    }
}

/// A job of the response-time analysis.
#[derive(Clone, Copy, Debug)]
struct JobSpec {
    name: &'static str,
    /// The function it runs.
    entry: &'static str,
    /// An exception handler: entry and return are added.
    handler: bool,
    side: Side,
}

/// The jobs, as `bound.rs`'s [`crate::hil`] costs name them.
const JOBS: &[JobSpec] = &[
    JobSpec {
        name: "sensing_poll",
        entry: "SWI_IRQ_1",
        handler: true,
        side: Side::Sensing,
    },
    JobSpec {
        name: "alarm",
        entry: "TIMER_IRQ_0",
        handler: true,
        side: Side::Any,
    },
    JobSpec {
        name: "gpio",
        entry: "IO_IRQ_BANK0",
        handler: true,
        side: Side::Any,
    },
    JobSpec {
        name: "deciding",
        entry: MAIN_TASK,
        handler: false,
        side: Side::Deciding,
    },
];

/// The body of the control task, whose poll is the deciding side's step.
const MAIN_TASK: &str = "psmpa_board_rp::__control_task::";

/// One job's result.
#[derive(Clone, Debug, Serialize)]
pub struct JobWcet {
    pub job: String,
    pub cycles: u64,
    /// The worst the bench measured of this job over every shipped run, as the committed
    /// budget records it (`cargo xtask hil --calibrate`); `None` without one.
    pub measured_worst_cycles: Option<u64>,
    /// Of which: the XIP cache's misses.
    pub xip_cycles: u64,
    /// Lines of code in flash it may run (none for code in SRAM).
    pub lines: usize,
    pub loops: Vec<LoopReport>,
    /// The function it runs (0 for the critical section, found in many).
    #[serde(skip)]
    pub entry: u64,
}

/// A loop as the report names it.
#[derive(Clone, Debug, Serialize)]
pub struct LoopReport {
    pub function: String,
    pub address: String,
    pub bound: u64,
    pub source: String,
    /// Cycles of its longest iteration.
    pub iteration_cycles: u64,
    /// Where it is, for the bench's count of its back edges.
    #[serde(skip)]
    pub at: BenchLoop,
}

/// An annotated loop as the bench checks it: per entry into the loop (a jump into its body from
/// the rest of its function, or a call of the function where it starts in the loop), the back
/// edges taken (a latch to an entry) must not exceed `bound`.
#[derive(Clone, Debug, Default, Serialize)]
pub struct BenchLoop {
    /// The annotation's key (the source function), or empty for a loop bounded from the code.
    pub annotation: String,
    /// Whether the bench counts it: an annotation of `loops` bounds it, not `timed`.
    #[serde(skip)]
    pub counted: bool,
    pub bound: u64,
    /// The machine function holding it: `[start, end)`.
    pub function: [u64; 2],
    pub entries: Vec<u64>,
    pub latches: Vec<u64>,
    pub body: Vec<u64>,
    /// Return addresses of latches that are calls: a return there from the callee is a back
    /// edge (the latch itself only leaves for the callee).
    pub returns: Vec<u64>,
    /// The bound a job at each exception level takes (0 thread mode, 16 + n interrupt n): an
    /// annotation may hold for some jobs only, and the bench checks each where its job runs.
    #[serde(skip)]
    pub levels: BTreeMap<u32, u64>,
    /// The bound a job that runs at any level takes (the critical section's), if one does.
    #[serde(skip)]
    pub any_level: Option<u64>,
}

impl BenchLoop {
    /// Loop `l` of the machine function `function`, bounded by `annotation` if one did.
    fn of(l: &cfg::Loop, function: [u64; 2], annotation: Option<&Annotation>) -> Self {
        Self {
            annotation: annotation.map(|a| a.function.clone()).unwrap_or_default(),
            counted: annotation.is_some_and(|a| !a.timed),
            bound: l.bound,
            function,
            entries: l.entries.clone(),
            latches: l.latches.clone(),
            body: l.body.clone(),
            returns: l.returns.clone(),
            levels: BTreeMap::new(),
            any_level: None,
        }
    }

    /// The most back edges an entry the analysis took at exception `level`, if a job there
    /// took any. A handler's job is all the handler runs, so its own bound holds there
    /// whatever the critical section took; thread mode runs more than the deciding job, so
    /// there the larger holds.
    pub fn bound_at(&self, level: u32) -> Option<u64> {
        match (self.levels.get(&level), self.any_level) {
            (Some(a), _) if level >= 16 => Some(*a),
            (Some(a), Some(b)) => Some((*a).max(b)),
            (a, b) => a.copied().or(b),
        }
    }

    /// Takes `bound`, what `job` took for this loop: at the job's exception level, and in
    /// the most of all.
    fn bounded_by(&mut self, job: &str, bound: u64) {
        self.bound = self.bound.max(bound);
        let at = match level_of(job) {
            Some(level) => self.levels.entry(level).or_insert(0),
            None => self.any_level.get_or_insert(0),
        };
        *at = (*at).max(bound);
    }
}

/// The exception level a job runs at: its handler's, thread mode for the deciding job, `None`
/// for the critical section (at any).
fn level_of(job: &str) -> Option<u32> {
    match job {
        "sensing_poll" => Some(bound::EXC_SENSING),
        "alarm" => Some(bound::EXC_ALARM),
        "gpio" => Some(bound::EXC_GPIO),
        "deciding" => Some(0),
        _ => None,
    }
}

/// The image as the analysis reads it.
struct Elf {
    text_addr: u64,
    text: Vec<u8>,
    /// Relocated words in the code (jump tables, literal pools).
    words: BTreeMap<u64, u64>,
    /// Functions: start -> (end, name).
    funcs: BTreeMap<u64, (u64, String)>,
    /// `.rodata`'s addresses.
    rodata: std::ops::Range<u64>,
    /// Where the vector table the handlers are fetched from is (VTOR).
    vectors: u64,
    path: PathBuf,
}

impl Elf {
    fn read(path: &Path) -> Result<Self, String> {
        let data = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let elf = object::File::parse(&*data).map_err(|e| e.to_string())?;
        let text = elf
            .section_by_name(".text")
            .ok_or("the image has no .text")?;
        let bytes = text.data().map_err(|e| e.to_string())?.to_vec();
        let mut words = BTreeMap::new();
        for (offset, reloc) in text.relocations() {
            if reloc.kind() != RelocationKind::Absolute || reloc.size() != 32 {
                continue;
            }
            let at = offset.checked_sub(text.address()).unwrap_or(offset) as usize;
            if let Some(w) = bytes
                .get(at..at + 4)
                .and_then(|w| <[u8; 4]>::try_from(w).ok())
            {
                words.insert(offset, u64::from(u32::from_le_bytes(w)));
            }
        }
        let mut funcs = BTreeMap::new();
        for s in elf.symbols().filter(|s| s.kind() == SymbolKind::Text) {
            if s.size() > 0 {
                let start = s.address() & !1;
                let name = format!("{:#}", rustc_demangle::demangle(s.name().unwrap_or("?")));
                funcs.insert(start, (start + s.size(), name));
            }
        }
        let rodata = elf
            .section_by_name(".rodata")
            .map_or(0..0, |r| r.address()..r.address() + r.size());
        let vectors = elf
            .section_by_name(".vector_table")
            .ok_or("the image has no .vector_table")?
            .address();
        Ok(Self {
            rodata,
            vectors,
            text_addr: text.address(),
            text: bytes,
            words,
            funcs,
            path: path.to_owned(),
        })
    }

    fn name(&self, addr: u64) -> String {
        self.funcs.range(..=addr).next_back().map_or_else(
            || format!("{addr:#x}"),
            |(s, (_, n))| {
                if *s == addr {
                    n.clone()
                } else {
                    format!("{n}+{:#x}", addr - s)
                }
            },
        )
    }
}

/// The source function each address is written in: the innermost frame of its inline chain
/// that is not the core library's or the register access crate's (a loop over a slice is the
/// caller's loop), as `addr2line` reads the debug information.
fn source_functions(elf: &Path, addrs: &[u64]) -> Result<HashMap<u64, Vec<String>>, String> {
    if addrs.is_empty() {
        return Ok(HashMap::new());
    }
    let out = Command::new("arm-none-eabi-addr2line")
        .arg("-e")
        .arg(elf)
        .args(["-f", "-i", "-C", "-a"])
        .args(addrs.iter().map(|a| format!("{a:#x}")))
        .output()
        .map_err(|e| format!("cannot run arm-none-eabi-addr2line: {e}"))?;
    if !out.status.success() {
        return Err("arm-none-eabi-addr2line failed".to_owned());
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let mut map: HashMap<u64, Vec<String>> = HashMap::new();
    let mut current = None;
    let mut lines = text.lines();
    while let Some(line) = lines.next() {
        if let Some(hex) = line.strip_prefix("0x") {
            current = u64::from_str_radix(hex, 16).ok();
            continue;
        }
        let _location = lines.next();
        if let Some(a) = current {
            map.entry(a).or_default().push(line.to_owned());
        }
    }
    Ok(map)
}

/// Whether a frame is library plumbing rather than where a loop is written.
fn plumbing(function: &str) -> bool {
    ["core::", "<core::", "rp_pac::", "<rp_pac::"]
        .iter()
        .any(|p| function.starts_with(p))
}

/// The analysis of one job: the image, the call graph, what it has found.
struct Job<'a> {
    elf: &'a Elf,
    graph: &'a CallGraph,
    annotations: &'a Annotations,
    sources: &'a HashMap<u64, Vec<String>>,
    side: Side,
    /// The job's name, for annotations that hold for some jobs only.
    job: &'a str,
    memo: HashMap<u64, Option<u64>>,
    /// The annotation (its index in `annotations.loops`) that bounds each loop, by header.
    annotated: std::cell::RefCell<HashMap<u64, usize>>,
    /// Memory functions' worst cases by (address, length).
    by_length: HashMap<(u64, u64), Option<u64>>,
    /// The length the memory function being analysed moves at most.
    length: Option<u64>,
    path: Vec<u64>,
    loops: Vec<LoopReport>,
    /// Loop headers without a bound or annotation: asked for their source.
    /// Loops without a bound: (function, back edge, the source function it is written in).
    unbounded: BTreeSet<(u64, u64, String)>,
    /// Calls to a memory function whose length nothing bounds.
    unsized_calls: BTreeSet<u64>,
    /// The lines of code and literals it may touch.
    touched: BTreeSet<u64>,
    reached: BTreeSet<u64>,
    /// Lines whose cache set holds more than the ways.
    conflicted: BTreeSet<u64>,
    /// Whether a line of `.rodata` is among them.
    constants_conflict: bool,
}

impl cfg::Image for Job<'_> {
    fn code(&self, addr: u64) -> Option<&[u8]> {
        let at = usize::try_from(addr.checked_sub(self.elf.text_addr)?).ok()?;
        self.elf.text.get(at..)
    }

    fn word(&self, addr: u64) -> Option<u64> {
        self.elf.words.get(&addr).copied()
    }

    fn call(&mut self, addr: u64) -> Result<Option<u64>, String> {
        if let Some(w) = self.memo.get(&addr) {
            return Ok(*w);
        }
        if self.path.contains(&addr) {
            return Err(format!("recursion through {}", self.elf.name(addr)));
        }
        let Some((end, name)) = self.elf.funcs.get(&addr).cloned() else {
            return Err(format!("a call to {addr:#x}, which starts no function"));
        };
        if DIVERGES.contains(&name.as_str()) {
            self.memo.insert(addr, None);
            return Ok(None);
        }
        self.reached.insert(addr);
        self.path.push(addr);
        let result = cfg::analyse(self, addr, end);
        self.path.pop();
        let worst = result.map_err(|e| format!("{}: {e}", self.elf.name(addr)))?;
        self.touched.extend(worst.touched.iter().map(|a| a / LINE));
        let end = self.elf.funcs.get(&addr).map_or(addr, |(e, _)| *e);
        for l in &worst.loops {
            let at = BenchLoop::of(l, [addr, end], self.annotation_of(l.header));
            self.loops.push(LoopReport {
                function: self.elf.name(addr),
                address: format!("{:#x}", l.header),
                bound: l.bound,
                source: l.source.clone(),
                iteration_cycles: l.iteration,
                at,
            });
        }
        self.memo.insert(addr, worst.cycles);
        Ok(worst.cycles)
    }

    fn length_register(&self, addr: u64) -> Option<u8> {
        let (_, name) = self.elf.funcs.get(&addr)?;
        LENGTHS.iter().find(|(n, _)| n == name).map(|(_, r)| *r)
    }

    fn length_at(&mut self, _function: u64, site: u64) -> Option<(u64, String)> {
        if let Some(n) = self.length {
            // A memory function passing on part of its own length.
            return Some((n, format!("part of a call's {n} bytes")));
        }
        let found = self
            .frames(site)
            .into_iter()
            .find_map(|f| {
                self.annotations
                    .lengths
                    .iter()
                    .enumerate()
                    .filter(|(_, a)| a.function == f && a.applies_to(self.job))
                    .max_by_key(|(i, a)| (a.narrowness(), std::cmp::Reverse(*i)))
            })
            .map(|(i, a)| {
                USED.with(|u| u.borrow_mut().insert((true, i)));
                (a.bound, a.why.clone())
            });
        if found.is_none() {
            self.unsized_calls.insert(site);
        }
        found.or(Some((0, String::new())))
    }

    fn call_with_length(&mut self, addr: u64, length: u64) -> Result<Option<u64>, String> {
        if let Some(w) = self.by_length.get(&(addr, length)) {
            return Ok(*w);
        }
        let Some((end, _)) = self.elf.funcs.get(&addr).cloned() else {
            return Err(format!("a call to {addr:#x}, which starts no function"));
        };
        self.reached.insert(addr);
        let outer = self.length.replace(length);
        let result = cfg::analyse(self, addr, end);
        self.length = outer;
        let worst = result.map_err(|e| format!("{}: {e}", self.elf.name(addr)))?;
        self.touched.extend(worst.touched.iter().map(|a| a / LINE));
        self.by_length.insert((addr, length), worst.cycles);
        Ok(worst.cycles)
    }

    fn indirect(&mut self, function: u64, site: u64) -> Result<Vec<u64>, String> {
        let mut targets = self
            .graph
            .targets(function, site, self.side)
            .ok_or_else(|| format!("the call graph has no call through a register at {site:#x}"))?;

        // A call through a vtable reaches an implementation of its own family, not whatever
        // other table holds a function at the same offset: a waker's functions from a
        // Waker's calls (the debug information shows the call inlined from core's Waker),
        // core's formatting traits from core's formatting code, a task's poll function from
        // embassy's executor; every other call, none of these.
        let frames: Vec<String> = self.sources.get(&site).cloned().unwrap_or_default();
        let caller = self.elf.name(function);
        let in_frames = |family: &[&str]| {
            frames
                .iter()
                .chain([&caller])
                .any(|f| family.iter().any(|p| f.starts_with(p) || f.contains(p)))
        };
        let waker = frames
            .iter()
            .any(|f| WAKER_CALLS.iter().any(|w| f.starts_with(w)));
        let formatting = in_frames(FORMATTING);
        let executor = in_frames(EXECUTOR);
        let of = |t: &u64, family: &[&str]| {
            let name = self.elf.name(*t);
            family
                .iter()
                .any(|p| name.starts_with(p) || name.contains(p))
        };
        let candidates = targets.clone();
        targets.retain(|t| {
            (waker == of(t, WAKER_FNS))
                && (formatting == of(t, FORMATTING))
                && (executor || !of(t, TASKS))
        });
        if targets.is_empty() && !waker {
            // The debug information does not show the call inlined from core's Waker (code
            // shared by two inlined paths keeps one path's frames, which one depends on the
            // link): every candidate but another family's, a waker's functions included.
            targets = candidates;
            targets.retain(|t| (formatting == of(t, FORMATTING)) && (executor || !of(t, TASKS)));
        }
        // An executor polls its own tasks: the sensing executor only the sensing task,
        // thread mode every other one (which task a poll function polls, by the debug
        // information of its code).
        targets.retain(|t| {
            if !self.elf.name(*t).starts_with(TASK_POLL) {
                return true;
            }
            let sensing = self.polls_task(*t, SENSING_TASK);
            match self.side {
                Side::Sensing => sensing,
                Side::Deciding => !sensing,
                Side::Any => true,
            }
        });
        if targets.is_empty() && formatting {
            // A call through a formatting trait object whose vtable the call graph did not
            // find (a vtable inside a larger constant): from a formatter, its output (any
            // implementation of `fmt::Write`); from elsewhere in core's formatting, any
            // implementation of `Display` or `Debug`.
            let family = if in_frames(FORMATTERS) {
                FMT_WRITERS
            } else {
                FMT_IMPLS
            };
            targets = self
                .elf
                .funcs
                .iter()
                .filter(|(_, (_, n))| family.iter().any(|p| n.contains(p)))
                .map(|(f, _)| *f)
                .collect();
        }
        if targets.is_empty() {
            return Err(format!(
                "nothing known for the call through a register at {site:#x} (inlined from: {})",
                if frames.is_empty() {
                    "no debug information".to_owned()
                } else {
                    frames.join(" < ")
                }
            ));
        }
        Ok(targets.into_iter().collect())
    }

    fn annotation(&self, _function: u64, site: &cfg::Site) -> Option<(u64, String)> {
        if let Some(n) = self.length {
            return Some((n, format!("moves at most {n} bytes (the call's length)")));
        }
        let (function, chain) = self.loop_function(site)?;
        let (i, found) = pick(&self.annotations.loops, &function, self.job, &chain)?;
        USED.with(|u| u.borrow_mut().insert((false, i)));
        self.annotated.borrow_mut().insert(site.header, i);
        Some((found.bound, found.why.clone()))
    }

    fn unbounded(&mut self, function: u64, site: &cfg::Site) -> Result<u64, String> {
        let at = site.latches.first().copied().unwrap_or(site.header);
        let written = self
            .loop_function(site)
            .map(|(f, chain)| {
                // An annotation of this function that does not apply (a job or a `within`
                // mistyped) is named: the loop is annotated, but not for here.
                let why = self
                    .annotations
                    .loops
                    .iter()
                    .find_map(|a| a.mismatch(&f, self.job, &chain))
                    .map_or(String::new(), |w| format!("; {w}"));
                let outer: Vec<&String> = chain.iter().rev().skip(1).take(2).collect();
                let f = format!("{f}{why}");
                match outer.as_slice() {
                    [] => f,
                    o => format!(
                        "{f} (inlined into {})",
                        o.iter()
                            .map(|s| s.as_str())
                            .collect::<Vec<_>>()
                            .join(", into ")
                    ),
                }
            })
            .unwrap_or_else(|| "no function the debug information names".to_owned());
        self.unbounded.insert((function, at, written));
        Ok(0)
    }

    fn fetch(&self, addr: u64, branched: bool) -> u64 {
        let line = addr / LINE;
        let enters = branched || addr.is_multiple_of(LINE);
        if enters && self.conflicted.contains(&line) {
            XIP_MISS
        } else {
            0
        }
    }

    fn unplaced_load(&self) -> u64 {
        // A load through a pointer may read a constant whose line another evicted.
        if self.constants_conflict { XIP_MISS } else { 0 }
    }
}

/// Every loop's back edges and every call through a register, in every function, for one
/// batch of `addr2line`.
fn loop_headers(elf: &Elf, graph: &CallGraph, annotations: &Annotations) -> Vec<u64> {
    // A first pass over each job with every loop bounded once collects the headers.
    struct Collect<'a> {
        inner: Job<'a>,
        headers: BTreeSet<u64>,
    }
    impl cfg::Image for Collect<'_> {
        fn code(&self, addr: u64) -> Option<&[u8]> {
            self.inner.code(addr)
        }
        fn word(&self, addr: u64) -> Option<u64> {
            self.inner.word(addr)
        }
        fn call(&mut self, addr: u64) -> Result<Option<u64>, String> {
            if let Some(w) = self.inner.memo.get(&addr) {
                return Ok(*w);
            }
            if self.inner.path.contains(&addr) {
                return Ok(Some(0));
            }
            let Some((end, _)) = self.inner.elf.funcs.get(&addr).cloned() else {
                return Ok(Some(0));
            };
            self.inner.path.push(addr);
            let r = cfg::analyse(self, addr, end);
            self.inner.path.pop();
            let w = r.map(|w| w.cycles).unwrap_or(Some(0));
            self.inner.memo.insert(addr, w);
            Ok(w)
        }
        fn length_at(&mut self, _function: u64, site: u64) -> Option<(u64, String)> {
            self.headers.insert(site);
            Some((0, String::new()))
        }
        fn length_register(&self, addr: u64) -> Option<u8> {
            self.inner.length_register(addr)
        }
        fn indirect(&mut self, function: u64, site: u64) -> Result<Vec<u64>, String> {
            // Every target the call graph knows: the narrowing needs these sites' sources.
            self.headers.insert(site);
            let side = self.inner.side;
            Ok(self
                .inner
                .graph
                .targets(function, site, side)
                .unwrap_or_default()
                .into_iter()
                .collect())
        }
        fn annotation(&self, _f: u64, _site: &cfg::Site) -> Option<(u64, String)> {
            Some((1, String::new()))
        }
    }
    let empty = HashMap::new();
    let mut headers = BTreeSet::new();
    // Tasks' poll functions, sampled every 16 bytes: which task each polls.
    for (start, (end, name)) in &elf.funcs {
        if name.starts_with(TASK_POLL) {
            headers.extend((*start..*end).step_by(16));
        }
    }
    for side in [Side::Sensing, Side::Deciding, Side::Any] {
        let mut c = Collect {
            inner: Job::new(elf, graph, annotations, &empty, side, ""),
            headers: BTreeSet::new(),
        };
        for (start, (end, _)) in &elf.funcs {
            c.inner.path.clear();
            if let Ok(w) = cfg::analyse(&mut c, *start, *end) {
                c.headers
                    .extend(w.loops.iter().flat_map(|l| l.body.iter().copied()));
            }
        }
        headers.extend(c.headers);
    }
    headers.into_iter().collect()
}

impl<'a> Job<'a> {
    /// The annotation that bounded the loop at `header`, if one did.
    fn annotation_of(&self, header: u64) -> Option<&'a Annotation> {
        let i = self.annotated.borrow().get(&header).copied()?;
        self.annotations.loops.get(i)
    }

    fn new(
        elf: &'a Elf,
        graph: &'a CallGraph,
        annotations: &'a Annotations,
        sources: &'a HashMap<u64, Vec<String>>,
        side: Side,
        job: &'a str,
    ) -> Self {
        Self {
            elf,
            graph,
            annotations,
            sources,
            side,
            job,
            memo: HashMap::new(),
            annotated: std::cell::RefCell::new(HashMap::new()),
            by_length: HashMap::new(),
            length: None,
            path: Vec::new(),
            loops: Vec::new(),
            unbounded: BTreeSet::new(),
            unsized_calls: BTreeSet::new(),
            touched: BTreeSet::new(),
            reached: BTreeSet::new(),
            conflicted: BTreeSet::new(),
            constants_conflict: false,
        }
    }

    /// Whether the task poll function at `f` polls the task whose body is `task`.
    fn polls_task(&self, f: u64, task: &str) -> bool {
        let Some((end, _)) = self.elf.funcs.get(&f) else {
            return false;
        };
        (f..*end).step_by(16).any(|a| {
            self.sources
                .get(&a)
                .is_some_and(|fs| fs.iter().any(|n| n.starts_with(task)))
        })
    }

    /// The source function a loop is written in: the innermost function whose inlined body
    /// holds every instruction of the loop (library plumbing aside: a `for` over a slice is
    /// its caller's loop); and the functions that hold it, outermost first.
    fn loop_function(&self, site: &cfg::Site) -> Option<(String, Vec<String>)> {
        let mut common: Option<Vec<&String>> = None;
        for a in &site.body {
            // An instruction the line table leaves out (`??`) says nothing.
            let Some(frames) = self.sources.get(a).filter(|f| f.iter().all(|n| n != "??")) else {
                continue;
            };
            let chain: Vec<&String> = frames.iter().rev().collect();
            common = Some(match common {
                None => chain,
                Some(c) => c
                    .iter()
                    .zip(&chain)
                    .take_while(|(x, y)| x == y)
                    .map(|(x, _)| *x)
                    .collect(),
            });
        }
        let common = common?;
        let at = common.iter().rposition(|f| !plumbing(f))?;
        let chain: Vec<String> = common.iter().take(at + 1).map(|f| (*f).clone()).collect();
        Some((chain.last()?.clone(), chain))
    }

    /// The source functions the instruction at `addr` is written in, innermost first, library
    /// plumbing aside.
    fn frames(&self, addr: u64) -> Vec<String> {
        self.sources
            .get(&addr)
            .map(|fs| fs.iter().filter(|f| !plumbing(f)).cloned().collect())
            .unwrap_or_default()
    }

    /// The lines of code (and its literals and jump tables) in flash the job may touch.
    fn footprint(&self) -> BTreeSet<u64> {
        in_flash(&self.touched)
    }
}

/// Of the lines `touched`, those read through the XIP cache: a line in SRAM never misses.
fn in_flash(touched: &BTreeSet<u64>) -> BTreeSet<u64> {
    touched
        .iter()
        .copied()
        .filter(|l| XIP.contains(&(l * LINE)))
        .collect()
}

/// Analyses one job: a first pass finds what it reaches, two more charge the XIP cache.
fn job(
    elf: &Elf,
    graph: &CallGraph,
    annotations: &Annotations,
    sources: &HashMap<u64, Vec<String>>,
    spec: JobSpec,
) -> Result<(JobWcet, HashMap<u64, Option<u64>>), String> {
    let probe = Job::new(elf, graph, annotations, sources, spec.side, spec.name);
    let entry = match graph.by_name(spec.entry) {
        Some(e) => e,
        // A task: its poll function.
        None => elf
            .funcs
            .iter()
            .find(|(f, (_, n))| n.starts_with(TASK_POLL) && probe.polls_task(**f, spec.entry))
            .map(|(f, _)| *f)
            .ok_or_else(|| format!("the image has no {}", spec.entry))?,
    };
    let run = |j: &mut Job<'_>| {
        use cfg::Image;
        j.call(entry)
    };
    let (mut wcet, reached) = bounded(&probe, spec.name, &run)?;
    wcet.entry = entry;
    if spec.handler {
        // Entry and return, and the vector's word: in flash, one more line.
        let vector = if XIP.contains(&elf.vectors) {
            XIP_MISS
        } else {
            0
        };
        let extra = EXCEPTION_ENTRY + EXCEPTION_RETURN + vector;
        wcet.cycles = overflow(wcet.cycles.saturating_add(extra))?;
        wcet.xip_cycles = wcet.xip_cycles.saturating_add(vector);
    }
    Ok((wcet, reached))
}

/// The longest critical section (interrupts off: embassy-rp's spinlock 31, or defmt's logger,
/// which holds one from a message's start to its end) in `functions`.
fn critical(
    elf: &Elf,
    graph: &CallGraph,
    annotations: &Annotations,
    sources: &HashMap<u64, Vec<String>>,
    functions: &HashMap<u64, Option<u64>>,
) -> Result<JobWcet, String> {
    let find = |names: &[&str]| -> Result<Vec<u64>, String> {
        names
            .iter()
            .map(|n| {
                graph
                    .by_name(n)
                    .ok_or_else(|| format!("the image has no {n}"))
            })
            .collect()
    };
    let acquire = find(ACQUIRES)?;
    let release = find(RELEASES)?;
    let probe = Job::new(elf, graph, annotations, sources, Side::Any, "critical");
    let mut worst: Option<JobWcet> = None;
    // Functions that return (a section in one that never does never ends).
    let mut reached: Vec<u64> = functions
        .iter()
        .filter(|(f, w)| !acquire.contains(f) && w.is_some())
        .map(|(f, _)| *f)
        .collect();
    reached.sort_unstable();
    for f in &reached {
        let Some((end, _)) = elf.funcs.get(f).cloned() else {
            continue;
        };
        let (starts, joins) = cfg::section_starts(&mut Scan(&probe, functions), *f, end, &acquire)?;
        for from in starts {
            // embassy-rp's release is always inlined: a section ends at its `CPSIE`, or at
            // defmt's release.
            let section = cfg::Section {
                from,
                release: &release,
                joins: &joins,
            };
            let run = |j: &mut Job<'_>| {
                j.reached.insert(*f);
                let w = cfg::analyse_from(j, *f, end, Some(section))?;
                j.touched.extend(w.touched.iter().map(|a| a / LINE));
                let found: Vec<LoopReport> = w
                    .loops
                    .iter()
                    .map(|l| LoopReport {
                        function: elf.name(*f),
                        address: format!("{:#x}", l.header),
                        bound: l.bound,
                        source: l.source.clone(),
                        iteration_cycles: l.iteration,
                        at: BenchLoop::of(l, [*f, end], j.annotation_of(l.header)),
                    })
                    .collect();
                j.loops.extend(found);
                Ok(w.cycles)
            };
            let (w, _) = bounded(&probe, "critical", &run).map_err(|e| {
                format!("the critical section at {from:#x} in {}: {e}", elf.name(*f))
            })?;
            if worst.as_ref().is_none_or(|m| w.cycles > m.cycles) {
                worst = Some(w);
            }
        }
    }
    worst.ok_or_else(|| "no critical section found".to_owned())
}

/// An image that only decodes: every call returns at once (finding where critical sections
/// begin needs the code, not its costs).
struct Scan<'a, 'b>(&'a Job<'b>, &'a HashMap<u64, Option<u64>>);

impl cfg::Image for Scan<'_, '_> {
    fn code(&self, addr: u64) -> Option<&[u8]> {
        self.0.code(addr)
    }
    fn word(&self, addr: u64) -> Option<u64> {
        self.0.word(addr)
    }
    fn call(&mut self, addr: u64) -> Result<Option<u64>, String> {
        // What the jobs found: a call that never returns ends the path.
        let name = self.0.elf.funcs.get(&addr).map(|(_, n)| n.as_str());
        Ok(match self.1.get(&addr) {
            Some(None) => None,
            _ if name.is_some_and(|n| DIVERGES.contains(&n)) => None,
            _ => Some(0),
        })
    }
    fn indirect(&mut self, _function: u64, _site: u64) -> Result<Vec<u64>, String> {
        // Any function the jobs found returning: the call returns.
        Ok(self
            .1
            .iter()
            .find(|(_, w)| w.is_some())
            .map(|(f, _)| vec![*f])
            .unwrap_or_default())
    }
    fn annotation(&self, _function: u64, _site: &cfg::Site) -> Option<(u64, String)> {
        Some((0, String::new()))
    }
}

/// What takes a critical section and returns holding it: the lock's acquire (its release is
/// inlined, a `CPSIE`), and defmt's start of a message.
const ACQUIRES: &[&str] = &[
    "<embassy_rp::critical_section_impl::RpSpinlockCs as critical_section::Impl>::acquire",
    "_defmt_acquire",
    "defmt::export::acquire_and_header",
];
/// What ends one that a function other than its own took: defmt's end of a message.
const RELEASES: &[&str] = &["_defmt_release"];

/// What `run` costs: a first pass finds the code it reaches (and fails on anything without a
/// bound), two more charge the XIP cache; the functions reached.
fn bounded(
    probe: &Job<'_>,
    name: &str,
    run: &dyn Fn(&mut Job<'_>) -> Result<Option<u64>, String>,
) -> Result<(JobWcet, HashMap<u64, Option<u64>>), String> {
    let mut first = Job::new(
        probe.elf,
        probe.graph,
        probe.annotations,
        probe.sources,
        probe.side,
        probe.job,
    );
    let core = run(&mut first)?;
    if !first.unbounded.is_empty() || !first.unsized_calls.is_empty() {
        let sizes = first.unsized_calls.iter().map(|at| {
            let written = first.frames(*at).join(", inlined into ");
            format!("\n  the call at {at:#x} passes a length nothing bounds; written in {written}")
        });
        let list: Vec<String> = first
            .unbounded
            .iter()
            .map(|(f, at, written)| {
                format!(
                    "\n  the loop with its back edge at {at:#x} in {}, written in {written}",
                    first.elf.name(*f)
                )
            })
            .chain(sizes)
            .collect();
        return Err(format!(
            "{} loop(s) or length(s) with no bound (neither counted nor annotated in {}):{}",
            list.len(),
            Annotations::path().display(),
            list.concat()
        ));
    }
    let core = overflow(core.ok_or("it never completes")?)?;
    let code = first.footprint();
    // Constants may be read through any pointer: every load the analysis cannot place is
    // charged a miss (the lines of `.rodata` stay out of the cold code's, so the bound does
    // not move with the constants' size: the panic locations hold the checkout's path).
    let (cycles, loops) = with_misses(&first, run, &code, true)?;
    let memo = first
        .reached
        .iter()
        .map(|f| (*f, first.memo.get(f).copied().flatten()))
        .collect();
    Ok((
        JobWcet {
            job: name.to_owned(),
            cycles,
            measured_worst_cycles: None,
            xip_cycles: cycles.saturating_sub(core),
            lines: code.len(),
            loops,
            entry: 0,
        },
        memo,
    ))
}

/// The job's cycles with the XIP cache's misses for the cold `lines`: each once, or, for a
/// line of a set that holds more than the cache's ways, each time it is entered (and on every
/// load the analysis cannot place if a constant's line is one, or `every_load`).
fn with_misses(
    first: &Job<'_>,
    run: &dyn Fn(&mut Job<'_>) -> Result<Option<u64>, String>,
    lines: &BTreeSet<u64>,
    every_load: bool,
) -> Result<(u64, Vec<LoopReport>), String> {
    let mut per_set: BTreeMap<u64, usize> = BTreeMap::new();
    for l in lines {
        *per_set.entry(l % SETS).or_default() += 1;
    }
    let conflicted: BTreeSet<u64> = lines
        .iter()
        .copied()
        .filter(|l| per_set.get(&(l % SETS)).copied().unwrap_or(0) > WAYS)
        .collect();
    let r = &first.elf.rodata;
    let mut job = Job::new(
        first.elf,
        first.graph,
        first.annotations,
        first.sources,
        first.side,
        first.job,
    );
    job.constants_conflict = (every_load && XIP.contains(&r.start))
        || conflicted
            .iter()
            .any(|l| (r.start / LINE..r.end.div_ceil(LINE)).contains(l));
    job.conflicted = conflicted;
    let core = overflow(run(&mut job)?.ok_or("it never completes")?)?;
    let cold = (lines.len() - job.conflicted.len()) as u64 * XIP_MISS;
    let mut loops = job.loops;
    loops.sort_by(|a, b| a.address.cmp(&b.address));
    loops.dedup_by(|a, b| a.address == b.address);
    Ok((overflow(core.saturating_add(cold))?, loops))
}

/// `cycles`, or an error when the sums and products of a bound saturated (the cost
/// arithmetic saturates rather than wrap or panic): an annotation's bound so large that the
/// job's bound does not fit in 64 bits.
fn overflow(cycles: u64) -> Result<u64, String> {
    if cycles == u64::MAX {
        Err(format!(
            "its bound overflows 64 bits of cycles: a bound in {} is too large",
            Annotations::path().display()
        ))
    } else {
        Ok(cycles)
    }
}

/// The whole report: each job, and each sensor's reaction bound from them.
#[derive(Debug, Serialize)]
pub struct Report {
    pub jobs: Vec<JobWcet>,
    /// By the mission's sensor names: the response-time bound of a reaction (cycles), from
    /// the static costs; `null` when the analysis cannot give one (`reaction_error`).
    pub reaction_bound_cycles: BTreeMap<String, Option<u64>>,
    /// Why there is no bound, if there is none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reaction_error: Option<String>,
}

impl Report {
    /// The costs the response-time analysis takes, by job.
    pub fn costs(&self) -> Option<Costs> {
        let get = |n: &str| self.jobs.iter().find(|j| j.job == n).map(|j| j.cycles);
        Some(Costs {
            sensing_poll: get("sensing_poll")?,
            alarm: get("alarm")?,
            gpio: get("gpio")?,
            deciding: get("deciding")?,
            critical: get("critical")?,
            control_poll: get("deciding")?,
        })
    }
}

/// The mission's sampling periods of the sonar and the bumper, ms.
fn periods_ms() -> Result<[u64; 2], String> {
    use psmpa_fetch_tea::fetch_tea::{Sensor, TABLES as MISSION};
    let period = |s: Sensor| match MISSION.domain.sensor(s.id()).map(|a| a.mode) {
        Some(psmpa_core::SensorMode::Cyclic { period }) => Ok(period.as_millis()),
        _ => Err(format!("the mission's {s:?} is not cyclic")),
    };
    Ok([period(Sensor::Sonar)?, period(Sensor::Bumper)?])
}

/// The image built for the analysis, checked to be the shipped code byte for byte.
fn analysed_image() -> Result<PathBuf, String> {
    let a = CallGraph::build_pico()?;
    let shipped = CallGraph::shipped_pico()?;
    if CallGraph::same_code(&a, &shipped)? {
        Ok(a)
    } else {
        Err("the image built for the analysis differs from the shipped one".to_owned())
    }
}

/// The bench's cost (`boards/pico/bench-budget.json`) that measures `job` as the analysis
/// bounds it: one poll of the control task for the deciding job, not thread mode's busy
/// stretch.
fn measured_as(job: &str) -> &str {
    if job == "deciding" {
        "control_poll"
    } else {
        job
    }
}

/// The annotated loops of the shipped Pico image, where they are, for the bench to count
/// their back edges: each machine loop an annotation of `loops` bounds, once (a busy wait the
/// design declares, `timed`: `block_for` in planning, is bounded by time, not by a count, and
/// is not among them); and where the deciding job starts, for the bench to time it.
pub fn bench_watch() -> Result<BenchWatch, String> {
    bench_watch_with(&Annotations::load()?)
}

/// What the bench watches of the analysis: the loops whose back edges it counts, and where
/// the deciding job (one poll of the control task) starts, to measure it as bounded.
pub struct BenchWatch {
    pub loops: Vec<BenchLoop>,
    /// The control task's poll function.
    pub control_poll: u64,
}

/// [`bench_watch`] with `annotations` for the file's.
pub fn bench_watch_with(annotations: &Annotations) -> Result<BenchWatch, String> {
    let (results, _) = analyse(&analysed_image()?, annotations)?;
    let mut out: Vec<BenchLoop> = Vec::new();
    let mut control_poll = 0;
    for job in results.into_iter().flatten() {
        if job.job == "deciding" {
            control_poll = job.entry;
        }
        for at in job.loops.into_iter().map(|l| l.at).filter(|at| at.counted) {
            let bound = at.bound;
            match out
                .iter_mut()
                .find(|o| o.function == at.function && o.entries == at.entries)
            {
                Some(o) => o.bounded_by(&job.job, bound),
                None => {
                    let mut at = at;
                    at.bounded_by(&job.job, bound);
                    out.push(at);
                }
            }
        }
    }
    if control_poll == 0 {
        return Err("the analysis found no control task's poll (the deciding job) to time".into());
    }
    Ok(BenchWatch {
        loops: out,
        control_poll,
    })
}

/// Runs the analysis: prints each job's bound; fails (1) naming the first loop or length it
/// cannot bound, or an annotation that matches nothing; 2 when its annotations do not load.
pub fn run(json: bool) -> Ending {
    // The inputs first: bad ones are refused before the image is built, and a page without
    // its markers fails before the analysis.
    let annotations = match Annotations::load() {
        Ok(a) => a,
        Err(e) => return Ending::BadInput(e),
    };
    if let Err(e) = bound::Budget::load() {
        return Ending::BadInput(e);
    }
    let root = crate::firmware::root();
    if let Err(e) = crate::pages::check_pages(&[
        (root.join("docs/firmware.md"), "wcet-figures"),
        (root.join("README.md"), "wcet"),
    ]) {
        return Ending::Failed(e);
    }
    let analysed = match analysed_image() {
        Ok(a) => a,
        Err(e) => return Ending::Failed(e),
    };
    let (results, used) = match analyse(&analysed, &annotations) {
        Ok(r) => r,
        Err(e) => return Ending::Failed(e),
    };
    let mut failures = Vec::new();
    let mut jobs = Vec::new();
    for r in results {
        match r {
            Ok(j) => jobs.push(j),
            Err(e) => failures.push(e),
        }
    }
    if failures.is_empty() {
        let stale = stale(&annotations, &used);
        for a in stale {
            failures.push(format!(
                "{}: the annotation for {} matches no loop or call of an analysed job (a narrower one of the same loop bounds it, or the code changed): update or remove it",
                Annotations::path().display(),
                a.key()
            ));
        }
    }
    // The bench's measured worst, beside each bound (a missing or bad budget leaves it out
    // here; the pages' figures fail on it).
    if let Ok(budget) = bound::Budget::load() {
        let measured = budget.measured.named();
        for j in &mut jobs {
            j.measured_worst_cycles = measured
                .iter()
                .find(|(n, _)| *n == measured_as(&j.job))
                .map(|(_, c)| *c);
        }
    }
    let mut report = Report {
        jobs,
        reaction_bound_cycles: BTreeMap::new(),
        reaction_error: None,
    };
    match (report.costs(), periods_ms()) {
        (Some(costs), Ok(periods)) => match bound::bounds(&costs, periods) {
            Ok([sonar, bumper]) => {
                report
                    .reaction_bound_cycles
                    .insert("sonar".to_owned(), Some(sonar));
                report
                    .reaction_bound_cycles
                    .insert("bumper".to_owned(), Some(bumper));
            }
            Err(e) => {
                report
                    .reaction_bound_cycles
                    .insert("sonar".to_owned(), None);
                report
                    .reaction_bound_cycles
                    .insert("bumper".to_owned(), None);
                report.reaction_error = Some(format!(
                    "the static costs at the mission's periods ({} and {} ms): {e}",
                    periods[0], periods[1]
                ));
            }
        },
        (None, _) => report.reaction_error = Some("a job has no bound".to_owned()),
        (_, Err(e)) => report.reaction_error = Some(e),
    }
    if failures.is_empty()
        && let Err(e) = figures(&report)
    {
        failures.push(e);
    }
    if json {
        match serde_json::to_string(&report) {
            Ok(text) => println!("{text}"),
            Err(e) => return Ending::Failed(e.to_string()),
        }
    } else {
        print!("{}", text(&report));
    }
    match failures.first() {
        None => Ending::Passed,
        Some(first) => Ending::Failed(first.clone()),
    }
}

/// The annotations no loop or call used (`used`: [`USED`]'s keys), each entry on its own: of
/// two entries for one function, the one a narrower entry always beat is stale too.
fn stale<'a>(annotations: &'a Annotations, used: &BTreeSet<(bool, usize)>) -> Vec<&'a Annotation> {
    annotations
        .loops
        .iter()
        .enumerate()
        .map(|(i, a)| ((false, i), a))
        .chain(
            annotations
                .lengths
                .iter()
                .enumerate()
                .map(|(i, a)| ((true, i), a)),
        )
        .filter(|(k, _)| !used.contains(k))
        .map(|(_, a)| a)
        .collect()
}

/// Writes the jobs' bounds beside the bench's committed budget into `docs/firmware.md`.
/// `x` to two significant figures, digits grouped (`≈45,000,000,000`).
fn about(x: f64) -> String {
    if x <= 0.0 || !x.is_finite() {
        return "0".to_owned();
    }
    let scale = 10f64.powi(x.log10().floor() as i32 - 1);
    format!(
        "≈{}",
        crate::hil::thousands(((x / scale).round() * scale) as u64)
    )
}

/// Writes the figures into the pages. A bound with the XIP cache's misses depends on the link's
/// layout, which the checkout's folder changes (cargo's crate hashes order the symbols), so
/// the pages give it to two significant figures; the instructions' bound, which the layout
/// does not move, exactly (the whole bound of an image that runs from SRAM).
fn figures(report: &Report) -> Result<(), String> {
    let budget = bound::Budget::load()?;
    let group = crate::hil::thousands;
    let mut text = String::from(
        "\n| job | static bound, cycles | of which XIP misses | instructions only | measured on the bench (budget) | bound / measured |\n|---|---|---|---|---|---|\n",
    );
    for j in &report.jobs {
        let measured = budget
            .measured
            .named()
            .iter()
            .find(|(n, _)| *n == measured_as(&j.job))
            .map(|(_, c)| *c);
        let budgeted = budget
            .budget
            .named()
            .iter()
            .find(|(n, _)| *n == measured_as(&j.job))
            .map(|(_, c)| *c);
        let (m, ratio) = match (measured, budgeted) {
            (Some(m), Some(b)) if m > 0 => (
                format!("{} ({})", group(m), group(b)),
                format!("{}x", about(j.cycles as f64 / m as f64)),
            ),
            _ => ("".to_owned(), "".to_owned()),
        };
        // With no miss charged (code in SRAM) the bound is the instructions' alone: exact.
        let (bound, xip) = if j.xip_cycles == 0 {
            (group(j.cycles), "0".to_owned())
        } else {
            (about(j.cycles as f64), about(j.xip_cycles as f64))
        };
        text += &format!(
            "| {} | {bound} | {xip} | {} | {m} | {ratio} |\n",
            j.job,
            group(j.cycles - j.xip_cycles)
        );
    }
    match &report.reaction_error {
        Some(_) => {
            text += "\nNo reaction bound: at the mission's periods the static costs need more than the processor (`cargo xtask wcet` says how much).\n";
        }
        None => {
            for (sensor, b) in &report.reaction_bound_cycles {
                if let Some(b) = b {
                    text += &format!(
                        "\nReaction bound of the {sensor}: {} cycles.\n",
                        about(*b as f64)
                    );
                }
            }
        }
    }
    let root = crate::firmware::root();
    let alarm = report.jobs.iter().find(|j| j.job == "alarm");
    let cell = match (alarm, &report.reaction_error) {
        (Some(a), Some(_)) => format!(
            "{} jobs bounded (alarm {} cycles); no reaction bound: the bounds need more than the processor",
            report.jobs.len(),
            about(a.cycles as f64)
        ),
        (Some(a), None) => format!(
            "{} jobs bounded (alarm {} cycles); reaction bounds from them",
            report.jobs.len(),
            about(a.cycles as f64)
        ),
        (None, _) => format!("{} jobs bounded", report.jobs.len()),
    };
    crate::pages::write_pages(&[
        (root.join("docs/firmware.md"), "wcet-figures", text),
        (root.join("README.md"), "wcet", cell),
    ])
}

/// The report in words.
fn text(report: &Report) -> String {
    let mut out = String::new();
    for j in &report.jobs {
        out += &format!(
            "{:<14} {:>13} cycles: {:>11} of instructions, {:>13} of XIP misses ({} lines), {} loops\n",
            j.job,
            j.cycles,
            j.cycles - j.xip_cycles,
            j.xip_cycles,
            j.lines,
            j.loops.len()
        );
    }
    for (sensor, b) in &report.reaction_bound_cycles {
        match b {
            Some(b) => out += &format!("reaction bound of the {sensor}: {b} cycles\n"),
            None => out += &format!("reaction bound of the {sensor}: none\n"),
        }
    }
    if let Some(e) = &report.reaction_error {
        out += &format!("no reaction bound: {e}\n");
    }
    out
}

/// The static bound of each of `functions` (by symbol) of the image at `path`: its address and
/// its cycles of instructions alone (code and constants with no wait state, as rp2040js fetches
/// them: no XIP miss charged), or why it has none.
pub fn instruction_cycles(
    path: &Path,
    annotations: &Annotations,
    functions: &[&str],
    table: thumb::Table,
) -> Result<Vec<(u64, u64)>, String> {
    thumb::with_table(table, || {
        instruction_cycles_now(path, annotations, functions)
    })
}

fn instruction_cycles_now(
    path: &Path,
    annotations: &Annotations,
    functions: &[&str],
) -> Result<Vec<(u64, u64)>, String> {
    let elf = Elf::read(path)?;
    let graph = CallGraph::of(path)?;
    let headers = loop_headers(&elf, &graph, annotations);
    let sources = source_functions(&elf.path, &headers)?;
    functions
        .iter()
        .map(|name| {
            let at = graph
                .by_name(name)
                .ok_or_else(|| format!("the image has no {name}"))?;
            let mut j = Job::new(&elf, &graph, annotations, &sources, Side::Any, name);
            let cycles = cfg::Image::call(&mut j, at)?;
            if !j.unbounded.is_empty() || !j.unsized_calls.is_empty() {
                return Err(format!("{name} has a loop or a length with no bound"));
            }
            let cycles = cycles.ok_or_else(|| format!("{name} never returns"))?;
            Ok((at, overflow(cycles).map_err(|e| format!("{name}: {e}"))?))
        })
        .collect()
}

/// The analysis of an image built for it, job by job; and the annotations it used.
#[allow(clippy::type_complexity)]
fn analyse(
    path: &Path,
    annotations: &Annotations,
) -> Result<(Vec<Result<JobWcet, String>>, BTreeSet<(bool, usize)>), String> {
    let elf = Elf::read(path)?;
    let graph = CallGraph::of(path)?;
    let headers = loop_headers(&elf, &graph, annotations);
    let sources = source_functions(&elf.path, &headers)?;
    let mut reached = HashMap::new();
    let mut out: Vec<Result<JobWcet, String>> = Vec::new();
    for spec in JOBS {
        out.push(match job(&elf, &graph, annotations, &sources, *spec) {
            Ok((w, r)) => {
                reached.extend(r);
                Ok(w)
            }
            Err(e) => Err(format!("{}: {e}", spec.name)),
        });
    }
    out.push(
        critical(&elf, &graph, annotations, &sources, &reached)
            .map_err(|e| format!("critical: {e}")),
    );
    Ok((out, USED.with(|u| u.borrow().clone())))
}

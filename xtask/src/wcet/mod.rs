//! `cargo xtask wcet`: static worst-case execution times of the Pico image's jobs, in cycles of
//! the RP2040's Cortex-M0+, from the binary alone.
//!
//! * Code: the image built for the stack analysis (the shipped code, relocations kept; checked
//!   byte for byte against the shipped image), decoded by `yaxpeax-arm` from each function's
//!   entry ([`cfg`]), costed by the Cortex-M0+ TRM's cycle table ([`thumb`]).
//! * Calls: direct calls by their target's worst case; calls through registers by the worst of
//!   what the stack analyser's call graph says they may reach (the sensing executor never polls
//!   the main task, and the thread-mode executor never the sensing task). Recursion is refused.
//! * Loops: counted loops are bounded from the code; any other needs an annotation in
//!   `boards/pico/wcet-loops.json`, keyed by the source function the loop is written in (as the
//!   debug information names it) and checked on the bench. A loop with neither fails, naming
//!   its function and address.
//! * Memory: see [`Memory`]: the stack and peripherals as the TRM and the RP2040 datasheet give
//!   them, code and constants in flash through the XIP cache with a miss per line.
//!
//! Jobs: the three handlers that release or run sensing work (exception entry and return
//! included), the longest critical section, and one poll of the main task (the deciding side).

mod cfg;
mod thumb;

#[cfg(test)]
mod tests;

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::process::Command;

use object::{Object, ObjectSection, ObjectSymbol, RelocationKind, SymbolKind};
use serde::{Deserialize, Serialize};

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
/// with a cold cache: each line it may touch misses once (every function it reaches, whole,
/// and all of `.rodata`, which it may read through any pointer), as long as no cache set holds
/// more of those lines than the cache's two ways; a code line of a set that does is charged a
/// miss every time control enters it, a constant's line on every load the analysis cannot
/// place.
pub const XIP_FILL: u64 = 56;
/// The SSI's chip-select and the AHB's hops around a fill: an allowance, not a measurement.
pub const XIP_OVERHEAD: u64 = 8;
/// A miss.
pub const XIP_MISS: u64 = XIP_FILL + XIP_OVERHEAD;
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

/// Where a call through a register is a waker's: the inline frames of `core::task::Waker`.
const WAKER_CALLS: &[&str] = &[
    "core::task::wake::Waker::",
    "<core::task::wake::Waker as core::ops::drop::Drop>::drop",
    "<core::task::wake::Waker as core::clone::Clone>::clone",
];

/// The functions of the image's waker vtables: embassy's executor's (and core's no-op waker).
const WAKER_FNS: &[&str] = &["embassy_executor::raw::waker::", "core::task::wake::"];

/// A task's poll function.
const TASK_POLL: &str = "embassy_executor::raw::TaskStorage<";
/// The body of the task the sensing executor polls.
const SENSING_TASK: &str = "psmpa_board_rp::__sensing_task::";

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
    /// Back edges per entry into the loop; for a length, bytes.
    pub bound: u64,
    /// Why the code bounds it so.
    pub why: String,
    /// The jobs it holds for (all if empty): a loop shared by two executors may have a
    /// different bound in each.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub jobs: Vec<String>,
}

impl Annotation {
    fn applies_to(&self, job: &str) -> bool {
        self.jobs.is_empty() || self.jobs.iter().any(|j| j == job)
    }
}

impl Annotations {
    /// The file.
    pub fn path() -> PathBuf {
        crate::firmware::root().join("boards/pico/wcet-loops.json")
    }

    fn load() -> Result<Self, String> {
        let path = Self::path();
        let text =
            std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        let a: Self =
            serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
        for l in &a.loops {
            if l.function.trim().is_empty() || l.why.trim().is_empty() {
                return Err(format!(
                    "{}: every loop needs a function and a reason",
                    path.display()
                ));
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

/// The body of the main task, whose poll is the deciding side's step.
const MAIN_TASK: &str = "psmpa_board_rp::____embassy_main_task::";

/// One job's result.
#[derive(Clone, Debug, Serialize)]
pub struct JobWcet {
    pub job: String,
    pub cycles: u64,
    /// Of which: the XIP cache's misses.
    pub xip_cycles: u64,
    /// Lines of code it may run.
    pub lines: usize,
    pub loops: Vec<LoopReport>,
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
        Ok(Self {
            rodata,
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
        for l in &worst.loops {
            self.loops.push(LoopReport {
                function: self.elf.name(addr),
                address: format!("{:#x}", l.header),
                bound: l.bound,
                source: l.source.clone(),
                iteration_cycles: l.iteration,
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
                    .find(|a| a.function == f && a.applies_to(self.job))
            })
            .map(|a| (a.bound, a.why.clone()));
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
        self.by_length.insert((addr, length), worst.cycles);
        Ok(worst.cycles)
    }

    fn indirect(&mut self, function: u64, site: u64) -> Result<Vec<u64>, String> {
        let mut targets = self
            .graph
            .targets(function, site, self.side)
            .ok_or_else(|| format!("the call graph has no call through a register at {site:#x}"))?;
        // A waker's call (its vtable's wake, wake_by_ref, clone or drop, as the debug
        // information shows the call inlined from core's Waker) reaches only a waker vtable's
        // functions, not whatever other table holds a function at the same offset.
        let waker = self.sources.get(&site).is_some_and(|fs| {
            fs.iter()
                .any(|f| WAKER_CALLS.iter().any(|w| f.starts_with(w)))
        });
        if waker {
            targets.retain(|t| {
                let name = self.elf.name(*t);
                WAKER_FNS.iter().any(|w| name.starts_with(w))
            });
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
        if targets.is_empty() {
            return Err(format!(
                "nothing known for the call through a register at {site:#x}"
            ));
        }
        Ok(targets.into_iter().collect())
    }

    fn annotation(&self, _function: u64, site: &cfg::Site) -> Option<(u64, String)> {
        if let Some(n) = self.length {
            return Some((n, format!("moves at most {n} bytes (the call's length)")));
        }
        let function = self.loop_function(site)?;
        self.annotations
            .loops
            .iter()
            .find(|a| a.function == function && a.applies_to(self.job))
            .map(|a| (a.bound, a.why.clone()))
    }

    fn unbounded(&mut self, function: u64, site: &cfg::Site) -> Result<u64, String> {
        let at = site.latches.first().copied().unwrap_or(site.header);
        let written = self
            .loop_function(site)
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
            self.headers.insert(site);
            Ok(self.inner.indirect(function, site).unwrap_or_default())
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
            by_length: HashMap::new(),
            length: None,
            path: Vec::new(),
            loops: Vec::new(),
            unbounded: BTreeSet::new(),
            unsized_calls: BTreeSet::new(),
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
    /// its caller's loop).
    fn loop_function(&self, site: &cfg::Site) -> Option<String> {
        let mut common: Option<Vec<&String>> = None;
        for a in &site.body {
            let chain: Vec<&String> = self.sources.get(a)?.iter().rev().collect();
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
        common?
            .iter()
            .rev()
            .find(|f| !plumbing(f))
            .map(|f| (*f).clone())
    }

    /// The source functions the instruction at `addr` is written in, innermost first, library
    /// plumbing aside.
    fn frames(&self, addr: u64) -> Vec<String> {
        self.sources
            .get(&addr)
            .map(|fs| fs.iter().filter(|f| !plumbing(f)).cloned().collect())
            .unwrap_or_default()
    }

    /// The lines of code the job may run: every function it reaches, whole.
    fn footprint(&self) -> BTreeSet<u64> {
        self.reached
            .iter()
            .filter_map(|f| self.elf.funcs.get(f).map(|(end, _)| (*f, *end)))
            .flat_map(|(s, e)| (s / LINE)..e.div_ceil(LINE))
            .collect()
    }
}

/// Analyses one job: a first pass finds what it reaches, two more charge the XIP cache.
fn job(
    elf: &Elf,
    graph: &CallGraph,
    annotations: &Annotations,
    sources: &HashMap<u64, Vec<String>>,
    spec: JobSpec,
) -> Result<JobWcet, String> {
    let mut first = Job::new(elf, graph, annotations, sources, spec.side, spec.name);
    let entry = match graph.by_name(spec.entry) {
        Some(e) => e,
        // A task: its poll function.
        None => elf
            .funcs
            .iter()
            .find(|(f, (_, n))| n.starts_with(TASK_POLL) && first.polls_task(**f, spec.entry))
            .map(|(f, _)| *f)
            .ok_or_else(|| format!("the image has no {}", spec.entry))?,
    };
    use cfg::Image;
    first.call(entry)?;
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
                    elf.name(*f)
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
    let core = first
        .memo
        .get(&entry)
        .copied()
        .flatten()
        .ok_or_else(|| format!("{} never returns", spec.entry))?;
    let code = first.footprint();
    let r = &elf.rodata;
    let constants: BTreeSet<u64> = (r.start / LINE..r.end.div_ceil(LINE)).collect();
    // Two bounds of the misses, both sound; the job's is the smaller. (a) Every line of the
    // constants misses once, like the code's; (b) the constants are left out of the cold
    // lines and every load the analysis cannot place misses instead.
    let with_constants: BTreeSet<u64> = code.union(&constants).copied().collect();
    let (a, loops) = with_misses(&first, entry, &with_constants, false)?;
    let (b, _) = with_misses(&first, entry, &code, true)?;
    let handler = if spec.handler {
        // The vector's word is a constant in flash: one more line.
        EXCEPTION_ENTRY + EXCEPTION_RETURN + XIP_MISS
    } else {
        0
    };
    let cycles = a.min(b) + handler;
    Ok(JobWcet {
        job: spec.name.to_owned(),
        cycles,
        xip_cycles: cycles - core,
        lines: code.len(),
        loops,
    })
}

/// The job's cycles with the XIP cache's misses for the cold `lines`: each once, or, for a
/// line of a set that holds more than the cache's ways, each time it is entered (and on every
/// load the analysis cannot place if a constant's line is one, or `every_load`).
fn with_misses(
    first: &Job<'_>,
    entry: u64,
    lines: &BTreeSet<u64>,
    every_load: bool,
) -> Result<(u64, Vec<LoopReport>), String> {
    use cfg::Image;
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
    job.constants_conflict = every_load
        || conflicted
            .iter()
            .any(|l| (r.start / LINE..r.end.div_ceil(LINE)).contains(l));
    job.conflicted = conflicted;
    let core = job.call(entry)?.ok_or("the job never returns")?;
    let cold = (lines.len() - job.conflicted.len()) as u64 * XIP_MISS;
    let mut loops = job.loops;
    loops.sort_by(|a, b| a.address.cmp(&b.address));
    loops.dedup_by(|a, b| a.address == b.address);
    Ok((core + cold, loops))
}

/// Runs the analysis: prints each job's bound, or fails naming what it cannot bound.
pub fn run(json: bool) -> Result<(), String> {
    let analysed = CallGraph::build_pico()?;
    let shipped = CallGraph::shipped_pico()?;
    if !CallGraph::same_code(&analysed, &shipped)? {
        return Err("the image built for the analysis differs from the shipped one".to_owned());
    }
    let results = analyse(&analysed)?;
    let mut failures = Vec::new();
    let mut jobs = Vec::new();
    for r in results {
        match r {
            Ok(j) => jobs.push(j),
            Err(e) => failures.push(e),
        }
    }
    if json {
        let report = serde_json::json!({ "jobs": jobs });
        println!("{report}");
    } else {
        for j in &jobs {
            println!(
                "{:<14} {:>9} cycles ({:>7} of them XIP misses, {} lines), {} loops",
                j.job,
                j.cycles,
                j.xip_cycles,
                j.lines,
                j.loops.len()
            );
            for l in &j.loops {
                println!(
                    "    loop at {} in {}: {} back edges of at most {} cycles ({})",
                    l.address, l.function, l.bound, l.iteration_cycles, l.source
                );
            }
        }
    }
    match failures.first() {
        None => Ok(()),
        Some(_) => Err(failures.join("\n")),
    }
}

/// The analysis of an image built for it, job by job.
fn analyse(path: &Path) -> Result<Vec<Result<JobWcet, String>>, String> {
    let elf = Elf::read(path)?;
    let graph = CallGraph::of(path)?;
    let annotations = Annotations::load()?;
    let headers = loop_headers(&elf, &graph, &annotations);
    let sources = source_functions(&elf.path, &headers)?;
    Ok(JOBS
        .iter()
        .map(|spec| {
            job(&elf, &graph, &annotations, &sources, *spec)
                .map_err(|e| format!("{}: {e}", spec.name))
        })
        .collect())
}

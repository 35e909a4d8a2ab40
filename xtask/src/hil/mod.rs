//! `cargo xtask hil`: the robot's firmware on an emulated Raspberry Pi Pico, in the loop with
//! the project's world.
//!
//! It builds the board's image for the RP2040 (`boards/pico`, as its README says), writes the
//! robot's calibration record for each scenario into the image's flash ([`settings_for`] on
//! the wheeled chassis), and plays the scenario in rp2040js ([`harness`]) against psmpa-sim's world of it
//! ([`world`]): the firmware's motor pins move the robot, the world answers its sonar's
//! triggers with echoes, closes its bump switch, shows it the door's marker. The firmware's
//! defmt log comes off the chip's RTT buffer and is decoded with its own table.
//!
//! The judge sees what a test rig sees: the pins and the chip's own flight recording
//! ([`chip`]), decoded as it comes off RTT. Every run is checked: each reading the robot
//! recorded against what the rig put on its pins; the outcome (detections and the sensor
//! that made each, collisions, reaching the door) against `psmpa-sim run` of the same
//! scenario; the sampling periods, from the trigger pin and the recording; every reaction
//! (from the pin edge that showed an obstacle to the motors stopping) against the
//! response-time bound that [`psmpa_core::timing`] gives from the committed cost budget, and
//! the measured costs against that budget ([`bound`]); the bench's fault scenarios
//! (`boards/faults/`) against what they expect ([`fault`]); any warning of the emulator (an
//! access silicon would fault on). The first run is played twice: the same pin log both
//! times. [`mutants`] plants bugs in a copy of the firmware and requires each to fail.

pub(crate) mod bound;
pub(crate) mod chip;
pub mod fault;
pub mod harness;
pub(crate) mod mutants;
mod svg;
pub mod world;

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant as WallClock;

use embassy_time::{Duration, Instant, Timer};
use object::{Object, ObjectSection, ObjectSymbol};
use psmpa_core::TraceHash;
use psmpa_drivers::switch::DEBOUNCE;
use psmpa_fetch_tea::fetch_tea::Sensor::{Bumper, Camera, Handle, Sonar};
use psmpa_fetch_tea::{RECORD_WORDS, Settings};
use psmpa_sim::rig::{Chassis, settings_for};
use psmpa_sim::robot::Arch;
use psmpa_sim::scenario::{Scenario, to_mm};
use psmpa_sim::sim::run_chassis;
use psmpa_sim::world::{Fate, ObstacleReport, Tally};
use serde::Serialize;

use crate::{firmware, recording};
use bound::Budget;
use fault::{Expect, Fault, FaultFile};
use harness::{Boot, Event, Harness, Stats, Symbols};
use world::{BenchWorld, PinFault, pin};

/// The RP2040's flash in the address space.
const FLASH: u32 = 0x1000_0000;
/// After the firmware's outcome (or its reset), the run goes on this long: the robot must stay
/// still.
const GRACE_NS: u64 = 1_000_000_000;

/// After a fault injected through a test point, the longest the run waits for the board to
/// say how its task ended or to be reset: the watchdog's timeout (500 ms,
/// `boards/rp/src/lib.rs`), the reset and the boot, and a grace.
const UNANSWERED_NS: u64 = 2_000_000_000;

/// What `cargo xtask hil` does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Play and check.
    Check,
    /// Play every shipped scenario and fault and rewrite the cost budget.
    Calibrate,
    /// Play images with planted bugs; each must fail.
    Mutants,
}

/// How `cargo xtask hil` ended.
pub enum Ending {
    /// Every run held its checks.
    Passed,
    /// A run did not.
    Failed(String),
    /// A file is not a scenario (exit 2).
    BadInput(String),
}

/// One thing to play: a scenario, maybe with a fault.
struct Play {
    /// The file given.
    file: PathBuf,
    /// The stem of its output files and image in `target/hil`, its own among the plays
    /// ([`unique_stems`]).
    stem: String,
    scenario: Scenario,
    fault: Option<FaultFile>,
    /// End the run at its first failure that shows while it runs (a planted bug's run: what
    /// caught it is all that is asked).
    stop_at_failure: bool,
}

impl Play {
    /// Its name, control characters escaped: printed, a name from a file never forges a
    /// line or a colour on the terminal.
    fn name(&self) -> String {
        psmpa_sim::json::printable(&match &self.fault {
            Some(f) => format!("fault {}", f.name),
            None => self.scenario.name.as_str().to_owned(),
        })
        .into_owned()
    }

    /// The stem of its output files and image in `target/hil`.
    fn stem(&self) -> String {
        self.stem.clone()
    }

    /// The stem its file gives: the file's own (`fault-` before a fault scenario's).
    fn file_stem(&self) -> String {
        let stem = self
            .file
            .file_stem()
            .map_or_else(|| self.name(), |s| s.to_string_lossy().into_owned());
        let stem = file_name(&stem);
        match &self.fault {
            Some(_) => format!("fault-{stem}"),
            None => stem,
        }
    }
}

/// Reads what to play: the files given, or every shipped scenario, fault scenario and the
/// bench's soak (`boards/soak`: runs past 65.536 s of uptime, where 16-bit milliseconds wrap).
fn plays(files: &[PathBuf]) -> Result<(Vec<Play>, bool), String> {
    let defaults = files.is_empty();
    let files: Vec<PathBuf> = if defaults {
        let root = firmware::root();
        let mut all = json_files(&root.join("scenarios"))?;
        all.extend(json_files(&root.join("boards/faults"))?);
        all.extend(json_files(&root.join("boards/soak"))?);
        all
    } else {
        files.to_vec()
    };
    let mut plays = Vec::new();
    for file in files {
        // A regular file of at most 1 MiB: a FIFO would wait for ever, a device never end.
        let bytes = read_input(&file, "scenario")?;
        if fault::is_fault_file(&bytes) {
            let f = fault::load(&file, &bytes)?;
            let scenario = read_input(&f.scenario, "scenario")
                .and_then(|b| psmpa_sim::load::parse(&f.scenario, &b).map_err(|e| e.to_string()))
                .map_err(|e| format!("{}: its scenario: {e}", file.display()))?;
            playable(&scenario).map_err(|e| format!("{}: its scenario: {e}", file.display()))?;
            f.fits(&scenario)
                .map_err(|e| format!("{}: {e}", file.display()))?;
            plays.push(Play {
                file,
                stem: String::new(),
                scenario,
                fault: Some(f),
                stop_at_failure: false,
            });
        } else {
            let scenario = psmpa_sim::load::parse(&file, &bytes).map_err(|e| e.to_string())?;
            playable(&scenario).map_err(|e| format!("{}: {e}", file.display()))?;
            plays.push(Play {
                file,
                stem: String::new(),
                scenario,
                fault: None,
                stop_at_failure: false,
            });
        }
    }
    unique_stems(&mut plays);
    Ok((plays, defaults))
}

/// Gives each play a stem of its own: its file's, and where two files give one stem (two
/// `sonar-6.json` in two folders), with the hash of its canonical path after it, so that
/// neither boots the other's image nor writes over its pictures and recording; the same file
/// given twice, with its place in the list too.
fn unique_stems(plays: &mut [Play]) {
    let stems: Vec<String> = plays.iter().map(Play::file_stem).collect();
    let keys: Vec<String> = plays
        .iter()
        .zip(&stems)
        .map(|(p, stem)| {
            if stems.iter().filter(|s| *s == stem).count() == 1 {
                return stem.clone();
            }
            let path = std::fs::canonicalize(&p.file).unwrap_or_else(|_| p.file.clone());
            // FNV-1a: stable from run to run and machine to machine.
            let hash = path
                .as_os_str()
                .as_encoded_bytes()
                .iter()
                .fold(0xcbf2_9ce4_8422_2325_u64, |h, b| {
                    (h ^ u64::from(*b)).wrapping_mul(0x0000_0100_0000_01b3)
                });
            format!("{stem}-{:08x}", hash >> 32)
        })
        .collect();
    for (i, p) in plays.iter_mut().enumerate() {
        p.stem = if keys.iter().filter(|k| **k == keys[i]).count() == 1 {
            keys[i].clone()
        } else {
            format!("{}-{}", keys[i], i + 1)
        };
    }
}

/// Reads an input file as psmpa-sim does: a regular file of at most 1 MiB.
fn read_input(path: &Path, what: &str) -> Result<Vec<u8>, String> {
    if path.as_os_str().is_empty() {
        return Err(format!("an empty path, not a {what} file"));
    }
    psmpa_sim::cli::files::read_input(path, what)
}

/// The shortest run the bench plays, ms: the chip boots and establishes its model first
/// (42 ms), and a run must leave it time to act.
pub const MIN_RUN_MS: u64 = 1_000;

/// Whether the bench can play `sc`: a scenario psmpa-sim accepts that the bench cannot play
/// faithfully is refused up front, saying why.
fn playable(sc: &Scenario) -> Result<(), String> {
    if sc.max_ms < MIN_RUN_MS {
        return Err(format!(
            "max_s {}: the bench plays runs of at least {} s (the chip boots and establishes its model first)",
            sc.max_ms as f64 / 1e3,
            MIN_RUN_MS / 1_000
        ));
    }
    if to_mm(sc.door_um) < 1 {
        return Err(
            "door_m: the board's walk is whole millimetres; a door less than 1 mm away is no walk"
                .to_owned(),
        );
    }
    Ok(())
}

/// The `.json` files of `dir`, sorted.
fn json_files(dir: &Path) -> Result<Vec<PathBuf>, String> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| format!("{}: {e}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "json"))
        .collect();
    files.sort();
    Ok(files)
}

/// The firmware image and what the bench needs of it.
struct Firmware {
    elf: Vec<u8>,
    /// Flash from [`FLASH`], up to the calibration record's end.
    flash: Vec<u8>,
    symbols: Symbols,
    /// Where the code runs: the `.text` section's first address and its end.
    code: [u32; 2],
    /// Bytes the boot copies into SRAM (`__psmpa_code_start` to `__psmpa_code_end`; 0 for an
    /// image that runs from flash).
    copied: u32,
    health_words: u32,
    /// Where the calibration record goes, as an offset in `flash`.
    settings_at: usize,
    /// The mission's sensor ids of the sonar, bumper, camera and handle.
    ids: [usize; 4],
    /// The stack: from its lowest address to its top (`_stack_end`, `_stack_start`).
    stack: (u32, u32),
    /// The annotated loops whose back edges the harness counts (`cargo xtask wcet`'s).
    loops: Vec<crate::wcet::BenchLoop>,
    /// The entries of the decisions' functions ([`TIMED`]), 0 for none.
    timed: Vec<u32>,
}

/// Builds the board's RP2040 image (`cargo build --release` in `boards/pico`).
fn build() -> Result<PathBuf, String> {
    firmware::build_board(firmware::PICO)
}

impl Firmware {
    fn read(path: &Path) -> Result<Self, String> {
        let elf = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let file = object::File::parse(&*elf).map_err(|e| format!("{}: {e}", path.display()))?;
        let symbol = |name: &str| {
            file.symbols()
                .find(|s| s.name() == Ok(name))
                .map(|s| (u32::try_from(s.address()).unwrap_or(0), s.size()))
                .ok_or_else(|| format!("{}: no symbol {name}", path.display()))
        };
        let (settings, _) = symbol("__psmpa_settings")?;
        let stack = (symbol("_stack_end")?.0, symbol("_stack_start")?.0);
        let (health, health_size) = symbol("PSMPA_HEALTH")?;
        let symbols = Symbols {
            rtt: symbol("_SEGGER_RTT")?.0,
            health,
            test_panic: symbol("psmpa_test_panic")?.0,
            test_hang: symbol("psmpa_test_hang")?.0,
        };
        let settings_at = usize::try_from(settings - FLASH).map_err(|e| e.to_string())?;
        let mut flash = vec![0xff; settings_at + RECORD_WORDS * 4];
        for (at, data) in load_segments(&file)? {
            let Some(offset) = at.checked_sub(FLASH).map(|o| o as usize) else {
                continue;
            };
            if offset + data.len() > settings_at {
                return Err(format!(
                    "{}: a segment at {at:#x} runs into the calibration record",
                    path.display()
                ));
            }
            flash[offset..offset + data.len()].copy_from_slice(data);
        }
        let text = file
            .section_by_name(".text")
            .ok_or_else(|| format!("{}: no .text section", path.display()))?;
        let code =
            [text.address(), text.address() + text.size()].map(|a| u32::try_from(a).unwrap_or(0));
        let copied = match (symbol("__psmpa_code_start"), symbol("__psmpa_code_end")) {
            (Ok((from, _)), Ok((to, _))) => to.saturating_sub(from),
            _ => 0,
        };
        let ids = [Sonar, Bumper, Camera, Handle].map(|s| s.id().index());
        let timed = timed_entries(&file).map_err(|e| format!("{}: {e}", path.display()))?;
        Ok(Self {
            elf,
            flash,
            symbols,
            code,
            copied,
            health_words: u32::try_from(health_size / 4).unwrap_or(0),
            settings_at,
            ids,
            stack,
            loops: Vec::new(),
            timed,
        })
    }

    /// This image with what the bench watches of the analysis of it: its annotated loops,
    /// counted, and the control task's poll, timed.
    fn watching(self, w: crate::wcet::BenchWatch) -> Self {
        let control = u32::try_from(w.control_poll).unwrap_or(0);
        Self {
            loops: w.loops,
            timed: [self.timed, vec![control]].concat(),
            ..self
        }
    }

    /// The flash image with `settings`' calibration record.
    fn image(&self, settings: &Settings) -> Vec<u8> {
        let mut flash = self.flash.clone();
        let record: Vec<u8> = settings
            .to_record()
            .iter()
            .flat_map(|w| w.to_le_bytes())
            .collect();
        flash[self.settings_at..self.settings_at + record.len()].copy_from_slice(&record);
        flash
    }
}

/// The bytes the ELF's loadable segments put at their load (physical) addresses: `.data`'s
/// initial values live in flash, where the program headers say.
fn load_segments<'a>(file: &object::File<'a>) -> Result<Vec<(u32, &'a [u8])>, String> {
    use object::read::elf::ProgramHeader;
    let object::File::Elf32(elf) = file else {
        return Err("the firmware is not a 32-bit ELF".to_owned());
    };
    let endian = elf.endian();
    let data = elf.data();
    elf.elf_program_headers()
        .iter()
        .filter(|h| h.p_type(endian) == object::elf::PT_LOAD && h.p_filesz(endian) > 0)
        .map(|h| {
            let bytes = h
                .data(endian, data)
                .map_err(|()| "a program header points outside the ELF".to_owned())?;
            Ok((h.p_paddr(endian), bytes))
        })
        .collect()
}

/// A line of the firmware's log.
#[derive(Clone, Debug, Serialize)]
pub struct LogLine {
    /// The firmware's timestamp (s since boot), as it prints it.
    pub at: String,
    /// Its level.
    pub level: String,
    /// The message.
    pub text: String,
    /// The emulated instant the harness read it, ns.
    #[serde(skip)]
    pub ns: u64,
}

/// What one run found.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// The scenario's name.
    pub scenario: String,
    /// The file played.
    pub file: String,
    /// The fault, for a fault scenario.
    pub fault: Option<String>,
    /// Interferences in the scenario.
    pub interferences: u32,
    /// Detected by the robot's sensors.
    pub detected: u32,
    /// Touched unregistered.
    pub collisions: u32,
    /// Whether the robot reached the kitchen door.
    pub reached_door: bool,
    /// Per obstacle, in order: the sensor whose recorded reading detected it, or `None`.
    pub detected_by: Vec<Option<String>>,
    /// The longest gap between two delivered samples while the sensor stayed on, ms (from
    /// the flight recording).
    pub sample_gap_max_ms: BTreeMap<String, Option<f64>>,
    /// The longest gap between two of the sonar's triggers while it stayed on, ms (from the
    /// pin).
    pub trigger_gap_max_ms: Option<f64>,
    /// The worst reaction measured per sensor, from the pin edge that showed the obstacle to
    /// the motors stopping, cycles at 125 MHz.
    pub reactions_cycles: BTreeMap<String, Option<u64>>,
    /// The response-time bound per sensor, cycles at 125 MHz.
    pub bound_cycles: BTreeMap<String, Option<u64>>,
    /// Where the bounds' costs come from: `"budget"` (`boards/pico/bench-budget.json`).
    pub bound_source: String,
    /// `psmpa-sim run --arch psmpa` of the same scenario (none for a fault scenario).
    pub host: Option<HostOutcome>,
    /// How the firmware said its task ended (its log's last word on it), if it did.
    pub mission: Option<String>,
    /// Whether the chip's own log says its mission reached its goal.
    pub mission_succeeded: bool,
    /// Whether the rig's world has the robot in the kitchen: moved there only by the motor
    /// pins (a drive that pushed an open door), never by what the chip says.
    pub in_kitchen: bool,
    /// The control loop's decisions on the chip, timed by the harness ([`DecisionCycles`]).
    pub decision_cycles: DecisionCycles,
    /// Resets by the watchdog.
    pub watchdog_resets: u32,
    /// Emulated time, s.
    pub emulated_s: f64,
    /// Wall time, s.
    pub wall_s: f64,
    /// The sensing side's cycles per delivered sample (all of its activations, mean).
    pub sensing_cycles_per_sample: Option<u64>,
    /// The step costs measured, cycles (the deciding step without the scenario's declared
    /// planning).
    pub costs: bound::Costs,
    /// The firmware's own health block at the end (`PSMPA_HEALTH`): a diagnostic, which no
    /// check reads.
    pub health_diagnostic: BTreeMap<String, world::Health>,
    /// The stack's high-water mark at the end, bytes (after a reset: the new boot's).
    pub stack_bytes: u64,
    /// The boot's copy of the image into SRAM (the last boot's), emulated cycles from reset
    /// to cortex-m-rt's reset handler, and the bytes it copied.
    pub boot_copy: BootCopy,
    /// Hash of every pin edge, duty and input level with its instant.
    pub pin_log_hash: String,
    /// The checks that failed (none: passed).
    pub failures: Vec<String>,
    /// The flight recording the firmware streamed, replayed on the host.
    pub recording: Option<BenchRecording>,
    /// The firmware's log.
    #[serde(skip)]
    pub log: Vec<LogLine>,
    /// Whether the run was cut at its scenario's `max_s` before the firmware said how its
    /// task ended.
    #[serde(skip)]
    pub cut_at_max_s: bool,
}

/// What the Pico's boot costs to run the image from SRAM: its boot vectors (in flash) copy the
/// vector table, the code and the constants to where they are linked.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct BootCopy {
    /// The emulator's cycles, reset to the reset handler (no XIP wait states counted).
    pub cycles: u64,
    /// Bytes copied.
    pub bytes: u64,
}

/// The worst own cycles of each decision of the control loop on the chip (the emulated
/// RP2040's, from a function's entry to its return, handlers excluded; 8 ns each at
/// 125 MHz), `None` where none was made: plan selection (BDI: the trigger, the context, the
/// applicable plans), one FSM compilation (Algorithm 2), one planner search (its start and
/// every slice, with `plan_expanded` the most nodes a search expanded, from the flight
/// recording).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct DecisionCycles {
    /// Selecting a plan.
    pub select: Option<u64>,
    /// Compiling a plan into its FSM.
    pub compile: Option<u64>,
    /// One search of the planner, all its slices.
    pub plan: Option<u64>,
    /// Nodes the planner expanded in a search, the most of one.
    pub plan_expanded: Option<u32>,
}

impl DecisionCycles {
    /// From the harness's timed calls of [`TIMED`]'s functions, in order (a search begins at
    /// each call of its start), and the most nodes a recorded search expanded.
    fn of(calls: &[(usize, u64)], expanded: Option<u32>) -> Self {
        let worst = |which: usize| {
            calls
                .iter()
                .filter(|(i, _)| *i == which)
                .map(|(_, c)| *c)
                .max()
        };
        let mut searches: Vec<u64> = Vec::new();
        for &(i, cycles) in calls {
            match i {
                PLAN_START => searches.push(cycles),
                PLAN_STEP => {
                    if let Some(s) = searches.last_mut() {
                        *s += cycles;
                    }
                }
                _ => {}
            }
        }
        Self {
            select: worst(SELECT),
            compile: worst(COMPILE),
            plan: searches.into_iter().max(),
            plan_expanded: expanded,
        }
    }
}

#[cfg(test)]
mod decision_tests {
    use super::*;

    #[test]
    fn a_control_poll_is_measured_without_the_planning_it_waited_out() {
        // The poll that planned: 6,060,000 cycles, 6,000,000 of them the declared wait; a
        // poll after it that did not plan keeps all of its own.
        let calls = [
            (SELECT, 600),
            (COMPUTE, 6_000_000),
            (CONTROL_POLL, 6_060_000),
            (CONTROL_POLL, 50_000),
        ];
        assert_eq!(bound::control_polls(&calls), 60_000);
        assert_eq!(bound::control_polls(&calls[..2]), 0);
        assert_eq!(bound::control_polls(&[(CONTROL_POLL, 70_000)]), 70_000);
    }

    #[test]
    fn a_search_is_its_start_and_every_slice_up_to_the_next_start() {
        let calls = [
            (SELECT, 600),
            (PLAN_START, 100),
            (PLAN_STEP, 1_000),
            (PLAN_STEP, 2_000),
            (COMPILE, 900),
            (PLAN_START, 50),
            (PLAN_STEP, 3_000),
            (SELECT, 700),
        ];
        let d = DecisionCycles::of(&calls, Some(3));
        assert_eq!(d.select, Some(700));
        assert_eq!(d.compile, Some(900));
        // 100 + 1,000 + 2,000 against 50 + 3,000.
        assert_eq!(d.plan, Some(3_100));
        assert_eq!(d.plan_expanded, Some(3));
        assert_eq!(DecisionCycles::of(&[], None), DecisionCycles::default());
    }
}

/// The functions the harness times, by their demangled names (without the hash): each
/// decision is one call, or a search's start and its slices. Out of line in the core for this.
const TIMED: [&str; 5] = [
    "psmpa_core::runtime::control::<impl psmpa_core::runtime::Runtime<M,P,T>>::select",
    "psmpa_core::runtime::fsm::Fsm::compile",
    "as psmpa_core::runtime::control::Fallback<_>>::start",
    "as psmpa_core::runtime::control::Fallback<_>>::step",
    // The walk's declared planning time (the board's busy wait), inside a control poll.
    "as psmpa_fetch_tea::Compute>::compute",
];
const SELECT: usize = 0;
const COMPILE: usize = 1;
const PLAN_START: usize = 2;
const PLAN_STEP: usize = 3;
const COMPUTE: usize = 4;
/// The control task's poll function, timed after [`TIMED`]'s (the analysis finds it:
/// embassy's generic task poll has no name of its own).
const CONTROL_POLL: usize = TIMED.len();

/// The entry of each of [`TIMED`] in `file`, 0 where the image has none (a library plan
/// only image has no planner); more than one is an error (the timing would be ambiguous), and
/// so is no selection: every image selects plans, so its name changed.
fn timed_entries(file: &object::File<'_>) -> Result<Vec<u32>, String> {
    TIMED
        .iter()
        .enumerate()
        .map(|(i, pattern)| {
            let found: Vec<u32> = file
                .symbols()
                .filter(|s| s.kind() == object::SymbolKind::Text)
                .filter(|s| {
                    let name = format!("{:#}", rustc_demangle::demangle(s.name().unwrap_or("")));
                    if pattern.starts_with("as ") {
                        name.contains(pattern)
                    } else {
                        name == *pattern
                    }
                })
                .map(|s| u32::try_from(s.address()).unwrap_or(0) & !1)
                .collect();
            match found[..] {
                [] if i == SELECT => Err(format!(
                    "the image has no function `{pattern}`: renamed? (the decisions' timing needs it)"
                )),
                [] => Ok(0),
                [at] => Ok(at),
                _ => Err(format!(
                    "the image has {} functions `{pattern}`",
                    found.len()
                )),
            }
        })
        .collect()
}

/// A run's flight recording, as `psmpa-sim replay` found it.
#[derive(Clone, Debug, Default, Serialize)]
pub struct BenchRecording {
    /// Frames streamed over RTT.
    pub frames: usize,
    /// Decisions the replay compared, all equal.
    pub decisions: usize,
    /// The most an event came earlier or later than recorded, ms.
    pub skew_ms: u64,
    /// After a watchdog reset: frames the RAM ring kept from before it (the streamed
    /// recording's last ones, checked).
    pub ring_frames: Option<usize>,
}

/// Keeps a run's recordings in `target/recordings/bench/` and checks them: the streamed one
/// replays on the host with every decision equal (where a reset cut it, up to its end), and
/// after a reset the ring's frames are the streamed recording's last ones.
fn check_recording(
    report: &mut Report,
    stem: &str,
    cut_at_end: bool,
    written: &Settings,
    dir: &Path,
) {
    let text: String = report
        .log
        .iter()
        .map(|l| format!("{} {}\n", l.level, l.text))
        .collect();
    let mut fail = |why: String| report.failures.push(format!("flight recording: {why}"));
    let recs = match psmpa_sim::replay::from_log(&text) {
        Ok(r) => r,
        Err(e) => return fail(e),
    };
    if let Err(e) = std::fs::create_dir_all(dir) {
        return fail(format!("{}: {e}", dir.display()));
    }
    if recs.len() > 2 {
        return fail(format!("{} recordings in one run's log", recs.len()));
    }
    let mut read = Vec::new();
    for (i, bytes) in recs.iter().enumerate() {
        let path = dir.join(if i == 0 {
            format!("{stem}.rec")
        } else {
            format!("{stem}.ring.rec")
        });
        if let Err(e) = std::fs::write(&path, bytes) {
            return fail(format!("{}: {e}", path.display()));
        }
        match psmpa_sim::replay::read(&path, bytes) {
            Ok(r) => read.push(r),
            Err(e) => return fail(e),
        }
    }
    let reset = report.watchdog_resets > 0;
    let Some(streamed) = read.first() else {
        return fail("none in the log".to_owned());
    };
    // The replay follows the recording's own calibration record: it must be the one the bench
    // wrote into flash (a board that changes what it read runs another robot).
    if let Some(why) = calibration_differs(&streamed.source, written) {
        fail(why);
    }
    let mut found = BenchRecording {
        frames: streamed.frames.len(),
        ..BenchRecording::default()
    };
    match psmpa_sim::replay::replay(streamed, None, recording::CHIP_LAG) {
        Ok((r, _)) => {
            // A recording a reset or the run's end (`max_s`) cut: equal up to its end.
            let cut = (reset || cut_at_end)
                && r.divergence
                    .as_ref()
                    .is_some_and(|d| d.recorded.is_none() && d.event == found.frames);
            if r.diverged && !cut {
                fail(format!("{stem}.rec: {}", r.text().trim_end()));
            }
            found.decisions = r.decisions;
            found.skew_ms = r.skew_ms;
        }
        Err(e) => fail(e),
    }
    match (reset, read.get(1)) {
        (true, Some(ring)) => {
            let n = ring.frames.len();
            let tail = streamed
                .frames
                .get(streamed.frames.len().saturating_sub(n)..);
            if n == 0 || tail != Some(&ring.frames[..]) {
                fail(format!(
                    "the ring kept {n} frames, not the streamed recording's last ones"
                ));
            }
            found.ring_frames = Some(n);
        }
        (true, None) => fail("no ring after the reset".to_owned()),
        (false, Some(_)) => fail("a second recording without a reset".to_owned()),
        (false, None) => {}
    }
    report.recording = Some(found);
}

/// The settings of a calibration record ([`Settings::to_record`]), word by word after its
/// magic and version: each one's name and unit (`‰`: a duty, two's complement).
const RECORD_FIELDS: [(&str, &str); RECORD_WORDS - 3] = [
    ("clearance", "mm"),
    ("walk", "mm"),
    ("walking duty", "‰"),
    ("walking speed", "mm/s"),
    ("push duty", "‰"),
    ("push", "ms"),
    ("enter duty", "‰"),
    ("enter", "ms"),
    ("planning", "µs"),
    ("sonar period", "ms"),
    ("bumper period", "ms"),
    ("side step", "ms"),
    ("echo rise", "ms"),
    ("back door", "mm"),
];

/// Why a board's recording does not carry the calibration record `written` into flash: its
/// first setting that differs, compared word by word; `None` when it does.
fn calibration_differs(source: &psmpa_sim::replay::Source, written: &Settings) -> Option<String> {
    let psmpa_sim::replay::Source::Board { settings } = source else {
        return Some("not a board's recording".to_owned());
    };
    let (ran, wrote) = (settings.to_record(), written.to_record());
    if ran == wrote {
        return None;
    }
    // A period of 0 is the mission's own.
    let word = |w: u32, (name, unit): (&str, &str)| match unit {
        "‰" => format!("{} {unit}", w as i32),
        _ if w == 0 && name.ends_with("period") => "the mission's".to_owned(),
        _ => format!("{w} {unit}"),
    };
    let field = ran
        .iter()
        .zip(&wrote)
        .skip(2)
        .zip(RECORD_FIELDS)
        .find(|((a, b), _)| a != b)
        .map_or_else(String::new, |((a, b), field)| {
            let (ran, wrote) = (word(*a, field), word(*b, field));
            format!(": {} {ran} where the bench wrote {wrote}", field.0)
        });
    Some(format!(
        "the board ran with another calibration than the bench wrote into its flash{field}"
    ))
}

/// psmpa-sim's outcome of the same scenario.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct HostOutcome {
    /// Detected.
    pub detected: u32,
    /// Collisions.
    pub collisions: u32,
    /// Reached the door.
    pub reached_door: bool,
    /// Reached its goal: the robot in the kitchen.
    pub mission_succeeded: bool,
}

/// One run's record of pins and events, for the picture and the hash.
#[derive(Default)]
pub struct PinLog {
    /// (ns, what, value): output edges, duties, inputs set.
    pub entries: Vec<(u64, String, i64)>,
    /// The world's events: (ms, position µm, event).
    pub world: Vec<(u64, i64, psmpa_sim::world::WorldEvent)>,
}

impl PinLog {
    fn push(&mut self, ns: u64, what: impl Into<String>, value: i64) {
        self.entries.push((ns, what.into(), value));
    }

    fn hash(&self) -> u64 {
        let mut h = TraceHash::new();
        for (ns, what, value) in &self.entries {
            h.write(&ns.to_le_bytes());
            h.write(what.as_bytes());
            h.write(&value.to_le_bytes());
        }
        h.value()
    }
}

/// Plays `play` on the image of `fw`, judged by `budget`; `out` is where its files go.
fn play(
    fw: &Firmware,
    play: &Play,
    budget: &Budget,
    out: &Path,
    recordings: &Path,
) -> Result<(Report, PinLog), String> {
    let sc = &play.scenario;
    let settings = settings_for(sc, Chassis::Wheeled);
    // The image is 2 MiB of flash, mostly empty: not kept, whatever ends the run (an error, a
    // panic, an interrupt).
    let scratch = psmpa_sim::cli::files::Scratch::new(&out.join(format!("{}.bin", play.stem())));
    let image = scratch.path().to_path_buf();
    std::fs::write(&image, fw.image(&settings)).map_err(|e| format!("{}: {e}", image.display()))?;
    let inputs: BTreeMap<u8, Option<u8>> = BenchWorld::initial_inputs()
        .iter()
        .map(|&(p, l)| (p, l.map(u8::from)))
        .collect();
    let boot = Boot {
        flash: image,
        symbols: fw.symbols,
        code: fw.code,
        health_words: fw.health_words,
        outputs: vec![
            pin::TRIGGER,
            pin::STBY,
            pin::LEFT[0],
            pin::LEFT[1],
            pin::RIGHT[0],
            pin::RIGHT[1],
        ],
        pwm: vec![pin::LEFT[2], pin::RIGHT[2]],
        inputs,
        seed: sc.seed.to_string(),
        loops: fw.loops.clone(),
        timed: fw.timed.clone(),
    };
    let mut harness = Harness::start(&boot)?;
    let table = defmt_decoder::Table::parse(&fw.elf)
        .map_err(|e| format!("the firmware's defmt table: {e}"))?
        .ok_or("the firmware has no defmt table")?;
    let wall = WallClock::now();
    let limit = Duration::from_millis(sc.max_ms) + Duration::from_secs(2);
    let run = psmpa_sim::backend::simulate(
        co_simulate(fw, play, &settings, budget, &mut harness, &table),
        limit,
    )
    .map_err(|e| format!("{}: {e}", play.name()))?
    .output?;
    drop(scratch);
    let (mut report, pins, obstacles) = run;
    report.wall_s = wall.elapsed().as_secs_f64();
    if play.fault.is_none() {
        compare_with_host(sc, &mut report, &obstacles);
    }
    let cut = report.cut_at_max_s;
    check_recording(&mut report, &play.stem(), cut, &settings, recordings);
    Ok((report, pins))
}

fn file_name(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Moves the world's clock to `ns` of emulated time (its millisecond).
async fn clock_to(ns: u64) {
    let at = Instant::from_millis(ns / 1_000_000);
    if at > Instant::now() {
        Timer::at(at).await;
    }
}

/// The pins a fault plays, from a fault scenario.
fn pin_fault(fault: Option<&Fault>) -> Option<PinFault> {
    match fault? {
        f @ Fault::NoEcho { .. } => Some(PinFault::NoEcho { at_ns: f.at_ns() }),
        f @ Fault::EchoStuckHigh { .. } => Some(PinFault::EchoStuck { at_ns: f.at_ns() }),
        f @ Fault::TooNear { .. } => Some(PinFault::TooNear { at_ns: f.at_ns() }),
        f @ Fault::MarkerGone { .. } => Some(PinFault::MarkerGone { at_ns: f.at_ns() }),
        f @ Fault::BumperChatter {
            for_s, every_us, ..
        } => Some(PinFault::Chatter {
            at_ns: f.at_ns(),
            until_ns: f.at_ns() + (for_s * 1e9) as u64,
            every_ns: every_us * 1_000,
        }),
        Fault::Hang { .. } | Fault::Panic { .. } => None,
    }
}

/// What a run collects besides the world.
#[derive(Default)]
struct Collected {
    log: Vec<LogLine>,
    resets: Vec<u64>,
    pins: PinLog,
    /// The chip's flight recording, read as it comes.
    chip: chip::ChipRecording,
    /// Why the recording could not be read, if it could not.
    chip_error: Option<String>,
    /// The emulator's warnings: what, where, when.
    warnings: Vec<(String, u32, u64)>,
    /// The firmware's health block, last read (a diagnostic).
    health: Vec<u32>,
    /// When the firmware said how its task ended (or that it was reset), ns.
    done: Option<u64>,
    /// What it said.
    ending: Option<String>,
    /// When the bench injected a fault through a test point, ns.
    injected: Option<u64>,
    /// Whether the motors drove when it did.
    drove_at_injection: bool,
    /// When a fault struck: the injection, the sensor's recorded failure, a reset, ns.
    struck: Option<u64>,
    /// The motors started to drive after the fault struck, ns.
    drove_after: Option<u64>,
    /// Whether the motors drove at the last motor event.
    driving: bool,
    /// After a fault struck: when the motors went off, and when the log first spoke.
    off_at: Option<u64>,
    spoke_at: Option<u64>,
    /// The most nodes a search the chip recorded expanded.
    expanded: Option<u32>,
}

async fn co_simulate(
    fw: &Firmware,
    play: &Play,
    settings: &Settings,
    budget: &Budget,
    harness: &mut Harness,
    table: &defmt_decoder::Table,
) -> Result<(Report, PinLog, Vec<ObstacleReport>), String> {
    let sc = &play.scenario;
    let fault = play.fault.as_ref().map(|f| f.fault);
    let walk = settings.walk_permille.unsigned_abs();
    let mut bw = BenchWorld::new(
        sc,
        walk,
        fw.ids,
        pin_fault(fault.as_ref()),
        budget.tolerance_mm(),
    );
    let mut decoder = table.new_stream_decoder();
    let mut c = Collected::default();
    let end_ns = sc.max_ms.saturating_mul(1_000_000);
    let inject = fault.filter(|f| matches!(f, Fault::Hang { .. } | Fault::Panic { .. }));
    let mut injected = false;
    let mut now = 0u64;
    let send = |harness: &mut Harness, pins: &mut PinLog, sets: Vec<world::Set>| {
        for (p, level, at) in sets {
            // 2: open.
            pins.push(at, format!("in{p}"), level.map_or(2, i64::from));
            harness.set(p, level, at)?;
        }
        Ok::<(), String>(())
    };
    send(harness, &mut c.pins, bw.chatter())?;
    let live_bounds = scenario_bounds(budget, sc).ok();
    loop {
        let mut finish = c
            .done
            .map_or(end_ns, |d| d.saturating_add(GRACE_NS).min(end_ns));
        // A fault injected through a test point that neither the firmware's word nor a reset
        // answers within the watchdog's timeout and a grace (a hang before the watchdog
        // started, a board still fed): the run ends there and its checks judge it, rather
        // than spin to the scenario's end.
        if let Some(at) = c.injected
            && c.done.is_none()
            && c.resets.is_empty()
        {
            finish = finish.min(at.saturating_add(UNANSWERED_NS));
        }
        if now >= finish || (play.stop_at_failure && failing(&bw, &c, live_bounds, now)) {
            break;
        }
        let mut stop = finish;
        if let Some(t) = bw.next_event_ns() {
            stop = stop.min(t.max((now / 1_000_000 + 1) * 1_000_000));
        }
        if let Some(f) = inject.filter(|_| !injected) {
            stop = stop.min(f.at_ns().max(now + 1));
        }
        for event in harness.run(stop)? {
            match event {
                Event::Pin { pin, level, ns } => {
                    clock_to(ns).await;
                    c.pins.push(ns, format!("out{pin}"), i64::from(level));
                    let sets = bw.output(pin, level == 1, ns);
                    send(harness, &mut c.pins, sets)?;
                    motors(&bw, &mut c, ns);
                }
                Event::Duty { pin, permille, ns } => {
                    clock_to(ns).await;
                    c.pins.push(ns, format!("duty{pin}"), i64::from(permille));
                    let sets = bw.duty(pin, permille, ns);
                    send(harness, &mut c.pins, sets)?;
                    motors(&bw, &mut c, ns);
                }
                Event::Health { words, .. } => c.health = words,
                Event::Rtt { data, ns } => {
                    c.spoke_at.get_or_insert(ns);
                    clock_to(ns).await;
                    let first = c.log.len();
                    decode(&mut *decoder, &data, ns, &mut c)?;
                    for i in first..c.log.len() {
                        let frames = match c.chip.line(&c.log[i].text) {
                            Ok(f) => f,
                            Err(e) => {
                                c.chip_error.get_or_insert(e);
                                continue;
                            }
                        };
                        for (at, frame) in frames {
                            if let Some(n) = frame.expanded() {
                                c.expanded = c.expanded.max(Some(n));
                            }
                            let sets = bw.recorded(at, &frame, ns);
                            send(harness, &mut c.pins, sets)?;
                        }
                    }
                    if fault.is_some()
                        && let Some(t) = bw.sensor_failed
                    {
                        c.struck.get_or_insert(t);
                    }
                }
                Event::Reset { ns, .. } => {
                    c.resets.push(ns);
                    c.pins.push(ns, "reset", 0);
                    c.struck.get_or_insert(ns);
                }
                Event::Warning { message, pc, ns } => c.warnings.push((message, pc, ns)),
                Event::At { ns } => now = ns,
                Event::Error { message } => return Err(message),
            }
        }
        clock_to(now).await;
        let mut sets = Vec::new();
        bw.inputs_now(now, &mut sets);
        send(harness, &mut c.pins, sets)?;
        if let Some(f) = inject.filter(|f| !injected && now >= f.at_ns()) {
            harness.inject(f.name())?;
            injected = true;
            c.injected = Some(now);
            c.drove_at_injection = bw.motors_on();
            c.struck = Some(now);
            c.off_at = None;
            c.spoke_at = None;
            c.pins.push(now, format!("inject-{}", f.name()), 0);
        }
    }
    bw.finish(now);
    let stats = harness.stats()?;
    let stack = harness.stack(fw.stack.0, fw.stack.1)?;
    let (mut report, mut pins) = report(fw, play, budget, &bw, c, &stats, now);
    report.stack_bytes = stack;
    let obstacles = bw.world().obstacles().to_vec();
    pins.world = bw.into_events();
    Ok((report, pins, obstacles))
}

/// The annotated loops that took more back edges on one entry than the analysis's jobs at
/// that exception level took on trust (`most[i][level]`, the harness's count); a level where
/// no job bounded the loop is not judged: no bound there was trusted.
fn loops_exceeded(loops: &[crate::wcet::BenchLoop], most: &[Vec<u64>]) -> Vec<String> {
    let mut failures = Vec::new();
    for (l, by_level) in loops.iter().zip(most) {
        for (level, most) in (0u32..).zip(by_level) {
            match l.bound_at(level) {
                Some(bound) if *most > bound => failures.push(format!(
                    "loops: the loop at {:#x} ({}) took {most} back edges on one entry at exception level {level}, more than the {bound} its annotation in boards/pico/wcet-loops.json allows there",
                    l.entries.first().copied().unwrap_or(l.function[0]),
                    l.annotation,
                )),
                _ => {}
            }
        }
    }
    failures
}

/// The sonar's and the bumper's bounds in `sc` from `budget`, its declared planning time added
/// to the deciding step.
fn scenario_bounds(
    budget: &Budget,
    sc: &Scenario,
) -> Result<[u64; 2], psmpa_core::timing::TimingError> {
    let plan = bound::cycles_of_us(u64::from(sc.plan_us));
    bound::bounds(
        &budget.budget.with_plan(plan),
        [sc.sonar.period_ms, sc.bumper_period_ms],
    )
}

/// Whether a check has failed already, as far as a run in progress shows: a reading the pins
/// contradict, an emulator warning, a reaction beyond its bound, or one pending longer.
fn failing(bw: &BenchWorld, c: &Collected, bounds: Option<[u64; 2]>, now: u64) -> bool {
    let late = bw
        .reactions
        .iter()
        .zip(bounds.unwrap_or([0; 2]))
        .any(|(r, b)| {
            r.worst_cycles.is_some_and(|w| w > b)
                || r.pending
                    .is_some_and(|edge| now.saturating_sub(edge) / world::NS_PER_CYCLE > b)
        });
    !bw.misreads.is_empty() || !c.warnings.is_empty() || (bounds.is_some() && late)
}

/// Notes when the motors start to drive or go off, for the fault checks.
fn motors(bw: &BenchWorld, c: &mut Collected, ns: u64) {
    let started = bw.motors_on() && !c.driving;
    c.driving = bw.motors_on();
    if let Some(struck) = c.struck {
        if started && ns > struck {
            c.drove_after.get_or_insert(ns);
        }
        if !bw.motors_on() && c.off_at.is_none() && ns >= struck {
            c.off_at = Some(ns);
        }
    }
}

/// Decodes log bytes; notes the firmware's outcome.
fn decode(
    decoder: &mut dyn defmt_decoder::StreamDecoder,
    hex: &str,
    ns: u64,
    c: &mut Collected,
) -> Result<(), String> {
    let bytes: Vec<u8> = (0..hex.len() / 2)
        .filter_map(|i| u8::from_str_radix(hex.get(2 * i..2 * i + 2)?, 16).ok())
        .collect();
    decoder.received(&bytes);
    loop {
        match decoder.decode() {
            Ok(frame) => {
                let text = frame.display_message().to_string();
                let line = LogLine {
                    at: frame
                        .display_timestamp()
                        .map_or(String::new(), |t| t.to_string()),
                    level: frame.level().map_or("", |l| l.as_str()).to_uppercase(),
                    text,
                    ns,
                };
                let ends = [
                    GOAL_REACHED,
                    "Fetch Tea failed",
                    "the watchdog reset the board",
                    "the mission does not load",
                ];
                if ends.iter().any(|e| line.text.contains(e)) {
                    c.done.get_or_insert(ns);
                    c.ending.get_or_insert_with(|| line.text.clone());
                }
                c.log.push(line);
            }
            Err(defmt_decoder::DecodeError::UnexpectedEof) => return Ok(()),
            Err(defmt_decoder::DecodeError::Malformed) => {
                return Err("the firmware's log is malformed (RTT bytes lost?)".to_owned());
            }
        }
    }
}

/// What each check judges from, for the report: none reads the world's truth of what the
/// robot sensed, nor memory the firmware writes for a debugger.
pub const JUDGED_FROM: &[(&str, &str)] = &[
    (
        "readings",
        "the flight recording's samples against the echoes and switch closures the rig put on the pins",
    ),
    (
        "detections",
        "the flight recording's samples (which sensor read the obstacle) and the motor pins",
    ),
    (
        "reactions",
        "pin edges: an echo's fall or the bump switch settling, to the motor pins stopping",
    ),
    (
        "bounds",
        "the committed cost budget (boards/pico/bench-budget.json), never this run's costs",
    ),
    (
        "loops",
        "the program counter: each annotated loop's back edges an entry, against boards/pico/wcet-loops.json",
    ),
    (
        "costs",
        "the emulator's cycle counts of handlers, thread mode and spinlock 31, against the budget",
    ),
    (
        "sampling",
        "the sonar's trigger pin and the recording's samples, between its own SensorOn and SensorOff",
    ),
    (
        "chip",
        "rp2040js's warnings: an access silicon would fault on",
    ),
    ("faults", "the motor pins, the watchdog's resets, the log"),
    (
        "mission",
        "the chip's word that it reached its goal against the world the motor pins drove into the kitchen, the heading they turned, and psmpa-sim's outcome",
    ),
];

/// How the board's log says its mission reached its goal (`boards/rp/src/lib.rs`).
const GOAL_REACHED: &str = "Fetch Tea: goal reached";

/// The run's report and its checks.
fn report(
    fw: &Firmware,
    play: &Play,
    budget: &Budget,
    bw: &BenchWorld,
    c: Collected,
    stats: &Stats,
    now: u64,
) -> (Report, PinLog) {
    let sc = &play.scenario;
    let tally: Tally = bw.world().tally();
    let names = ["sonar", "bumper"];
    let mut failures = Vec::new();
    let plan = bound::cycles_of_us(u64::from(sc.plan_us));
    let mut costs = bound::Costs::of(stats);
    costs.deciding = costs.deciding.saturating_sub(plan);
    for over in costs.over(&budget.budget) {
        failures.push(format!("costs: {over}"));
    }
    let bounds = scenario_bounds(budget, sc);
    let ms = |ns: u64| ns as f64 / 1e6;
    let mut sample_gap_max_ms = BTreeMap::new();
    let mut reactions_cycles = BTreeMap::new();
    let mut bound_cycles = BTreeMap::new();
    for (i, name) in names.iter().enumerate() {
        let sampled = &bw.sampled[i];
        let gap = sampled.max_gap(&sampled.samples).map(ms);
        sample_gap_max_ms.insert((*name).to_owned(), gap);
        let r = bw.reactions[i].worst_cycles;
        reactions_cycles.insert((*name).to_owned(), r);
        let b = bounds.as_ref().ok().map(|b| b[i]);
        bound_cycles.insert((*name).to_owned(), b);
        if let (Some(r), Some(b)) = (r, b)
            && r > b
        {
            failures.push(format!(
                "reactions: a {name} reaction of {r} cycles exceeds its bound of {b} cycles"
            ));
        }
    }
    if let Err(e) = &bounds {
        failures.push(format!("bounds: no response-time bound: {e}"));
    }
    let trigger_gap = bw.sampled[0].max_gap(&bw.triggers).map(ms);
    if play.fault.is_none() {
        // Nothing the deciding side does holds a sample up: the sonar triggers on its period
        // (and a millisecond of scheduling); the bumper, never lost, delivers within its
        // period, plus a debounce time for a read that saw its level change (and a tick). A
        // walk that computes for 50 ms (`replan`) must not stretch either.
        let sonar_max = (sc.sonar.period_ms + 1) as f64;
        if let Some(gap) = trigger_gap.filter(|g| *g > sonar_max) {
            failures.push(format!(
                "sampling: the sonar's triggers lay {gap:.3} ms apart, more than its period and a millisecond ({sonar_max} ms)"
            ));
        }
        let bumper_max = (sc.bumper_period_ms + DEBOUNCE.as_millis() + 1) as f64;
        if let Some(Some(gap)) = sample_gap_max_ms.get("bumper")
            && *gap > bumper_max
        {
            failures.push(format!(
                "sampling: the bumper's samples lay {gap:.3} ms apart, more than its period and a debounce ({bumper_max} ms)"
            ));
        }
    }
    for m in &bw.misreads {
        failures.push(format!("readings: {m}"));
    }
    failures.extend(loops_exceeded(&fw.loops, &stats.loops));
    for (i, edge) in &bw.unanswered {
        failures.push(format!(
            "reactions: the robot still drove {:.3} ms after its {} showed an obstacle at {:.3} s",
            now.saturating_sub(*edge) as f64 / 1e6,
            names.get(*i).unwrap_or(&"?"),
            *edge as f64 / 1e9
        ));
    }
    for (ns, off) in &bw.off_course {
        failures.push(format!(
            "mission: the robot set off along its way at {:.3} s facing {} ms of turning {} off it: its turns did not cancel",
            *ns as f64 / 1e9,
            off.abs(),
            if *off > 0 { "left" } else { "right" }
        ));
    }
    // A reset or a panic lets the wheels coast (every pin low): a stop the firmware did not
    // command is no reaction of its.
    let commanded = !matches!(
        play.fault.as_ref().map(|f| f.fault),
        Some(Fault::Hang { .. } | Fault::Panic { .. })
    );
    for (i, edge, stop) in bw.coasted.iter().filter(|_| commanded) {
        failures.push(format!(
            "reactions: the motors coasted to a stop at {:.3} s, after the {} showed an obstacle at {:.3} s (IN1 and IN2 low, or STBY low): a reaction short-brakes the wheels",
            *stop as f64 / 1e9,
            names.get(*i).unwrap_or(&"?"),
            *edge as f64 / 1e9
        ));
    }
    for (message, pc, ns) in &c.warnings {
        failures.push(format!(
            "chip: rp2040js: {message} at PC {pc:#010x}, {:.6} s",
            *ns as f64 / 1e9
        ));
    }
    if let Some(e) = &c.chip_error {
        failures.push(format!("flight recording: it does not read: {e}"));
    }
    let cut = cut_at_max_s(sc, c.done, now);
    if let Some(f) = &play.fault {
        if let Some(e) = never_struck(&f.fault, c.injected, now) {
            failures.push(format!("faults: {e}"));
        }
        expectations(&f.expect, &tally, &c, &sample_gap_max_ms, &mut failures);
    } else if c.done.is_none() && !cut {
        failures.push("mission: the firmware never said how its task ended".to_owned());
    }
    let claimed = c
        .ending
        .as_deref()
        .is_some_and(|e| e.contains(GOAL_REACHED));
    let in_kitchen = bw.world().in_kitchen();
    // A claim the wheels did not make true always fails; a robot in the kitchen that never
    // says so fails unless a fault was injected (a hang may come after the last push).
    if (claimed && !in_kitchen) || (in_kitchen && !claimed && play.fault.is_none()) {
        failures.push(format!(
            "mission: the chip says it reached its goal: {claimed}; the rig's world, moved by the motor pins, has the robot in the kitchen: {in_kitchen}"
        ));
    }
    let delivered: u64 = bw.sampled.iter().map(|s| s.samples.len() as u64).sum();
    let sensing = stats
        .handlers
        .get(&bound::EXC_SENSING)
        .map_or(0, |h| h.total);
    let health_diagnostic = ["sonar", "bumper", "camera", "handle"]
        .iter()
        .zip(fw.ids)
        .map(|(name, id)| ((*name).to_owned(), world::Health::of(&c.health, id)))
        .collect();
    let detected_by = bw
        .world()
        .obstacles()
        .iter()
        .map(|o| match o.fate {
            Fate::Detected(d) => Some(d.name().to_owned()),
            _ => None,
        })
        .collect();
    let report = Report {
        scenario: sc.name.as_str().to_owned(),
        file: play.file.display().to_string(),
        fault: play.fault.as_ref().map(|f| f.fault.name().to_owned()),
        interferences: tally.interferences,
        detected: tally.detected,
        collisions: tally.collisions,
        reached_door: tally.reached_door,
        detected_by,
        sample_gap_max_ms,
        trigger_gap_max_ms: trigger_gap,
        reactions_cycles,
        bound_cycles,
        bound_source: "budget".to_owned(),
        host: None,
        mission_succeeded: claimed,
        in_kitchen,
        mission: c.ending.clone(),
        decision_cycles: DecisionCycles::of(&stats.calls, c.expanded),
        watchdog_resets: c.resets.len() as u32,
        emulated_s: now as f64 / 1e9,
        wall_s: 0.0,
        sensing_cycles_per_sample: sensing.checked_div(delivered),
        costs,
        health_diagnostic,
        stack_bytes: 0,
        boot_copy: BootCopy {
            cycles: stats.boot,
            bytes: u64::from(fw.copied),
        },
        pin_log_hash: format!("{:016x}", c.pins.hash()),
        failures,
        recording: None,
        log: c.log,
        cut_at_max_s: cut,
    };
    (report, c.pins)
}

/// Whether the run was cut at the scenario's `max_s` before the firmware said how its task
/// ended: as psmpa-sim's run, the robot is where the time left it (not at the door), which
/// the comparison with psmpa-sim judges.
fn cut_at_max_s(sc: &Scenario, done: Option<u64>, now: u64) -> bool {
    done.is_none() && now >= sc.max_ms.saturating_mul(1_000_000)
}

/// Why a fault never struck in a run that ended at `now`, if it did not: one through a test
/// point never injected, one on the pins after the run's end (a fault after the goal and its
/// grace).
fn never_struck(fault: &Fault, injected: Option<u64>, now: u64) -> Option<String> {
    let missed = match fault {
        Fault::Hang { .. } | Fault::Panic { .. } => injected.is_none(),
        _ => now < fault.at_ns(),
    };
    missed.then(|| {
        format!(
            "the fault never struck: the run ended at {:.3} s, before its at_s {} s",
            now as f64 / 1e9,
            fault.at_s()
        )
    })
}

/// psmpa-sim's outcome of the same scenario beside the bench's: reaching the door, and
/// obstacle by obstacle its fate and the sensor that detected it, all equal; and reaching the
/// goal (a difference there is never put down to timing).
fn compare_with_host(sc: &Scenario, r: &mut Report, bench: &[ObstacleReport]) {
    let s = match run_chassis(sc, Arch::PSmpa, Chassis::Wheeled) {
        Ok(s) => s,
        Err(e) => return r.failures.push(format!("mission: psmpa-sim: {e}")),
    };
    let host_succeeded = matches!(s.ending, psmpa_sim::run::Ending::Goal(_));
    r.host = Some(HostOutcome {
        detected: s.tally.detected,
        collisions: s.tally.collisions,
        reached_door: s.tally.reached_door,
        mission_succeeded: host_succeeded,
    });
    let mut differ = Vec::new();
    if s.tally.reached_door != r.reached_door {
        differ.push((
            "mission",
            format!(
                "psmpa-sim's robot reached the door: {}; the bench's: {}",
                s.tally.reached_door, r.reached_door
            ),
        ));
    }
    if host_succeeded != r.mission_succeeded {
        // The same robot on the same body plans the same way past a locked door: no timing
        // explains a difference here.
        r.failures.push(format!(
            "mission: psmpa-sim's robot reached its goal: {host_succeeded}; the bench's: {}",
            r.mission_succeeded
        ));
    }
    for (i, (host, bench)) in s.obstacles.iter().zip(bench).enumerate() {
        if host.fate == bench.fate {
            continue;
        }
        let kind = sc.interferences.get(i).map_or("?", |x| match x.kind {
            psmpa_sim::scenario::Kind::Box => "box",
            psmpa_sim::scenario::Kind::Ball => "ball",
        });
        differ.push((
            "detections",
            format!(
                "#{} {kind}: psmpa-sim's robot {}, the bench's {}",
                i + 1,
                fate(host.fate),
                fate(bench.fate)
            ),
        ));
    }
    // The same robot on the same body: any difference is a failure, none is excused.
    for (check, what) in differ {
        r.failures.push(format!("{check}: {what}"));
    }
}

/// An obstacle's fate in words.
fn fate(f: Fate) -> String {
    match f {
        Fate::Unmet => "never met it".to_owned(),
        Fate::Detected(d) => format!("detected it with its {}", d.name()),
        Fate::Collided => "collided with it".to_owned(),
    }
}

/// How soon the motors must stop once a fault with `still` struck, unless it says
/// (`stops_within_ms`): the runtime halts the robot in the deciding poll that learns of the
/// failure, which a poll in progress and the interrupts delay by a few ms at most.
const STILL_WITHIN_MS: u64 = 20;

/// A fault scenario's expectations, checked.
fn expectations(
    e: &Expect,
    tally: &Tally,
    c: &Collected,
    gaps: &BTreeMap<String, Option<f64>>,
    failures: &mut Vec<String>,
) {
    let mut check = |ok: bool, what: String| {
        if !ok {
            failures.push(format!("faults: {what}"));
        }
    };
    if let Some(want) = e.reached_door {
        check(
            tally.reached_door == want,
            format!("expected reached_door {want}, got {}", tally.reached_door),
        );
    }
    if let Some(want) = e.collisions {
        check(
            tally.collisions == want,
            format!("expected {want} collisions, got {}", tally.collisions),
        );
    }
    if let Some(want) = e.watchdog_resets {
        check(
            c.resets.len() as u32 == want,
            format!("expected {want} watchdog resets, got {}", c.resets.len()),
        );
    }
    // A reset before the fault was not the fault's.
    if let (Some(at), Some(first)) = (c.injected, c.resets.first()) {
        check(
            *first >= at,
            format!(
                "the watchdog reset the board at {:.3} s, before the fault at {:.3} s",
                *first as f64 / 1e9,
                at as f64 / 1e9
            ),
        );
    }
    if let Some(within) = e.stops_within_ms {
        match c.injected {
            None => check(
                false,
                "the fault was never injected: the run ended before it".to_owned(),
            ),
            Some(at) => {
                check(
                    c.drove_at_injection,
                    format!(
                        "the motors were not driving when the fault struck at {:.3} s: nothing to stop",
                        at as f64 / 1e9
                    ),
                );
                match c.off_at {
                    Some(off) => check(
                        off > at && off - at <= within * 1_000_000,
                        format!(
                            "the motors stopped {:.3} ms after the fault, not within {within} ms",
                            (off as f64 - at as f64) / 1e6
                        ),
                    ),
                    None => check(false, "the motors never stopped after the fault".to_owned()),
                }
            }
        }
    }
    if e.still {
        check(c.struck.is_some(), "the fault never struck".to_owned());
        // Stopped, and stopped in time: a halt that leaves the wheels turning drives blind.
        if let Some(struck) = c.struck {
            let within = e.stops_within_ms.unwrap_or(STILL_WITHIN_MS);
            if let Some(off) = c.off_at {
                check(
                    off.saturating_sub(struck) <= within * 1_000_000,
                    format!(
                        "the motors stopped {:.3} ms after the fault struck at {:.3} s, not within {within} ms",
                        off.saturating_sub(struck) as f64 / 1e6,
                        struck as f64 / 1e9
                    ),
                );
            }
            check(
                !c.driving,
                format!(
                    "the motors still drove when the run ended, after the fault struck at {:.3} s",
                    struck as f64 / 1e9
                ),
            );
        }
        if let Some(at) = c.drove_after {
            check(
                false,
                format!(
                    "the motors drove at {:.3} s, after the fault",
                    at as f64 / 1e9
                ),
            );
        }
    }
    if e.motors_off_first {
        match (c.off_at, c.spoke_at) {
            (Some(off), Some(spoke)) => check(
                off <= spoke,
                format!("the log spoke at {spoke} ns, before the motors went off at {off} ns"),
            ),
            (None, _) => check(false, "the motors never went off".to_owned()),
            // A panic logs its message: a log that never spoke shows nothing of the order.
            (Some(_), None) => check(
                false,
                "the log never spoke after the fault: which came first cannot be told".to_owned(),
            ),
        }
    }
    for want in &e.log {
        check(
            c.log.iter().any(|l| l.text.contains(want.as_str())),
            format!("the log never said {want:?}"),
        );
    }
    for (sensor, max) in &e.sample_gap_max_ms {
        match gaps.get(sensor).copied().flatten() {
            Some(g) => check(
                g <= *max,
                format!("{sensor}'s samples lay {g} ms apart, more than {max} ms"),
            ),
            None => check(false, format!("{sensor} delivered fewer than two samples")),
        }
    }
}

/// The boards' README shows log lines of a bench run of `sonar-6`: each must be a line of this
/// run's log, in the README's order, so that the README never shows lines written by hand.
/// Lines are compared by level and words, numbers aside (timestamps, counts, instants): a
/// microsecond's change does not fail it, a missing or reordered event does.
fn readme_log(reports: &[(Report, PinLog)]) -> Vec<String> {
    let path = firmware::root().join("boards/README.md");
    let Ok(readme) = std::fs::read_to_string(&path) else {
        return vec![format!("{}: cannot read it", path.display())];
    };
    let Some(run) = reports
        .iter()
        .find(|(r, _)| r.scenario == "sonar-6" && r.fault.is_none())
        .map(|(r, _)| r)
    else {
        return vec!["no run of sonar-6 to check the boards' README against".to_owned()];
    };
    let lines: Vec<String> = run
        .log
        .iter()
        .map(|l| format!("{} {}", l.level, l.text))
        .collect();
    log_block_in(&readme, &lines)
        .into_iter()
        .map(|l| {
            format!("boards/README.md shows a log line this bench run did not write there: {l}")
        })
        .collect()
}

/// The lines of `readme`'s log block that are not in `log` (`LEVEL text` lines) in the
/// block's order, numbers aside; a block with no lines, or none, is one such line.
fn log_block_in(readme: &str, log: &[String]) -> Vec<String> {
    let Some((_, block)) = readme.split_once("```text\n") else {
        return vec!["(no log block)".to_owned()];
    };
    let block = block.split("```").next().unwrap_or("");
    let log: Vec<String> = log.iter().map(|l| words(l)).collect();
    let mut from = 0;
    let mut missing = Vec::new();
    for line in block.lines().filter(|l| *l != "...") {
        // The block's lines start with the firmware's timestamp.
        let shown = words(line.split_once(' ').map_or(line, |(_, rest)| rest));
        match log
            .get(from..)
            .and_then(|rest| rest.iter().position(|l| *l == shown))
        {
            Some(i) => from += i + 1,
            None => missing.push(line.to_owned()),
        }
    }
    if block.lines().all(|l| l == "...") {
        missing.push("(an empty log block)".to_owned());
    }
    missing
}

/// A log line with each number as `#` and runs of spaces as one.
fn words(line: &str) -> String {
    let mut out = String::new();
    let mut number = false;
    for ch in line.chars() {
        if ch.is_ascii_digit() || (number && ch == '.') {
            if !number {
                out.push('#');
            }
            number = true;
            continue;
        }
        number = false;
        if ch == ' ' && out.ends_with(' ') {
            continue;
        }
        out.push(ch);
    }
    out.trim().to_owned()
}

/// One run's report and pin log, or why it could not run.
type Played = Result<(Report, PinLog), String>;

/// The Pico image `elf` booted on the bench's chip with no world (no input driven, no loop
/// counted), for calling its functions ([`Harness::call`]).
pub fn chip_for_calls(elf: &Path) -> Result<Harness, String> {
    harness::check_tools()?;
    let fw = Firmware::read(elf)?;
    let dir = firmware::root().join("target/hil");
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let image = dir.join("calls.bin");
    std::fs::write(&image, fw.image(&Settings::DEFAULT))
        .map_err(|e| format!("{}: {e}", image.display()))?;
    Harness::start(&Boot {
        flash: image,
        symbols: fw.symbols,
        code: fw.code,
        health_words: fw.health_words,
        outputs: Vec::new(),
        pwm: Vec::new(),
        inputs: BTreeMap::new(),
        seed: "0".to_owned(),
        loops: Vec::new(),
        timed: Vec::new(),
    })
}

/// The deepest stack the last bench run measured, bytes (`target/hil/stack.json`), and the
/// hash of the image's code it ran ([`crate::stack::pico_code_hash`]).
pub fn stack_high_water() -> Option<(u64, Option<u64>)> {
    let at = firmware::root().join("target/hil/stack.json");
    let text = std::fs::read(at).ok()?;
    let v = serde_json::from_slice::<serde_json::Value>(&text).ok()?;
    Some((v["stack_bytes"].as_u64()?, v["code_hash"].as_u64()))
}

/// Plays every one of `plays` on `fw`, two at a time (each run is one Node process and one
/// thread here); the results in their order.
fn play_all(
    fw: &Firmware,
    plays: &[Play],
    budget: &Budget,
    out: &Path,
    recordings: &Path,
) -> Vec<Played> {
    let next = std::sync::atomic::AtomicUsize::new(0);
    let slots: Vec<std::sync::Mutex<Option<Played>>> =
        plays.iter().map(|_| std::sync::Mutex::new(None)).collect();
    std::thread::scope(|s| {
        for _ in 0..2 {
            s.spawn(|| {
                loop {
                    let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    let (Some(p), Some(slot)) = (plays.get(i), slots.get(i)) else {
                        break;
                    };
                    let result = play(fw, p, budget, out, recordings);
                    if let Ok(mut slot) = slot.lock() {
                        *slot = Some(result);
                    }
                }
            });
        }
    });
    slots
        .into_iter()
        .map(|m| {
            m.into_inner()
                .ok()
                .flatten()
                .unwrap_or_else(|| Err("a run did not finish".to_owned()))
        })
        .collect()
}

/// The budget a calibration plays with: the committed one (its reading tolerance), or one of
/// typical costs when there is none. Its cost and bound checks are set aside
/// ([`calibrating`]): the costs are what is being measured.
fn provisional_budget() -> Budget {
    let typical = bound::Costs {
        sensing_poll: 15_000,
        alarm: 500,
        gpio: 1_000,
        deciding: 80_000,
        critical: 18_000,
        control_poll: 40_000,
    };
    let with_margin = bound::Costs {
        sensing_poll: 18_750,
        alarm: 1_500,
        gpio: 2_000,
        deciding: 100_000,
        critical: 22_500,
        control_poll: 50_000,
    };
    Budget::load().unwrap_or_else(|_| Budget {
        about: String::new(),
        margin_percent: bound::MARGIN_PERCENT,
        measured: typical,
        budget: with_margin,
    })
}

/// Whether a failure is one a calibration sets aside: a cost over the old budget, or a bound
/// computed from it.
fn calibrating(failure: &str) -> bool {
    failure.starts_with("costs:")
        || failure.starts_with("bounds:")
        || failure.contains("exceeds its bound")
}

/// `cargo xtask hil [FILE ...] [--json] [--calibrate | --mutants]`.
pub fn run(files: &[PathBuf], json: bool, mode: Mode) -> Ending {
    // An interrupted run leaves no image behind (`Scratch`).
    psmpa_sim::cli::files::clean_up_on_interrupt();
    if mode == Mode::Mutants {
        return mutants::run(json);
    }
    let (plays, defaults) = match plays(files) {
        Ok(p) => p,
        Err(e) => return Ending::BadInput(e),
    };
    // The budget is an input too: refused (2) before anything else is looked at.
    let budget = match mode {
        Mode::Calibrate => provisional_budget(),
        _ => match Budget::load() {
            Ok(b) => b,
            Err(e) => return Ending::BadInput(e),
        },
    };
    // The pages the figures go to, checked before the runs: a page without its markers fails
    // now, not after every run, and never leaves one page written and another not.
    if defaults && mode == Mode::Check {
        let root = firmware::root();
        if let Err(e) = crate::pages::check_pages(&[
            (root.join("docs/firmware.md"), "hil-figures"),
            (root.join("docs/firmware.md"), "decisions"),
            (root.join("README.md"), "hil"),
        ]) {
            return Ending::Failed(e);
        }
    }
    if let Err(e) = harness::check_tools() {
        return Ending::Failed(e);
    }
    eprintln!("xtask hil: building the Pico's image (boards/pico; a few minutes the first time)");
    let fw = match build().and_then(|elf| Firmware::read(&elf)) {
        Ok(fw) => fw,
        Err(e) => return Ending::Failed(e),
    };
    // Every loop bound the static timing analysis takes on trust is counted on every run.
    eprintln!("xtask hil: finding the annotated loops (cargo xtask wcet's analysis)");
    let fw = match crate::wcet::bench_watch() {
        Ok(w) => fw.watching(w),
        Err(e) => return Ending::Failed(format!("the annotated loops: {e}")),
    };
    let out = firmware::root().join("target/hil");
    if let Err(e) = std::fs::create_dir_all(&out) {
        return Ending::Failed(format!("{}: {e}", out.display()));
    }
    let wall = WallClock::now();
    let results = play_all(&fw, &plays, &budget, &out, &recording::dir("bench"));
    let mut failed = Vec::new();
    let mut reports = Vec::new();
    for (p, result) in plays.iter().zip(results) {
        match result {
            Ok((mut report, pins)) => {
                if mode == Mode::Calibrate {
                    report.failures.retain(|f| !calibrating(f));
                }
                if !report.failures.is_empty() {
                    failed.push(p.name());
                }
                let stem = p.stem();
                let svg = out.join(format!("{stem}.svg"));
                if let Err(e) = svg::write(&svg, &report, &pins) {
                    eprintln!("{}: {e}", svg.display());
                }
                let events = out.join(format!("{stem}.txt"));
                if let Err(e) = std::fs::write(&events, timeline(&report, &pins)) {
                    eprintln!("{}: {e}", events.display());
                }
                if json {
                    println!("{}", serde_json::to_string(&report).unwrap_or_default());
                } else {
                    print!("{}", text(&report));
                }
                reports.push((report, pins));
            }
            Err(e) => {
                failed.push(p.name());
                eprintln!(
                    "{}",
                    psmpa_sim::json::printable(&format!("{}: {e}", p.name()))
                );
            }
        }
    }
    // The same scenario, the same pin log: the first one again.
    if defaults && let (Some(p), Some((first, _))) = (plays.first(), reports.first()) {
        match play(&fw, p, &budget, &out, &out.join("again")) {
            Ok((again, _)) if again.pin_log_hash == first.pin_log_hash => {
                if !json {
                    println!(
                        "determinism: {} played twice, the same pin log ({})",
                        psmpa_sim::json::printable(&first.scenario),
                        first.pin_log_hash
                    );
                }
            }
            Ok((again, _)) => failed.push(format!(
                "{} played twice gave two pin logs ({} and {})",
                psmpa_sim::json::printable(&first.scenario),
                first.pin_log_hash,
                again.pin_log_hash
            )),
            Err(e) => failed.push(e),
        }
    }
    if defaults {
        failed.extend(readme_log(&reports));
    }
    // The deepest stack of the runs, for `cargo xtask stack`'s check of its bound.
    if let Some(deepest) = reports.iter().map(|(r, _)| r.stack_bytes).max() {
        let at = out.join("stack.json");
        let code_hash = crate::stack::pico_code_hash(&fw.elf).ok();
        let text = serde_json::json!({ "image": "psmpa-pico", "stack_bytes": deepest, "code_hash": code_hash })
            .to_string();
        if let Err(e) = std::fs::write(&at, text) {
            eprintln!("{}: {e}", at.display());
        }
    }
    if !json {
        println!("\nwhat each check judges from:");
        for (check, from) in JUDGED_FROM {
            println!("  {check:<10} {from}");
        }
        let emulated: f64 = reports.iter().map(|(r, _)| r.emulated_s).sum();
        println!(
            "\n{} runs, {:.1} s emulated in {:.1} s ({:.1} emulated s a wall s, two at a time); pictures in {}",
            reports.len(),
            emulated,
            wall.elapsed().as_secs_f64(),
            emulated / wall.elapsed().as_secs_f64().max(1e-9),
            out.display()
        );
    }
    if !failed.is_empty() {
        let what = if mode == Mode::Calibrate {
            "not calibrated: the bench's checks failed"
        } else {
            "the bench's checks failed"
        };
        return Ending::Failed(format!("{what}: {}", failed.join(", ")));
    }
    if defaults && mode == Mode::Check {
        let (md, cell) = figures(&reports);
        let decisions = decisions_table(&reports);
        let root = firmware::root();
        if let Err(e) = crate::pages::write_pages(&[
            (root.join("docs/firmware.md"), "hil-figures", md),
            (root.join("docs/firmware.md"), "decisions", decisions),
            (root.join("README.md"), "hil", cell),
        ]) {
            return Ending::Failed(e);
        }
    }
    if mode == Mode::Calibrate {
        let measured = reports
            .iter()
            .map(|(r, _)| r.costs)
            .fold(bound::Costs::default(), bound::Costs::max);
        // The new budget must bound every reaction the calibration measured.
        let new = match Budget::of(measured) {
            Ok(b) => b,
            Err(e) => return Ending::Failed(format!("not calibrated: {e}")),
        };
        for ((r, _), p) in reports.iter().zip(&plays) {
            let bounds = match scenario_bounds(&new, &p.scenario) {
                Ok(b) => b,
                Err(e) => {
                    return Ending::Failed(format!(
                        "{}: no bound from the new budget: {e}",
                        p.name()
                    ));
                }
            };
            for (i, name) in ["sonar", "bumper"].iter().enumerate() {
                if let Some(Some(c)) = r.reactions_cycles.get(*name)
                    && *c > bounds[i]
                {
                    return Ending::Failed(format!(
                        "{}: a {name} reaction of {c} cycles exceeds the new budget's bound of {} cycles",
                        p.name(),
                        bounds[i]
                    ));
                }
            }
        }
        return calibrate(measured, reports.len());
    }
    Ending::Passed
}

pub use crate::pages::write_between;

/// One decision's cycles of a run.
type Pick = fn(&DecisionCycles) -> Option<u64>;

/// The table of the control loop's decisions on the chip: each decision's worst over every
/// run, and the run it came from.
fn decisions_table(reports: &[(Report, PinLog)]) -> String {
    let worst = |of: Pick| {
        reports
            .iter()
            .filter_map(|(r, _)| of(&r.decision_cycles).map(|c| (c, r.scenario.as_str())))
            .max_by_key(|(c, _)| *c)
    };
    let expanded = reports
        .iter()
        .filter_map(|(r, _)| r.decision_cycles.plan_expanded)
        .max();
    let mut md = String::from(
        "\n| decision | worst own cycles | µs at 125 MHz | run |\n|---|---|---|---|\n",
    );
    let rows: [(&str, Pick); 3] = [
        (
            "plan selection (BDI: trigger, context, applicable plans)",
            |d| d.select,
        ),
        (
            "one FSM compilation (Algorithm 2 at run time: a plan the planner made)",
            |d| d.compile,
        ),
        ("one planner search, every slice", |d| d.plan),
    ];
    for (what, of) in rows {
        let _ = match worst(of) {
            Some((c, run)) => writeln!(
                md,
                "| {what} | {} | {:.1} | `{run}` |",
                thousands(c),
                bound::us_of_cycles(c)
            ),
            None => writeln!(md, "| {what} | - | - | none made |"),
        };
    }
    let _ = writeln!(
        md,
        "\nThe search expanded at most {} nodes (breadth-first, the robot's `PLANNER`).",
        expanded.map_or("no".to_owned(), |n| n.to_string())
    );
    md
}

/// The figures of a full bench run: a paragraph for docs/firmware.md and a table cell for the
/// README.
fn figures(reports: &[(Report, PinLog)]) -> (String, String) {
    let plain: Vec<&Report> = reports
        .iter()
        .map(|(r, _)| r)
        .filter(|r| r.fault.is_none())
        .collect();
    let worst = |name: &str, of: &dyn Fn(&Report) -> &BTreeMap<String, Option<u64>>| {
        plain
            .iter()
            .filter_map(|r| of(r).get(name).copied().flatten())
            .collect::<Vec<u64>>()
    };
    let max = |v: &[u64]| v.iter().copied().max().unwrap_or(0);
    let min = |v: &[u64]| v.iter().copied().min().unwrap_or(0);
    let us = |c: u64| c as f64 * 8.0 / 1e3;
    let (sr, sb) = (
        worst("sonar", &|r| &r.reactions_cycles),
        worst("sonar", &|r| &r.bound_cycles),
    );
    let (br, bb) = (
        worst("bumper", &|r| &r.reactions_cycles),
        worst("bumper", &|r| &r.bound_cycles),
    );
    let gap = |name: &str| {
        plain
            .iter()
            .filter_map(|r| r.sample_gap_max_ms.get(name).copied().flatten())
            .fold(0.0, f64::max)
    };
    let trigger = plain
        .iter()
        .filter_map(|r| r.trigger_gap_max_ms)
        .fold(0.0, f64::max);
    let samples: usize = reports
        .iter()
        .map(|(r, _)| r.recording.as_ref().map_or(0, |x| x.frames))
        .sum();
    let n = |c: u64| thousands(c);
    let copy = reports
        .iter()
        .map(|(r, _)| r.boot_copy)
        .max_by_key(|b| b.cycles)
        .unwrap_or_default();
    // On silicon every 8-byte line the copy reads misses the XIP cache, at the ring
    // oscillator's nominal 6.5 MHz: the clocks are set up after the copy, by the firmware.
    let silicon = copy.cycles + copy.bytes.div_ceil(8) * crate::wcet::XIP_MISS;
    let md = format!(
        "\n{} runs ({} scenarios, {} fault runs), every check held; {} frames of flight recording judged. \
Sonar reactions at most {} cycles ({:.1} µs) against budgeted bounds of {} to {} cycles (the largest \
where a scenario declares planning time); bumper reactions, which include its 5 ms debounce, at most \
{} cycles ({:.2} ms) against {} to {}. The sonar triggered at most {trigger:.3} ms apart and the \
bumper's samples came at most {:.3} ms apart (the sonar's up to {:.3} ms: a sample is delivered when \
its echo ends, a lost one not at all). Every outcome equal to psmpa-sim's, running the same robot. \
The boot copies the code region, {} B (the image's code and constants, and what follows them in \
flash), into SRAM in {} emulated cycles; with a miss \
of the XIP cache per 8-byte line read, as on silicon, about {} cycles: {:.0} ms at the ring \
oscillator's nominal 6.5 MHz, before the firmware sets up its clocks.\n",
        reports.len(),
        plain.len(),
        reports.len() - plain.len(),
        n(samples as u64),
        n(max(&sr)),
        us(max(&sr)),
        n(min(&sb)),
        n(max(&sb)),
        n(max(&br)),
        us(max(&br)) / 1e3,
        n(min(&bb)),
        n(max(&bb)),
        gap("bumper"),
        gap("sonar"),
        n(copy.bytes),
        n(copy.cycles),
        n(silicon),
        silicon as f64 / 6.5e3,
    );
    let cell = format!(
        "{} runs; sonar reactions at most {:.0} µs, bounds from the committed budget",
        reports.len(),
        us(max(&sr))
    );
    (md, cell)
}

/// `n` with a comma between each three digits.
pub(crate) fn thousands(n: u64) -> String {
    let digits = n.to_string();
    let mut out = String::new();
    for (i, ch) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(ch);
    }
    out
}

/// Writes the budget of `measured` (the worst costs of `runs` runs) and prints it beside the
/// committed one.
fn calibrate(measured: bound::Costs, runs: usize) -> Ending {
    let new = match Budget::of(measured) {
        Ok(b) => b,
        Err(e) => return Ending::Failed(format!("not calibrated: {e}")),
    };
    let old = Budget::load().ok();
    println!(
        "\ncost budget of the Pico's image, cycles at 125 MHz (worst of {runs} runs, +{} %):",
        new.margin_percent
    );
    println!(
        "  {:<13} {:>12} {:>12} {:>12} {:>12}",
        "cost", "old measured", "old budget", "measured", "budget"
    );
    for (i, (name, m)) in new.measured.named().iter().enumerate() {
        let o = |c: Option<bound::Costs>| c.map_or("-".to_owned(), |c| c.named()[i].1.to_string());
        println!(
            "  {name:<13} {:>12} {:>12} {m:>12} {:>12}",
            o(old.as_ref().map(|b| b.measured)),
            o(old.as_ref().map(|b| b.budget)),
            new.budget.named()[i].1
        );
    }
    let path = Budget::path();
    let text = serde_json::to_string_pretty(&new).unwrap_or_default() + "\n";
    match crate::pages::write_file(&path, text.as_bytes()) {
        Ok(()) => {
            println!("written to {}", path.display());
            Ending::Passed
        }
        Err(e) => Ending::Failed(e),
    }
}

/// A run's timeline: the world's events and the firmware's log, in time order.
fn timeline(r: &Report, pins: &PinLog) -> String {
    let mut lines: Vec<(u64, String)> = pins
        .world
        .iter()
        .map(|(ms, pos, e)| {
            (
                ms * 1_000_000,
                format!(
                    "{:>10.3} world    {:>7.3} m  {e:?}",
                    *ms as f64 / 1e3,
                    *pos as f64 / 1e6
                ),
            )
        })
        .collect();
    lines.extend(r.log.iter().map(|l| {
        (
            l.ns,
            format!(
                "{:>10.3} firmware {:>9} {:<5} {}",
                l.ns as f64 / 1e9,
                l.at,
                l.level,
                l.text
            ),
        )
    }));
    lines.extend(
        pins.entries
            .iter()
            .filter(|(_, w, _)| w == "reset" || w.starts_with("inject"))
            .map(|(ns, w, _)| (*ns, format!("{:>10.3} bench    {w}", *ns as f64 / 1e9))),
    );
    lines.sort_by_key(|(t, _)| *t);
    let header = "# time (s)  source   then: the robot's position (m) and the world's event, or the\n\
                  # firmware's own timestamp, level and log line. World events: Appeared/Removed\n\
                  # (an obstacle by index from 0, where), Detected(i, sensor), Collided(i),\n\
                  # Reacted(i, ms from certain to stopped), Walk/Stop, Speed(thousandths of the\n\
                  # scenario's speed, the wheels' mean), Sample(device, reading).\n";
    header.to_owned() + &lines.into_iter().map(|(_, l)| l + "\n").collect::<String>()
}

/// A run as text: its log, its outcome beside psmpa-sim's, its reactions beside their bounds.
fn text(r: &Report) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "\n== {}{} ({}): {:.1} s emulated in {:.1} s",
        psmpa_sim::json::printable(&r.scenario),
        r.fault
            .as_ref()
            .map_or(String::new(), |f| format!(", fault {f}")),
        psmpa_sim::json::printable(&r.file),
        r.emulated_s,
        r.wall_s
    );
    for l in &r.log {
        let _ = writeln!(s, "  {:>10} {:<5} {}", l.at, l.level, l.text);
    }
    let host = r.host.map_or(String::new(), |h| {
        format!(
            " (psmpa-sim: {}, {}, {})",
            h.detected, h.collisions, h.reached_door
        )
    });
    let _ = writeln!(
        s,
        "  detected {} of {}, collisions {}, reached the door {}{host}; watchdog resets {}",
        r.detected, r.interferences, r.collisions, r.reached_door, r.watchdog_resets
    );
    if !r.detected_by.is_empty() {
        let by: Vec<&str> = r
            .detected_by
            .iter()
            .map(|d| d.as_deref().unwrap_or("-"))
            .collect();
        let _ = writeln!(s, "  detected by (obstacle by obstacle): {}", by.join(", "));
    }
    let _ = writeln!(
        s,
        "  mission: {}",
        r.mission
            .as_deref()
            .unwrap_or("the firmware never said how it ended")
    );
    let d = r.decision_cycles;
    if d.select.is_some() {
        let cycles = |c: Option<u64>| {
            c.map_or("-".to_owned(), |c| {
                format!("{c} cycles ({:.1} µs)", bound::us_of_cycles(c))
            })
        };
        let _ = writeln!(
            s,
            "  decisions on the chip (worst): select {}, compile {}, plan {}{}",
            cycles(d.select),
            cycles(d.compile),
            cycles(d.plan),
            d.plan_expanded
                .map_or(String::new(), |n| format!(", {n} nodes expanded"))
        );
    }
    if let Some(g) = r.trigger_gap_max_ms {
        let _ = writeln!(s, "  sonar : longest gap between triggers {g:.3} ms");
    }
    for name in ["sonar", "bumper"] {
        let gap = r.sample_gap_max_ms.get(name).copied().flatten();
        let re = r.reactions_cycles.get(name).copied().flatten();
        let b = r.bound_cycles.get(name).copied().flatten();
        let _ = writeln!(
            s,
            "  {name:<6}: longest sample gap {}, worst reaction {} (bound {}, from the budget)",
            gap.map_or("-".to_owned(), |g| format!("{g:.3} ms")),
            re.map_or("-".to_owned(), |c| format!("{c} cycles")),
            b.map_or("-".to_owned(), |c| format!("{c} cycles")),
        );
    }
    if let Some(rec) = &r.recording {
        let _ = writeln!(
            s,
            "  flight recording: {} frames over RTT, {} decisions replayed on the host as recorded (within {} ms){}",
            rec.frames,
            rec.decisions,
            rec.skew_ms,
            rec.ring_frames.map_or(String::new(), |n| format!(
                "; after the reset the RAM ring gave back its last {n}"
            ))
        );
    }
    if r.failures.is_empty() {
        let _ = writeln!(s, "  checks held");
    }
    for f in &r.failures {
        let _ = writeln!(s, "  FAILED: {f}");
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The recording's calibration record against the one the bench wrote: a board that
    /// lengthens a period when it reads its calibration runs another robot.
    /// A bound holds where its job runs: a loop the sensing job bounds at 1 may go round 3
    /// times in thread mode (no job there), not twice in the sensing handler; a bound of the
    /// critical section holds at every level as well.
    #[test]
    fn a_loop_bound_is_judged_at_the_levels_of_its_jobs() {
        let mut l = crate::wcet::BenchLoop {
            annotation: "f".to_owned(),
            bound: 1,
            function: [0x100, 0x200],
            entries: vec![0x120],
            ..Default::default()
        };
        l.levels.insert(bound::EXC_SENSING, 1);
        let counts = |level: u32, most: u64| {
            let mut v = vec![0; 64];
            v[level as usize] = most;
            vec![v]
        };
        let judged = |l: &crate::wcet::BenchLoop, level, most| {
            loops_exceeded(std::slice::from_ref(l), &counts(level, most))
        };
        assert!(judged(&l, 0, 3).is_empty());
        assert!(judged(&l, bound::EXC_SENSING, 1).is_empty());
        let e = judged(&l, bound::EXC_SENSING, 2);
        assert!(
            matches!(&e[..], [m] if m.contains("0x120") && m.contains("level 43") && m.contains("the 1 ")),
            "{e:?}"
        );
        // The critical section's 2 holds at every level; in a handler, its own job's 1 still
        // does (the job is all the handler runs); in thread mode the larger.
        l.any_level = Some(2);
        assert_eq!(judged(&l, 0, 3).len(), 1);
        assert_eq!(judged(&l, bound::EXC_SENSING, 2).len(), 1);
        l.levels.insert(0, 1);
        assert!(judged(&l, 0, 2).is_empty());
    }

    #[test]
    fn a_recording_with_another_calibration_than_the_flash_fails() {
        let written = Settings::DEFAULT;
        let board = |settings| psmpa_sim::replay::Source::Board { settings };
        assert_eq!(calibration_differs(&board(written), &written), None);
        let mut ran = written;
        ran.bumper_period = Some(embassy_time::Duration::from_millis(25));
        let why = calibration_differs(&board(ran), &written).unwrap();
        assert!(
            why.contains("bumper period 25 ms where the bench wrote the mission's"),
            "{why}"
        );
    }

    /// `still`: the motors must stop once a fault struck, in time, and stay stopped; a halt
    /// that leaves them driving (the robot drives blind to the run's end) fails.
    #[test]
    fn still_requires_the_motors_stopped_after_the_fault() {
        let e = Expect {
            still: true,
            ..Expect::default()
        };
        let judge = |c: &Collected| {
            let mut failures = Vec::new();
            expectations(&e, &Tally::default(), c, &BTreeMap::new(), &mut failures);
            failures
        };
        let struck = 3_000_000_000;
        // Stopped 1 ms after the fault, and still at the end: held.
        let stopped = Collected {
            struck: Some(struck),
            off_at: Some(struck + 1_000_000),
            ..Collected::default()
        };
        assert_eq!(judge(&stopped), Vec::<String>::new());
        // Never stopped (halt does nothing): driving when the run ended.
        let blind = Collected {
            struck: Some(struck),
            driving: true,
            ..Collected::default()
        };
        let f = judge(&blind);
        assert!(
            f.iter()
                .any(|f| f.contains("still drove when the run ended")),
            "{f:?}"
        );
        // Stopped late.
        let late = Collected {
            struck: Some(struck),
            off_at: Some(struck + (STILL_WITHIN_MS + 1) * 1_000_000),
            ..Collected::default()
        };
        let f = judge(&late);
        assert!(f.iter().any(|f| f.contains("not within 20 ms")), "{f:?}");
    }

    #[test]
    fn bad_input_is_refused_before_anything_is_built() {
        let dir = std::env::temp_dir().join(format!("psmpa-hil-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let write = |name: &str, text: &str| {
            let p = dir.join(name);
            std::fs::write(&p, text).unwrap();
            p
        };
        let cases = [
            (dir.join("missing.json"), "cannot read the file"),
            (write("malformed.json", "{ \"name\": "), "malformed.json"),
            (
                write(
                    "field.json",
                    r#"{"name": "x", "interferences": [], "door_m": -1}"#,
                ),
                "door_m",
            ),
            (
                write(
                    "fault.json",
                    r#"{"name": "f", "scenario": "x.json", "fault": {"kind": "melt", "at_s": 1}, "expect": {}}"#,
                ),
                "unknown fault kind",
            ),
        ];
        for (file, says) in cases {
            match run(std::slice::from_ref(&file), true, Mode::Check) {
                Ending::BadInput(e) => assert!(e.contains(says), "{}: {e}", file.display()),
                _ => panic!("{} was not refused as bad input", file.display()),
            }
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Whether `file` is refused as bad input, saying `says`, at once.
    fn refused(file: &Path, says: &str) {
        let started = std::time::Instant::now();
        match run(&[file.to_path_buf()], true, Mode::Check) {
            Ending::BadInput(e) => assert!(e.contains(says), "{}: {e}", file.display()),
            _ => panic!("{} was not refused as bad input", file.display()),
        }
        // Refused before anything is read to its end or built: well within a second.
        assert!(started.elapsed().as_secs() < 5, "{}", file.display());
    }

    #[test]
    fn hostile_input_files_are_refused_in_one_line() {
        let dir = std::env::temp_dir().join(format!("psmpa-hil-hostile-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // A FIFO would wait for a writer for ever; /dev/zero never ends.
        let fifo = dir.join("fifo.json");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.is_ok_and(|s| s.success()) {
            refused(&fifo, "is a FIFO, not a scenario file");
        }
        refused(Path::new("/dev/zero"), "is a device, not a scenario file");
        let write = |name: &str, text: &str| {
            let p = dir.join(name);
            std::fs::write(&p, text).unwrap();
            p
        };
        let big = dir.join("big.json");
        std::fs::write(&big, vec![b' '; (1 << 20) + 1]).unwrap();
        refused(&big, "larger than 1 MiB");
        // Scenarios psmpa-sim accepts that the bench cannot play.
        refused(
            &write(
                "tiny.json",
                r#"{"name": "t", "max_s": 0.001, "interferences": []}"#,
            ),
            "runs of at least 1 s",
        );
        refused(
            &write(
                "near.json",
                r#"{"name": "t", "door_m": 0.000001, "interferences": []}"#,
            ),
            "less than 1 mm away",
        );
        // Fault files: the scenario a device, nonsense times, names and sensors, a chatter
        // faster than the emulator plays.
        let quiet = firmware::root().join("scenarios/quiet.json");
        let fault = |name: &str, scenario: &Path, body: &str| {
            write(
                name,
                &format!(
                    r#"{{"name": "f", "scenario": {:?}, {body}}}"#,
                    scenario.display().to_string()
                ),
            )
        };
        refused(
            &fault(
                "zero.json",
                Path::new("/dev/zero"),
                r#""fault": {"kind": "hang", "at_s": 1}, "expect": {}"#,
            ),
            "its scenario: /dev/zero: is a device",
        );
        for (name, body, says) in [
            (
                "late.json",
                r#""fault": {"kind": "hang", "at_s": 1e300}, "expect": {}"#,
                "a day",
            ),
            (
                "negative.json",
                r#""fault": {"kind": "hang", "at_s": -1}, "expect": {}"#,
                "from 0",
            ),
            (
                "after.json",
                r#""fault": {"kind": "hang", "at_s": 700}, "expect": {}"#,
                "after its scenario's run ends",
            ),
            (
                "chatter.json",
                r#""fault": {"kind": "bumper-chatter", "at_s": 1, "for_s": 2, "every_us": 1}, "expect": {}"#,
                "at least 20 us between edges",
            ),
            (
                "edges.json",
                r#""fault": {"kind": "bumper-chatter", "at_s": 1, "for_s": 60, "every_us": 20}, "expect": {}"#,
                "the bench plays at most",
            ),
            (
                "sensor.json",
                r#""fault": {"kind": "hang", "at_s": 1}, "expect": {"sample_gap_max_ms": {"lidar": 5}}"#,
                "no sensor \"lidar\"",
            ),
        ] {
            refused(&fault(name, &quiet, body), says);
        }
        let empty = write(
            "empty-name.json",
            &format!(
                r#"{{"name": " ", "scenario": {:?}, "fault": {{"kind": "hang", "at_s": 1}}, "expect": {{}}}}"#,
                quiet.display().to_string()
            ),
        );
        refused(&empty, "name: empty");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn round_four_fault_files_are_refused_in_one_line() {
        let dir = std::env::temp_dir().join(format!("psmpa-hil-round4-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let quiet = firmware::root().join("scenarios/quiet.json");
        let fault = |name: &str, body: &str| {
            let p = dir.join(name);
            std::fs::write(
                &p,
                format!(
                    r#"{{"name": "f", "scenario": {:?}, {body}}}"#,
                    quiet.display().to_string()
                ),
            )
            .unwrap();
            p
        };
        for (name, body, says) in [
            // Item 4: an interval whose nanoseconds overflow.
            (
                "every.json",
                r#""fault": {"kind": "bumper-chatter", "at_s": 1, "for_s": 2, "every_us": 18446744073709551615}, "expect": {}"#,
                "at most 60000000 (its longest)",
            ),
            // Item 13: a pin fault is never injected through a test point.
            (
                "within.json",
                r#""fault": {"kind": "no-echo", "at_s": 1}, "expect": {"stops_within_ms": 500}"#,
                "only hang and panic have it",
            ),
            (
                "within-huge.json",
                r#""fault": {"kind": "hang", "at_s": 1}, "expect": {"stops_within_ms": 18446744073709551615}"#,
                "at most 60000 ms",
            ),
            // Item 27: a negative gap, an empty log line, motors_off_first on a hang.
            (
                "gap.json",
                r#""fault": {"kind": "hang", "at_s": 1}, "expect": {"sample_gap_max_ms": {"sonar": -5}}"#,
                "a gap is more than 0 ms",
            ),
            (
                "log.json",
                r#""fault": {"kind": "hang", "at_s": 1}, "expect": {"log": ["", "x"]}"#,
                "expect.log: an empty line",
            ),
            (
                "first.json",
                r#""fault": {"kind": "hang", "at_s": 1}, "expect": {"motors_off_first": true}"#,
                "only a panic logs",
            ),
            // Item 25: a fault file without `expect` is a fault file missing it.
            (
                "no-expect.json",
                r#""fault": {"kind": "hang", "at_s": 1}"#,
                "not a fault scenario: missing field `expect`",
            ),
            // Item 24: a duplicate key is named as such.
            (
                "twice.json",
                r#""fault": {"kind": "hang", "at_s": 1, "at_s": 2}, "expect": {}"#,
                r#"the key "at_s" appears twice"#,
            ),
        ] {
            refused(&fault(name, body), says);
        }
        // A scenario's own `fault` (its sonar's) keeps it a scenario.
        assert!(!fault::is_fault_file(
            br#"{"name": "s", "fault": {"kind": "silent", "at_s": 1}, "interferences": []}"#
        ));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn two_scenarios_of_one_file_name_get_their_own_stems_and_names_print_escaped() {
        let dir = std::env::temp_dir().join(format!("psmpa-hil-stems-{}", std::process::id()));
        let text = std::fs::read(firmware::root().join("scenarios/sonar-6.json")).unwrap();
        let (a, b) = (dir.join("a/sonar-6.json"), dir.join("b/sonar-6.json"));
        for p in [&a, &b] {
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, &text).unwrap();
        }
        let crafted = dir.join("crafted.json");
        std::fs::write(
            &crafted,
            r#"{"name": "x\u001b[32m OK\nall 26 runs passed", "interferences": []}"#,
        )
        .unwrap();
        let (list, _) = plays(&[a.clone(), b.clone(), a.clone(), crafted]).unwrap();
        let stems: Vec<String> = list.iter().map(Play::stem).collect();
        let mut unique = stems.clone();
        unique.sort();
        unique.dedup();
        assert_eq!(unique.len(), 4, "{stems:?}");
        assert!(stems[0].starts_with("sonar-6-") && stems[1].starts_with("sonar-6-"));
        // A stem that is alone stays the file's: the README's sonar-6.txt.
        assert_eq!(stems[3], "crafted");
        let (alone, _) = plays(&[a]).unwrap();
        assert_eq!(alone[0].stem(), "sonar-6");
        let name = list[3].name();
        assert!(!name.chars().any(char::is_control), "{name:?}");
        assert!(
            name.contains("\\u001b") && name.contains("\\u000a"),
            "{name}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_fault_the_run_never_reached_fails_and_a_run_cut_at_max_s_is_no_failure() {
        // Item 14: a hang after the goal (the run ended first) never struck.
        let hang = Fault::Hang { at_s: 30.0 };
        let e = never_struck(&hang, None, 25_000_000_000).unwrap();
        assert!(
            e.contains("the fault never struck") && e.contains("25.000 s"),
            "{e}"
        );
        assert_eq!(
            never_struck(&hang, Some(30_000_000_000), 31_000_000_000),
            None
        );
        let silent = Fault::NoEcho { at_s: 30.0 };
        assert!(never_struck(&silent, None, 25_000_000_000).is_some());
        assert_eq!(never_struck(&silent, None, 30_000_000_000), None);
        // Item 16: a run that reached max_s without the firmware's word was cut there.
        let sc = psmpa_sim::load::parse(
            Path::new("s.json"),
            br#"{"name": "s", "max_s": 1, "interferences": []}"#,
        )
        .unwrap();
        assert!(cut_at_max_s(&sc, None, 1_000_000_000));
        assert!(!cut_at_max_s(&sc, None, 999_999_999));
        assert!(!cut_at_max_s(&sc, Some(900_000_000), 1_000_000_000));
    }

    #[test]
    fn an_image_is_removed_whatever_ends_its_run() {
        let dir = std::env::temp_dir().join(format!("psmpa-hil-scratch-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let image = dir.join("x.bin");
        let failing = || -> Result<(), String> {
            let scratch = psmpa_sim::cli::files::Scratch::new(&image);
            std::fs::write(scratch.path(), b"image").map_err(|e| e.to_string())?;
            Err("the harness did not start".to_owned())
        };
        assert!(failing().is_err());
        assert!(!image.exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_readme_log_block_is_checked_for_events_and_order_not_numbers() {
        let readme = "x\n```text\n0.003 INFO  go to door started\n...\n27.2 INFO  sonar off: 274 samples\n```\n";
        let log = |lines: &[&str]| lines.iter().map(|l| (*l).to_owned()).collect::<Vec<_>>();
        // Other instants and counts: the same events.
        let moved = log(&["INFO go to door started", "INFO sonar off: 275 samples"]);
        assert!(log_block_in(readme, &moved).is_empty());
        // An event missing, or in another order, is not.
        let missing = log(&["INFO go to door started"]);
        assert_eq!(
            log_block_in(readme, &missing),
            ["27.2 INFO  sonar off: 274 samples"]
        );
        let swapped = log(&["INFO sonar off: 1 samples", "INFO go to door started"]);
        assert_eq!(log_block_in(readme, &swapped).len(), 1);
        assert_eq!(log_block_in("no block", &moved), ["(no log block)"]);
        assert_eq!(words("a  12.5 mm,  3"), "a # mm, #");
        assert_eq!(thousands(1_234_567), "1,234,567");
        assert_eq!(thousands(999), "999");
    }

    #[test]
    fn a_budget_of_huge_costs_or_an_odd_margin_is_refused_not_a_panic() {
        let huge = bound::Costs {
            sensing_poll: u64::MAX / 2,
            alarm: u64::MAX,
            gpio: 1,
            deciding: u64::MAX,
            critical: 1,
            control_poll: 1,
        };
        assert!(huge.with_margin(25).is_none());
        assert!(Budget::of(huge).unwrap_err().contains("beyond"));
        let b = Budget {
            about: String::new(),
            margin_percent: 25,
            measured: huge,
            budget: huge,
        };
        assert!(
            b.check().unwrap_err().contains("beyond any step"),
            "{:?}",
            b.check()
        );
        // The bounds of absurd costs: unschedulable, not an overflow.
        assert!(bound::bounds(&huge, [100, 20]).is_err());
        assert!(b.tolerance_mm() > 0);
        let measured = bound::Costs {
            sensing_poll: 100,
            alarm: 3,
            gpio: 0,
            deciding: 1_000,
            critical: 10,
            control_poll: 500,
        };
        for margin in [0, 10_000, u64::MAX] {
            let odd = Budget {
                margin_percent: margin,
                budget: measured.with_margin(margin.min(100)).unwrap(),
                ..Budget::of(measured).unwrap()
            };
            let e = odd.check().unwrap_err();
            assert!(e.contains(&format!("margin_percent {margin}")), "{e}");
        }
    }

    #[test]
    fn a_budget_is_its_measured_costs_with_the_margin() {
        let measured = bound::Costs {
            sensing_poll: 100,
            alarm: 3,
            gpio: 0,
            deciding: 1_000,
            critical: 10,
            control_poll: 500,
        };
        let b = Budget::of(measured).unwrap();
        // At least 1,000 cycles more.
        assert_eq!(b.budget.sensing_poll, 1_100);
        assert_eq!(b.budget.alarm, 1_003);
        // A quarter more where that is more: rounded up.
        let big = bound::Costs {
            deciding: 10_001,
            ..measured
        }
        .with_margin(25)
        .unwrap();
        assert_eq!(big.deciding, 12_502);
        assert!(b.check().is_ok());
        let mut edited = b.clone();
        edited.budget.deciding += 1;
        assert!(edited.check().unwrap_err().contains("--calibrate"));
        let over = bound::Costs {
            deciding: 2_001,
            ..measured
        }
        .over(&b.budget);
        assert_eq!(
            over,
            ["the deciding cost of 2001 cycles exceeds its budget of 2000 cycles"]
        );
        // Declared planning time is the scenario's, added to the step.
        assert_eq!(
            b.budget.with_plan(bound::cycles_of_us(1_000)).deciding,
            2_000 + 125_000
        );
    }

    #[test]
    fn the_robot_is_calibrated_to_its_scenario() {
        let sc = psmpa_sim::load::parse(
            Path::new("t.json"),
            br#"{"name": "t", "door_m": 1.5, "robot": {"speed_mps": 0.15, "plan_us": 50000},
                 "sonar": {"period_ms": 50, "threshold_m": 0.4}, "bumper": {"period_ms": 10},
                 "interferences": []}"#,
        )
        .unwrap();
        let s = settings_for(&sc, Chassis::Wheeled);
        // It stops for a reading below the threshold, as the world registers one.
        assert_eq!(s.clearance_mm, 399);
        assert_eq!((s.walk_mm, s.walk_mm_s), (1_500, 150));
        assert_eq!(s.plan.as_micros(), 50_000);
        assert_eq!(s.sonar_period.map(|p| p.as_millis()), Some(50));
        assert_eq!(s.bumper_period.map(|p| p.as_millis()), Some(10));
        assert_eq!(Settings::from_record(&s.to_record()), Ok(s));
    }
}

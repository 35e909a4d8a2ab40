//! The emulated Pico: `xtask/hil/harness.mjs` (rp2040js under Node) as a child process,
//! spoken to one JSON object a line (the protocol is described at the top of that file).

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};

use serde::{Deserialize, Serialize};

/// What the harness needs to boot the chip.
#[derive(Serialize)]
pub struct Boot {
    /// The flash image, from 0x1000_0000.
    pub flash: PathBuf,
    /// Where the firmware keeps what the harness reads or calls.
    pub symbols: Symbols,
    /// Where the image's code runs (its `.text`, in SRAM on the Pico): the addresses the
    /// harness watches for [`Boot::loops`] and [`Boot::timed`].
    pub code: [u32; 2],
    /// Words in the health block.
    pub health_words: u32,
    /// Output pins whose edges are reported.
    pub outputs: Vec<u8>,
    /// PWM outputs whose duty is reported.
    pub pwm: Vec<u8>,
    /// Input pins and what the world does to them at reset: driven 0 or 1, or open (`None`).
    pub inputs: BTreeMap<u8, Option<u8>>,
    /// Seeds the floating level of an open input with no pull (a decimal string: JSON's
    /// numbers are doubles in JavaScript).
    pub seed: String,
    /// Loops whose back edges an entry the harness counts (the most, in [`Stats::loops`]).
    pub loops: Vec<crate::wcet::BenchLoop>,
    /// Entry addresses of functions whose calls the harness times (0: none), in
    /// [`Stats::calls`].
    pub timed: Vec<u32>,
}

/// Addresses in the firmware image.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Symbols {
    /// The RTT control block (`_SEGGER_RTT`).
    pub rtt: u32,
    /// The sensors' health (`PSMPA_HEALTH`).
    pub health: u32,
    /// The test point `psmpa_test_panic`.
    pub test_panic: u32,
    /// The test point `psmpa_test_hang`.
    pub test_hang: u32,
}

/// One handler's cycles.
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize)]
pub struct HandlerCycles {
    /// Activations.
    pub count: u64,
    /// Their own cycles (nested handlers excluded), together.
    pub total: u64,
    /// The longest.
    pub max: u64,
    /// When the longest ended, ns.
    #[serde(rename = "maxAt")]
    pub max_at: u64,
}

/// The longest critical sections, cycles.
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize)]
pub struct Critical {
    /// Taken in thread mode (deciding).
    pub thread: u64,
    /// Taken in a handler.
    pub handler: u64,
}

/// The harness's cycle accounts.
#[derive(Clone, Debug, Default, Deserialize, Serialize)]
pub struct Stats {
    /// By exception number (16 + the interrupt's).
    pub handlers: BTreeMap<u32, HandlerCycles>,
    /// Thread mode's busy stretches, from a wake-up to the next sleep, handlers excluded.
    pub thread: HandlerCycles,
    /// Critical sections.
    pub critical: Critical,
    /// The last boot's cycles from reset to the first instruction in [`Boot::code`]: the
    /// boot vectors' copy of the image into SRAM.
    #[serde(default)]
    pub boot: u64,
    /// Of each of [`Boot::loops`], the most back edges taken on one entry, by exception
    /// level (0 thread mode, 16 + n interrupt n).
    #[serde(default)]
    pub loops: Vec<Vec<u64>>,
    /// Every call of a [`Boot::timed`] function, in order: its index there and its own
    /// cycles (from its entry to its return, handlers excluded).
    #[serde(default)]
    pub calls: Vec<(usize, u64)>,
}

/// Something that happened on the chip.
#[derive(Clone, Debug, Deserialize, PartialEq, Eq)]
#[serde(tag = "ev", rename_all = "lowercase")]
pub enum Event {
    /// An output's edge (a pin no longer driven reads 0).
    Pin {
        /// GPIO number.
        pin: u8,
        /// 0 or 1.
        level: u8,
        /// When, ns.
        ns: u64,
    },
    /// A PWM output's duty changed.
    Duty {
        /// GPIO number.
        pin: u8,
        /// Thousandths.
        permille: u16,
        /// When, ns.
        ns: u64,
    },
    /// The health block changed.
    Health {
        /// Its words.
        words: Vec<u32>,
        /// When, ns.
        ns: u64,
    },
    /// Bytes of the defmt log, hex.
    Rtt {
        /// The bytes.
        data: String,
        /// When they were read, ns.
        ns: u64,
    },
    /// The watchdog fired and the chip was reset.
    Reset {
        /// Why.
        cause: String,
        /// When, ns.
        ns: u64,
    },
    /// rp2040js warned: an access to unmapped memory or to a register or instruction it does
    /// not implement (beyond the registers silicon has and it does not model).
    Warning {
        /// What.
        message: String,
        /// The program counter when it warned.
        pc: u32,
        /// When, ns.
        ns: u64,
    },
    /// The emulator reported an error.
    Error {
        /// What.
        message: String,
    },
    /// A run stopped here.
    At {
        /// When, ns.
        ns: u64,
    },
}

/// The harness process.
pub struct Harness {
    child: Child,
    stdin: BufWriter<ChildStdin>,
    stdout: BufReader<ChildStdout>,
}

/// The harness's folder: its script, package.json and lock file (`npm ci` there).
pub fn dir() -> PathBuf {
    crate::firmware::root().join("xtask/hil")
}

/// Says in one line what is missing to run the harness, if anything.
pub fn check_tools() -> Result<(), String> {
    let node = Command::new("node").arg("--version").output();
    if !node.is_ok_and(|o| o.status.success()) {
        return Err("node is not installed: the bench runs rp2040js under Node.js (bash scripts/install-tools.sh bench installs what is missing)".to_owned());
    }
    if !dir().join("node_modules/rp2040js/package.json").exists() {
        return Err("rp2040js is not installed: run `bash scripts/install-tools.sh bench` (it runs `npm ci --prefix xtask/hil`)".to_owned());
    }
    Ok(())
}

impl Harness {
    /// Starts the harness and boots the chip.
    pub fn start(boot: &Boot) -> Result<Self, String> {
        let script: &Path = &dir().join("harness.mjs");
        let mut child = Command::new("node")
            .arg(script)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .map_err(|e| format!("cannot start node: {e}"))?;
        let stdin = child.stdin.take().ok_or("no stdin for the harness")?;
        let stdout = child.stdout.take().ok_or("no stdout from the harness")?;
        let mut harness = Self {
            child,
            stdin: BufWriter::new(stdin),
            stdout: BufReader::new(stdout),
        };
        let mut cmd = serde_json::to_value(boot).map_err(|e| e.to_string())?;
        cmd["cmd"] = "boot".into();
        harness.send(&cmd)?;
        harness.until_at()?;
        Ok(harness)
    }

    fn send(&mut self, cmd: &serde_json::Value) -> Result<(), String> {
        writeln!(self.stdin, "{cmd}")
            .and_then(|()| self.stdin.flush())
            .map_err(|e| format!("the harness stopped listening: {e}"))
    }

    fn next(&mut self) -> Result<serde_json::Value, String> {
        let mut line = String::new();
        let n = self
            .stdout
            .read_line(&mut line)
            .map_err(|e| format!("cannot read the harness: {e}"))?;
        if n == 0 {
            return Err("the harness ended unexpectedly".to_owned());
        }
        serde_json::from_str(&line).map_err(|e| format!("the harness said {line:?}: {e}"))
    }

    /// Events up to the next `at`, which ends the list.
    fn until_at(&mut self) -> Result<Vec<Event>, String> {
        let mut events = Vec::new();
        loop {
            let value = self.next()?;
            let event: Event = serde_json::from_value(value.clone())
                .map_err(|e| format!("the harness said {value}: {e}"))?;
            if let Event::Error { message } = &event {
                return Err(format!("the emulator: {message}"));
            }
            let at = matches!(event, Event::At { .. });
            events.push(event);
            if at {
                return Ok(events);
            }
        }
    }

    /// Drives input `pin` to `level` from `at_ns` on, or leaves it open (`None`).
    pub fn set(&mut self, pin: u8, level: Option<bool>, at_ns: u64) -> Result<(), String> {
        self.send(
            &serde_json::json!({"cmd": "set", "pin": pin, "level": level.map(u8::from), "at": at_ns}),
        )
    }

    /// Runs until `until_ns` or until something happens; the events, `At` last.
    pub fn run(&mut self, until_ns: u64) -> Result<Vec<Event>, String> {
        self.send(&serde_json::json!({"cmd": "run", "until": until_ns}))?;
        self.until_at()
    }

    /// Thread mode calls test point `what` (`panic` or `hang`) next.
    pub fn inject(&mut self, what: &str) -> Result<(), String> {
        self.send(&serde_json::json!({"cmd": "inject", "what": what}))
    }

    /// Bytes of the stack `[from, to)` used so far (cortex-m-rt's paint scrubbed off).
    pub fn stack(&mut self, from: u32, to: u32) -> Result<u64, String> {
        self.send(&serde_json::json!({"cmd": "stack", "from": from, "to": to}))?;
        let value = self.next()?;
        value["used"]
            .as_u64()
            .ok_or_else(|| format!("the harness said {value} of the stack"))
    }

    /// Calls the function at `function` with `args` in r0-r3, on the chip as booted (before any
    /// [`Harness::run`]), to its return: its cycles, and r0 and r1 on return.
    pub fn call(&mut self, function: u32, args: [u32; 4]) -> Result<(u64, [u32; 2]), String> {
        self.send(&serde_json::json!({"cmd": "call", "function": function, "args": args}))?;
        let value = self.next()?;
        let word = |k: &str| value[k].as_u64().and_then(|v| u32::try_from(v).ok());
        match (value["cycles"].as_u64(), word("r0"), word("r1")) {
            (Some(cycles), Some(r0), Some(r1)) => Ok((cycles, [r0, r1])),
            _ => Err(format!("the harness said {value} of a call")),
        }
    }

    /// The cycle accounts so far.
    pub fn stats(&mut self) -> Result<Stats, String> {
        self.send(&serde_json::json!({"cmd": "stats"}))?;
        let value = self.next()?;
        serde_json::from_value(value).map_err(|e| format!("the harness's accounts: {e}"))
    }
}

impl Drop for Harness {
    fn drop(&mut self) {
        // Best effort: it exits on `quit`, and is killed if it does not.
        let _ = self.send(&serde_json::json!({"cmd": "quit"}));
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

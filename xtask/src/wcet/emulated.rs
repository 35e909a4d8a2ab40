//! `cargo xtask wcet --emulated`: the analysis's cycle costs against an independent count.
//! Functions of the shipped Pico image are called on rp2040js, the bench's emulated RP2040,
//! with chosen and seeded arguments; each call's cycles must be within the function's static
//! bound, and where every path of a function is taken by some argument (the straight-line
//! multiplication, both ways of the shift), the worst call must equal the bound: a cost the
//! analysis undercharges fails the first rule, one it overcharges the second.
//!
//! The memory model is rp2040js's: code and constants fetched with no wait state, so the bound
//! compared is the analysis's instructions alone, without the XIP cache's misses.

use super::thumb::Table;
use super::{Annotations, instruction_cycles};
use crate::hil::Ending;

/// A function called with arguments in r0-r3.
struct Case {
    function: &'static str,
    /// The arguments of each call: these, then `seeded` more drawn from a fixed seed.
    fixed: &'static [[u32; 4]],
    seeded: usize,
    /// Whether the calls take every path through it, so the worst must reach the bound.
    every_path: bool,
    /// What r0 and r1 must hold on return (`None`: anything), a check that the call ran it.
    expect: fn([u32; 4]) -> [Option<u32>; 2],
}

fn pair(lo: u32, hi: u32) -> u64 {
    u64::from(lo) | (u64::from(hi) << 32)
}

fn both(v: u64) -> [Option<u32>; 2] {
    [Some(v as u32), Some((v >> 32) as u32)]
}

const CASES: &[Case] = &[
    Case {
        function: "__aeabi_lmul",
        fixed: &[[0, 0, 0, 0], [u32::MAX, u32::MAX, u32::MAX, u32::MAX]],
        seeded: 16,
        every_path: true,
        expect: |a| both(pair(a[0], a[1]).wrapping_mul(pair(a[2], a[3]))),
    },
    Case {
        function: "__aeabi_llsl",
        // No shift, shifts within the low word, and past it.
        fixed: &[
            [0x89ab_cdef, 0x0123_4567, 0, 0],
            [0x89ab_cdef, 0x0123_4567, 5, 0],
            [0x89ab_cdef, 0x0123_4567, 31, 0],
            [0x89ab_cdef, 0x0123_4567, 32, 0],
            [0x89ab_cdef, 0x0123_4567, 63, 0],
        ],
        seeded: 0,
        every_path: true,
        expect: |a| both(pair(a[0], a[1]) << (a[2] & 63)),
    },
    Case {
        function: "__aeabi_uidiv",
        // Quotients of every length, the longest 32 bits.
        fixed: &[
            [u32::MAX, 1, 0, 0],
            [u32::MAX, 3, 0, 0],
            [0x8000_0000, 1, 0, 0],
            [7, 9, 0, 0],
        ],
        seeded: 64,
        every_path: false,
        expect: |a| [Some(a[0] / a[1]), None],
    },
    Case {
        function: "__aeabi_uldivmod",
        fixed: &[
            [u32::MAX, u32::MAX, 1, 0],
            [u32::MAX, u32::MAX, 3, 0],
            [u32::MAX, u32::MAX, 0x8000_0001, 1],
            [5, 0, 9, 0],
        ],
        seeded: 64,
        every_path: false,
        expect: |a| both(pair(a[0], a[1]) / pair(a[2], a[3])),
    },
];

/// The seeded arguments, the same on every machine.
struct Seed(u64);

impl Seed {
    fn next(&mut self) -> u64 {
        crate::splitmix::next(&mut self.0)
    }

    /// Four words; a divisor (r1, or r2:r3) of any length and never zero.
    fn args(&mut self, function: &str) -> [u32; 4] {
        let mut w = [0u32; 4].map(|_| self.next() as u32);
        let cut = (self.next() % 64) as u32;
        match function {
            "__aeabi_uidiv" => w[1] = (w[1] >> (cut % 32)).max(1),
            "__aeabi_uldivmod" => {
                let d = (pair(w[2], w[3]) >> cut).max(1);
                [w[2], w[3]] = [d as u32, (d >> 32) as u32];
            }
            _ => {}
        }
        w
    }
}

/// One function's calls: its bounds, the worst call and its arguments.
struct Measured {
    /// The analysis's, with the TRM's costs and with rp2040js's.
    trm: u64,
    bound: u64,
    worst: u64,
    worst_args: [u32; 4],
    calls: usize,
}

/// Calls every case on `chip`; the first wrong result is an error.
fn measure(
    chip: &mut crate::hil::harness::Harness,
    trm: &[(u64, u64)],
    emulated: &[(u64, u64)],
) -> Result<Vec<Measured>, String> {
    let mut out = Vec::new();
    for (i, case) in CASES.iter().enumerate() {
        let (Some((at, trm)), Some((_, bound))) = (trm.get(i), emulated.get(i)) else {
            return Err(format!("no bound of {}", case.function));
        };
        let mut seed = Seed(0x5053_4d50_4100 + i as u64);
        let mut args: Vec<[u32; 4]> = case.fixed.to_vec();
        args.extend((0..case.seeded).map(|_| seed.args(case.function)));
        let mut m = Measured {
            trm: *trm,
            bound: *bound,
            worst: 0,
            worst_args: [0; 4],
            calls: args.len(),
        };
        let function = u32::try_from(*at).map_err(|e| e.to_string())?;
        for a in args {
            let (cycles, got) = chip.call(function, a)?;
            let want = (case.expect)(a);
            if want.iter().zip(got).any(|(w, g)| w.is_some_and(|w| w != g)) {
                return Err(format!(
                    "{}({a:x?}) returned {got:x?}, not {want:x?}: the call did not run it",
                    case.function
                ));
            }
            if cycles > m.worst {
                m.worst = cycles;
                m.worst_args = a;
            }
        }
        out.push(m);
    }
    Ok(out)
}

/// What is wrong with a function's measurement, if anything.
fn verdict(case: &Case, m: &Measured) -> Option<String> {
    if m.worst > m.bound {
        Some(format!(
            "a call took {} cycles, over the static bound of {} (with rp2040js's costs): the analysis undercharges an instruction on its path",
            m.worst, m.bound
        ))
    } else if case.every_path && m.worst != m.bound {
        Some(format!(
            "every path was taken and the worst took {} cycles, not the bound's {} (with rp2040js's costs): the analysis overcharges",
            m.worst, m.bound
        ))
    } else {
        None
    }
}

/// Runs the check on the shipped Pico image and writes its table into `docs/firmware.md`; 1
/// naming each function whose calls disagree.
pub fn run() -> Ending {
    match check(Table::RP2040JS, true) {
        Ok(failures) if failures.is_empty() => Ending::Passed,
        Ok(failures) => Ending::Failed(failures.join("; ")),
        Err(e) => Ending::Failed(e),
    }
}

/// The check with the analysis's costs for rp2040js's in `emulated` (a planted bug in the cost
/// table, for `cargo xtask wcet --mutants`); the functions that fail it.
pub fn check(emulated: Table, print: bool) -> Result<Vec<String>, String> {
    let image = super::analysed_image()?;
    let annotations = Annotations::load()?;
    let names: Vec<&str> = CASES.iter().map(|c| c.function).collect();
    let trm = instruction_cycles(&image, &annotations, &names, Table::TRM)?;
    let bounds = instruction_cycles(&image, &annotations, &names, emulated)?;
    let mut chip = crate::hil::chip_for_calls(&image)?;
    let measured = measure(&mut chip, &trm, &bounds)?;
    let say = |line: String| {
        if print {
            println!("{line}");
        }
    };
    say(format!(
        "{:<18} {:>5} {:>7} {:>10} {:>7}  {:<10} worst call's arguments",
        "function", "calls", "static", "(rp2040js)", "worst", "tightness"
    ));
    let mut failures = Vec::new();
    let group = crate::hil::thousands;
    let mut page = String::from(
        "\n| function | calls | static bound (TRM), cycles | with rp2040js's costs | worst call on rp2040js | bound / worst |\n|---|---|---|---|---|---|\n",
    );
    for (case, m) in CASES.iter().zip(&measured) {
        page += &format!(
            "| `{}` | {} | {} | {} | {} | {:.2} |\n",
            case.function,
            m.calls,
            group(m.trm),
            group(m.bound),
            group(m.worst),
            m.bound as f64 / m.worst.max(1) as f64
        );
        say(format!(
            "{:<18} {:>5} {:>7} {:>10} {:>7}  {:<10} {:x?}",
            case.function,
            m.calls,
            m.trm,
            m.bound,
            m.worst,
            format!("{:.2}", m.bound as f64 / m.worst.max(1) as f64),
            m.worst_args
        ));
        if let Some(why) = verdict(case, m) {
            failures.push(format!("{}: {why}", case.function));
        }
    }
    if print && failures.is_empty() {
        let doc = crate::firmware::root().join("docs/firmware.md");
        crate::hil::write_between(&doc, "wcet-emulated", &page)?;
    }
    Ok(failures)
}

//! The analyser's rules on hand-written images: objdump's text, frames and relocated words, as
//! `program` reads them from an ELF, but small enough that every bound is known by hand. The
//! bounds are exact: a call edge lost or added changes them.

use std::collections::{BTreeSet, HashMap};

use super::{
    Analysis, Binary, Insn, NO_TASK, Program, Rules, Site, by_name, disassembly, jump_table,
    measured_on,
};

/// No rule: every cycle is unbounded, every pointer may reach every candidate.
const NO_RULES: Rules = Rules {
    only_from: &[],
    only_to: &[],
    recursion: &[],
};

/// Where the fixtures' constants (vtables, statics) start.
const RODATA: u64 = 0x3000;

/// A hand-written image. `text` is objdump's with spaces for tabs: `addr <name>:` starts a
/// function, `addr: mnemonic args` is one of its instructions.
#[derive(Default)]
struct Fixture {
    text: &'static str,
    /// LLVM's frames by function name; a function without one has its prologue's.
    frames: &'static [(&'static str, u64)],
    /// Relocated words in the code (literal pools): (address, value).
    pool: &'static [(u64, u64)],
    /// Relocated words of the constants: (address, value).
    rodata: &'static [(u64, u64)],
    /// `movw`/`movt` instructions the linker filled with an address's halves.
    movw: &'static [u64],
    movt: &'static [u64],
}

impl Fixture {
    fn program(&self) -> Program {
        let mut symbols = Vec::new();
        let mut text = String::new();
        for line in self.text.lines().map(str::trim).filter(|l| !l.is_empty()) {
            if let Some((addr, name)) = line.strip_suffix(">:").and_then(|l| l.split_once(" <")) {
                let addr = u64::from_str_radix(addr, 16).expect("a function's address");
                // Thumb functions' symbols have the low bit set.
                symbols.push((name.to_owned(), addr | 1, 2));
            } else {
                text.push_str(&format!("    {}\n", line.replacen(": ", ":\t", 1)));
            }
        }
        let address = |name: &str| {
            let symbol = symbols.iter().find(|(n, _, _)| n == name).expect(name);
            symbol.1 & !1
        };
        let frames: HashMap<u64, u64> = self.frames.iter().map(|(n, f)| (address(n), *f)).collect();
        let mut rodata = vec![0u8; 0x100];
        for (at, value) in self.rodata {
            let at = usize::try_from(at - RODATA).expect("in the constants");
            let value = u32::try_from(*value).expect("a 32-bit word");
            rodata[at..at + 4].copy_from_slice(&value.to_le_bytes());
        }
        Program::new(Binary {
            symbols,
            frames,
            relocated: self.rodata.iter().copied().collect(),
            text_words: self.pool.iter().copied().collect(),
            movw: self.movw.iter().copied().collect(),
            movt: self.movt.iter().copied().collect(),
            data: vec![(RODATA, rodata.as_slice())],
            code: disassembly(&text),
        })
        .expect("a program")
    }
}

fn addr(p: &Program, name: &str) -> u64 {
    by_name(p, name).unwrap_or_else(|| panic!("no function {name}"))
}

/// The worst stack of a call to `entry`: `None` if unbounded.
fn bound(p: &Program, rules: &Rules, entry: &str) -> Option<u64> {
    Analysis::new(p, rules, NO_TASK).worst(addr(p, entry)).0
}

/// What `caller` may call, directly or through pointers, by name.
fn callees(p: &Program, rules: &Rules, caller: &str) -> BTreeSet<String> {
    let a = Analysis::new(p, rules, NO_TASK);
    let f = &p.funcs[&addr(p, caller)];
    a.callees(f).iter().map(|c| a.name(*c).to_owned()).collect()
}

fn names(list: &[&str]) -> BTreeSet<String> {
    list.iter().map(|n| (*n).to_owned()).collect()
}

/// main calls a shallow function and `dispatch`, which tail-calls `deep` (a branch out of it;
/// its `bne` stays inside), which calls `leaf`. The deepest path needs each of these edges.
const CALLS: Fixture = Fixture {
    text: "
        00001000 <app::main>:
        1000: push {r7, lr}
        1002: bl 1100 <app::shallow>
        1006: bl 1200 <app::dispatch>
        100a: pop {r7, pc}
        00001100 <app::shallow>:
        1100: push {r4, lr}
        1102: sub sp, #92
        1104: add sp, #92
        1106: pop {r4, pc}
        00001200 <app::dispatch>:
        1200: push {r7, lr}
        1202: cmp r0, #0
        1204: bne.n 120a <app::dispatch+0xa>
        1206: movs r0, #0
        1208: pop {r7, pc}
        120a: pop.w {r7, lr}
        120e: b.w 1300 <app::deep>
        00001300 <app::deep>:
        1300: push {r4, r5, r6, lr}
        1302: bl 1400 <app::leaf>
        1306: pop {r4, r5, r6, pc}
        00001400 <app::leaf>:
        1400: sub sp, #96
        1402: add sp, #96
        1404: bx lr
    ",
    frames: &[
        ("app::main", 8),
        ("app::shallow", 100),
        ("app::dispatch", 8),
        ("app::deep", 16),
        ("app::leaf", 96),
    ],
    pool: &[],
    rodata: &[],
    movw: &[],
    movt: &[],
};

#[test]
fn direct_calls_and_tail_calls_are_edges_of_the_bound() {
    let p = CALLS.program();
    // main -> dispatch -> (tail call) deep -> leaf: 8 + 8 + 16 + 96. Without the `bl` to
    // dispatch, the tail call or the `bl` to leaf the bound would be main -> shallow's 108.
    assert_eq!(bound(&p, &NO_RULES, "app::main"), Some(128));
    assert_eq!(
        callees(&p, &NO_RULES, "app::main"),
        names(&["app::dispatch", "app::shallow"])
    );
    // A branch inside the function is not a call.
    assert_eq!(
        callees(&p, &NO_RULES, "app::dispatch"),
        names(&["app::deep"])
    );
    assert!(
        p.funcs.values().all(|f| f.sites.is_empty()),
        "`bx lr` returns"
    );
    let mut a = Analysis::new(&p, &NO_RULES, NO_TASK);
    let path: Vec<String> = a
        .deepest_path(addr(&p, "app::main"))
        .into_iter()
        .map(|(_, name)| name)
        .collect();
    assert_eq!(
        path,
        ["app::main", "app::dispatch", "app::deep", "app::leaf"]
    );
}

/// A frame LLVM does not give (precompiled code) is the prologue's; one the prologue does
/// not show leaves the bound unknown rather than zero.
#[test]
fn a_frame_without_llvm_is_the_prologue_or_unbounded() {
    let p = Fixture {
        text: "
            00001000 <app::main>:
            1000: push {r7, lr}
            1002: bl 1100 <compiler_builtins::memcpy>
            1006: bl 1200 <app::odd>
            100a: pop {r7, pc}
            00001100 <compiler_builtins::memcpy>:
            1100: push {r4, r5, r6, r7, lr}
            1102: vpush {d8-d9}
            1104: sub sp, #12
            1106: add sp, #12
            1108: vpop {d8-d9}
            110a: pop {r4, r5, r6, r7, pc}
            00001200 <app::odd>:
            1200: mov sp, r0
            1202: bx lr
        ",
        frames: &[("app::main", 8)],
        ..Fixture::default()
    }
    .program();
    let memcpy = &p.funcs[&addr(&p, "compiler_builtins::memcpy")];
    assert_eq!(
        (memcpy.frame, memcpy.from_prologue),
        (Some(20 + 16 + 12), true)
    );
    let mut a = Analysis::new(&p, &NO_RULES, NO_TASK);
    assert_eq!(a.worst(addr(&p, "app::main")).0, None);
    assert_eq!(a.unknown_frame, names(&["app::odd"]));
}

/// main calls slot 12 of a vtable: `ldr r1, [r0, #12]; blx r1`, r0 from a literal pool.
/// Tables in the constants: A's vtable (drop function, size, align, area, name), B's (no drop
/// function: a zero word; area), a waker table (four functions), all referenced; C's vtable,
/// whose address nothing holds.
const VTABLES: Fixture = Fixture {
    text: "
        00001000 <app::main>:
        1000: push {r7, lr}
        1002: ldr r0, [pc, #8] @ (100c <app::main+0xc>)
        1004: ldr r1, [r0, #12]
        1006: blx r1
        1008: pop {r7, pc}
        00001100 <A::drop>:
        1100: bx lr
        00001110 <A::area>:
        1110: bx lr
        00001120 <A::name>:
        1120: bx lr
        00001130 <B::area>:
        1130: bx lr
        00001140 <C::drop>:
        1140: bx lr
        00001150 <C::area>:
        1150: bx lr
        00001160 <waker::clone>:
        1160: bx lr
        00001170 <waker::wake>:
        1170: bx lr
        00001180 <waker::wake_by_ref>:
        1180: bx lr
        00001190 <waker::drop>:
        1190: bx lr
    ",
    frames: &[
        ("app::main", 8),
        ("A::area", 40),
        ("A::name", 400),
        ("B::area", 24),
        ("C::area", 500),
        ("waker::drop", 8),
    ],
    // main's pool holds A's vtable.
    pool: &[(0x100c, 0x3000)],
    rodata: &[
        // A: drop, (size, align: plain words), area, name.
        (0x3000, 0x1100 | 1),
        (0x300c, 0x1110 | 1),
        (0x3010, 0x1120 | 1),
        // B: a zero word, (size, align), area.
        (0x302c, 0x1130 | 1),
        // C, which no word points at: drop, (size, align), area.
        (0x3040, 0x1140 | 1),
        (0x304c, 0x1150 | 1),
        // A waker table: clone, wake, wake_by_ref, drop.
        (0x3060, 0x1160 | 1),
        (0x3064, 0x1170 | 1),
        (0x3068, 0x1180 | 1),
        (0x306c, 0x1190 | 1),
        // A `&dyn` to B (data, vtable), and a static holding the waker table.
        (0x3080, 0x3090),
        (0x3084, 0x3020),
        (0x3088, 0x3060),
    ],
    movw: &[],
    movt: &[],
};

#[test]
fn a_call_through_a_vtable_reaches_its_slot_of_the_tables_in_use() {
    let p = VTABLES.program();
    let main = &p.funcs[&addr(&p, "app::main")];
    assert!(main.calls.is_empty());
    assert_eq!(main.sites, BTreeSet::from([Site::Slot(12)]));
    // Slot 12 of A's, B's and the waker table; not A's slot 16, nor C's unreferenced table.
    assert_eq!(
        callees(&p, &NO_RULES, "app::main"),
        names(&["A::area", "B::area", "waker::drop"])
    );
    assert_eq!(bound(&p, &NO_RULES, "app::main"), Some(8 + 40));
}

#[test]
fn only_to_narrows_a_vtable_call() {
    let p = VTABLES.program();
    let rules = Rules {
        only_to: &[(&["app::main"], &["B::area"], "main holds only B")],
        ..NO_RULES
    };
    assert_eq!(callees(&p, &rules, "app::main"), names(&["B::area"]));
    assert_eq!(bound(&p, &rules, "app::main"), Some(8 + 24));
}

/// The address a call jumps to, loaded from a literal pool (`ldr r3, [pc, #4]`) or built by
/// a relocated `movw`/`movt` pair: a direct call.
#[test]
fn a_literal_pool_load_then_blx_is_a_direct_call() {
    let p = Fixture {
        text: "
            00001000 <app::main>:
            1000: push {r7, lr}
            1002: ldr r3, [pc, #4] @ (1008 <app::main+0x8>)
            1004: blx r3
            1006: pop {r7, pc}
            00001100 <app::callee>:
            1100: sub sp, #56
            1102: add sp, #56
            1104: bx lr
            00001200 <app::armv8m>:
            1200: push {r7, lr}
            1202: movw r3, #4353 @ 0x1101
            1206: movt r3, #0
            120a: blx r3
            120c: pop {r7, pc}
        ",
        frames: &[("app::main", 8), ("app::callee", 56), ("app::armv8m", 8)],
        pool: &[(0x1008, 0x1100 | 1)],
        movw: &[0x1202],
        movt: &[0x1206],
        ..Fixture::default()
    }
    .program();
    let callee = addr(&p, "app::callee");
    for caller in ["app::main", "app::armv8m"] {
        let f = &p.funcs[&addr(&p, caller)];
        assert_eq!(f.calls, BTreeSet::from([callee]), "{caller}");
        assert!(f.sites.is_empty(), "{caller}");
        assert_eq!(bound(&p, &NO_RULES, caller), Some(8 + 56), "{caller}");
    }
    // Called, not stored: it joins no call through a pointer.
    assert!(p.stored.is_empty());
}

/// `spawn` stores `poll`'s address (a literal-pool load no call uses); `executor` calls an
/// argument, `shape` slot 12 of a vtable (B's: no drop function, area).
const STORED: Fixture = Fixture {
    text: "
        00001000 <app::spawn>:
        1000: ldr r1, [pc, #4] @ (1008 <app::spawn+0x8>)
        1002: str r1, [r0, #0]
        1004: bx lr
        00001100 <app::executor>:
        1100: push {r7, lr}
        1102: blx r0
        1104: pop {r7, pc}
        00001200 <app::shape>:
        1200: push {r7, lr}
        1202: ldr r3, [r0, #12]
        1204: blx r3
        1206: pop {r7, pc}
        00001300 <app::poll>:
        1300: bx lr
        00001400 <B::area>:
        1400: bx lr
    ",
    frames: &[
        ("app::executor", 8),
        ("app::shape", 8),
        ("app::poll", 300),
        ("B::area", 16),
    ],
    pool: &[(0x1008, 0x1300 | 1)],
    rodata: &[(0x300c, 0x1400 | 1), (0x3080, 0x3000)],
    movw: &[],
    movt: &[],
};

#[test]
fn a_pointer_stored_at_run_time_joins_every_indirect_call() {
    let p = STORED.program();
    assert_eq!(p.stored, BTreeSet::from([addr(&p, "app::poll")]));
    let executor = &p.funcs[&addr(&p, "app::executor")];
    assert_eq!(executor.sites, BTreeSet::from([Site::Unknown(0x1102)]));
    for caller in ["app::executor", "app::shape"] {
        assert_eq!(
            callees(&p, &NO_RULES, caller),
            names(&["B::area", "app::poll"]),
            "{caller}"
        );
        assert_eq!(bound(&p, &NO_RULES, caller), Some(8 + 300), "{caller}");
    }
}

#[test]
fn only_from_keeps_a_stored_pointer_to_its_caller() {
    let p = STORED.program();
    let rules = Rules {
        only_from: &[("app::poll", &["app::executor"], "the executor polls")],
        ..NO_RULES
    };
    assert_eq!(
        callees(&p, &rules, "app::executor"),
        names(&["B::area", "app::poll"])
    );
    assert_eq!(bound(&p, &rules, "app::executor"), Some(8 + 300));
    assert_eq!(callees(&p, &rules, "app::shape"), names(&["B::area"]));
    assert_eq!(bound(&p, &rules, "app::shape"), Some(8 + 16));
}

/// `walk` calls itself.
const SELF_RECURSION: Fixture = Fixture {
    text: "
        00001000 <app::main>:
        1000: push {r7, lr}
        1002: bl 1100 <tree::walk>
        1006: pop {r7, pc}
        00001100 <tree::walk>:
        1100: push {r4, r5, r7, lr}
        1102: cbz r0, 110a <tree::walk+0xa>
        1104: ldr r0, [r0, #0]
        1106: bl 1100 <tree::walk>
        110a: pop {r4, r5, r7, pc}
    ",
    frames: &[("app::main", 8), ("tree::walk", 24)],
    pool: &[],
    rodata: &[],
    movw: &[],
    movt: &[],
};

/// `value` calls `array`, which calls `value` back; `value` also calls `number`, deeper than
/// `array`.
const MUTUAL_RECURSION: Fixture = Fixture {
    text: "
        00001000 <app::main>:
        1000: push {r7, lr}
        1002: bl 1100 <json::value>
        1006: pop {r7, pc}
        00001100 <json::value>:
        1100: push {r4, r5, r6, r7, lr}
        1102: bl 1200 <json::array>
        1106: bl 1300 <json::number>
        110a: pop {r4, r5, r6, r7, pc}
        00001200 <json::array>:
        1200: push {r7, lr}
        1202: bl 1100 <json::value>
        1206: pop {r7, pc}
        00001300 <json::number>:
        1300: bx lr
    ",
    frames: &[
        ("app::main", 8),
        ("json::value", 32),
        ("json::array", 16),
        ("json::number", 40),
    ],
    pool: &[],
    rodata: &[],
    movw: &[],
    movt: &[],
};

#[test]
fn a_recursion_without_a_rule_is_unbounded_and_reported() {
    let rules = Rules {
        recursion: &[("json::number", 4, "not on the cycle")],
        ..NO_RULES
    };
    for (fixture, rules, cycle) in [
        (&SELF_RECURSION, &NO_RULES, "tree::walk"),
        (
            &MUTUAL_RECURSION,
            &NO_RULES,
            "json::value\n    -> json::array",
        ),
        // A rule for a function off the cycle bounds nothing.
        (&MUTUAL_RECURSION, &rules, "json::value\n    -> json::array"),
    ] {
        let p = fixture.program();
        let mut a = Analysis::new(&p, rules, NO_TASK);
        assert_eq!(a.worst(addr(&p, "app::main")).0, None, "{cycle}");
        assert_eq!(a.recursion, names(&[cycle]));
    }
}

#[test]
fn a_bounded_recursion_costs_its_cycle_depth_times() {
    let p = SELF_RECURSION.program();
    let rules = Rules {
        recursion: &[("tree::walk", 5, "a tree 5 deep")],
        ..NO_RULES
    };
    let mut a = Analysis::new(&p, &rules, NO_TASK);
    assert_eq!(a.worst(addr(&p, "app::main")).0, Some(8 + 24 * 5));
    assert!(a.recursion.is_empty());

    // `depth - 1` times around value -> array (32 + 16), then value's deepest way out: number.
    let p = MUTUAL_RECURSION.program();
    let rules = Rules {
        recursion: &[("json::value", 4, "nesting 4 deep")],
        ..NO_RULES
    };
    let mut a = Analysis::new(&p, &rules, NO_TASK);
    assert_eq!(
        a.worst(addr(&p, "app::main")).0,
        Some(8 + 3 * (32 + 16) + 32 + 40)
    );
    assert!(a.recursion.is_empty());
}

fn insn(addr: u64, mnemonic: &str, args: &str) -> Insn {
    Insn {
        addr,
        mnemonic: mnemonic.to_owned(),
        args: args.to_owned(),
    }
}

/// A Cortex-M0+ switch, as objdump prints one of `Engine::trace`'s.
fn switch(table_at: u64) -> Vec<Insn> {
    vec![
        insn(
            0x1000,
            "add",
            &format!("r2, pc, #8\t@ (adr r2, {table_at:x} <f+0x10>)"),
        ),
        insn(0x1002, "ldr", "r4, [r2, r1]"),
        insn(0x1004, "ldr", "r2, [sp, #36]\t@ 0x24"),
        insn(0x1006, "mov", "r1, r2"),
        insn(0x1008, "mov", "pc, r4"),
    ]
}

#[test]
fn a_switch_through_a_table_in_the_function_is_a_branch_not_a_call() {
    let code = switch(0x1010);
    assert!(jump_table(&code, 4, 0x1000..0x1100));
    // A table outside the function, or a jump through a register loaded otherwise, is a
    // call the analysis cannot follow.
    assert!(!jump_table(&code, 4, 0x0f00..0x1000));
    let mut other = switch(0x1010);
    other[1] = insn(0x1002, "ldr", "r4, [r0, #4]");
    assert!(!jump_table(&other, 4, 0x1000..0x1100));
}

/// The Pico's bound is checked against the bench's measurement of the image as built: none,
/// or one of another build, is an error saying what to run (it was skipped, or trusted).
#[test]
fn a_missing_or_stale_bench_measurement_is_an_error() {
    assert_eq!(measured_on(Some((7000, Some(42))), 42), Ok(7000));
    let missing = measured_on(None, 42).unwrap_err();
    assert!(missing.contains("run `cargo xtask hil` first"), "{missing}");
    for stale in [Some((7000, Some(41))), Some((7000, None))] {
        let e = measured_on(stale, 42).unwrap_err();
        assert!(
            e.contains("another build") && e.contains("cargo xtask hil"),
            "{e}"
        );
    }
}

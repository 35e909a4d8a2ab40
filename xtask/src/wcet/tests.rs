//! The analysis on hand-assembled Thumb, each fixture's cycles worked out by hand from the
//! Cortex-M0+ TRM's table (one instruction a cycle unless [`thumb`](super::thumb) says more).

use std::collections::BTreeMap;

use super::cfg::{self, Image, Site};
use super::{JobWcet, Report};

/// Code at address 0, its functions, and what the analysis would ask of an ELF.
#[derive(Default)]
struct Fixture {
    code: Vec<u8>,
    /// start -> end
    funcs: BTreeMap<u64, u64>,
    /// A call through a register at this address reaches these.
    indirect: BTreeMap<u64, Vec<u64>>,
    /// The bound of a loop whose header is here.
    annotated: BTreeMap<u64, u64>,
}

impl Fixture {
    fn new(halfwords: &[u16]) -> Self {
        Self {
            code: halfwords.iter().flat_map(|h| h.to_le_bytes()).collect(),
            ..Self::default()
        }
    }

    fn function(mut self, start: u64, end: u64) -> Self {
        self.funcs.insert(start, end);
        self
    }

    fn worst(&mut self, start: u64) -> Result<cfg::Worst, String> {
        let end = *self.funcs.get(&start).ok_or("no such function")?;
        cfg::analyse(self, start, end)
    }
}

impl Image for Fixture {
    fn code(&self, addr: u64) -> Option<&[u8]> {
        self.code.get(usize::try_from(addr).ok()?..)
    }
    fn word(&self, _addr: u64) -> Option<u64> {
        None
    }
    fn call(&mut self, addr: u64) -> Result<Option<u64>, String> {
        Ok(self.worst(addr)?.cycles)
    }
    fn indirect(&mut self, _function: u64, site: u64) -> Result<Vec<u64>, String> {
        self.indirect
            .get(&site)
            .cloned()
            .ok_or_else(|| format!("nothing known at {site:#x}"))
    }
    fn annotation(&self, _function: u64, site: &Site) -> Option<(u64, String)> {
        self.annotated
            .get(&site.header)
            .map(|b| (*b, "annotated".to_owned()))
    }
}

const BX_LR: u16 = 0x4770;

#[test]
fn straight_line_costs_each_instruction() {
    // movs r0, #1; adds r0, r0, #2; bx lr: 1 + 1 + 2.
    let mut f = Fixture::new(&[0x2001, 0x1c80, BX_LR]).function(0, 6);
    assert_eq!(f.worst(0).map(|w| w.cycles), Ok(Some(4)));
}

#[test]
fn if_else_takes_the_longer_arm() {
    // 0: cmp r0, #0; 2: beq 8; 4: movs r1, #1; 6: b 10; 8: movs r1, #2; 10: bx lr.
    // Not taken: 1 + 1 + 1 + 2 + 2 = 7; taken: 1 + 2 + 1 + 2 = 6.
    let mut f = Fixture::new(&[0x2800, 0xd001, 0x2101, 0xe000, 0x2102, BX_LR]).function(0, 12);
    assert_eq!(f.worst(0).map(|w| w.cycles), Ok(Some(7)));
}

#[test]
fn a_branch_target_is_where_objdump_puts_it() {
    // The same if/else with the arms' costs made different, so that a target one halfword
    // off (the decoder's quirk) changes the result or fails to decode: 8: three instructions.
    // 0: cmp r0, #0; 2: beq 8; 4: movs r1, #1; 6: bx lr; 8: movs r1, #2; 10: movs r2, #2;
    // 12: movs r3, #2; 14: bx lr. Taken: 1 + 2 + 3 + 2 = 8; not taken: 1 + 1 + 1 + 2 = 5.
    let mut f = Fixture::new(&[0x2800, 0xd001, 0x2101, BX_LR, 0x2102, 0x2202, 0x2302, BX_LR])
        .function(0, 16);
    assert_eq!(f.worst(0).map(|w| w.cycles), Ok(Some(8)));
}

#[test]
fn a_counted_loop_is_bounded_from_the_code() {
    // 0: movs r1, #0; 2: adds r1, r1, #1; 4: cmp r1, #10; 6: bne 2; 8: bx lr.
    // Run: 10 iterations, 9 back edges: 1 + 10 * 2 + 9 * 2 + 1 + 2 = 42.
    // Bound: 10 steps + 1 back edges (the exit may test before or after the step) of 4
    // cycles (adds, cmp, bne taken), then the way out (adds, cmp, bne) and bx:
    // 1 + 11 * 4 + 3 + 2 = 50.
    let mut f = Fixture::new(&[0x2100, 0x1c49, 0x290a, 0xd1fc, BX_LR]).function(0, 10);
    let w = f.worst(0).expect("bounded");
    assert_eq!(w.cycles, Some(50));
    assert!(w.cycles >= Some(42));
    assert_eq!(w.loops.len(), 1);
    assert_eq!(
        w.loops.first().map(|l| (l.bound, l.source.as_str())),
        Some((11, "auto"))
    );
}

#[test]
fn a_loop_to_a_limit_in_a_register_is_bounded_from_the_code() {
    // 0: movs r1, #0; 2: movs r2, #125; 4: lsls r2, r2, #3 (1000); 6: adds r1, r1, #1;
    // 8: cmp r1, r2; 10: bne 6; 12: bx lr.
    // Run: 1000 iterations: 3 + 999 * 4 + 3 + 2 = 4004. Bound: 1001 back edges of 4 cycles:
    // 3 + 1001 * 4 + 3 + 2 = 4012.
    let mut f =
        Fixture::new(&[0x2100, 0x227d, 0x00d2, 0x1c49, 0x4291, 0xd1fc, BX_LR]).function(0, 14);
    let w = f.worst(0).expect("bounded");
    assert_eq!(w.loops.first().map(|l| l.bound), Some(1001));
    assert_eq!(w.cycles, Some(4012));
}

#[test]
fn a_compare_of_the_limit_with_the_counter_is_read_either_way_round() {
    // 0: movs r1, #0; 2: movs r2, #10; 4: adds r1, r1, #1; 6: cmp r2, r1; 8: bhi 4; 10: bx lr.
    // Goes on while 10 > r1: 10 iterations. Bound: 11 back edges of 4 cycles:
    // 2 + 11 * 4 + 3 + 2 = 51.
    let mut f = Fixture::new(&[0x2100, 0x220a, 0x1c49, 0x428a, 0xd8fc, BX_LR]).function(0, 12);
    let w = f.worst(0).expect("bounded");
    assert_eq!(w.loops.first().map(|l| l.bound), Some(11));
    assert_eq!(w.cycles, Some(51));
}

#[test]
fn a_counter_that_goes_on_past_its_limit_is_not_counted() {
    // 0: movs r1, #9; 2: adds r1, r1, #1; 4: cmp r1, #10; 6: bhs 2; 8: bx lr: goes on while
    // r1 >= 10, which after the first step is for ever (until it wraps).
    let mut f = Fixture::new(&[0x2109, 0x1c49, 0x290a, 0xd2fc, BX_LR]).function(0, 10);
    let e = f.worst(0).expect_err("no bound");
    assert!(e.contains("no bound"), "{e}");
}

#[test]
fn a_loop_over_set_bits_is_bounded_by_the_word() {
    // 0: cmp r0, #0; 2: beq 10; 4: subs r1, r0, #1; 6: ands r0, r1; 8: b 0; 10: bx lr.
    // At most 32 bits to clear: 32 back edges of 1 + 1 + 1 + 1 + 2 = 6, then cmp, beq
    // taken and bx: 32 * 6 + 1 + 2 + 2 = 197.
    let mut f = Fixture::new(&[0x2800, 0xd002, 0x1e41, 0x4008, 0xe7fa, BX_LR]).function(0, 12);
    let w = f.worst(0).expect("bounded");
    assert_eq!(w.loops.first().map(|l| l.bound), Some(32));
    assert_eq!(w.cycles, Some(197));
}

#[test]
fn a_call_adds_the_callee() {
    // 0: push {r7, lr}; 2: bl 8; 6: pop {r7, pc} | 8: movs r0, #0; 10: bx lr.
    // Callee 1 + 2 = 3; caller: push 1 + 2, bl 3, pop 3 + 2: 3 + 3 + 3 + 5 = 14.
    let mut f = Fixture::new(&[0xb580, 0xf000, 0xf801, 0xbd80, 0x2000, BX_LR])
        .function(0, 8)
        .function(8, 12);
    let w = f.worst(0).expect("bounded");
    assert_eq!(w.cycles, Some(14));
    assert!(w.callees.contains(&8));
}

#[test]
fn an_indirect_call_takes_its_costliest_target() {
    // 0: push {r7, lr}; 2: blx r3; 4: pop {r7, pc} | 6: bx lr (2) | 8: movs; movs; bx lr (4).
    // 3 + 2 + 4 + 5 = 14.
    let mut f = Fixture::new(&[0xb580, 0x4798, 0xbd80, BX_LR, 0x2000, 0x2000, BX_LR])
        .function(0, 6)
        .function(6, 8)
        .function(8, 14);
    f.indirect.insert(2, vec![6, 8]);
    assert_eq!(f.worst(0).map(|w| w.cycles), Ok(Some(14)));
}

#[test]
fn a_loop_without_a_bound_is_refused_naming_it() {
    // A busy wait on a flag: 0: ldr r1, [r0]; 2: cmp r1, #0; 4: beq 0; 6: bx lr.
    let mut f = Fixture::new(&[0x6801, 0x2900, 0xd0fc, BX_LR]).function(0, 8);
    let e = f.worst(0).expect_err("unbounded");
    assert!(e.contains("no bound") && e.contains("0x0"), "{e}");
    // Annotated: two back edges of ldr (2, and 2 of waits: an address the analysis cannot
    // place may be a peripheral), cmp and beq taken, 7 cycles each, then the way out (ldr,
    // cmp, beq) and bx: 2 * 7 + 6 + 2 = 22.
    f.annotated.insert(0, 2);
    assert_eq!(f.worst(0).map(|w| w.cycles), Ok(Some(22)));
}

/// A rotated loop whose latch is a call, as embassy's run queue is: the bench counts its back
/// edge where the callee returns, at the entry after the call.
#[test]
fn a_latch_that_is_a_call_goes_round_where_its_callee_returns() {
    // 0: b 6; 2: nop; 4: blx r1; 6: cmp r0, #0; 8: bne 4; 10: bx lr | 12: bx lr.
    let mut f = Fixture::new(&[0xe001, 0xbf00, 0x4788, 0x2800, 0xd1fc, BX_LR, BX_LR])
        .function(0, 12)
        .function(12, 14);
    f.indirect.insert(4, vec![12]);
    f.annotated.insert(6, 3);
    let w = f.worst(0).expect("annotated");
    let [l] = &w.loops[..] else {
        panic!("{:?}", w.loops)
    };
    assert_eq!((l.entries.clone(), l.latches.clone()), (vec![6], vec![4]));
    assert_eq!(l.returns, vec![6]);
}

#[test]
fn a_wait_for_interrupt_is_refused() {
    // wfi; bx lr
    let mut f = Fixture::new(&[0xbf30, BX_LR]).function(0, 4);
    let e = f.worst(0).expect_err("waits");
    assert!(e.contains("waits"), "{e}");
}

#[test]
fn a_panic_path_does_not_complete() {
    // 0: cmp r0, #0; 2: beq 6; 4: bx lr; 6: udf: the returning path only, 1 + 1 + 2.
    let mut f = Fixture::new(&[0x2800, 0xd000, BX_LR, 0xde00]).function(0, 8);
    assert_eq!(f.worst(0).map(|w| w.cycles), Ok(Some(4)));
}

#[test]
fn thumb2_outside_armv6m_is_refused() {
    // cbz r0, ... (0xb100) is Armv7-M only.
    let mut f = Fixture::new(&[0xb100, BX_LR]).function(0, 4);
    assert!(f.worst(0).is_err());
}

/// The pages give a bound with XIP misses to two significant figures: two checkouts in other
/// folders link the same code in another order, and their bounds differed in the fifth.
#[test]
fn a_layout_dependent_figure_is_given_to_two_significant_figures() {
    use super::about;
    assert_eq!(about(44_732_154_604.0), "≈45,000,000,000");
    assert_eq!(about(44_724_067_628.0), about(44_732_154_604.0));
    assert_eq!(about(45_272.0), "≈45,000");
    assert_eq!(about(2_959_454.0), "≈3,000,000");
    assert_eq!(about(99.06), "≈99");
    assert_eq!(about(49.0), "≈49");
}

/// The Pico's image runs from SRAM: its lines cost no miss; a line in flash (any XIP alias)
/// still does.
#[test]
fn only_lines_in_flash_are_charged_misses() {
    let lines = |addrs: &[u64]| addrs.iter().map(|a| a / super::LINE).collect();
    let touched = lines(&[
        0x2002_8000,
        0x2003_fff8,
        0x1000_0200,
        0x1300_0000,
        0x0000_0100,
    ]);
    assert_eq!(
        super::in_flash(&touched),
        lines(&[0x1000_0200, 0x1300_0000])
    );
}

#[test]
fn rp2040js_charges_nothing_for_the_link_register_and_the_pc() {
    // The fixture of `a_call_adds_the_callee`: 14 cycles by the TRM, whose N counts `PUSH`'s LR
    // and `POP`'s PC; rp2040js counts neither, 12 (what `cargo xtask wcet --emulated` compares).
    let code = [0xb580, 0xf000, 0xf801, 0xbd80, 0x2000, BX_LR];
    let cycles = |table| {
        super::thumb::with_table(table, || {
            let mut f = Fixture::new(&code).function(0, 8).function(8, 12);
            f.worst(0).map(|w| w.cycles)
        })
    };
    assert_eq!(cycles(super::thumb::Table::TRM), Ok(Some(14)));
    assert_eq!(cycles(super::thumb::Table::RP2040JS), Ok(Some(12)));
}

#[test]
fn a_bound_whose_sums_overflow_saturates_instead_of_panicking() {
    // 0: push {r7, lr}; 2: bl 12; 6: bl 12; 10: pop {r7, pc}; 12: the busy wait of
    // `a_loop_without_a_bound_is_refused_naming_it`, annotated 2^64-1 rounds: each call
    // costs more than 64 bits hold, and so do both.
    let mut f = Fixture::new(&[
        0xb580, 0xf000, 0xf803, 0xf000, 0xf801, 0xbd80, 0x6801, 0x2900, 0xd0fc, BX_LR,
    ])
    .function(0, 12)
    .function(12, 20);
    f.annotated.insert(12, u64::MAX);
    assert_eq!(f.worst(0).map(|w| w.cycles), Ok(Some(u64::MAX)));
    // Which the analysis reports as an error naming the annotations' file.
    let e = super::overflow(u64::MAX).unwrap_err();
    assert!(
        e.contains("overflows") && e.contains("wcet-loops.json"),
        "{e}"
    );
    assert_eq!(super::overflow(7), Ok(7));
}

fn annotations(loops: &str, lengths: &str) -> Result<super::Annotations, String> {
    super::Annotations::parse(&format!(
        r#"{{"about": "a", "loops": [{loops}], "lengths": [{lengths}]}}"#
    ))
}

#[test]
fn the_narrowest_annotation_bounds_a_loop_whatever_their_order() {
    let general = r#"{"function": "critical_section::with", "bound": 0, "why": "w"}"#;
    let within =
        r#"{"function": "critical_section::with", "within": "flush", "bound": 65, "why": "w"}"#;
    let chain = [
        "main".to_owned(),
        "flush".to_owned(),
        "critical_section::with".to_owned(),
    ];
    for loops in [
        format!("{general}, {within}"),
        format!("{within}, {general}"),
    ] {
        let a = annotations(&loops, "").unwrap();
        let (_, found) = super::pick(&a.loops, "critical_section::with", "deciding", &chain)
            .expect("an annotation");
        assert_eq!(found.bound, 65, "{loops}");
        // Outside `flush`, the general one.
        let (_, found) = super::pick(&a.loops, "critical_section::with", "deciding", &chain[2..])
            .expect("an annotation");
        assert_eq!(found.bound, 0, "{loops}");
    }
}

#[test]
fn annotations_refuse_duplicates_empty_reasons_and_unknown_jobs() {
    let l = |extra: &str| format!(r#"{{"function": "f", "bound": 3, "why": "w"{extra}}}"#);
    let e = annotations(&format!("{}, {}", l(""), l("")), "").unwrap_err();
    assert!(
        e.contains("two annotations of f") && e.contains("wcet-loops.json"),
        "{e}"
    );
    let e = annotations(
        &format!(
            "{}, {}",
            l(r#", "jobs": ["alarm", "gpio"]"#),
            l(r#", "jobs": ["gpio", "alarm"]"#)
        ),
        "",
    )
    .unwrap_err();
    assert!(e.contains("two annotations of f"), "{e}");
    let e = annotations("", &format!("{}, {}", l(""), l(""))).unwrap_err();
    assert!(e.contains("lengths: two annotations"), "{e}");
    // Different jobs or a `within`: two annotations.
    assert!(annotations(&format!("{}, {}", l(""), l(r#", "within": "g""#)), "").is_ok());
    let e = annotations("", r#"{"function": "f", "bound": 3, "why": " "}"#).unwrap_err();
    assert!(e.contains("lengths needs a function and a reason"), "{e}");
    let e = annotations(&l(r#", "jobs": ["decidng"]"#), "").unwrap_err();
    assert!(e.contains(r#"the job "decidng": no such job"#), "{e}");
}

#[test]
fn an_annotation_that_does_not_apply_says_why() {
    let a = annotations(
        r#"{"function": "f", "bound": 3, "why": "w", "within": "flusj"}, {"function": "g", "bound": 3, "why": "w", "jobs": ["alarm"]}"#,
        "",
    )
    .unwrap();
    let chain = ["flush".to_owned(), "f".to_owned()];
    let why = a.loops[0].mismatch("f", "deciding", &chain).unwrap();
    assert!(
        why.contains(r#"within "flusj""#) && why.contains("flush, f"),
        "{why}"
    );
    let why = a.loops[1].mismatch("g", "deciding", &chain).unwrap();
    assert!(why.contains("not deciding"), "{why}");
    assert_eq!(a.loops[1].mismatch("h", "deciding", &chain), None);
}

#[test]
fn json_inputs_name_a_byte_order_mark_a_duplicate_key_and_text_that_is_not_json() {
    let good = r#"{"about": "a", "loops": [{"function": "f", "bound": 3, "why": "w"}]}"#;
    assert!(super::Annotations::parse(good).is_ok());
    let e = super::Annotations::parse(&format!("\u{feff}{good}")).unwrap_err();
    assert!(
        e.contains("wcet-loops.json") && e.contains("byte order mark"),
        "{e}"
    );
    // A second `bound` in one annotation, which serde_json would take silently.
    let twice = good.replace(r#""bound": 3,"#, r#""bound": 3, "bound": 100000,"#);
    let e = super::Annotations::parse(&twice).unwrap_err();
    assert!(e.contains(r#"the key "bound" appears twice"#), "{e}");
    let e = super::Annotations::parse("loops: none").unwrap_err();
    assert!(
        e.contains("wcet-loops.json: ") && e.contains("line 1"),
        "{e}"
    );
    let path = std::path::Path::new("boards/pico/bench-budget.json");
    let text = std::fs::read(crate::firmware::root().join(path)).unwrap();
    assert!(crate::hil::bound::Budget::parse(path, &text).is_ok());
    let e = crate::hil::bound::Budget::parse(path, &[b"\xef\xbb\xbf".as_slice(), &text].concat())
        .unwrap_err();
    assert!(
        e.starts_with("boards/pico/bench-budget.json: ") && e.contains("byte order mark"),
        "{e}"
    );
}

#[test]
fn an_entry_no_loop_used_is_stale_though_another_of_its_function_was_used() {
    let a = annotations(
        r#"{"function": "critical_section::with", "within": "flush", "bound": 65, "why": "w"}, {"function": "critical_section::with", "bound": 0, "why": "w"}"#,
        r#"{"function": "memcpy", "bound": 8, "why": "w"}"#,
    )
    .unwrap();
    // Only the general entry bounded a loop: the `within` one is stale, and so is the length.
    let used = std::collections::BTreeSet::from([(false, 1)]);
    let stale: Vec<String> = super::stale(&a, &used).iter().map(|s| s.key()).collect();
    assert_eq!(
        stale,
        [
            "critical_section::with (jobs [], within flush)",
            "memcpy (jobs [])"
        ]
    );
}

/// `cargo xtask wcet --json`'s object, as the design's command-line contract (SIMULATION.md) names its fields: each
/// job's name, bound, the bench's measured worst and loops; each sensor's reaction bound.
#[test]
fn the_json_report_has_the_contracts_fields() {
    let report = Report {
        jobs: vec![JobWcet {
            job: "alarm".to_owned(),
            cycles: 45_144,
            measured_worst_cycles: Some(457),
            xip_cycles: 37_568,
            lines: 84,
            loops: Vec::new(),
            entry: 0,
        }],
        reaction_bound_cycles: BTreeMap::from([("sonar".to_owned(), Some(9_000))]),
        reaction_error: None,
    };
    let v: serde_json::Value = serde_json::to_value(&report).unwrap();
    let job = &v["jobs"][0];
    assert_eq!(job["job"], "alarm");
    assert_eq!(job["cycles"], 45_144);
    assert_eq!(job["measured_worst_cycles"], 457);
    assert!(job["loops"].is_array());
    assert_eq!(v["reaction_bound_cycles"]["sonar"], 9_000);
}

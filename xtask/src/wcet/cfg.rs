//! A function's control-flow graph, its loops and its longest path.
//!
//! The graph is one node per instruction, decoded from the entry by following the flow (so a
//! literal pool is never read as code). Thumb-1 has no `TBB`: LLVM's switches on the
//! Cortex-M0+ are `ADD rX, PC; LDRB rX, [rX, #k]; LSLS rX, rX, #1; ADD PC, rX` (a table of
//! byte offsets after the dispatch) or `ADR rX, T; LDR rY, [rX, rZ]; MOV PC, rY` (a table of
//! relocated addresses). A `BL` into its own function is a far branch, not a call.
//!
//! Loops are natural loops (a back edge's target dominates its source); a graph with a cycle
//! that is not one (irreducible) is refused. Each loop, innermost first, becomes one node:
//! `bound` times its longest iteration (header to a back edge), then its longest way out. A
//! loop's bound is the most times its back edges run per entry into it.

use std::collections::{BTreeMap, BTreeSet};

use super::thumb::{self, Flow, Insn};

/// What the analysis of one function asks of the image.
pub trait Image {
    /// The bytes from `addr` to the end of the code.
    fn code(&self, addr: u64) -> Option<&[u8]>;
    /// The relocated word at `addr` in the code (a jump table's entry), if any.
    fn word(&self, addr: u64) -> Option<u64>;
    /// The worst cycles of a call to the function at `addr`; `None`: it never returns.
    fn call(&mut self, addr: u64) -> Result<Option<u64>, String>;
    /// For a function whose loops a length argument bounds (`memcpy`, `memset` ...): the
    /// register that carries it.
    fn length_register(&self, _addr: u64) -> Option<u8> {
        None
    }
    /// The most a call at `site` in `function` passes as such a length, when the code before
    /// it does not show a constant: (bytes, why).
    fn length_at(&mut self, _function: u64, _site: u64) -> Option<(u64, String)> {
        None
    }
    /// The worst cycles of a call to such a function with a length of at most `length`.
    fn call_with_length(&mut self, addr: u64, _length: u64) -> Result<Option<u64>, String> {
        self.call(addr)
    }
    /// The functions a call or jump through a register at `site`, in the function starting
    /// at `function`, may reach.
    fn indirect(&mut self, function: u64, site: u64) -> Result<Vec<u64>, String>;
    /// The bound of the loop `site` in `function`, when the code cannot show it: (back edges
    /// per entry, why).
    fn annotation(&self, function: u64, site: &Site) -> Option<(u64, String)>;
    /// A loop with neither bound: an error, or (to list them all) a stand-in bound.
    fn unbounded(&mut self, function: u64, site: &Site) -> Result<u64, String> {
        let _ = function;
        let at = site.latches.first().copied().unwrap_or(site.header);
        Err(format!(
            "the loop at {:#x} (back edge at {at:#x}) has no bound: neither counted nor annotated",
            site.header
        ))
    }
    /// Extra cycles of a load from an address the analysis cannot place (beyond the
    /// peripheral wait the instruction's cost has).
    fn unplaced_load(&self) -> u64 {
        0
    }
    /// Extra cycles of fetching the instruction at `addr` when control enters it from
    /// `from` (not the instruction before it in memory), or falls into it.
    fn fetch(&self, _addr: u64, _branched: bool) -> u64 {
        0
    }
}

/// Where a loop is: its first entry, its back edges' sources, every instruction in it.
#[derive(Clone, Debug, Default)]
pub struct Site {
    pub header: u64,
    pub latches: Vec<u64>,
    pub body: Vec<u64>,
}

/// A loop found and bounded.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Loop {
    /// The header's address.
    pub header: u64,
    /// The back edges' sources.
    pub latches: Vec<u64>,
    /// Back edges per entry.
    pub bound: u64,
    /// `auto` (counted), or the annotation's reason.
    pub source: String,
    /// Cycles of its longest iteration.
    pub iteration: u64,
    /// Every instruction in it.
    #[serde(skip)]
    pub body: Vec<u64>,
    /// Where the back edges of latches that are calls go: the calls' return addresses, each
    /// an entry (the loop goes round when the callee returns there).
    #[serde(skip)]
    pub returns: Vec<u64>,
    /// Where control enters it (a back edge goes from a latch to one of these).
    #[serde(skip)]
    pub entries: Vec<u64>,
}

/// A function's worst case.
#[derive(Clone, Debug, Default)]
pub struct Worst {
    /// Cycles from entry to return; `None` if no path returns.
    pub cycles: Option<u64>,
    pub loops: Vec<Loop>,
    /// Functions called (directly, through registers, or tail called).
    pub callees: BTreeSet<u64>,
    /// Addresses of the code it may run and the constants it reads from its literal pools and
    /// jump tables (its own, not its callees').
    pub touched: BTreeSet<u64>,
}

/// Where control goes after an instruction, with the cycles the edge adds.
#[derive(Clone, Copy, Debug)]
enum Edge {
    To(usize, u64),
}

/// A node: an instruction, what it costs (calls included) and where it goes.
struct Node {
    insn: Insn,
    cost: u64,
    succ: Vec<Edge>,
    /// Ends the function here: returns (with this many more cycles: a tail call's callee).
    completes: Option<u64>,
}

/// A critical section to bound instead of the whole function: from the instruction at `from`
/// (a call of an acquire, or a `CPSID`) to a call of one of `release` or a `CPSIE`.
#[derive(Clone, Copy, Debug)]
pub struct Section<'a> {
    pub from: u64,
    pub release: &'a [u64],
    /// Where an inlined release's paths join after its `CPSIE` (which a nested section skips):
    /// the section has ended there too.
    pub joins: &'a [u64],
}

/// Decodes the function at `start..end` (or one of its critical sections) and builds its
/// graph.
fn graph(
    image: &mut dyn Image,
    start: u64,
    end: u64,
    section: Option<Section<'_>>,
) -> Result<(Vec<Node>, Worst), String> {
    let inside = |a: u64| (start..end).contains(&a);
    let mut index: BTreeMap<u64, usize> = BTreeMap::new();
    let mut nodes: Vec<Node> = Vec::new();
    let mut targets: Vec<(usize, Vec<(u64, u64)>)> = Vec::new();
    let mut work = vec![section.map_or(start, |s| s.from)];
    let mut worst = Worst::default();
    // Calls to a memory function: (site, callee).
    let mut sized: Vec<(u64, u64)> = Vec::new();
    while let Some(addr) = work.pop() {
        if index.contains_key(&addr) {
            continue;
        }
        if !inside(addr) {
            return Err(format!("control flows out of the function at {addr:#x}"));
        }
        let bytes = image
            .code(addr)
            .ok_or_else(|| format!("no code at {addr:#x}"))?;
        let insn = thumb::decode(bytes, addr)?;
        let next = addr + insn.len;
        let mut cost = insn.cost();
        let mut completes = None;
        // (target, extra cycles of the edge)
        let mut succ: Vec<(u64, u64)> = Vec::new();
        let ends_section = section.is_some_and(|s| match insn.flow {
            Flow::Call(t) => s.release.contains(&t),
            Flow::Return => true,
            _ => insn.opcode() == yaxpeax_arm::armv7::Opcode::CPS(false) || s.joins.contains(&addr),
        });
        // A return inside a section ends it too: the lock was already held (a nested section,
        // whose outer one is bounded from its own start with this call in it), or interrupts
        // were off before it.
        let flow = if ends_section { Flow::Stop } else { insn.flow };
        if ends_section {
            completes = Some(match insn.flow {
                Flow::Call(t) => image.call(t)?.unwrap_or(0),
                _ => 0,
            });
        }
        match flow {
            Flow::Next => succ.push((next, 0)),
            Flow::Branch(t) if inside(t) => succ.push((t, 0)),
            Flow::Branch(t) => {
                worst.callees.insert(t);
                completes = image.call(t)?;
                if completes.is_none() {
                    cost = 0;
                }
            }
            Flow::Conditional(t) if inside(t) => {
                succ.push((next, 0));
                succ.push((t, insn.taken_extra()));
            }
            Flow::Conditional(t) => {
                return Err(format!(
                    "{} at {addr:#x} branches out of the function to {t:#x}",
                    insn.text
                ));
            }
            Flow::Call(t) if inside(t) => {
                // A far branch: BL's reach, LR is dead.
                succ.push((t, 0));
            }
            Flow::Call(t) => {
                worst.callees.insert(t);
                if image.length_register(t).is_some() {
                    // Costed once the graph is whole: the length is a constant before it.
                    sized.push((addr, t));
                    succ.push((next, 0));
                } else if let Some(c) = image.call(t)? {
                    cost = cost.saturating_add(c);
                    succ.push((next, 0));
                }
            }
            Flow::CallRegister(_) => {
                let mut most: Option<u64> = None;
                for t in image.indirect(start, addr)? {
                    worst.callees.insert(t);
                    if let Some(c) = image.call(t)? {
                        most = Some(most.map_or(c, |m| m.max(c)));
                    }
                }
                if let Some(c) = most {
                    cost = cost.saturating_add(c);
                    succ.push((next, 0));
                }
            }
            Flow::Return => completes = Some(0),
            Flow::Jump(r) => {
                if let Some(table) = jump_table(image, &nodes, &index, &insn, r, start, end)? {
                    succ.extend(table.into_iter().map(|t| (t, 0)));
                } else {
                    let mut most: Option<u64> = None;
                    for t in image.indirect(start, addr)? {
                        worst.callees.insert(t);
                        if let Some(c) = image.call(t)? {
                            most = Some(most.map_or(c, |m| m.max(c)));
                        }
                    }
                    completes = most;
                }
            }
            Flow::Wait => {
                return Err(format!(
                    "{} at {addr:#x} waits for an event: no bound",
                    insn.text
                ));
            }
            Flow::Stop => {}
        }
        let i = nodes.len();
        index.insert(addr, i);
        for (t, _) in &succ {
            work.push(*t);
        }
        targets.push((i, succ));
        nodes.push(Node {
            insn,
            cost,
            succ: Vec::new(),
            completes,
        });
    }
    for (i, succ) in targets {
        let edges = succ
            .into_iter()
            .map(|(t, extra)| {
                let j = *index
                    .get(&t)
                    .ok_or_else(|| format!("no instruction at {t:#x}"))?;
                Ok(Edge::To(j, extra))
            })
            .collect::<Result<Vec<_>, String>>()?;
        if let Some(n) = nodes.get_mut(i) {
            n.succ = edges;
        }
    }
    let mut preds: Vec<Vec<usize>> = vec![Vec::new(); nodes.len()];
    for (v, n) in nodes.iter().enumerate() {
        for Edge::To(w, _) in &n.succ {
            if let Some(p) = preds.get_mut(*w) {
                p.push(v);
            }
        }
    }
    for (site, t) in sized {
        let i = *index.get(&site).ok_or("a call vanished")?;
        let r = image
            .length_register(t)
            .ok_or("a memory function vanished")?;
        let n = match constant(&*image, &nodes, &preds, i, r) {
            Some(n) => n,
            None => image.length_at(start, site).map(|(n, _)| n).ok_or_else(|| {
                format!(
                    "the call at {site:#x} passes a length that neither the code before it shows nor an annotation bounds"
                )
            })?,
        };
        let c = image
            .call_with_length(t, n)?
            .ok_or("a memory function never returns")?;
        if let Some(node) = nodes.get_mut(i) {
            node.cost = node.cost.saturating_add(c);
        }
    }
    // A load or store whose base register holds a constant address: the stack's SRAM, or a
    // peripheral; anything else stays unplaced.
    for i in 0..nodes.len() {
        let thumb::Access::Unknown { words, write } = nodes[i].insn.access else {
            continue;
        };
        let Some((base, _, _)) = thumb::address(&nodes[i].insn, 1)
            .or_else(|| thumb::register(&nodes[i].insn, 0).map(|r| (r, None, None)))
        else {
            continue;
        };
        if let Some(at) = constant(&*image, &nodes, &preds, i, base) {
            let placed = thumb::place(at);
            let node = &mut nodes[i];
            node.cost = node
                .cost
                .saturating_sub(node.insn.cost())
                .saturating_add(thumb::cost_at(&node.insn, placed, words, write));
            node.insn.access = placed.access(words, write);
        }
    }
    // Instruction fetch: entering an instruction by a branch, or falling into it.
    let addr_of: Vec<u64> = nodes.iter().map(|n| n.insn.addr).collect();
    let mut branched = vec![false; nodes.len()];
    for (i, n) in nodes.iter().enumerate() {
        for Edge::To(j, _) in &n.succ {
            let falls = addr_of.get(i).map(|a| a + n.insn.len) == addr_of.get(*j).copied();
            if !falls && let Some(b) = branched.get_mut(*j) {
                *b = true;
            }
        }
    }
    if let Some(b) = branched.first_mut() {
        *b = true;
    }
    for n in &nodes {
        let i = &n.insn;
        worst.touched.insert(i.addr);
        worst.touched.insert(i.addr + i.len - 1);
        if let Some((15, Some(k), None)) = thumb::address(i, 1) {
            let word = ((i.addr + 4) & !3) + k;
            worst.touched.extend([word, word + 3]);
        }
        if let Flow::Jump(_) = i.flow {
            // A jump table lies between the dispatch and its first target.
            let first = n
                .succ
                .iter()
                .filter_map(|Edge::To(w, _)| addr_of.get(*w).copied())
                .filter(|t| *t > i.addr)
                .min();
            if let Some(first) = first {
                worst.touched.extend((i.addr..first).step_by(2));
            }
        }
    }
    let unplaced = image.unplaced_load();
    for (n, b) in nodes.iter_mut().zip(branched) {
        n.cost = n.cost.saturating_add(image.fetch(n.insn.addr, b));
        if let thumb::Access::Unknown {
            words,
            write: false,
        } = n.insn.access
        {
            n.cost = n
                .cost
                .saturating_add(unplaced.saturating_mul(u64::from(words)));
        }
    }
    Ok((nodes, worst))
}

/// The value register `r` holds before node `at`, if the code before it, along its one way
/// in, sets it from constants: `MOVS r, #k`, a literal (`LDR r, [PC, #k]`), shifts and
/// additions of immediates, copies.
fn constant(
    image: &dyn Image,
    nodes: &[Node],
    preds: &[Vec<usize>],
    at: usize,
    r: u8,
) -> Option<u64> {
    let mut v = at;
    for _ in 0..24 {
        let [p] = preds.get(v)?.as_slice() else {
            return None;
        };
        v = *p;
        if writes_register(&nodes.get(v)?.insn, r) {
            return written(image, nodes, preds, v, r);
        }
    }
    None
}

/// The value register `r` holds after node `v`.
fn value_after(
    image: &dyn Image,
    nodes: &[Node],
    preds: &[Vec<usize>],
    v: usize,
    r: u8,
) -> Option<u64> {
    if writes_register(&nodes.get(v)?.insn, r) {
        written(image, nodes, preds, v, r)
    } else {
        constant(image, nodes, preds, v, r)
    }
}

/// The constant node `v` writes to register `r`, if it writes one.
fn written(
    image: &dyn Image,
    nodes: &[Node],
    preds: &[Vec<usize>],
    v: usize,
    r: u8,
) -> Option<u64> {
    use yaxpeax_arm::armv7::Opcode;
    let i = &nodes.get(v)?.insn;
    let imm = |k| thumb::immediate(i, k);
    let src = thumb::register(i, 1);
    match i.opcode() {
        Opcode::MOV => match (imm(1), src) {
            (Some(k), _) => Some(k),
            (None, Some(s)) if s < 13 => constant(image, nodes, preds, v, s),
            _ => None,
        },
        Opcode::LSL => {
            let k = imm(2)?;
            let value = constant(image, nodes, preds, v, src?)?;
            value
                .checked_shl(u32::try_from(k).ok()?)
                .filter(|x| *x <= u64::from(u32::MAX))
        }
        Opcode::ADD => match (src, imm(1), imm(2)) {
            (None, Some(k), _) => constant(image, nodes, preds, v, r)?.checked_add(k),
            (Some(s), None, Some(k)) if s < 13 => {
                constant(image, nodes, preds, v, s)?.checked_add(k)
            }
            _ => None,
        },
        Opcode::LDR => match thumb::address(i, 1)? {
            (15, Some(k), None) => {
                let word = ((i.addr + 4) & !3) + k;
                let bytes = image.code(word)?.get(..4)?;
                Some(u64::from(u32::from_le_bytes(bytes.try_into().ok()?)))
            }
            _ => None,
        },
        _ => None,
    }
}

/// The targets of the jump table `insn` (which writes the PC from `r`) dispatches through, if
/// it is one of LLVM's two Thumb-1 patterns; the instructions before it were decoded already
/// (they fall through into it).
fn jump_table(
    image: &dyn Image,
    nodes: &[Node],
    index: &BTreeMap<u64, usize>,
    insn: &Insn,
    r: u8,
    start: u64,
    end: u64,
) -> Result<Option<Vec<u64>>, String> {
    use yaxpeax_arm::armv7::Opcode;
    // The up to six instructions before, in memory order.
    let before: Vec<&Insn> = (1..=6u64)
        .filter_map(|k| index.get(&insn.addr.checked_sub(2 * k)?))
        .filter_map(|i| nodes.get(*i).map(|n| &n.insn))
        .collect();
    let writes = |i: &Insn, reg: u8| thumb::register(i, 0) == Some(reg);
    let Some(load) = before.iter().find(|i| writes(i, r)) else {
        return Ok(None);
    };
    match (insn.opcode(), load.opcode()) {
        // Offsets: `ADD PC, rX` after `LSLS rX, rX, #1` after `LDRB`/`LDRH rX, [rT, #k]`.
        (Opcode::ADD, Opcode::LSL) => {
            let Some(entry) = before.iter().find(|i| {
                i.addr < load.addr
                    && writes(i, r)
                    && matches!(i.opcode(), Opcode::LDRB | Opcode::LDRH)
            }) else {
                return Ok(None);
            };
            let size = if entry.opcode() == Opcode::LDRB { 1 } else { 2 };
            let table = match thumb::address(entry, 1) {
                // `ADD rT, PC; LDRH rX, [rT, #k]`: rT = index + (the ADD's address + 4).
                Some((t, Some(k), None)) => {
                    let Some(add_pc) = before.iter().find(|i| {
                        i.addr < entry.addr
                            && i.opcode() == Opcode::ADD
                            && writes(i, t)
                            && thumb::register(i, 1) == Some(15)
                    }) else {
                        return Ok(None);
                    };
                    add_pc.addr + 4 + k
                }
                // `ADR rT, table; LDRH rX, [rT, rI]`.
                Some((t, None, Some(_))) => {
                    let Some(adr) = before
                        .iter()
                        .find(|i| i.addr < entry.addr && writes(i, t) && adr_target(i).is_some())
                        .and_then(|i| adr_target(i))
                    else {
                        return Ok(None);
                    };
                    adr
                }
                _ => return Ok(None),
            };
            let base = insn.addr + 4;
            let mut out = Vec::new();
            let mut first_target = end;
            let mut at = table;
            // The table ends where the code it jumps to begins.
            while at + size <= first_target {
                let bytes = image
                    .code(at)
                    .and_then(|b| b.get(..size as usize))
                    .ok_or_else(|| format!("the jump table at {table:#x} leaves the code"))?;
                let value = bytes
                    .iter()
                    .rev()
                    .fold(0u64, |v, b| (v << 8) | u64::from(*b));
                let target = base + 2 * value;
                if target < at + size || target >= end {
                    break;
                }
                first_target = first_target.min(target);
                out.push(target);
                at += size;
            }
            Ok((!out.is_empty()).then_some(out))
        }
        // Addresses: `MOV PC, rY` after `LDR rY, [rT, rI]` after `ADR rT, table`.
        (Opcode::MOV, Opcode::LDR) => {
            let Some((t, None, Some(_))) = thumb::address(load, 1) else {
                return Ok(None);
            };
            let Some(adr) = before
                .iter()
                .find(|i| i.addr < load.addr && writes(i, t) && adr_target(i).is_some())
            else {
                return Ok(None);
            };
            let Some(table) = adr_target(adr) else {
                return Ok(None);
            };
            let mut out = Vec::new();
            let mut at = table;
            while let Some(w) = image.word(at) {
                let target = w & !1;
                if w & 1 == 0 || !(start..end).contains(&target) {
                    break;
                }
                out.push(target);
                at += 4;
            }
            Ok((!out.is_empty()).then_some(out))
        }
        _ => Ok(None),
    }
}

/// The address `ADR rD, label` (or `ADD rD, PC, #k`) makes.
fn adr_target(insn: &Insn) -> Option<u64> {
    use yaxpeax_arm::armv7::Opcode;
    let pc_word = (insn.addr + 4) & !3;
    match insn.opcode() {
        Opcode::ADR => thumb::immediate(insn, 1).map(|k| pc_word + k),
        Opcode::ADD if thumb::register(insn, 1) == Some(15) => {
            thumb::immediate(insn, 2).map(|k| pc_word + k)
        }
        _ => None,
    }
}

/// Immediate dominators (Cooper, Harvey and Kennedy's iteration over reverse postorder).
fn dominators(nodes: &[Node]) -> (Vec<usize>, Vec<usize>) {
    let n = nodes.len();
    let mut order = Vec::with_capacity(n);
    let mut seen = vec![false; n];
    // Iterative DFS for postorder.
    let mut stack: Vec<(usize, usize)> = vec![(0, 0)];
    if let Some(s) = seen.first_mut() {
        *s = true;
    }
    while let Some((v, k)) = stack.pop() {
        let succ = nodes.get(v).map_or(&[][..], |n| &n.succ[..]);
        if let Some(Edge::To(w, _)) = succ.get(k) {
            stack.push((v, k + 1));
            if !seen.get(*w).copied().unwrap_or(true) {
                seen[*w] = true;
                stack.push((*w, 0));
            }
        } else {
            order.push(v);
        }
    }
    let mut rpo_index = vec![usize::MAX; n];
    for (i, v) in order.iter().rev().enumerate() {
        rpo_index[*v] = i;
    }
    let mut preds: Vec<Vec<usize>> = vec![Vec::new(); n];
    for (v, node) in nodes.iter().enumerate() {
        for Edge::To(w, _) in &node.succ {
            preds[*w].push(v);
        }
    }
    let mut idom = vec![usize::MAX; n];
    idom[0] = 0;
    let mut changed = true;
    while changed {
        changed = false;
        for &v in order.iter().rev().skip(1) {
            let mut new = usize::MAX;
            for &p in &preds[v] {
                if idom[p] == usize::MAX {
                    continue;
                }
                new = if new == usize::MAX {
                    p
                } else {
                    intersect(&idom, &rpo_index, p, new)
                };
            }
            if new != usize::MAX && idom[v] != new {
                idom[v] = new;
                changed = true;
            }
        }
    }
    (idom, rpo_index)
}

fn intersect(idom: &[usize], rpo: &[usize], mut a: usize, mut b: usize) -> usize {
    while a != b {
        while rpo[a] > rpo[b] {
            a = idom[a];
        }
        while rpo[b] > rpo[a] {
            b = idom[b];
        }
    }
    a
}

fn dominates(idom: &[usize], a: usize, mut b: usize) -> bool {
    loop {
        if a == b {
            return true;
        }
        if b == 0 || idom[b] == usize::MAX {
            return false;
        }
        b = idom[b];
    }
}

/// A loop's summary once collapsed: cycles from entering its header to leaving by each exit
/// edge (target node), or to completing the function from inside it.
#[derive(Clone, Debug, Default)]
struct Summary {
    exits: Vec<(usize, u64)>,
    completes: Option<u64>,
}

/// Longest paths in the region `members` from `entries`, with inner loops already collapsed
/// into `item` (node -> the loop standing for it). An edge back to an entry ends an
/// iteration. Returns (longest iteration, exits and completion). `top`: the function's own
/// region, whose entry may itself stand for a loop.
fn region(
    nodes: &[Node],
    entries: &[usize],
    members: &[bool],
    item: &[Option<usize>],
    summaries: &BTreeMap<usize, Summary>,
    top: bool,
) -> Result<(Option<u64>, Summary), String> {
    let is_entry = |v: usize| !top && entries.contains(&v);
    // The item a node belongs to: its collapsed loop, or itself.
    let rep = |v: usize| -> usize {
        if is_entry(v) {
            v
        } else {
            item.get(v).copied().flatten().map_or(v, |l| LOOP + l)
        }
    };
    // Out-edges of an item: (to, cycles from the item's start), and its completion.
    let out = |r: usize| -> (Vec<(usize, u64)>, Option<u64>) {
        if let Some(l) = r.checked_sub(LOOP) {
            return summaries
                .get(&l)
                .map_or((Vec::new(), None), |s| (s.exits.clone(), s.completes));
        }
        let Some(node) = nodes.get(r) else {
            return (Vec::new(), None);
        };
        let edges = node
            .succ
            .iter()
            .map(|Edge::To(w, extra)| (*w, node.cost.saturating_add(*extra)))
            .collect();
        (edges, node.completes.map(|c| node.cost.saturating_add(c)))
    };
    let inside = |v: usize| members.get(v).copied().unwrap_or(false);
    let starts: Vec<usize> = entries.iter().map(|e| rep(*e)).collect();
    // Items reachable from the entries, and in-degrees (edges back to an entry aside).
    let mut indeg: BTreeMap<usize, usize> = starts.iter().map(|s| (*s, 0)).collect();
    let mut stack = starts.clone();
    let mut seen: BTreeSet<usize> = starts.iter().copied().collect();
    while let Some(v) = stack.pop() {
        for (w, _) in out(v).0 {
            if !inside(w) || is_entry(w) {
                continue;
            }
            let r = rep(w);
            *indeg.entry(r).or_insert(0) += 1;
            if seen.insert(r) {
                stack.push(r);
            }
        }
    }
    let mut dist: BTreeMap<usize, u64> = starts.iter().map(|s| (*s, 0)).collect();
    let mut ready: Vec<usize> = starts
        .iter()
        .copied()
        .filter(|s| indeg.get(s) == Some(&0))
        .collect();
    ready.dedup();
    let (mut back, mut summary) = (None::<u64>, Summary::default());
    let mut done = 0usize;
    while let Some(v) = ready.pop() {
        done += 1;
        let d = dist.get(&v).copied().unwrap_or(0);
        let (edges, completes) = out(v);
        if let Some(c) = completes {
            let c = d.saturating_add(c);
            summary.completes = Some(summary.completes.map_or(c, |m| m.max(c)));
        }
        for (w, c) in edges {
            let c = d.saturating_add(c);
            if is_entry(w) {
                back = Some(back.map_or(c, |b| b.max(c)));
            } else if !inside(w) {
                summary.exits.push((w, c));
            } else {
                let r = rep(w);
                let e = dist.entry(r).or_insert(0);
                *e = (*e).max(c);
                let k = indeg.get_mut(&r).ok_or("an item without in-degree")?;
                *k -= 1;
                if *k == 0 {
                    ready.push(r);
                }
            }
        }
    }
    if done != seen.len() {
        return Err("a cycle left inside a loop's iteration".to_owned());
    }
    Ok((back, summary))
}

/// Items standing for a loop are numbered from here (nodes below).
const LOOP: usize = usize::MAX / 2;

/// Strongly connected components of the nodes in `set`, edges into `cut` left out: those
/// with a cycle (more than one node, or a node with an edge to itself).
fn cycles(nodes: &[Node], set: &[usize], cut: &[usize]) -> Vec<Vec<usize>> {
    let n = nodes.len();
    let mut member = vec![false; n];
    for v in set {
        member[*v] = true;
    }
    let succ = |v: usize| -> Vec<usize> {
        nodes[v]
            .succ
            .iter()
            .map(|Edge::To(w, _)| *w)
            .filter(|w| member[*w] && !cut.contains(w))
            .collect()
    };
    // Tarjan's algorithm, iterative.
    let (mut index, mut low, mut on) = (vec![usize::MAX; n], vec![0; n], vec![false; n]);
    let (mut counter, mut stack, mut out) = (0usize, Vec::new(), Vec::new());
    for &root in set {
        if index[root] != usize::MAX {
            continue;
        }
        let mut call: Vec<(usize, Vec<usize>, usize)> = vec![(root, succ(root), 0)];
        index[root] = counter;
        low[root] = counter;
        counter += 1;
        stack.push(root);
        on[root] = true;
        while let Some((v, ws, k)) = call.last_mut() {
            let v = *v;
            if let Some(&w) = ws.get(*k) {
                *k += 1;
                if index[w] == usize::MAX {
                    index[w] = counter;
                    low[w] = counter;
                    counter += 1;
                    stack.push(w);
                    on[w] = true;
                    call.push((w, succ(w), 0));
                } else if on[w] {
                    low[v] = low[v].min(index[w]);
                }
                continue;
            }
            call.pop();
            if let Some((p, ..)) = call.last() {
                low[*p] = low[*p].min(low[v]);
            }
            if low[v] == index[v] {
                let mut scc = Vec::new();
                while let Some(w) = stack.pop() {
                    on[w] = false;
                    scc.push(w);
                    if w == v {
                        break;
                    }
                }
                let cyclic = scc.len() > 1 || succ(v).contains(&v);
                if cyclic {
                    scc.sort_unstable();
                    out.push(scc);
                }
            }
        }
    }
    out
}

/// What the loop analysis carries while it descends.
struct Loops<'g> {
    nodes: &'g [Node],
    preds: Vec<Vec<usize>>,
    idom: Vec<usize>,
    item: Vec<Option<usize>>,
    summaries: BTreeMap<usize, Summary>,
    found: Vec<Loop>,
}

impl Loops<'_> {
    /// Collapses every loop in `set` (edges into `cut`, the enclosing loop's entries, left
    /// out), innermost first.
    fn collapse(
        &mut self,
        image: &mut dyn Image,
        start: u64,
        set: &[usize],
        cut: &[usize],
    ) -> Result<(), String> {
        for scc in cycles(self.nodes, set, cut) {
            let mut inside = vec![false; self.nodes.len()];
            for v in &scc {
                inside[*v] = true;
            }
            // Its entries: the function's entry, or nodes entered from outside it.
            let entries: Vec<usize> = scc
                .iter()
                .copied()
                .filter(|v| *v == 0 || self.preds[*v].iter().any(|p| !inside[*p]))
                .collect();
            self.collapse(image, start, &scc, &entries)?;
            let latches: Vec<usize> = scc
                .iter()
                .copied()
                .filter(|v| {
                    self.nodes[*v]
                        .succ
                        .iter()
                        .any(|Edge::To(w, _)| entries.contains(w))
                })
                .collect();
            let latch_addrs: Vec<u64> = latches.iter().map(|l| self.nodes[*l].insn.addr).collect();
            let header = entries.first().map_or(0, |e| self.nodes[*e].insn.addr);
            let site = Site {
                header,
                latches: latch_addrs.clone(),
                body: scc.iter().map(|v| self.nodes[*v].insn.addr).collect(),
            };
            let counted = match entries.as_slice() {
                [h] => counted(&*image, self, *h, &inside, &latches),
                _ => None,
            };
            let (bound, source) = match counted {
                Some(b) => (b, "auto".to_owned()),
                // An annotation counts rounds of the loop as written; a round passes each of
                // the machine loop's entries (an `await`'s resume points) at most once, each
                // a back edge.
                None => match image.annotation(start, &site) {
                    Some((rounds, why)) => {
                        (rounds.saturating_mul(entries.len().max(1) as u64), why)
                    }
                    None => (image.unbounded(start, &site)?, "unbounded".to_owned()),
                },
            };
            let (iteration, exits) = region(
                self.nodes,
                &entries,
                &inside,
                &self.item,
                &self.summaries,
                false,
            )
            .map_err(|e| format!("the loop at {header:#x}: {e}"))?;
            let per = iteration.unwrap_or(0).saturating_mul(bound);
            let id = scc.first().copied().unwrap_or(0);
            self.summaries.insert(
                id,
                Summary {
                    exits: exits
                        .exits
                        .into_iter()
                        .map(|(w, c)| (w, c.saturating_add(per)))
                        .collect(),
                    completes: exits.completes.map(|c| c.saturating_add(per)),
                },
            );
            for v in &scc {
                self.item[*v] = Some(id);
            }
            let entry_addrs: Vec<u64> = entries.iter().map(|e| self.nodes[*e].insn.addr).collect();
            let returns = latches
                .iter()
                .map(|l| &self.nodes[*l].insn)
                .filter(|i| matches!(i.flow, Flow::Call(_) | Flow::CallRegister(_)))
                .map(|i| i.addr + i.len)
                .filter(|r| entry_addrs.contains(r))
                .collect();
            self.found.push(Loop {
                header,
                latches: latch_addrs,
                bound,
                source,
                iteration: iteration.unwrap_or(0),
                body: site.body,
                entries: entry_addrs,
                returns,
            });
        }
        Ok(())
    }
}

/// The worst case of the function at `start..end`.
pub fn analyse(image: &mut dyn Image, start: u64, end: u64) -> Result<Worst, String> {
    analyse_from(image, start, end, None)
}

/// The worst case of the function at `start..end`, or of one of its critical sections.
pub fn analyse_from(
    image: &mut dyn Image,
    start: u64,
    end: u64,
    section: Option<Section<'_>>,
) -> Result<Worst, String> {
    let (nodes, mut worst) = graph(image, start, end, section)?;
    let (idom, _) = dominators(&nodes);
    let mut preds: Vec<Vec<usize>> = vec![Vec::new(); nodes.len()];
    for (v, node) in nodes.iter().enumerate() {
        for Edge::To(w, _) in &node.succ {
            preds[*w].push(v);
        }
    }
    let mut loops = Loops {
        nodes: &nodes,
        preds,
        idom,
        item: vec![None; nodes.len()],
        summaries: BTreeMap::new(),
        found: Vec::new(),
    };
    let all: Vec<usize> = (0..nodes.len()).collect();
    loops.collapse(image, start, &all, &[])?;
    let members = vec![true; nodes.len()];
    let (_, whole) = region(&nodes, &[0], &members, &loops.item, &loops.summaries, true)?;
    worst.cycles = whole.completes;
    worst.loops = loops.found;
    worst.loops.sort_by_key(|l| l.header);
    Ok(worst)
}

/// A loop that counts to a constant: a register set to a constant before the loop, moved by a
/// constant step once on every iteration (the step dominates every back edge and sits in no
/// inner loop), and compared with a constant where the loop leaves (its one exit). Returns a
/// bound on its back edges per entry: the steps from the start to the limit, plus one (the
/// exit may test before or after the step).
fn counted(
    image: &dyn Image,
    loops: &Loops<'_>,
    h: usize,
    body: &[bool],
    latches: &[usize],
) -> Option<u64> {
    let (nodes, preds, idom, item) = (loops.nodes, &loops.preds, &loops.idom, &loops.item);
    let inside = |v: usize| body.get(v).copied().unwrap_or(false);
    // An exit that tests the counter on every iteration (it dominates every back edge);
    // other exits only leave sooner.
    let exits: Vec<usize> = (0..nodes.len())
        .filter(|v| inside(*v))
        .filter(|v| nodes[*v].succ.iter().any(|Edge::To(w, _)| !inside(*w)))
        .filter(|v| latches.iter().all(|l| dominates(idom, *v, *l)))
        .collect();
    exits
        .iter()
        .filter_map(|exit| {
            counted_exit(image, nodes, h, *exit, body, preds, idom, item, latches)
                .or_else(|| set_bits_exit(nodes, *exit, body, preds, idom, latches))
        })
        .min()
}

/// How a counted loop's counter relates to its limit while the loop goes on.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Goes {
    /// `counter != limit`
    Ne,
    /// `counter < limit`
    Lt,
    /// `counter <= limit`
    Le,
}

/// The bound [`counted`] finds for the loop's exit at node `exit`.
#[allow(clippy::too_many_arguments)]
fn counted_exit(
    image: &dyn Image,
    nodes: &[Node],
    h: usize,
    exit: usize,
    body: &[bool],
    preds: &[Vec<usize>],
    idom: &[usize],
    item: &[Option<usize>],
    latches: &[usize],
) -> Option<u64> {
    use yaxpeax_arm::armv7::{ConditionCode as C, Opcode};
    let inside = |v: usize| body.get(v).copied().unwrap_or(false);
    let branch = &nodes[exit].insn;
    let Flow::Conditional(target) = branch.flow else {
        return None;
    };
    // The condition under which the loop goes on: the branch's, when it branches back in.
    let stays = nodes[exit]
        .succ
        .iter()
        .any(|Edge::To(w, _)| nodes[*w].insn.addr == target && inside(*w));
    let negate = |c: C| match c {
        C::EQ => C::NE,
        C::NE => C::EQ,
        C::HS => C::LO,
        C::LO => C::HS,
        C::HI => C::LS,
        C::LS => C::HI,
        C::GE => C::LT,
        C::LT => C::GE,
        C::GT => C::LE,
        C::LE => C::GT,
        other => other,
    };
    let goes_on = if stays {
        branch.inner.condition
    } else {
        negate(branch.inner.condition)
    };
    // The compare just before the branch: `CMP` of the counter and its limit (either way
    // round), or `SUBS r, #s` (counts down to zero).
    let c = preds[exit]
        .iter()
        .copied()
        .find(|p| nodes[*p].insn.addr + nodes[*p].insn.len == branch.addr)?;
    let cmp = &nodes[c].insn;
    let [first] = preds[h]
        .iter()
        .copied()
        .filter(|p| !inside(*p))
        .collect::<Vec<_>>()[..]
    else {
        return None;
    };
    let written_inside =
        |r: u8| (0..nodes.len()).any(|u| inside(u) && writes_register(&nodes[u].insn, r));
    // A limit: an immediate, or a register the loop never writes, constant on the way in.
    let invariant = |r: u8| {
        if written_inside(r) {
            None
        } else {
            value_after(image, nodes, preds, first, r)
        }
    };
    // (counter, limit, how it goes on)
    let (reg, limit, goes, down) = match cmp.opcode() {
        Opcode::SUB if cmp.inner.s() && goes_on == C::NE => {
            (thumb::register(cmp, 0)?, 0, Goes::Ne, true)
        }
        Opcode::CMP => {
            if !down_free(goes_on) {
                return None;
            }
            let a = thumb::register(cmp, 0)?;
            let b = thumb::register(cmp, 1);
            // A limit: an immediate, what straight-line code before the compare sets the
            // register to (a constant rebuilt every iteration), or a register the loop never
            // writes that holds a constant on the way in.
            let limit_of = |r: u8| constant(image, nodes, preds, c, r).or_else(|| invariant(r));
            let as_counter = thumb::immediate(cmp, 1)
                .or_else(|| limit_of(b?))
                .and_then(|limit| {
                    let goes = match goes_on {
                        C::NE => Goes::Ne,
                        C::LO | C::LT => Goes::Lt,
                        C::LS | C::LE => Goes::Le,
                        _ => return None,
                    };
                    Some((a, limit, goes, false))
                });
            // Or `CMP limit, counter`.
            let swapped = || {
                let limit = limit_of(a)?;
                let goes = match goes_on {
                    C::NE => Goes::Ne,
                    C::HI | C::GT => Goes::Lt,
                    C::HS | C::GE => Goes::Le,
                    _ => return None,
                };
                Some((b?, limit, goes, false))
            };
            as_counter.or_else(swapped)?
        }
        _ => return None,
    };
    let imm = |i: &Insn| match thumb::register(i, 1) {
        Some(r) if r == reg => thumb::immediate(i, 2),
        Some(_) => None,
        None => thumb::immediate(i, 1),
    };
    // Every write of the counter in the loop: exactly one, the step, on every iteration.
    let writes: Vec<usize> = (0..nodes.len())
        .filter(|v| inside(*v) && writes_register(&nodes[*v].insn, reg))
        .collect();
    let [w] = writes.as_slice() else {
        return None;
    };
    let step_insn = &nodes[*w].insn;
    let every_time = latches.iter().all(|l| dominates(idom, *w, *l))
        && item.get(*w).copied().flatten().is_none();
    let step = match step_insn.opcode() {
        Opcode::SUB if down && *w == c => imm(step_insn)?,
        Opcode::ADD if !down && thumb::register(step_insn, 0) == Some(reg) => imm(step_insn)?,
        _ => return None,
    };
    if !every_time || step == 0 {
        return None;
    }
    let init = value_after(image, nodes, preds, first, reg)?;
    // Counters and limits past 2^31 may compare signed as negative: not counted here.
    if init >= 1 << 31 || limit >= 1 << 31 {
        return None;
    }
    let span = if down { init } else { limit.checked_sub(init)? };
    let iterations = match goes {
        // An equality test the steps jump over never ends.
        Goes::Ne if span == 0 || span % step != 0 => return None,
        Goes::Ne | Goes::Lt => span.div_ceil(step),
        Goes::Le => span / step + 1,
    };
    // Back edges: at most the iterations, and one more where the exit tests before the step.
    Some(iterations + 1)
}

/// Whether the loop's going-on condition is one a counted loop may have.
fn down_free(c: yaxpeax_arm::armv7::ConditionCode) -> bool {
    !matches!(
        c,
        yaxpeax_arm::armv7::ConditionCode::EQ | yaxpeax_arm::armv7::ConditionCode::AL
    )
}

/// [`set_bits`] for the loop's exit at node `exit`: `CMP x, #0` then the branch.
fn set_bits_exit(
    nodes: &[Node],
    exit: usize,
    body: &[bool],
    preds: &[Vec<usize>],
    idom: &[usize],
    latches: &[usize],
) -> Option<u64> {
    use yaxpeax_arm::armv7::Opcode;
    let branch = &nodes[exit].insn;
    let c = preds[exit]
        .iter()
        .copied()
        .find(|p| nodes[*p].insn.addr + nodes[*p].insn.len == branch.addr)?;
    let cmp = &nodes[c].insn;
    if cmp.opcode() != Opcode::CMP || thumb::immediate(cmp, 1) != Some(0) {
        return None;
    }
    let reg = thumb::register(cmp, 0)?;
    let inside = |v: usize| body.get(v).copied().unwrap_or(false);
    set_bits(nodes, reg, &inside, idom, latches)
}

/// A loop over the set bits of a word (`x &= x - 1` until `x == 0`): every write of `x` in the
/// loop clears its lowest set bit, and one runs on every iteration; a word has 32 bits.
fn set_bits(
    nodes: &[Node],
    reg: u8,
    inside: &dyn Fn(usize) -> bool,
    idom: &[usize],
    latches: &[usize],
) -> Option<u64> {
    use yaxpeax_arm::armv7::Opcode;
    let in_loop: Vec<usize> = (0..nodes.len()).filter(|v| inside(*v)).collect();
    // `SUBS rT, x, #1` in the loop: the registers holding `x - 1`.
    let minus_one: Vec<u8> = in_loop
        .iter()
        .map(|v| &nodes[*v].insn)
        .filter(|i| {
            i.opcode() == Opcode::SUB
                && thumb::register(i, 1) == Some(reg)
                && thumb::immediate(i, 2) == Some(1)
        })
        .filter_map(|i| thumb::register(i, 0))
        .collect();
    let writes: Vec<usize> = in_loop
        .iter()
        .copied()
        .filter(|v| writes_register(&nodes[*v].insn, reg))
        .collect();
    let clears = |v: &usize| {
        let i = &nodes[*v].insn;
        i.opcode() == Opcode::AND
            && thumb::register(i, 0) == Some(reg)
            && thumb::register(i, 1).is_some_and(|t| minus_one.contains(&t))
            && thumb::register(i, 2).is_none()
    };
    let every_time = writes
        .iter()
        .any(|w| latches.iter().all(|l| dominates(idom, *w, *l)));
    (!writes.is_empty() && writes.iter().all(clears) && every_time).then_some(32)
}

/// Whether `insn` writes general register `reg` (the destination operand of what the
/// counted-loop pattern needs; anything else that may write it counts as a write).
fn writes_register(insn: &Insn, reg: u8) -> bool {
    use yaxpeax_arm::armv7::Opcode;
    match insn.opcode() {
        Opcode::CMP
        | Opcode::CMN
        | Opcode::TST
        | Opcode::B
        | Opcode::STR
        | Opcode::STRB
        | Opcode::STRH
        | Opcode::PUSH => false,
        Opcode::POP | Opcode::LDM(..) => insn
            .operands()
            .iter()
            .any(|o| matches!(o, yaxpeax_arm::armv7::Operand::RegList(l) if l & (1 << reg) != 0)),
        Opcode::BL | Opcode::BLX => reg <= 3 || reg == 12 || reg == 14,
        _ => thumb::register(insn, 0) == Some(reg),
    }
}

/// The addresses in the function at `start..end` where a critical section begins (calls of
/// one of `acquire`, and `CPSID` instructions: an acquire inlined), and where an inlined
/// release's paths join (after each `CPSIE`).
pub fn section_starts(
    image: &mut dyn Image,
    start: u64,
    end: u64,
    acquire: &[u64],
) -> Result<(Vec<u64>, Vec<u64>), String> {
    let (nodes, _) = graph(image, start, end, None)?;
    let joins: Vec<u64> = nodes
        .iter()
        .map(|n| &n.insn)
        .filter(|i| i.opcode() == yaxpeax_arm::armv7::Opcode::CPS(false))
        .map(|i| i.addr + i.len)
        .collect();
    let mut out: Vec<u64> = nodes
        .iter()
        .map(|n| &n.insn)
        .filter(|i| {
            matches!(i.flow, Flow::Call(t) if acquire.contains(&t))
                || i.opcode() == yaxpeax_arm::armv7::Opcode::CPS(true)
        })
        .map(|i| i.addr)
        .collect();
    out.sort_unstable();
    Ok((out, joins))
}

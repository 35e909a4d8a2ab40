//! One Armv6-M Thumb instruction: decoded by `yaxpeax-arm`, classified by what it does to the
//! control flow, and costed in cycles of the Cortex-M0+.
//!
//! Costs are Table 3-1 of the Cortex-M0+ Technical Reference Manual (Arm DDI 0484C, "Cortex-M0+
//! instruction summary", zero wait states): data processing 1; `MOV PC`/`ADD PC` 2; loads and
//! stores 2; `LDM`/`STM`/`PUSH` 1+N; `POP` 1+N, or 3+N with the PC; `B` 2, a conditional
//! branch 2 taken and 1 not; `BL` 3; `BX`/`BLX` 2; `MRS`/`MSR` 3; `DMB`/`DSB`/`ISB` 3; `MULS`
//! 1 (the RP2040 has the single-cycle multiplier). On the RP2040 an access to an APB
//! peripheral waits on the bridge: a load from an address the analysis cannot place costs
//! [`APB_READ`], a store [`APB_WRITE`].

use yaxpeax_arch::{Decoder, U8Reader};
use yaxpeax_arm::armv7::{InstDecoder, Instruction, Opcode, Operand};

/// A load through the APB bridge, cycles: 2 of the core and 2 of wait (the RP2040's APB runs at
/// the system clock behind an AHB-to-APB bridge; rp2040js charges the same).
pub const APB_READ: u32 = 4;
/// A store through the APB bridge, cycles: 2 of the core and 3 of wait.
pub const APB_WRITE: u32 = 5;

/// The cycles of the instructions whose cost differs between the TRM and rp2040js, the emulator
/// the bench runs: rp2040js charges nothing for `PUSH`'s LR and `POP`'s PC (the TRM's N counts
/// them: one cycle each), so the bench measures a call's return up to 2 cycles short of silicon.
/// The analysis uses [`Table::TRM`]; `cargo xtask wcet --emulated` compares with
/// [`Table::RP2040JS`], where the two must agree cycle for cycle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Table {
    /// `PUSH {.., LR}`'s cycles for the LR.
    pub push_lr: u32,
    /// `POP {.., PC}`'s cycles for the PC's word (the pipeline's refill, 2, comes on top).
    pub pop_pc: u32,
    /// A load's or store's (`LDR`, `STR` and their byte and halfword forms) cycles.
    pub memory: u32,
}

impl Table {
    /// Table 3-1 of the Cortex-M0+ TRM.
    pub const TRM: Self = Self {
        push_lr: 1,
        pop_pc: 1,
        memory: 2,
    };
    /// rp2040js 1.x's `executeInstruction`.
    pub const RP2040JS: Self = Self {
        push_lr: 0,
        pop_pc: 0,
        memory: 2,
    };
}

thread_local! {
    static TABLE: std::cell::Cell<Table> = const { std::cell::Cell::new(Table::TRM) };
}

/// Runs `f` with the instructions costed by `table`.
pub fn with_table<T>(table: Table, f: impl FnOnce() -> T) -> T {
    let old = TABLE.with(|t| t.replace(table));
    let out = f();
    TABLE.with(|t| t.set(old));
    out
}

/// Where a constant address is, for what an access there costs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Region {
    /// SRAM (no wait states) or the single-cycle I/O port (SIO).
    Fast,
    /// A peripheral behind the APB bridge (or the AHB's, charged the same).
    Peripheral,
    /// Anywhere else (flash through the XIP cache, the ROM): left unplaced.
    Other,
}

impl Region {
    /// The access an instruction makes there.
    pub fn access(self, words: u32, write: bool) -> Access {
        match self {
            Region::Fast => Access::Known,
            Region::Peripheral => Access::Peripheral { words, write },
            Region::Other => Access::Unknown { words, write },
        }
    }
}

/// The region of the RP2040's address map `at` falls in (datasheet 2.2).
pub fn place(at: u64) -> Region {
    match at {
        0x2000_0000..0x2004_2000 | 0xd000_0000..0xe000_0000 => Region::Fast,
        0x4000_0000..0x6000_0000 => Region::Peripheral,
        _ => Region::Other,
    }
}

/// What `insn` costs when its access goes to `region`.
pub fn cost_at(insn: &Insn, region: Region, words: u32, write: bool) -> u64 {
    let placed = Insn {
        access: region.access(words, write),
        ..insn.clone()
    };
    placed.cost()
}

/// Where an instruction's data access goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Access {
    /// None.
    None,
    /// The stack (SRAM, no wait states) or a PC-relative literal (the code's own flash lines).
    Known,
    /// A peripheral: the bridge's wait on each of `words` accesses.
    Peripheral { words: u32, write: bool },
    /// Anywhere: SRAM, flash, or a peripheral; `words` accesses, stores if `write`.
    Unknown { words: u32, write: bool },
}

/// What an instruction does to the control flow.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Flow {
    /// Falls through.
    Next,
    /// Always branches (`B`, or a `BL` inside its own function: a far branch).
    Branch(u64),
    /// Branches or falls through.
    Conditional(u64),
    /// Calls the function at this address (`BL`), then falls through.
    Call(u64),
    /// Calls through a register (`BLX rM`), then falls through.
    CallRegister(u8),
    /// Returns (`BX LR`, `POP {.., PC}`).
    Return,
    /// Writes the PC from a register (`MOV PC, rM`, `ADD PC, rM`, `BX rM`): a jump table or a
    /// tail call through a pointer.
    Jump(u8),
    /// Waits for an event or interrupt (`WFI`, `WFE`): for ever, as far as a bound knows.
    Wait,
    /// Faults or halts (`UDF`, `BKPT`, `SVC`): the job does not complete.
    Stop,
}

/// A decoded instruction.
#[derive(Clone, Debug)]
pub struct Insn {
    pub addr: u64,
    pub len: u64,
    /// Cycles when a branch is not taken, or the instruction's only cost.
    pub cycles: u32,
    pub flow: Flow,
    pub access: Access,
    /// What it is, for messages.
    pub text: String,
    pub(crate) inner: Instruction,
}

/// The general register an operand names.
fn reg(op: &Operand) -> Option<u8> {
    match op {
        Operand::Reg(r) | Operand::RegWBack(r, _) => Some(r.number()),
        _ => None,
    }
}

/// The base register of a memory operand.
fn base(op: &Operand) -> Option<u8> {
    match op {
        Operand::RegDeref(r)
        | Operand::RegDerefPreindexOffset(r, ..)
        | Operand::RegDerefPostindexOffset(r, ..)
        | Operand::RegDerefPreindexReg(r, ..)
        | Operand::RegDerefPostindexReg(r, ..)
        | Operand::RegDerefPreindexRegShift(r, ..)
        | Operand::RegDerefPostindexRegShift(r, ..) => Some(r.number()),
        _ => None,
    }
}

const SP: u8 = 13;
const LR: u8 = 14;
const PC: u8 = 15;

/// Decodes the instruction at `addr` from `bytes` (which start there).
pub fn decode(bytes: &[u8], addr: u64) -> Result<Insn, String> {
    let mut inner = Instruction::default();
    let mut reader = U8Reader::new(bytes);
    InstDecoder::default_thumb()
        .decode_into(&mut inner, &mut reader)
        .map_err(|e| format!("cannot decode the instruction at {addr:#x}: {e}"))?;
    let len = if inner.wide() { 4 } else { 2 };
    let ops = inner.operands;
    let [op0, op1, ..] = ops;
    let text = inner.to_string();
    // A branch's target: the PC (the instruction's address + 4) plus the offset in halfwords.
    let target = |op: &Operand| match op {
        Operand::BranchThumbOffset(o) => Some((addr as i64 + 4 + 2 * i64::from(*o)) as u64),
        _ => None,
    };
    let unsupported = || Err(format!("{text} at {addr:#x} is not an Armv6-M instruction"));
    let conditional = inner.condition != yaxpeax_arm::armv7::ConditionCode::AL;
    let count = |list: &Operand| match list {
        Operand::RegList(l) => l.count_ones(),
        _ => 0,
    };
    let with_pc = |list: &Operand| matches!(list, Operand::RegList(l) if l & (1 << PC) != 0);
    let with_lr = |list: &Operand| matches!(list, Operand::RegList(l) if l & (1 << LR) != 0);
    let table = TABLE.with(std::cell::Cell::get);
    let memory = |write: bool, words: u32| match base(&op1) {
        Some(SP | PC) => Access::Known,
        _ => Access::Unknown { words, write },
    };
    let (cycles, flow, access) = match inner.opcode {
        Opcode::B => {
            let mut t = target(&op0).ok_or_else(|| format!("{text} at {addr:#x}: no target"))?;
            if conditional && !inner.wide() {
                // yaxpeax-arm 0.5 gives a 16-bit conditional branch's offset one halfword more
                // than its encoding (checked against objdump, and in the tests).
                t -= 2;
            }
            if conditional {
                (1, Flow::Conditional(t), Access::None)
            } else {
                (2, Flow::Branch(t), Access::None)
            }
        }
        Opcode::BL => {
            let t = target(&op0).ok_or_else(|| format!("{text} at {addr:#x}: no target"))?;
            (3, Flow::Call(t), Access::None)
        }
        Opcode::BLX => match reg(&op0) {
            Some(r) => (2, Flow::CallRegister(r), Access::None),
            None => return unsupported(),
        },
        Opcode::BX => match reg(&op0) {
            Some(LR) => (2, Flow::Return, Access::None),
            Some(r) => (2, Flow::Jump(r), Access::None),
            None => return unsupported(),
        },
        Opcode::MOV | Opcode::ADD if reg(&op0) == Some(PC) => {
            // `MOV PC, rM` and `ADD PC, rM` (the second operand may repeat the PC).
            let from = ops
                .iter()
                .skip(1)
                .filter_map(reg)
                .find(|r| *r != PC)
                .ok_or_else(|| format!("{text} at {addr:#x}: no source register"))?;
            (2, Flow::Jump(from), Access::None)
        }
        Opcode::PUSH if with_lr(&op0) => (count(&op0) + table.push_lr, Flow::Next, Access::Known),
        Opcode::PUSH => (1 + count(&op0), Flow::Next, Access::Known),
        Opcode::POP if with_pc(&op0) => {
            let cycles = 2 + count(&op0) + table.pop_pc;
            (cycles, Flow::Return, Access::Known)
        }
        Opcode::POP => (1 + count(&op0), Flow::Next, Access::Known),
        Opcode::LDM(..) | Opcode::STM(..) => {
            let n = count(&op1);
            let write = matches!(inner.opcode, Opcode::STM(..));
            if !write && with_pc(&op1) {
                return unsupported();
            }
            let access = match reg(&op0) {
                Some(SP) => Access::Known,
                _ => Access::Unknown { words: n, write },
            };
            (1 + n, Flow::Next, access)
        }
        Opcode::LDR | Opcode::LDRB | Opcode::LDRH | Opcode::LDRSB | Opcode::LDRSH => {
            (table.memory, Flow::Next, memory(false, 1))
        }
        Opcode::STR | Opcode::STRB | Opcode::STRH => (table.memory, Flow::Next, memory(true, 1)),
        Opcode::MRS | Opcode::MSR | Opcode::DMB | Opcode::DSB | Opcode::ISB => {
            (3, Flow::Next, Access::None)
        }
        Opcode::WFI | Opcode::WFE => (2, Flow::Wait, Access::None),
        Opcode::UDF | Opcode::BKPT | Opcode::SVC => (1, Flow::Stop, Access::None),
        Opcode::ADC
        | Opcode::ADD
        | Opcode::ADR
        | Opcode::AND
        | Opcode::ASR
        | Opcode::BIC
        | Opcode::CMN
        | Opcode::CMP
        | Opcode::CPS(_)
        | Opcode::EOR
        | Opcode::LSL
        | Opcode::LSR
        | Opcode::MOV
        | Opcode::MUL
        | Opcode::MVN
        | Opcode::NOP
        | Opcode::ORR
        | Opcode::REV
        | Opcode::REV16
        | Opcode::REVSH
        | Opcode::ROR
        | Opcode::RSB
        | Opcode::SBC
        | Opcode::SEV
        | Opcode::SUB
        | Opcode::SXTB
        | Opcode::SXTH
        | Opcode::TST
        | Opcode::UXTB
        | Opcode::UXTH
        | Opcode::YIELD => (1, Flow::Next, Access::None),
        _ => return unsupported(),
    };
    // Armv6-M's only 32-bit instructions are BL, MRS, MSR and the barriers; a conditional
    // instruction other than a branch is Thumb-2.
    let wide_ok = matches!(
        inner.opcode,
        Opcode::BL | Opcode::MRS | Opcode::MSR | Opcode::DMB | Opcode::DSB | Opcode::ISB
    );
    if (inner.wide() && !wide_ok) || (conditional && inner.opcode != Opcode::B) {
        return unsupported();
    }
    Ok(Insn {
        addr,
        len,
        cycles,
        flow,
        access,
        text,
        inner,
    })
}

impl Insn {
    /// Cycles the instruction may take, data waits included, when it does not branch.
    pub fn cost(&self) -> u64 {
        let wait = match self.access {
            Access::Unknown { words, write } | Access::Peripheral { words, write } => {
                let per = if write { APB_WRITE } else { APB_READ } - 2;
                per * words
            }
            _ => 0,
        };
        u64::from(self.cycles + wait)
    }

    /// Cycles a taken conditional branch adds.
    pub fn taken_extra(&self) -> u64 {
        u64::from(matches!(self.flow, Flow::Conditional(_)))
    }

    /// `(destination, source)` registers of a register move or an addition of the PC
    /// (`ADD rD, PC` / `ADR`): what the jump-table patterns look for.
    pub fn opcode(&self) -> Opcode {
        self.inner.opcode
    }

    /// The operands.
    pub fn operands(&self) -> &[Operand; 4] {
        &self.inner.operands
    }
}

/// The general register operand `i` names.
pub fn register(insn: &Insn, i: usize) -> Option<u8> {
    insn.inner.operands.get(i).and_then(reg)
}

/// The base register and immediate offset of a memory operand `[rN, #k]`, or `[rN, rM]` as
/// `(rN, None, Some(rM))`.
pub fn address(insn: &Insn, i: usize) -> Option<(u8, Option<u64>, Option<u8>)> {
    match insn.inner.operands.get(i)? {
        Operand::RegDeref(r) => Some((r.number(), Some(0), None)),
        Operand::RegDerefPreindexOffset(r, k, true, false) => {
            Some((r.number(), Some(u64::from(*k)), None))
        }
        Operand::RegDerefPreindexReg(r, m, true, false) => {
            Some((r.number(), None, Some(m.number())))
        }
        _ => None,
    }
}

/// The immediate operand `i`.
pub fn immediate(insn: &Insn, i: usize) -> Option<u64> {
    match insn.inner.operands.get(i)? {
        Operand::Imm32(k) => Some(u64::from(*k)),
        Operand::Imm12(k) => Some(u64::from(*k)),
        _ => None,
    }
}

//! Model programs: the maps a nonlinear plant's controller evaluates on the target (the coordinates ξ(x),
//! κ(x) and λ(x) of the feedback law (3.17) for §3.1.2, the flat maps of §3.1.3), as a compact stack
//! bytecode evaluated in `f32` with `libm` and [`crate::trig`] (DESIGN §5 "model programs"; issue 13).
//!
//! [`Program::decode`] validates every byte before anything runs: the length against
//! [`MAX_PROGRAM_LEN`], the counts against their capacities, every constant finite, every opcode known,
//! every slot, constant, register and output index in range (a register read only after a write), and
//! the stack depth by one forward pass (no underflow,
//! never beyond [`MAX_PROGRAM_STACK`], equal to the depth the header stores, empty at the end), and that
//! every output is stored exactly once. A decoded program then evaluates with a fixed `[f32;
//! MAX_PROGRAM_STACK]` stack in one pass over at most [`MAX_PROGRAM_LEN`] bytes of code, so its cost is
//! bounded by its length. Nothing here panics or allocates.
//!
//! # Byte layout (little endian; one image section's body, so it can become a section kind unchanged)
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 1 | `n_inputs`: input slots the program reads, `0..=MAX_PROGRAM_INPUTS` |
//! | 1 | 1 | `n_outputs`: outputs it stores, `1..=MAX_PROGRAM_OUTPUTS` |
//! | 2 | 2 | `n_consts`: `f32` constants in the pool, `0..=MAX_PROGRAM_CONSTS` |
//! | 4 | 2 | `code_len`: bytes of code |
//! | 6 | 1 | `max_stack`: the stack depth the code reaches (re-derived and compared at decode) |
//! | 7 | 1 | reserved, 0 |
//! | 8 | 4·`n_consts` | the constant pool, `f32` each (4-byte aligned relative to the body) |
//! | 8 + 4·`n_consts` | `code_len` | the code |
//!
//! The body is exactly `8 + 4·n_consts + code_len` bytes. Instructions (one opcode byte, then its operand):
//!
//! | opcode | operand | effect |
//! |---|---|---|
//! | `0x01` LOAD | slot `u8` | push `inputs[slot]` |
//! | `0x02` CONST | index `u16` | push `consts[index]` |
//! | `0x03` STORE | output `u8` | pop into `out[output]` |
//! | `0x04` TEE | register `u8` | copy the top into `regs[register]` (the top stays) |
//! | `0x05` RECALL | register `u8` | push `regs[register]`; a register no earlier `TEE` wrote is refused |
//! | `0x10`–`0x13` ADD SUB MUL DIV | — | pop `b`, pop `a`, push `a ∘ b` |
//! | `0x14` NEG | — | negate the top |
//! | `0x15` POWI | exponent `i8`, `1 ≤ |k| ≤ MAX_PROGRAM_POWI` | `x^|k|` by `|k| − 1` multiplications left to right, then `1 / ·` if `k < 0` |
//! | `0x20`–`0x28` SIN COS TAN EXP LOG SQRT ABS ATAN TANH | — | replace the top by its `f32` function: sine and cosine [`crate::trig::sincos`], the others `libm`'s |
//! | `0x29` ATAN2 | — | pop `x`, pop `y`, push `atan2(y, x)` |
//!
//! An image carries programs in its model maps section ([`crate::maps`]), which declares their slots.

use crate::capacity::{
    MAX_PROGRAM_CONSTS, MAX_PROGRAM_INPUTS, MAX_PROGRAM_LEN, MAX_PROGRAM_OUTPUTS, MAX_PROGRAM_POWI,
    MAX_PROGRAM_REGS, MAX_PROGRAM_STACK,
};
use crate::error::{Dim, Field, ImageError, Pos};
use crate::raw::{check_dim, check_finite, f32_at, sat16, sat32, u16_at};

// The interpreter masks stack indices with the capacity ([`Program::eval`]).
const _: () = assert!(MAX_PROGRAM_STACK.is_power_of_two());
// And register indices alike; the decoder's bit set of written registers is a `u32`.
const _: () = assert!(MAX_PROGRAM_REGS.is_power_of_two() && MAX_PROGRAM_REGS <= 32);

/// Bytes of a program's header.
pub const PROGRAM_HEADER_LEN: usize = 8;

/// The opcode bytes.
pub mod opcode {
    /// Push an input slot.
    pub const LOAD: u8 = 0x01;
    /// Push a pool constant.
    pub const CONST: u8 = 0x02;
    /// Pop into an output.
    pub const STORE: u8 = 0x03;
    /// Copy the top into a register.
    pub const TEE: u8 = 0x04;
    /// Push a register.
    pub const RECALL: u8 = 0x05;
    /// `a + b`.
    pub const ADD: u8 = 0x10;
    /// `a − b`.
    pub const SUB: u8 = 0x11;
    /// `a · b`.
    pub const MUL: u8 = 0x12;
    /// `a / b`.
    pub const DIV: u8 = 0x13;
    /// `−a`.
    pub const NEG: u8 = 0x14;
    /// `a^k` for an integer `k`.
    pub const POWI: u8 = 0x15;
    /// First of the unary functions, in [`super::Func`] order.
    pub const FUNC0: u8 = 0x20;
    /// `atan2(y, x)`.
    pub const ATAN2: u8 = 0x29;
}

/// The unary functions a program evaluates: sine and cosine by [`crate::trig`], the others by `libm`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Func {
    /// Sine ([`crate::trig::sincos`]).
    Sin,
    /// Cosine ([`crate::trig::sincos`]).
    Cos,
    /// `tanf`.
    Tan,
    /// `expf`.
    Exp,
    /// `logf` (natural logarithm).
    Log,
    /// `sqrtf` (correctly rounded, IEEE 754).
    Sqrt,
    /// `fabsf` (exact).
    Abs,
    /// `atanf`.
    Atan,
    /// `tanhf`.
    Tanh,
}

impl Func {
    /// Every function, in opcode order (`opcode::FUNC0 + i`).
    pub const ALL: [Func; 9] = [
        Func::Sin,
        Func::Cos,
        Func::Tan,
        Func::Exp,
        Func::Log,
        Func::Sqrt,
        Func::Abs,
        Func::Atan,
        Func::Tanh,
    ];

    /// Its opcode byte.
    pub const fn opcode(self) -> u8 {
        opcode::FUNC0 + self as u8
    }

    /// Its name in expressions.
    pub const fn name(self) -> &'static str {
        match self {
            Func::Sin => "sin",
            Func::Cos => "cos",
            Func::Tan => "tan",
            Func::Exp => "exp",
            Func::Log => "log",
            Func::Sqrt => "sqrt",
            Func::Abs => "abs",
            Func::Atan => "atan",
            Func::Tanh => "tanh",
        }
    }

    /// The `f32` value the target computes.
    #[inline]
    pub fn apply(self, x: f32) -> f32 {
        match self {
            Func::Sin => crate::trig::sincos(x).0,
            Func::Cos => crate::trig::sincos(x).1,
            Func::Tan => libm::tanf(x),
            Func::Exp => libm::expf(x),
            Func::Log => libm::logf(x),
            Func::Sqrt => libm::sqrtf(x),
            Func::Abs => libm::fabsf(x),
            Func::Atan => libm::atanf(x),
            Func::Tanh => libm::tanhf(x),
        }
    }
}

/// One decoded instruction.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Op {
    /// Push input slot `i`.
    Load(u8),
    /// Push constant `i` of the pool.
    Const(u16),
    /// Pop into output `i`.
    Store(u8),
    /// Copy the top into register `i` (the top stays).
    Tee(u8),
    /// Push register `i`.
    Recall(u8),
    /// Pop `b`, pop `a`, push `a + b`.
    Add,
    /// Pop `b`, pop `a`, push `a − b`.
    Sub,
    /// Pop `b`, pop `a`, push `a · b`.
    Mul,
    /// Pop `b`, pop `a`, push `a / b`.
    Div,
    /// Negate the top.
    Neg,
    /// Replace the top `x` by `x^k` ([`powi`]).
    Powi(i8),
    /// Replace the top by a function of it.
    Func(Func),
    /// Pop `x`, pop `y`, push `atan2(y, x)`.
    Atan2,
}

impl Op {
    /// Values popped and pushed.
    pub const fn arity(self) -> (usize, usize) {
        match self {
            Op::Load(_) | Op::Const(_) | Op::Recall(_) => (0, 1),
            Op::Store(_) => (1, 0),
            Op::Tee(_) => (1, 1),
            Op::Add | Op::Sub | Op::Mul | Op::Div | Op::Atan2 => (2, 1),
            Op::Neg | Op::Powi(_) | Op::Func(_) => (1, 1),
        }
    }

    /// Its bytes: the first `len` of the array.
    pub const fn encode(self) -> ([u8; 3], usize) {
        match self {
            Op::Load(i) => ([opcode::LOAD, i, 0], 2),
            Op::Const(i) => {
                let b = i.to_le_bytes();
                ([opcode::CONST, b[0], b[1]], 3)
            }
            Op::Store(i) => ([opcode::STORE, i, 0], 2),
            Op::Tee(i) => ([opcode::TEE, i, 0], 2),
            Op::Recall(i) => ([opcode::RECALL, i, 0], 2),
            Op::Add => ([opcode::ADD, 0, 0], 1),
            Op::Sub => ([opcode::SUB, 0, 0], 1),
            Op::Mul => ([opcode::MUL, 0, 0], 1),
            Op::Div => ([opcode::DIV, 0, 0], 1),
            Op::Neg => ([opcode::NEG, 0, 0], 1),
            Op::Powi(k) => ([opcode::POWI, k as u8, 0], 2),
            Op::Func(f) => ([f.opcode(), 0, 0], 1),
            Op::Atan2 => ([opcode::ATAN2, 0, 0], 1),
        }
    }
}

/// `x^k` as the target computes it: `|k| − 1` multiplications left to right (`((x·x)·x)·…`), then one
/// division `1 / ·` for `k < 0`; `k = 0` gives 1 (the decoder refuses it in code). The rounding analysis
/// on the host follows exactly these operations.
#[inline]
pub fn powi(x: f32, k: i8) -> f32 {
    if k == 0 {
        return 1.0;
    }
    let n = k.unsigned_abs();
    let mut acc = x;
    let mut i = 1u8;
    while i < n {
        acc *= x;
        i += 1;
    }
    if k < 0 {
        1.0 / acc
    } else {
        acc
    }
}

/// The instruction at `offset` of `code` and its length in bytes. Checks the opcode, that the operand is
/// present, and the exponent range; index ranges are checked by [`Program::decode`].
fn decode_op(code: &[u8], offset: usize) -> Result<(Op, usize), ImageError> {
    let at = sat16(offset);
    let operand = |k: usize| code.get(offset.saturating_add(k)).copied();
    let Some(byte) = operand(0) else {
        return Err(ImageError::ProgramOperand { offset: at });
    };
    let bad = ImageError::ProgramOperand { offset: at };
    let op = match byte {
        opcode::LOAD => (Op::Load(operand(1).ok_or(bad)?), 2),
        opcode::STORE => (Op::Store(operand(1).ok_or(bad)?), 2),
        opcode::TEE => (Op::Tee(operand(1).ok_or(bad)?), 2),
        opcode::RECALL => (Op::Recall(operand(1).ok_or(bad)?), 2),
        opcode::CONST => {
            if operand(2).is_none() {
                return Err(bad);
            }
            (Op::Const(u16_at(code, offset.saturating_add(1))), 3)
        }
        opcode::ADD => (Op::Add, 1),
        opcode::SUB => (Op::Sub, 1),
        opcode::MUL => (Op::Mul, 1),
        opcode::DIV => (Op::Div, 1),
        opcode::NEG => (Op::Neg, 1),
        opcode::POWI => {
            let k = operand(1).ok_or(bad)? as i8;
            if k == 0 || k.unsigned_abs() > MAX_PROGRAM_POWI.unsigned_abs() {
                return Err(bad);
            }
            (Op::Powi(k), 2)
        }
        opcode::ATAN2 => (Op::Atan2, 1),
        b => {
            let i = b.wrapping_sub(opcode::FUNC0) as usize;
            match Func::ALL.get(i) {
                Some(&f) if b >= opcode::FUNC0 => (Op::Func(f), 1),
                _ => {
                    return Err(ImageError::UnknownOpcode {
                        offset: at,
                        opcode: b,
                    })
                }
            }
        }
    };
    Ok(op)
}

/// A validated model program: a zero-copy view of its bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Program<'a> {
    consts: &'a [u8],
    code: &'a [u8],
    n_inputs: u8,
    n_outputs: u8,
    max_stack: u8,
}

impl<'a> Program<'a> {
    /// Validates `bytes` (see the module docs for every check) and returns the program.
    pub fn decode(bytes: &'a [u8]) -> Result<Self, ImageError> {
        check_dim(
            Dim::ProgramBytes,
            bytes.len(),
            PROGRAM_HEADER_LEN,
            MAX_PROGRAM_LEN,
        )?;
        let header = |i: usize| bytes.get(i).copied().unwrap_or(0);
        let n_inputs = header(0);
        let n_outputs = header(1);
        let n_consts = usize::from(u16_at(bytes, 2));
        let code_len = usize::from(u16_at(bytes, 4));
        let stored_stack = header(6);
        if header(7) != 0 {
            return Err(ImageError::ReservedNotZero);
        }
        check_dim(Dim::ProgramInputs, n_inputs.into(), 0, MAX_PROGRAM_INPUTS)?;
        check_dim(
            Dim::ProgramOutputs,
            n_outputs.into(),
            1,
            MAX_PROGRAM_OUTPUTS,
        )?;
        check_dim(Dim::ProgramConsts, n_consts, 0, MAX_PROGRAM_CONSTS)?;
        let code_start = PROGRAM_HEADER_LEN + 4 * n_consts;
        let expected = code_start + code_len;
        if bytes.len() != expected {
            return Err(ImageError::FieldLength {
                field: Field::Program,
                expected: sat32(expected),
                found: sat32(bytes.len()),
            });
        }
        let consts = bytes.get(PROGRAM_HEADER_LEN..code_start).unwrap_or(&[]);
        let code = bytes.get(code_start..).unwrap_or(&[]);
        check_finite(Field::ProgramConst, consts, |i| Pos(sat16(i), 0, 0))?;

        // One forward pass: every instruction decodes, its indices are in range, the stack never
        // underflows nor exceeds the capacity, and each output is stored exactly once.
        let mut depth = 0usize;
        let mut max_depth = 0usize;
        let mut stored = 0u64;
        let mut written = 0u32;
        let mut offset = 0usize;
        while offset < code.len() {
            let (op, len) = decode_op(code, offset)?;
            let at = sat16(offset);
            let reg_bit = |i: u8| 1u32.checked_shl(u32::from(i)).unwrap_or(0);
            let in_range = match op {
                Op::Load(i) => i < n_inputs,
                Op::Const(i) => usize::from(i) < n_consts,
                Op::Store(i) => i < n_outputs,
                Op::Tee(i) => usize::from(i) < MAX_PROGRAM_REGS,
                Op::Recall(i) => usize::from(i) < MAX_PROGRAM_REGS && written & reg_bit(i) != 0,
                _ => true,
            };
            if let Op::Tee(i) = op {
                written |= reg_bit(i);
            }
            if !in_range {
                return Err(ImageError::ProgramOperand { offset: at });
            }
            let (pops, pushes) = op.arity();
            depth = depth
                .checked_sub(pops)
                .ok_or(ImageError::StackUnderflow { offset: at })?
                + pushes;
            if depth > MAX_PROGRAM_STACK {
                return Err(ImageError::StackOverflow { offset: at });
            }
            max_depth = max_depth.max(depth);
            if let Op::Store(i) = op {
                let bit = 1u64.checked_shl(u32::from(i)).unwrap_or(0);
                if stored & bit != 0 {
                    return Err(ImageError::OutputStoredTwice { output: i });
                }
                stored |= bit;
            }
            offset += len;
        }
        if depth != 0 {
            return Err(ImageError::StackNotEmpty);
        }
        for i in 0..n_outputs {
            if stored & 1u64.checked_shl(u32::from(i)).unwrap_or(0) == 0 {
                return Err(ImageError::OutputNotStored { output: i });
            }
        }
        if usize::from(stored_stack) != max_depth {
            return Err(ImageError::ProgramStackMismatch {
                stored: stored_stack,
                actual: u8::try_from(max_depth).unwrap_or(u8::MAX),
            });
        }
        Ok(Self {
            consts,
            code,
            n_inputs,
            n_outputs,
            max_stack: stored_stack,
        })
    }

    /// Input slots the program reads.
    pub fn n_inputs(&self) -> usize {
        self.n_inputs.into()
    }

    /// Outputs the program stores.
    pub fn n_outputs(&self) -> usize {
        self.n_outputs.into()
    }

    /// Constants in the pool.
    pub fn n_consts(&self) -> usize {
        self.consts.len() / 4
    }

    /// The stack depth the code reaches.
    pub fn max_stack(&self) -> usize {
        self.max_stack.into()
    }

    /// Bytes of code.
    pub fn code_len(&self) -> usize {
        self.code.len()
    }

    /// Constant `i` of the pool (0 out of range).
    pub fn constant(&self, i: usize) -> f32 {
        f32_at(self.consts, i)
    }

    /// The instructions with their offsets in the code, in order.
    pub fn ops(&self) -> Ops<'a> {
        Ops {
            code: self.code,
            offset: 0,
        }
    }

    /// Evaluates the program: `inputs` has [`Self::n_inputs`] values, `out` receives
    /// [`Self::n_outputs`]. Slices of other lengths are refused with [`ImageError::ProgramArity`].
    /// Non-finite inputs or results are not refused here: the caller judges the outputs.
    pub fn eval(&self, inputs: &[f32], out: &mut [f32]) -> Result<(), ImageError> {
        self.eval_with(inputs, out, &mut Workspace::new())
    }

    /// [`Program::eval`] in the working memory `work`, which an earlier evaluation may have left as it
    /// was (the evaluator keeps one across steps, so that a step does not clear it): the stack slots and
    /// registers are written before they are read (validation), and the library calls remembered in it
    /// are exact (the coordinates and the input map both need sin θ), so the results are the same bits
    /// either way.
    // `tos = under + tos`, not `tos += under`: the operands stay in the table's order a ∘ b.
    #[allow(clippy::assign_op_pattern)]
    pub fn eval_with(
        &self,
        inputs: &[f32],
        out: &mut [f32],
        work: &mut Workspace,
    ) -> Result<(), ImageError> {
        if inputs.len() != self.n_inputs() {
            return Err(ImageError::ProgramArity {
                expected: self.n_inputs.into(),
                found: sat16(inputs.len()),
            });
        }
        if out.len() != self.n_outputs() {
            return Err(ImageError::ProgramArity {
                expected: self.n_outputs.into(),
                found: sat16(out.len()),
            });
        }
        // The top of the stack is kept in `tos`, the values under it in `stack[..sp]`: a push spills
        // `tos`, a pop reloads it. Validation proved 0 ≤ sp ≤ MAX_PROGRAM_STACK at every instruction,
        // so masking the index with the (power-of-two) capacity changes nothing; it only lets the
        // compiler drop the bounds checks, and no path can panic. One dispatch on the opcode byte per
        // instruction; the arithmetic is that of the instruction table, in code order.
        const MASK: usize = MAX_PROGRAM_STACK - 1;
        const REG_MASK: usize = MAX_PROGRAM_REGS - 1;
        let Workspace { stack, regs, memo } = work;
        let mut sp = 0usize;
        let mut tos = 0.0f32;
        let code = self.code;
        let mut pc = 0usize;
        while let Some(&byte) = code.get(pc) {
            // The operand byte, read only by the instructions that have one.
            macro_rules! operand {
                () => {
                    code.get(pc.wrapping_add(1)).copied().unwrap_or(0)
                };
            }
            // Push `v`: spill the old top under it.
            macro_rules! push {
                ($v:expr) => {{
                    let v = $v;
                    stack[sp & MASK] = tos;
                    sp = sp.wrapping_add(1);
                    tos = v;
                }};
            }
            // Pop the value under the top (the left operand of a binary instruction).
            macro_rules! pop_under {
                () => {{
                    sp = sp.wrapping_sub(1);
                    stack[sp & MASK]
                }};
            }
            pc += match byte {
                opcode::LOAD => {
                    push!(inputs.get(usize::from(operand!())).copied().unwrap_or(0.0));
                    2
                }
                opcode::CONST => {
                    let hi = code.get(pc.wrapping_add(2)).copied().unwrap_or(0);
                    push!(self.constant(usize::from(u16::from_le_bytes([operand!(), hi]))));
                    3
                }
                opcode::STORE => {
                    if let Some(o) = out.get_mut(usize::from(operand!())) {
                        *o = tos;
                    }
                    tos = pop_under!();
                    2
                }
                opcode::TEE => {
                    regs[usize::from(operand!()) & REG_MASK] = tos;
                    2
                }
                opcode::RECALL => {
                    push!(regs[usize::from(operand!()) & REG_MASK]);
                    2
                }
                opcode::ADD => {
                    tos = pop_under!() + tos;
                    1
                }
                opcode::SUB => {
                    tos = pop_under!() - tos;
                    1
                }
                opcode::MUL => {
                    tos = pop_under!() * tos;
                    1
                }
                opcode::DIV => {
                    tos = pop_under!() / tos;
                    1
                }
                opcode::ATAN2 => {
                    tos = libm::atan2f(pop_under!(), tos);
                    1
                }
                opcode::NEG => {
                    tos = -tos;
                    1
                }
                opcode::POWI => {
                    tos = powi(tos, operand!() as i8);
                    2
                }
                b => {
                    match Func::ALL.get(usize::from(b.wrapping_sub(opcode::FUNC0))) {
                        Some(&f @ (Func::Sqrt | Func::Abs)) => tos = f.apply(tos),
                        Some(&f) => tos = memo.apply(f, tos),
                        // Not an opcode (never in a validated program): stop.
                        None => break,
                    }
                    1
                }
            };
        }
        Ok(())
    }
}

/// How many library calls one evaluation remembers ([`Memo`]).
const MEMO_LEN: usize = 4;

/// The working memory of program evaluations ([`Program::eval_with`]): the value stack, the registers
/// and the [`Memo`] of library calls. The evaluator keeps one for as long as the controller lives,
/// which spares every step the clearing of the two arrays; nothing an evaluation reads in it depends
/// on what an earlier one left (see `eval_with`).
#[derive(Clone, Copy, Debug)]
pub struct Workspace {
    stack: [f32; MAX_PROGRAM_STACK],
    regs: [f32; MAX_PROGRAM_REGS],
    memo: Memo,
}

impl Default for Workspace {
    fn default() -> Self {
        Self::new()
    }
}

impl Workspace {
    /// Zeroed, nothing remembered.
    pub const fn new() -> Self {
        Workspace {
            stack: [0.0; MAX_PROGRAM_STACK],
            regs: [0.0; MAX_PROGRAM_REGS],
            memo: Memo::new(),
        }
    }
}

/// The library calls already made, by function and argument bits: a program shares a
/// subexpression through its registers, but two programs of one step (the coordinates and the input
/// map) and two equal arguments the compiler did not see as one expression would otherwise pay for a call
/// twice, and a call costs more on the target than a few comparisons (most of `libm`'s f32 functions
/// compute in f64, which a Cortex-M4F emulates). The functions are pure, so a remembered value has exactly the bits a new call
/// would give, in this step or a later one. Oldest entry replaced first; bounded by [`MEMO_LEN`].
#[derive(Clone, Copy, Debug)]
struct Memo {
    /// (opcode, argument bits, value); opcode 0 (no function has it) marks an empty entry.
    entries: [(u8, u32, f32); MEMO_LEN],
    next: usize,
}

impl Memo {
    /// Nothing remembered.
    const fn new() -> Self {
        Memo {
            entries: [(0, 0, 0.0); MEMO_LEN],
            next: 0,
        }
    }

    /// `f(x)`, remembered. A sine or cosine is computed with [`crate::trig::sincos`] and both are
    /// remembered (a rotation needs both of the same angle), the bits [`Func::apply`] gives.
    #[inline]
    fn apply(&mut self, f: Func, x: f32) -> f32 {
        let bits = x.to_bits();
        if let Some(&(_, _, v)) = self
            .entries
            .iter()
            .find(|e| e.0 == f.opcode() && e.1 == bits)
        {
            return v;
        }
        match f {
            Func::Sin | Func::Cos => {
                let (s, c) = crate::trig::sincos(x);
                self.remember(Func::Sin, bits, s);
                self.remember(Func::Cos, bits, c);
                if f == Func::Sin {
                    s
                } else {
                    c
                }
            }
            _ => {
                let v = f.apply(x);
                self.remember(f, bits, v);
                v
            }
        }
    }

    fn remember(&mut self, f: Func, bits: u32, v: f32) {
        if let Some(e) = self.entries.get_mut(self.next % MEMO_LEN) {
            *e = (f.opcode(), bits, v);
        }
        self.next = self.next.wrapping_add(1);
    }
}

/// The instructions of a validated program ([`Program::ops`]): `(offset, op)` in code order.
#[derive(Clone, Debug)]
pub struct Ops<'a> {
    code: &'a [u8],
    offset: usize,
}

impl Iterator for Ops<'_> {
    type Item = (usize, Op);

    fn next(&mut self) -> Option<(usize, Op)> {
        if self.offset >= self.code.len() {
            return None;
        }
        match decode_op(self.code, self.offset) {
            Ok((op, len)) => {
                let at = self.offset;
                self.offset += len;
                Some((at, op))
            }
            // Not reached for a decoded program; stop rather than loop.
            Err(_) => {
                self.offset = self.code.len();
                None
            }
        }
    }
}

/// Writes the header of a program with these counts into the first [`PROGRAM_HEADER_LEN`] bytes of
/// `buf` (the host's encoder; the decoder is the judge of the result). Returns `false` if a count does
/// not fit its field or `buf` is too short.
pub fn write_header(
    buf: &mut [u8],
    n_inputs: usize,
    n_outputs: usize,
    n_consts: usize,
    code_len: usize,
    max_stack: usize,
) -> bool {
    let (Ok(i), Ok(o), Ok(c), Ok(l), Ok(s)) = (
        u8::try_from(n_inputs),
        u8::try_from(n_outputs),
        u16::try_from(n_consts),
        u16::try_from(code_len),
        u8::try_from(max_stack),
    ) else {
        return false;
    };
    let Some(h) = buf.get_mut(..PROGRAM_HEADER_LEN) else {
        return false;
    };
    let [c0, c1] = c.to_le_bytes();
    let [l0, l1] = l.to_le_bytes();
    for (d, v) in h.iter_mut().zip([i, o, c0, c1, l0, l1, s, 0]) {
        *d = v;
    }
    true
}

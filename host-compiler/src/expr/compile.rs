//! Compiling expressions to the target's model program (`shared_types::program`): postfix code with a
//! deduplicated constant pool, parameters bound to their values, and the operands of `+` and `·`
//! ordered so that the deeper side runs first (Sethi–Ullman), which lowers the stack depth without
//! changing a single result bit (f32 addition and multiplication are commutative). A subexpression that
//! occurs more than once over all the outputs (a derived map repeats sin θ, T/m, their products, …) is
//! computed once, kept in a register (`TEE`) and recalled (`RECALL`) where it recurs: the same bits,
//! since its f32 evaluation does not depend on where it stands. The bytes are judged by
//! `Program::decode` before they are returned, and every size is checked against the capacities.
//!
//! Slot layout of the program's inputs: states `x_0..x_{n−1}` in slots `0..n`, then inputs `u_0..u_{m−1}`
//! in slots `n..n+m`. Parameters are constants of the pool.

use super::{Expr, ExprError, Var};
use shared_types::capacity::{
    MAX_PROGRAM_CONSTS, MAX_PROGRAM_INPUTS, MAX_PROGRAM_LEN, MAX_PROGRAM_OUTPUTS, MAX_PROGRAM_REGS,
    MAX_PROGRAM_STACK,
};
use shared_types::program::{write_header, Op, Program, PROGRAM_HEADER_LEN};
use std::collections::HashMap;

/// A compiled program: its bytes, and for every pool constant the f64 value it rounds (what the rounding
/// analysis of [`super::interval`] takes as exact).
#[derive(Clone, Debug, PartialEq)]
pub struct Compiled {
    pub bytes: Vec<u8>,
    /// The exact (f64) value of pool entry i; the pool stores `consts[i] as f32`.
    pub consts: Vec<f64>,
    /// States n (slots `0..n`).
    pub n_states: usize,
    /// Inputs m (slots `n..n+m`).
    pub n_inputs: usize,
}

impl Compiled {
    /// The validated program view of the bytes.
    pub fn program(&self) -> Program<'_> {
        Program::decode(&self.bytes).expect("compile returns only bytes that decode")
    }

    /// Evaluates in f32 through the shared evaluator (what the firmware computes): `x` and `u` are
    /// rounded to f32 first.
    pub fn eval_f32(&self, x: &[f64], u: &[f64]) -> Vec<f32> {
        let p = self.program();
        let inputs: Vec<f32> = x.iter().chain(u).map(|&v| v as f32).collect();
        let mut out = vec![0.0f32; p.n_outputs()];
        p.eval(&inputs, &mut out)
            .expect("the slices have the program's lengths");
        out
    }
}

struct Gen<'e> {
    code: Vec<u8>,
    pool: Vec<f64>,
    index: HashMap<u64, u16>,
    n_states: usize,
    /// The stack depth after the code so far, and the most it reached.
    depth: usize,
    max_depth: usize,
    /// Every compound subtree's structural hash, by address ([`hash_tree`]).
    hashes: HashMap<*const Expr, u64>,
    /// Per hash, the distinct subtrees with it: how often each is used once shared ones are computed once
    /// ([`count_uses`]), and the register holding it once computed.
    uses: HashMap<u64, Vec<Use<'e>>>,
    /// Registers handed out.
    regs: usize,
}

/// A compound subtree of the outputs: how many times the code needs its value, and its register.
struct Use<'e> {
    tree: &'e Expr,
    count: usize,
    reg: Option<u8>,
}

/// Whether `e` is a leaf (a load or a constant: as cheap as a recall).
fn leaf(e: &Expr) -> bool {
    matches!(e, Expr::Const(_) | Expr::Var(_))
}

/// The structural hash of `e` (equal trees hash alike), recorded with every compound subtree's in `out`.
fn hash_tree(e: &Expr, out: &mut HashMap<*const Expr, u64>) -> u64 {
    use std::hash::{Hash, Hasher};
    // SipHash with fixed keys: the same on every run, so the program's bytes are too.
    let mut h = std::collections::hash_map::DefaultHasher::new();
    std::mem::discriminant(e).hash(&mut h);
    match e {
        Expr::Const(v) => v.to_bits().hash(&mut h),
        Expr::Var(v) => v.hash(&mut h),
        Expr::Neg(a) => hash_tree(a, out).hash(&mut h),
        Expr::Pow(a, k) => {
            hash_tree(a, out).hash(&mut h);
            k.hash(&mut h);
        }
        Expr::Func(f, a) => {
            f.hash(&mut h);
            hash_tree(a, out).hash(&mut h);
        }
        Expr::Add(a, b)
        | Expr::Sub(a, b)
        | Expr::Mul(a, b)
        | Expr::Div(a, b)
        | Expr::Atan2(a, b) => {
            hash_tree(a, out).hash(&mut h);
            hash_tree(b, out).hash(&mut h);
        }
    }
    let v = h.finish();
    if !leaf(e) {
        out.insert(e as *const Expr, v);
    }
    v
}

/// Counts the uses of every compound subtree of `e` into `uses`, not descending into one already seen
/// (its inside is computed once, with it).
fn count_uses<'e>(
    e: &'e Expr,
    hashes: &HashMap<*const Expr, u64>,
    uses: &mut HashMap<u64, Vec<Use<'e>>>,
) {
    if leaf(e) {
        return;
    }
    let h = hashes[&(e as *const Expr)];
    let bucket = uses.entry(h).or_default();
    if let Some(u) = bucket.iter_mut().find(|u| *u.tree == *e) {
        u.count += 1;
        return;
    }
    bucket.push(Use {
        tree: e,
        count: 1,
        reg: None,
    });
    match e {
        Expr::Const(_) | Expr::Var(_) => {}
        Expr::Neg(a) | Expr::Pow(a, _) | Expr::Func(_, a) => count_uses(a, hashes, uses),
        Expr::Add(a, b)
        | Expr::Sub(a, b)
        | Expr::Mul(a, b)
        | Expr::Div(a, b)
        | Expr::Atan2(a, b) => {
            count_uses(a, hashes, uses);
            count_uses(b, hashes, uses);
        }
    }
}

/// Stack depth the postfix code of `e` needs (with the operand order [`Gen::emit`] chooses).
fn need(e: &Expr) -> usize {
    match e {
        Expr::Const(_) | Expr::Var(_) => 1,
        Expr::Neg(a) | Expr::Pow(a, _) | Expr::Func(_, a) => need(a),
        Expr::Add(a, b) | Expr::Mul(a, b) => {
            let (na, nb) = (need(a), need(b));
            na.max(nb + 1).min(nb.max(na + 1))
        }
        Expr::Sub(a, b) | Expr::Div(a, b) | Expr::Atan2(a, b) => need(a).max(need(b) + 1),
    }
}

impl<'e> Gen<'e> {
    fn op(&mut self, op: Op) {
        let (b, len) = op.encode();
        self.code.extend_from_slice(&b[..len]);
        let (pops, pushes) = op.arity();
        self.depth = self.depth.saturating_sub(pops) + pushes;
        self.max_depth = self.max_depth.max(self.depth);
    }

    /// The use record of the compound subtree `e`.
    fn use_of(&mut self, e: &Expr) -> Option<&mut Use<'e>> {
        let h = *self.hashes.get(&(e as *const Expr))?;
        self.uses
            .get_mut(&h)?
            .iter_mut()
            .find(|u| std::ptr::eq(u.tree, e) || *u.tree == *e)
    }

    /// Emits `e`: recalled from its register when computed before; else computed, and teed into a new
    /// register when the code needs it again (while registers last).
    fn emit(&mut self, e: &'e Expr) -> Result<(), ExprError> {
        if leaf(e) {
            return self.emit_tree(e);
        }
        let (reg, shared) = match self.use_of(e) {
            Some(u) => (u.reg, u.count > 1),
            None => (None, false),
        };
        if let Some(r) = reg {
            self.op(Op::Recall(r));
            return Ok(());
        }
        self.emit_tree(e)?;
        // The next free register after e's own code (which may have taken some for its inside).
        if shared && self.regs < MAX_PROGRAM_REGS {
            let r = self.regs as u8;
            if let Some(u) = self.use_of(e) {
                u.reg = Some(r);
            }
            self.regs += 1;
            self.op(Op::Tee(r));
        }
        Ok(())
    }

    fn constant(&mut self, v: f64) -> Result<(), ExprError> {
        let v32 = v as f32;
        if !v32.is_finite() {
            return Err(ExprError::Program(format!(
                "the constant {v} is beyond the range of f32"
            )));
        }
        // -0.0 and 0.0 are different bits and kept apart: the stored value is exactly what was asked.
        let key = v.to_bits();
        let i = match self.index.get(&key) {
            Some(&i) => i,
            None => {
                let i = self.pool.len();
                if i >= MAX_PROGRAM_CONSTS {
                    return Err(ExprError::Program(format!(
                        "more than {MAX_PROGRAM_CONSTS} distinct constants"
                    )));
                }
                self.pool.push(v);
                self.index.insert(key, i as u16);
                i as u16
            }
        };
        self.op(Op::Const(i));
        Ok(())
    }

    /// The code of `e` itself (its operands through [`Gen::emit`]).
    fn emit_tree(&mut self, e: &'e Expr) -> Result<(), ExprError> {
        if self.code.len() > MAX_PROGRAM_LEN {
            return Err(ExprError::Program(format!(
                "the code is longer than {MAX_PROGRAM_LEN} bytes"
            )));
        }
        match e {
            Expr::Const(v) => self.constant(*v)?,
            Expr::Var(v) => {
                let slot = match *v {
                    Var::State(i) => i as usize,
                    Var::Input(i) => self.n_states + i as usize,
                    Var::Param(_) => {
                        return Err(ExprError::Program(
                            "a parameter is left unbound (bind_params first)".into(),
                        ))
                    }
                };
                self.op(Op::Load(slot as u8));
            }
            Expr::Neg(a) => {
                self.emit(a)?;
                self.op(Op::Neg);
            }
            Expr::Pow(a, k) => {
                self.emit(a)?;
                self.op(Op::Powi(*k));
            }
            Expr::Func(f, a) => {
                self.emit(a)?;
                self.op(Op::Func(*f));
            }
            Expr::Add(a, b) | Expr::Mul(a, b) => {
                // The deeper operand first; the result bits are the same either way.
                let (first, second) = if need(b) > need(a) { (b, a) } else { (a, b) };
                self.emit(first)?;
                self.emit(second)?;
                self.op(if matches!(e, Expr::Add(..)) {
                    Op::Add
                } else {
                    Op::Mul
                });
            }
            Expr::Sub(a, b) | Expr::Div(a, b) | Expr::Atan2(a, b) => {
                self.emit(a)?;
                self.emit(b)?;
                self.op(match e {
                    Expr::Sub(..) => Op::Sub,
                    Expr::Div(..) => Op::Div,
                    _ => Op::Atan2,
                });
            }
        }
        Ok(())
    }
}

/// Compiles `outputs` (expressions over n states and m inputs; parameters are bound to `params` first)
/// into one program whose output i is `outputs[i]`.
pub fn compile(
    outputs: &[Expr],
    n_states: usize,
    n_inputs: usize,
    params: &[f64],
) -> Result<Compiled, ExprError> {
    let slots = n_states + n_inputs;
    if slots > MAX_PROGRAM_INPUTS {
        return Err(ExprError::Program(format!(
            "{slots} input slots, more than {MAX_PROGRAM_INPUTS}"
        )));
    }
    if outputs.is_empty() || outputs.len() > MAX_PROGRAM_OUTPUTS {
        return Err(ExprError::Program(format!(
            "{} outputs, allowed 1..={MAX_PROGRAM_OUTPUTS}",
            outputs.len()
        )));
    }
    let bound: Vec<Expr> = outputs.iter().map(|e| e.bind_params(params)).collect();
    for (i, e) in bound.iter().enumerate() {
        if let Some(bad) = out_of_range(e, n_states, n_inputs) {
            return Err(ExprError::Program(format!(
                "output {i} uses {bad}, outside the {n_states} states and {n_inputs} inputs"
            )));
        }
        // The stack a tree needs without sharing bounds what it needs with it (a recall is one slot).
        let depth = need(e);
        if depth > MAX_PROGRAM_STACK {
            return Err(ExprError::Program(format!(
                "output {i} needs a stack of {depth} values, more than {MAX_PROGRAM_STACK}"
            )));
        }
    }
    let mut hashes = HashMap::new();
    for e in &bound {
        hash_tree(e, &mut hashes);
    }
    let mut uses = HashMap::new();
    for e in &bound {
        count_uses(e, &hashes, &mut uses);
    }
    let mut g = Gen {
        code: Vec::new(),
        pool: Vec::new(),
        index: HashMap::new(),
        n_states,
        depth: 0,
        max_depth: 0,
        hashes,
        uses,
        regs: 0,
    };
    for (i, e) in bound.iter().enumerate() {
        g.emit(e)?;
        g.op(Op::Store(i as u8));
    }
    let depth = g.max_depth;
    let len = PROGRAM_HEADER_LEN + 4 * g.pool.len() + g.code.len();
    if len > MAX_PROGRAM_LEN {
        return Err(ExprError::Program(format!(
            "{len} bytes, more than {MAX_PROGRAM_LEN}"
        )));
    }
    let mut bytes = vec![0u8; PROGRAM_HEADER_LEN];
    if !write_header(
        &mut bytes,
        slots,
        outputs.len(),
        g.pool.len(),
        g.code.len(),
        depth,
    ) {
        return Err(ExprError::Program("a count does not fit the header".into()));
    }
    for &c in &g.pool {
        bytes.extend_from_slice(&(c as f32).to_le_bytes());
    }
    bytes.extend_from_slice(&g.code);
    Program::decode(&bytes)
        .map_err(|e| ExprError::Program(format!("the compiled bytes do not decode: {e}")))?;
    Ok(Compiled {
        bytes,
        consts: g.pool,
        n_states,
        n_inputs,
    })
}

/// A variable of `e` outside the slots, if any.
fn out_of_range(e: &Expr, n: usize, m: usize) -> Option<Var> {
    match e {
        Expr::Const(_) => None,
        Expr::Var(v) => {
            let ok = match *v {
                Var::State(i) => (i as usize) < n,
                Var::Input(i) => (i as usize) < m,
                Var::Param(_) => false,
            };
            (!ok).then_some(*v)
        }
        Expr::Neg(a) | Expr::Pow(a, _) | Expr::Func(_, a) => out_of_range(a, n, m),
        Expr::Add(a, b)
        | Expr::Sub(a, b)
        | Expr::Mul(a, b)
        | Expr::Div(a, b)
        | Expr::Atan2(a, b) => out_of_range(a, n, m).or_else(|| out_of_range(b, n, m)),
    }
}

//! Several expressions evaluated together in f64 at one point, as one straight-line tape: the trees
//! flattened in post-order, and a subtree that occurs more than once (structurally equal, constants by
//! their bits) computed once. The verifier's flows and maps evaluate the same few expressions of a
//! nonlinear plant at millions of points (`model::nonlinear`'s field, a flat plant's coordinates), where
//! walking boxed trees and repeating `sin θ` in every entry cost more than the arithmetic.
//!
//! Every instruction is the tree's own operation on the same operand values, so each output is
//! [`Expr::eval`]'s value bit for bit. Written here because the expressions are this crate's own AST (an
//! expression crate would parse its own language and evaluate its own trees).

use super::{apply_f64, Expr, Point, Var};
use shared_types::program::Func;
use std::collections::HashMap;

/// One instruction: its operands are the slots of earlier instructions.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum Op {
    /// A constant, by its bits (so that equal constants share a slot and −0 stays apart from +0).
    Const(u64),
    Var(Var),
    Neg(u32),
    Add(u32, u32),
    Sub(u32, u32),
    Mul(u32, u32),
    Div(u32, u32),
    Pow(u32, i8),
    Func(Func, u32),
    Atan2(u32, u32),
}

/// The tape of a list of expressions ([`Tape::new`]).
#[derive(Clone, Debug)]
pub struct Tape {
    ops: Vec<Op>,
    /// The slot of each expression's value, in the order given.
    outputs: Vec<u32>,
}

/// Slots a tape evaluates on the stack; a longer tape uses the heap.
const STACK_SLOTS: usize = 256;

impl Tape {
    /// The tape of `exprs`, in their order.
    pub fn new<'a>(exprs: impl IntoIterator<Item = &'a Expr>) -> Self {
        let mut tape = Tape {
            ops: Vec::new(),
            outputs: Vec::new(),
        };
        let mut seen = HashMap::new();
        for e in exprs {
            let slot = tape.push(e, &mut seen);
            tape.outputs.push(slot);
        }
        tape
    }

    /// The number of expressions.
    pub fn len(&self) -> usize {
        self.outputs.len()
    }

    /// True for a tape of no expressions.
    pub fn is_empty(&self) -> bool {
        self.outputs.is_empty()
    }

    fn push(&mut self, e: &Expr, seen: &mut HashMap<Op, u32>) -> u32 {
        let op = match e {
            Expr::Const(v) => Op::Const(v.to_bits()),
            Expr::Var(v) => Op::Var(*v),
            Expr::Neg(a) => Op::Neg(self.push(a, seen)),
            Expr::Add(a, b) => Op::Add(self.push(a, seen), self.push(b, seen)),
            Expr::Sub(a, b) => Op::Sub(self.push(a, seen), self.push(b, seen)),
            Expr::Mul(a, b) => Op::Mul(self.push(a, seen), self.push(b, seen)),
            Expr::Div(a, b) => Op::Div(self.push(a, seen), self.push(b, seen)),
            Expr::Pow(a, k) => Op::Pow(self.push(a, seen), *k),
            Expr::Func(f, a) => Op::Func(*f, self.push(a, seen)),
            Expr::Atan2(y, x) => Op::Atan2(self.push(y, seen), self.push(x, seen)),
        };
        *seen.entry(op).or_insert_with(|| {
            self.ops.push(op);
            (self.ops.len() - 1) as u32
        })
    }

    /// `then` of every expression's value at `at`, in order, held on the stack for a short tape.
    pub fn with_values<R>(&self, at: &Point<'_>, then: impl FnOnce(&[f64]) -> R) -> R {
        let mut stack = [0.0f64; 64];
        if self.len() <= stack.len() {
            let vals = &mut stack[..self.len()];
            self.eval_into(at, vals);
            then(vals)
        } else {
            let mut vals = vec![0.0; self.len()];
            self.eval_into(at, &mut vals);
            then(&vals)
        }
    }

    /// Every expression's value at `at`, in order, into `out` (length [`Tape::len`]).
    pub fn eval_into(&self, at: &Point<'_>, out: &mut [f64]) {
        let mut stack = [0.0f64; STACK_SLOTS];
        let mut heap = Vec::new();
        let slots: &mut [f64] = if self.ops.len() <= STACK_SLOTS {
            &mut stack[..self.ops.len()]
        } else {
            heap.resize(self.ops.len(), 0.0);
            &mut heap
        };
        for i in 0..self.ops.len() {
            let s = |k: u32| slots[k as usize];
            slots[i] = match self.ops[i] {
                Op::Const(bits) => f64::from_bits(bits),
                Op::Var(v) => at.get(v),
                Op::Neg(a) => -s(a),
                Op::Add(a, b) => s(a) + s(b),
                Op::Sub(a, b) => s(a) - s(b),
                Op::Mul(a, b) => s(a) * s(b),
                Op::Div(a, b) => s(a) / s(b),
                Op::Pow(a, k) => s(a).powi(k.into()),
                Op::Func(f, a) => apply_f64(f, s(a)),
                Op::Atan2(y, x) => s(y).atan2(s(x)),
            };
        }
        for (o, &k) in out.iter_mut().zip(&self.outputs) {
            *o = slots[k as usize];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::expr::{parse, Names};

    /// The flat quadrotor's coordinates and field entries: every output equals `Expr::eval`'s bit for
    /// bit at random points, and the repeated `sin(th)`, `cos(th)` and their products take one slot each.
    #[test]
    fn a_tape_gives_each_tree_s_value_bit_for_bit_and_shares_repeats() {
        use rand::{Rng, SeedableRng};
        let names = Names {
            states: ["X", "Xd", "Y", "Yd", "th", "thd", "T", "Td"]
                .map(String::from)
                .to_vec(),
            inputs: vec![],
            params: vec![("m".into(), 1.5), ("g".into(), 9.81)],
        };
        let texts = [
            "-T*sin(th)/m",
            "-(Td*sin(th) + T*cos(th)*thd)/m",
            "T*cos(th)/m - g",
            "(Td*cos(th) - T*sin(th)*thd)/m",
            "atan2(-X, Y + g)^2 - 0.0",
            "-0.0 + exp(-Xd^2) * (Yd^-3)",
        ];
        let exprs: Vec<Expr> = texts.iter().map(|t| parse(t, &names).expect(t)).collect();
        let tape = Tape::new(&exprs);
        assert_eq!(tape.len(), exprs.len());
        let distinct_trig = tape
            .ops
            .iter()
            .filter(|o| matches!(o, Op::Func(Func::Sin | Func::Cos, _)))
            .count();
        assert_eq!(distinct_trig, 2, "{:?}", tape.ops);
        let nodes: usize = exprs.iter().map(Expr::size).sum();
        assert!(
            tape.ops.len() < nodes * 2 / 3,
            "{} of {nodes}",
            tape.ops.len()
        );
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let p = [1.5, 9.81];
        let mut out = vec![0.0; tape.len()];
        for _ in 0..2000 {
            let x: Vec<f64> = (0..8).map(|_| rng.random_range(-3.0..3.0)).collect();
            let at = Point {
                x: &x,
                u: &[],
                p: &p,
            };
            tape.eval_into(&at, &mut out);
            for (e, o) in exprs.iter().zip(&out) {
                assert_eq!(e.eval(&at).to_bits(), o.to_bits(), "{e:?} at {x:?}");
            }
        }
    }
}

//! Model programs: hand-assembled programs evaluate to what their expressions say, every validation rule
//! refuses what it names, and random or mutated bytes never panic the decoder or the evaluator.

use proptest::prelude::*;
use shared_types::capacity::{MAX_PROGRAM_LEN, MAX_PROGRAM_REGS, MAX_PROGRAM_STACK};
use shared_types::error::{Dim, Field, ImageError};
use shared_types::program::{powi, write_header, Func, Op, Program, Workspace, PROGRAM_HEADER_LEN};

/// Assembles a program from its parts (the stored stack depth is given, so tests can lie about it).
pub(crate) fn assemble(
    n_inputs: usize,
    n_outputs: usize,
    consts: &[f32],
    ops: &[Op],
    stack: usize,
) -> Vec<u8> {
    let mut code = Vec::new();
    for op in ops {
        let (b, len) = op.encode();
        code.extend_from_slice(&b[..len]);
    }
    let mut bytes = vec![0u8; PROGRAM_HEADER_LEN];
    assert!(write_header(
        &mut bytes,
        n_inputs,
        n_outputs,
        consts.len(),
        code.len(),
        stack
    ));
    for c in consts {
        bytes.extend_from_slice(&c.to_le_bytes());
    }
    bytes.extend_from_slice(&code);
    bytes
}

/// out0 = x0·sin(x1) + 2, out1 = atan2(x1, x0)^-2 − exp(−x0)
fn sample() -> Vec<u8> {
    use Op::*;
    assemble(
        2,
        2,
        &[2.0],
        &[
            Load(0),
            Load(1),
            Func(shared_types::program::Func::Sin),
            Mul,
            Const(0),
            Add,
            Store(0),
            Load(1),
            Load(0),
            Atan2,
            Powi(-2),
            Load(0),
            Neg,
            Func(shared_types::program::Func::Exp),
            Sub,
            Store(1),
        ],
        2,
    )
}

#[test]
fn sample_program_evaluates_its_expressions() {
    let bytes = sample();
    let p = Program::decode(&bytes).expect("valid");
    assert_eq!(
        (p.n_inputs(), p.n_outputs(), p.n_consts(), p.max_stack()),
        (2, 2, 1, 2)
    );
    let x = [0.7f32, -1.3f32];
    let mut out = [0.0f32; 2];
    p.eval(&x, &mut out).unwrap();
    let (a, b) = (x[0] as f64, x[1] as f64);
    let e0 = a * b.sin() + 2.0;
    let e1 = b.atan2(a).powi(-2) - (-a).exp();
    assert!((out[0] as f64 - e0).abs() < 1e-6, "{} vs {e0}", out[0]);
    assert!((out[1] as f64 - e1).abs() < 1e-5, "{} vs {e1}", out[1]);
}

#[test]
fn powi_multiplies_left_to_right_and_inverts_negative_powers() {
    let x = 1.1f32;
    assert_eq!(powi(x, 3), (x * x) * x);
    assert_eq!(powi(x, -2), 1.0 / (x * x));
    assert_eq!(powi(x, 1), x);
}

#[test]
fn eval_refuses_slices_of_the_wrong_length() {
    let bytes = sample();
    let p = Program::decode(&bytes).unwrap();
    let mut out = [0.0f32; 2];
    assert_eq!(
        p.eval(&[1.0], &mut out),
        Err(ImageError::ProgramArity {
            expected: 2,
            found: 1
        })
    );
    let mut short = [0.0f32; 1];
    assert_eq!(
        p.eval(&[1.0, 2.0], &mut short),
        Err(ImageError::ProgramArity {
            expected: 2,
            found: 1
        })
    );
}

#[test]
fn every_validation_rule_refuses_what_it_names() {
    use Op::*;
    // Stack depth stored wrong.
    let b = assemble(1, 1, &[], &[Load(0), Store(0)], 2);
    assert_eq!(
        Program::decode(&b).unwrap_err(),
        ImageError::ProgramStackMismatch {
            stored: 2,
            actual: 1
        }
    );
    // Underflow.
    let b = assemble(1, 1, &[], &[Load(0), Add, Store(0)], 1);
    assert_eq!(
        Program::decode(&b).unwrap_err(),
        ImageError::StackUnderflow { offset: 2 }
    );
    // Slot out of range.
    let b = assemble(1, 1, &[], &[Load(1), Store(0)], 1);
    assert_eq!(
        Program::decode(&b).unwrap_err(),
        ImageError::ProgramOperand { offset: 0 }
    );
    // Constant out of range.
    let b = assemble(0, 1, &[1.0], &[Const(1), Store(0)], 1);
    assert_eq!(
        Program::decode(&b).unwrap_err(),
        ImageError::ProgramOperand { offset: 0 }
    );
    // Output out of range, stored twice, never stored.
    let b = assemble(1, 1, &[], &[Load(0), Store(1)], 1);
    assert_eq!(
        Program::decode(&b).unwrap_err(),
        ImageError::ProgramOperand { offset: 2 }
    );
    let b = assemble(1, 1, &[], &[Load(0), Store(0), Load(0), Store(0)], 1);
    assert_eq!(
        Program::decode(&b).unwrap_err(),
        ImageError::OutputStoredTwice { output: 0 }
    );
    let b = assemble(1, 2, &[], &[Load(0), Store(0)], 1);
    assert_eq!(
        Program::decode(&b).unwrap_err(),
        ImageError::OutputNotStored { output: 1 }
    );
    // Values left on the stack.
    let b = assemble(1, 1, &[], &[Load(0), Load(0), Store(0)], 2);
    assert_eq!(Program::decode(&b).unwrap_err(), ImageError::StackNotEmpty);
    // Non-finite constant.
    let b = assemble(0, 1, &[f32::NAN], &[Const(0), Store(0)], 1);
    assert!(matches!(
        Program::decode(&b).unwrap_err(),
        ImageError::NonFinite {
            field: Field::ProgramConst,
            ..
        }
    ));
    // Unknown opcode, truncated operand, zero and too large exponents.
    let mut b = assemble(1, 1, &[], &[Load(0), Neg, Store(0)], 1);
    b[PROGRAM_HEADER_LEN + 2] = 0x7f;
    assert_eq!(
        Program::decode(&b).unwrap_err(),
        ImageError::UnknownOpcode {
            offset: 2,
            opcode: 0x7f
        }
    );
    let mut b = assemble(1, 1, &[], &[Load(0), Store(0)], 1);
    b.pop();
    b[4] -= 1;
    assert_eq!(
        Program::decode(&b).unwrap_err(),
        ImageError::ProgramOperand { offset: 2 }
    );
    for k in [0i8, 17, -17] {
        let b = assemble(1, 1, &[], &[Load(0), Powi(k), Store(0)], 1);
        assert_eq!(
            Program::decode(&b).unwrap_err(),
            ImageError::ProgramOperand { offset: 2 }
        );
    }
    // Length disagreeing with the header, reserved byte, dimensions.
    let mut b = sample();
    b.push(0);
    assert!(matches!(
        Program::decode(&b).unwrap_err(),
        ImageError::FieldLength {
            field: Field::Program,
            ..
        }
    ));
    let mut b = sample();
    b[7] = 1;
    assert_eq!(
        Program::decode(&b).unwrap_err(),
        ImageError::ReservedNotZero
    );
    let b = assemble(1, 0, &[], &[], 0);
    assert!(matches!(
        Program::decode(&b).unwrap_err(),
        ImageError::DimOutOfRange {
            dim: Dim::ProgramOutputs,
            ..
        }
    ));
    assert!(matches!(
        Program::decode(&vec![0u8; MAX_PROGRAM_LEN + 1]).unwrap_err(),
        ImageError::DimOutOfRange {
            dim: Dim::ProgramBytes,
            ..
        }
    ));
}

#[test]
fn a_register_is_read_only_after_a_write_and_within_capacity() {
    use Op::*;
    // x0·x0 teed into register 3, recalled: out0 = (x0·x0) + (x0·x0).
    let ok = assemble(
        1,
        1,
        &[],
        &[Load(0), Load(0), Mul, Tee(3), Recall(3), Add, Store(0)],
        2,
    );
    let p = Program::decode(&ok).expect("valid");
    let mut out = [0.0f32];
    p.eval(&[1.5], &mut out).unwrap();
    assert_eq!(out[0].to_bits(), (1.5f32 * 1.5 + 1.5 * 1.5).to_bits());
    // A recall before any tee of that register, a register beyond the capacity.
    let unwritten = assemble(1, 1, &[], &[Load(0), Tee(2), Recall(3), Add, Store(0)], 2);
    assert_eq!(
        Program::decode(&unwritten),
        Err(ImageError::ProgramOperand { offset: 4 })
    );
    let r = MAX_PROGRAM_REGS as u8;
    let beyond = assemble(1, 1, &[], &[Load(0), Tee(r), Store(0)], 1);
    assert_eq!(
        Program::decode(&beyond),
        Err(ImageError::ProgramOperand { offset: 2 })
    );
}

#[test]
fn stack_beyond_capacity_is_refused_at_the_instruction_that_overflows() {
    let mut ops = vec![Op::Load(0); MAX_PROGRAM_STACK + 1];
    ops.extend(std::iter::repeat_n(Op::Add, MAX_PROGRAM_STACK));
    ops.push(Op::Store(0));
    let b = assemble(1, 1, &[], &ops, MAX_PROGRAM_STACK + 1);
    assert_eq!(
        Program::decode(&b).unwrap_err(),
        ImageError::StackOverflow {
            offset: 2 * MAX_PROGRAM_STACK as u16
        }
    );
    // At capacity exactly it decodes.
    let mut ops = vec![Op::Load(0); MAX_PROGRAM_STACK];
    ops.extend(std::iter::repeat_n(Op::Add, MAX_PROGRAM_STACK - 1));
    ops.push(Op::Store(0));
    let b = assemble(1, 1, &[], &ops, MAX_PROGRAM_STACK);
    let p = Program::decode(&b).unwrap();
    let mut out = [0.0];
    p.eval(&[1.0], &mut out).unwrap();
    assert_eq!(out[0], MAX_PROGRAM_STACK as f32);
}

#[test]
fn every_function_matches_f64_closely() {
    for (i, f) in Func::ALL.iter().enumerate() {
        let b = assemble(1, 1, &[], &[Op::Load(0), Op::Func(*f), Op::Store(0)], 1);
        let p = Program::decode(&b).unwrap();
        let x = 0.3f32 + 0.1 * i as f32;
        let mut out = [0.0];
        p.eval(&[x], &mut out).unwrap();
        let x = x as f64;
        let exact = match f {
            Func::Sin => x.sin(),
            Func::Cos => x.cos(),
            Func::Tan => x.tan(),
            Func::Exp => x.exp(),
            Func::Log => x.ln(),
            Func::Sqrt => x.sqrt(),
            Func::Abs => x.abs(),
            Func::Atan => x.atan(),
            Func::Tanh => x.tanh(),
        };
        assert!(
            (out[0] as f64 - exact).abs() <= 4.0 * f32::EPSILON as f64 * exact.abs(),
            "{}: {} vs {exact}",
            f.name(),
            out[0]
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    /// Random bytes: decode answers (almost always an error) and never panics; what decodes evaluates.
    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..96)) {
        if let Ok(p) = Program::decode(&bytes) {
            let inputs = vec![0.5f32; p.n_inputs()];
            let mut out = vec![0.0f32; p.n_outputs()];
            prop_assert!(p.eval(&inputs, &mut out).is_ok());
        }
    }

    /// Mutations of a valid program: decode either refuses or gives a program that evaluates.
    #[test]
    fn mutated_programs_never_panic(pos in 0usize..64, byte in any::<u8>(), x in -3.0f32..3.0) {
        let mut b = sample();
        let i = pos % b.len();
        b[i] = byte;
        if let Ok(p) = Program::decode(&b) {
            let inputs = vec![x; p.n_inputs()];
            let mut out = vec![0.0f32; p.n_outputs()];
            prop_assert!(p.eval(&inputs, &mut out).is_ok());
        }
    }
}

/// Remembered library calls ([`Program::eval`]'s memo) give the bits of fresh ones: a program with the
/// same calls repeated, more distinct calls than the memo holds, and sine and cosine of one argument.
#[test]
fn remembered_calls_give_the_bits_of_fresh_ones() {
    use rand::{Rng, SeedableRng};
    let funcs = [
        Func::Sin,
        Func::Cos,
        Func::Tan,
        Func::Exp,
        Func::Atan,
        Func::Tanh,
    ];
    // out_k = f_k(x_(k mod 2)), for the functions above twice over (12 outputs, 6 distinct calls per
    // input), then cos(x0) and sin(x0) once more.
    let mut ops = Vec::new();
    let mut expect: Vec<(Func, usize)> = Vec::new();
    for rep in 0..2 {
        for (k, &f) in funcs.iter().enumerate() {
            let slot = (k + rep) % 2;
            ops.extend([
                Op::Load(slot as u8),
                Op::Func(f),
                Op::Store(expect.len() as u8),
            ]);
            expect.push((f, slot));
        }
    }
    for f in [Func::Cos, Func::Sin] {
        ops.extend([Op::Load(0), Op::Func(f), Op::Store(expect.len() as u8)]);
        expect.push((f, 0));
    }
    let bytes = assemble(2, expect.len(), &[], &ops, 1);
    let p = Program::decode(&bytes).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x4e30);
    let mut out = vec![0.0f32; expect.len()];
    for i in 0..2000 {
        let x = match i {
            0 => [0.0, -0.0],
            1 => [f32::NAN, 1e30],
            _ => [
                rng.random_range(-10.0f32..10.0),
                f32::from_bits(rng.random::<u32>()),
            ],
        };
        p.eval(&x, &mut out).unwrap();
        for (k, &(f, slot)) in expect.iter().enumerate() {
            assert_eq!(
                out[k].to_bits(),
                f.apply(x[slot]).to_bits(),
                "{f:?}({})",
                x[slot]
            );
        }
    }
}

/// The instruction table read literally: a stack machine over the decoded instructions ([`Program::ops`]),
/// each library call made afresh.
fn reference_eval(p: &Program<'_>, inputs: &[f32], out: &mut [f32]) {
    let mut stack: Vec<f32> = Vec::new();
    let mut regs = std::collections::HashMap::new();
    for (_, op) in p.ops() {
        match op {
            Op::Tee(r) => {
                regs.insert(r, *stack.last().unwrap());
            }
            Op::Recall(r) => stack.push(regs[&r]),
            Op::Load(i) => stack.push(inputs[i as usize]),
            Op::Const(i) => stack.push(p.constant(i as usize)),
            Op::Store(i) => out[i as usize] = stack.pop().unwrap(),
            Op::Add | Op::Sub | Op::Mul | Op::Div | Op::Atan2 => {
                let b = stack.pop().unwrap();
                let a = stack.pop().unwrap();
                stack.push(match op {
                    Op::Add => a + b,
                    Op::Sub => a - b,
                    Op::Mul => a * b,
                    Op::Div => a / b,
                    _ => libm::atan2f(a, b),
                });
            }
            Op::Neg | Op::Powi(_) | Op::Func(_) => {
                let a = stack.pop().unwrap();
                stack.push(match op {
                    Op::Neg => -a,
                    Op::Powi(k) => powi(a, k),
                    Op::Func(f) => f.apply(a),
                    _ => unreachable!(),
                });
            }
        }
    }
    assert!(stack.is_empty());
}

#[test]
fn interpreter_equals_the_instruction_table_on_random_programs() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x1e7);
    // One working memory across all cases, as the evaluator keeps one across steps: what earlier
    // programs left in its stack, registers and memo must not change a result.
    let mut work = Workspace::new();
    for case in 0..3000 {
        let (n_inputs, n_outputs, n_consts) = (
            rng.random_range(1..6usize),
            rng.random_range(1..5usize),
            rng.random_range(1..4usize),
        );
        let consts: Vec<f32> = (0..n_consts).map(|_| rng.random_range(-3.0..3.0)).collect();
        let mut ops = Vec::new();
        let mut max_depth = 0usize;
        let mut teed: Vec<u8> = Vec::new();
        for o in 0..n_outputs {
            let mut depth = 0usize;
            for _ in 0..rng.random_range(1..30) {
                let choice = rng.random_range(0..11);
                let op = if choice == 10 && depth > 0 {
                    let r = rng.random_range(0..MAX_PROGRAM_REGS) as u8;
                    teed.push(r);
                    Op::Tee(r)
                } else if depth == 0 || (choice < 4 && depth < MAX_PROGRAM_STACK) {
                    if !teed.is_empty() && rng.random_bool(0.2) {
                        Op::Recall(teed[rng.random_range(0..teed.len())])
                    } else if rng.random_bool(0.7) {
                        Op::Load(rng.random_range(0..n_inputs) as u8)
                    } else {
                        Op::Const(rng.random_range(0..n_consts) as u16)
                    }
                } else if choice < 7 || depth < 2 {
                    match rng.random_range(0..3) {
                        0 => Op::Neg,
                        1 => Op::Powi(
                            rng.random_range(1..4) * if rng.random_bool(0.3) { -1 } else { 1 },
                        ),
                        _ => Op::Func(Func::ALL[rng.random_range(0..Func::ALL.len())]),
                    }
                } else {
                    [Op::Add, Op::Sub, Op::Mul, Op::Div, Op::Atan2][rng.random_range(0..5)]
                };
                let (pops, pushes) = op.arity();
                depth = depth - pops + pushes;
                max_depth = max_depth.max(depth);
                ops.push(op);
            }
            while depth > 1 {
                ops.push([Op::Add, Op::Mul, Op::Sub][rng.random_range(0..3)]);
                depth -= 1;
            }
            ops.push(Op::Store(o as u8));
        }
        let bytes = assemble(n_inputs, n_outputs, &consts, &ops, max_depth);
        let p = Program::decode(&bytes).unwrap_or_else(|e| panic!("case {case}: {e:?}"));
        for _ in 0..4 {
            let x: Vec<f32> = (0..n_inputs).map(|_| rng.random_range(-4.0..4.0)).collect();
            let (mut got, mut want) = (vec![0.0f32; n_outputs], vec![0.0f32; n_outputs]);
            p.eval(&x, &mut got).unwrap();
            reference_eval(&p, &x, &mut want);
            for (g, w) in got.iter().zip(&want) {
                assert_eq!(g.to_bits(), w.to_bits(), "case {case}: {ops:?} at {x:?}");
            }
            p.eval_with(&x, &mut got, &mut work).unwrap();
            for (g, w) in got.iter().zip(&want) {
                assert_eq!(
                    g.to_bits(),
                    w.to_bits(),
                    "case {case}, kept workspace: {ops:?} at {x:?}"
                );
            }
        }
    }
}

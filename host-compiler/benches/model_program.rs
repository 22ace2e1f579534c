//! The model program of Example 4.9 (issue 13): the law u = λ(x)w with κ = 0 and λ = R(θ) = Γ (3.31),
//! Γ taken from `examples/fl-4-9.toml` by the Lie derivatives of Def 3.5 and compiled to the target's
//! bytecode. Its size, the time of one f32 evaluation through the shared evaluator (`Program::eval`, what
//! the firmware runs) against the f64 tree walk of the same expressions in the same run (ratio = tree
//! time / program time), and its f32 rounding bound over Init × {‖w‖∞ ≤ 2}.
//!
//! Rows: `model_program_bytes`, `model_program_eval_ns` (with baseline), `model_program_error_bound`.

use criterion::{criterion_group, Criterion};
use host_compiler::benchkit::{write_rows, Row};
use host_compiler::expr::compile::compile;
use host_compiler::expr::interval::{rounding_bound, Interval};
use host_compiler::expr::{Expr, Point, Var};
use shared_types::program::Program;
use std::hint::black_box;
use std::time::{Duration, Instant};

/// Median wall time of one call of `f` (which runs `reps` evaluations) per evaluation, over runs
/// lasting at least `budget`.
fn median_ns(mut f: impl FnMut(), reps: usize, budget: Duration) -> f64 {
    let start = Instant::now();
    let mut times = Vec::new();
    while start.elapsed() < budget || times.len() < 5 {
        let s = Instant::now();
        f();
        times.push(s.elapsed().as_secs_f64() * 1e9 / reps as f64);
    }
    times.sort_by(|a, b| a.total_cmp(b));
    times[times.len() / 2]
}

fn bench(c: &mut Criterion) {
    let path = format!("{}/../examples/fl-4-9.toml", env!("CARGO_MANIFEST_DIR"));
    let problem = host_compiler::spec::load(&path).expect("the shipped example parses");
    let nl = problem.nonlinear.expect("a feedback-linearizable plant");
    let pv = nl.names.param_values();
    // Γ from the spec loader's Lie derivatives (Def 3.5 at Init's centre).
    let rd = &nl.derivatives;
    // u_j = Σ_k Γ_jk w_k: Γ = R(θ) is its own inverse, so λ = Γ⁻¹ = Γ (checked at a point below).
    let m = nl.system.m();
    let law: Vec<Expr> = (0..m)
        .map(|j| {
            (0..m).fold(Expr::c(0.0), |acc, k| {
                Expr::add(
                    acc,
                    Expr::mul(rd.gamma[j][k].clone(), Expr::var(Var::Input(k as u16))),
                )
            })
        })
        .collect();
    let x = [0.05, 0.2, -0.03, 0.9, 0.7, 0.1];
    let g = host_compiler::expr::diff::eval_matrix(
        &rd.gamma,
        &Point {
            x: &x,
            u: &[],
            p: &pv,
        },
    );
    for i in 0..m {
        for j in 0..m {
            let gg: f64 = (0..m).map(|k| g[i][k] * g[k][j]).sum();
            assert!(
                (gg - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12,
                "Γ·Γ ≠ I"
            );
        }
    }
    let n = nl.system.n();
    let compiled = compile(&law, n, m, &pv).unwrap();
    let bytes = compiled.bytes.len();
    let program = Program::decode(&compiled.bytes).unwrap();
    let inputs: Vec<f32> = x.iter().chain(&[1.2, -0.7]).map(|&v| v as f32).collect();
    let mut out = vec![0.0f32; m];
    println!(
        "Example 4.9 law u = R(θ)w: {bytes} bytes, {} constants, {} bytes of code, stack {}",
        program.n_consts(),
        program.code_len(),
        program.max_stack()
    );

    let mut grp = c.benchmark_group("model_program");
    grp.sample_size(20)
        .measurement_time(Duration::from_secs(2))
        .warm_up_time(Duration::from_millis(500));
    grp.bench_function("fl_4_9_law_f32", |b| {
        b.iter(|| {
            program
                .eval(black_box(&inputs), black_box(&mut out))
                .unwrap()
        })
    });
    grp.finish();

    const REPS: usize = 100_000;
    let ours = median_ns(
        || {
            for _ in 0..REPS {
                program
                    .eval(black_box(&inputs), black_box(&mut out))
                    .unwrap();
            }
        },
        REPS,
        Duration::from_secs(2),
    );
    let w = [1.2, -0.7];
    let law_bound: Vec<Expr> = law.iter().map(|e| e.bind_params(&pv)).collect();
    let tree = median_ns(
        || {
            for _ in 0..REPS {
                let pt = Point {
                    x: black_box(&x),
                    u: black_box(&w),
                    p: &pv,
                };
                for e in &law_bound {
                    black_box(e.eval(&pt));
                }
            }
        },
        REPS,
        Duration::from_secs(2),
    );
    let xbox: Vec<Interval> = problem
        .init
        .lo
        .iter()
        .zip(&problem.init.hi)
        .map(|(&l, &h)| Interval::new(l, h))
        .collect();
    let wbox = vec![Interval::new(-2.0, 2.0); m];
    let bound = rounding_bound(&compiled, &xbox, &wbox)
        .unwrap()
        .iter()
        .map(|b| b.error)
        .fold(0.0, f64::max);
    println!(
        "f32 program {ours:.1} ns per evaluation, f64 tree walk {tree:.1} ns; rounding bound over Init × \
         ‖w‖∞ ≤ 2: {bound:.3e}"
    );
    write_rows(
        "model_program",
        &[
            Row::new("model_program_bytes", bytes as f64, "bytes"),
            Row::with_baseline("model_program_eval_ns", ours, "ns", tree, tree / ours),
            Row::new("model_program_error_bound", bound, "abs, u"),
        ],
    )
    .unwrap();
}

criterion_group!(benches, bench);

fn main() {
    benches();
    Criterion::default().configure_from_args().final_summary();
}

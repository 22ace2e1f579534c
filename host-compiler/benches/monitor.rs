//! The task's monitor (issue 46) on the host: the shared evaluator (`shared_types::monitor`, what the
//! firmware runs) against the host's f32 reference (`host_compiler::monitor::reference`) at every sample
//! of ≥ 10⁴ seeded traces: random formulas over boxes, balls, polytopes and half-spaces on random walks,
//! and every monitorable example's own program on random walks through its state space. Rows:
//! `monitor_mismatches` (samples where the bounds or the verdict differ in any bit; target 0),
//! `monitor_traces`, and per example `monitor_arena_bytes_<example>` (the evaluator's arena, the part of
//! its RAM the program sizes; the target's total is `hil-bench`'s `monitor_ram_bytes`).

use host_compiler::benchkit::{write_rows, Row};
use host_compiler::monitor::{reference, AtomSet, Program};
use host_compiler::robustness::mtl::{Expr, Interval, Span};
use host_compiler::spec::{Coords, SetDesc, Shape};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use shared_types::monitor::{Monitor, MonitorProgram};

/// Samples where the streaming evaluator and the reference differ, over `trace`.
fn mismatches(prog: &Program, trace: &[Vec<f32>]) -> usize {
    let body = prog.encode();
    let section = MonitorProgram::decode(&body, prog.n).expect("a compiled program decodes");
    let want = reference::reports(prog, &section, trace);
    let mut arena = vec![0u32; section.words()];
    let mut mon = Monitor::new(section, &mut arena).expect("arena");
    trace
        .iter()
        .zip(&want)
        .filter(|(x, w)| {
            let g = mon.update(x);
            g.lo.to_bits() != w.lo.to_bits()
                || g.hi.to_bits() != w.hi.to_bits()
                || g.verdict != w.verdict
        })
        .count()
}

fn walk(rng: &mut ChaCha8Rng, lo: &[f64], hi: &[f64], len: usize) -> Vec<Vec<f32>> {
    let mut x: Vec<f64> = lo
        .iter()
        .zip(hi)
        .map(|(l, h)| rng.random_range(*l..=*h))
        .collect();
    (0..len)
        .map(|_| {
            for (i, v) in x.iter_mut().enumerate() {
                let w = (hi[i] - lo[i]).max(1e-3);
                *v = (*v + rng.random_range(-0.1 * w..0.1 * w)).clamp(lo[i], hi[i]);
            }
            x.iter().map(|&v| v as f32).collect()
        })
        .collect()
}

fn random_set(rng: &mut ChaCha8Rng) -> SetDesc {
    let c = [rng.random_range(-2.0..2.0), rng.random_range(-2.0..2.0)];
    let shape = match rng.random_range(0..3) {
        0 => Shape::Box {
            lo: vec![c[0] - 0.7, c[1] - 0.4],
            hi: vec![c[0] + 0.5, c[1] + 0.9],
        },
        1 => Shape::Ball {
            center: c.to_vec(),
            radius: rng.random_range(0.2..1.5),
        },
        _ => Shape::Polytope {
            A: host_compiler::spec::Matrix {
                rows: 2,
                cols: 2,
                data: (0..4).map(|_| rng.random_range(-1.0..1.0)).collect(),
            },
            b: vec![rng.random_range(-0.5..1.0), rng.random_range(-0.5..1.0)],
        },
    };
    SetDesc {
        shape,
        coords: Coords::State,
    }
}

fn random_expr(rng: &mut ChaCha8Rng, depth: usize) -> Expr {
    let span = Span::new(0, 0);
    if depth == 0 || rng.random_bool(0.25) {
        return Expr::Set {
            name: format!("S{}", rng.random_range(0..3)),
            span,
        };
    }
    let a = rng.random_range(0..4) as f64;
    let i = Interval {
        a,
        b: a + rng.random_range(0..8) as f64,
    };
    let op = rng.random_range(0..7);
    let mut sub = || Box::new(random_expr(rng, depth - 1));
    match op {
        0 => Expr::Not(sub()),
        1 => Expr::And(vec![*sub(), *sub()]),
        2 => Expr::Or(vec![*sub(), *sub()]),
        3 => Expr::Eventually(i, sub()),
        4 => Expr::Always(i, sub()),
        5 => Expr::Until(i, sub(), sub()),
        _ => Expr::Release(i, sub(), sub()),
    }
}

fn main() {
    let mut rng = ChaCha8Rng::seed_from_u64(46_000);
    let (mut traces, mut bad) = (0usize, 0usize);
    let mut rows = Vec::new();
    // The examples' own programs.
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples");
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .expect("examples")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    for path in files {
        let stem = path
            .file_stem()
            .unwrap()
            .to_string_lossy()
            .replace('-', "_");
        let problem = match host_compiler::spec::load(&path) {
            Ok(p) => p,
            Err(e) => {
                println!("{stem}: not loaded ({e})");
                continue;
            }
        };
        let prog = match Program::for_problem(&problem) {
            Ok(p) => p,
            Err(e) => {
                println!("{stem}: no monitor ({e})");
                continue;
            }
        };
        let (words, _) = prog.footprint();
        rows.push(Row::new(
            &format!("monitor_arena_bytes_{stem}"),
            4.0 * words as f64,
            "bytes",
        ));
        // A box over Init and Goal's neighbourhood: the Init box widened by its own size and by 2.
        let (lo, hi): (Vec<f64>, Vec<f64>) = problem
            .init
            .lo
            .iter()
            .zip(&problem.init.hi)
            .map(|(l, h)| (l - (h - l) - 2.0, h + (h - l) + 2.0))
            .unzip();
        let runs = 20;
        let mut m = 0;
        for _ in 0..runs {
            let tr = walk(&mut rng, &lo, &hi, prog.horizon + 3);
            m += mismatches(&prog, &tr);
        }
        println!(
            "{stem}: {} atoms, {} nodes, N = {}, arena {} bytes; {runs} traces, {m} mismatching samples",
            prog.atoms.len(),
            prog.nodes.len(),
            prog.horizon,
            4 * words
        );
        traces += runs;
        bad += m;
    }
    // Random formulas on random walks in the plane.
    let mut random = 0;
    while random < 10_000 {
        let sets: Vec<(String, AtomSet)> = (0..3)
            .map(|i| (format!("S{i}"), AtomSet::Set(random_set(&mut rng))))
            .collect();
        let e = random_expr(&mut rng, 1 + random % 4);
        let horizon = rng.random_range(0..40);
        let Ok(prog) = Program::compile(&e, &sets, 2, 1.0, horizon) else {
            continue;
        };
        let tr = walk(&mut rng, &[-3.0, -3.0], &[3.0, 3.0], horizon + 3);
        bad += mismatches(&prog, &tr);
        random += 1;
    }
    traces += random;
    println!("monitor: {traces} traces ({random} random formulas), {bad} mismatching samples");
    rows.push(Row::new("monitor_mismatches", bad as f64, "samples"));
    rows.push(Row::new("monitor_traces", traces as f64, "traces"));
    let path = write_rows("monitor", &rows).expect("rows written");
    println!("rows: {}", path.display());
    assert_eq!(bad, 0, "the evaluator and the reference differ");
}

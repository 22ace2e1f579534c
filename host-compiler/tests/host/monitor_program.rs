//! The on-target monitor's program (issue 46): the streaming evaluator of `shared_types::monitor` against
//! the host's reference of the same semantics, bit for bit at every step, on seeded random formulas and
//! runs; the final value against the f64 `mtl` within the stated rounding bound; the decoder's refusals.

use host_compiler::monitor::reference::{atom_rounding_bound, reports};
use host_compiler::monitor::{AtomSet, MonitorCompileError, Program};
use host_compiler::robustness::mtl::{Expr, Interval, NamedSet, Span, Trace};
use host_compiler::spec::{Coords, Matrix, SetDesc, Shape};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use shared_types::monitor::{Monitor, MonitorError, MonitorProgram, Verdict};

fn random_set(rng: &mut ChaCha8Rng, polytopes: bool) -> SetDesc {
    let c = [rng.random_range(-2.0..2.0), rng.random_range(-2.0..2.0)];
    let kind = rng.random_range(0..if polytopes { 4 } else { 3 });
    let coords = match rng.random_range(0..3) {
        0 => Coords::StateIndices(vec![1]),
        _ => Coords::State,
    };
    let d = match &coords {
        Coords::StateIndices(v) => v.len(),
        _ => 2,
    };
    let shape = match kind {
        0 => {
            let w: Vec<f64> = (0..d).map(|_| rng.random_range(0.1..1.5)).collect();
            Shape::Box {
                lo: (0..d).map(|i| c[i] - w[i]).collect(),
                hi: (0..d).map(|i| c[i] + w[i]).collect(),
            }
        }
        1 | 2 => Shape::Ball {
            center: c[..d].to_vec(),
            radius: rng.random_range(0.1..1.5),
        },
        _ => {
            let rows = rng.random_range(1..4);
            let data: Vec<f64> = (0..rows * d).map(|_| rng.random_range(-1.0..1.0)).collect();
            Shape::Polytope {
                A: Matrix {
                    rows,
                    cols: d,
                    data,
                },
                b: (0..rows).map(|_| rng.random_range(-0.5..1.0)).collect(),
            }
        }
    };
    SetDesc { shape, coords }
}

fn interval(rng: &mut ChaCha8Rng) -> Interval {
    let a = rng.random_range(0..4) as f64;
    let b = if rng.random_bool(0.1) {
        f64::INFINITY
    } else {
        a + rng.random_range(0..6) as f64
    };
    Interval { a, b }
}

fn random_expr(rng: &mut ChaCha8Rng, depth: usize, names: &[String]) -> Expr {
    let span = Span::new(0, 0);
    if depth == 0 || rng.random_bool(0.25) {
        return match rng.random_range(0..12) {
            0 => Expr::True,
            1 => Expr::False,
            _ => Expr::Set {
                name: names[rng.random_range(0..names.len())].clone(),
                span,
            },
        };
    }
    let op = rng.random_range(0..9);
    let i = interval(rng);
    let mut sub = || Box::new(random_expr(rng, depth - 1, names));
    match op {
        0 => Expr::Not(sub()),
        1 => Expr::And(vec![*sub(), *sub()]),
        2 => Expr::Or(vec![*sub(), *sub(), *sub()]),
        3 => Expr::Implies(sub(), sub()),
        4 => Expr::Eventually(i, sub()),
        5 => Expr::Always(i, sub()),
        6 | 7 => Expr::Until(i, sub(), sub()),
        _ => Expr::Release(i, sub(), sub()),
    }
}

/// A random walk in the plane, rounded to f32.
fn random_run(rng: &mut ChaCha8Rng, len: usize) -> Vec<Vec<f32>> {
    let mut x = [rng.random_range(-2.0f64..2.0), rng.random_range(-2.0..2.0)];
    (0..len)
        .map(|_| {
            for v in &mut x {
                *v = (*v + rng.random_range(-0.4..0.4)).clamp(-3.0, 3.0);
            }
            x.iter().map(|&v| v as f32).collect()
        })
        .collect()
}

fn sets_for(rng: &mut ChaCha8Rng, polytopes: bool) -> Vec<(String, AtomSet)> {
    let mut sets: Vec<(String, AtomSet)> = (0..3)
        .map(|i| (format!("S{i}"), AtomSet::Set(random_set(rng, polytopes))))
        .collect();
    sets.push((
        "Unsafe".into(),
        AtomSet::Union(vec![random_set(rng, polytopes), random_set(rng, polytopes)]),
    ));
    sets.push((
        "H".into(),
        AtomSet::HalfSpace {
            a: vec![rng.random_range(-1.0..1.0), 1.0],
            b: rng.random_range(-1.0..1.0),
        },
    ));
    sets
}

#[test]
fn the_streaming_monitor_equals_the_reference_bit_for_bit_at_every_step() {
    let mut rng = ChaCha8Rng::seed_from_u64(46);
    let mut compared = 0usize;
    let mut skipped = 0usize;
    let mut decided = [0usize; 4];
    for case in 0..700 {
        let sets = sets_for(&mut rng, true);
        let names: Vec<String> = sets.iter().map(|(n, _)| n.clone()).collect();
        let expr = random_expr(&mut rng, 1 + case % 4, &names);
        let horizon = rng.random_range(0..28);
        let prog = match Program::compile(&expr, &sets, 2, 1.0, horizon) {
            Ok(p) => p,
            // Deep random formulas may exceed the firmware's node capacity: refused, and skipped here.
            Err(MonitorCompileError::Capacity { .. }) => {
                skipped += 1;
                continue;
            }
            Err(e) => panic!("case {case}: {e} for {expr}"),
        };
        let body = prog.encode();
        let section = MonitorProgram::decode(&body, 2).expect("a compiled program decodes");
        let run = random_run(&mut rng, horizon + 4);
        let want = reports(&prog, &section, &run);
        let mut arena = vec![0u32; section.words()];
        let mut mon = Monitor::new(section, &mut arena).expect("arena sized by the program");
        for (k, x) in run.iter().enumerate() {
            let got = mon.update(x);
            let w = want[k];
            assert!(
                got.lo.to_bits() == w.lo.to_bits()
                    && got.hi.to_bits() == w.hi.to_bits()
                    && got.verdict == w.verdict,
                "case {case}, step {k} (N = {horizon}): streaming {got:?}, reference {w:?}\nformula {expr}\nnodes {:?}",
                prog.nodes
            );
            compared += 1;
        }
        decided[want[horizon].verdict as usize] += 1;
        // At N every value is known.
        assert_eq!(want[horizon].lo.to_bits(), want[horizon].hi.to_bits());
    }
    // The cases exercise both verdicts, not only one.
    assert!(
        decided[Verdict::Satisfied as usize] > 50 && decided[Verdict::Violated as usize] > 50,
        "{decided:?}"
    );
    assert!(compared > 10_000, "{compared}");
    assert!(
        skipped > 0 && skipped < 100,
        "{skipped} formulas over the capacity"
    );
}

#[test]
fn the_monitor_agrees_with_the_f64_mtl_within_the_stated_rounding_bound() {
    let mut rng = ChaCha8Rng::seed_from_u64(4646);
    let h = 0.25;
    let mut worst = 0.0f64;
    for case in 0..300 {
        // Boxes, balls and half-spaces: the atoms whose monitor value is the Euclidean signed distance.
        let sets: Vec<(String, AtomSet)> = sets_for(&mut rng, false)
            .into_iter()
            .filter(|(n, _)| n != "Unsafe")
            .collect();
        let names: Vec<String> = sets.iter().map(|(n, _)| n.clone()).collect();
        let mut expr = random_expr(&mut rng, 1 + case % 4, &names);
        // Windows in seconds at h = 0.25 (exact in binary, so the f64 windows are the monitor's).
        scale(&mut expr, h);
        let horizon = rng.random_range(1..24);
        let prog = match Program::compile(&expr, &sets, 2, h, horizon) {
            Ok(p) => p,
            Err(MonitorCompileError::Capacity { .. }) => continue,
            Err(e) => panic!("case {case}: {e}"),
        };
        let body = prog.encode();
        let section = MonitorProgram::decode(&body, 2).expect("decodes");
        let run = random_run(&mut rng, horizon + 1);
        let mut arena = vec![0u32; section.words()];
        let mut mon = Monitor::new(section, &mut arena).expect("arena");
        let mut last = None;
        for x in &run {
            last = Some(mon.update(x));
        }
        let got = last.expect("a report");
        assert_eq!(got.lo.to_bits(), got.hi.to_bits(), "decided at N");
        // The f64 mtl on the same samples (as f64), times k·h.
        let signals = vec!["x1".to_string(), "x2".to_string()];
        let named: Vec<NamedSet> = sets
            .iter()
            .map(|(n, s)| {
                let region = match s {
                    AtomSet::Set(d) => d.to_region(2).expect("region"),
                    AtomSet::HalfSpace { a, b } => Box::new(
                        host_compiler::geometry::Polytope::new(2, a.clone(), vec![*b])
                            .expect("half-space"),
                    ),
                    AtomSet::Union(_) => unreachable!(),
                };
                NamedSet::euclidean(n.clone(), signals.clone(), region)
            })
            .collect();
        let trace = Trace::new(
            (0..run.len()).map(|k| k as f64 * h).collect(),
            signals.clone(),
            (0..2)
                .map(|c| run.iter().map(|x| x[c] as f64).collect())
                .collect(),
        )
        .expect("trace");
        let rho = host_compiler::robustness::mtl::robustness(&expr.to_string(), &trace, &named)
            .expect("mtl evaluates")[0];
        let bound = run
            .iter()
            .flat_map(|x| prog.atoms.iter().map(move |w| atom_rounding_bound(w, x)))
            .fold(0.0, f64::max);
        let diff = if rho.is_infinite() || (got.lo as f64).is_infinite() {
            assert_eq!(
                rho, got.lo as f64,
                "case {case}: {expr}\nN = {horizon}, nodes {:?}",
                prog.nodes
            );
            0.0
        } else {
            (got.lo as f64 - rho).abs()
        };
        assert!(
            diff <= bound,
            "case {case}: monitor {} vs mtl {rho}: {diff:e} > {bound:e}\n{expr}",
            got.lo
        );
        worst = worst.max(diff / bound.max(f64::MIN_POSITIVE));
    }
    assert!(
        worst > 0.0,
        "some rounding is seen, so the comparison is not vacuous"
    );
}

/// Every interval of `e` scaled by `h` (samples to seconds).
fn scale(e: &mut Expr, h: f64) {
    let s = |i: &mut Interval| {
        i.a *= h;
        i.b *= h;
    };
    match e {
        Expr::Not(x) => scale(x, h),
        Expr::And(v) | Expr::Or(v) => v.iter_mut().for_each(|x| scale(x, h)),
        Expr::Implies(l, r) => {
            scale(l, h);
            scale(r, h)
        }
        Expr::Eventually(i, x) | Expr::Always(i, x) => {
            s(i);
            scale(x, h)
        }
        Expr::Until(i, l, r) | Expr::Release(i, l, r) => {
            s(i);
            scale(l, h);
            scale(r, h)
        }
        _ => {}
    }
}

#[test]
fn a_reach_avoid_monitor_says_violated_at_the_sample_inside_unsafe_and_satisfied_in_goal() {
    let goal = SetDesc {
        shape: Shape::Ball {
            center: vec![2.0, 0.0],
            radius: 0.5,
        },
        coords: Coords::State,
    };
    let wall = SetDesc {
        shape: Shape::Box {
            lo: vec![0.9, -1.0],
            hi: vec![1.1, 1.0],
        },
        coords: Coords::State,
    };
    let prog = Program::reach_avoid(&goal, &[wall], 2, 30).expect("compiles");
    let body = prog.encode();
    // Straight through the wall at y = 0: samples every 0.25 from x = 0.
    let through: Vec<Vec<f32>> = (0..31).map(|k| vec![0.25 * k as f32, 0.0]).collect();
    let section = MonitorProgram::decode(&body, 2).expect("decodes");
    let mut arena = vec![0u32; section.words()];
    let mut mon = Monitor::new(section, &mut arena).expect("arena");
    let verdicts: Vec<Verdict> = through.iter().map(|x| mon.update(x).verdict).collect();
    // x = 1.0 (k = 4) is inside the wall: violated from that sample on, pending before.
    assert!(
        verdicts[..4].iter().all(|v| *v == Verdict::Pending),
        "{verdicts:?}"
    );
    assert!(
        verdicts[4..].iter().all(|v| *v == Verdict::Violated),
        "{verdicts:?}"
    );
    // Around the wall (y = 1.5 while crossing x = 1): satisfied once in Goal, with the upper bound the
    // least clearance so far.
    let around: Vec<Vec<f32>> = (0..31)
        .map(|k| {
            let x = 0.25 * k as f32;
            vec![x, if (0.5..=1.5).contains(&x) { 1.5 } else { 0.0 }]
        })
        .collect();
    let section = MonitorProgram::decode(&body, 2).expect("decodes");
    let mut arena = vec![0u32; section.words()];
    let mut mon = Monitor::new(section, &mut arena).expect("arena");
    let reports: Vec<_> = around.iter().map(|x| mon.update(x)).collect();
    let first_in_goal = around
        .iter()
        .position(|x| ((x[0] - 2.0).powi(2) + x[1].powi(2)).sqrt() < 0.5)
        .expect("enters Goal");
    assert_eq!(reports[first_in_goal].verdict, Verdict::Satisfied);
    assert!(reports[..first_in_goal]
        .iter()
        .all(|r| r.verdict == Verdict::Pending && r.hi > 0.0 && r.lo < 0.0));
}

#[test]
fn the_decoder_refuses_a_bad_section_and_never_panics() {
    let goal = SetDesc {
        shape: Shape::Box {
            lo: vec![1.0, -1.0],
            hi: vec![2.0, 1.0],
        },
        coords: Coords::State,
    };
    let prog = Program::reach_avoid(&goal, &[goal.clone()], 2, 10).expect("compiles");
    let body = prog.encode();
    assert!(MonitorProgram::decode(&body, 2).is_ok());
    assert_eq!(MonitorProgram::decode(&body, 3), Err(MonitorError::Dims));
    assert_eq!(
        MonitorProgram::decode(&body[..body.len() - 4], 2),
        Err(MonitorError::Length)
    );
    // The root's child listed twice: not a tree.
    let mut twice = body.clone();
    let last = twice.len() - 20;
    let c1 = u32::from_le_bytes(twice[last + 4..last + 8].try_into().unwrap());
    twice[last + 8..last + 12].copy_from_slice(&c1.to_le_bytes());
    assert!(matches!(
        MonitorProgram::decode(&twice, 2),
        Err(MonitorError::Node(_))
    ));
    // Every single-word change decodes or is refused; what decodes runs to the end without panicking.
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for _ in 0..3000 {
        let mut b = body.clone();
        let w = rng.random_range(0..b.len() / 4);
        let v: u32 = match rng.random_range(0..3) {
            0 => rng.random(),
            1 => rng.random_range(0..40),
            _ => f32::NAN.to_bits(),
        };
        b[4 * w..4 * w + 4].copy_from_slice(&v.to_le_bytes());
        if let Ok(p) = MonitorProgram::decode(&b, 2) {
            let mut arena = vec![0u32; p.words()];
            let mut m = Monitor::new(p, &mut arena).expect("arena");
            for k in 0..14 {
                m.update(&[k as f32 * 0.2, 0.0]);
            }
        }
    }
}

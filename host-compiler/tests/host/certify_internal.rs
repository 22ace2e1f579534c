//! General switching (Theorem 4.24 for the sampled loop, `certify::internal`) on Example 4.25.
#![allow(non_snake_case)]

use host_compiler::synth::hybrid::{ball_starts, image, plan_run, HybridTask};
use host_compiler::verify::hybrid::monte_carlo_hybrid;

fn task(file: &str) -> HybridTask {
    let path = format!("{}/../examples/{file}", env!("CARGO_MANIFEST_DIR"));
    HybridTask::new(host_compiler::spec::load(&path).unwrap()).unwrap()
}

#[test]
fn example_4_25_run_is_certified() {
    let t = task("hybrid-internal-4-25.toml");
    let run = plan_run(&t, &[-5.0, 1.0, 2.0]).unwrap();
    for (i, s) in run.certificate.segments.iter().enumerate() {
        eprintln!(
            "segment {i}: delta {:.4} rows {} samples {} events {:?} eta {:.2e} exit {:?} binding {} | goal {:.3} unsafe {:.3} input {:.3} rcrit {:.2e}",
            s.delta, s.rows, s.samples, s.events, s.eta, s.exit, s.binding,
            s.base.delta_goal, s.base.delta_unsafe_intersample, s.base.delta_input, s.base.r_crit
        );
    }
    assert!(run.delta() > 0.0);
    // The image of this run, run by the shared evaluator against the exact hybrid flow from the ball's
    // interior and boundary: every run switches once and meets the task.
    let bytes = image(&t, std::slice::from_ref(&run)).unwrap();
    // Re-proved from the bytes alone.
    let rc = host_compiler::verify::hybrid::recheck(&t.plant, &t.property, None, t.steps, &bytes)
        .unwrap();
    eprintln!("{rc:?}");
    assert!(rc.iter().all(|r| r.ok), "{rc:?}");
    // An enlarged stored radius is refused.
    let mut big = run.clone();
    big.certificate.delta_stored *= 1.01;
    let bytes_big = image(&t, std::slice::from_ref(&big)).unwrap();
    let rc_big =
        host_compiler::verify::hybrid::recheck(&t.plant, &t.property, None, t.steps, &bytes_big)
            .unwrap();
    assert!(!rc_big[0].ok, "{rc_big:?}");
    // The stored detection threshold θ is what the firmware tests, so the re-proof certifies that one: a
    // θ still above twice the guard test's rounding bound (synthesis stores 1.25 times it) is re-proved
    // as stored, one below it is refused, naming the threshold.
    let theta = run.certificate.segments[0].exit.as_ref().unwrap().theta;
    let reproof = |scale: f32| {
        let mut r = run.clone();
        r.certificate.segments[0].exit.as_mut().unwrap().theta = theta * scale;
        let b = image(&t, std::slice::from_ref(&r)).unwrap();
        host_compiler::verify::hybrid::recheck(&t.plant, &t.property, None, t.steps, &b)
            .unwrap()
            .remove(0)
    };
    let lower = reproof(0.9);
    assert!(lower.ok, "{lower:?}");
    let too_low = reproof(0.5);
    assert!(!too_low.ok, "{too_low:?}");
    assert!(
        too_low.why.as_deref().unwrap_or("").contains("threshold"),
        "{too_low:?}"
    );
    let starts = ball_starts(&t, &run, 40, 40, 7);
    let rep = monte_carlo_hybrid(
        &t.plant,
        &t.property,
        None,
        t.initial,
        t.steps,
        &bytes,
        &starts,
    )
    .unwrap();
    eprintln!("{rep:?}");
    assert_eq!(rep.violations, 0, "{:?}", rep.first_violation);
    // Boundary starts are 1e-6 inside the stored radius: the f32 selection may refuse a few.
    assert!(
        rep.rejected <= 8,
        "{} of 40 boundary starts refused",
        rep.rejected
    );
    assert_eq!(rep.switched, rep.runs - rep.rejected);
    assert_eq!(rep.max_events, 1);
}

/// The exit check bounds a run's deviation at sample κ by ‖Ã^κ‖_P·r (the closed loop's powers,
/// `LoopConstants::power_norms`) instead of r: runs of Example 5.5's first segment from its ball's
/// boundary, simulated by the location's exact sampled loop, stay within it, and the factor is well
/// below 1 by the crossing (what the landing gains).
#[test]
fn a_segment_s_runs_contract_as_the_closed_loop_s_powers_say() {
    use host_compiler::linalg::p_norm;
    let t = task("hybrid-internal-5-5.toml");
    let run = plan_run(&t, &[-5.0, 1.0, 2.0]).unwrap();
    let loc = run.locations[0];
    let nom = &run.nominals[0];
    let power = t.constants[loc].power_norms(nom.steps() + 1);
    let P = t.designs[loc].P.as_ref();
    let (first, _) = run.certificate.segments[0].events.unwrap();
    assert!(power[first] < 0.9, "‖Ã^{first}‖_P = {}", power[first]);
    let delta = run.delta();
    for start in ball_starts(&t, &run, 0, 24, 11) {
        let x = t.lp(loc).simulate(&start, &nom.v).x;
        let r0 = p_norm(P, &sub(&start, &nom.x[0]));
        assert!(r0 <= delta * (1.0 + 1e-6), "{r0} > {delta}");
        for k in 0..=nom.steps() {
            let rk = p_norm(P, &sub(&x[k], &nom.x[k]));
            assert!(
                rk <= power[k] * r0 * (1.0 + 1e-9) + 1e-12,
                "sample {k}: {rk} > ‖Ã^k‖_P·{r0} = {}",
                power[k] * r0
            );
        }
    }
}

/// Lemma 4.23's safe transition as certified (item 4's landing bound through the crossing map, module
/// doc of `certify::internal`): runs of Example 5.5 from the first segment's certified ball (boundary and
/// interior), under the segment's law on the exact hybrid flow, seen switched by the stored f32 guard test,
/// are at that sample inside the second segment's certified ball. The δ this certifies is above the
/// ball-around-the-landing bound's 0.585 (the text: 0.8387).
#[test]
fn example_5_5_runs_land_in_the_next_segment_s_ball() {
    use host_compiler::linalg::p_norm;
    let t = task("hybrid-internal-5-5.toml");
    let run = plan_run(&t, &[-5.0, 1.0, 2.0]).unwrap();
    let (seg0, seg1) = (&run.certificate.segments[0], &run.certificate.segments[1]);
    eprintln!(
        "δ = {:.4} ({}), next δ = {:.4}",
        seg0.delta, seg0.binding, seg1.delta
    );
    assert!(seg0.delta > 0.7, "δ = {} ({})", seg0.delta, seg0.binding);
    let exit = seg0.exit.as_ref().unwrap();
    let (l0, l1) = (run.locations[0], run.locations[1]);
    let (nom, next) = (&run.nominals[0], &run.nominals[1]);
    let gain = &t.designs[l0].K;
    let metric_next = t.designs[l1].P.as_ref();
    let mut worst = 0.0f64;
    let starts = ball_starts(&t, &run, 200, 400, 5);
    for start in &starts {
        let (mut x, mut loc) = (start.clone(), l0);
        let mut landed = None;
        // Samples 0..=κ_f: the segment keeps rows 0..κ_f, and every run is seen switched by sample κ_f.
        for k in 0..=seg0.rows {
            // The evaluator's guard test: switched when fl(âᵀx − b̂) ≤ −θ.
            let g = exit
                .a
                .iter()
                .zip(&x)
                .fold(0.0f32, |acc, (a, v)| acc + a * *v as f32)
                - exit.b;
            if g <= -exit.theta {
                landed = Some(x.clone());
                break;
            }
            if k == seg0.rows {
                break;
            }
            let u: Vec<f64> = (0..gain.nrows())
                .map(|p| nom.v[k][p] + (0..x.len()).map(|q| gain[(p, q)] * x[q]).sum::<f64>())
                .collect();
            let step = t.plant.flow(loc, &x, &u).unwrap();
            (x, loc) = (step.x, step.loc);
        }
        let landed =
            landed.unwrap_or_else(|| panic!("the run from {start:?} was not seen switched"));
        assert_eq!(loc, l1);
        let d = p_norm(metric_next, &sub(&landed, &next.x[0]));
        assert!(
            d <= seg1.delta,
            "from {start:?}: landing {d} outside the next ball {}",
            seg1.delta
        );
        worst = worst.max(d);
    }
    eprintln!(
        "{} runs, farthest landing {worst:.4} of {:.4}",
        starts.len(),
        seg1.delta
    );
}

fn sub(a: &[f64], b: &[f64]) -> Vec<f64> {
    a.iter().zip(b).map(|(p, q)| p - q).collect()
}

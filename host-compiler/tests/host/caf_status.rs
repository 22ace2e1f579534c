//! Solver outcomes are statuses: not stabilizable (with the PBH certificate), margin unachievable,
//! infeasible; bad input is an error. Nothing here may panic.
#![allow(non_snake_case)]

use faer::{c64, Mat};
use host_compiler::caf::*;
use host_compiler::model::DiscretePlant;

fn diag(d: &[f64]) -> Mat<f64> {
    Mat::from_fn(d.len(), d.len(), |i, j| if i == j { d[i] } else { 0.0 })
}

fn col(v: &[f64]) -> Mat<f64> {
    Mat::from_fn(v.len(), 1, |i, _| v[i])
}

/// ‖w* A − λ w*‖ and ‖w* B‖ for a reported mode.
fn residuals(A: &Mat<f64>, B: &Mat<f64>, mode: &UncontrollableMode) -> (f64, f64) {
    let n = A.nrows();
    let w = &mode.left_eigenvector;
    let mut ra: f64 = 0.0;
    for j in 0..n {
        let s: c64 =
            (0..n).map(|i| w[i].conj() * A[(i, j)]).sum::<c64>() - mode.eigenvalue * w[j].conj();
        ra = ra.max(s.norm());
    }
    let mut rb: f64 = 0.0;
    for j in 0..B.ncols() {
        let s: c64 = (0..n).map(|i| w[i].conj() * B[(i, j)]).sum();
        rb = rb.max(s.norm());
    }
    (ra, rb)
}

#[test]
fn unstable_uncontrollable_mode_is_reported_with_its_left_eigenvector() {
    let A = diag(&[1.2, 0.5]);
    let B = col(&[0.0, 1.0]);
    let out = synthesize(
        TimeKind::Discrete,
        A.as_ref(),
        B.as_ref(),
        &CafSettings::default(),
    )
    .unwrap();
    let CafOutcome::NotStabilizable { mode } = out else {
        panic!("expected NotStabilizable, got {out:?}")
    };
    assert!((mode.eigenvalue - c64::new(1.2, 0.0)).norm() < 1e-12);
    let (ra, rb) = residuals(&A, &B, &mode);
    assert!(ra < 1e-12 && rb < 1e-12);
    assert!(
        (mode
            .left_eigenvector
            .iter()
            .map(|z| z.norm_sqr())
            .sum::<f64>()
            - 1.0)
            .abs()
            < 1e-12
    );

    // Continuous time: Re λ ≥ 0 is unstable; a marginal mode (λ = 0) counts.
    let A = diag(&[0.0, -1.0]);
    let out = synthesize(
        TimeKind::Continuous,
        A.as_ref(),
        B.as_ref(),
        &CafSettings::default(),
    )
    .unwrap();
    assert!(matches!(out, CafOutcome::NotStabilizable { mode } if mode.eigenvalue.norm() < 1e-12));
}

#[test]
fn repeated_eigenvalue_with_one_uncontrollable_direction() {
    // A = 1.1 I: every vector is a left eigenvector; B actuates only e1, so e2 is the uncontrollable direction.
    // An eigenvector-based test that happened to pick e1 would miss it.
    let A = diag(&[1.1, 1.1]);
    let B = col(&[1.0, 0.0]);
    let out = synthesize(
        TimeKind::Discrete,
        A.as_ref(),
        B.as_ref(),
        &CafSettings::default(),
    )
    .unwrap();
    let CafOutcome::NotStabilizable { mode } = out else {
        panic!("expected NotStabilizable, got {out:?}")
    };
    let (ra, rb) = residuals(&A, &B, &mode);
    assert!(ra < 1e-12 && rb < 1e-12);
    assert!(mode.left_eigenvector[1].norm() > 1.0 - 1e-12);
}

#[test]
fn complex_uncontrollable_pair() {
    // A rotation-with-growth block that B cannot reach, next to a controllable integrator.
    let A = Mat::from_fn(3, 3, |i, j| match (i, j) {
        (0, 0) | (1, 1) => 1.0,
        (0, 1) => 0.5,
        (1, 0) => -0.5,
        (2, 2) => 1.0,
        _ => 0.0,
    });
    let B = col(&[0.0, 0.0, 1.0]);
    let modes = uncontrollable_modes(A.as_ref(), B.as_ref(), 1e-9).unwrap();
    assert_eq!(modes.len(), 2, "{modes:?}");
    for m in &modes {
        assert!(
            (m.eigenvalue.re - 1.0).abs() < 1e-12 && (m.eigenvalue.im.abs() - 0.5).abs() < 1e-12
        );
        let (ra, rb) = residuals(&A, &B, m);
        assert!(ra < 1e-12 && rb < 1e-12);
    }
    assert!(matches!(
        synthesize(
            TimeKind::Discrete,
            A.as_ref(),
            B.as_ref(),
            &CafSettings::default()
        )
        .unwrap(),
        CafOutcome::NotStabilizable { .. }
    ));
}

#[test]
fn slow_uncontrollable_mode_limits_the_margin() {
    // λ = 0.99 cannot be moved: ψ along it contracts at most to 0.99, so σ < 1 − 0.99² = 0.0199.
    let A = diag(&[0.99, 2.0]);
    let B = col(&[0.0, 1.0]);
    let out = synthesize(
        TimeKind::Discrete,
        A.as_ref(),
        B.as_ref(),
        &CafSettings::default(),
    )
    .unwrap();
    let CafOutcome::MarginUnachievable { max_sigma, .. } = out else {
        panic!("expected MarginUnachievable, got {out:?}")
    };
    assert!((max_sigma - (1.0 - 0.99f64 * 0.99)).abs() < 1e-12);
    // Below the limit it is solved and certified.
    let s = CafSettings::builder().sigma(0.01).build().unwrap();
    let caf = synthesize(TimeKind::Discrete, A.as_ref(), B.as_ref(), &s)
        .unwrap()
        .solved()
        .expect("σ = 0.01 < 0.0199");
    assert!(caf.certificate.margin >= 0.01);
}

#[test]
fn condition_cap_makes_it_infeasible() {
    // A sampled double integrator cannot have a round metric with a margin: a cap of 1.5 is too tight.
    let h = 0.1;
    let A = Mat::from_fn(2, 2, |i, j| match (i, j) {
        (0, 0) | (1, 1) => 1.0,
        (0, 1) => h,
        _ => 0.0,
    });
    let B = col(&[h * h / 2.0, h]);
    let s = CafSettings::builder()
        .max_condition(1.5)
        .sigma(0.05)
        .build()
        .unwrap();
    let out = synthesize(TimeKind::Discrete, A.as_ref(), B.as_ref(), &s).unwrap();
    assert!(matches!(out, CafOutcome::Infeasible { .. }), "{out:?}");
    // Without the cap it is solved, with a condition number above 1.5.
    let s = CafSettings::builder().sigma(0.05).build().unwrap();
    let caf = synthesize(TimeKind::Discrete, A.as_ref(), B.as_ref(), &s)
        .unwrap()
        .solved()
        .unwrap();
    assert!(caf.certificate.condition > 1.5);
}

#[test]
fn bad_input_is_an_error() {
    let s = CafSettings::default();
    let A = diag(&[0.5, 0.5]);
    assert!(matches!(
        synthesize(
            TimeKind::Discrete,
            A.as_ref(),
            Mat::<f64>::zeros(3, 1).as_ref(),
            &s
        ),
        Err(CafError::Dimension { .. })
    ));
    assert!(matches!(
        synthesize(
            TimeKind::Discrete,
            Mat::<f64>::zeros(2, 3).as_ref(),
            Mat::<f64>::zeros(2, 1).as_ref(),
            &s
        ),
        Err(CafError::Dimension { .. })
    ));
    assert!(matches!(
        synthesize(
            TimeKind::Discrete,
            A.as_ref(),
            Mat::<f64>::zeros(2, 0).as_ref(),
            &s
        ),
        Err(CafError::Dimension { .. })
    ));
    let mut nan = A.clone();
    nan[(1, 0)] = f64::NAN;
    assert!(matches!(
        synthesize(
            TimeKind::Discrete,
            nan.as_ref(),
            col(&[1.0, 0.0]).as_ref(),
            &s
        ),
        Err(CafError::NonFinite { .. })
    ));
    // σ ≥ 1 is impossible in discrete time but fine in continuous time.
    let big = CafSettings::builder().sigma(1.0).build().unwrap();
    assert!(matches!(
        synthesize(
            TimeKind::Discrete,
            A.as_ref(),
            col(&[1.0, 1.0]).as_ref(),
            &big
        ),
        Err(CafError::Settings { field: "sigma", .. })
    ));
    assert!(synthesize(
        TimeKind::Continuous,
        A.as_ref(),
        Mat::from_fn(2, 2, |i, j| if i == j { 1.0 } else { 0.0 }).as_ref(),
        &big
    )
    .is_ok());
    // The builder checks ranges.
    assert!(CafSettings::builder().sigma(-1.0).build().is_err());
    assert!(CafSettings::builder().sigma(f64::NAN).build().is_err());
    assert!(CafSettings::builder().max_condition(1.0).build().is_err());
    assert!(CafSettings::builder().pbh_tol(0.0).build().is_err());
    assert!(CafSettings::builder().solver_tol(2.0).build().is_err());
    assert!(CafSettings::builder().max_iter(0).build().is_err());
    assert!(CafSettings::builder().time_limit(0.0).build().is_err());
    assert!(CafSettings::builder().stage_slack(-0.1).build().is_err());
    // Model constructors reject the same things before the synthesis sees them.
    assert!(DiscretePlant::new(A.clone(), col(&[1.0]), vec![0.0; 2], 0.1).is_err());
}

#[test]
fn r_crit_rejects_what_the_theorem_does_not_cover() {
    let At = diag(&[0.5, 0.5]);
    let P = diag(&[1.0, 1.0]);
    let E = col(&[1.0, 0.0]);
    assert!(matches!(
        r_crit(At.as_ref(), P.as_ref(), E.as_ref(), -1.0),
        Err(CafError::Disturbance(_))
    ));
    assert!(matches!(
        r_crit(At.as_ref(), P.as_ref(), E.as_ref(), f64::INFINITY),
        Err(CafError::Disturbance(_))
    ));
    // Not contractive: P − ÃᵀPÃ = 0.
    let rot = Mat::from_fn(2, 2, |i, j| match (i, j) {
        (0, 1) => 1.0,
        (1, 0) => -1.0,
        _ => 0.0,
    });
    assert!(matches!(
        r_crit(rot.as_ref(), P.as_ref(), E.as_ref(), 1e-3),
        Err(CafError::NoMargin { .. })
    ));
    assert!(matches!(
        r_crit(At.as_ref(), diag(&[1.0]).as_ref(), E.as_ref(), 1e-3),
        Err(CafError::Dimension { .. })
    ));
    // A continuous-time CAF has no r_crit.
    let caf = synthesize(
        TimeKind::Continuous,
        diag(&[-1.0, -1.0]).as_ref(),
        col(&[1.0, 1.0]).as_ref(),
        &CafSettings::default(),
    )
    .unwrap()
    .solved()
    .unwrap();
    assert!(matches!(caf.r_crit(1e-3), Err(CafError::NotDiscrete)));
}

//! The Unsafe bound between samples along each piece's normal (`certify::pieces`' module doc, "Between
//! samples along a direction"), on the SCOTS point-mass maze (`examples/maze-scots-pointmass.toml`),
//! against the exact closed-loop flow: the continuous plant with the input held over the period, sampled
//! densely. The certified clearance never exceeds the true least distance from Unsafe of any run from
//! the ball; along a wall the directional bound is strictly larger than the isotropic one; the MTL tube
//! certifies the same Unsafe radius for `G !Unsafe` as Theorem 4.7's Unsafe piece; and the optimiser's
//! gradient follows the directional value where it binds.

use host_compiler::certify::temporal::{certify_temporal, TemporalLoop};
use host_compiler::certify::{certify, LoopConstants, OwnedLoop, Pieces};
use host_compiler::geometry::Metric;
use host_compiler::linalg::{mat_vec, p_norm};
use host_compiler::property::TemporalTask;
use host_compiler::trajectory::Nominal;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn maze() -> (host_compiler::spec::Problem, OwnedLoop, LoopConstants) {
    let p = host_compiler::spec::load(format!(
        "{}/../examples/maze-scots-pointmass.toml",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap();
    let ol = OwnedLoop::from_problem(&p).unwrap();
    let lc = ol.constants().unwrap();
    (p, ol, lc)
}

/// The nominal from `x0` under the applied inputs `u` (v = u − K̂x along it), as the loop simulates it.
fn nominal(ol: &OwnedLoop, x0: &[f64], u: &[[f64; 2]]) -> Nominal {
    let lp = ol.lp();
    let mut x = x0.to_vec();
    let mut v = Vec::new();
    for uk in u {
        let kx = mat_vec(lp.K, &x);
        v.push(vec![uk[0] - kx[0], uk[1] - kx[1]]);
        x = lp.model().step(&x, uk);
    }
    lp.simulate(x0, &v)
}

/// The least P-distance from Unsafe over one period of the exact flow (x' = v, v' = u held), from the
/// sample state `x` under the input `u`, at 400 instants.
fn exact_least(
    us: &dyn host_compiler::geometry::Region,
    metric: &Metric,
    x: &[f64],
    u: &[f64],
    h: f64,
) -> f64 {
    (0..=400)
        .map(|i| {
            let t = h * i as f64 / 400.0;
            let z = [
                x[0] + x[2] * t + 0.5 * u[0] * t * t,
                x[1] + x[3] * t + 0.5 * u[1] * t * t,
                x[2] + u[0] * t,
                x[3] + u[1] * t,
            ];
            -us.signed_dist(&z, metric).value
        })
        .fold(f64::INFINITY, f64::min)
}

/// Samples of the maze's corridors at speed, a run along the first corridor's walls among them: for
/// each, the certified radius between samples r, and runs from the r-ball (aimed at the nearest wall,
/// and random; the input off by up to ε̄) flowed exactly. The certified clearance at r never exceeds
/// the least distance any of them reaches, so none enters Unsafe; the along-wall run's directional
/// clearance beats the isotropic one.
#[test]
fn the_certified_clearance_never_exceeds_the_exact_flows_least_distance() {
    let (_, ol, lc) = maze();
    let lp = ol.lp();
    let pc = Pieces::new(&lp, &lc);
    let us = lp.unsafe_set().unwrap();
    let metric = pc.metric().clone();
    let h = lp.plant.period();
    let eps = 1e-6;
    let mut rng = ChaCha8Rng::seed_from_u64(47);
    // (x0, input): along the corridor between walls 1 and 2 (x ∈ [1.2, 2.2]) upwards, then random.
    let mut cases: Vec<([f64; 4], [f64; 2])> = vec![([1.7, 3.0, 0.0, 0.6], [0.0, 0.0])];
    for _ in 0..60 {
        cases.push((
            [
                rng.random_range(0.2..9.8),
                rng.random_range(0.2..9.8),
                rng.random_range(-0.8..0.8),
                rng.random_range(-0.8..0.8),
            ],
            [rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)],
        ));
    }
    let (mut checked, mut better) = (0, 0);
    for (i, (x0, u)) in cases.iter().enumerate() {
        let nom = nominal(&ol, x0, &[*u, *u]);
        let d = -us.signed_dist(&nom.x[0], &metric).value;
        if d.is_nan() || d <= 0.0 {
            continue;
        }
        let r = pc.unsafe_margin(&nom, 0, d, eps);
        if r.is_nan() || r <= 0.0 {
            continue;
        }
        let (iso, dir) = pc.unsafe_clearance(&nom, 0, r, eps).unwrap();
        let certified = iso.max(dir.unwrap_or(f64::NEG_INFINITY));
        assert!(
            certified >= -1e-9 * d,
            "case {i}: the margin's clearance {certified}"
        );
        if i == 0 {
            let dir = dir.expect("the maze's walls are convex pieces");
            assert!(
                dir > iso + 0.1 * d,
                "along the wall the directional clearance {dir} should beat the isotropic {iso}"
            );
            let (_, dir0) = pc.unsafe_clearance(&nom, 0, 0.0, eps).unwrap();
            let fp = p_norm(
                lp.P,
                &lp.plant.vector_field(0, &nom.x[0], &nom.u[0]).unwrap(),
            );
            assert!(
                dir0.unwrap() > d - lc.phi * fp,
                "the directional clearance of the nominal itself should beat d − φ‖f‖_P"
            );
        }
        checked += 1;
        if dir.is_some_and(|v| v > iso) {
            better += 1;
        }
        // Runs from the r-ball: e aimed at the nearest wall, or random, with ‖e‖_P = r; the input
        // K̂(x̃ + e) + v off by ε̄.
        let towards = us.dist(&nom.x[0], &metric).point;
        let mut least = f64::INFINITY;
        for probe in 0..40 {
            let dir_e: Vec<f64> = if probe % 2 == 0 {
                (0..4).map(|j| towards[j] - nom.x[0][j]).collect()
            } else {
                (0..4).map(|_| rng.random_range(-1.0..1.0)).collect()
            };
            let s = r / p_norm(lp.P, &dir_e);
            let x: Vec<f64> = (0..4).map(|j| nom.x[0][j] + s * dir_e[j]).collect();
            let ke = mat_vec(lp.K, &(0..4).map(|j| s * dir_e[j]).collect::<Vec<_>>());
            let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
            let u: Vec<f64> = (0..2)
                .map(|j| nom.u[0][j] + ke[j] + eps * [a.cos(), a.sin()][j])
                .collect();
            least = least.min(exact_least(us, &metric, &x, &u, h));
        }
        assert!(
            certified <= least * (1.0 + 1e-9) + 1e-12,
            "case {i} (x0 {x0:?}, u {u:?}): certified clearance {certified} (iso {iso}, dir {dir:?}) \
             above the exact flow's least distance {least}"
        );
        assert!(
            least > 0.0,
            "case {i}: a run from the certified ball entered Unsafe"
        );
    }
    assert!(checked >= 30, "only {checked} cases with a positive margin");
    assert!(
        better >= 5,
        "the directional clearance won in only {better} of {checked}"
    );
}

/// Remark 2.29's view: `G !Unsafe` through the MTL tube certifies the radius Theorem 4.7's Unsafe piece
/// certifies, directional bound included, on a run along a wall (where it binds).
#[test]
fn the_mtl_tube_certifies_theorem_4_7s_unsafe_radius_along_a_wall() {
    let (mut p, ol, lc) = maze();
    let lp = ol.lp();
    let pc = Pieces::new(&lp, &lc);
    let nom = nominal(&ol, &[1.7, 3.0, 0.0, 0.6], &[[0.0, 0.0]; 6]);
    let c = certify(&lp, &lc, &nom);
    // The isotropic bound alone at the first sample, against which the directional one is needed.
    let d0 = -lp
        .unsafe_set()
        .unwrap()
        .signed_dist(&nom.x[0], pc.metric())
        .value;
    let f = lp.plant.vector_field(0, &nom.x[0], &nom.u[0]).unwrap();
    let held = lc.held_disturbance(c.eps_f32);
    let iso = pc.isotropic_margin(d0, p_norm(lp.P, &f), held);
    assert!(
        c.delta_unsafe_intersample > iso * 1.05,
        "the directional margin {} should bind above the isotropic {iso}",
        c.delta_unsafe_intersample
    );
    p.mtl = Some(format!("G[0,{}] !Unsafe", 6.0 * lp.plant.period()));
    let tt = TemporalTask::from_problem(&p).unwrap();
    let tl = TemporalLoop::new(&tt, &lp).unwrap();
    let ct = certify_temporal(&lp, &lc, &tl, &nom);
    let ratio = ct.delta_continuous / c.delta_unsafe_intersample;
    assert!(
        (ratio - 1.0).abs() < 1e-6,
        "tube {} vs Theorem 4.7 {}",
        ct.delta_continuous,
        c.delta_unsafe_intersample
    );
}

/// Where the directional margin binds, the optimiser's gradient is its gradient: against central
/// differences of the value along the inputs (the normal moves too, so to a loose tolerance).
#[test]
fn the_unsafe_gradient_follows_the_directional_margin() {
    let (_, ol, lc) = maze();
    let lp = ol.lp();
    let pc = Pieces::new(&lp, &lc);
    let nom = nominal(&ol, &[1.7, 3.0, 0.0, 0.6], &[[0.2, 0.1], [0.0, 0.0]]);
    let eps = 1e-6;
    let (val, g) = pc.unsafe_grad(&nom, 0, eps);
    let d = -lp
        .unsafe_set()
        .unwrap()
        .signed_dist(&nom.x[0], pc.metric())
        .value;
    assert_eq!(val, pc.unsafe_margin(&nom, 0, d, eps));
    let f = lp.plant.vector_field(0, &nom.x[0], &nom.u[0]).unwrap();
    let iso = pc.isotropic_margin(d, p_norm(lp.P, &f), lc.held_disturbance(eps));
    assert!(
        val > iso,
        "the directional margin should bind: {val} vs {iso}"
    );
    let value_at = |dv: [f64; 2]| {
        let v: Vec<Vec<f64>> = nom
            .v
            .iter()
            .enumerate()
            .map(|(k, v)| {
                if k == 0 {
                    vec![v[0] + dv[0], v[1] + dv[1]]
                } else {
                    v.clone()
                }
            })
            .collect();
        let n2 = lp.simulate(&nom.x[0], &v);
        let d = -lp
            .unsafe_set()
            .unwrap()
            .signed_dist(&n2.x[0], pc.metric())
            .value;
        pc.unsafe_margin(&n2, 0, d, eps)
    };
    let hstep = 1e-5;
    for i in 0..2 {
        let mut plus = [0.0; 2];
        plus[i] = hstep;
        let mut minus = [0.0; 2];
        minus[i] = -hstep;
        let fd = (value_at(plus) - value_at(minus)) / (2.0 * hstep);
        assert!(
            (fd - g.gv[i]).abs() <= 0.05 * fd.abs().max(1e-3),
            "∂/∂v{i}: gradient {} vs finite difference {fd}",
            g.gv[i]
        );
    }
}

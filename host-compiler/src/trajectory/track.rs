//! What a user has, turned into what the loop takes (issue 47, item 2): the reference inputs v(κ) of the
//! closed loop u = K̂ x + v (Algorithm 2's controller), from a recording's applied inputs u(κ) or from its
//! states alone ([`super::csv::Given`]). The gain K̂ is the shipped one, so this runs once the CAF is
//! designed; everything here only proposes a nominal, which is certified afterwards as every other.
//!
//! * **Applied inputs.** The sampled model x(κ+1) = A x(κ) + B u(κ) + g stepped from x0 (the *replay*),
//!   and v(κ) = u(κ) − K̂ x(κ) along it ([`references_of_applied`]). The closed loop with these references,
//!   x⁺ = A x + B (K̂ x + v) + g, is the replay itself, so the nominal certified is the run of the applied
//!   inputs (up to the f32 rounding of the stored v, which the certificate is computed for).
//! * **States alone.** Inputs by least squares within the input bound ([`track_states`]):
//!   min Σ_{κ=1..N} ‖x(κ) − x̄(κ)‖² over u(0..N−1) in the bound, subject to the replay's dynamics from x0,
//!   one convex program over the whole horizon (a QP for a box bound, an SOCP for a norm bound) solved by
//!   clarabel, with the replay's states as variables so that its matrix is banded and sparse. One problem
//!   over the horizon rather than one per step: with fewer inputs than states (a double integrator) a
//!   recorded state is reached only through earlier inputs, and a fit per step is myopic: it cannot
//!   brake early to meet a later state within the bound, and its error in the directions B does not reach
//!   in one step is never corrected (a one-step deadbeat law, unstable where the sampled plant has an
//!   unstable inverse). The inputs found are projected into the bound and replayed; a sample whose replay
//!   is further than [`TRACK_TOLERANCE`] of the recording's extent from the recorded state refuses the
//!   recording, naming the first sample the bound cannot reach and the residual, and saying whether the
//!   bound is the cause or the states are no run of the model at all (the same fit without the bound
//!   misses too). Then they are applied inputs as above.

use super::csv::{Given, Recording};
use crate::model::DiscretePlant;
use crate::property::InputBound;
use crate::solver::SetupError;
use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
    SupportedConeT::{NonnegativeConeT, SecondOrderConeT, ZeroConeT},
};
use faer::MatRef;

/// How far the replay of a states-only recording may be from a recorded state, as a fraction of the
/// recording's extent (its largest spread over one state coordinate; its largest |x̄| when every
/// coordinate is constant, and at least 1 then): a route followed to within a hundredth of its size. A
/// route planned on another discretisation of the same plant (an Euler step at the spec's period) is
/// followed within it; one that asks more than the input bound, or moves unlike the plant, is not.
pub const TRACK_TOLERANCE: f64 = 1e-2;

/// Weight of Σ‖u‖² in the least squares, against the states' residual: a tie-breaker (inputs B does not
/// see), far below what changes the replay.
const INPUT_WEIGHT: f64 = 1e-9;

/// Why a recording gives no references.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TrackError {
    #[error(
        "the recording does not fit the model: x0 has {x0} values and a row {row} values where \
         {expected} are expected (n = {n}, m = {m})"
    )]
    Dimension {
        n: usize,
        m: usize,
        x0: usize,
        row: usize,
        expected: usize,
    },
    #[error(
        "its states cannot be followed within the input bound from sample {sample} on (t = {time:.3} s \
         after the first row): the states up to the sample before it can be, but no inputs within the \
         bound bring the replay within the tolerance {tolerance:.3e} ({frac} of the recording's extent) \
         of every state up to sample {sample} (the least-squares fit misses by {residual:.3e}; over the \
         whole recording by {worst:.3e}, at sample {worst_sample}): slow the route down before that \
         sample, or give the applied inputs (`u1…um`)",
        frac = TRACK_TOLERANCE
    )]
    Untrackable {
        sample: usize,
        time: f64,
        residual: f64,
        tolerance: f64,
        worst: f64,
        worst_sample: usize,
    },
    #[error(
        "its states are not a run of the plant's sampled model from sample {sample} on (t = {time:.3} s \
         after the first row): no inputs at all, within the input bound or not, bring the replay within \
         the tolerance {tolerance:.3e} ({frac} of the recording's extent) of every state up to sample \
         {sample} (the least-squares fit misses by {residual:.3e}): the states may come from another \
         model or discretisation; give the applied inputs (`u1…um`), or states of this model sampled at \
         the spec's period",
        frac = TRACK_TOLERANCE
    )]
    NotAModelRun {
        sample: usize,
        time: f64,
        residual: f64,
        tolerance: f64,
    },
    #[error("the least squares of its states did not solve: {0:?}")]
    Solver(SolverStatus),
    #[error("the least squares of its states could not be set up: {0}")]
    Setup(SetupError),
}

/// The states of the sampled model stepped from `x0` under the inputs `u` (N + 1 samples).
pub fn replay(model: &DiscretePlant, x0: &[f64], u: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let mut x = Vec::with_capacity(u.len() + 1);
    x.push(x0.to_vec());
    for uk in u {
        let xn = model.step(x.last().expect("x holds x0"), uk);
        x.push(xn);
    }
    x
}

/// The references v(κ) = u(κ) − K̂ x(κ) along the replay of the applied inputs `u` from `x0` (module doc).
pub fn references_of_applied(
    model: &DiscretePlant,
    K: MatRef<'_, f64>,
    x0: &[f64],
    u: &[Vec<f64>],
) -> Vec<Vec<f64>> {
    let x = replay(model, x0, u);
    let n = x0.len();
    u.iter()
        .zip(&x)
        .map(|(uk, xk)| {
            uk.iter()
                .enumerate()
                .map(|(i, &ui)| ui - (0..n).map(|j| K[(i, j)] * xk[j]).sum::<f64>())
                .collect()
        })
        .collect()
}

/// Inputs found for a states-only recording: within the bound, and how closely their replay follows.
#[derive(Clone, Debug, PartialEq)]
pub struct Tracked {
    /// u(0..N−1), in the input bound.
    pub u: Vec<Vec<f64>>,
    /// The largest distance (Euclidean) between the replay and a recorded state, and its sample.
    pub worst: f64,
    pub worst_sample: usize,
}

/// Inputs within `input` whose replay from `x0` follows the recorded `states` (x̄(0) first, which the
/// replay starts from as `x0`) in least squares over the whole horizon (module doc); refused when a
/// sample's residual exceeds the tolerance, naming the first sample the bound cannot reach: the
/// smallest K such that no inputs within the bound follow the states 0…K within the tolerance (found by
/// bisection over the prefixes, each its own least squares; a prefix that can be followed has every
/// shorter one followed too). The fit over the whole horizon spreads a late shortfall over earlier
/// samples, so its own first residual above the tolerance would name a sample before the trouble.
pub fn track_states(
    model: &DiscretePlant,
    input: &InputBound,
    x0: &[f64],
    states: &[Vec<f64>],
) -> Result<Tracked, TrackError> {
    let (n, m) = (model.A.nrows(), model.B.ncols());
    let N = states.len().saturating_sub(1);
    if N == 0 || x0.len() != n {
        return Err(TrackError::Dimension {
            n,
            m,
            x0: x0.len(),
            row: states.len(),
            expected: n,
        });
    }
    if let Some(r) = states.iter().find(|r| r.len() != n) {
        return Err(TrackError::Dimension {
            n,
            m,
            x0: x0.len(),
            row: r.len(),
            expected: n,
        });
    }
    let tolerance = TRACK_TOLERANCE * extent(states);
    let (u, residual) = fit(model, Some(input), x0, states)?;
    let (worst_sample, worst) = largest(&residual);
    if worst <= tolerance {
        return Ok(Tracked {
            u,
            worst,
            worst_sample,
        });
    }
    // Samples 0…lo can be followed, 0…hi cannot.
    let (mut lo, mut hi) = (0usize, states.len() - 1);
    let mut at_hi = worst;
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        let (_, r) = fit(model, Some(input), x0, &states[..=mid])?;
        let w = largest(&r).1;
        if w <= tolerance {
            lo = mid;
        } else {
            (hi, at_hi) = (mid, w);
        }
    }
    // Whether the bound is what stops it: the same states without it.
    let free = largest(&fit(model, None, x0, &states[..=hi])?.1).1;
    if free > tolerance {
        return Err(TrackError::NotAModelRun {
            sample: hi,
            time: hi as f64 * model.period,
            residual: free,
            tolerance,
        });
    }
    Err(TrackError::Untrackable {
        sample: hi,
        time: hi as f64 * model.period,
        residual: at_hi,
        tolerance,
        worst,
        worst_sample,
    })
}

/// The largest of `r` and its index (the first on ties).
fn largest(r: &[f64]) -> (usize, f64) {
    r.iter()
        .copied()
        .enumerate()
        .fold((0, 0.0f64), |a, b| if b.1 > a.1 { b } else { a })
}

/// The least squares of the module doc over `states` (0…N): the inputs, projected into the bound, and
/// their replay's distance from each recorded state (`input` `None`: without a bound).
fn fit(
    model: &DiscretePlant,
    input: Option<&InputBound>,
    x0: &[f64],
    states: &[Vec<f64>],
) -> Result<(Vec<Vec<f64>>, Vec<f64>), TrackError> {
    let (A, B, g) = (model.A.as_ref(), model.B.as_ref(), &model.g);
    let (n, m) = (A.nrows(), B.ncols());
    let N = states.len().saturating_sub(1);
    // Variables: x(1..N) then u(0..N−1).
    let xi = |k: usize, i: usize| (k - 1) * n + i;
    let ui = |k: usize, i: usize| N * n + k * m + i;
    let nvar = N * (n + m);
    let (mut I, mut J, mut V, mut b) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut row = |entries: &[(usize, f64)], rhs: f64, b: &mut Vec<f64>| {
        let r = b.len();
        for &(j, v) in entries {
            if v != 0.0 {
                I.push(r);
                J.push(j);
                V.push(v);
            }
        }
        b.push(rhs);
    };
    let mut cones: Vec<SupportedConeT<f64>> = Vec::new();
    // x(κ+1) − A x(κ) − B u(κ) = g, with x(0) = x0 moved to the right-hand side.
    for k in 0..N {
        for i in 0..n {
            let mut e = vec![(xi(k + 1, i), 1.0)];
            let mut rhs = g[i];
            for j in 0..n {
                if k == 0 {
                    rhs += A[(i, j)] * x0[j];
                } else {
                    e.push((xi(k, j), -A[(i, j)]));
                }
            }
            for j in 0..m {
                e.push((ui(k, j), -B[(i, j)]));
            }
            row(&e, rhs, &mut b);
        }
    }
    cones.push(ZeroConeT(N * n));
    match input {
        None => {}
        Some(InputBound::Box { lo, hi }) => {
            let start = b.len();
            for k in 0..N {
                for i in 0..m {
                    if hi[i].is_finite() {
                        row(&[(ui(k, i), 1.0)], hi[i], &mut b);
                    }
                    if lo[i].is_finite() {
                        row(&[(ui(k, i), -1.0)], -lo[i], &mut b);
                    }
                }
            }
            if b.len() > start {
                cones.push(NonnegativeConeT(b.len() - start));
            }
        }
        Some(InputBound::Norm2 { center, max }) => {
            for k in 0..N {
                row(&[], *max, &mut b);
                for (i, c) in center.iter().enumerate().take(m) {
                    row(&[(ui(k, i), -1.0)], -c, &mut b);
                }
                cones.push(SecondOrderConeT(m + 1));
            }
        }
    }
    // ½ zᵀ P z + qᵀ z = Σ ‖x(κ) − x̄(κ)‖² + INPUT_WEIGHT Σ ‖u‖² (up to a constant).
    let diag: Vec<f64> = (0..nvar)
        .map(|j| if j < N * n { 2.0 } else { 2.0 * INPUT_WEIGHT })
        .collect();
    let idx: Vec<usize> = (0..nvar).collect();
    let Pm = CscMatrix::new_from_triplets(nvar, nvar, idx.clone(), idx, diag);
    let mut q = vec![0.0; nvar];
    for k in 1..=N {
        for i in 0..n {
            q[xi(k, i)] = -2.0 * states[k][i];
        }
    }
    let Am = CscMatrix::new_from_triplets(b.len(), nvar, I, J, V);
    let st = DefaultSettingsBuilder::default()
        .verbose(false)
        .max_iter(200)
        .build()
        .expect("verbose and max_iter = 200 are in clarabel's valid range");
    let mut solver = DefaultSolver::new(&Pm, &q, &Am, &b, &cones, st)
        .map_err(|e| TrackError::Setup(e.into()))?;
    solver.solve();
    match solver.solution.status {
        SolverStatus::Solved | SolverStatus::AlmostSolved => {}
        s => return Err(TrackError::Solver(s)),
    }
    let z = &solver.solution.x;
    let u: Vec<Vec<f64>> = (0..N)
        .map(|k| {
            let uk: Vec<f64> = (0..m).map(|i| z[ui(k, i)]).collect();
            match input {
                Some(b) => project(b, uk),
                None => uk,
            }
        })
        .collect();
    // The replay of what is returned is judged, not the solver's states.
    let x = replay(model, x0, &u);
    let residual: Vec<f64> = x
        .iter()
        .zip(states)
        .map(|(a, r)| {
            a.iter()
                .zip(r)
                .map(|(p, q)| (p - q).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .collect();
    Ok((u, residual))
}

/// The recording's extent (the scale of [`TRACK_TOLERANCE`]): its largest spread over one state
/// coordinate, or when every coordinate is constant its largest |x̄|, at least 1.
fn extent(states: &[Vec<f64>]) -> f64 {
    let n = states.first().map_or(0, Vec::len);
    let spread = (0..n)
        .map(|i| {
            let (lo, hi) = states
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), r| {
                    (l.min(r[i]), h.max(r[i]))
                });
            hi - lo
        })
        .fold(0.0f64, f64::max);
    if spread > 0.0 {
        spread
    } else {
        states.iter().flatten().fold(1.0f64, |a, &v| a.max(v.abs()))
    }
}

/// `u` moved into the bound (the solver's answer may leave it by its tolerance).
fn project(input: &InputBound, mut u: Vec<f64>) -> Vec<f64> {
    match input {
        InputBound::Box { lo, hi } => {
            for ((v, &l), &h) in u.iter_mut().zip(lo).zip(hi) {
                *v = v.clamp(l, h);
            }
        }
        InputBound::Norm2 { center, max } => {
            let r = u
                .iter()
                .zip(center)
                .map(|(a, c)| (a - c).powi(2))
                .sum::<f64>()
                .sqrt();
            if r > *max {
                for (v, c) in u.iter_mut().zip(center) {
                    *v = c + (*v - c) * (max / r);
                }
            }
        }
    }
    u
}

/// The references of a recording for the loop with gain `K` on `model` (module doc), from `x0` (the
/// start the nominal is simulated from: the recording's, rounded as the image stores it): as recorded,
/// or derived from its applied inputs or its states.
pub fn references(
    model: &DiscretePlant,
    K: MatRef<'_, f64>,
    input: &InputBound,
    x0: &[f64],
    rec: &Recording,
) -> Result<Vec<Vec<f64>>, TrackError> {
    let (n, m) = (model.A.nrows(), model.B.ncols());
    let bad = |row: usize, expected: usize| TrackError::Dimension {
        n,
        m,
        x0: x0.len(),
        row,
        expected,
    };
    if x0.len() != n {
        return Err(bad(n, n));
    }
    match &rec.given {
        Given::References => Ok(rec.v.clone()),
        Given::Applied(u) => match u.iter().find(|r| r.len() != m) {
            Some(r) => Err(bad(r.len(), m)),
            None => Ok(references_of_applied(model, K, x0, u)),
        },
        Given::States(x) => {
            let t = track_states(model, input, x0, x)?;
            Ok(references_of_applied(model, K, x0, &t.u))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::Mat;

    /// The double integrator sampled at h with ZOH.
    fn di(h: f64) -> DiscretePlant {
        DiscretePlant {
            A: Mat::from_fn(2, 2, |i, j| match (i, j) {
                (0, 0) | (1, 1) => 1.0,
                (0, 1) => h,
                _ => 0.0,
            }),
            B: Mat::from_fn(2, 1, |i, _| if i == 0 { 0.5 * h * h } else { h }),
            g: vec![0.0; 2],
            period: h,
        }
    }

    #[test]
    fn the_closed_loop_with_the_derived_references_is_the_replay() {
        let model = di(0.1);
        let K = Mat::from_fn(1, 2, |_, j| [-1.5, -2.0][j]);
        let u: Vec<Vec<f64>> = (0..20).map(|k| vec![(k as f64 * 0.3).sin()]).collect();
        let x0 = [0.5, -0.25];
        let v = references_of_applied(&model, K.as_ref(), &x0, &u);
        let closed = crate::trajectory::simulate(&model, K.as_ref(), &x0, &v);
        for (a, b) in closed.x.iter().zip(replay(&model, &x0, &u)) {
            assert!(
                a.iter().zip(&b).all(|(p, q)| (p - q).abs() < 1e-12),
                "{a:?} {b:?}"
            );
        }
        for (a, b) in closed.u.iter().zip(&u) {
            assert!((a[0] - b[0]).abs() < 1e-12);
        }
    }

    #[test]
    fn states_of_inputs_within_the_bound_are_tracked_and_faster_ones_are_refused_at_their_sample() {
        let model = di(0.1);
        let bound = InputBound::Box {
            lo: vec![-1.0],
            hi: vec![1.0],
        };
        let u: Vec<Vec<f64>> = (0..30)
            .map(|k| vec![0.9 * (k as f64 * 0.2).cos()])
            .collect();
        let x = replay(&model, &[0.0, 0.0], &u);
        let t = track_states(&model, &bound, &[0.0, 0.0], &x).expect("tracked");
        assert!(t.worst < 1e-6, "{}", t.worst);
        assert!(t.u.iter().zip(&u).all(|(a, b)| (a[0] - b[0]).abs() < 1e-4));
        // The same within a norm bound (a second-order cone per step).
        let ball = InputBound::Norm2 {
            center: vec![0.0],
            max: 1.0,
        };
        let t = track_states(&model, &ball, &[0.0, 0.0], &x).expect("tracked in the ball");
        assert!(t.worst < 1e-6, "{}", t.worst);
        // Twice the acceleration from sample 10 on: the bound cannot follow it.
        let fast: Vec<Vec<f64>> = (0..30)
            .map(|k| vec![if k < 10 { 0.5 } else { 2.0 }])
            .collect();
        let x = replay(&model, &[0.0, 0.0], &fast);
        let e = track_states(&model, &bound, &[0.0, 0.0], &x).unwrap_err();
        let TrackError::Untrackable { sample, .. } = e else {
            panic!("{e}")
        };
        // The input of step 10 is the first beyond the bound: from sample 11 on the replay falls behind,
        // past the tolerance (a hundredth of this fast route's extent) a sample later.
        assert_eq!(sample, 12);
        // States that move the position at zero velocity are no run of the model, whatever the bound.
        let euler: Vec<Vec<f64>> = (0..30).map(|k| vec![0.05 * k as f64, 0.0]).collect();
        let wide = InputBound::Box {
            lo: vec![-100.0],
            hi: vec![100.0],
        };
        let e = track_states(&model, &wide, &[0.0, 0.0], &euler).unwrap_err();
        assert!(matches!(e, TrackError::NotAModelRun { .. }), "{e}");
    }
}

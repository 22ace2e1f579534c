//! The matrix exponential by scaling and squaring with diagonal Padé approximants (Higham, "The scaling and
//! squaring method for the matrix exponential revisited", SIAM J. Matrix Anal. Appl. 26(4), 2005: the
//! degrees 3, 5, 7, 9, 13 and the 1-norm thresholds θ_m of its Table 2.3, backward error ≤ 2⁻⁵³).
//!
//! Written here because faer has no matrix exponential and no maintained crate provides one on faer
//! matrices; the matrices exponentiated here are small (n + m + 1 ≤ a few dozen).

// The θ_m are quoted to the digits the paper gives.
#![allow(clippy::excessive_precision)]

use super::{check_finite, ModelError};
use faer::linalg::solvers::Solve;
use faer::{Mat, MatRef};

/// θ_m: the largest ‖A‖₁ for which the degree-m Padé approximant is accurate to unit roundoff.
const THETA: [(usize, f64); 4] = [
    (3, 1.495585217958292e-2),
    (5, 2.539398330063230e-1),
    (7, 9.504178996162932e-1),
    (9, 2.097847961257068e0),
];
const THETA_13: f64 = 5.371920351148152e0;

/// Numerator coefficients b_0..b_m of the diagonal Padé approximant of degree m (the denominator has the same
/// coefficients with alternating signs).
fn pade_coefficients(m: usize) -> &'static [f64] {
    match m {
        3 => &[120.0, 60.0, 12.0, 1.0],
        5 => &[30240.0, 15120.0, 3360.0, 420.0, 30.0, 1.0],
        7 => &[
            17297280.0, 8648640.0, 1995840.0, 277200.0, 25200.0, 1512.0, 56.0, 1.0,
        ],
        9 => &[
            17643225600.0,
            8821612800.0,
            2075673600.0,
            302702400.0,
            30270240.0,
            2162160.0,
            110880.0,
            3960.0,
            90.0,
            1.0,
        ],
        _ => &[
            64764752532480000.0,
            32382376266240000.0,
            7771770303897600.0,
            1187353796428800.0,
            129060195264000.0,
            10559470521600.0,
            670442572800.0,
            33522128640.0,
            1323241920.0,
            40840800.0,
            960960.0,
            16380.0,
            182.0,
            1.0,
        ],
    }
}

fn norm1(a: MatRef<'_, f64>) -> f64 {
    (0..a.ncols())
        .map(|j| (0..a.nrows()).map(|i| a[(i, j)].abs()).sum::<f64>())
        .fold(0.0, f64::max)
}

fn identity(n: usize) -> Mat<f64> {
    Mat::from_fn(n, n, |i, j| if i == j { 1.0 } else { 0.0 })
}

/// Σ c_k X_k over matrices of the same shape.
fn lin(terms: &[(f64, &Mat<f64>)]) -> Mat<f64> {
    let (r, c) = (terms[0].1.nrows(), terms[0].1.ncols());
    Mat::from_fn(r, c, |i, j| terms.iter().map(|(k, x)| k * x[(i, j)]).sum())
}

/// r_m(A) = q_m(A)⁻¹ p_m(A) with p_m = V + U, q_m = V − U (U the odd, V the even part).
fn pade(a: &Mat<f64>, m: usize) -> Mat<f64> {
    let n = a.nrows();
    let b = pade_coefficients(m);
    let id = identity(n);
    let a2 = a * a;
    let (u, v) = if m == 13 {
        let a4 = &a2 * &a2;
        let a6 = &a4 * &a2;
        let u_inner = &a6 * lin(&[(b[13], &a6), (b[11], &a4), (b[9], &a2)]);
        let u_inner = lin(&[
            (1.0, &u_inner),
            (b[7], &a6),
            (b[5], &a4),
            (b[3], &a2),
            (b[1], &id),
        ]);
        let u = a * u_inner;
        let v = &a6 * lin(&[(b[12], &a6), (b[10], &a4), (b[8], &a2)]);
        let v = lin(&[
            (1.0, &v),
            (b[6], &a6),
            (b[4], &a4),
            (b[2], &a2),
            (b[0], &id),
        ]);
        (u, v)
    } else {
        // Powers A^0, A^2, ..., A^(m-1).
        let mut pows = vec![id.clone(), a2.clone()];
        while pows.len() < m.div_ceil(2) {
            let next = &pows[pows.len() - 1] * &a2;
            pows.push(next);
        }
        let odd: Vec<(f64, &Mat<f64>)> = pows
            .iter()
            .enumerate()
            .map(|(k, p)| (b[2 * k + 1], p))
            .collect();
        let even: Vec<(f64, &Mat<f64>)> = pows
            .iter()
            .enumerate()
            .map(|(k, p)| (b[2 * k], p))
            .collect();
        (a * lin(&odd), lin(&even))
    };
    let p = lin(&[(1.0, &v), (1.0, &u)]);
    let q = lin(&[(1.0, &v), (-1.0, &u)]);
    q.partial_piv_lu().solve(&p)
}

/// e^M for a square, finite M.
pub fn expm(M: MatRef<'_, f64>) -> Result<Mat<f64>, ModelError> {
    if M.nrows() != M.ncols() {
        return Err(ModelError::Dimension {
            what: "expm argument",
            expected: "a square matrix".into(),
            got: format!("{}×{}", M.nrows(), M.ncols()),
        });
    }
    check_finite("expm argument", M)?;
    let a = M.to_owned();
    let norm = norm1(a.as_ref());
    for (m, theta) in THETA {
        if norm <= theta {
            let r = pade(&a, m);
            check_finite("e^M", r.as_ref()).map_err(|_| ModelError::ExpOverflow { norm })?;
            return Ok(r);
        }
    }
    let s = if norm > THETA_13 {
        (norm / THETA_13).log2().ceil() as i32
    } else {
        0
    };
    let scale = 0.5f64.powi(s);
    let scaled = Mat::from_fn(a.nrows(), a.ncols(), |i, j| a[(i, j)] * scale);
    let mut r = pade(&scaled, 13);
    for _ in 0..s {
        r = &r * &r;
    }
    check_finite("e^M", r.as_ref()).map_err(|_| ModelError::ExpOverflow { norm })?;
    Ok(r)
}

//! The task's sets in the forms the pipeline computes with: convex pieces (Goal, the members of Unsafe)
//! for the trajectory generator's convex subproblems, and the input set.

use crate::linalg::from_row_major;
use crate::spec::sets::{SetDesc, Shape};
use crate::spec::{InputSet, SpecError};
use faer::Mat;

/// A convex set in state coordinates (Goal, or one piece of Unsafe).
#[derive(Clone, Debug)]
pub enum ConvexPiece {
    /// {x : (C x − c)ᵀ Q (C x − c) ≤ 1} with C p×n and Q p×p positive definite.
    Ellipsoid {
        C: Mat<f64>,
        c: Vec<f64>,
        Q: Mat<f64>,
    },
    /// {x : H x ≤ b}.
    Polytope { H: Mat<f64>, b: Vec<f64> },
}

/// The input set.
#[derive(Clone, Debug)]
pub enum InputBound {
    /// lo ≤ u ≤ hi componentwise.
    Box { lo: Vec<f64>, hi: Vec<f64> },
    /// ‖u − center‖₂ ≤ max.
    Norm2 { center: Vec<f64>, max: f64 },
}

/// A spec set as a convex piece in state coordinates: y = M x with M from the set's coordinates. The error
/// is the set's coordinates not fitting an `n`-dimensional state ([`SetDesc::map_matrix`]).
pub fn convex_piece(s: &SetDesc, n: usize) -> Result<ConvexPiece, SpecError> {
    let d = s.dim();
    let M = match s.map_matrix(n)? {
        None => Mat::<f64>::identity(n, n),
        Some(M) => from_row_major(M.rows, M.cols, &M.data),
    };
    Ok(match &s.shape {
        Shape::Ball { center, radius } if *radius > 0.0 => ConvexPiece::Ellipsoid {
            C: M,
            c: center.clone(),
            Q: Mat::from_fn(
                d,
                d,
                |i, j| if i == j { 1.0 / (radius * radius) } else { 0.0 },
            ),
        },
        Shape::Ellipsoid { center, Q } => ConvexPiece::Ellipsoid {
            C: M,
            c: center.clone(),
            Q: from_row_major(d, d, &Q.data),
        },
        Shape::Polytope { A, b } => {
            let Ay = from_row_major(A.rows, A.cols, &A.data);
            ConvexPiece::Polytope {
                H: &Ay * &M,
                b: b.clone(),
            }
        }
        Shape::Box { lo, hi } => box_piece(&M, lo, hi),
        Shape::Ball { center, .. } => box_piece(&M, center, center),
    })
}

fn box_piece(M: &Mat<f64>, lo: &[f64], hi: &[f64]) -> ConvexPiece {
    let d = lo.len();
    let n = M.ncols();
    let H = Mat::from_fn(
        2 * d,
        n,
        |r, j| if r < d { M[(r, j)] } else { -M[(r - d, j)] },
    );
    let b = hi.iter().copied().chain(lo.iter().map(|l| -l)).collect();
    ConvexPiece::Polytope { H, b }
}

/// The spec's input set in the generator's form.
pub fn input_bound(i: &InputSet) -> InputBound {
    match i {
        InputSet::Box { lo, hi } => InputBound::Box {
            lo: lo.clone(),
            hi: hi.clone(),
        },
        InputSet::Ball { center, radius } => InputBound::Norm2 {
            center: center.clone(),
            max: *radius,
        },
    }
}

/// A magnitude of admissible inputs (for relative margins).
pub fn input_scale(i: &InputBound) -> f64 {
    match i {
        InputBound::Box { lo, hi } => lo
            .iter()
            .chain(hi)
            .fold(0.0f64, |a, b| a.max(b.abs()))
            .max(1e-12),
        InputBound::Norm2 { center, max } => center.iter().fold(*max, |a, b| a.max(b.abs())),
    }
}

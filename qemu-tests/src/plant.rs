//! The plant the firmware controls, simulated on the host: a continuous linear affine system
//! `ẋ = A x + B u + c`, sampled with an exact zero-order hold (DESIGN §5).
//!
//! The discretisation is done here, in f64, with a scaling-and-squaring Taylor matrix exponential of the
//! augmented matrix `[[A, B, c], [0, 0, 0]]·h`, whose exponential is `[[Ad, Bd, cd], [0, I, 0], [0, 0, 1]]`
//! (Van Loan's construction). It is written here because `host_compiler::model` had no ZOH function yet
//! when this harness was written; once it has one, this module should call it (kept small so that the
//! swap is easy, and tested against the closed form for the double integrator).

/// A dense row-major matrix, small (plant dimensions are at most a dozen).
#[derive(Clone, Debug, PartialEq)]
pub struct Mat {
    pub rows: usize,
    pub cols: usize,
    pub data: Vec<f64>,
}

impl Mat {
    /// The zero matrix.
    pub fn zeros(rows: usize, cols: usize) -> Self {
        Self {
            rows,
            cols,
            data: vec![0.0; rows * cols],
        }
    }

    /// From rows; `None` if they are ragged.
    pub fn from_rows(rows: &[&[f64]]) -> Option<Self> {
        let cols = rows.first().map_or(0, |r| r.len());
        if rows.iter().any(|r| r.len() != cols) {
            return None;
        }
        Some(Self {
            rows: rows.len(),
            cols,
            data: rows.iter().flat_map(|r| r.iter().copied()).collect(),
        })
    }

    /// Entry `(i, j)`.
    pub fn at(&self, i: usize, j: usize) -> f64 {
        self.data[i * self.cols + j]
    }

    fn at_mut(&mut self, i: usize, j: usize) -> &mut f64 {
        &mut self.data[i * self.cols + j]
    }

    fn identity(n: usize) -> Self {
        let mut m = Self::zeros(n, n);
        for i in 0..n {
            *m.at_mut(i, i) = 1.0;
        }
        m
    }

    fn mul(&self, o: &Mat) -> Mat {
        let mut r = Mat::zeros(self.rows, o.cols);
        for i in 0..self.rows {
            for k in 0..self.cols {
                let a = self.at(i, k);
                for j in 0..o.cols {
                    *r.at_mut(i, j) += a * o.at(k, j);
                }
            }
        }
        r
    }

    fn norm_inf(&self) -> f64 {
        (0..self.rows)
            .map(|i| (0..self.cols).map(|j| self.at(i, j).abs()).sum::<f64>())
            .fold(0.0, f64::max)
    }

    /// `self · v`.
    pub fn mul_vec(&self, v: &[f64]) -> Vec<f64> {
        (0..self.rows)
            .map(|i| (0..self.cols).map(|j| self.at(i, j) * v[j]).sum())
            .collect()
    }
}

/// Matrix exponential by scaling and squaring with a Taylor series: scale so that ‖M/2^s‖∞ ≤ 1/2, sum
/// terms until they no longer change the sum in f64, square `s` times. Accurate to a few ulps·‖M‖ for the
/// small, well-scaled matrices a sampled plant gives; not meant for stiff or large systems.
pub fn expm(m: &Mat) -> Mat {
    let n = m.rows;
    let norm = m.norm_inf();
    let s = if norm > 0.5 {
        (norm / 0.5).log2().ceil() as i32
    } else {
        0
    };
    let scale = 0.5f64.powi(s);
    let ms = Mat {
        rows: n,
        cols: n,
        data: m.data.iter().map(|x| x * scale).collect(),
    };
    let mut sum = Mat::identity(n);
    let mut term = Mat::identity(n);
    for k in 1..40 {
        term = term.mul(&ms);
        let inv = 1.0 / k as f64;
        term.data.iter_mut().for_each(|x| *x *= inv);
        let before = sum.clone();
        sum.data
            .iter_mut()
            .zip(&term.data)
            .for_each(|(a, b)| *a += b);
        if sum == before {
            break;
        }
    }
    for _ in 0..s {
        sum = sum.mul(&sum);
    }
    sum
}

/// `ẋ = A x + B u + c`.
#[derive(Clone, Debug)]
pub struct ContinuousPlant {
    pub A: Mat,
    pub B: Mat,
    pub c: Vec<f64>,
}

/// `x⁺ = Ad x + Bd u + cd`, the exact sampling of a [`ContinuousPlant`] under a zero-order hold.
#[derive(Clone, Debug)]
pub struct DiscretePlant {
    pub Ad: Mat,
    pub Bd: Mat,
    pub cd: Vec<f64>,
}

impl ContinuousPlant {
    /// The double integrator `ẍ = u`: state (position, velocity).
    pub fn double_integrator() -> Self {
        Self {
            A: Mat::from_rows(&[&[0.0, 1.0], &[0.0, 0.0]]).expect("rectangular"),
            B: Mat::from_rows(&[&[0.0], &[1.0]]).expect("rectangular"),
            c: vec![0.0, 0.0],
        }
    }

    /// State dimension.
    pub fn n(&self) -> usize {
        self.A.rows
    }

    /// Input dimension.
    pub fn m(&self) -> usize {
        self.B.cols
    }

    /// Exact zero-order-hold discretisation with period `h` (Van Loan: one exponential of the augmented
    /// matrix gives `Ad = e^{Ah}`, `Bd = ∫₀ʰ e^{As} ds B`, `cd = ∫₀ʰ e^{As} ds c`).
    pub fn zoh(&self, h: f64) -> DiscretePlant {
        let (n, m) = (self.n(), self.m());
        let size = n + m + 1;
        let mut aug = Mat::zeros(size, size);
        for i in 0..n {
            for j in 0..n {
                *aug.at_mut(i, j) = self.A.at(i, j) * h;
            }
            for j in 0..m {
                *aug.at_mut(i, n + j) = self.B.at(i, j) * h;
            }
            *aug.at_mut(i, n + m) = self.c[i] * h;
        }
        let e = expm(&aug);
        let mut Ad = Mat::zeros(n, n);
        let mut Bd = Mat::zeros(n, m);
        for i in 0..n {
            for j in 0..n {
                *Ad.at_mut(i, j) = e.at(i, j);
            }
            for j in 0..m {
                *Bd.at_mut(i, j) = e.at(i, n + j);
            }
        }
        let cd = (0..n).map(|i| e.at(i, n + m)).collect();
        DiscretePlant { Ad, Bd, cd }
    }
}

impl DiscretePlant {
    /// One sample: `Ad x + Bd u + cd`.
    pub fn step(&self, x: &[f64], u: &[f64]) -> Vec<f64> {
        let ax = self.Ad.mul_vec(x);
        let bu = self.Bd.mul_vec(u);
        ax.iter()
            .zip(&bu)
            .zip(&self.cd)
            .map(|((a, b), c)| a + b + c)
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn double_integrator_matches_closed_form() {
        let h = 0.1;
        let d = ContinuousPlant::double_integrator().zoh(h);
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-15;
        assert!(close(d.Ad.at(0, 0), 1.0) && close(d.Ad.at(0, 1), h));
        assert!(close(d.Ad.at(1, 0), 0.0) && close(d.Ad.at(1, 1), 1.0));
        assert!(close(d.Bd.at(0, 0), h * h / 2.0) && close(d.Bd.at(1, 0), h));
        assert_eq!(d.cd, vec![0.0, 0.0]);
    }

    #[test]
    fn scalar_affine_plant_matches_closed_form() {
        // ẋ = a x + b u + c: Ad = e^{ah}, Bd = b (e^{ah} - 1)/a, cd = c (e^{ah} - 1)/a. With |a h| = 3 the
        // exponential needs scaling and squaring.
        let (a, b, c, h) = (-1.5, 2.0, 0.25, 2.0);
        let p = ContinuousPlant {
            A: Mat::from_rows(&[&[a]]).unwrap(),
            B: Mat::from_rows(&[&[b]]).unwrap(),
            c: vec![c],
        };
        let d = p.zoh(h);
        let e = (a * h).exp();
        let rel = |x: f64, y: f64| ((x - y) / y).abs();
        assert!(rel(d.Ad.at(0, 0), e) < 1e-13, "{} vs {e}", d.Ad.at(0, 0));
        assert!(rel(d.Bd.at(0, 0), b * (e - 1.0) / a) < 1e-13);
        assert!(rel(d.cd[0], c * (e - 1.0) / a) < 1e-13);
    }

    #[test]
    fn rotation_exponential_is_orthogonal() {
        // e^{[[0, w], [-w, 0]] t} is a rotation by w t.
        let t = 7.0;
        let m = Mat::from_rows(&[&[0.0, t], &[-t, 0.0]]).unwrap();
        let e = expm(&m);
        assert!((e.at(0, 0) - t.cos()).abs() < 1e-12 && (e.at(0, 1) - t.sin()).abs() < 1e-12);
        assert!((e.at(1, 0) + t.sin()).abs() < 1e-12 && (e.at(1, 1) - t.cos()).abs() < 1e-12);
    }
}

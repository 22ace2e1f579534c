//! The geometry of Algorithm 4 (§5.4, automatic trajectory generation): the distance (5.32) of a coverage
//! sample to the certified cover, the projection of the nearest uncovered sample onto the boundary of the
//! closest ball in the CAF metric, the reference sequence of that ball's feedback law, and a summary of
//! where the samples lie that local variation cannot reach ("needs a new seed trajectory").
//!
//! The growth loop itself (batches, optimisation, acceptance) is [`super::grow`].

use super::CoverTrajectory;
use crate::linalg::p_norm;
use crate::linalg::round32;
use faer::MatRef;

/// (5.32): ψ₀(y, S) = min_i ‖y − x̃_i(0)‖_P − δ_i over the certified balls (δ_i as stored in the image),
/// with the index i that attains it; `None` when there is no ball.
pub fn gap(P: MatRef<'_, f64>, y: &[f64], trajs: &[CoverTrajectory]) -> Option<(f64, usize)> {
    let mut best: Option<(f64, usize)> = None;
    for (i, t) in trajs.iter().enumerate() {
        let d = dist(P, y, &t.nominal.x[0]) - t.certificate.delta_stored as f64;
        if best.is_none_or(|(b, _)| d < b) {
            best = Some((d, i));
        }
    }
    best
}

/// ‖a − b‖_P.
pub fn dist(P: MatRef<'_, f64>, a: &[f64], b: &[f64]) -> f64 {
    let e: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
    p_norm(P, &e)
}

/// Whether `y` lies in the stored ball of `t` (the f64 test; the image's f32 selection is checked
/// separately by the final coverage estimate).
pub fn covers(P: MatRef<'_, f64>, t: &CoverTrajectory, y: &[f64]) -> bool {
    dist(P, y, &t.nominal.x[0]) <= t.certificate.delta_stored as f64
}

/// The median of `it` (the upper one of an even count); Algorithm 4 spreads a batch by the balls' median
/// radius. `None` when empty.
pub fn median(it: impl Iterator<Item = f64>) -> Option<f64> {
    let mut v: Vec<f64> = it.collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    Some(v[v.len() / 2])
}

/// ŷ: `y` projected onto the boundary ∂B_P(c, δ) along the ray from the centre (the point of the
/// sphere nearest to `y` in the P-metric), rounded to f32 so that the image stores it exactly. Pinned
/// coordinates of Init (equal in `y` and `c`) stay exact. `None` when `y` coincides with the centre.
pub fn project_onto_boundary(
    P: MatRef<'_, f64>,
    y: &[f64],
    c: &[f64],
    delta: f64,
) -> Option<Vec<f64>> {
    let r = dist(P, y, c);
    if !r.is_finite() || r <= 0.0 {
        return None;
    }
    let s = delta / r;
    Some(
        c.iter()
            .zip(y)
            .map(|(&ci, &yi)| {
                if yi == ci {
                    ci
                } else {
                    round32(ci + s * (yi - ci))
                }
            })
            .collect(),
    )
}

/// The reference sequence of trajectory m's feedback law u = K (x − x̃_m(κ)) + ũ_m(κ) (Algorithm 4, step
/// 2) in the loop's form u = K x + v: since ũ_m = K x̃_m + ṽ_m, it is v = ṽ_m, applied from the new x0.
pub fn feedback_law_reference(t: &CoverTrajectory) -> &[Vec<f64>] {
    &t.nominal.v
}

/// One group of uncovered samples.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Cluster {
    /// Mean of the group (full state).
    pub center: Vec<f64>,
    /// Componentwise extent of the group.
    pub lo: Vec<f64>,
    pub hi: Vec<f64>,
    pub count: usize,
}

/// Where the samples lie that no local variation of the cover reaches.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct UncoveredRegion {
    pub count: usize,
    /// Bounding box of all of them.
    pub lo: Vec<f64>,
    pub hi: Vec<f64>,
    /// Leader clusters (largest first, at most [`MAX_CLUSTERS`]).
    pub clusters: Vec<Cluster>,
}

/// Most clusters reported.
pub const MAX_CLUSTERS: usize = 4;

impl UncoveredRegion {
    /// Summary of `points` (full states). Clusters: leader clustering in the order given (deterministic)
    /// with radius `radius` in the P-metric; the largest [`MAX_CLUSTERS`] are kept.
    pub fn of(P: MatRef<'_, f64>, points: &[Vec<f64>], radius: f64) -> Option<Self> {
        let first = points.first()?;
        let n = first.len();
        let mut lo = first.clone();
        let mut hi = first.clone();
        for p in points {
            for j in 0..n {
                lo[j] = lo[j].min(p[j]);
                hi[j] = hi[j].max(p[j]);
            }
        }
        let mut leaders: Vec<(Vec<f64>, Vec<usize>)> = Vec::new();
        for (i, p) in points.iter().enumerate() {
            match leaders.iter_mut().find(|(c, _)| dist(P, p, c) <= radius) {
                Some((_, members)) => members.push(i),
                None => leaders.push((p.clone(), vec![i])),
            }
        }
        let mut clusters: Vec<Cluster> = leaders
            .into_iter()
            .map(|(_, members)| {
                let mut center = vec![0.0; n];
                let mut clo = points[members[0]].clone();
                let mut chi = clo.clone();
                for &i in &members {
                    for j in 0..n {
                        center[j] += points[i][j] / members.len() as f64;
                        clo[j] = clo[j].min(points[i][j]);
                        chi[j] = chi[j].max(points[i][j]);
                    }
                }
                Cluster {
                    center,
                    lo: clo,
                    hi: chi,
                    count: members.len(),
                }
            })
            .collect();
        // Stable sort: ties keep the order of discovery.
        clusters.sort_by_key(|c| std::cmp::Reverse(c.count));
        clusters.truncate(MAX_CLUSTERS);
        Some(Self {
            count: points.len(),
            lo,
            hi,
            clusters,
        })
    }

    /// One line for the CLI and the report: the bounding box on the free coordinates and the clusters.
    pub fn describe(&self, free: &[usize]) -> String {
        let fmt_box = |lo: &[f64], hi: &[f64]| {
            free.iter()
                .map(|&j| format!("x{} ∈ [{:.4}, {:.4}]", j + 1, lo[j], hi[j]))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let mut s = format!(
            "{} uncovered samples in {}",
            self.count,
            fmt_box(&self.lo, &self.hi)
        );
        for c in &self.clusters {
            let centre: Vec<String> = free
                .iter()
                .map(|&j| format!("x{} = {:.4}", j + 1, c.center[j]))
                .collect();
            s.push_str(&format!("; {} around ({})", c.count, centre.join(", ")));
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::certify::Certificate;
    use crate::trajectory::Nominal;
    use faer::Mat;

    fn ball(c: Vec<f64>, delta: f32) -> CoverTrajectory {
        CoverTrajectory {
            source: super::super::Source::import("t"),
            nominal: Nominal {
                x: vec![c],
                v: vec![],
                u: vec![],
            },
            certificate: Certificate {
                delta_goal: 1.0,
                k_star: 0,
                delta_unsafe: 1.0,
                k_unsafe: 0,
                delta_input: 1.0,
                k_input: 0,
                delta_unsafe_intersample: 1.0,
                eps_components: vec![],
                eps_f32: 0.0,
                r_crit: 0.0,
                delta: delta as f64,
                delta_stored: delta,
                accumulated: 0.0,
            },
        }
    }

    #[test]
    fn projection_lands_on_the_sphere_and_outside_the_other_balls() {
        let P = Mat::from_fn(3, 3, |i, j| match (i, j) {
            (0, 0) => 4.0,
            (1, 1) => 1.0,
            (0, 1) | (1, 0) => 0.5,
            (2, 2) => 1.0,
            _ => 0.0,
        });
        let trajs = vec![
            ball(vec![0.0, 0.0, 1.0], 0.5),
            ball(vec![1.2, 0.3, 1.0], 0.25),
        ];
        let y = vec![0.3, 0.9, 1.0];
        let (g, m) = gap(P.as_ref(), &y, &trajs).unwrap();
        assert!(g > 0.0, "y is uncovered");
        let c = &trajs[m].nominal.x[0];
        let yh = project_onto_boundary(P.as_ref(), &y, c, trajs[m].certificate.delta).unwrap();
        // On the sphere (up to f32 rounding of ŷ), pinned coordinate exact.
        let r = dist(P.as_ref(), &yh, c);
        assert!((r - 0.5).abs() < 1e-6, "{r}");
        assert_eq!(yh[2], 1.0);
        assert!(yh.iter().all(|&v| v as f32 as f64 == v));
        // Not strictly inside any other ball (the argument after (5.32)).
        for (j, t) in trajs.iter().enumerate() {
            if j != m {
                assert!(dist(P.as_ref(), &yh, &t.nominal.x[0]) >= 0.25 - 1e-6);
            }
        }
        // The gap of y shrinks to its distance to ŷ.
        assert!((dist(P.as_ref(), &y, &yh) - g).abs() < 1e-6);
    }

    #[test]
    fn region_summarises_two_groups() {
        let P = Mat::<f64>::identity(2, 2);
        let mut pts = vec![];
        for i in 0..5 {
            pts.push(vec![0.0 + 0.01 * i as f64, 0.0]);
        }
        for i in 0..3 {
            pts.push(vec![1.0, 1.0 + 0.01 * i as f64]);
        }
        let r = UncoveredRegion::of(P.as_ref(), &pts, 0.1).unwrap();
        assert_eq!(r.count, 8);
        assert_eq!(r.clusters.len(), 2);
        assert_eq!(r.clusters[0].count, 5);
        assert_eq!(r.clusters[1].count, 3);
        assert_eq!(r.lo, vec![0.0, 0.0]);
        assert_eq!(r.hi, vec![1.0, 1.02]);
        assert!(r.describe(&[0, 1]).contains("8 uncovered samples"));
        assert!(UncoveredRegion::of(P.as_ref(), &[], 0.1).is_none());
    }
}

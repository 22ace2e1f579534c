//! A quick refusal of a forced-switching task whose Goal no run can reach: before any planning, an
//! interval over-approximation of the states the automaton can be in at each sample (every start in
//! Init, every input of the input set held over a period, every choice of switches the controller may
//! make where a forced edge's guard may hold, Def 4.15), tested against Goal at every sample of the
//! horizon. When no sample's box meets Goal in any location, no run reaches Goal at a sample, so no
//! certificate exists (a certified run ends in Goal at a sample, Theorem 4.17); the planner would only
//! exhaust its schedules to find that out.
//!
//! The boxes are centre and radius vectors stepped by the location's exact ZOH (`Plant::error_dynamics`):
//! c ← A c + B u_c + g, r ← |A| r + |B| r_u, widened by a relative slack for the f64 rounding of the
//! step. A guard may hold on a box unless one of its rows is violated at every point of the box. The
//! verdict is one-sided: an over-approximation that grows too wide (unstable locations, long horizons)
//! or a Goal test the budget does not allow gives no verdict, and planning goes ahead as before.

use crate::model::hybrid::{EdgeKind, Hybrid};
use crate::model::{Location, Plant};
use crate::spec::checks::{box_meets_set, Meet};
use crate::spec::{InitBox, InputSet, SetDesc, Shape};

/// Radii past which the boxes are too wide to decide anything.
const MAX_RADIUS: f64 = 1e12;
/// Most Goal tests by linear program (a Goal that is not a box in state coordinates).
const MAX_SET_TESTS: usize = 20_000;
/// Relative widening of each step for the f64 rounding of the products.
const SLACK: f64 = 1e-9;

/// Why no run can reach Goal.
#[derive(Clone, Debug, PartialEq)]
pub struct Unreachable {
    /// Samples tested (the horizon's).
    pub steps: usize,
    /// The forced edges out of an entered location whose guard no reachable box meets (`from → to` by
    /// location name).
    pub edges_never_enabled: Vec<String>,
    /// The locations no run can enter.
    pub locations_never_entered: Vec<String>,
}

impl std::fmt::Display for Unreachable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "no run can reach Goal within the horizon ({} samples): from every start in Init, under \
             every input of the input set and every switch the forced edges allow, the state at every \
             sample lies outside Goal (by an interval over-approximation of the automaton's reachable \
             states)",
            self.steps
        )?;
        if !self.edges_never_enabled.is_empty() {
            write!(
                f,
                "; no run reaches the guard of {} {}",
                if self.edges_never_enabled.len() == 1 {
                    "the edge"
                } else {
                    "the edges"
                },
                self.edges_never_enabled.join(", ")
            )?;
        }
        if !self.locations_never_entered.is_empty() {
            write!(
                f,
                ", so no run enters {}",
                self.locations_never_entered.join(", ")
            )?;
        }
        Ok(())
    }
}

/// A box as centre and radius.
#[derive(Clone, Debug)]
struct CBox {
    c: Vec<f64>,
    r: Vec<f64>,
}

impl CBox {
    fn lo(&self) -> Vec<f64> {
        self.c.iter().zip(&self.r).map(|(c, r)| c - r).collect()
    }
    fn hi(&self) -> Vec<f64> {
        self.c.iter().zip(&self.r).map(|(c, r)| c + r).collect()
    }
    fn hull(&self, o: &CBox) -> CBox {
        let (lo, hi): (Vec<f64>, Vec<f64>) = self
            .lo()
            .iter()
            .zip(o.lo())
            .zip(self.hi().iter().zip(o.hi()))
            .map(|((a, b), (c, d))| (a.min(b), c.max(d)))
            .unzip();
        CBox {
            c: lo.iter().zip(&hi).map(|(l, h)| 0.5 * (l + h)).collect(),
            r: lo.iter().zip(&hi).map(|(l, h)| 0.5 * (h - l)).collect(),
        }
    }
    /// Whether every row a·x ≤ b may hold at some point of the box (each row on its own: an
    /// over-approximation of the polytope meeting the box).
    fn may_meet(&self, a: &[Vec<f64>], b: &[f64]) -> bool {
        a.iter().zip(b).all(|(row, &bj)| {
            let min: f64 = row
                .iter()
                .zip(self.c.iter().zip(&self.r))
                .map(|(ai, (c, r))| ai * c - ai.abs() * r)
                .sum();
            min <= bj + SLACK * (1.0 + bj.abs())
        })
    }
}

/// Goal's test against a box: exact for a box in state coordinates, else the spec's box–set test.
struct GoalTest<'a> {
    goal: &'a SetDesc,
    state_box: Option<(Vec<f64>, Vec<f64>)>,
    lp_budget: usize,
}

impl GoalTest<'_> {
    /// `Some(true)` if the box may meet Goal, `Some(false)` if it certainly does not, `None` past the
    /// budget.
    fn may_meet(&mut self, b: &CBox) -> Option<bool> {
        if let Some((glo, ghi)) = &self.state_box {
            let (lo, hi) = (b.lo(), b.hi());
            return Some((0..lo.len()).all(|i| lo[i] <= ghi[i] && hi[i] >= glo[i]));
        }
        self.lp_budget = self.lp_budget.checked_sub(1)?;
        Some(box_meets_set(&b.lo(), &b.hi(), self.goal) != Meet::Disjoint)
    }
}

/// `Some(why)` when no run of a forced-switching automaton reaches Goal at a sample within `steps`
/// samples (module doc); `None` when one may, or the over-approximation cannot tell.
pub fn goal_unreachable(
    plant: &Hybrid,
    initial: Location,
    init: &InitBox,
    input: &InputSet,
    goal: &SetDesc,
    steps: usize,
) -> Option<Unreachable> {
    let edges = plant.edges();
    if edges.iter().any(|e| e.kind != EdgeKind::Forced) {
        return None;
    }
    let n = plant.n();
    let locs = plant.locations();
    let (uc, ur): (Vec<f64>, Vec<f64>) = match input {
        InputSet::Box { lo, hi } => lo
            .iter()
            .zip(hi)
            .map(|(l, h)| (0.5 * (l + h), 0.5 * (h - l)))
            .unzip(),
        InputSet::Ball { center, radius } => (center.clone(), vec![*radius; center.len()]),
    };
    let state_box = match (&goal.shape, goal.map_matrix(n)) {
        (Shape::Box { lo, hi }, Ok(None)) => Some((lo.clone(), hi.clone())),
        _ => None,
    };
    let mut test = GoalTest {
        goal,
        state_box,
        lp_budget: MAX_SET_TESTS,
    };
    let mut boxes: Vec<Option<CBox>> = vec![None; locs];
    boxes[initial] = Some(CBox {
        c: init.centre(),
        r: init
            .lo
            .iter()
            .zip(&init.hi)
            .map(|(l, h)| 0.5 * (h - l))
            .collect(),
    });
    let mut enabled = vec![false; edges.len()];
    let mut entered = vec![false; locs];
    entered[initial] = true;
    for k in 0..=steps {
        // Switches at this sample: any number along forced edges whose guard may hold (identity resets).
        for _ in 0..locs {
            let mut changed = false;
            for (i, e) in edges.iter().enumerate() {
                let Some(from) = boxes[e.from].clone() else {
                    continue;
                };
                if !from.may_meet(&e.guard.a, &e.guard.b) {
                    continue;
                }
                enabled[i] = true;
                entered[e.to] = true;
                let merged = match &boxes[e.to] {
                    Some(to) => to.hull(&from),
                    None => from,
                };
                let grew = boxes[e.to].as_ref().is_none_or(|to| {
                    merged.lo().iter().zip(to.lo()).any(|(a, b)| *a < b)
                        || merged.hi().iter().zip(to.hi()).any(|(a, b)| *a > b)
                });
                if grew {
                    boxes[e.to] = Some(merged);
                    changed = true;
                }
            }
            if !changed {
                break;
            }
        }
        for b in boxes.iter().flatten() {
            if test.may_meet(b)? {
                return None;
            }
        }
        if k == steps {
            break;
        }
        for (loc, slot) in boxes.iter_mut().enumerate() {
            let Some(b) = slot.as_mut() else { continue };
            let d = plant.error_dynamics(loc);
            let mut c = vec![0.0; n];
            let mut r = vec![0.0; n];
            for i in 0..n {
                let mut ci = d.g[i];
                let mut ri = 0.0;
                let mut mag = d.g[i].abs();
                for j in 0..n {
                    let a = d.A[(i, j)];
                    ci += a * b.c[j];
                    ri += a.abs() * b.r[j];
                    mag += (a * b.c[j]).abs();
                }
                for j in 0..uc.len() {
                    let bb = d.B[(i, j)];
                    ci += bb * uc[j];
                    ri += bb.abs() * ur[j];
                    mag += (bb * uc[j]).abs();
                }
                c[i] = ci;
                r[i] = ri + SLACK * (mag + ri) + f64::MIN_POSITIVE;
            }
            if r.iter()
                .chain(&c)
                .any(|v| !v.is_finite() || v.abs() > MAX_RADIUS)
            {
                return None;
            }
            *b = CBox { c, r };
        }
    }
    let name = |l: Location| plant.modes()[l].name.clone();
    Some(Unreachable {
        steps,
        edges_never_enabled: edges
            .iter()
            .zip(&enabled)
            .filter(|(e, on)| !**on && entered[e.from])
            .map(|(e, _)| format!("{} → {}", name(e.from), name(e.to)))
            .collect(),
        locations_never_entered: (0..locs).filter(|&l| !entered[l]).map(name).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn task(guard: &str) -> crate::spec::Problem {
        let src = include_str!("../../../../examples/hybrid-forced-cart.toml").replacen(
            "from = \"forward\"\nto = \"backward\"\nkind = \"forced\"",
            &format!("from = \"forward\"\nto = \"backward\"\nkind = \"forced\"\n{guard}"),
            1,
        );
        crate::spec::parse(&src, "cart.toml").unwrap_or_else(|e| panic!("{}", e.headline()))
    }

    fn verdict(p: &crate::spec::Problem) -> Option<Unreachable> {
        let h = p.hybrid.as_ref().expect("hybrid");
        let plant = Hybrid::from_spec(h, p.plant.period).expect("automaton");
        goal_unreachable(
            &plant,
            h.initial,
            &p.init,
            &p.input,
            &p.goal,
            p.horizon_steps(),
        )
    }

    #[test]
    fn a_guard_beyond_reach_makes_goal_unreachable_and_is_named() {
        let p = task("guard = { A = [[-1.0, 0.0]], b = [-100.0] }");
        let why = verdict(&p).expect("refused");
        assert_eq!(
            why.edges_never_enabled,
            vec!["forward → backward".to_string()]
        );
        assert_eq!(why.locations_never_entered, vec!["backward".to_string()]);
        let text = why.to_string();
        assert!(text.contains("no run can reach Goal"), "{text}");
        assert!(text.contains("forward → backward"), "{text}");
    }

    #[test]
    fn the_example_with_its_guards_gets_no_verdict() {
        assert_eq!(verdict(&task("")), None);
    }
}

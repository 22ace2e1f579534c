//! Evaluator behaviour (Algorithm 2 with (3.5)–(3.6)): ball selection, out of envelope, the law per step,
//! terminal behaviour, fallbacks, bad input; and an f64 reference comparison on random images.
#![allow(non_snake_case, clippy::needless_range_loop)]

use crate::common::{random_content, Content, FallbackC};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use shared_types::eval::{rejected_image_input, Controller, Input, Status};
use shared_types::image::{decode, Terminal};

/// n = 2, m = 1, two locations; three trajectories:
/// 0: centre (0,0), δ 1, P_0 = I, rows v = 10, 11, 12 (location 0)
/// 1: centre (1,0), δ 1, P_0 = I, rows v = 20, 21 (location 0, then location 1)
/// 2: centre (5,5), δ 1, P_1 = 4 I, row v = 30 (location 1)
fn three_balls() -> Content {
    Content {
        n: 2,
        m: 1,
        nl: 2,
        period: 0.1,
        K: vec![-1.0, -2.0, /* loc 1 */ -3.0, -4.0],
        P: vec![1.0, 0.0, 0.0, 1.0, /* loc 1 */ 4.0, 0.0, 0.0, 4.0],
        traj_len: vec![3, 2, 1],
        centre: vec![0.0, 0.0, 1.0, 0.0, 5.0, 5.0],
        delta: vec![1.0, 1.0, 1.0],
        v: vec![10.0, 11.0, 12.0, 20.0, 21.0, 30.0],
        location: vec![0, 0, 0, 0, 1, 1],
        fallback: FallbackC::Zero,
        input_box: None,
        terminal: Terminal::HoldLast,
    }
}

fn with<R>(c: &Content, f: impl FnOnce(Controller<'_>) -> R) -> R {
    let bytes = c.to_bytes().unwrap();
    let img = decode(&bytes).unwrap();
    f(Controller::new(img))
}

#[test]
fn status_wire_values() {
    assert_eq!(Status::Ok as u8, 0);
    assert_eq!(Status::OutOfEnvelope as u8, 1);
    assert_eq!(Status::BadFrame as u8, 2);
    assert_eq!(Status::ImageRejected as u8, 3);
    for b in 0..=255u8 {
        match Status::from_u8(b) {
            Some(s) => assert_eq!(s as u8, b),
            None => assert!(b > 3),
        }
    }
    assert_eq!(rejected_image_input(3).as_slice(), &[0.0, 0.0, 0.0]);
    assert_eq!(rejected_image_input(100).len(), 6);
}

#[test]
fn selects_nearest_of_overlapping_balls() {
    with(&three_balls(), |ctl| {
        // (0.4, 0): in both balls 0 and 1; nearer to 0.
        assert_eq!(ctl.select(&[0.4, 0.0]), Some(0));
        // (0.6, 0.1): in both; nearer to 1.
        assert_eq!(ctl.select(&[0.6, 0.1]), Some(1));
        // Exactly between: tie goes to the lower index.
        assert_eq!(ctl.select(&[0.5, 0.0]), Some(0));
        // Boundary is inclusive: ‖(−1,0)‖ = 1 = δ_0.
        assert_eq!(ctl.select(&[-1.0, 0.0]), Some(0));
        assert_eq!(ctl.select(&[-1.0001, 0.0]), None);
        // Ball 2 uses P_1 = 4I: (5.4, 5) has ‖·‖_P = 0.8 ≤ 1; (5.6, 5) has 1.2 > 1.
        assert_eq!(ctl.select(&[5.4, 5.0]), Some(2));
        assert_eq!(ctl.select(&[5.6, 5.0]), None);
        assert_eq!(ctl.select(&[5.4]), None);
    });
}

#[test]
fn nearest_is_in_each_balls_own_metric() {
    // Ball 0 at 0 with P = I; ball 1 at (2,0) with P = 0.01 I (wide metric), δ = 1 each.
    // x = (0.9, 0): d0² = 0.81, d1² = 0.01·1.21 = 0.0121 → ball 1, although Euclidean-nearer to ball 0.
    let mut c = three_balls();
    c.nl = 2;
    c.P = vec![1.0, 0.0, 0.0, 1.0, 0.01, 0.0, 0.0, 0.01];
    c.traj_len = vec![1, 1];
    c.centre = vec![0.0, 0.0, 2.0, 0.0];
    c.delta = vec![1.0, 1.0];
    c.v = vec![1.0, 2.0];
    c.location = vec![0, 1];
    with(&c, |ctl| assert_eq!(ctl.select(&[0.9, 0.0]), Some(1)));
}

#[test]
fn applies_K_x_plus_v_row_by_row_with_row_location() {
    with(&three_balls(), |mut ctl| {
        assert_eq!(ctl.step_index(), 0);
        assert_eq!(ctl.active_trajectory(), None);
        let x0 = [0.9, 0.1]; // nearer ball 1
        let u = ctl.step(&x0).unwrap();
        assert_eq!(ctl.active_trajectory(), Some(1));
        assert_eq!(u.as_slice(), &[-0.9 - 2.0 * 0.1 + 20.0]);
        assert_eq!(ctl.step_index(), 1);
        // Row 1 of trajectory 1 is in location 1: K_1 = (−3, −4). The state may leave the ball now.
        let u = ctl.step(&[2.0, 3.0]).unwrap();
        assert_eq!(u.as_slice(), &[-3.0 * 2.0 - 4.0 * 3.0 + 21.0]);
        assert_eq!(ctl.last_input(), u);
        // Terminal HoldLast: keep the last row, with its location's K.
        for k in 2..5 {
            let u = ctl.step(&[1.0, 1.0]).unwrap();
            assert_eq!(u.as_slice(), &[-3.0 - 4.0 + 21.0]);
            assert_eq!(ctl.step_index(), k + 1);
        }
    });
}

#[test]
fn out_of_envelope_is_latched_until_reset() {
    with(&three_balls(), |mut ctl| {
        assert_eq!(ctl.step(&[3.0, 3.0]), Err(Status::OutOfEnvelope));
        assert_eq!(ctl.active_trajectory(), None);
        // Now inside ball 0, but Algorithm 2 selects at κ = 0 only.
        assert_eq!(ctl.step(&[0.0, 0.0]), Err(Status::OutOfEnvelope));
        assert_eq!(ctl.step_index(), 0);
        ctl.reset();
        assert_eq!(ctl.step(&[0.0, 0.0]).unwrap().as_slice(), &[10.0]);
        assert_eq!(ctl.active_trajectory(), Some(0));
    });
}

#[test]
fn bad_state_is_bad_frame_and_does_not_advance() {
    with(&three_balls(), |mut ctl| {
        assert_eq!(ctl.step(&[0.0]), Err(Status::BadFrame));
        assert_eq!(ctl.step(&[0.0, 0.0, 0.0]), Err(Status::BadFrame));
        assert_eq!(ctl.step(&[]), Err(Status::BadFrame));
        assert_eq!(ctl.step(&[f32::NAN, 0.0]), Err(Status::BadFrame));
        assert_eq!(ctl.step(&[0.0, f32::INFINITY]), Err(Status::BadFrame));
        assert_eq!(ctl.step_index(), 0);
        assert_eq!(ctl.step(&[0.0, 0.0]).unwrap().as_slice(), &[10.0]);
        assert_eq!(ctl.step(&[0.0]), Err(Status::BadFrame));
        assert_eq!(ctl.step_index(), 1);
        assert_eq!(ctl.step(&[0.0, 0.0]).unwrap().as_slice(), &[11.0]);
    });
}

#[test]
fn overflowing_input_is_out_of_envelope() {
    with(&three_balls(), |mut ctl| {
        ctl.step(&[0.0, 0.0]).unwrap();
        assert_eq!(ctl.step(&[3.0e38, 3.0e38]), Err(Status::OutOfEnvelope));
        assert_eq!(ctl.step_index(), 1);
    });
}

#[test]
fn terminal_fallback_uses_each_fallback_kind() {
    // Trajectory 0 has 3 rows; from κ = 3 on the fallback applies.
    let x = [0.5, -0.25];
    let mut c = three_balls();
    c.terminal = Terminal::Fallback;
    c.fallback = FallbackC::Hold;
    with(&c, |mut ctl| {
        let mut last = None;
        for _ in 0..3 {
            last = Some(ctl.step(&[0.0, 0.0]).unwrap());
        }
        assert_eq!(last.unwrap().as_slice(), &[12.0]);
        assert_eq!(ctl.step(&x).unwrap().as_slice(), &[12.0]);
        assert_eq!(ctl.step(&x).unwrap().as_slice(), &[12.0]);
    });
    c.fallback = FallbackC::Zero;
    with(&c, |mut ctl| {
        for _ in 0..3 {
            ctl.step(&[0.0, 0.0]).unwrap();
        }
        assert_eq!(ctl.step(&x).unwrap().as_slice(), &[0.0]);
    });
    c.fallback = FallbackC::Linear {
        K: vec![2.0, 4.0],
        x_ref: vec![0.25, 0.25],
        u_ref: vec![0.5],
    };
    with(&c, |mut ctl| {
        for _ in 0..3 {
            ctl.step(&[0.0, 0.0]).unwrap();
        }
        // 2·0.25 + 4·(−0.5) + 0.5 = −1.0
        assert_eq!(ctl.step(&x).unwrap().as_slice(), &[-1.0]);
    });
    c.input_box = Some((vec![-0.75], vec![0.75]));
    with(&c, |mut ctl| {
        for _ in 0..3 {
            ctl.step(&[0.0, 0.0]).unwrap();
        }
        assert_eq!(ctl.step(&x).unwrap().as_slice(), &[-0.75]);
    });
}

#[test]
fn fallback_function_variants() {
    let mut c = three_balls();
    c.fallback = FallbackC::Hold;
    with(&c, |ctl| {
        let last = Input::from_slice(&[3.5]).unwrap();
        assert_eq!(ctl.fallback(&[9.0, 9.0], &last).as_slice(), &[3.5]);
        // Wrong x is irrelevant to hold; a non-finite held value becomes 0.
        assert_eq!(
            ctl.fallback(&[], &Input::from_slice(&[f32::NAN]).unwrap())
                .as_slice(),
            &[0.0]
        );
        // A last input of another dimension: first m values, zero-padded.
        assert_eq!(
            ctl.fallback(&[], &Input::from_slice(&[1.0, 2.0]).unwrap())
                .as_slice(),
            &[1.0]
        );
        assert_eq!(ctl.fallback(&[], &Input::zero(0)).as_slice(), &[0.0]);
    });
    c.fallback = FallbackC::Zero;
    with(&c, |ctl| {
        assert_eq!(
            ctl.fallback(&[1.0, 1.0], &Input::from_slice(&[3.5]).unwrap())
                .as_slice(),
            &[0.0]
        );
    });
    c.fallback = FallbackC::Linear {
        K: vec![1.0, -1.0],
        x_ref: vec![1.0, 2.0],
        u_ref: vec![0.125],
    };
    c.input_box = Some((vec![-2.0], vec![3.0]));
    with(&c, |ctl| {
        let l = Input::from_slice(&[7.0]).unwrap();
        // (3−1) − (2−2) + 0.125
        assert_eq!(ctl.fallback(&[3.0, 2.0], &l).as_slice(), &[2.125]);
        assert_eq!(ctl.fallback(&[10.0, 2.0], &l).as_slice(), &[3.0]);
        assert_eq!(ctl.fallback(&[-10.0, 2.0], &l).as_slice(), &[-2.0]);
        // Unusable state: zero.
        assert_eq!(ctl.fallback(&[1.0], &l).as_slice(), &[0.0]);
        assert_eq!(ctl.fallback(&[f32::NAN, 0.0], &l).as_slice(), &[0.0]);
    });
}

#[test]
fn input_from_slice_rejects_oversize() {
    assert!(Input::from_slice(&[0.0; 7]).is_none());
    let i = Input::from_slice(&[1.0, 2.0]).unwrap();
    assert_eq!(i.len(), 2);
    assert_eq!(i.values(), [1.0, 2.0, 0.0, 0.0, 0.0, 0.0]);
}

/// f64 reference of Algorithm 2 on the stored f32 data: (d², δ²) of every ball, and the selection.
fn reference_select(c: &Content, x: &[f64]) -> (Vec<(f64, f64)>, Option<usize>) {
    let n = c.n;
    let mut start = 0;
    let mut all: Vec<(f64, f64)> = Vec::new();
    let mut best: Option<usize> = None;
    for (t, &len) in c.traj_len.iter().enumerate() {
        let l = c.location[start] as usize;
        let P = &c.P[l * n * n..(l + 1) * n * n];
        let e: Vec<f64> = (0..n).map(|i| x[i] - c.centre[t * n + i] as f64).collect();
        let mut d2 = 0.0;
        for i in 0..n {
            for j in 0..n {
                d2 += e[i] * P[i * n + j] as f64 * e[j];
            }
        }
        let d = c.delta[t] as f64;
        if d2 <= d * d && best.is_none_or(|b| d2 < all[b].0) {
            best = Some(t);
        }
        all.push((d2, d * d));
        start += len;
    }
    (all, best)
}

#[test]
fn f32_evaluator_matches_f64_reference_within_rounding_bound() {
    let mut rng = ChaCha8Rng::seed_from_u64(2024);
    let u_round = f64::from(f32::EPSILON) / 2.0;
    let rel = 1e-4; // f32 distance evaluation with n ≤ 12 is far more accurate than this
    let mut compared_steps = 0;
    let mut agreed = 0;
    let mut near_disagreements = 0;
    for _ in 0..300 {
        let c = random_content(&mut rng, 12, 6, 12, 20);
        let bytes = c.to_bytes().unwrap();
        let img = decode(&bytes).unwrap();
        let (n, m) = (c.n, c.m);
        for _ in 0..5 {
            let mut ctl = Controller::new(img);
            // Start near a random ball centre so most starts are inside.
            let t0 = rng.random_range(0..c.traj_len.len());
            let x0: Vec<f32> = (0..n)
                .map(|i| c.centre[t0 * n + i] + rng.random_range(-0.3f32..0.3))
                .collect();
            let x064: Vec<f64> = x0.iter().map(|&v| v as f64).collect();
            let (d2, reference) = reference_select(&c, &x064);
            let got = ctl
                .step(&x0)
                .ok()
                .and(ctl.active_trajectory())
                .map(|t| t as usize);
            if got != reference {
                // Allowed only within rounding of a boundary or of a tie.
                match (got, reference) {
                    (None, Some(t)) => assert!(d2[t].0 >= d2[t].1 * (1.0 - rel), "{:?}", d2[t]),
                    (Some(t), None) => assert!(d2[t].0 <= d2[t].1 * (1.0 + rel), "{:?}", d2[t]),
                    (Some(a), Some(b)) => {
                        assert!((d2[a].0 - d2[b].0).abs() <= rel * d2[a].0.max(d2[b].0) + 1e-30)
                    }
                    (None, None) => unreachable!(),
                }
                near_disagreements += 1;
                continue;
            }
            let Some(t) = got else {
                assert_eq!(ctl.step(&x0), Err(Status::OutOfEnvelope));
                continue;
            };
            agreed += 1;
            // Replay from scratch and compare every step's input with the f64 reference.
            ctl.reset();
            assert_eq!(ctl.select(&x0), Some(t as u16));
            let start: usize = c.traj_len[..t].iter().sum();
            let len = c.traj_len[t];
            let mut x = x0.clone();
            for k in 0..len + 3 {
                let u = ctl.step(&x).unwrap();
                let row = start + k.min(len - 1);
                if k >= len && c.terminal == Terminal::Fallback {
                    break;
                }
                let l = c.location[row] as usize;
                for j in 0..m {
                    let mut exact = c.v[row * m + j] as f64;
                    let mut abs = exact.abs();
                    for i in 0..n {
                        let p = c.K[(l * m + j) * n + i] as f64 * x[i] as f64;
                        exact += p;
                        abs += p.abs();
                    }
                    // Recursive summation of n products and one addition: |error| ≤ γ_{n+1} Σ|terms|.
                    let k1 = (n + 1) as f64;
                    let gamma = k1 * u_round / (1.0 - k1 * u_round);
                    let err = (u.as_slice()[j] as f64 - exact).abs();
                    assert!(
                        err <= gamma * abs + 1e-30,
                        "err {err} > bound {} (row {row}, j {j})",
                        gamma * abs
                    );
                }
                compared_steps += 1;
                x = (0..n).map(|_| rng.random_range(-4.0f32..4.0)).collect();
            }
        }
    }
    // The test must actually have compared something substantial.
    eprintln!("agreed selections {agreed}, near-boundary disagreements {near_disagreements}, steps {compared_steps}");
    assert!(agreed > 500, "only {agreed} selections compared");
    assert!(
        near_disagreements < 10,
        "{near_disagreements} near-boundary disagreements"
    );
    assert!(
        compared_steps > 5000,
        "only {compared_steps} steps compared"
    );
}

/// Algorithm 2's selection in f32 with the operations in the order `shared_types::linalg` states:
/// e = x − c, sᵢ = ((0 + Pᵢ₀e₀) + Pᵢ₁e₁) + …, d² = ((0 + e₀s₀) + e₁s₁) + …, accepted when d² ≤ δ·δ,
/// the least d² first and ties to the lowest index.
fn f32_select(c: &Content, x: &[f32]) -> Option<u16> {
    let n = c.n;
    let (mut best, mut best_d2, mut start) = (None, f32::INFINITY, 0);
    for (t, &len) in c.traj_len.iter().enumerate() {
        let l = c.location[start] as usize;
        let P = &c.P[l * n * n..(l + 1) * n * n];
        let e: Vec<f32> = (0..n).map(|i| x[i] - c.centre[t * n + i]).collect();
        let mut d2 = 0.0f32;
        for i in 0..n {
            let mut s = 0.0f32;
            for j in 0..n {
                s += P[i * n + j] * e[j];
            }
            d2 += e[i] * s;
        }
        let d = c.delta[t];
        if d2 <= d * d && d2 < best_d2 {
            best_d2 = d2;
            best = Some(t as u16);
        }
        start += len;
    }
    best
}

/// The selection (the fixed-size path of one-location images of dimension 4, and with model maps of
/// dimension 8 too, and the general loop otherwise) answers exactly what the documented f32 operations
/// give, at states near the balls' centres and on their boundaries.
#[test]
fn selection_equals_the_documented_f32_operations() {
    let mut rng = ChaCha8Rng::seed_from_u64(0x5e1);
    for case in 0..900 {
        let c = random_content(&mut rng, 8, 2, 16, 3);
        let bytes = c.to_bytes().unwrap();
        let img = decode(&bytes).unwrap();
        let ctl = Controller::new(img);
        let n = c.n;
        for k in 0..20 {
            let t = rng.random_range(0..c.traj_len.len());
            let mut x: Vec<f32> = (0..n)
                .map(|i| c.centre[t * n + i] + rng.random_range(-1.0f32..1.0))
                .collect();
            if k % 4 == 0 {
                // Onto ball t's boundary along the first axis, where rounding decides.
                let start: usize = c.traj_len[..t].iter().sum();
                let l = c.location[start] as usize;
                let p00 = c.P[l * n * n];
                x = (0..n).map(|i| c.centre[t * n + i]).collect();
                x[0] += c.delta[t] / p00.sqrt();
            }
            let want = f32_select(&c, &x);
            assert_eq!(ctl.select(&x), want, "case {case}, n {n}, x {x:?}");
            assert_eq!(ctl.select_maps(&x), want, "case {case}, n {n}, x {x:?}");
        }
    }
}

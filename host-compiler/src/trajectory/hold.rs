//! Reference hold (move blocking): reference sequences ṽ that are constant over blocks of `hold` samples.
//!
//! The feedback law of Ch. 6 is learned from the pairs (x̃_i(κ), ṽ_i(κ)). §6.2 notes that a piecewise
//! constant law θ_j = 0, θ0_j = ṽ fits a reference that stays constant for extended periods exactly, while
//! a reference that changes by more than the fitting tolerance every sample needs almost one partition per
//! sample. With a continuous-time plant sampled finely, ṽ = ũ − K x̃ changes at every sample even when the
//! applied input ũ is smooth (K moves with the state). Holding ṽ over blocks of L samples (κ = bL ..
//! (b+1)L − 1, counted from κ = 0; the last block may be shorter) makes every block fit one law exactly, so
//! the PWA law needs about N/L partitions per trajectory.
//!
//! The optimisers keep the sequence in this subspace by the Euclidean projection: the block mean. A
//! gradient projected this way is the gradient of the cost over the block values (up to the factor L),
//! so descents and bundle steps started in the subspace stay in it. `hold = 1` is the identity.

/// Replaces every block of `hold` consecutive entries of `v` by its mean (the projection onto
/// block-constant sequences). `hold ≤ 1` leaves `v` unchanged.
pub fn project(v: &mut [Vec<f64>], hold: usize) {
    if hold <= 1 {
        return;
    }
    for block in v.chunks_mut(hold) {
        let m = block[0].len();
        let len = block.len() as f64;
        for i in 0..m {
            let mean = block.iter().map(|r| r[i]).sum::<f64>() / len;
            for r in block.iter_mut() {
                r[i] = mean;
            }
        }
    }
}

/// Whether `v` is constant over every block of `hold` samples (exactly).
pub fn is_held(v: &[Vec<f64>], hold: usize) -> bool {
    hold <= 1 || v.chunks(hold).all(|b| b.iter().all(|r| r == &b[0]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn project_is_the_block_mean_and_idempotent() {
        let mut v = vec![
            vec![1.0, 0.0],
            vec![3.0, 2.0],
            vec![5.0, 4.0],
            vec![7.0, 6.0],
            vec![9.0, 8.0],
        ];
        project(&mut v, 2);
        assert_eq!(
            v,
            vec![
                vec![2.0, 1.0],
                vec![2.0, 1.0],
                vec![6.0, 5.0],
                vec![6.0, 5.0],
                vec![9.0, 8.0]
            ]
        );
        assert!(is_held(&v, 2));
        assert!(!is_held(&v, 3));
        let w = v.clone();
        project(&mut v, 2);
        assert_eq!(v, w);
    }
}

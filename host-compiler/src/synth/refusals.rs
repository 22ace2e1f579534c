//! Where a cover stopped growing: the seeds a growth refused (Algorithm 1's seeds that certified no run),
//! grouped by the kind of their reason, each group with the box of Init it spans. When the growth ends
//! with "a new seed trajectory is needed" (§5.4), this says where one is needed and why the automatic
//! ones failed there.

/// Refused seeds that share the kind of their reason.
#[derive(Clone, Debug, PartialEq)]
pub struct RefusalGroup {
    /// The reason of the group's first seed with its measured values elided ([`kind`]).
    pub reason: String,
    /// Seeds in the group.
    pub count: usize,
    /// The smallest box holding the group's seeds.
    pub lo: Vec<f64>,
    pub hi: Vec<f64>,
}

/// The refused seeds (start, reason) grouped by [`kind`], largest group first (ties in the order of
/// first appearance).
pub fn groups(refused: &[(Vec<f64>, String)]) -> Vec<RefusalGroup> {
    let mut out: Vec<RefusalGroup> = Vec::new();
    for (x, why) in refused {
        let reason = kind(why);
        match out.iter_mut().find(|g| g.reason == reason) {
            Some(g) => {
                g.count += 1;
                for (i, &v) in x.iter().enumerate().take(g.lo.len()) {
                    g.lo[i] = g.lo[i].min(v);
                    g.hi[i] = g.hi[i].max(v);
                }
            }
            None => out.push(RefusalGroup {
                reason,
                count: 1,
                lo: x.clone(),
                hi: x.clone(),
            }),
        }
    }
    // Stable: equal counts keep their first appearance.
    out.sort_by_key(|g| std::cmp::Reverse(g.count));
    out
}

/// A reason's kind: the text with every bracketed list replaced by `[…]` and every measured number (one
/// with a decimal point or an exponent) by `…`; integers (segment indices, step counts) and references
/// (Theorem 4.7) stay.
pub fn kind(why: &str) -> String {
    let mut out = String::with_capacity(why.len());
    let chars: Vec<char> = why.chars().collect();
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        if c == '[' {
            let mut depth = 0usize;
            while i < chars.len() {
                match chars[i] {
                    '[' => depth += 1,
                    ']' => depth -= 1,
                    _ => {}
                }
                i += 1;
                if depth == 0 {
                    break;
                }
            }
            out.push_str("[…]");
            continue;
        }
        // A number starts a word (`x1`'s digit is part of a name).
        let in_word = out
            .chars()
            .last()
            .is_some_and(|p| p.is_alphanumeric() || p == '_');
        let signed = c == '-' && chars.get(i + 1).is_some_and(|d| d.is_ascii_digit());
        if !in_word && (c.is_ascii_digit() || signed) {
            let start = i;
            i += 1;
            while i < chars.len() {
                let d = chars[i];
                let sign_after_e = matches!(d, '+' | '-') && matches!(chars[i - 1], 'e' | 'E');
                if d.is_ascii_digit() || d == '.' || matches!(d, 'e' | 'E') || sign_after_e {
                    i += 1;
                } else {
                    break;
                }
            }
            // A sentence's full stop is not the number's.
            while i > start + 1 && chars[i - 1] == '.' {
                i -= 1;
            }
            let token: String = chars[start..i].iter().collect();
            // A reference (Theorem 4.7, §5.3) names a result, not a value.
            let reference = ["Theorem ", "Lemma ", "Definition ", "Example ", "§"]
                .iter()
                .any(|w| out.ends_with(w));
            if !reference && token.contains(['.', 'e', 'E']) {
                out.push('…');
            } else {
                out.push_str(&token);
            }
            continue;
        }
        out.push(c);
        i += 1;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_reason_s_kind_elides_its_values_and_keeps_its_indices() {
        assert_eq!(
            kind("segment 0 (left): no trajectory from x0 = [-4.02, 0.4, -0.93] reaches Goal in 700 steps"),
            "segment 0 (left): no trajectory from x0 = […] reaches Goal in 700 steps"
        );
        assert_eq!(
            kind(
                "δ = 3.215e-1 is below min_robustness = 4.000e-1 (δ_Input = 1.2e0 at t = 0.12 s)."
            ),
            "δ = … is below min_robustness = … (δ_Input = … at t = … s)."
        );
        assert_eq!(kind("x1 at -2.5 and K2"), "x1 at … and K2");
        assert_eq!(
            kind("segment 1 (right): δ = 3.1e-1, Theorem 4.7 (Goal, Unsafe, Input); §5.3"),
            "segment 1 (right): δ = …, Theorem 4.7 (Goal, Unsafe, Input); §5.3"
        );
    }

    #[test]
    fn refused_seeds_group_by_kind_with_the_box_they_span() {
        let refused = vec![
            (
                vec![-5.0, 1.0],
                "δ = 1.0e-1 is below min_robustness = 4.0e-1".to_string(),
            ),
            (
                vec![-4.5, 0.2],
                "segment 0 (left): no trajectory".to_string(),
            ),
            (
                vec![-4.0, 1.5],
                "δ = 2.5e-1 is below min_robustness = 4.0e-1".to_string(),
            ),
            (
                vec![-6.0, 0.5],
                "δ = 3.0e-1 is below min_robustness = 4.0e-1".to_string(),
            ),
        ];
        let g = groups(&refused);
        assert_eq!(g.len(), 2);
        assert_eq!(g[0].reason, "δ = … is below min_robustness = …");
        assert_eq!((g[0].count, g[1].count), (3, 1));
        assert_eq!(
            (g[0].lo.clone(), g[0].hi.clone()),
            (vec![-6.0, 0.5], vec![-4.0, 1.5])
        );
        assert_eq!(
            (g[1].lo.clone(), g[1].hi.clone()),
            (vec![-4.5, 0.2], vec![-4.5, 0.2])
        );
        assert!(groups(&[]).is_empty());
    }
}

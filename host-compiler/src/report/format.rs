//! Text formatting for the report: numbers to four significant digits (scientific for tiny or huge
//! values), percentages, grouped counts, vectors, and HTML escaping.

/// Four significant digits; scientific (`1.235e-5`) when |x| < 10⁻³ or |x| ≥ 10⁶; `0` for zero;
/// trailing zeros trimmed. Non-finite values print as `NaN`, `∞`, `−∞`.
pub fn num(x: f64) -> String {
    sig(x, 4)
}

/// Like [`num`] with `digits` significant digits (at least 1).
pub fn sig(x: f64, digits: usize) -> String {
    let digits = digits.max(1);
    if x.is_nan() {
        return "NaN".into();
    }
    if x.is_infinite() {
        return if x > 0.0 {
            "∞".into()
        } else {
            "−∞".into()
        };
    }
    if x == 0.0 {
        return "0".into();
    }
    let ax = x.abs();
    if !(1e-3..1e6).contains(&ax) {
        let s = format!("{:.*e}", digits - 1, x);
        let (mant, exp) = s.split_once('e').unwrap_or((&s, "0"));
        return format!("{}e{}", trim_zeros(mant), exp);
    }
    // Decimals so that `digits` significant digits remain; rounding can carry into a new digit
    // (9.9996 → 10.00), which the decimal count computed from the rounded value handles.
    let mut decimals = (digits as i32 - 1 - ax.log10().floor() as i32).max(0) as usize;
    let rounded: f64 = format!("{:.*}", decimals, x).parse().unwrap_or(x);
    if rounded.abs() >= 10f64.powi(digits as i32 - decimals as i32) && decimals > 0 {
        decimals -= 1;
    }
    trim_zeros(&format!("{:.*}", decimals, x)).to_string()
}

fn trim_zeros(s: &str) -> &str {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        s
    }
}

/// A fraction in [0, 1] as a percentage with up to four significant digits, e.g. `99.21 %`.
pub fn pct(frac: f64) -> String {
    if !frac.is_finite() {
        return num(frac);
    }
    let p = 100.0 * frac;
    // Do not round 99.996 % up to 100 % — the difference matters for a coverage claim.
    let s = if p != 100.0 && p > 99.99 && p < 100.0 {
        directed(p, 4, Round::Down, 100.0)
    } else {
        sig(p, 4)
    };
    format!("{} %", trim_zeros(&s))
}

/// Which way a shown number may be rounded: toward the weaker claim. A lower bound or a confidence
/// shown larger than computed would claim what the run did not show, so it is rounded [`Round::Down`];
/// an upper bound is rounded [`Round::Up`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Round {
    Down,
    Up,
}

/// `x` with at least `decimals` decimals, rounded in direction `dir`, and with more decimals where
/// needed so that a value below `limit` never shows as `limit` (e.g. a confidence 1 − 10⁻¹² is
/// `0.999999999999`, not `1`). At most 17 decimals; trailing zeros trimmed.
pub fn directed(x: f64, decimals: usize, dir: Round, limit: f64) -> String {
    if !x.is_finite() {
        return num(x);
    }
    let gap = match dir {
        Round::Down => limit - x,
        Round::Up => x - limit,
    };
    let mut d = decimals;
    if gap > 0.0 && gap.is_finite() {
        // 10^-d ≤ gap: the rounded value cannot reach `limit`.
        d = d.max((-gap.log10()).ceil().max(0.0) as usize);
    }
    let d = d.min(17);
    let scale = 10f64.powi(d as i32);
    // x·10^d within 10⁻¹² (relative) of an integer is that integer: binary rounding of x itself (0.99 is
    // stored a hair below 0.99) must not take a decimal down a digit.
    let y = x * scale;
    let r = if (y - y.round()).abs() <= 1e-12 * y.abs() {
        y.round()
    } else {
        match dir {
            Round::Down => y.floor(),
            Round::Up => y.ceil(),
        }
    } / scale;
    let crossed = match dir {
        Round::Down => x < limit && r >= limit,
        Round::Up => x > limit && r <= limit,
    };
    if crossed {
        // Beyond f64's decimal resolution: the shortest text that reads back as x itself.
        return format!("{x:?}");
    }
    trim_zeros(&format!("{r:.d$}")).to_string()
}

/// A fraction as a percentage with two decimals (more where needed), rounded toward the weaker claim
/// ([`directed`]); `100 %` only for exactly 1 (when rounding down).
pub fn pct_directed(frac: f64, dir: Round) -> String {
    if !frac.is_finite() {
        return num(frac);
    }
    let limit = match dir {
        Round::Down => 100.0,
        Round::Up => 0.0,
    };
    format!("{} %", directed(100.0 * frac, 2, dir, limit))
}

/// A lower bound or a confidence in [0, 1] as a percentage, rounded down ([`pct_directed`]).
pub fn pct_down(frac: f64) -> String {
    pct_directed(frac, Round::Down)
}

/// An upper bound in [0, 1] as a percentage, rounded up ([`pct_directed`]).
pub fn pct_up(frac: f64) -> String {
    pct_directed(frac, Round::Up)
}

/// A count with thin-space digit groups: `10 000` (U+202F narrow no-break space).
pub fn count(n: usize) -> String {
    let s = n.to_string();
    if s.len() <= 4 {
        return s;
    }
    let mut out = String::new();
    for (i, ch) in s.chars().enumerate() {
        if i > 0 && (s.len() - i).is_multiple_of(3) {
            out.push('\u{202F}');
        }
        out.push(ch);
    }
    out
}

/// A vector as `[a, b, c]` with [`num`] entries.
pub fn vector(v: &[f64]) -> String {
    let parts: Vec<String> = v.iter().map(|&x| num(x)).collect();
    format!("[{}]", parts.join(", "))
}

/// A duration in seconds: `12.3 ms`, `4.56 s`, `2 min 5.1 s`.
pub fn seconds(s: f64) -> String {
    if !s.is_finite() {
        return num(s);
    }
    if s.abs() < 1.0 && s != 0.0 {
        return format!("{} ms", sig(s * 1e3, 3));
    }
    if s.abs() < 120.0 {
        return format!("{} s", sig(s, 3));
    }
    let min = (s / 60.0).floor();
    format!("{} min {} s", min, sig(s - 60.0 * min, 3))
}

/// A byte count: `1 234 B (1.21 KiB)`.
pub fn bytes(n: usize) -> String {
    if n < 1024 {
        format!("{} B", n)
    } else if n < 1024 * 1024 {
        format!("{} B ({} KiB)", count(n), sig(n as f64 / 1024.0, 3))
    } else {
        format!(
            "{} B ({} MiB)",
            count(n),
            sig(n as f64 / (1024.0 * 1024.0), 3)
        )
    }
}

/// Escapes text for HTML element content and attribute values.
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for ch in s.chars() {
        match ch {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

//! Numbers beyond ±`MAX_MAGNITUDE` in a spec (issue 18: an Init box spanning ±1e308 used to panic when
//! Init was sampled, its width overflowing to ∞) are diagnostics at their line and column, whatever key
//! they are under.

use crate::spec_errors::pos;
use host_compiler::spec::{self, ErrorKind, MAX_MAGNITUDE};

pub(crate) const BASE: &str = r#"seed = 3
horizon = 2.0

[plant]
time = "continuous"
A = [[0.0, 1.0], [0.0, 0.0]]
B = [[0.0], [1.0]]
period = 0.1

[init]
kind = "box"
lo = [-0.1, 0.0]
hi = [0.1, 0.0]

[goal]
kind = "ball"
center = [1.0, 0.0]
radius = 0.2

[input]
kind = "box"
lo = [-1.0]
hi = [1.0]
"#;

/// `BASE` with the first `from` (which must exist) replaced by `to`.
pub(crate) fn edit(from: &str, to: &str) -> String {
    assert!(BASE.contains(from), "test bug: `{from}` not in BASE");
    BASE.replacen(from, to, 1)
}

/// Refused with `kind`, the diagnostic at the first `needle` of `src`; returns the message.
#[track_caller]
pub(crate) fn refused(src: &str, kind: ErrorKind, needle: &str) -> String {
    let e = spec::parse(src, "spec.toml").expect_err("must be refused");
    assert_eq!(e.kind(), kind, "{}", e.message());
    assert_eq!(
        e.line_col(),
        Some(pos(src, needle, needle)),
        "{}",
        e.message()
    );
    e.message().to_string()
}

#[test]
fn numbers_beyond_the_magnitude_bound_are_diagnostics_at_their_place() {
    // The case of the issue: an Init box spanning ±1e308 (its width overflows to ∞).
    let src = edit(
        "lo = [-0.1, 0.0]\nhi = [0.1, 0.0]",
        "lo = [-1e308, 0.0]\nhi = [1e308, 0.0]",
    );
    let msg = refused(&src, ErrorKind::OutOfRange, "-1e308");
    assert!(msg.contains("init.lo[0]") && msg.contains("1e12"), "{msg}");
    // The same class elsewhere: a matrix entry, a radius, an input bound, the period.
    let src = edit("A = [[0.0, 1.0]", "A = [[0.0, 2e300]");
    refused(&src, ErrorKind::OutOfRange, "2e300");
    let src = edit("radius = 0.2", "radius = 1e200");
    refused(&src, ErrorKind::OutOfRange, "1e200");
    let src = edit("hi = [1.0]", "hi = [5e12]");
    refused(&src, ErrorKind::OutOfRange, "5e12");
    // At the bound itself the spec is accepted.
    let src = edit("hi = [1.0]", &format!("hi = [{MAX_MAGNITUDE:e}]"));
    spec::parse(&src, "spec.toml").unwrap();
}

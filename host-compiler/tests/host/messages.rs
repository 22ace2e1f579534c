//! Messages that name the place and the reason (issue 18): a plant whose sampling overflows says so, one
//! that no input reaches names the mode and the spec keys (no Rust debug dump), and user text quoted in
//! an error is an excerpt, never a whole huge line.

use host_compiler::robustness::mtl::Trace;
use host_compiler::spec;
use host_compiler::task::Task;

use crate::spec_bounds::edit;

#[test]
fn plants_that_cannot_be_sampled_or_reached_are_readable_messages() {
    // exp(A·h) overflows: said as such, not as a non-finite entry of A.
    let src = edit(
        "A = [[0.0, 1.0], [0.0, 0.0]]",
        "A = [[1e4, 0.0], [0.0, 0.0]]",
    );
    let Err(e) = Task::new(spec::parse(&src, "s").unwrap()) else {
        panic!("exp(A·h) of e^1000 was accepted");
    };
    let msg = e.to_string();
    assert!(
        msg.contains("exp(A·h) overflows") && msg.contains("plant.period"),
        "{msg}"
    );
    // No input reaches the second state, which is unstable: the message names the mode and the keys,
    // not a Rust debug dump.
    let src = edit(
        "A = [[0.0, 1.0], [0.0, 0.0]]",
        "A = [[0.0, 0.0], [0.0, 0.5]]",
    )
    .replacen("B = [[0.0], [1.0]]", "B = [[1.0], [0.0]]", 1);
    let task = Task::new(spec::parse(&src, "s").unwrap()).unwrap();
    let Err(e) = host_compiler::caf::design(&task) else {
        panic!("a plant with an unreachable unstable mode was stabilised");
    };
    let msg = e.to_string();
    assert!(
        msg.contains("not stabilizable") && msg.contains("plant.A and plant.B"),
        "{msg}"
    );
    assert!(!msg.contains("Complex {") && !msg.contains("re:"), "{msg}");
}

#[test]
fn huge_fields_and_headers_are_quoted_as_excerpts() {
    // A header of a million signals and a row with one field too few: the error names the line and
    // the count, and quotes a bounded excerpt of the names.
    let names: Vec<String> = (0..1_000_000).map(|i| format!("s{i}")).collect();
    let text = format!(
        "t,{}\n0,{}\n",
        names.join(","),
        vec!["1"; 999_999].join(",")
    );
    let e = Trace::from_csv_str(&text, "big.csv")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("big.csv:2") && e.contains("expected 1000001"),
        "{}",
        &e[..e.len().min(300)]
    );
    assert!(e.len() < 1_000, "{} bytes", e.len());
    // A huge field that is not a number.
    let text = format!("t,x\n0,{}\n", "z".repeat(1_000_000));
    let e = Trace::from_csv_str(&text, "big.csv")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("is not a number") && e.contains("1000000 characters"),
        "{}",
        &e[..e.len().min(300)]
    );
    assert!(e.len() < 1_000, "{} bytes", e.len());
    // A huge name in a formula (within the formula's length limit, `spec::limits::MAX_FORMULA_LEN`;
    // a longer text is refused by its length, `plain_bounds`).
    let f = format!("x1 <= 1 {}", "y".repeat(4_000));
    let e = host_compiler::robustness::mtl::Formula::parse(&f).unwrap_err();
    assert!(
        e.message.contains("yyy…"),
        "{}",
        &e.message[..e.message.len().min(300)]
    );
    assert!(e.message.len() < 1_000, "{} bytes", e.message.len());
}

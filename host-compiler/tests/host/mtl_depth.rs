//! Formulas that are long or deep (issue 18): chains of `&`/`|` parse and evaluate flat (up to the
//! atom limit, issue 42), and nesting past `MAX_DEPTH` — parentheses, `!`, `F`/`G`, `->`, `U` — is an
//! error naming the position and the limit, never a stack overflow.

use host_compiler::robustness::mtl::parse::MAX_DEPTH;
use host_compiler::robustness::mtl::{Formula, FormulaErrorKind, Trace};

fn trace() -> Trace {
    Trace::from_csv_str("t,x1\n0,0.5\n1,2\n2,-1\n", "trace.csv").unwrap()
}

#[test]
fn chains_of_the_most_atoms_evaluate() {
    let tr = trace();
    let most = host_compiler::robustness::mtl::parse::MAX_FORMULA_ATOMS;
    // x1 <= 3 & x1 <= 4 & … & x1 <= 258: the tightest term is x1 <= 3.
    let and: Vec<String> = (0..most).map(|i| format!("x1 <= {}", i + 3)).collect();
    let f = Formula::parse(&and.join(" & ")).unwrap();
    let rho = f.bind(tr.names(), &[]).unwrap().robustness(&tr).unwrap();
    assert_eq!(rho, vec![2.5, 1.0, 4.0]);
    // x1 >= 3 | x1 >= 4 | …: the loosest term is x1 >= 3.
    let or: Vec<String> = (0..most).map(|i| format!("x1 >= {}", i + 3)).collect();
    let f = Formula::parse(&or.join(" || ")).unwrap();
    let rho = f.bind(tr.names(), &[]).unwrap().robustness(&tr).unwrap();
    assert_eq!(rho, vec![-2.5, -1.0, -4.0]);
    // The printed form is as flat and parses back to itself (printing spells each predicate out, so a
    // chain short enough that its printed form is within the length limit).
    let f = Formula::parse(&or[..150].join(" || ")).unwrap();
    let printed = f.expr().to_string();
    assert_eq!(
        Formula::parse(&printed).unwrap().expr().to_string(),
        printed
    );
}

#[track_caller]
fn too_deep(src: &str, column: usize) {
    let e = Formula::parse(src).expect_err("deeper than the limit");
    assert_eq!(e.kind, FormulaErrorKind::TooDeep { limit: MAX_DEPTH });
    assert_eq!((e.line, e.column), (1, column), "{e}");
    let msg = e.to_string();
    assert!(
        msg.contains(&format!("column {column}")) && msg.contains(&MAX_DEPTH.to_string()),
        "{msg}"
    );
}

#[test]
fn deep_nesting_is_an_error_at_the_level_past_the_limit() {
    let atom = "x1 <= 1";
    // 1 000 nested parentheses: the (MAX_DEPTH + 1)-th `(` opens one level too many; the error points
    // at it. (Each formula stays within the length limit, `parse::MAX_FORMULA_LEN`.)
    let parens = format!("{}{atom}{}", "(".repeat(1000), ")".repeat(1000));
    too_deep(&parens, MAX_DEPTH + 1);
    too_deep(&format!("{}{atom}", "!".repeat(2_000)), MAX_DEPTH + 1);
    too_deep(&format!("{}{atom}", "F ".repeat(1_000)), 2 * MAX_DEPTH + 1);
    too_deep(
        &format!("{}{atom}", "G[0,1] ".repeat(500)),
        7 * MAX_DEPTH + 1,
    );
    // `x1 <= 1 -> x1 <= 1 -> …`: the k-th arrow starts at column 9 + 11 (k − 1).
    too_deep(&vec![atom; 200].join(" -> "), 11 * MAX_DEPTH + 9);
    // `a U a U …`: the k-th `U` is at column 3 + 4 (k − 1).
    too_deep(&vec!["a"; 200].join(" U "), 4 * MAX_DEPTH + 3);
}

#[test]
fn nesting_at_the_limit_parses_prints_and_evaluates() {
    let tr = trace();
    let atom = "x1 <= 1";
    // (src, whether its printed form parses back: printing parenthesises a predicate, `->` and `U`,
    // which adds levels, so only formulas one level below the limit reprint).
    let below = MAX_DEPTH - 1;
    for (src, reprints) in [
        (
            format!("{}{atom}{}", "(".repeat(MAX_DEPTH), ")".repeat(MAX_DEPTH)),
            true,
        ),
        (format!("{}{atom}", "!".repeat(MAX_DEPTH)), false),
        (format!("{}{atom}", "G[0,1] ".repeat(MAX_DEPTH)), false),
        (format!("{}{atom}", "!".repeat(below)), true),
        (format!("{}{atom}", "G[0,1] ".repeat(below)), true),
        (vec![atom; MAX_DEPTH + 1].join(" -> "), false),
        (vec![atom; MAX_DEPTH + 1].join(" U "), false),
    ] {
        let f = Formula::parse(&src).unwrap_or_else(|e| panic!("{e}"));
        let rho = f.bind(tr.names(), &[]).unwrap().robustness(&tr).unwrap();
        assert_eq!(rho.len(), 3);
        assert!(rho.iter().all(|r| !r.is_nan()), "{rho:?}");
        if reprints {
            let printed = f.expr().to_string();
            let again = Formula::parse(&printed).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(again.expr().to_string(), printed);
        }
    }
}

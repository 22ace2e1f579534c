//! Formula errors (column and what was expected), binding errors (unknown names), and CSV trace errors
//! (line and column) of the MTL monitor.

use host_compiler::geometry::{Metric, Region, Witness};
use host_compiler::robustness::mtl::{Formula, FormulaErrorKind, NamedSet, Trace, TraceError};

#[track_caller]
fn syntax(src: &str, column: usize, expected_contains: &str) {
    let e = Formula::parse(src).expect_err(src);
    assert_eq!(e.column, column, "{src}: {e}");
    let exp = e
        .expected()
        .unwrap_or_else(|| panic!("{src}: not a syntax error: {e}"));
    assert!(
        exp.contains(expected_contains),
        "{src}: expected {exp:?} to mention {expected_contains:?}"
    );
    // The message repeats both the expectation and the column.
    let msg = e.to_string();
    assert!(
        msg.contains(&format!("column {column}")) && msg.contains(exp),
        "{msg}"
    );
}

#[test]
fn syntax_errors_point_at_the_column_and_say_what_was_expected() {
    syntax("", 1, "a formula");
    syntax("x1 >= ", 7, "a number or a signal name");
    syntax("x1 >= 0 &", 10, "a formula");
    syntax("(x1 >= 0", 9, "`)`");
    syntax("x1 >= 0 x2", 9, "end of the formula");
    syntax("G[0,1 x1 >= 0", 7, "`]`");
    syntax("G[0 1] x1 >= 0", 5, "`,`");
    syntax("G[-1,2] x1 >= 0", 3, "non-negative number");
    syntax("G[1,x] x1 >= 0", 5, "`inf`");
    syntax("x1 # 2", 4, "an operator");
    syntax("x1 + 2", 7, "comparison");
    syntax("x1 * x2 <= 1", 6, "a number (a coefficient)");
    syntax("F <= 2", 3, "a formula");
    syntax("2*U <= 1", 3, "a signal name");
    syntax("a U", 4, "a formula");
    syntax("a R[1,2] ", 10, "a formula");
    // Columns count characters, not bytes.
    syntax("x1 >= 0 & é", 11, "an operator");
    // Second line: the column is relative to the line.
    let e = Formula::parse("x1 >= 0 &\n  & x2 <= 1").unwrap_err();
    assert_eq!((e.line, e.column), (2, 3));
}

#[test]
fn semantic_errors_in_the_text() {
    let e = Formula::parse("G[2,1] x1 >= 0").unwrap_err();
    assert_eq!(e.kind, FormulaErrorKind::BadInterval);
    assert_eq!(e.column, 2);
    let e = Formula::parse("x >= 0 & x1 - x1 <= 2").unwrap_err();
    assert_eq!(e.kind, FormulaErrorKind::DegeneratePredicate);
    assert_eq!(e.column, 10);
    let e = Formula::parse("1 <= 2").unwrap_err();
    assert_eq!(e.kind, FormulaErrorKind::DegeneratePredicate);
    let e = Formula::parse("x1 <= 1e999").unwrap_err();
    assert_eq!(e.kind, FormulaErrorKind::BadNumber);
    assert_eq!(e.column, 7);
}

struct Everything;
impl Region for Everything {
    fn dim(&self) -> usize {
        1
    }
    fn contains(&self, _: &[f64]) -> bool {
        true
    }
    fn dist(&self, x: &[f64], _: &Metric) -> Witness {
        Witness {
            value: 0.0,
            point: x.to_vec(),
        }
    }
    fn depth(&self, x: &[f64], _: &Metric) -> Witness {
        Witness {
            value: f64::INFINITY,
            point: x.to_vec(),
        }
    }
}

#[test]
fn binding_errors_name_the_unknown_thing() {
    let names = vec!["x1".to_string(), "x2".to_string()];
    let sets = vec![NamedSet::euclidean(
        "Safe",
        vec!["x1".into()],
        Box::new(Everything),
    )];
    let bind = |s: &str| {
        Formula::parse(s)
            .unwrap()
            .bind(&names, &sets)
            .err()
            .expect(s)
    };

    let e = bind("G (x1 >= 0 & x9 <= 1)");
    assert_eq!(e.kind, FormulaErrorKind::UnknownName { name: "x9".into() });
    assert_eq!(e.column, 14);
    assert!(
        e.help.as_deref().unwrap().contains("x1, x2"),
        "help lists the signals"
    );

    let e = bind("F Obstacle");
    assert_eq!(
        e.kind,
        FormulaErrorKind::UnknownName {
            name: "Obstacle".into()
        }
    );
    assert_eq!(e.column, 3);
    assert!(
        e.help.as_deref().unwrap().contains("Safe"),
        "help lists the sets"
    );

    let e = bind("x1 & Safe");
    assert!(
        e.message.contains("is a signal, not a set"),
        "{}",
        e.message
    );

    let sets2 = vec![NamedSet::euclidean(
        "Bad",
        vec!["x7".into()],
        Box::new(Everything),
    )];
    let e = Formula::parse("Bad")
        .unwrap()
        .bind(&names, &sets2)
        .err()
        .unwrap();
    assert!(matches!(e.kind, FormulaErrorKind::SetMismatch { .. }));
    let sets3 = vec![NamedSet::euclidean(
        "Bad",
        vec!["x1".into(), "x2".into()],
        Box::new(Everything),
    )];
    let e = Formula::parse("Bad")
        .unwrap()
        .bind(&names, &sets3)
        .err()
        .unwrap();
    assert!(e.message.contains("dimension 1"), "{}", e.message);
    // Bound to one layout, refuses another.
    let m = Formula::parse("x1 >= 0")
        .unwrap()
        .bind(&names, &[])
        .unwrap();
    let other = Trace::new(
        vec![0.0],
        vec!["x2".into(), "x1".into()],
        vec![vec![0.0], vec![0.0]],
    )
    .unwrap();
    assert!(m.robustness(&other).is_err());
}

fn csv(text: &str) -> TraceError {
    Trace::from_csv_str(text, "trace.csv").expect_err(text)
}

#[test]
fn csv_errors_have_line_and_column() {
    assert!(matches!(csv(""), TraceError::Empty { .. }));
    assert!(matches!(csv("\n  \n"), TraceError::Empty { .. }));
    assert!(matches!(csv("t,x1\n"), TraceError::NoRows { .. }));

    let e = csv("time,x1\n0,1\n");
    assert_eq!((e.line(), e.column()), (Some(1), Some(1)));
    assert!(e.to_string().contains("must be named `t`"), "{e}");
    let e = csv("t,x1,x1\n0,1,2\n");
    assert_eq!((e.line(), e.column()), (Some(1), Some(3)));
    let e = csv("t,x1,\n0,1,2\n");
    assert_eq!((e.line(), e.column()), (Some(1), Some(3)));

    // Missing column on line 3: says which.
    let e = csv("t,x1,x2\n0,1,2\n1,2\n");
    assert_eq!(e.line(), Some(3));
    let msg = e.to_string();
    assert!(
        msg.contains("trace.csv:3") && msg.contains("missing `x2`"),
        "{msg}"
    );
    let e = csv("t,x1\n0,1,2\n");
    assert!(e.to_string().contains("1 extra"), "{e}");

    // Non-numeric field: line 3, field 2 (`x1`), character column 5.
    let e = csv("t,x1\n0,1\n1,  abc\n");
    assert_eq!((e.line(), e.column()), (Some(3), Some(2)));
    let msg = e.to_string();
    assert!(
        msg.contains("trace.csv:3:5")
            && msg.contains("`x1`")
            && msg.contains("`abc` is not a number"),
        "{msg}"
    );
    let e = csv("t,x1\n0,NaN\n");
    assert!(
        matches!(
            e,
            TraceError::NonFinite {
                line: 2,
                column: 2,
                ..
            }
        ),
        "{e}"
    );
    let e = csv("t,x1\n,1\n");
    assert!(
        matches!(
            e,
            TraceError::NotNumeric {
                line: 2,
                column: 1,
                ..
            }
        ),
        "{e}"
    );

    // Time must increase strictly.
    let e = csv("t,x1\n0,1\n1,1\n1,2\n");
    assert_eq!((e.line(), e.column()), (Some(4), Some(1)));
    assert!(e.to_string().contains("t = 1 follows t = 1"), "{e}");
    let e = csv("t,x1\n0,1\n\n-1,1\n");
    assert_eq!(
        e.line(),
        Some(4),
        "blank lines still count for line numbers"
    );
}

#[test]
fn csv_accepts_crlf_spaces_and_blank_lines() {
    let tr = Trace::from_csv_str("t, x1 ,x2\r\n0, 1, 2\r\n\r\n0.5,3,-4e-1\r\n", "x").unwrap();
    assert_eq!(tr.times(), &[0.0, 0.5]);
    assert_eq!(tr.names(), &["x1".to_string(), "x2".to_string()]);
    assert_eq!(tr.signal("x2").unwrap(), &[2.0, -0.4]);
    assert!(tr.signal("x3").is_none());
    let only_t = Trace::from_csv_str("t\n0\n1\n", "x").unwrap();
    assert_eq!(only_t.len(), 2);
}

#[test]
fn trace_constructor_validates() {
    assert!(Trace::new(vec![], vec![], vec![]).is_err());
    assert!(Trace::new(vec![0.0, 0.0], vec![], vec![]).is_err());
    assert!(Trace::new(vec![0.0], vec!["a".into()], vec![vec![]]).is_err());
    assert!(Trace::new(vec![0.0], vec!["t".into()], vec![vec![1.0]]).is_err());
    assert!(Trace::new(
        vec![0.0],
        vec!["a".into(), "a".into()],
        vec![vec![1.0], vec![1.0]]
    )
    .is_err());
    assert!(Trace::new(vec![0.0], vec!["a".into()], vec![vec![f64::NAN]]).is_err());
}

/// One CSV dialect for traces, recordings and `simulate`'s output: a byte-order mark, comment lines
/// (such as a recording's `# x0` line) and a `status` column are accepted; every other field must still
/// be a number, named at its own column.
#[test]
fn traces_accept_a_bom_comments_and_a_status_column() {
    let t = Trace::from_csv_str(
        "\u{feff}# x0 = 0, 1\nt,x1,status,x2\n# a comment\n0,0,ok,1\n0.1,0.5,out-of-envelope,2\n",
        "sim.csv",
    )
    .unwrap();
    assert_eq!(t.names(), ["x1", "x2"]);
    assert_eq!(t.len(), 2);
    assert_eq!(t.columns()[1], vec![1.0, 2.0]);
    let e = Trace::from_csv_str("t,x1,status,x2\n0,0,ok,one\n", "sim.csv").unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("sim.csv:2:"), "{msg}");
    assert!(msg.contains("x2"), "{msg}");
}

//! Tests of the expression language: parsing and its errors, derivatives against hand-derived ones, the
//! relative degree and Γ of Example 3.7 / 4.9, compilation against f64, and the interval enclosures and
//! f32 rounding bound at random points of their box.

use super::compile::compile;
use super::diff::{derivative, jacobian, lie, AffineSystem, RelativeDegreeError};
use super::interval::{
    certainly_regular, enclose, enclose_matrix, rounding_bound, Interval, IntervalError, VarBox,
};
use super::*;
use proptest::prelude::*;

fn names() -> Names {
    Names {
        states: (1..=6).map(|i| format!("x{i}")).collect(),
        inputs: vec!["u1".into(), "u2".into()],
        params: vec![("a".into(), 1.5), ("b".into(), 0.5)],
    }
}

fn p(text: &str) -> Expr {
    parse(text, &names()).unwrap_or_else(|e| panic!("{text}: {e}"))
}

fn at<'a>(x: &'a [f64], u: &'a [f64], params: &'a [f64]) -> Point<'a> {
    Point { x, u, p: params }
}

const PARAMS: [f64; 2] = [1.5, 0.5];

#[test]
fn names_are_validated() {
    assert!(names().validate().is_ok());
    let mut n = names();
    n.inputs.push("x1".into());
    assert!(matches!(n.validate(), Err(ExprError::BadName { why, .. }) if why.contains("twice")));
    let mut n = names();
    n.params.push(("sin".into(), 1.0));
    assert!(
        matches!(n.validate(), Err(ExprError::BadName { why, .. }) if why.contains("reserved"))
    );
    let mut n = names();
    n.states.push("2x".into());
    assert!(n.validate().is_err());
    let mut n = names();
    n.params.push(("c".into(), f64::NAN));
    assert!(n.validate().is_err());
    let mut n = names();
    n.params = (0..=MAX_PARAMS).map(|i| (format!("p{i}"), 1.0)).collect();
    assert!(matches!(
        n.validate(),
        Err(ExprError::TooLarge {
            limit: MAX_PARAMS,
            ..
        })
    ));
}

#[test]
fn precedence_and_associativity_follow_mathematics() {
    let x = [2.0, 3.0, 0.0, 0.0, 0.0, 0.0];
    let pt = at(&x, &[], &PARAMS);
    assert_eq!(p("-x1^2").eval(&pt), -4.0);
    assert_eq!(p("x1 - x2 - 1").eval(&pt), -2.0);
    assert_eq!(p("x2 / x1 / 2").eval(&pt), 0.75);
    assert_eq!(p("1 + 2*x1^3").eval(&pt), 17.0);
    assert_eq!(p("x1^(-1)").eval(&pt), 0.5);
    assert_eq!(p("x1^-2").eval(&pt), 0.25);
    assert_eq!(p("2e-1 * a + .5").eval(&pt), 0.8);
    assert_eq!(p("atan2(x2, x1)").eval(&pt), 3.0f64.atan2(2.0));
    assert!((p("cos(pi)").eval(&pt) + 1.0).abs() < 1e-15);
    assert_eq!(p("--x1").eval(&pt), 2.0);
}

#[test]
fn parse_errors_carry_the_span_of_what_is_wrong() {
    let n = names();
    let e = parse("x1 + y * 2", &n).unwrap_err();
    assert_eq!(
        e,
        ExprError::UnknownName {
            name: "y".into(),
            span: 5..6,
            hint: String::new()
        }
    );
    assert!(e.to_string().contains("`y`"));
    let e = parse("x1 + sinh(x2)", &n).unwrap_err();
    assert!(
        matches!(&e, ExprError::UnknownName { name, span, hint } if name == "sinh" && *span == (5..9) && hint.contains("functions"))
    );
    let e = parse("sin x1", &n).unwrap_err();
    assert!(
        matches!(&e, ExprError::Syntax { span, .. } if *span == (0..3)),
        "{e:?}"
    );
    let e = parse("x1^0.5", &n).unwrap_err();
    assert!(
        matches!(&e, ExprError::Syntax { message, span } if message.contains("integer") && span.start == 3)
    );
    let e = parse("x1^2^3", &n).unwrap_err();
    assert!(matches!(&e, ExprError::Syntax { span, .. } if *span == (4..5)));
    let e = parse("(x1 + 1", &n).unwrap_err();
    assert!(
        matches!(&e, ExprError::Syntax { span, message } if *span == (7..7) && message.contains("`)`"))
    );
    let e = parse("x1 + * 2", &n).unwrap_err();
    assert!(matches!(&e, ExprError::Syntax { span, .. } if *span == (5..6)));
    let e = parse("x1 ** 2", &n).unwrap_err();
    assert!(matches!(&e, ExprError::Syntax { message, .. } if message.contains("**")));
    let e = parse("x1^17", &n).unwrap_err();
    assert!(matches!(
        &e,
        ExprError::TooLarge {
            what: "integer power",
            ..
        }
    ));
    let e = parse("atan2(x1)", &n).unwrap_err();
    assert!(matches!(&e, ExprError::Syntax { .. }));
    let e = parse("sin(x1, x2)", &n).unwrap_err();
    assert!(matches!(&e, ExprError::Syntax { message, .. } if message.contains("one argument")));
    let e = parse("x1(2)", &n).unwrap_err();
    assert!(matches!(&e, ExprError::Syntax { message, .. } if message.contains("not a function")));
    assert!(matches!(parse("  ", &n), Err(ExprError::Syntax { .. })));
    assert!(matches!(parse("1e999", &n), Err(ExprError::Syntax { .. })));
}

#[test]
fn hostile_sizes_are_refused_before_they_cost_anything() {
    let n = names();
    let deep = format!("{}x1{}", "(".repeat(200), ")".repeat(200));
    assert!(matches!(
        parse(&deep, &n),
        Err(ExprError::TooLarge {
            limit: MAX_EXPR_NESTING,
            ..
        })
    ));
    let signs = format!("{}x1", "-".repeat(100));
    assert!(matches!(
        parse(&signs, &n),
        Err(ExprError::TooLarge {
            limit: MAX_EXPR_NESTING,
            ..
        })
    ));
    let long_sum = vec!["x1"; 300].join("+");
    assert!(matches!(
        parse(&long_sum, &n),
        Err(ExprError::TooLarge {
            limit: MAX_EXPR_DEPTH,
            ..
        })
    ));
    let huge = "x1+".repeat(MAX_EXPR_LEN);
    assert!(matches!(
        parse(&huge, &n),
        Err(ExprError::TooLarge {
            limit: MAX_EXPR_LEN,
            ..
        })
    ));
    // A product chain whose repeated derivatives explode is stopped by the node budget.
    let chain = (1..=6)
        .map(|i| format!("sin(x{i})"))
        .collect::<Vec<_>>()
        .join("*");
    let mut e = p(&format!("({chain})^16"));
    let mut refused = false;
    for _ in 0..12 {
        match derivative(&e, Var::State(0)) {
            Ok(d) => e = d,
            Err(ExprError::TooLarge { .. }) => {
                refused = true;
                break;
            }
            Err(other) => panic!("{other}"),
        }
    }
    assert!(refused, "the derivative tower should exceed the budget");
}

/// ∂/∂x1 and ∂/∂x2 of a few functions against their hand-derived derivatives at several points.
#[test]
fn derivatives_match_hand_derived_ones() {
    type Hand = fn(f64, f64) -> (f64, f64);
    let cases: [(&str, Hand); 7] = [
        ("x1^2*sin(x2)", |a, b| (2.0 * a * b.sin(), a * a * b.cos())),
        ("atan2(x2, x1)", |a, b| {
            let r = a * a + b * b;
            (-b / r, a / r)
        }),
        ("exp(-x1)/(1 + x2^2)", |a, b| {
            let d = 1.0 + b * b;
            (-(-a).exp() / d, -(-a).exp() * 2.0 * b / (d * d))
        }),
        ("sqrt(x1)*log(x2)", |a, b| {
            (b.ln() / (2.0 * a.sqrt()), a.sqrt() / b)
        }),
        ("tan(x1*x2) - atan(x2)", |a, b| {
            let s = 1.0 / (a * b).cos().powi(2);
            (b * s, a * s - 1.0 / (1.0 + b * b))
        }),
        ("tanh(a*x1) + abs(x2)^3", |a, b| {
            (1.5 * (1.0 - (1.5 * a).tanh().powi(2)), 3.0 * b * b.abs())
        }),
        ("x1^(-2) * cos(x2)", |a, b| {
            (-2.0 * b.cos() / a.powi(3), -b.sin() / (a * a))
        }),
    ];
    let points = [(0.7, 1.3), (1.9, 0.4), (0.2, 2.2), (1.1, -0.6)];
    for (text, hand) in cases {
        let e = p(text);
        let g = [
            derivative(&e, Var::State(0)).unwrap(),
            derivative(&e, Var::State(1)).unwrap(),
        ];
        for (a, b) in points {
            if text.starts_with("sqrt") && b <= 0.0 {
                continue;
            }
            let x = [a, b, 0.0, 0.0, 0.0, 0.0];
            let pt = at(&x, &[], &PARAMS);
            let (da, db) = hand(a, b);
            for (got, want) in [(g[0].eval(&pt), da), (g[1].eval(&pt), db)] {
                assert!(
                    (got - want).abs() <= 1e-12 * (1.0 + want.abs()),
                    "{text} at ({a}, {b}): {got} vs {want}"
                );
            }
        }
    }
}

/// What `display` writes parses back to the same value.
#[test]
fn display_round_trips_through_the_parser() {
    let n = names();
    let x = [0.7, 1.3, -0.4, 2.0, 0.3, -1.1];
    let pt = at(&x, &[0.5, -0.25], &PARAMS);
    for t in [
        "-x1^2 + (x2 - x3)*(-2)",
        "x1^(-3) / (1 - x2) - atan2(-x3, x4)",
        "exp(-(x5 + a)) * tanh(b*x6) - -x1",
        "u1*sin(x5) - (x2/(x3*x4))^2",
    ] {
        let e = p(t);
        let shown = e.display(&n).to_string();
        let back = parse(&shown, &n).unwrap_or_else(|err| panic!("{shown}: {err}"));
        assert!(
            (back.eval(&pt) - e.eval(&pt)).abs() <= 1e-12 * (1.0 + e.eval(&pt).abs()),
            "{t} → {shown}"
        );
    }
}

#[test]
fn simplification_removes_trivial_terms() {
    let e = p("x1*x2 + 3*x3");
    assert_eq!(derivative(&e, Var::State(2)).unwrap(), Expr::c(3.0));
    assert_eq!(derivative(&e, Var::State(4)).unwrap(), Expr::c(0.0));
    assert_eq!(derivative(&e, Var::State(0)).unwrap(), p("x2"));
    assert_eq!(
        derivative(&p("sin(x5)"), Var::State(4)).unwrap(),
        p("cos(x5)")
    );
}

#[test]
fn jacobian_of_a_vector_field() {
    let f = [p("x2"), p("-sin(x1) - 0.1*x2")];
    let j = jacobian(&f, &[Var::State(0), Var::State(1)]).unwrap();
    let x = [0.3, 0.0, 0.0, 0.0, 0.0, 0.0];
    let v = diff::eval_matrix(&j, &at(&x, &[], &PARAMS));
    assert_eq!(v[0], vec![0.0, 1.0]);
    assert!((v[1][0] + 0.3f64.cos()).abs() < 1e-15);
    assert_eq!(v[1][1], -0.1);
}

/// Example 3.7 / 4.9 (examples.md §2.1) with a/I = 1.5 and b/I = 0.5.
fn offset_thruster() -> AffineSystem {
    AffineSystem {
        f: ["x2", "1 - x1 + 0.1*x2", "x4", "1 - x3 + 0.1*x4", "x6", "0"]
            .map(p)
            .to_vec(),
        g: [
            ["0", "0"],
            ["-sin(x5)", "cos(x5)"],
            ["0", "0"],
            ["cos(x5)", "sin(x5)"],
            ["0", "0"],
            ["a", "-b"],
        ]
        .iter()
        .map(|r| r.map(p).to_vec())
        .collect(),
        h: vec![p("x1"), p("x3")],
    }
}

#[test]
fn offset_thruster_has_relative_degree_two_two_and_the_rotation_as_gamma() {
    let sys = offset_thruster();
    let x = [0.1, -0.2, 0.05, 1.0, 0.4, 0.3];
    let pt = at(&x, &[], &PARAMS);
    let rd = sys.relative_degree_at(&pt, 0.0).unwrap();
    assert_eq!(rd.r, vec![2, 2]);
    let g = diff::eval_matrix(&rd.gamma, &pt);
    let (s, c) = 0.4f64.sin_cos();
    assert_eq!(g, vec![vec![-s, c], vec![c, s]]);
    // L_f h1 = x2, L_f² h1 = 1 − x1 + 0.1 x2 (3.32).
    assert_eq!(rd.lf[0][1], p("x2"));
    assert!((rd.lf[0][2].eval(&pt) - (1.0 - 0.1 + 0.1 * -0.2)).abs() < 1e-15);
    assert!((rd.lf[1][2].eval(&pt) - (1.0 - 0.05 + 0.1)).abs() < 1e-15);
    // Γ is a reflection (det −1): nonsingular over any box of θ.
    let bx: Vec<Interval> = x.iter().map(|&v| Interval::new(v - 0.5, v + 0.5)).collect();
    let vb = VarBox {
        x: &bx,
        u: &[],
        p: &PARAMS.map(Interval::point),
    };
    assert!(certainly_regular(&enclose_matrix(&rd.gamma, &vb).unwrap()));
}

#[test]
fn an_output_no_input_reaches_has_no_relative_degree() {
    let mut sys = offset_thruster();
    sys.h[1] = p("2 + 0*x6");
    let x = [0.0; 6];
    let err = sys
        .relative_degree_at(&at(&x, &[], &PARAMS), 0.0)
        .unwrap_err();
    assert_eq!(
        err,
        RelativeDegreeError::NoRelativeDegree { output: 1, n: 6 }
    );
    // The lie derivative of a constant is 0.
    assert!(lie(&p("3"), &sys.f).unwrap().is_zero());
}

#[test]
fn a_matrix_singular_inside_the_box_is_not_proved_regular() {
    // [[x1, 1], [1, x1]] is singular at x1 = 1.
    let m = vec![vec![p("x1"), p("1")], vec![p("1"), p("x1")]];
    let mk = |lo, hi| {
        let bx = vec![Interval::new(lo, hi); 6];
        enclose_matrix(
            &m,
            &VarBox {
                x: &bx,
                u: &[],
                p: &[],
            },
        )
        .unwrap()
    };
    assert!(!certainly_regular(&mk(0.5, 1.5)));
    assert!(certainly_regular(&mk(2.0, 2.5)));
}

#[test]
fn compiled_program_agrees_with_f64_and_refuses_what_does_not_fit() {
    let n = names();
    let exprs = [
        "x1*sin(x5) + a*u1",
        "atan2(x3, x1)^2 - exp(-x2)/b",
        "sqrt(x1^2 + 1)",
    ]
    .map(|t| parse(t, &n).unwrap());
    let c = compile(&exprs, 6, 2, &PARAMS).unwrap();
    let prog = c.program();
    assert_eq!((prog.n_inputs(), prog.n_outputs()), (8, 3));
    // a, b, 1 and the bound constants share the pool once each.
    assert_eq!(c.consts.len(), prog.n_consts());
    let x = [0.3, -0.2, 0.5, 0.0, 1.1, 0.0];
    let u = [0.7, 0.1];
    let got = c.eval_f32(&x, &u);
    for (e, g) in exprs.iter().zip(&got) {
        let want = e.eval(&at(&x, &u, &PARAMS));
        assert!(
            (f64::from(*g) - want).abs() < 1e-6 * (1.0 + want.abs()),
            "{g} vs {want}"
        );
    }
    // Right-nested subtraction needs one stack slot per level: 40 levels exceed the capacity.
    let deep = format!("{}x3{}", "x1-(x2-(".repeat(20), ")".repeat(40));
    let e = parse(&deep, &n).unwrap();
    assert!(
        matches!(compile(&[e], 6, 2, &PARAMS), Err(ExprError::Program(m)) if m.contains("stack"))
    );
    // Right-nested products are reordered (deeper side first) and need two slots.
    let prod = format!("{}x1{}", "x1*(".repeat(40), ")".repeat(40));
    let c = compile(&[parse(&prod, &n).unwrap()], 6, 2, &PARAMS).unwrap();
    assert_eq!(c.program().max_stack(), 2);
    assert!(matches!(
        compile(&[p("1e39*x1")], 6, 2, &PARAMS),
        Err(ExprError::Program(m)) if m.contains("f32")
    ));
}

#[test]
fn rounding_bound_refuses_what_it_cannot_bound() {
    let c = compile(&[p("1/x1"), p("log(x2)")], 6, 2, &PARAMS).unwrap();
    let bx = [
        Interval::new(-1.0, 1.0),
        Interval::new(0.5, 2.0),
        Interval::point(0.0),
        Interval::point(0.0),
        Interval::point(0.0),
        Interval::point(0.0),
    ];
    let u = [Interval::point(0.0); 2];
    assert!(matches!(
        rounding_bound(&c, &bx, &u),
        Err(IntervalError::DivisionByZero { .. })
    ));
    let c = compile(&[p("log(x2)")], 6, 2, &PARAMS).unwrap();
    let mut bx2 = bx;
    bx2[1] = Interval::new(-0.1, 2.0);
    assert!(matches!(
        rounding_bound(&c, &bx2, &u),
        Err(IntervalError::Domain { func: "log", .. })
    ));
    let c = compile(&[p("exp(x1)")], 6, 2, &PARAMS).unwrap();
    bx2[0] = Interval::new(0.0, 100.0);
    assert!(matches!(
        rounding_bound(&c, &bx2, &u),
        Err(IntervalError::Overflow { .. })
    ));
}

/// Expressions the property tests run on (box: every state in [0.2, 1.4], inputs in [−2, 2]).
const PROGRAMS: [&str; 8] = [
    "-u1*sin(x5) + u2*cos(x5)",
    "u1*cos(x5) + u2*sin(x5)",
    "x1*x2 - x3/(1 + x4^2) + 0.1*x6",
    "exp(-x1)*tanh(3*x2) + atan(x3 - 1)",
    "sqrt(x1 + x2) * log(x3 + 0.5)",
    "atan2(x2, x1)^3 + tan(x4)",
    "(x1 + 0.3)^(-2) + x5^7 - x6^(-3)",
    "abs(x1 - 0.8) * a - b / x2",
];

fn state_box() -> Vec<Interval> {
    vec![Interval::new(0.2, 1.4); 6]
}

fn input_box() -> Vec<Interval> {
    vec![Interval::new(-2.0, 2.0); 2]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(3000))]

    /// At random points of the box: the f64 value lies in the enclosure, and the shared f32 evaluator
    /// differs from it by no more than the rounding bound (plus the f64 reference's own rounding, a few
    /// 2⁻⁵³ relative, far below the f32 terms).
    #[test]
    fn f32_program_stays_within_its_rounding_bound(
        x in proptest::array::uniform6(0.2f64..1.4),
        u in proptest::array::uniform2(-2.0f64..2.0),
    ) {
        let exprs: Vec<Expr> = PROGRAMS.iter().map(|t| p(t)).collect();
        let c = compile(&exprs, 6, 2, &PARAMS).unwrap();
        let bounds = rounding_bound(&c, &state_box(), &input_box()).unwrap();
        let got = c.eval_f32(&x, &u);
        let params = PARAMS.map(Interval::point);
        for (i, e) in exprs.iter().enumerate() {
            let want = e.eval(&at(&x, &u, &PARAMS));
            let slack = 1e-13 * (1.0 + want.abs());
            let b = bounds[i];
            prop_assert!(b.exact.widen(slack).contains(want), "{}: {want} outside {:?}", PROGRAMS[i], b.exact);
            let enc = enclose(e, &VarBox { x: &state_box(), u: &input_box(), p: &params }).unwrap();
            prop_assert!(enc.widen(slack).contains(want), "{}: {want} outside {enc:?}", PROGRAMS[i]);
            let err = (f64::from(got[i]) - want).abs();
            prop_assert!(err <= b.error + slack, "{}: |{} − {want}| = {err:e} > {:e}", PROGRAMS[i], got[i], b.error);
        }
    }
}

/// The bound is not vacuous: on the rotation of Example 4.9 it is a few f32 ulps of the result.
#[test]
fn rounding_bound_of_the_rotation_is_tight() {
    let c = compile(&[p("-u1*sin(x5) + u2*cos(x5)")], 6, 2, &PARAMS).unwrap();
    let bx = vec![Interval::new(-0.5, 0.5); 6];
    let u = vec![Interval::new(-2.0, 2.0); 2];
    let b = rounding_bound(&c, &bx, &u).unwrap()[0];
    assert!(b.error > 0.0 && b.error < 5e-6, "{}", b.error);
    assert!(b.exact.lo >= -5.0 && b.exact.hi <= 5.0, "{:?}", b.exact);
}

/// Random expressions over x1, x2, x3 built so that every operation stays in its domain on any box
/// (divisors and logarithm arguments are 1 + a², exponentials take tanh(a)).
fn arb_expr() -> impl Strategy<Value = Expr> {
    let leaf = prop_oneof![
        (0u16..3).prop_map(|i| Expr::var(Var::State(i))),
        (-3.0f64..3.0).prop_map(Expr::c),
    ];
    leaf.prop_recursive(5, 40, 2, |inner| {
        let one_plus_sq = |a: Expr| Expr::add(Expr::c(1.0), Expr::pow(a, 2));
        prop_oneof![
            (inner.clone(), inner.clone()).prop_map(|(a, b)| Expr::add(a, b)),
            (inner.clone(), inner.clone()).prop_map(|(a, b)| Expr::sub(a, b)),
            (inner.clone(), inner.clone()).prop_map(|(a, b)| Expr::mul(a, b)),
            (inner.clone(), inner.clone()).prop_map(move |(a, b)| Expr::div(a, one_plus_sq(b))),
            inner.clone().prop_map(Expr::neg),
            (inner.clone(), 2i8..4).prop_map(|(a, k)| Expr::pow(a, k)),
            inner.clone().prop_map(|a| Expr::func(Func::Sin, a)),
            inner.clone().prop_map(|a| Expr::func(Func::Cos, a)),
            inner.clone().prop_map(|a| Expr::func(Func::Atan, a)),
            inner
                .clone()
                .prop_map(|a| Expr::func(Func::Exp, Expr::func(Func::Tanh, a))),
            inner
                .clone()
                .prop_map(move |a| Expr::func(Func::Log, one_plus_sq(a))),
            inner.prop_map(move |a| Expr::func(Func::Sqrt, one_plus_sq(a))),
        ]
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1000))]

    /// Random expressions, a random box and random points in it: the f32 program stays within its
    /// bound of the f64 value, and the value within the enclosures.
    #[test]
    fn random_programs_stay_within_their_rounding_bound(
        e in arb_expr(),
        lo in proptest::array::uniform3(-2.0f64..2.0),
        w in proptest::array::uniform3(0.0f64..1.0),
        t in proptest::collection::vec(proptest::array::uniform3(0.0f64..=1.0), 8),
    ) {
        let bx: Vec<Interval> = (0..3).map(|i| Interval::new(lo[i], lo[i] + w[i])).collect();
        let Ok(c) = compile(std::slice::from_ref(&e), 3, 0, &[]) else {
            // Only a stack beyond the capacity can refuse these; nothing to check then.
            return Ok(());
        };
        // A bound may be refused where the f32 value's enclosure (the exact range widened by the
        // rounding error) leaves a function's domain, e.g. log(1 + a²) with a huge a²: a refusal, which
        // the spec reports, never a wrong bound. What is checked is every bound that is given.
        let b = match rounding_bound(&c, &bx, &[]) {
            Ok(b) => b[0],
            Err(IntervalError::Domain { .. }) => return Ok(()),
            Err(other) => panic!("{other}"),
        };
        let enc = enclose(&e, &VarBox { x: &bx, u: &[], p: &[] }).unwrap();
        for s in &t {
            let x: Vec<f64> = (0..3).map(|i| bx[i].lo + s[i] * (bx[i].hi - bx[i].lo)).collect();
            let want = e.eval(&at(&x, &[], &[]));
            let slack = 1e-12 * (1.0 + want.abs());
            prop_assert!(enc.widen(slack).contains(want), "{want} ∉ {enc:?}");
            prop_assert!(b.exact.widen(slack).contains(want), "{want} ∉ {:?}", b.exact);
            let got = f64::from(c.eval_f32(&x, &[])[0]);
            prop_assert!((got - want).abs() <= b.error + slack, "|{got} − {want}| > {:e}", b.error);
        }
    }
}

#[test]
fn a_repeated_subexpression_is_computed_once_with_the_same_bits() {
    use shared_types::program::{Func, Op};
    let n = names();
    // sin(x5)·x1 recurs within and across outputs, 1 + x2² twice, and sin(x5) also on its own (a
    // shared subtree inside a shared subtree: each keeps its own register).
    let exprs = [
        "sin(x5)*x1 + sin(x5)*x1/(1 + x2^2)",
        "(sin(x5)*x1)^2 - (1 + x2^2)",
        "x3 + sin(x5)",
    ]
    .map(|t| parse(t, &n).unwrap());
    let shared = compile(&exprs, 6, 2, &PARAMS).unwrap();
    let ops: Vec<Op> = shared.program().ops().map(|(_, op)| op).collect();
    let count = |f: &dyn Fn(&Op) -> bool| ops.iter().filter(|o| f(o)).count();
    assert_eq!(count(&|o| *o == Op::Func(Func::Sin)), 1, "{ops:?}");
    assert_eq!(count(&|o| matches!(o, Op::Tee(_))), 3, "{ops:?}");
    assert_eq!(count(&|o| matches!(o, Op::Recall(_))), 4, "{ops:?}");
    // Each output compiled on its own (nothing to share) gives the same bits.
    for (i, e) in exprs.iter().enumerate() {
        let alone = compile(std::slice::from_ref(e), 6, 2, &PARAMS).unwrap();
        for x in [
            [0.3, -0.2, 0.5, 0.0, 1.1, 0.7],
            [-2.0, 1.5, 3.0, 0.1, 0.0, -0.4],
        ] {
            let u = [0.7, 0.1];
            assert_eq!(
                shared.eval_f32(&x, &u)[i].to_bits(),
                alone.eval_f32(&x, &u)[0].to_bits(),
                "output {i} at {x:?}"
            );
        }
    }
}

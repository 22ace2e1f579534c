//! Hand-written lexer and recursive-descent parser for MTL formulas, and the formula error type
//! (a miette diagnostic pointing at the offending column).
//!
//! Grammar, loosest binding first (`->` is right-associative, `&`/`|` left-associative, `U`/`R`
//! right-associative; the prefix operators bind tightest):
//!
//! ```text
//! formula   := or ( "->" formula )?
//! or        := and ( ("|" | "||") and )*
//! and       := until ( ("&" | "&&") until )*
//! until     := unary ( ("U" | "R") interval? until )?
//! unary     := "!" unary | ("F" | "G") interval? unary | primary
//! primary   := "true" | "false" | "(" formula ")" | predicate | SETNAME
//! predicate := linexpr ("<=" | ">=" | "<" | ">") linexpr
//! linexpr   := sterm ( ("+" | "-") sterm )*
//! sterm     := ("+" | "-")? ( NUMBER ("*" SIGNAL)? | SIGNAL ("*" NUMBER)? )
//! interval  := "[" NUMBER "," ( NUMBER | "inf" ) "]"        with 0 ≤ a ≤ b
//! ```
//!
//! Nesting is limited to [`MAX_DEPTH`] levels; `&` and `|` chains of any length are flat n-ary nodes.
//! The text is at most [`MAX_FORMULA_LEN`] bytes and has at most [`MAX_FORMULA_ATOMS`] atoms (limits of
//! `crate::spec::limits`), since every atom is evaluated at every sample of every run.
//!
//! An operator written without an interval ranges over [0, inf]. `F G U R true false inf` are reserved
//! words. An identifier followed by `* + - <= >= < >` starts a linear predicate, any other identifier
//! names a set. Strict and non-strict comparisons have the same robustness (the boundary is a null
//! set for the signed distance). Parentheses group formulas, not arithmetic.

// Formula errors carry their source text for miette; they are built once per failed parse.
#![allow(clippy::result_large_err)]

use super::ast::{Expr, Interval, LinearPredicate, Span};
use miette::SourceSpan;

/// What went wrong in a formula.
#[derive(Clone, Debug, PartialEq)]
pub enum FormulaErrorKind {
    /// The text does not follow the grammar: what the parser expected and what it found.
    Syntax { expected: String, found: String },
    /// An interval with a < 0, a > b, or a = inf.
    BadInterval,
    /// A number that does not fit in an f64.
    BadNumber,
    /// A linear predicate whose signal coefficients are all zero.
    DegeneratePredicate,
    /// Nesting deeper than `limit` levels ([`MAX_DEPTH`]).
    TooDeep { limit: usize },
    /// A formula longer than [`MAX_FORMULA_LEN`] bytes or with more than [`MAX_FORMULA_ATOMS`] atoms.
    TooLarge { what: &'static str, limit: usize },
    /// A name that is neither a signal of the trace (for predicates) nor a known set.
    UnknownName { name: String },
    /// A named set whose coordinates do not match the trace or whose dimension is wrong.
    SetMismatch { name: String },
}

/// An error in a formula, located by byte span and by 1-based line and character column.
#[derive(Debug, Clone, thiserror::Error, miette::Diagnostic)]
#[error("formula error at line {line}, column {column}: {message}")]
#[diagnostic(code(mtl::formula))]
pub struct FormulaError {
    pub kind: FormulaErrorKind,
    pub message: String,
    /// 1-based line of the span start.
    pub line: usize,
    /// 1-based character column of the span start within its line.
    pub column: usize,
    #[source_code]
    pub src: String,
    #[label("{label}")]
    pub span: SourceSpan,
    pub label: String,
    #[help]
    pub help: Option<String>,
}

impl FormulaError {
    pub(crate) fn new(
        src: &str,
        span: Span,
        kind: FormulaErrorKind,
        message: String,
        label: String,
    ) -> Self {
        let start = span.start.min(src.len());
        let before = &src[..start];
        let line = before.matches('\n').count() + 1;
        let line_start = before.rfind('\n').map(|i| i + 1).unwrap_or(0);
        let column = src[line_start..start].chars().count() + 1;
        let len = span.end.saturating_sub(span.start).min(src.len() - start);
        // What a rendering shows: an overlong line cut around the span (`text::clip_source`).
        let (shown, spans) = crate::text::clip_source(src, &[start..start + len]);
        let at = spans.first().cloned().unwrap_or(0..0);
        Self {
            kind,
            message,
            line,
            column,
            src: shown,
            span: (at.start, at.end - at.start).into(),
            label,
            help: None,
        }
    }
    pub(crate) fn with_help(mut self, help: impl Into<String>) -> Self {
        self.help = Some(help.into());
        self
    }
    /// For syntax errors, what the parser expected.
    pub fn expected(&self) -> Option<&str> {
        match &self.kind {
            FormulaErrorKind::Syntax { expected, .. } => Some(expected),
            _ => None,
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
enum Tok {
    Ident(String),
    Num(f64),
    LBrack,
    RBrack,
    LParen,
    RParen,
    Comma,
    Bang,
    Amp,
    Pipe,
    Arrow,
    Le,
    Ge,
    Lt,
    Gt,
    Plus,
    Minus,
    Star,
    Eof,
}

const RESERVED: [&str; 7] = ["F", "G", "U", "R", "true", "false", "inf"];

fn describe(t: &Tok, text: &str) -> String {
    match t {
        Tok::Ident(s) => format!("`{}`", crate::text::excerpt(s)),
        Tok::Num(_) => format!("number `{}`", crate::text::excerpt(text)),
        Tok::Eof => "end of formula".into(),
        _ => format!("`{text}`"),
    }
}

struct Token {
    tok: Tok,
    span: Span,
}

fn lex(src: &str) -> Result<Vec<Token>, FormulaError> {
    let b = src.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c.is_ascii_whitespace() {
            i += 1;
            continue;
        }
        let start = i;
        let two = |s: &[u8]| b[i..].starts_with(s);
        let (tok, len) = if two(b"->") {
            (Tok::Arrow, 2)
        } else if two(b"<=") {
            (Tok::Le, 2)
        } else if two(b">=") {
            (Tok::Ge, 2)
        } else if two(b"&&") {
            (Tok::Amp, 2)
        } else if two(b"||") {
            (Tok::Pipe, 2)
        } else if c.is_ascii_alphabetic() || c == b'_' {
            let mut j = i + 1;
            while j < b.len() && (b[j].is_ascii_alphanumeric() || b[j] == b'_') {
                j += 1;
            }
            (Tok::Ident(src[i..j].to_string()), j - i)
        } else if c.is_ascii_digit()
            || (c == b'.' && b.get(i + 1).is_some_and(|d| d.is_ascii_digit()))
        {
            let mut j = i;
            while j < b.len() && (b[j].is_ascii_digit() || b[j] == b'.') {
                j += 1;
            }
            if j < b.len() && (b[j] == b'e' || b[j] == b'E') {
                let mut k = j + 1;
                if k < b.len() && (b[k] == b'+' || b[k] == b'-') {
                    k += 1;
                }
                if k < b.len() && b[k].is_ascii_digit() {
                    while k < b.len() && b[k].is_ascii_digit() {
                        k += 1;
                    }
                    j = k;
                }
            }
            let text = &src[i..j];
            let v: f64 = text.parse().map_err(|_| {
                let quoted = crate::text::excerpt(text);
                FormulaError::new(
                    src,
                    Span::new(i, j),
                    FormulaErrorKind::Syntax {
                        expected: "a number".into(),
                        found: format!("`{quoted}`"),
                    },
                    format!("expected a number, found `{quoted}`"),
                    "not a number".into(),
                )
            })?;
            if !v.is_finite() {
                let quoted = crate::text::excerpt(text);
                return Err(FormulaError::new(
                    src,
                    Span::new(i, j),
                    FormulaErrorKind::BadNumber,
                    format!("number `{quoted}` is out of range"),
                    "out of the f64 range".into(),
                ));
            }
            (Tok::Num(v), j - i)
        } else {
            let tok = match c {
                b'[' => Tok::LBrack,
                b']' => Tok::RBrack,
                b'(' => Tok::LParen,
                b')' => Tok::RParen,
                b',' => Tok::Comma,
                b'!' | b'~' => Tok::Bang,
                b'&' => Tok::Amp,
                b'|' => Tok::Pipe,
                b'<' => Tok::Lt,
                b'>' => Tok::Gt,
                b'+' => Tok::Plus,
                b'-' => Tok::Minus,
                b'*' => Tok::Star,
                _ => {
                    let ch = src[i..].chars().next().unwrap_or('?');
                    return Err(FormulaError::new(
                        src,
                        Span::new(i, i + ch.len_utf8()),
                        FormulaErrorKind::Syntax {
                            expected: "an operator, a name, a number or a bracket".into(),
                            found: format!("`{ch}`"),
                        },
                        format!(
                            "expected an operator, a name, a number or a bracket, found `{ch}`"
                        ),
                        "not part of the formula language".into(),
                    ));
                }
            };
            (tok, 1)
        };
        out.push(Token {
            tok,
            span: Span::new(start, start + len),
        });
        i += len;
    }
    out.push(Token {
        tok: Tok::Eof,
        span: Span::new(b.len(), b.len()),
    });
    Ok(out)
}

struct Parser<'s> {
    src: &'s str,
    toks: Vec<Token>,
    pos: usize,
    /// Current nesting level ([`MAX_DEPTH`]).
    depth: usize,
    /// Atoms parsed so far ([`MAX_FORMULA_ATOMS`]).
    atoms: usize,
}

/// The deepest nesting a formula may have. Each parenthesis, prefix operator (`!`, `F`, `G`) and
/// right-associative operator (`->`, `U`, `R`) opens a level; chains of `&` and `|` are flat and open
/// none. Deeper input is a [`FormulaErrorKind::TooDeep`] error at the token that would exceed it, so
/// neither the parser nor the evaluator, the printer or `Drop` (all recursive over the tree, whose
/// depth this bounds) can overflow the stack.
pub const MAX_DEPTH: usize = 100;

pub use crate::spec::limits::{MAX_FORMULA_ATOMS, MAX_FORMULA_LEN};

const FORMULA_START: &str =
    "a formula (`true`, `false`, `!`, `F`, `G`, `(`, a set name or a linear predicate)";

impl<'s> Parser<'s> {
    fn peek(&self) -> &Tok {
        &self.toks[self.pos].tok
    }
    fn peek2(&self) -> &Tok {
        &self.toks[(self.pos + 1).min(self.toks.len() - 1)].tok
    }
    fn span(&self) -> Span {
        self.toks[self.pos].span
    }
    fn bump(&mut self) -> Span {
        let s = self.span();
        if self.pos + 1 < self.toks.len() {
            self.pos += 1;
        }
        s
    }
    fn text(&self, span: Span) -> &'s str {
        &self.src[span.start..span.end]
    }
    fn is_kw(&self, kw: &str) -> bool {
        matches!(self.peek(), Tok::Ident(s) if s == kw)
    }
    /// A syntax error at the current token.
    fn expected(&self, what: &str) -> FormulaError {
        let span = self.span();
        let found = describe(self.peek(), self.text(span));
        FormulaError::new(
            self.src,
            span,
            FormulaErrorKind::Syntax {
                expected: what.to_string(),
                found: found.clone(),
            },
            format!("expected {what}, found {found}"),
            format!("expected {what}"),
        )
    }
    /// Opens one nesting level at the current token (the one that opens it), or refuses past
    /// [`MAX_DEPTH`].
    fn descend(&mut self) -> Result<(), FormulaError> {
        self.depth += 1;
        if self.depth <= MAX_DEPTH {
            return Ok(());
        }
        Err(FormulaError::new(
            self.src,
            self.span(),
            FormulaErrorKind::TooDeep { limit: MAX_DEPTH },
            format!(
                "the formula nests deeper than {MAX_DEPTH} levels here (each `(`, `!`, `F`, `G`, \
                 `->`, `U` and `R` opens one)"
            ),
            format!("level {} of at most {MAX_DEPTH}", self.depth),
        )
        .with_help("flatten the formula: chains of `&` and `|` do not nest, `!!φ` is `φ`"))
    }
    fn eat(&mut self, t: &Tok, what: &str) -> Result<Span, FormulaError> {
        if self.peek() == t {
            Ok(self.bump())
        } else {
            Err(self.expected(what))
        }
    }

    fn formula(&mut self) -> Result<Expr, FormulaError> {
        let lhs = self.or()?;
        if *self.peek() == Tok::Arrow {
            self.descend()?;
            self.bump();
            let rhs = self.formula()?;
            self.depth -= 1;
            return Ok(Expr::Implies(Box::new(lhs), Box::new(rhs)));
        }
        Ok(lhs)
    }
    /// `a | b | …` as one flat [`Expr::Or`] (a loop, not recursion: a chain of any length is shallow).
    fn or(&mut self) -> Result<Expr, FormulaError> {
        let first = self.and()?;
        if *self.peek() != Tok::Pipe {
            return Ok(first);
        }
        let mut terms = vec![first];
        while *self.peek() == Tok::Pipe {
            self.bump();
            terms.push(self.and()?);
        }
        Ok(Expr::Or(terms))
    }
    /// `a & b & …` as one flat [`Expr::And`].
    fn and(&mut self) -> Result<Expr, FormulaError> {
        let first = self.until()?;
        if *self.peek() != Tok::Amp {
            return Ok(first);
        }
        let mut terms = vec![first];
        while *self.peek() == Tok::Amp {
            self.bump();
            terms.push(self.until()?);
        }
        Ok(Expr::And(terms))
    }
    fn until(&mut self) -> Result<Expr, FormulaError> {
        let lhs = self.unary()?;
        let release = if self.is_kw("U") {
            false
        } else if self.is_kw("R") {
            true
        } else {
            return Ok(lhs);
        };
        self.descend()?;
        self.bump();
        let i = self.opt_interval()?;
        let rhs = self.until()?;
        self.depth -= 1;
        Ok(if release {
            Expr::Release(i, Box::new(lhs), Box::new(rhs))
        } else {
            Expr::Until(i, Box::new(lhs), Box::new(rhs))
        })
    }
    fn unary(&mut self) -> Result<Expr, FormulaError> {
        if *self.peek() == Tok::Bang {
            self.descend()?;
            self.bump();
            let e = self.unary()?;
            self.depth -= 1;
            return Ok(Expr::Not(Box::new(e)));
        }
        for (kw, always) in [("F", false), ("G", true)] {
            if self.is_kw(kw) {
                self.descend()?;
                self.bump();
                let i = self.opt_interval()?;
                let e = Box::new(self.unary()?);
                self.depth -= 1;
                return Ok(if always {
                    Expr::Always(i, e)
                } else {
                    Expr::Eventually(i, e)
                });
            }
        }
        self.primary()
    }
    /// Counts one atom at the current token, or refuses past [`MAX_FORMULA_ATOMS`].
    fn atom(&mut self) -> Result<(), FormulaError> {
        self.atoms += 1;
        if self.atoms <= MAX_FORMULA_ATOMS {
            return Ok(());
        }
        Err(FormulaError::new(
            self.src,
            self.span(),
            FormulaErrorKind::TooLarge {
                what: "atoms",
                limit: MAX_FORMULA_ATOMS,
            },
            format!(
                "the formula has more than {MAX_FORMULA_ATOMS} atoms (set names, predicates, `true`, \
                 `false`); atom {} is here",
                self.atoms
            ),
            format!("atom {} of at most {MAX_FORMULA_ATOMS}", self.atoms),
        )
        .with_help("name a region in [sets.*] instead of spelling it out as many predicates"))
    }
    fn primary(&mut self) -> Result<Expr, FormulaError> {
        if matches!(
            self.peek(),
            Tok::Ident(_) | Tok::Num(_) | Tok::Minus | Tok::Plus
        ) {
            self.atom()?;
        }
        match self.peek().clone() {
            Tok::LParen => {
                self.descend()?;
                self.bump();
                let e = self.formula()?;
                self.depth -= 1;
                self.eat(&Tok::RParen, "`)`")?;
                Ok(e)
            }
            Tok::Ident(s) if s == "true" => {
                self.bump();
                Ok(Expr::True)
            }
            Tok::Ident(s) if s == "false" => {
                self.bump();
                Ok(Expr::False)
            }
            Tok::Ident(s) if RESERVED.contains(&s.as_str()) => Err(self.expected(FORMULA_START)),
            Tok::Ident(name) => {
                if matches!(
                    self.peek2(),
                    Tok::Star | Tok::Plus | Tok::Minus | Tok::Le | Tok::Ge | Tok::Lt | Tok::Gt
                ) {
                    self.predicate()
                } else {
                    let span = self.bump();
                    Ok(Expr::Set { name, span })
                }
            }
            Tok::Num(_) | Tok::Minus | Tok::Plus => self.predicate(),
            _ => Err(self.expected(FORMULA_START)),
        }
    }

    /// `[a, b]` if present, else [0, inf].
    fn opt_interval(&mut self) -> Result<Interval, FormulaError> {
        if *self.peek() != Tok::LBrack {
            return Ok(Interval::UNBOUNDED);
        }
        let open = self.bump();
        let a = match self.peek() {
            Tok::Num(v) => {
                let v = *v;
                self.bump();
                v
            }
            _ => return Err(self.expected("a non-negative number (the interval's lower bound)")),
        };
        self.eat(&Tok::Comma, "`,`")?;
        let b = match self.peek() {
            Tok::Num(v) => {
                let v = *v;
                self.bump();
                v
            }
            Tok::Ident(s) if s == "inf" => {
                self.bump();
                f64::INFINITY
            }
            _ => {
                return Err(
                    self.expected("a non-negative number or `inf` (the interval's upper bound)")
                )
            }
        };
        let close = self.eat(&Tok::RBrack, "`]`")?;
        Interval::new(a, b).ok_or_else(|| {
            FormulaError::new(
                self.src,
                open.join(close),
                FormulaErrorKind::BadInterval,
                format!("interval [{a}, {b}] is empty: the lower bound exceeds the upper bound"),
                "need 0 <= a <= b".into(),
            )
        })
    }

    /// `linexpr cmp linexpr`, normalised to aᵀx ≤ b.
    fn predicate(&mut self) -> Result<Expr, FormulaError> {
        let start = self.span();
        let mut terms: Vec<(String, f64, Span)> = Vec::new();
        let mut c0 = 0.0;
        self.linexpr(1.0, &mut terms, &mut c0)?;
        let flip = match self.peek() {
            Tok::Le | Tok::Lt => 1.0,
            Tok::Ge | Tok::Gt => -1.0,
            _ => return Err(self.expected("a comparison `<=`, `>=`, `<` or `>`")),
        };
        self.bump();
        self.linexpr(-1.0, &mut terms, &mut c0)?;
        let end = self.toks[self.pos.saturating_sub(1)].span;
        let span = start.join(end);
        // lhs − rhs = Σ c_i x_i + c0, and the predicate is flip·(lhs − rhs) ≤ 0.
        // `+ 0.0` turns a negative zero into +0 so that printing is canonical.
        for t in terms.iter_mut() {
            t.1 = t.1 * flip + 0.0;
        }
        let p = LinearPredicate {
            terms,
            b: -flip * c0 + 0.0,
            span,
        };
        let norm = p.norm();
        if norm == 0.0 || !norm.is_finite() || !p.b.is_finite() {
            return Err(FormulaError::new(
                self.src,
                span,
                FormulaErrorKind::DegeneratePredicate,
                if norm == 0.0 {
                    "this predicate does not depend on any signal (its coefficients cancel)".into()
                } else {
                    "this predicate's coefficients overflow".into()
                },
                "degenerate predicate".into(),
            )
            .with_help("write `true` or `false` for a constant"));
        }
        Ok(Expr::Linear(p))
    }

    /// Adds `sign ·` the expression into (terms, c0).
    fn linexpr(
        &mut self,
        sign: f64,
        terms: &mut Vec<(String, f64, Span)>,
        c0: &mut f64,
    ) -> Result<(), FormulaError> {
        self.sterm(sign, terms, c0)?;
        loop {
            let s = match self.peek() {
                Tok::Plus => sign,
                Tok::Minus => -sign,
                _ => return Ok(()),
            };
            self.bump();
            self.sterm(s, terms, c0)?;
        }
    }

    fn sterm(
        &mut self,
        mut sign: f64,
        terms: &mut Vec<(String, f64, Span)>,
        c0: &mut f64,
    ) -> Result<(), FormulaError> {
        match self.peek() {
            Tok::Minus => {
                sign = -sign;
                self.bump();
            }
            Tok::Plus => {
                self.bump();
            }
            _ => {}
        }
        let mut add = |name: String, c: f64, span: Span| {
            if let Some(t) = terms.iter_mut().find(|t| t.0 == name) {
                t.1 += c;
            } else {
                terms.push((name, c, span));
            }
        };
        match self.peek().clone() {
            Tok::Num(v) => {
                self.bump();
                if *self.peek() == Tok::Star {
                    self.bump();
                    let (name, span) = self.signal()?;
                    add(name, sign * v, span);
                } else {
                    *c0 += sign * v;
                }
                Ok(())
            }
            Tok::Ident(_) => {
                let (name, span) = self.signal()?;
                let mut c = sign;
                if *self.peek() == Tok::Star {
                    self.bump();
                    match self.peek() {
                        Tok::Num(v) => {
                            c *= *v;
                            self.bump();
                        }
                        _ => return Err(self.expected("a number (a coefficient)")),
                    }
                }
                add(name, c, span);
                Ok(())
            }
            _ => Err(self.expected("a number or a signal name")),
        }
    }

    fn signal(&mut self) -> Result<(String, Span), FormulaError> {
        match self.peek().clone() {
            Tok::Ident(s) if !RESERVED.contains(&s.as_str()) => Ok((s, self.bump())),
            Tok::Ident(s) => Err(self.expected("a signal name").with_help(format!(
                "`{s}` is reserved (F G U R true false inf); rename the signal in the trace"
            ))),
            _ => Err(self.expected("a signal name")),
        }
    }
}

/// Parse a formula (grammar in the module doc).
pub fn parse(src: &str) -> Result<Expr, FormulaError> {
    if src.len() > MAX_FORMULA_LEN {
        let end = (0..=MAX_FORMULA_LEN)
            .rev()
            .find(|&i| src.is_char_boundary(i))
            .unwrap_or(0);
        return Err(FormulaError::new(
            src,
            Span::new(end, src.len()),
            FormulaErrorKind::TooLarge {
                what: "bytes",
                limit: MAX_FORMULA_LEN,
            },
            format!(
                "the formula is {} bytes long, more than the limit {MAX_FORMULA_LEN}",
                src.len()
            ),
            format!("beyond byte {MAX_FORMULA_LEN}"),
        )
        .with_help("name a region in [sets.*] instead of spelling it out as many predicates"));
    }
    let toks = lex(src)?;
    let mut p = Parser {
        src,
        toks,
        pos: 0,
        depth: 0,
        atoms: 0,
    };
    let e = p.formula()?;
    if *p.peek() != Tok::Eof {
        return Err(p.expected("an operator (`&`, `|`, `->`, `U`, `R`) or the end of the formula"));
    }
    Ok(e)
}

//! The expression parser: recursive descent over the bytes of one expression, with byte spans on every
//! error and the nesting and depth limits of the module docs (so its recursion is bounded on any input).
//!
//! ```text
//! expr  := term (("+" | "-") term)*
//! term  := unary (("*" | "/") unary)*
//! unary := ("-" | "+") unary | power
//! power := atom ("^" integer)?            integer: [-+]?digits, optionally in parentheses
//! atom  := number | "pi" | name | func "(" expr ")" | "atan2" "(" expr "," expr ")" | "(" expr ")"
//! ```
//!
//! `-x^2` is `-(x^2)`; powers are integers only (`x^(-1)` is allowed, `x^0.5` is refused: write `sqrt`),
//! and a chain `x^2^3` is refused rather than guessed.

use super::{
    Expr, ExprError, Func, Names, MAX_EXPR_DEPTH, MAX_EXPR_LEN, MAX_EXPR_NESTING, MAX_PROGRAM_POWI,
};
use std::ops::Range;

/// A callable name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Callable {
    Unary(Func),
    Atan2,
}

/// The function a name calls, if any.
pub(super) fn function(name: &str) -> Option<Callable> {
    if name == "atan2" {
        return Some(Callable::Atan2);
    }
    Func::ALL
        .iter()
        .find(|f| f.name() == name)
        .map(|&f| Callable::Unary(f))
}

/// Parses one expression over `names` (which should have passed [`Names::validate`]).
pub fn parse(text: &str, names: &Names) -> Result<Expr, ExprError> {
    if text.len() > MAX_EXPR_LEN {
        return Err(ExprError::TooLarge {
            what: "expression length in bytes",
            value: text.len(),
            limit: MAX_EXPR_LEN,
            span: 0..text.len(),
        });
    }
    let mut p = Parser {
        s: text.as_bytes(),
        text,
        pos: 0,
        nesting: 0,
        names,
    };
    p.ws();
    if p.pos == p.s.len() {
        return Err(p.syntax("empty expression", p.pos..p.pos));
    }
    let e = p.expr()?;
    p.ws();
    if p.pos < p.s.len() {
        return Err(p.unexpected("an operator or the end of the expression"));
    }
    let depth = e.depth();
    if depth > MAX_EXPR_DEPTH {
        return Err(ExprError::TooLarge {
            what: "expression tree depth",
            value: depth,
            limit: MAX_EXPR_DEPTH,
            span: 0..text.len(),
        });
    }
    Ok(e)
}

struct Parser<'a> {
    s: &'a [u8],
    text: &'a str,
    pos: usize,
    nesting: usize,
    names: &'a Names,
}

impl Parser<'_> {
    fn ws(&mut self) {
        while self.s.get(self.pos).is_some_and(u8::is_ascii_whitespace) {
            self.pos += 1;
        }
    }

    fn peek(&mut self) -> Option<u8> {
        self.ws();
        self.s.get(self.pos).copied()
    }

    fn syntax(&self, message: impl Into<String>, span: Range<usize>) -> ExprError {
        ExprError::Syntax {
            message: message.into(),
            span,
        }
    }

    /// "expected X, found Y" at the current position.
    fn unexpected(&self, expected: &str) -> ExprError {
        match self.text.get(self.pos..).and_then(|t| t.chars().next()) {
            Some(c) => self.syntax(
                format!("expected {expected}, found `{c}`"),
                self.pos..self.pos + c.len_utf8(),
            ),
            None => self.syntax(
                format!("expected {expected}, found the end of the expression"),
                self.pos..self.pos,
            ),
        }
    }

    /// Enters one level of nesting (parenthesis, call or unary sign), refusing beyond the limit.
    fn enter(&mut self, start: usize) -> Result<(), ExprError> {
        self.nesting += 1;
        if self.nesting > MAX_EXPR_NESTING {
            return Err(ExprError::TooLarge {
                what: "nesting depth of parentheses, calls and signs",
                value: self.nesting,
                limit: MAX_EXPR_NESTING,
                span: start..start + 1,
            });
        }
        Ok(())
    }

    fn expect(&mut self, c: u8, what: &str) -> Result<(), ExprError> {
        if self.peek() == Some(c) {
            self.pos += 1;
            Ok(())
        } else {
            Err(self.unexpected(what))
        }
    }

    fn expr(&mut self) -> Result<Expr, ExprError> {
        let mut e = self.term()?;
        while let Some(c @ (b'+' | b'-')) = self.peek() {
            self.pos += 1;
            let r = self.term()?;
            e = if c == b'+' {
                Expr::add(e, r)
            } else {
                Expr::sub(e, r)
            };
        }
        Ok(e)
    }

    fn term(&mut self) -> Result<Expr, ExprError> {
        let mut e = self.unary()?;
        while let Some(c @ (b'*' | b'/')) = self.peek() {
            self.pos += 1;
            if self.peek() == Some(b'*') {
                return Err(self.syntax(
                    "`**` is not an operator: write powers as `x^2`",
                    self.pos - 1..self.pos + 1,
                ));
            }
            let r = self.unary()?;
            e = if c == b'*' {
                Expr::mul(e, r)
            } else {
                Expr::div(e, r)
            };
        }
        Ok(e)
    }

    fn unary(&mut self) -> Result<Expr, ExprError> {
        match self.peek() {
            Some(c @ (b'-' | b'+')) => {
                let start = self.pos;
                self.pos += 1;
                self.enter(start)?;
                let e = self.unary()?;
                self.nesting -= 1;
                Ok(if c == b'-' { Expr::neg(e) } else { e })
            }
            _ => self.power(),
        }
    }

    fn power(&mut self) -> Result<Expr, ExprError> {
        let base = self.atom()?;
        if self.peek() != Some(b'^') {
            return Ok(base);
        }
        self.pos += 1;
        let start = self.pos;
        let paren = self.peek() == Some(b'(');
        if paren {
            self.pos += 1;
        }
        let neg = match self.peek() {
            Some(b'-') => {
                self.pos += 1;
                true
            }
            Some(b'+') => {
                self.pos += 1;
                false
            }
            _ => false,
        };
        self.ws();
        let digits = self.pos;
        while self.s.get(self.pos).is_some_and(u8::is_ascii_digit) {
            self.pos += 1;
        }
        if self.pos == digits
            || matches!(
                self.s.get(self.pos),
                Some(b'.' | b'e' | b'E' | b'a'..=b'z' | b'A'..=b'Z' | b'_')
            )
        {
            return Err(self.syntax(
                "a power must be an integer (`x^2`, `x^(-1)`); for other powers write `sqrt(x)` or \
                 `exp(a*log(x))`",
                start..self.pos.max(start + 1).min(self.s.len()),
            ));
        }
        let span = start..self.pos;
        let k: i64 = self.text[digits..self.pos]
            .parse::<i64>()
            .unwrap_or(i64::MAX);
        let k = if neg { -k } else { k };
        let max = MAX_PROGRAM_POWI as i64;
        if k.abs() > max {
            return Err(ExprError::TooLarge {
                what: "integer power",
                value: k.unsigned_abs().min(usize::MAX as u64) as usize,
                limit: max as usize,
                span,
            });
        }
        if paren {
            self.expect(b')', "`)` closing the power")?;
        }
        if self.peek() == Some(b'^') {
            return Err(self.syntax(
                "chained powers are ambiguous: write `(x^a)^b` or `x^(a*b)`",
                self.pos..self.pos + 1,
            ));
        }
        Ok(Expr::pow(base, k as i8))
    }

    fn atom(&mut self) -> Result<Expr, ExprError> {
        match self.peek() {
            Some(b'(') => {
                let start = self.pos;
                self.pos += 1;
                self.enter(start)?;
                let e = self.expr()?;
                self.expect(b')', "`)`")?;
                self.nesting -= 1;
                Ok(e)
            }
            Some(b'0'..=b'9' | b'.') => self.number(),
            Some(c) if c.is_ascii_alphabetic() || c == b'_' => self.name(),
            _ => Err(self.unexpected("a number, a name or `(`")),
        }
    }

    fn number(&mut self) -> Result<Expr, ExprError> {
        let start = self.pos;
        let digits = |p: &mut Self| {
            while p.s.get(p.pos).is_some_and(u8::is_ascii_digit) {
                p.pos += 1;
            }
        };
        digits(self);
        if self.s.get(self.pos) == Some(&b'.') {
            self.pos += 1;
            digits(self);
        }
        if matches!(self.s.get(self.pos), Some(b'e' | b'E')) {
            let save = self.pos;
            self.pos += 1;
            if matches!(self.s.get(self.pos), Some(b'+' | b'-')) {
                self.pos += 1;
            }
            let d = self.pos;
            digits(self);
            if self.pos == d {
                self.pos = save;
            }
        }
        let span = start..self.pos;
        match self.text[span.clone()].parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(Expr::c(v)),
            Ok(_) => Err(self.syntax("number out of the range of f64", span)),
            Err(_) => Err(self.syntax("not a number", span)),
        }
    }

    fn name(&mut self) -> Result<Expr, ExprError> {
        let start = self.pos;
        while self
            .s
            .get(self.pos)
            .is_some_and(|c| c.is_ascii_alphanumeric() || *c == b'_')
        {
            self.pos += 1;
        }
        let span = start..self.pos;
        let name = &self.text[span.clone()];
        let call = self.peek() == Some(b'(');
        match (function(name), call) {
            (Some(f), true) => {
                let open = self.pos;
                self.pos += 1;
                self.enter(open)?;
                let a = self.expr()?;
                let e = match f {
                    Callable::Unary(f) => Expr::func(f, a),
                    Callable::Atan2 => {
                        self.expect(b',', "`,` and the second argument of atan2(y, x)")?;
                        let b = self.expr()?;
                        Expr::atan2(a, b)
                    }
                };
                if f != Callable::Atan2 && self.peek() == Some(b',') {
                    return Err(self.syntax(
                        format!("`{name}` takes one argument"),
                        self.pos..self.pos + 1,
                    ));
                }
                self.expect(b')', "`)` closing the call")?;
                self.nesting -= 1;
                Ok(e)
            }
            (Some(_), false) => Err(self.syntax(
                format!("`{name}` is a function: call it as `{name}(...)`"),
                span,
            )),
            (None, _) if name == "pi" => Ok(Expr::c(std::f64::consts::PI)),
            (None, call) => match self.names.lookup(name) {
                Some(v) if !call => Ok(Expr::var(v)),
                Some(_) => Err(self.syntax(
                    format!(
                        "`{0}` is not a function: write `{0}*(...)` to multiply",
                        crate::text::excerpt(name)
                    ),
                    span,
                )),
                None => Err(ExprError::UnknownName {
                    name: crate::text::excerpt(name),
                    span,
                    hint: if call {
                        "; the functions are sin, cos, tan, exp, log, sqrt, abs, atan, tanh and atan2"
                            .into()
                    } else {
                        String::new()
                    },
                }),
            },
        }
    }
}

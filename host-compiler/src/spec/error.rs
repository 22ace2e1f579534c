//! The spec loader's error type: one [`SpecError`] per rejected spec, a miette diagnostic that carries
//! the source text, the offending TOML span(s) with labels, and a 1-based `line:col` for tests and logs.

use std::fmt;
use std::ops::Range;

use miette::{Diagnostic, LabeledSpan, NamedSource, SourceCode};

/// What is wrong with a spec. Every [`SpecError`] has exactly one kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum ErrorKind {
    /// The file could not be read.
    Io,
    /// The text is not valid TOML.
    Syntax,
    /// A key the spec format does not know (or that the set's `kind` does not use).
    UnknownKey,
    /// A required key is absent.
    MissingField,
    /// A value has the wrong TOML type (e.g. a string where a number is expected).
    WrongType,
    /// A value of the right type that is not allowed (unknown `kind`, bad coordinate name,
    /// negative radius, contradictory keys, ...).
    BadValue,
    /// A matrix or vector has the wrong size.
    Dimension,
    /// A number is `inf` or `nan`.
    NonFinite,
    /// A finite number beyond the largest magnitude a spec may use ([`super::MAX_MAGNITUDE`]).
    OutOfRange,
    /// A box has `lo > hi` in some coordinate.
    InvertedBox,
    /// An ellipsoid's shape matrix is not symmetric.
    NotSymmetric,
    /// An ellipsoid's shape matrix is not positive semidefinite.
    NotPsd,
    /// Init and an Unsafe set have a common point.
    InitMeetsUnsafe,
    /// Goal cannot be reached with positive robustness whatever the controller (see `spec::checks`).
    GoalUnreachable,
    /// The horizon `T` is not a positive finite number of at least one period.
    Horizon,
    /// The sample period is not a positive finite number.
    Period,
    /// The seed is not a non-negative integer.
    Seed,
    /// A `[synthesis]` setting is out of its documented range.
    Setting,
    /// A size the spec implies (dimension, samples in the horizon, table rows, polytope rows, coverage
    /// samples) exceeds the image's capacity or the work budget (`spec::limits`).
    Capacity,
    /// An expression of a nonlinear plant is not one (syntax, unknown name, size limits: `spec::nonlinear`).
    Expression,
    /// A nonlinear plant fails a check of its class (relative degree, a singular decoupling matrix Γ, a
    /// value that is not finite), named with the equation and the point.
    Model,
}

impl ErrorKind {
    /// Stable diagnostic code, e.g. `spec::not_psd`.
    pub fn code(self) -> &'static str {
        match self {
            ErrorKind::Io => "spec::io",
            ErrorKind::Syntax => "spec::syntax",
            ErrorKind::UnknownKey => "spec::unknown_key",
            ErrorKind::MissingField => "spec::missing_field",
            ErrorKind::WrongType => "spec::wrong_type",
            ErrorKind::BadValue => "spec::bad_value",
            ErrorKind::Dimension => "spec::dimension",
            ErrorKind::NonFinite => "spec::non_finite",
            ErrorKind::OutOfRange => "spec::out_of_range",
            ErrorKind::InvertedBox => "spec::inverted_box",
            ErrorKind::NotSymmetric => "spec::not_symmetric",
            ErrorKind::NotPsd => "spec::not_psd",
            ErrorKind::InitMeetsUnsafe => "spec::init_meets_unsafe",
            ErrorKind::GoalUnreachable => "spec::goal_unreachable",
            ErrorKind::Horizon => "spec::horizon",
            ErrorKind::Period => "spec::period",
            ErrorKind::Seed => "spec::seed",
            ErrorKind::Setting => "spec::setting",
            ErrorKind::Capacity => "spec::capacity",
            ErrorKind::Expression => "spec::expression",
            ErrorKind::Model => "spec::model",
        }
    }
}

/// A rejected spec: kind, reason, and where in the file.
///
/// Implements [`miette::Diagnostic`]; render it with miette's handlers to get the file name, `line:col`
/// and the labelled TOML snippet. The first label is the primary one; [`SpecError::line_col`] is its
/// start.
#[derive(Debug)]
pub struct SpecError(Box<Inner>);

#[derive(Debug)]
struct Inner {
    kind: ErrorKind,
    message: String,
    help: Option<String>,
    /// (byte range, label text); the first entry is the primary location.
    labels: Vec<(Range<usize>, String)>,
    src: Option<NamedSource<String>>,
    /// What a rendering shows: the source with every overlong line cut to an excerpt around its labels
    /// ([`crate::text::clip_source`]), and the labels moved into it.
    shown: Option<(NamedSource<String>, Vec<(Range<usize>, String)>)>,
    io: Option<std::io::Error>,
}

impl SpecError {
    /// A new error without location; attach one with [`SpecError::at`].
    pub(crate) fn new(kind: ErrorKind, message: impl Into<String>) -> Self {
        Self(Box::new(Inner {
            kind,
            message: message.into(),
            help: None,
            labels: Vec::new(),
            src: None,
            shown: None,
            io: None,
        }))
    }

    /// The file could not be read.
    pub(crate) fn io(path: &std::path::Path, e: std::io::Error) -> Self {
        let mut s = Self::new(
            ErrorKind::Io,
            format!("cannot read `{}`: {e}", path.display()),
        );
        s.0.io = Some(e);
        s
    }

    /// Add a labelled span (the first one added is primary).
    pub(crate) fn at(mut self, span: Range<usize>, label: impl Into<String>) -> Self {
        self.0.labels.push((span, label.into()));
        self
    }

    /// Add a help line.
    pub(crate) fn help(mut self, help: impl Into<String>) -> Self {
        self.0.help = Some(help.into());
        self
    }

    /// Attach the source text (done once, by the loader).
    pub(crate) fn with_source(mut self, name: &str, text: &str) -> Self {
        // Clamp spans into the text so rendering never fails on an end-of-file position.
        let len = text.len();
        for (r, _) in &mut self.0.labels {
            r.start = r.start.min(len);
            r.end = r.end.clamp(r.start, len);
        }
        self.0.src = Some(NamedSource::new(name, text.to_string()));
        let spans: Vec<Range<usize>> = self.0.labels.iter().map(|(r, _)| r.clone()).collect();
        let (clipped, moved) = crate::text::clip_source(text, &spans);
        let labels = moved
            .into_iter()
            .zip(&self.0.labels)
            .map(|(r, (_, l))| (r, l.clone()))
            .collect();
        self.0.shown = Some((NamedSource::new(name, clipped), labels));
        self
    }

    /// Convert a TOML/serde error (syntax, unknown key, missing key, wrong type) keeping its span.
    pub(crate) fn from_toml(e: &toml::de::Error) -> Self {
        let msg = crate::text::clip_runs(e.message().trim());
        let kind = if msg.starts_with("unknown field") {
            ErrorKind::UnknownKey
        } else if msg.starts_with("missing field") {
            ErrorKind::MissingField
        } else if msg.starts_with("invalid type") || msg.starts_with("invalid length") {
            ErrorKind::WrongType
        } else if msg.starts_with("unknown variant") || msg.starts_with("invalid value") {
            ErrorKind::BadValue
        } else {
            ErrorKind::Syntax
        };
        let label = match kind {
            ErrorKind::UnknownKey => "unknown key",
            ErrorKind::MissingField => "in this table",
            ErrorKind::WrongType => "wrong type",
            ErrorKind::BadValue => "not allowed here",
            _ => "here",
        };
        let mut s = Self::new(kind, msg);
        let span = e.span().unwrap_or(0..0);
        s.0.labels.push((span, label.to_string()));
        s
    }

    /// What is wrong.
    pub fn kind(&self) -> ErrorKind {
        self.0.kind
    }

    /// The reason, without location.
    pub fn message(&self) -> &str {
        &self.0.message
    }

    /// The file name given to [`crate::spec::parse`] / [`crate::spec::load`], if the error has a source.
    pub fn file_name(&self) -> Option<&str> {
        self.0.src.as_ref().map(|s| s.name())
    }

    /// Byte range of the primary label.
    pub fn span(&self) -> Option<Range<usize>> {
        self.0.labels.first().map(|(r, _)| r.clone())
    }

    /// All labels, primary first: (byte range, text).
    pub fn label_spans(&self) -> &[(Range<usize>, String)] {
        &self.0.labels
    }

    /// 1-based line and 1-based column (in characters) of the primary label's start.
    pub fn line_col(&self) -> Option<(usize, usize)> {
        let src = self.0.src.as_ref()?;
        let (r, _) = self.0.labels.first()?;
        Some(line_col(src.inner(), r.start))
    }

    /// `file:line:col: message` (or just the message when there is no location), for logs.
    pub fn headline(&self) -> String {
        match (self.file_name(), self.line_col()) {
            (Some(f), Some((l, c))) => format!("{f}:{l}:{c}: {}", self.0.message),
            _ => self.0.message.clone(),
        }
    }
}

/// 1-based (line, column) of a byte offset; the column counts characters. Offsets inside a multi-byte
/// character or past the end are clamped.
pub fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let mut off = offset.min(text.len());
    while !text.is_char_boundary(off) {
        off -= 1;
    }
    let before = &text[..off];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let col = text[line_start..off].chars().count() + 1;
    (line, col)
}

impl fmt::Display for SpecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0.message)
    }
}

impl std::error::Error for SpecError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        self.0
            .io
            .as_ref()
            .map(|e| e as &(dyn std::error::Error + 'static))
    }
}

impl Diagnostic for SpecError {
    fn code<'a>(&'a self) -> Option<Box<dyn fmt::Display + 'a>> {
        Some(Box::new(self.0.kind.code()))
    }

    fn help<'a>(&'a self) -> Option<Box<dyn fmt::Display + 'a>> {
        self.0
            .help
            .as_ref()
            .map(|h| Box::new(h) as Box<dyn fmt::Display + 'a>)
    }

    fn source_code(&self) -> Option<&dyn SourceCode> {
        self.0.shown.as_ref().map(|(s, _)| s as &dyn SourceCode)
    }

    fn labels(&self) -> Option<Box<dyn Iterator<Item = LabeledSpan> + '_>> {
        let (_, labels) = self.0.shown.as_ref()?;
        if labels.is_empty() {
            return None;
        }
        Some(Box::new(labels.iter().enumerate().map(|(i, (r, text))| {
            let span = (r.start, r.end - r.start);
            let label = if text.is_empty() {
                None
            } else {
                Some(text.clone())
            };
            if i == 0 {
                LabeledSpan::new_primary_with_span(label, span)
            } else {
                LabeledSpan::new_with_span(label, span)
            }
        })))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_col_counts_lines_and_characters() {
        let t = "a = 1\nbé = 2\n\nc";
        assert_eq!(line_col(t, 0), (1, 1));
        assert_eq!(line_col(t, 4), (1, 5));
        assert_eq!(line_col(t, 6), (2, 1));
        // 'é' is two bytes but one column.
        let eq = t.find("= 2").unwrap();
        assert_eq!(line_col(t, eq), (2, 4));
        assert_eq!(line_col(t, t.len()), (4, 2));
        assert_eq!(line_col(t, 10_000), (4, 2));
    }
}

//! Discrete-time traces for MTL monitoring and their CSV form.
//!
//! A trace is a strictly increasing list of sample times t_k with one value per named signal at each
//! sample. The CSV form is the tools' one dialect ([`crate::csv`]: byte-order mark, comment and blank
//! lines, the `# x0` line, trimmed fields, the text columns `status` and `location` skipped), with a header
//! `t,<signal names>` and one row per sample.
//! Every other field must be a finite number. Errors name the 1-based line, the 1-based field number
//! and the 1-based character column where the field starts.

use crate::text::excerpt;
use std::path::Path;

/// An error reading or building a trace.
#[derive(Debug, thiserror::Error, miette::Diagnostic)]
pub enum TraceError {
    #[error("{origin}: cannot read: {source}")]
    Io {
        origin: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{origin}: the file is empty; expected a header `t,<signal names>`")]
    Empty { origin: String },
    #[error("{origin}:{line}:{char_column}: header field {column}: {message}")]
    Header {
        origin: String,
        line: usize,
        column: usize,
        char_column: usize,
        message: String,
    },
    #[error("{origin}: the header has no data rows after it; a trace needs at least one sample")]
    NoRows { origin: String },
    #[error("{origin}:{line}: row has {found} fields, expected {expected} ({names}){missing}")]
    FieldCount {
        origin: String,
        line: usize,
        found: usize,
        expected: usize,
        names: String,
        missing: String,
    },
    #[error("{origin}:{line}:{char_column}: field {column} (`{name}`): `{field}` is not a number")]
    NotNumeric {
        origin: String,
        line: usize,
        column: usize,
        char_column: usize,
        name: String,
        field: String,
    },
    #[error("{origin}:{line}:{char_column}: field {column} (`{name}`): `{field}` is not finite")]
    NonFinite {
        origin: String,
        line: usize,
        column: usize,
        char_column: usize,
        name: String,
        field: String,
    },
    #[error(
        "{origin}:{line}:{char_column}: time must increase strictly, but t = {value} follows t = {prev} (field 1, `t`)"
    )]
    NonMonotoneTime {
        origin: String,
        line: usize,
        char_column: usize,
        value: f64,
        prev: f64,
    },
    #[error("trace: {0}")]
    Invalid(String),
}

impl TraceError {
    /// The 1-based line of the error, when it has one.
    pub fn line(&self) -> Option<usize> {
        match self {
            TraceError::Header { line, .. }
            | TraceError::FieldCount { line, .. }
            | TraceError::NotNumeric { line, .. }
            | TraceError::NonFinite { line, .. }
            | TraceError::NonMonotoneTime { line, .. } => Some(*line),
            _ => None,
        }
    }
    /// The 1-based field number of the error, when it has one.
    pub fn column(&self) -> Option<usize> {
        match self {
            TraceError::Header { column, .. }
            | TraceError::NotNumeric { column, .. }
            | TraceError::NonFinite { column, .. } => Some(*column),
            TraceError::NonMonotoneTime { .. } => Some(1),
            _ => None,
        }
    }
}

/// A validated trace: strictly increasing finite times and finite signal values.
#[derive(Clone, Debug, PartialEq)]
pub struct Trace {
    times: Vec<f64>,
    names: Vec<String>,
    columns: Vec<Vec<f64>>,
}

impl Trace {
    /// Build from columns. `names` and `columns` pair up; every column has one value per time.
    pub fn new(
        times: Vec<f64>,
        names: Vec<String>,
        columns: Vec<Vec<f64>>,
    ) -> Result<Self, TraceError> {
        let bad = |m: String| Err(TraceError::Invalid(m));
        if times.is_empty() {
            return bad("no samples".into());
        }
        if names.len() != columns.len() {
            return bad(format!(
                "{} names for {} columns",
                names.len(),
                columns.len()
            ));
        }
        for (k, &t) in times.iter().enumerate() {
            if !t.is_finite() {
                return bad(format!("time t[{k}] = {t} is not finite"));
            }
            if k > 0 && t <= times[k - 1] {
                return bad(format!(
                    "time must increase strictly: t[{k}] = {t} follows t[{}] = {}",
                    k - 1,
                    times[k - 1]
                ));
            }
        }
        let mut seen = std::collections::HashSet::new();
        for (name, col) in names.iter().zip(&columns) {
            if name.is_empty() || name == "t" || !seen.insert(name) {
                return bad(format!(
                    "signal name `{}` is empty, `t`, or repeated",
                    excerpt(name)
                ));
            }
            if col.len() != times.len() {
                return bad(format!(
                    "signal `{name}` has {} values for {} times",
                    col.len(),
                    times.len()
                ));
            }
            if let Some(k) = col.iter().position(|v| !v.is_finite()) {
                return bad(format!(
                    "signal `{name}` at sample {k} is not finite ({})",
                    col[k]
                ));
            }
        }
        Ok(Self {
            times,
            names,
            columns,
        })
    }

    /// Parse CSV text (format in the module doc). `origin` names the source in error messages.
    pub fn from_csv_str(text: &str, origin: &str) -> Result<Self, TraceError> {
        let origin_s = origin.to_string();
        let mut lines = crate::csv::data_lines(text);
        let (hline, header) = lines.next().ok_or_else(|| TraceError::Empty {
            origin: origin_s.clone(),
        })?;
        let hfields = crate::csv::split(header);
        let herr = |column: usize, char_column: usize, message: String| TraceError::Header {
            origin: origin_s.clone(),
            line: hline,
            column,
            char_column,
            message,
        };
        let (c0, first) = hfields[0];
        if first != "t" {
            return Err(herr(
                1,
                c0,
                format!(
                    "the first column must be named `t` (time), found `{}`",
                    excerpt(first)
                ),
            ));
        }
        let mut names: Vec<String> = Vec::new();
        // The fields of the text columns (`simulate`'s status, a hybrid run's location), each kept once
        // in increasing order (skipped in every row).
        let mut text: Vec<usize> = Vec::new();
        // Seen names, for the duplicate check in linear time (a header may have a million columns).
        let mut seen = std::collections::HashSet::new();
        for (i, &(cc, name)) in hfields.iter().enumerate().skip(1) {
            if crate::csv::TEXT_COLUMNS.contains(&name)
                && !text.iter().any(|&j| hfields[j].1 == name)
            {
                text.push(i);
                continue;
            }
            if name.is_empty() {
                return Err(herr(i + 1, cc, "empty signal name".into()));
            }
            if name == "t" || !seen.insert(name) {
                return Err(herr(
                    i + 1,
                    cc,
                    format!("signal name `{}` appears twice", excerpt(name)),
                ));
            }
            names.push(name.to_string());
        }
        let mut all: Vec<&str> = std::iter::once("t")
            .chain(names.iter().map(|s| s.as_str()))
            .collect();
        for &i in &text {
            all.insert(i, hfields[i].1);
        }
        let width = all.len();
        let mut times = Vec::new();
        let mut columns: Vec<Vec<f64>> = vec![Vec::new(); names.len()];
        for (line, row) in lines {
            let fields = crate::csv::split(row);
            if fields.len() != width {
                let missing = if fields.len() < width {
                    format!(
                        "; missing {}",
                        excerpt(
                            &all[fields.len()..]
                                .iter()
                                .map(|n| format!("`{n}`"))
                                .collect::<Vec<_>>()
                                .join(", ")
                        )
                    )
                } else {
                    format!("; {} extra", fields.len() - width)
                };
                return Err(TraceError::FieldCount {
                    origin: origin_s,
                    line,
                    found: fields.len(),
                    expected: width,
                    names: excerpt(&all.join(", ")),
                    missing,
                });
            }
            for (i, &(cc, f)) in fields.iter().enumerate() {
                if text.contains(&i) {
                    continue;
                }
                // The signal this field belongs to: fields after a text column shift by one each.
                let signal = i - text.iter().filter(|&&s| s < i).count();
                let v: f64 = f.parse().map_err(|_| TraceError::NotNumeric {
                    origin: origin_s.clone(),
                    line,
                    column: i + 1,
                    char_column: cc,
                    name: excerpt(all[i]),
                    field: excerpt(f),
                })?;
                if !v.is_finite() {
                    return Err(TraceError::NonFinite {
                        origin: origin_s,
                        line,
                        column: i + 1,
                        char_column: cc,
                        name: excerpt(all[i]),
                        field: excerpt(f),
                    });
                }
                if i == 0 {
                    if let Some(&prev) = times.last() {
                        if v <= prev {
                            return Err(TraceError::NonMonotoneTime {
                                origin: origin_s,
                                line,
                                char_column: cc,
                                value: v,
                                prev,
                            });
                        }
                    }
                    times.push(v);
                } else {
                    columns[signal - 1].push(v);
                }
            }
        }
        if times.is_empty() {
            return Err(TraceError::NoRows { origin: origin_s });
        }
        Ok(Self {
            times,
            names,
            columns,
        })
    }

    /// Read and parse a CSV file.
    pub fn from_csv_path(path: &Path) -> Result<Self, TraceError> {
        let origin = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| TraceError::Io {
            origin: origin.clone(),
            source,
        })?;
        Self::from_csv_str(&text, &origin)
    }

    /// Number of samples (≥ 1).
    pub fn len(&self) -> usize {
        self.times.len()
    }
    /// Always false (a trace has at least one sample).
    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }
    /// Sample times.
    pub fn times(&self) -> &[f64] {
        &self.times
    }
    /// Signal names (without `t`), in column order.
    pub fn names(&self) -> &[String] {
        &self.names
    }
    /// Signal values by column.
    pub fn columns(&self) -> &[Vec<f64>] {
        &self.columns
    }
    /// One signal by name.
    pub fn signal(&self, name: &str) -> Option<&[f64]> {
        self.names
            .iter()
            .position(|n| n == name)
            .map(|i| self.columns[i].as_slice())
    }
}

//! CSV import of a recorded reference-input sequence (how a person's trajectories come in).
//!
//! Format: a header `t,v1,…,vm` (or `k,…`), then one row per sample period with the reference input v(κ)
//! of the closed loop u = K x + v. Times must increase by the plant's sample period. A recording also names
//! its initial state in a comment line `# x0 = a, b, …` before the header.

use std::path::Path;

/// Errors with the line and column of the offending field.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CsvError {
    #[error("{path}: cannot read: {reason}")]
    Io { path: String, reason: String },
    #[error("{path}: the file is empty; expected a header `t,v1,…,vm`")]
    Empty { path: String },
    #[error("{path}:1: header has {found} input columns, the plant has m = {expected}")]
    Columns {
        path: String,
        expected: usize,
        found: usize,
    },
    #[error("{path}:{line}:{col}: expected {expected} fields, found {found}")]
    RowLength {
        path: String,
        line: usize,
        col: usize,
        expected: usize,
        found: usize,
    },
    #[error("{path}:{line}:{col}: `{field}` is not a finite number")]
    NotNumber {
        path: String,
        line: usize,
        col: usize,
        field: String,
    },
    #[error("{path}:{line}:1: time {t} does not follow {prev} by the sample period {period}")]
    Time {
        path: String,
        line: usize,
        t: f64,
        prev: f64,
        period: f64,
    },
    #[error("{path}: no samples after the header")]
    NoRows { path: String },
    #[error("{path}:{line}: the initial state line `# x0 = …` {reason}")]
    X0 {
        path: String,
        line: usize,
        reason: String,
    },
}

/// Parse a recorded input sequence from CSV text. `period` is the plant's sample period; `m` its input count.
pub fn parse_inputs(
    text: &str,
    path: &str,
    m: usize,
    period: f64,
) -> Result<Vec<Vec<f64>>, CsvError> {
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
    let (_, header) = lines
        .next()
        .ok_or_else(|| CsvError::Empty { path: path.into() })?;
    let cols: Vec<&str> = header.split(',').map(str::trim).collect();
    if cols.len() != m + 1 {
        return Err(CsvError::Columns {
            path: path.into(),
            expected: m,
            found: cols.len().saturating_sub(1),
        });
    }
    let mut out = Vec::new();
    let mut prev_t: Option<f64> = None;
    for (i, line) in lines {
        let lineno = i + 1;
        let fields: Vec<&str> = line.split(',').collect();
        if fields.len() != m + 1 {
            let col = line.len().min(line.rfind(',').map(|p| p + 2).unwrap_or(1));
            return Err(CsvError::RowLength {
                path: path.into(),
                line: lineno,
                col,
                expected: m + 1,
                found: fields.len(),
            });
        }
        let mut vals = Vec::with_capacity(m + 1);
        let mut col = 1;
        for f in &fields {
            let v: f64 = f
                .trim()
                .parse()
                .ok()
                .filter(|v: &f64| v.is_finite())
                .ok_or_else(|| CsvError::NotNumber {
                    path: path.into(),
                    line: lineno,
                    col,
                    field: crate::text::excerpt(f.trim()),
                })?;
            vals.push(v);
            col += f.len() + 1;
        }
        let t = vals[0];
        if let Some(p) = prev_t {
            if ((t - p) - period).abs() > 1e-6 * period.max(1.0) {
                return Err(CsvError::Time {
                    path: path.into(),
                    line: lineno,
                    t,
                    prev: p,
                    period,
                });
            }
        }
        prev_t = Some(t);
        out.push(vals[1..].to_vec());
    }
    if out.is_empty() {
        return Err(CsvError::NoRows { path: path.into() });
    }
    Ok(out)
}

/// A recording: the initial state and the reference inputs.
#[derive(Clone, Debug, PartialEq)]
pub struct Recording {
    pub x0: Vec<f64>,
    pub v: Vec<Vec<f64>>,
}

/// Parse a recording: the `# x0 = …` comment (n values) and the input rows.
pub fn parse_recording(
    text: &str,
    path: &str,
    n: usize,
    m: usize,
    period: f64,
) -> Result<Recording, CsvError> {
    let mut x0 = None;
    for (i, line) in text.lines().enumerate() {
        let t = line.trim();
        if let Some(rest) = t
            .strip_prefix('#')
            .map(str::trim)
            .and_then(|r| r.strip_prefix("x0"))
        {
            let err = |reason: String| CsvError::X0 {
                path: path.into(),
                line: i + 1,
                reason,
            };
            let rest = rest
                .trim_start()
                .strip_prefix('=')
                .ok_or_else(|| err("has no `=`".into()))?;
            let vals: Result<Vec<f64>, _> =
                rest.split(',').map(|f| f.trim().parse::<f64>()).collect();
            let vals = vals.map_err(|e| err(format!("has a field that is not a number ({e})")))?;
            if vals.len() != n || vals.iter().any(|v| !v.is_finite()) {
                return Err(err(format!(
                    "must give {n} finite values, found {}",
                    vals.len()
                )));
            }
            x0 = Some(vals);
            break;
        }
        if !t.is_empty() && !t.starts_with('#') {
            break;
        }
    }
    let x0 = x0.ok_or_else(|| CsvError::X0 {
        path: path.into(),
        line: 1,
        reason: "is missing".into(),
    })?;
    Ok(Recording {
        x0,
        v: parse_inputs(text, path, m, period)?,
    })
}

/// Read and parse a recording.
pub fn load_recording(path: &Path, n: usize, m: usize, period: f64) -> Result<Recording, CsvError> {
    let p = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| CsvError::Io {
        path: p.clone(),
        reason: e.to_string(),
    })?;
    parse_recording(&text, &p, n, m, period)
}

/// Read and parse a recorded input sequence.
pub fn load_inputs(path: &Path, m: usize, period: f64) -> Result<Vec<Vec<f64>>, CsvError> {
    let p = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| CsvError::Io {
        path: p.clone(),
        reason: e.to_string(),
    })?;
    parse_inputs(&text, &p, m, period)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_a_sequence() {
        let v = parse_inputs("t,v1,v2\n0,1,2\n0.1,3,4\n", "a.csv", 2, 0.1).unwrap();
        assert_eq!(v, vec![vec![1.0, 2.0], vec![3.0, 4.0]]);
    }

    #[test]
    fn reads_a_recording_with_its_initial_state() {
        let r =
            parse_recording("# x0 = 0.1, -0.2\nt,v1\n0,1\n0.5,2\n", "r.csv", 2, 1, 0.5).unwrap();
        assert_eq!(r.x0, vec![0.1, -0.2]);
        assert_eq!(r.v, vec![vec![1.0], vec![2.0]]);
        let e = parse_recording("t,v1\n0,1\n", "r.csv", 2, 1, 0.5).unwrap_err();
        assert!(matches!(e, CsvError::X0 { .. }));
        let e = parse_recording("# x0 = 1\nt,v1\n0,1\n", "r.csv", 2, 1, 0.5).unwrap_err();
        assert!(
            e.to_string().contains("must give 2 finite values, found 1"),
            "{e}"
        );
    }

    #[test]
    fn errors_say_where() {
        let e = parse_inputs("t,v1,v2\n0,1,2\n0.1,x,4\n", "a.csv", 2, 0.1).unwrap_err();
        assert_eq!(
            e,
            CsvError::NotNumber {
                path: "a.csv".into(),
                line: 3,
                col: 5,
                field: "x".into()
            }
        );
        let e = parse_inputs("t,v1\n0,1\n", "a.csv", 2, 0.1).unwrap_err();
        assert!(matches!(
            e,
            CsvError::Columns {
                found: 1,
                expected: 2,
                ..
            }
        ));
        let e = parse_inputs("t,v1,v2\n0,1,2\n0.3,1,2\n", "a.csv", 2, 0.1).unwrap_err();
        assert!(matches!(e, CsvError::Time { line: 3, .. }));
        let e = parse_inputs("t,v1,v2\n0,1\n", "a.csv", 2, 0.1).unwrap_err();
        assert!(matches!(
            e,
            CsvError::RowLength {
                line: 2,
                found: 2,
                ..
            }
        ));
        assert!(matches!(
            parse_inputs("", "a.csv", 2, 0.1),
            Err(CsvError::Empty { .. })
        ));
        assert!(matches!(
            parse_inputs("t,v1,v2\n", "a.csv", 2, 0.1),
            Err(CsvError::NoRows { .. })
        ));
        let e = parse_inputs("t,v1,v2\n0,1,inf\n", "a.csv", 2, 0.1).unwrap_err();
        assert!(matches!(e, CsvError::NotNumber { col: 5, .. }));
    }
}

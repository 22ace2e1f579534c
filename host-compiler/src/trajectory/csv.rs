//! CSV import of a recorded reference-input sequence (how a person's trajectories come in).
//!
//! Format: a header `t,v1,…,vm` (or `k,…`), then one row per sample period with the reference input v(κ)
//! of the closed loop u = K x + v. Times must increase by the plant's sample period. A recording also names
//! its initial state in a comment line `# x0 = a, b, …` before the header.
//!
//! # Bounds
//! The caller gives the most rows it can use (for an import, the samples in the spec's horizon, at most
//! the image's table capacity): a longer recording is refused at its first extra row, and a file larger
//! than [`MAX_FIELD_BYTES`] per field of that many rows is refused before it is read.

use std::path::Path;

/// Bytes allowed per field (of the header and of at most `max_rows` rows) when a file is read, plus
/// [`SLACK_BYTES`] for comments: a file larger than that cannot hold a valid recording of that many rows
/// written sensibly, and is refused before it is read.
pub const MAX_FIELD_BYTES: u64 = 64;
/// Bytes allowed beyond the fields (comments, the `# x0` line, blank lines).
pub const SLACK_BYTES: u64 = 1 << 20;

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
    #[error(
        "{path}:{line}: more than {max} rows of inputs; the horizon has {max} samples (horizon / period), \
         and a recording cannot be longer"
    )]
    TooLong {
        path: String,
        line: usize,
        max: usize,
    },
    #[error(
        "{path}: {bytes} bytes is more than a recording of at most {max_rows} rows can take ({limit} bytes); \
         not read"
    )]
    TooLarge {
        path: String,
        bytes: u64,
        max_rows: usize,
        limit: u64,
    },
    #[error("{path}:{line}: the initial state line `# x0 = …` {reason}")]
    X0 {
        path: String,
        line: usize,
        reason: String,
    },
}

/// Parse a recorded input sequence from CSV text. `period` is the plant's sample period; `m` its input
/// count; `max_rows` the most rows accepted ([`CsvError::TooLong`] beyond).
pub fn parse_inputs(
    text: &str,
    path: &str,
    m: usize,
    period: f64,
    max_rows: usize,
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
        if out.len() >= max_rows {
            return Err(CsvError::TooLong {
                path: path.into(),
                line: lineno,
                max: max_rows,
            });
        }
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
    max_rows: usize,
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
        v: parse_inputs(text, path, m, period, max_rows)?,
    })
}

/// Read and parse a recording of at most `max_rows` rows.
pub fn load_recording(
    path: &Path,
    n: usize,
    m: usize,
    period: f64,
    max_rows: usize,
) -> Result<Recording, CsvError> {
    let p = path.display().to_string();
    let text = read_bounded(path, &p, m.max(n), max_rows)?;
    parse_recording(&text, &p, n, m, period, max_rows)
}

/// The recordings an import names: the file itself, or for a directory every `*.csv` file directly in
/// it (not hidden), sorted by name so that an import of a directory is deterministic.
pub fn recordings_in(path: &Path) -> Result<Vec<std::path::PathBuf>, CsvError> {
    if !path.is_dir() {
        return Ok(vec![path.to_path_buf()]);
    }
    let io = |e: std::io::Error| CsvError::Io {
        path: path.display().to_string(),
        reason: e.to_string(),
    };
    let mut files = Vec::new();
    for entry in std::fs::read_dir(path).map_err(io)? {
        let p = entry.map_err(io)?.path();
        let name = p.file_name().map(|n| n.to_string_lossy().into_owned());
        if p.is_file()
            && name.is_some_and(|n| !n.starts_with('.') && n.to_ascii_lowercase().ends_with(".csv"))
        {
            files.push(p);
        }
    }
    files.sort();
    Ok(files)
}

/// Read and parse a recorded input sequence of at most `max_rows` rows.
pub fn load_inputs(
    path: &Path,
    m: usize,
    period: f64,
    max_rows: usize,
) -> Result<Vec<Vec<f64>>, CsvError> {
    let p = path.display().to_string();
    let text = read_bounded(path, &p, m, max_rows)?;
    parse_inputs(&text, &p, m, period, max_rows)
}

/// The file's text, refused unread when it is larger than `max_rows` rows (and a header) of `fields + 1`
/// fields can be ([`MAX_FIELD_BYTES`], [`SLACK_BYTES`]).
fn read_bounded(path: &Path, p: &str, fields: usize, max_rows: usize) -> Result<String, CsvError> {
    let io = |e: std::io::Error| CsvError::Io {
        path: p.into(),
        reason: e.to_string(),
    };
    let bytes = std::fs::metadata(path).map_err(io)?.len();
    let limit = (max_rows as u64)
        .saturating_add(1)
        .saturating_mul(fields as u64 + 1)
        .saturating_mul(MAX_FIELD_BYTES)
        .saturating_add(SLACK_BYTES);
    if bytes > limit {
        return Err(CsvError::TooLarge {
            path: p.into(),
            bytes,
            max_rows,
            limit,
        });
    }
    std::fs::read_to_string(path).map_err(io)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_a_sequence() {
        let v = parse_inputs("t,v1,v2\n0,1,2\n0.1,3,4\n", "a.csv", 2, 0.1, usize::MAX).unwrap();
        assert_eq!(v, vec![vec![1.0, 2.0], vec![3.0, 4.0]]);
    }

    #[test]
    fn reads_a_recording_with_its_initial_state() {
        let r = parse_recording(
            "# x0 = 0.1, -0.2\nt,v1\n0,1\n0.5,2\n",
            "r.csv",
            2,
            1,
            0.5,
            usize::MAX,
        )
        .unwrap();
        assert_eq!(r.x0, vec![0.1, -0.2]);
        assert_eq!(r.v, vec![vec![1.0], vec![2.0]]);
        let e = parse_recording("t,v1\n0,1\n", "r.csv", 2, 1, 0.5, usize::MAX).unwrap_err();
        assert!(matches!(e, CsvError::X0 { .. }));
        let e =
            parse_recording("# x0 = 1\nt,v1\n0,1\n", "r.csv", 2, 1, 0.5, usize::MAX).unwrap_err();
        assert!(
            e.to_string().contains("must give 2 finite values, found 1"),
            "{e}"
        );
    }

    #[test]
    fn errors_say_where() {
        let e = parse_inputs("t,v1,v2\n0,1,2\n0.1,x,4\n", "a.csv", 2, 0.1, usize::MAX).unwrap_err();
        assert_eq!(
            e,
            CsvError::NotNumber {
                path: "a.csv".into(),
                line: 3,
                col: 5,
                field: "x".into()
            }
        );
        let e = parse_inputs("t,v1\n0,1\n", "a.csv", 2, 0.1, usize::MAX).unwrap_err();
        assert!(matches!(
            e,
            CsvError::Columns {
                found: 1,
                expected: 2,
                ..
            }
        ));
        let e = parse_inputs("t,v1,v2\n0,1,2\n0.3,1,2\n", "a.csv", 2, 0.1, usize::MAX).unwrap_err();
        assert!(matches!(e, CsvError::Time { line: 3, .. }));
        let e = parse_inputs("t,v1,v2\n0,1\n", "a.csv", 2, 0.1, usize::MAX).unwrap_err();
        assert!(matches!(
            e,
            CsvError::RowLength {
                line: 2,
                found: 2,
                ..
            }
        ));
        assert!(matches!(
            parse_inputs("", "a.csv", 2, 0.1, usize::MAX),
            Err(CsvError::Empty { .. })
        ));
        assert!(matches!(
            parse_inputs("t,v1,v2\n", "a.csv", 2, 0.1, usize::MAX),
            Err(CsvError::NoRows { .. })
        ));
        let e = parse_inputs("t,v1,v2\n0,1,inf\n", "a.csv", 2, 0.1, usize::MAX).unwrap_err();
        assert!(matches!(e, CsvError::NotNumber { col: 5, .. }));
        // One row more than the horizon: refused at that row.
        let e = parse_inputs("t,v1\n0,1\n0.1,2\n0.2,3\n", "a.csv", 1, 0.1, 2).unwrap_err();
        assert_eq!(
            e,
            CsvError::TooLong {
                path: "a.csv".into(),
                line: 4,
                max: 2
            }
        );
    }
}

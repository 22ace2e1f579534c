//! CSV import of a recorded reference-input sequence (how a person's trajectories come in).
//!
//! Format: the tools' one CSV dialect ([`crate::csv`]: byte-order mark, comments, the `# x0` line, the
//! `status` column skipped); a header `t,v1,…,vm` (or `k,…`), then one row per sample period with the
//! reference input v(κ) of the closed loop u = K x + v. Times must increase by the plant's sample period.
//! A recording also names its initial state in a comment line `# x0 = a, b, …` before the header. The
//! inputs are the columns named `v1…vm` when the header has them, so a run `simulate` wrote (`t`, the
//! states `x1…xn`, the applied inputs `u1…um`, the references `v1…vm`, `status`) is a recording as it is:
//! its last row is the final state, whose input no step applies, and is not read.
//!
//! A recording of a hybrid plant with forced switching (§4.2.1) also names, per row, the location the
//! controller chose for that sample: a column [`LOCATION`] of location names (`host-compiler play` writes
//! it). A change of location between two rows is a switch at the later row's sample. A run `simulate`
//! wrote of a hybrid image has the column for either kind of switching (the location the plant flows in
//! from the row's sample on); with internal switching the import checks it against the replay.
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
    #[error(
        "{path}:{line}:{col}: `{field}` is not a location name (1 to {MAX_LOCATION_NAME} characters)"
    )]
    Location {
        path: String,
        line: usize,
        col: usize,
        field: String,
    },
    #[error("{path}:{line}: the initial state line `# x0 = …` {reason}")]
    X0 {
        path: String,
        line: usize,
        reason: String,
    },
}

/// The column that names each row's location (module doc).
pub use crate::csv::LOCATION;
/// Longest location name a recording's row may give (characters).
pub const MAX_LOCATION_NAME: usize = 64;

/// Where a file's reference inputs are: the field index of `v1…vm`, and whether the file is a run.
struct Layout {
    /// Field index of each input, in input order.
    inputs: Vec<usize>,
    /// Field index of the [`LOCATION`] column, when the header has one.
    location: Option<usize>,
    /// The header names the state columns `x1…xn` (a run `simulate` wrote): its last row is the final
    /// state, whose input no step applies.
    run: bool,
}

impl Layout {
    /// The inputs are the columns named `v1`…`vm` when the header has them all (the other columns, such
    /// as a run's states and applied inputs, are not read); otherwise every column after `t` but
    /// [`crate::csv::STATUS`], which must be m. `None`: neither (or a run without `v1…vm`).
    fn of(header: &[(usize, &str)], m: usize) -> Option<Layout> {
        let run = header.iter().any(|&(_, h)| h == "x1");
        let location = header.iter().position(|&(_, h)| h == LOCATION);
        let named: Option<Vec<usize>> = (1..=m)
            .map(|j| {
                let name = format!("v{j}");
                header.iter().position(|&(_, h)| h == name)
            })
            .collect();
        if let Some(inputs) = named {
            return Some(Layout {
                inputs,
                location,
                run,
            });
        }
        // A run without its references: its columns are states and applied inputs, none of them v.
        if run {
            return None;
        }
        let inputs: Vec<usize> = (1..header.len())
            .filter(|&i| {
                header
                    .get(i)
                    .is_some_and(|&(_, h)| h != crate::csv::STATUS && h != LOCATION)
            })
            .collect();
        (inputs.len() == m).then_some(Layout {
            inputs,
            location,
            run,
        })
    }
}

/// Parse a recorded input sequence from CSV text in the tools' dialect ([`crate::csv`]). `period` is the
/// plant's sample period; `m` its input count; `max_rows` the most rows accepted ([`CsvError::TooLong`]
/// beyond; a run's final-state row is not counted).
pub fn parse_inputs(
    text: &str,
    path: &str,
    m: usize,
    period: f64,
    max_rows: usize,
) -> Result<Vec<Vec<f64>>, CsvError> {
    parse_rows(text, path, m, period, max_rows).map(|(v, _)| v)
}

/// The reference inputs of a file's rows, and their [`LOCATION`] names when the header has the column.
type Rows = (Vec<Vec<f64>>, Option<Vec<String>>);

/// [`parse_inputs`], and the [`LOCATION`] column's names when the header has one.
fn parse_rows(
    text: &str,
    path: &str,
    m: usize,
    period: f64,
    max_rows: usize,
) -> Result<Rows, CsvError> {
    let mut lines = crate::csv::data_lines(text);
    let (_, header) = lines
        .next()
        .ok_or_else(|| CsvError::Empty { path: path.into() })?;
    let cols = crate::csv::split(header);
    let layout = Layout::of(&cols, m).ok_or_else(|| CsvError::Columns {
        path: path.into(),
        expected: m,
        found: cols
            .iter()
            .skip(1)
            .filter(|&&(_, h)| h != crate::csv::STATUS && h != LOCATION)
            .count(),
    })?;
    let mut locations = layout.location.map(|_| Vec::new());
    // A run has one row more than inputs: its final state.
    let limit = max_rows.saturating_add(usize::from(layout.run));
    let mut out = Vec::new();
    let mut prev_t: Option<f64> = None;
    for (lineno, line) in lines {
        if out.len() >= limit {
            return Err(CsvError::TooLong {
                path: path.into(),
                line: lineno,
                max: max_rows,
            });
        }
        let fields = crate::csv::split(line);
        if fields.len() != cols.len() {
            let col = fields.last().map_or(1, |&(c, _)| c);
            return Err(CsvError::RowLength {
                path: path.into(),
                line: lineno,
                col,
                expected: cols.len(),
                found: fields.len(),
            });
        }
        let number = |i: usize| {
            let (col, f) = fields.get(i).copied().unwrap_or((1, ""));
            f.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| CsvError::NotNumber {
                    path: path.into(),
                    line: lineno,
                    col,
                    field: crate::text::excerpt(f),
                })
        };
        let t = number(0)?;
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
        if let (Some(i), Some(names)) = (layout.location, locations.as_mut()) {
            let (col, f) = fields.get(i).copied().unwrap_or((1, ""));
            if f.is_empty() || f.chars().count() > MAX_LOCATION_NAME {
                return Err(CsvError::Location {
                    path: path.into(),
                    line: lineno,
                    col,
                    field: crate::text::excerpt(f),
                });
            }
            names.push(f.to_string());
        }
        out.push(
            layout
                .inputs
                .iter()
                .map(|&i| number(i))
                .collect::<Result<Vec<f64>, _>>()?,
        );
    }
    if layout.run {
        out.pop();
        if let Some(names) = locations.as_mut() {
            names.pop();
        }
    }
    if out.is_empty() {
        return Err(CsvError::NoRows { path: path.into() });
    }
    Ok((out, locations))
}

/// A recording: the initial state and the reference inputs, and for forced switching the location of
/// each row (module doc).
#[derive(Clone, Debug, PartialEq)]
pub struct Recording {
    pub x0: Vec<f64>,
    pub v: Vec<Vec<f64>>,
    /// The [`LOCATION`] column, one name per row of `v`, when the file has it.
    pub locations: Option<Vec<String>>,
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
    if let Some((line, rest)) = crate::csv::x0_comment(text) {
        let err = |reason: String| CsvError::X0 {
            path: path.into(),
            line,
            reason,
        };
        let rest = rest
            .trim_start()
            .strip_prefix('=')
            .ok_or_else(|| err("has no `=`".into()))?;
        let vals: Result<Vec<f64>, _> = rest.split(',').map(|f| f.trim().parse::<f64>()).collect();
        let vals = vals.map_err(|e| err(format!("has a field that is not a number ({e})")))?;
        if vals.len() != n || vals.iter().any(|v| !v.is_finite()) {
            return Err(err(format!(
                "must give {n} finite values, found {}",
                vals.len()
            )));
        }
        x0 = Some(vals);
    }
    let x0 = x0.ok_or_else(|| CsvError::X0 {
        path: path.into(),
        line: 1,
        reason: "is missing".into(),
    })?;
    let (v, locations) = parse_rows(text, path, m, period, max_rows)?;
    Ok(Recording { x0, v, locations })
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
    fn a_forced_recording_names_each_rows_location() {
        // Unnamed inputs: the location column is not one of them.
        let r = parse_recording(
            "# x0 = 0, 0\nt,a,location\n0,1,fwd\n0.5,2,back\n",
            "r.csv",
            2,
            1,
            0.5,
            usize::MAX,
        )
        .unwrap();
        assert_eq!(r.v, vec![vec![1.0], vec![2.0]]);
        assert_eq!(r.locations, Some(vec!["fwd".into(), "back".into()]));
        let e = parse_recording(
            "# x0 = 0, 0\nt,v1,location\n0,1,fwd\n0.5,2,\n",
            "r.csv",
            2,
            1,
            0.5,
            usize::MAX,
        )
        .unwrap_err();
        assert!(matches!(e, CsvError::Location { line: 4, .. }), "{e}");
        assert!(e.to_string().contains("is not a location name"), "{e}");
    }

    /// A run as `simulate` writes it: the `# x0` line, states, applied inputs, references, status.
    const RUN: &str = "# x0 = 0.1, 0\nt,x1,x2,u1,v1,status\n0,0.1,0,0.5,0.25,ok\n\
                       0.1,0.2,0.1,0.4,0.125,ok\n0.2,0.3,0.1,0.3,0.0625,out-of-envelope\n";

    #[test]
    fn a_run_simulate_wrote_is_a_recording_and_a_trace() {
        // Its references, not its applied inputs; the final state's row is not an input.
        let r = parse_recording(RUN, "run.csv", 2, 1, 0.1, 2).unwrap();
        assert_eq!(r.x0, vec![0.1, 0.0]);
        assert_eq!(r.v, vec![vec![0.25], vec![0.125]]);
        // One row more than that is too long.
        let e = parse_recording(RUN, "run.csv", 2, 1, 0.1, 1).unwrap_err();
        assert!(
            matches!(
                e,
                CsvError::TooLong {
                    line: 5,
                    max: 1,
                    ..
                }
            ),
            "{e}"
        );
        // `mtl` reads the same file as a trace (status skipped).
        let t = crate::robustness::mtl::Trace::from_csv_str(RUN, "run.csv").unwrap();
        assert_eq!(t.names(), ["x1", "x2", "u1", "v1"]);
        // A run without its references is refused: its columns are no inputs.
        let bare = "t,x1,x2,u1\n0,0,0,1\n0.1,0,0,1\n";
        assert!(matches!(
            parse_inputs(bare, "a.csv", 1, 0.1, 9),
            Err(CsvError::Columns { .. })
        ));
    }

    #[test]
    fn a_byte_order_mark_comments_and_the_status_column_are_read_as_mtl_reads_them() {
        let text = "\u{feff}# x0 = 1, 2\n# recorded by hand\n\nt, v1, status\n0, 1, ok\n# mid\n\n0.5, 2, ok\n";
        let r = parse_recording(text, "r.csv", 2, 1, 0.5, 9).unwrap();
        assert_eq!(r.x0, vec![1.0, 2.0]);
        assert_eq!(r.v, vec![vec![1.0], vec![2.0]]);
        let t = crate::robustness::mtl::Trace::from_csv_str(text, "r.csv").unwrap();
        assert_eq!(t.names(), ["v1"]);
        assert_eq!(t.times(), [0.0, 0.5]);
        // Without the BOM the same; a positional header (no `v` names) reads its one column.
        let r2 = parse_recording(
            &text.replace('\u{feff}', "").replace("v1", "u"),
            "r.csv",
            2,
            1,
            0.5,
            9,
        )
        .unwrap();
        assert_eq!(r2, r);
        // The x0 line after the header is not the initial state.
        let late = "t,v1\n# x0 = 1, 2\n0,1\n";
        assert!(matches!(
            parse_recording(late, "r.csv", 2, 1, 0.5, 9),
            Err(CsvError::X0 { .. })
        ));
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

//! CSV import of a recorded run (how a person's trajectories, and routes planned outside the tool, come
//! in).
//!
//! Format: the tools' one CSV dialect ([`crate::csv`]: byte-order mark, comments, the `# x0` line, the
//! `status` column skipped); a header whose first column is the time, then one row per sample period.
//! Times must increase by the plant's sample period. What the loop takes is the reference input v(κ) of
//! the closed loop u = K̂ x + v; a recording gives it, or what a user has (read by [`parse_import`]):
//!
//! * **References** `v1…vm`: v(κ) per row, with the initial state in a comment line `# x0 = a, b, …`
//!   before the header. The columns named `v1…vm` are read when the header has them all, whatever else
//!   it has, so a run `simulate` wrote (`t`, the states `x1…xn`, the applied inputs `u1…um`, the
//!   references `v1…vm`, `status`) is a recording as it is: its last row is the final state, whose input
//!   no step applies, and is not read. A header without any column named like a state or an input reads
//!   every column after `t` as v (m of them).
//! * **Applied inputs** `u1…um` (no `v` columns): the input applied over each period, with the `# x0`
//!   line or the state columns `x1…xn` (then the first row's state is x0, the last row the final state
//!   whose inputs are not read, and the other states are not read: the replay decides). Once the CAF is
//!   designed the plant's sampled model is stepped from x0 under u, and v(κ) = u(κ) − K̂ x(κ) along that
//!   replay, so the nominal is the run of the applied inputs (`trajectory::track::references`).
//! * **States alone** `x1…xn` (no input columns): the states at the samples 0…N, the first being x0
//!   (one row more than steps). The inputs are found by least squares within the input bound, one
//!   problem over the whole horizon (`trajectory::track::track_states`), and then used as applied
//!   inputs; a recording the replay cannot follow within the input bound is refused, naming the sample
//!   and the residual.
//!
//! The states and inputs are those of the model the task's nominals live in: for a linear plant its own
//! (`x`, `u`); for a feedback-linearizable or flat plant those of its linear model in ξ, named `xi1…xin`
//! and `w1…wm` ([`Coordinates`]), so that a run `simulate` wrote of such a plant (the plant's own x and
//! u, no references) is refused rather than read as the model's. A hybrid plant's recordings give
//! references only (its gain changes with the location; `synth --import` refuses the others).
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
        "{path}: one row of states is no step; a recording of states alone gives the states at two \
         samples at least"
    )]
    OneState { path: String },
    #[error("{path}:1: {reason}; {expected}")]
    Header {
        path: String,
        reason: String,
        /// What a header may name, in the plant's dimensions and coordinates.
        expected: String,
    },
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

/// The coordinates a recording's state and input columns are named in ([`parse_import`]): the plant's
/// own (`x1…xn`, `u1…um`), or for a feedback-linearizable or flat plant those of its linear model in ξ,
/// which the task and its nominals live in (`xi1…xin`, `w1…wm`). Distinct names, so that a run
/// `simulate` wrote of such a plant (the plant's own x and u) is never read as the model's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Coordinates {
    Plant,
    Linearized,
}

impl Coordinates {
    /// The prefix of the state columns.
    pub fn state(self) -> &'static str {
        match self {
            Coordinates::Plant => "x",
            Coordinates::Linearized => "xi",
        }
    }
    /// The prefix of the applied-input columns.
    pub fn input(self) -> &'static str {
        match self {
            Coordinates::Plant => "u",
            Coordinates::Linearized => "w",
        }
    }
}

/// What a file's rows give.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    References,
    Applied,
    States,
}

/// Where a file's columns are: the inputs (references `v1…vm` or applied inputs), the states, and
/// whether the file is a run.
struct Layout {
    kind: Kind,
    /// Field index of each input, in input order (none for [`Kind::States`]).
    inputs: Vec<usize>,
    /// Field index of each state, when the file's states are read (applied inputs or states alone).
    states: Option<Vec<usize>>,
    /// Field index of the [`LOCATION`] column, when the header has one.
    location: Option<usize>,
    /// The header names state columns (a run `simulate` wrote, or a user's states): its last row is the
    /// final state, whose input no step applies.
    run: bool,
}

/// The columns `prefix1…prefixk` as a message names them (`u1` alone when k = 1).
fn columns(prefix: &str, k: usize) -> String {
    match k {
        1 => format!("`{prefix}1`"),
        _ => format!("`{prefix}1…{prefix}{k}`"),
    }
}

/// Whether a header field is `prefix` followed by a number (`u3`, `xi1`).
fn numbered(h: &str, prefix: &str) -> bool {
    h.strip_prefix(prefix)
        .is_some_and(|d| !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit()))
}

impl Layout {
    /// The field indices of `prefix1…prefixk`, when the header has them all.
    fn named(header: &[(usize, &str)], prefix: &str, k: usize) -> Option<Vec<usize>> {
        (1..=k)
            .map(|j| {
                let name = format!("{prefix}{j}");
                header.iter().position(|&(_, h)| h == name)
            })
            .collect()
    }

    /// References only (`parse_recording`): the columns named `v1`…`vm` when the header has them all
    /// (the other columns, such as a run's states and applied inputs, are not read); otherwise every
    /// column after `t` but [`crate::csv::STATUS`], which must be m. `None`: neither (or a run without
    /// `v1…vm`).
    fn references(header: &[(usize, &str)], m: usize) -> Option<Layout> {
        let run = header.iter().any(|&(_, h)| h == "x1");
        let location = header.iter().position(|&(_, h)| h == LOCATION);
        if let Some(inputs) = Self::named(header, "v", m) {
            return Some(Layout {
                kind: Kind::References,
                inputs,
                states: None,
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
            kind: Kind::References,
            inputs,
            states: None,
            location,
            run,
        })
    }

    /// An import's layout (module doc): the references `v1…vm` when the header has them all (as
    /// [`Layout::references`]); else the applied inputs `u1…um` (in `c`'s names), with the states
    /// `x1…xn` when it has them all; else the states alone; else, when no column is named like a state
    /// or an input, every column after `t` as references. `Err`: why the header is none of these.
    fn import(
        header: &[(usize, &str)],
        n: usize,
        m: usize,
        c: Coordinates,
    ) -> Result<Layout, String> {
        let (s, u) = (c.state(), c.input());
        let location = header.iter().position(|&(_, h)| h == LOCATION);
        let states = Self::named(header, s, n);
        let any = |prefix: &str| header.iter().skip(1).any(|&(_, h)| numbered(h, prefix));
        if let Some(inputs) = Self::named(header, "v", m) {
            return Ok(Layout {
                kind: Kind::References,
                inputs,
                states: None,
                location,
                run: any(s) || header.iter().any(|&(_, h)| h == "x1"),
            });
        }
        if c == Coordinates::Linearized && (any("x") || any("u")) && !any(s) && !any(u) {
            return Err(format!(
                "the plant is feedback linearizable or flat: its recordings are in its linear model's \
                 coordinates, the states {} (ξ) and the inputs {} (w); the columns `x…`, `u…` (the \
                 plant's own, as `simulate` writes them) are not read",
                columns(s, n),
                columns(u, m)
            ));
        }
        if any(s) && states.is_none() {
            return Err(format!(
                "the header names some of the states {} but not all {n}",
                columns(s, n)
            ));
        }
        if let Some(inputs) = Self::named(header, u, m) {
            return Ok(Layout {
                kind: Kind::Applied,
                inputs,
                run: states.is_some(),
                states,
                location,
            });
        }
        if any(u) || any("v") {
            return Err(format!(
                "the header names some inputs but not all m = {m} of {} or {}",
                columns(u, m),
                columns("v", m)
            ));
        }
        if states.is_some() {
            return Ok(Layout {
                kind: Kind::States,
                inputs: Vec::new(),
                run: true,
                states,
                location,
            });
        }
        Self::references(header, m).ok_or_else(|| {
            let found = header
                .iter()
                .skip(1)
                .filter(|&&(_, h)| h != crate::csv::STATUS && h != LOCATION)
                .count();
            format!("header has {found} input columns, the plant has m = {m}")
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
    parse_rows(text, path, 0, m, period, max_rows, None).map(|r| r.inputs)
}

/// A file's rows: the inputs (references or applied, one row per step), the states (per sample, the
/// final one included) when read, and the [`LOCATION`] names when the header has the column.
struct Rows {
    kind: Kind,
    inputs: Vec<Vec<f64>>,
    states: Option<Vec<Vec<f64>>>,
    locations: Option<Vec<String>>,
}

/// The rows of a file: references only ([`Layout::references`]) when `import` is `None`, else any
/// import layout in those coordinates ([`Layout::import`]).
fn parse_rows(
    text: &str,
    path: &str,
    n: usize,
    m: usize,
    period: f64,
    max_rows: usize,
    import: Option<Coordinates>,
) -> Result<Rows, CsvError> {
    let mut lines = crate::csv::data_lines(text);
    let (_, header) = lines
        .next()
        .ok_or_else(|| CsvError::Empty { path: path.into() })?;
    let cols = crate::csv::split(header);
    let layout = match import {
        None => Layout::references(&cols, m).ok_or_else(|| CsvError::Columns {
            path: path.into(),
            expected: m,
            found: cols
                .iter()
                .skip(1)
                .filter(|&&(_, h)| h != crate::csv::STATUS && h != LOCATION)
                .count(),
        })?,
        Some(c) => Layout::import(&cols, n, m, c).map_err(|reason| CsvError::Header {
            path: path.into(),
            reason,
            expected: format!(
                "a recording's header names the references {}, or the applied inputs {} (with the `# x0` \
                 line or the states {}), or the states {} alone",
                columns("v", m),
                columns(c.input(), m),
                columns(c.state(), n),
                columns(c.state(), n)
            ),
        })?,
    };
    let mut locations = layout.location.map(|_| Vec::new());
    let mut states = layout.states.as_ref().map(|_| Vec::new());
    // A run has one row more than inputs: its final state.
    let limit = max_rows.saturating_add(usize::from(layout.run));
    let mut out = Vec::new();
    let mut rows = 0usize;
    let mut prev_t: Option<f64> = None;
    for (lineno, line) in lines {
        if rows >= limit {
            return Err(CsvError::TooLong {
                path: path.into(),
                line: lineno,
                max: max_rows,
            });
        }
        rows += 1;
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
        if let (Some(idx), Some(states)) = (layout.states.as_ref(), states.as_mut()) {
            states.push(
                idx.iter()
                    .map(|&i| number(i))
                    .collect::<Result<Vec<f64>, _>>()?,
            );
        }
        if layout.kind != Kind::States {
            out.push(
                layout
                    .inputs
                    .iter()
                    .map(|&i| number(i))
                    .collect::<Result<Vec<f64>, _>>()?,
            );
        }
    }
    if layout.run {
        out.pop();
        if let Some(names) = locations.as_mut() {
            names.pop();
        }
    }
    let steps = match layout.kind {
        Kind::States => states.as_ref().map_or(0, |s| s.len().saturating_sub(1)),
        _ => out.len(),
    };
    if steps == 0 {
        return Err(if rows == 0 || layout.kind != Kind::States {
            CsvError::NoRows { path: path.into() }
        } else {
            CsvError::OneState { path: path.into() }
        });
    }
    Ok(Rows {
        kind: layout.kind,
        inputs: out,
        states,
        locations,
    })
}

/// What a recording's rows give (module doc): the references the loop takes, or what a user has, from
/// which the references are derived once the CAF and its gain K̂ are designed
/// (`trajectory::track::references`).
#[derive(Clone, Debug, PartialEq, Default)]
pub enum Given {
    /// The references v(κ) themselves, in [`Recording::v`].
    #[default]
    References,
    /// The inputs u(κ) applied over each period (one row per step; [`Recording::v`] is empty).
    Applied(Vec<Vec<f64>>),
    /// The states at the samples 0…N alone, the first being x0 ([`Recording::v`] is empty).
    States(Vec<Vec<f64>>),
}

/// A recording: the initial state and the reference inputs, and for forced switching the location of
/// each row (module doc).
#[derive(Clone, Debug, PartialEq)]
pub struct Recording {
    pub x0: Vec<f64>,
    /// The references, one row per step; empty until derived when the file gives applied inputs or
    /// states ([`Given`]).
    pub v: Vec<Vec<f64>>,
    /// The [`LOCATION`] column, one name per row of `v`, when the file has it.
    pub locations: Option<Vec<String>>,
    /// What the file's rows give.
    pub given: Given,
}

impl Recording {
    /// The number of steps the recording gives.
    pub fn steps(&self) -> usize {
        match &self.given {
            Given::References => self.v.len(),
            Given::Applied(u) => u.len(),
            Given::States(x) => x.len().saturating_sub(1),
        }
    }
}

/// The `# x0 = …` comment's n values, with its line, when the file has one.
fn x0_line(text: &str, path: &str, n: usize) -> Result<Option<(usize, Vec<f64>)>, CsvError> {
    let Some((line, rest)) = crate::csv::x0_comment(text) else {
        return Ok(None);
    };
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
    Ok(Some((line, vals)))
}

/// The `# x0` line is missing.
fn x0_missing(path: &str) -> CsvError {
    CsvError::X0 {
        path: path.into(),
        line: 1,
        reason: "is missing".into(),
    }
}

/// Parse a recording of references: the `# x0 = …` comment (n values) and the rows of `v1…vm` (what
/// `play` writes and reads back; [`parse_import`] reads what a user has too).
pub fn parse_recording(
    text: &str,
    path: &str,
    n: usize,
    m: usize,
    period: f64,
    max_rows: usize,
) -> Result<Recording, CsvError> {
    let x0 = x0_line(text, path, n)?.ok_or_else(|| x0_missing(path))?.1;
    let rows = parse_rows(text, path, n, m, period, max_rows, None)?;
    Ok(Recording {
        x0,
        v: rows.inputs,
        locations: rows.locations,
        given: Given::References,
    })
}

/// Parse a recording `synth --import` reads (module doc): references, applied inputs, or states alone,
/// with state and input columns named in the coordinates `c`. The initial state is the `# x0` line, or
/// when the file has none the first row's states; when it has both they must agree.
pub fn parse_import(
    text: &str,
    path: &str,
    n: usize,
    m: usize,
    period: f64,
    max_rows: usize,
    c: Coordinates,
) -> Result<Recording, CsvError> {
    let line = x0_line(text, path, n)?;
    let rows = parse_rows(text, path, n, m, period, max_rows, Some(c))?;
    let first = rows.states.as_ref().and_then(|s| s.first());
    let x0 = match (line, first) {
        (Some((line, x0)), Some(s0)) => {
            let off = x0
                .iter()
                .zip(s0)
                .position(|(a, b)| (a - b).abs() > X0_AGREEMENT * a.abs().max(1.0));
            if let Some(i) = off {
                return Err(CsvError::X0 {
                    path: path.into(),
                    line,
                    reason: format!(
                        "gives {}{} = {}, the first row's state column says {}",
                        c.state(),
                        i + 1,
                        x0[i],
                        s0[i]
                    ),
                });
            }
            x0
        }
        (Some((_, x0)), None) => x0,
        (None, Some(s0)) if rows.kind != Kind::References => s0.clone(),
        (None, _) => return Err(x0_missing(path)),
    };
    let (v, given) = match rows.kind {
        Kind::References => (rows.inputs, Given::References),
        Kind::Applied => (Vec::new(), Given::Applied(rows.inputs)),
        Kind::States => (Vec::new(), Given::States(rows.states.unwrap_or_default())),
    };
    Ok(Recording {
        x0,
        v,
        locations: rows.locations,
        given,
    })
}

/// How far (relative, at least absolute) the `# x0` line and the first row's states may differ: the
/// digits a file prints, not a tolerance of the model.
pub const X0_AGREEMENT: f64 = 1e-6;

/// Read and parse a recording `synth --import` reads ([`parse_import`]) of at most `max_rows` steps.
pub fn load_import(
    path: &Path,
    n: usize,
    m: usize,
    period: f64,
    max_rows: usize,
    c: Coordinates,
) -> Result<Recording, CsvError> {
    let p = path.display().to_string();
    let text = read_bounded(path, &p, n + 2 * m + 2, max_rows)?;
    parse_import(&text, &p, n, m, period, max_rows, c)
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

    #[test]
    fn an_import_reads_references_applied_inputs_or_states_alone() {
        let imp = |t: &str| parse_import(t, "r.csv", 2, 1, 0.1, 9, Coordinates::Plant);
        // The references win when the file has them (a run `simulate` wrote): as before.
        let r = imp(RUN).unwrap();
        assert_eq!(r.given, Given::References);
        assert_eq!(r.v, vec![vec![0.25], vec![0.125]]);
        // Applied inputs with the `# x0` line: every row an input.
        let r = imp("# x0 = 1, 2\nt,u1\n0,0.5\n0.1,-0.5\n").unwrap();
        assert_eq!(r.x0, vec![1.0, 2.0]);
        assert!(r.v.is_empty());
        assert_eq!(r.given, Given::Applied(vec![vec![0.5], vec![-0.5]]));
        assert_eq!(r.steps(), 2);
        // Applied inputs with the states and no `# x0` line: x0 is the first row's, the last row the
        // final state (its input not read).
        let r = imp("t,x1,x2,u1,status\n0,1,2,0.5,ok\n0.1,1,2,0.25,ok\n0.2,1,2,9,ok\n").unwrap();
        assert_eq!(r.x0, vec![1.0, 2.0]);
        assert_eq!(r.given, Given::Applied(vec![vec![0.5], vec![0.25]]));
        // States alone: one row more than steps.
        let r = imp("t,x1,x2\n0,0,0\n0.1,0.1,1\n0.2,0.3,2\n").unwrap();
        assert_eq!(r.x0, vec![0.0, 0.0]);
        assert_eq!(r.steps(), 2);
        let Given::States(x) = &r.given else {
            panic!("{r:?}")
        };
        assert_eq!(x.len(), 3);
        // The `# x0` line and the first row's states must agree.
        let e = imp("# x0 = 5, 0\nt,x1,x2\n0,0,0\n0.1,0,0\n").unwrap_err();
        assert!(
            matches!(e, CsvError::X0 { line: 1, .. }) && e.to_string().contains("x1 = 5"),
            "{e}"
        );
        // One row of states is no step; applied inputs without x0 are refused as before.
        assert!(matches!(
            imp("t,x1,x2\n0,0,0\n"),
            Err(CsvError::OneState { .. })
        ));
        assert!(matches!(imp("t,u1\n0,1\n"), Err(CsvError::X0 { .. })));
        // Some states or some inputs named, not all: said.
        let e = imp("# x0 = 0, 0\nt,x1,u1\n0,0,1\n0.1,0,1\n").unwrap_err();
        assert!(e.to_string().contains("some of the states `x1…x2`"), "{e}");
        let e = parse_import(
            "# x0 = 0, 0\nt,u1\n0,1\n",
            "r.csv",
            2,
            2,
            0.1,
            9,
            Coordinates::Plant,
        )
        .unwrap_err();
        assert!(
            e.to_string().contains("some inputs but not all m = 2"),
            "{e}"
        );
        // The references-only reader refuses what it did before.
        assert!(matches!(
            parse_recording(
                "# x0 = 0, 0\nt,x1,x2,u1\n0,0,0,1\n0.1,0,0,1\n",
                "a.csv",
                2,
                1,
                0.1,
                9
            ),
            Err(CsvError::Columns { .. })
        ));
        // Too long: the states' final row is not counted.
        assert!(imp("t,x1,x2\n0,0,0\n0.1,0,0\n").is_ok());
        let e = parse_import(
            "t,x1,x2\n0,0,0\n0.1,0,0\n0.2,0,0\n",
            "r.csv",
            2,
            1,
            0.1,
            1,
            Coordinates::Plant,
        )
        .unwrap_err();
        assert!(matches!(e, CsvError::TooLong { line: 4, .. }), "{e}");
    }

    #[test]
    fn a_linearized_plant_s_recording_names_its_model_s_coordinates() {
        let imp = |t: &str| parse_import(t, "r.csv", 2, 1, 0.1, 9, Coordinates::Linearized);
        let r = imp("t,xi1,xi2,w1\n0,1,2,0.5\n0.1,1,2,0\n").unwrap();
        assert_eq!(r.x0, vec![1.0, 2.0]);
        assert_eq!(r.given, Given::Applied(vec![vec![0.5]]));
        // A run `simulate` wrote of such a plant: the plant's own x and u, no references.
        let e = imp("# x0 = 0, 0\nt,x1,x2,u1,status\n0,0,0,1,ok\n0.1,0,0,1,ok\n").unwrap_err();
        assert!(
            matches!(e, CsvError::Header { .. })
                && e.to_string()
                    .contains("`xi1…xi2` (ξ) and the inputs `w1` (w)"),
            "{e}"
        );
        // Its references are read as before.
        assert_eq!(imp("# x0 = 0, 0\nt,v1\n0,1\n").unwrap().v, vec![vec![1.0]]);
    }
}

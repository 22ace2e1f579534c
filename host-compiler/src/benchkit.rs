//! Benchmark rows: the one format every bench uses to report its figures to `cargo xtask bench`.
//!
//! Each bench target writes `target/bench/rows/<target>.json`, a JSON list of [`Row`]; `cargo xtask bench`
//! merges all of them into `target/bench/summary.json` and prints one table.

use serde::Serialize;
use std::path::PathBuf;

/// One line of the bench table.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    pub name: String,
    pub value: f64,
    pub unit: String,
    /// The baseline measured in the same run, where one exists.
    pub baseline: Option<f64>,
    /// How many times better than the baseline (orientation documented per row), where one exists.
    pub ratio: Option<f64>,
}

impl Row {
    /// A row without baseline.
    pub fn new(name: &str, value: f64, unit: &str) -> Self {
        Self {
            name: name.into(),
            value,
            unit: unit.into(),
            baseline: None,
            ratio: None,
        }
    }
    /// A row with a baseline and its ratio.
    pub fn with_baseline(name: &str, value: f64, unit: &str, baseline: f64, ratio: f64) -> Self {
        Self {
            name: name.into(),
            value,
            unit: unit.into(),
            baseline: Some(baseline),
            ratio: Some(ratio),
        }
    }
}

/// The directory rows go to: `$CARGO_TARGET_DIR/bench/rows`, or `<workspace>/target/bench/rows`.
pub fn rows_dir() -> PathBuf {
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(env!("CARGO_MANIFEST_DIR"))
                .join("..")
                .join("target")
        });
    target.join("bench").join("rows")
}

/// Write (replace) the rows of one bench target and print them.
pub fn write_rows(target: &str, rows: &[Row]) -> std::io::Result<PathBuf> {
    let dir = rows_dir();
    std::fs::create_dir_all(&dir)?;
    let path = dir.join(format!("{target}.json"));
    std::fs::write(&path, serde_json::to_string_pretty(rows)?)?;
    for r in rows {
        println!(
            "BENCH {:<40} {:>14.6} {:<10} baseline={:?} ratio={:?}",
            r.name, r.value, r.unit, r.baseline, r.ratio
        );
    }
    Ok(path)
}

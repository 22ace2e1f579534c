//! Benchmark rows: the one format every bench uses to report its figures to `cargo xtask bench`.
//!
//! Each bench target writes `target/bench/rows/<target>.json`, a JSON list of [`Row`]; `cargo xtask bench`
//! merges all of them into `target/bench/summary.json` and prints one table.

use serde::Serialize;
use std::path::PathBuf;
use std::time::{Duration, Instant};

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

/// Median wall time in seconds of one call of `f` over repeated calls lasting at least `budget`, and at
/// least `min_runs` calls.
pub fn median_time(mut f: impl FnMut(), budget: Duration, min_runs: usize) -> f64 {
    let start = Instant::now();
    let mut times = Vec::new();
    while start.elapsed() < budget || times.len() < min_runs {
        let s = Instant::now();
        f();
        times.push(s.elapsed().as_secs_f64());
    }
    times.sort_by(|a, b| a.total_cmp(b));
    times[times.len() / 2]
}

/// One target's line of a fuzz campaign record (`fuzz/CAMPAIGN.md`).
#[derive(Clone, Debug, PartialEq)]
pub struct FuzzTarget {
    pub target: String,
    pub executions: u64,
    pub crashes: u64,
}

/// The per-target lines of a fuzz campaign record: the rows of its Markdown table
/// `| target | executions | crashes | …`, in file order (rows whose second and third cells are not
/// integers, such as the header and its rule, are not target lines). An error when there are none.
pub fn fuzz_campaign(text: &str) -> Result<Vec<FuzzTarget>, String> {
    let rows: Vec<FuzzTarget> = text
        .lines()
        .filter_map(|l| {
            let cells: Vec<&str> = l
                .trim()
                .strip_prefix('|')?
                .split('|')
                .map(str::trim)
                .collect();
            let int = |i: usize| {
                cells
                    .get(i)?
                    .replace([' ', '_', ','], "")
                    .parse::<u64>()
                    .ok()
            };
            Some(FuzzTarget {
                target: cells.first()?.trim_matches('`').to_string(),
                executions: int(1)?,
                crashes: int(2)?,
            })
        })
        .collect();
    if rows.is_empty() {
        return Err(
            "no target rows `| target | executions | crashes | …` in the campaign record".into(),
        );
    }
    Ok(rows)
}

/// The bench rows of a campaign record: `fuzz_execs_min` (the fewest executions of any target) and
/// `fuzz_crashes` (summed over the targets).
pub fn fuzz_rows(targets: &[FuzzTarget]) -> Vec<Row> {
    let min = targets.iter().map(|t| t.executions).min().unwrap_or(0);
    let crashes: u64 = targets.iter().map(|t| t.crashes).sum();
    vec![
        Row::new("fuzz_execs_min", min as f64, "executions"),
        Row::new("fuzz_crashes", crashes as f64, "crashes"),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_campaign_table_gives_the_rows() {
        let text = "# Campaign\n\n| target | executions | crashes | seconds |\n|---|---|---|---|\n\
                    | `image_decode` | 12 000 000 | 0 | 600 |\n| spec_parse | 10_000_001 | 2 | 900 |\n\
                    not a row | 5 | 5\n";
        let t = fuzz_campaign(text).unwrap();
        assert_eq!(
            t,
            vec![
                FuzzTarget {
                    target: "image_decode".into(),
                    executions: 12_000_000,
                    crashes: 0
                },
                FuzzTarget {
                    target: "spec_parse".into(),
                    executions: 10_000_001,
                    crashes: 2
                },
            ]
        );
        let rows = fuzz_rows(&t);
        assert_eq!(rows[0].name, "fuzz_execs_min");
        assert_eq!(rows[0].value, 10_000_001.0);
        assert_eq!(rows[1].value, 2.0);
        assert!(fuzz_campaign("| a | b | c |\n").is_err());
    }
}

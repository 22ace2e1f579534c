//! `host-compiler mtl`: robustness of a CSV trace against an MTL formula (Def 2.17), using
//! [`crate::robustness::mtl`].
//!
//! Output: with `--all`, the header `t,rho` and one line per sample first; always, as the last line,
//! `robustness at t = <t0>: <value>` where t0 is the first sample time, so the value at the start of the
//! trace is the last token. Values print as Rust's shortest round-trip decimal; ±∞ print as `inf` and
//! `-inf`.

use crate::robustness::mtl::{sets::from_spec_sets, Formula, NamedSet, Trace};
use miette::IntoDiagnostic;
use std::io::Write;

/// Arguments of `mtl`.
#[derive(clap::Args, Debug)]
pub struct MtlArgs {
    /// Trace as CSV with header `t,<signal names>`.
    #[arg(long)]
    pub trace: std::path::PathBuf,
    /// The formula, e.g. 'G[0,10] (x1 >= 0.5 & !Unsafe)'.
    #[arg(long)]
    pub formula: String,
    /// Named sets (TOML) that atomic propositions may refer to.
    #[arg(long)]
    pub sets: Option<std::path::PathBuf>,
    /// Print the whole robustness signal, not only its value at t = 0.
    #[arg(long)]
    pub all: bool,
}

/// Run `mtl`: read the trace (and sets), parse and bind the formula, print the robustness.
pub fn run(a: &MtlArgs) -> miette::Result<()> {
    let trace = Trace::from_csv_path(&a.trace)?;
    let sets: Vec<NamedSet> = match &a.sets {
        Some(path) => from_spec_sets(crate::spec::load_named_sets(path)?, trace.names())?,
        None => Vec::new(),
    };
    let formula = Formula::parse(&a.formula)?;
    let monitor = formula.bind(trace.names(), &sets)?;
    let rho = monitor.robustness(&trace)?;
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    if a.all {
        writeln!(out, "t,rho").into_diagnostic()?;
        for (t, r) in trace.times().iter().zip(&rho) {
            writeln!(out, "{t},{r}").into_diagnostic()?;
        }
    }
    writeln!(out, "robustness at t = {}: {}", trace.times()[0], rho[0]).into_diagnostic()?;
    out.flush().into_diagnostic()?;
    Ok(())
}

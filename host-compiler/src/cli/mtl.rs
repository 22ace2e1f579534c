//! `host-compiler mtl`: robustness of a CSV trace against an MTL formula.

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

pub fn run(_a: &MtlArgs) -> miette::Result<()> {
    Err(miette::miette!("mtl: not built yet"))
}

//! `host-compiler inspect IMAGE [--json]`: decode, validate and print a controller image.

/// Arguments of `inspect`.
#[derive(clap::Args, Debug)]
pub struct InspectArgs {
    /// Controller image file.
    pub image: std::path::PathBuf,
    /// Print the whole content as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(_a: &InspectArgs) -> miette::Result<()> {
    Err(miette::miette!("inspect: not built yet"))
}

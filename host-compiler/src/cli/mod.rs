//! Command-line interface: argument parsing and dispatch. Each subcommand lives in its own file.

use clap::{Parser, Subcommand};
use std::path::PathBuf;

pub mod inspect;
pub mod mtl;
pub mod simulate;
pub mod synth;
pub mod synth_pwa;
pub mod verify;

/// Synthesise controllers that are provably safe for one task, and the fixed-size image a
/// microcontroller runs.
#[derive(Parser, Debug)]
#[command(
    name = "host-compiler",
    version,
    about,
    after_help = "Typical use:\n  \
    host-compiler synth examples/planar-vehicle.toml --out out/planar-vehicle\n  \
    host-compiler verify examples/planar-vehicle.toml out/planar-vehicle/controller.img\n  \
    host-compiler simulate examples/planar-vehicle.toml out/planar-vehicle/controller.img --x0 0.1,0,0,1\n  \
    host-compiler inspect out/planar-vehicle/controller.img --json\n\n\
    `synth` covers Init with certified balls around nominal trajectories, writes the image the firmware \
    runs, a report (report.html) and the certificate data; everything it calls certified is re-checked by \
    closed-loop simulation through the firmware's own f32 evaluator."
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Synthesise a certified controller image and report from a task spec (TOML).
    Synth(SynthArgs),
    /// Re-check an image against its spec by closed-loop Monte Carlo through the shared f32 evaluator.
    ///
    /// Every run must reach Goal within the horizon, stay out of Unsafe (also between samples for
    /// continuous-time plants) and apply only inputs in the input set. For a PWA-feedback image the
    /// certificate is first recomputed from the image bytes alone: (6.6) and (6.7) per partition, the
    /// one-step inclusion of every ball into a ball whose f32 test provably accepts, the input bound,
    /// containment of every ball across the tree's boundaries, and a bound on the steps to Goal from the
    /// order in which the leaves list their balls. Exits non-zero on any failure or violation.
    Verify(verify::VerifyArgs),
    /// Simulate the closed loop of a spec's plant with an image from one initial state; writes CSV.
    Simulate(simulate::SimulateArgs),
    /// Decode and validate a controller image; print its whole content.
    Inspect(inspect::InspectArgs),
    /// Robustness of a recorded trace against a metric temporal logic formula (Def 2.17).
    Mtl(mtl::MtlArgs),
}

/// Entry point of the binary.
pub fn main() -> miette::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Inspect(a) => inspect::run(&a),
        Command::Mtl(a) => mtl::run(&a),
        Command::Synth(a) => synth::run(&a),
        Command::Verify(a) => verify::run(&a),
        Command::Simulate(a) => simulate::run(&a),
    }
}

/// Arguments of `synth`.
#[derive(clap::Args, Debug)]
pub struct SynthArgs {
    /// Task spec (TOML); see examples/README.md for the format.
    pub spec: PathBuf,
    /// Output directory: controller.img, report.html and certificate.json are written there.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Monte Carlo runs from the certified cover in the final verification.
    #[arg(long, default_value_t = 10_000)]
    pub verify_runs: usize,
    /// A recorded trajectory to certify and use before any is generated (repeatable): CSV with a comment
    /// line `# x0 = …` giving the initial state, a header `t,v1,…,vm` and one row of reference inputs per
    /// sample period.
    #[arg(long = "import", value_name = "FILE.csv")]
    pub imports: Vec<PathBuf>,
    /// How trajectories after the first are made: `algorithm4` (§5.4: grow from the boundary of the
    /// closest ball and maximise δ by §5.3) or `scp` (Algorithm 1: the SCP generator per uncovered seed).
    #[arg(long, value_enum, default_value_t = crate::synth::Generator::Algorithm4)]
    pub generator: crate::synth::Generator,
    /// Hide progress bars.
    #[arg(long)]
    pub quiet: bool,
}

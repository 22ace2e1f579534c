//! Command-line interface: argument parsing and dispatch. Each subcommand lives in its own file.

use clap::{Parser, Subcommand};

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
    Synth(synth::SynthArgs),
    /// Re-check an image against its spec by closed-loop Monte Carlo through the shared f32 evaluator.
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

//! `host-compiler export --c IMAGE --out DIR`: writes the C export of a controller image
//! (`crate::export::c`): a self-contained C99 evaluator and the image bytes as a `const` array.

use std::path::PathBuf;

use super::{BadInput, Exit, Outcome};

/// Arguments of `export`.
#[derive(clap::Args, Debug)]
#[command(after_help = "Writes into DIR:\n  \
    controller.h, controller.c        the evaluator: sc_init (decode and validate), sc_reset, sc_step, sc_fallback\n  \
    controller_image.h, controller_image.c   the image bytes as `const uint8_t sc_image_bytes[]`\n\n\
    The C is C99 without malloc, recursion or unbounded loops (every loop is bounded by the capacities the \
    image format declares). sc_init validates the bytes as the Rust decoder does (CRC, directory, every \
    field) and refuses a corrupted array with an error code. sc_step gives the same status and the same \
    input bits as the Rust evaluator when compiled with\n  \
    cc -std=c99 -O2 -ffp-contract=off -fno-fast-math\n\
    (no fused multiply-add contraction, no fast math; the header says so too).\n\n\
    Example:\n  \
    host-compiler export --c out/planar-vehicle/controller.img --out out/planar-vehicle/c\n\n\
    Exit status: 0 written; 2 the image is unreadable or invalid, or DIR cannot be written.")]
pub struct ExportArgs {
    /// Controller image to export as C (`controller.img` of `synth`).
    #[arg(long = "c", value_name = "IMAGE")]
    pub c: PathBuf,
    /// Output directory (created if missing; the four files in it are replaced).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
}

/// Entry point of the subcommand.
pub fn run(a: &ExportArgs) -> Outcome {
    let bytes = super::read_image(&a.c)?;
    let written = crate::export::c::write(&bytes, &a.out)
        .map_err(|e| miette::miette!("{}: {e}", a.c.display()))
        .bad_input()?;
    for p in written {
        println!("wrote {}", p.display());
    }
    Ok(Exit::Success)
}

//! Command-line interface: argument parsing and dispatch. Each subcommand lives in its own file.

use clap::{Parser, Subcommand};
use miette::{IntoDiagnostic, WrapErr};
use std::path::PathBuf;

pub mod export;
pub mod inspect;
pub mod mtl;
pub mod play;
pub mod simulate;
pub mod synth;
pub mod synth_hybrid;
mod synth_pwa;
pub mod synth_temporal;
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
    host-compiler inspect out/planar-vehicle/controller.img --json\n  \
    host-compiler export --c out/planar-vehicle/controller.img --out out/planar-vehicle/c\n\n\
    `synth` covers Init with certified balls around nominal trajectories, writes the image the firmware \
    runs, a report (report.html) and the certificate data; everything it calls certified is re-checked by \
    closed-loop simulation through the firmware's own f32 evaluator.\n\n\
    Exit status:\n  \
    0    success (synth: the coverage target is met and the verification passed)\n  \
    1    a check failed: a violation, a certificate the image bytes do not prove, or nothing certified\n  \
    2    bad input: a spec, image, trace, recording or flag that is invalid, unreadable or does not match; \
    or (synth) a task whose loop provably certifies no trajectory, refused before any search\n  \
    3    certified and verified, but short of the coverage target (synth: the cover; verify: the image's coverage of the spec's Init)\n  \
    130  synth interrupted by Ctrl-C (the image holds what was certified so far)"
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
    /// Play the task in a browser: your runs are certified live and join the cover (`--out`).
    Play(play::PlayArgs),
    /// Export an image for a C firmware: a self-contained C99 evaluator and the image as a const array.
    ///
    /// The C evaluator validates the bytes as the firmware's decoder does and gives the Rust evaluator's
    /// status and input bits when compiled with -std=c99 -O2 -ffp-contract=off -fno-fast-math.
    Export(export::ExportArgs),
}

/// How a command ended: the process's exit status (listed in `--help`). Clap's own usage errors exit
/// with 2 too, so every kind of bad input has one code.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Exit {
    /// 0: done; for `synth`, the coverage target is met and the verification passed.
    Success,
    /// 1: a check failed: a violation, a certificate the image bytes do not prove, or nothing certified.
    Failed,
    /// 2: bad input: a spec, image, trace, recording or flag that is invalid, unreadable or does not
    /// match the others; or, for `synth`, a task whose loop provably certifies no trajectory
    /// (`certify::Ceiling`), refused before any search.
    BadInput,
    /// 3: `synth` certified and verified an image, but its cover is short of the coverage target; or
    /// `verify` passed every check, but the image's coverage of the spec's Init is short of it.
    ShortOfTarget,
    /// 130: `synth` was interrupted (Ctrl-C); the image holds what was certified so far.
    Interrupted,
}

impl Exit {
    /// The process exit status.
    pub fn code(self) -> u8 {
        match self {
            Exit::Success => 0,
            Exit::Failed => 1,
            Exit::BadInput => 2,
            Exit::ShortOfTarget => 3,
            Exit::Interrupted => 130,
        }
    }
}

/// A command that did not succeed: the report to print and the exit status.
#[derive(Debug)]
pub struct Failure {
    pub exit: Exit,
    pub report: miette::Report,
}

impl Failure {
    /// Bad input ([`Exit::BadInput`]).
    pub fn bad_input(report: impl Into<miette::Report>) -> Self {
        Self {
            exit: Exit::BadInput,
            report: report.into(),
        }
    }
}

/// An error without a class is a failed check ([`Exit::Failed`]); bad input says so with
/// [`BadInput::bad_input`].
impl From<miette::Report> for Failure {
    fn from(report: miette::Report) -> Self {
        Self {
            exit: Exit::Failed,
            report,
        }
    }
}

/// The outcome of a subcommand: how it ended (a success or a short-of-target result), or a failure.
pub type Outcome = Result<Exit, Failure>;

/// Marks an error as bad input.
pub trait BadInput<T> {
    fn bad_input(self) -> Result<T, Failure>;
}

impl<T, E: Into<miette::Report>> BadInput<T> for Result<T, E> {
    fn bad_input(self) -> Result<T, Failure> {
        self.map_err(Failure::bad_input)
    }
}

/// Entry point of the binary: runs the subcommand, prints its error (if any) and returns its status.
pub fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let outcome = match cli.command {
        // Every error of these two is about their input (the image; the trace, sets or formula).
        Command::Inspect(a) => inspect::run(&a).map(|()| Exit::Success).bad_input(),
        Command::Mtl(a) => mtl::run(&a).map(|()| Exit::Success).bad_input(),
        Command::Synth(a) => synth::run(&a),
        Command::Verify(a) => verify::run(&a),
        Command::Simulate(a) => simulate::run(&a),
        Command::Play(a) => play::run(&a),
        Command::Export(a) => export::run(&a),
    };
    let exit = outcome.unwrap_or_else(|f| {
        eprintln!("Error: {:?}", f.report);
        f.exit
    });
    std::process::ExitCode::from(exit.code())
}

/// Arguments of `synth`.
#[derive(clap::Args, Debug)]
pub struct SynthArgs {
    /// Task spec (TOML); see examples/README.md for the format.
    pub spec: PathBuf,
    /// Output directory: controller.img, report.html and certificate.json are written there.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Monte Carlo runs from the certified cover in the final verification; at most 1000000
    /// (`verify::MAX_RUNS`).
    #[arg(long, default_value_t = 10_000, value_parser = clap::value_parser!(u64).range(..=crate::verify::MAX_RUNS))]
    pub verify_runs: u64,
    /// A recorded trajectory (a route planned elsewhere, a run `play` wrote) to certify and use before any
    /// is generated (repeatable). CSV, one row per sample period, the time first, at most as many steps
    /// as the spec's horizon has samples; the columns give one of: the references `v1…vm` of the loop
    /// u = K̂x + v, with a comment line `# x0 = …` before the header (what `play` and `simulate` write;
    /// `v` columns are read whenever present); the applied inputs `u1…um`, with the `# x0` line or the
    /// states `x1…xn` (then the last row is the final state), v derived along their replay once K̂ is
    /// designed; or the states `x1…xn` alone, the inputs found by least squares within the input bound
    /// (a recording the plant cannot follow within it is refused, naming the sample). For a
    /// feedback-linearizable or flat plant the states and inputs are its linear model's, `xi1…xin` and
    /// `w1…wm`. A directory imports all its `*.csv` files in sorted order. For a hybrid plant (references
    /// only) the run is replayed on the automaton and split at its events into the location path's
    /// segments.
    #[arg(long = "import", value_name = "FILE.csv|DIR")]
    pub imports: Vec<PathBuf>,
    /// How trajectories after the first are made: `algorithm4` (§5.4: grow from the boundary of the
    /// closest ball and maximise δ by §5.3; the default for a single-location plant) or `scp` (Algorithm
    /// 1: the generator from each uncovered seed; the default for a hybrid plant, whose planner tries
    /// every switching schedule and, for forced switching, maximises δ by §5.3 over the segments).
    /// Algorithm 4 on a hybrid plant keeps its parent's locations and, for forced switching, its
    /// switching samples; across an internal guard it follows the parent's law through the crossing.
    #[arg(long, value_enum)]
    pub generator: Option<crate::synth::Generator>,
    /// A hybrid plant with internal switching: once a round of seeds certifies no run, ask the global
    /// route search for routes from the seed to Goal through the guards (in other homotopy classes, e.g.
    /// under an obstacle the planner passes over) and plan along each. Minutes per seed. Single-location
    /// plants ask their routes whenever the growth stalls, without this flag. Refused (exit 2) for a spec
    /// without internal switching.
    #[arg(long)]
    pub guard_routes: bool,
    /// Add the task's online monitor to the image (section 14): the firmware evaluates the spec's
    /// [mtl] formula, or a reach-avoid task as `!Unsafe U[0,T] Goal`, on the measured state every step
    /// and reports the running lower and upper bound of its robustness and the verdict once decided.
    /// The sets must be boxes, balls, polytopes or half-spaces over state coordinates (refused, exit 2,
    /// before synthesis otherwise). The control law and its certificate are unchanged.
    #[arg(long)]
    pub monitor: bool,
    /// Hide progress bars.
    #[arg(long)]
    pub quiet: bool,
}

/// The monitor section of the spec `a.spec` as written ([`crate::monitor::Program::for_problem`]) when
/// `--monitor` asks for one; a spec it cannot monitor is bad input saying why.
pub(crate) fn monitor_section(
    a: &SynthArgs,
    problem: &crate::spec::Problem,
) -> Result<Option<crate::monitor::Program>, Failure> {
    if !a.monitor {
        return Ok(None);
    }
    crate::monitor::Program::for_problem(problem)
        .map(Some)
        .map_err(|e| miette::miette!("--monitor: {e}"))
        .bad_input()
}

/// `image` with the spec's monitor attached when `--monitor` asks for it (and a line on it), else the
/// image itself.
pub(crate) fn monitored(a: &SynthArgs, image: &[u8]) -> Result<Vec<u8>, Failure> {
    if !a.monitor {
        return Ok(image.to_vec());
    }
    let problem = crate::spec::load(&a.spec).bad_input()?;
    let Some(prog) = monitor_section(a, &problem)? else {
        return Ok(image.to_vec());
    };
    let (words, ram) = prog.footprint();
    println!(
        "monitor: {} atoms, {} nodes over {} samples; arena {words} words, {ram} bytes of RAM",
        prog.atoms.len(),
        prog.nodes.len(),
        prog.horizon + 1
    );
    crate::monitor::attach(image, &prog.encode()).map_err(|e| Failure {
        exit: Exit::Failed,
        report: miette::miette!("attaching the monitor: {e}"),
    })
}

/// The bytes of an image file; an unreadable file is bad input naming the file.
/// The stage lines of a long command (`synth`, `verify`): each printed on stderr as it comes, with the
/// seconds since this receiver was made (stdout keeps the report).
pub(crate) fn stage_lines() -> crate::cover::StageHook {
    let t0 = std::time::Instant::now();
    crate::cover::StageHook(std::sync::Arc::new(move |line: &str| {
        eprintln!("{line} ({:.0} s)", t0.elapsed().as_secs_f64())
    }))
}

pub(crate) fn read_image(path: &std::path::Path) -> Result<Vec<u8>, Failure> {
    std::fs::read(path)
        .into_diagnostic()
        .wrap_err_with(|| format!("cannot read the image {}", path.display()))
        .bad_input()
}

/// The decoded image; a rejected one is bad input naming the file and the decoder's reason.
pub(crate) fn decode_image<'a>(
    bytes: &'a [u8],
    path: &std::path::Path,
) -> Result<shared_types::image::Image<'a>, Failure> {
    shared_types::image::decode(bytes)
        .map_err(|e| miette::miette!("{}: the image is rejected: {e}", path.display()))
        .bad_input()
}

/// The image's dimensions, sample period and spec fingerprint against the spec's
/// (`verify::check_matches`); a mismatch is bad input naming both files. An image without a fingerprint is
/// accepted with a warning on standard error.
pub(crate) fn image_matches_spec(
    problem: &crate::spec::Problem,
    img: &shared_types::image::Image<'_>,
    image: &std::path::Path,
    spec: &std::path::Path,
) -> Result<(), Failure> {
    crate::verify::check_matches(problem, img)
        .map_err(|e| {
            miette::miette!(
                "{} does not belong to {}: {e}",
                image.display(),
                spec.display()
            )
        })
        .bad_input()?;
    if img.fingerprint().is_none() {
        eprintln!(
            "warning: {} stores no spec fingerprint (written before images had one): it cannot be told \
             whether {} changed since it was synthesised",
            image.display(),
            spec.display()
        );
    }
    Ok(())
}

/// A feedback-linearizable task's model maps against the image's (`verify::nonlinear::check_maps`): an
/// image made for another model, or without maps, is bad input naming both files.
pub(crate) fn maps_match(
    maps: &crate::model::feedback_linearizable::FlMaps,
    img: &shared_types::image::Image<'_>,
    image: &std::path::Path,
    spec: &std::path::Path,
) -> Result<(), Failure> {
    crate::verify::nonlinear::check_maps(maps, img)
        .map_err(|e| {
            miette::miette!(
                "{} does not belong to {}: {e}",
                image.display(),
                spec.display()
            )
        })
        .bad_input()
}

/// The task of a validated spec; a spec that makes no task (its plant cannot be sampled, a set cannot be
/// built) is bad input.
pub(crate) fn task_of(problem: crate::spec::Problem) -> Result<crate::task::Task, Failure> {
    crate::task::Task::new(problem)
        .map_err(|e| miette::miette!("{e}"))
        .bad_input()
}

/// The identity of an image as `certificate.json` records it (key `"image"`): the file name it was
/// written under, its size and its SHA-256, so that `inspect` can tell whether a certificate belongs to
/// the image it is shown with ([`inspect`]).
pub(crate) fn image_identity(file: &std::path::Path, bytes: &[u8]) -> serde_json::Value {
    serde_json::json!({
        "file": file.file_name().map(|f| f.to_string_lossy().into_owned()),
        "bytes": bytes.len(),
        "sha256": sha256_hex(bytes),
    })
}

/// The SHA-256 of `bytes`, in lowercase hex.
pub(crate) fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// What runs did after Goal under a terminal law, each count a violation except the handed-over one: one
/// wording for `synth`, the PWA `synth` and `verify`.
pub(crate) fn after_goal_judged(
    steps: usize,
    left_goal: usize,
    unsafe_: usize,
    input: usize,
    not_handed_over: usize,
    handed_over: usize,
) -> String {
    format!(
        "judged over runs of {steps} samples: {left_goal} runs left Goal, {unsafe_} entered Unsafe, \
         {input} left the input set, {not_handed_over} were not handed over within the horizon (each a \
         violation); {handed_over} were handed over"
    )
}

/// What runs did after Goal without a terminal law (reported, not judged: the task ends in Goal).
pub(crate) fn after_goal_unjudged(
    steps: usize,
    left_goal: usize,
    unsafe_: usize,
    input: usize,
) -> String {
    format!(
        "not judged (no terminal law): within {steps} samples {left_goal} runs were outside Goal again, \
         {unsafe_} entered Unsafe, {input} left the input set"
    )
}

//! `host-compiler play SPEC`: serves the game (`crate::play`) on 127.0.0.1 and prints its address;
//! accepted runs are written into `--out`, where `synth --import DIR` reads them. A hybrid spec plays on
//! its automaton (with forced switching the player chooses the location); a feedback-linearizable spec
//! plays the nonlinear plant under the linearising law (`crate::play::played`).

use super::{task_of, BadInput, Exit, Outcome};
use std::path::PathBuf;

/// Arguments of `play`.
#[derive(clap::Args, Debug)]
pub struct PlayArgs {
    /// Task spec (TOML).
    pub spec: PathBuf,
    /// Port on 127.0.0.1 (0: any free port; the address is printed).
    #[arg(long, default_value_t = 8765)]
    pub port: u16,
    /// Where accepted runs are written as recordings (`run-NNNN-<player>.csv`); the runs already there
    /// are certified again and join the cover. `synth --import DIR` reads the directory.
    #[arg(long, default_value = "out/play")]
    pub out: PathBuf,
    /// The page's default speed as a fraction of real time (the text's game ran at 1/3).
    #[arg(long, default_value_t = 1.0 / 3.0)]
    pub slow: f64,
    /// The two state coordinates drawn, e.g. `x1,x2` (default: Goal's two coordinates, else x1,x2).
    #[arg(long, value_name = "xi,xj")]
    pub projection: Option<String>,
}

pub fn run(a: &PlayArgs) -> Outcome {
    let problem = crate::spec::load(&a.spec).bad_input()?;
    let projection = a
        .projection
        .as_deref()
        .map(parse_projection)
        .transpose()
        .map_err(|e| miette::miette!("--projection: {e}"))
        .bad_input()?;
    let settings = crate::play::PlaySettings {
        out: a.out.clone(),
        projection,
        slow: a.slow,
    };
    // A hybrid automaton plays through its own task (a CAF per location, the location path).
    let game = if problem.hybrid.is_some() {
        let task = crate::synth::hybrid::HybridTask::new(problem)
            .map_err(|e| miette::miette!("{e}"))
            .bad_input()?;
        crate::play::Game::hybrid(task, settings)
    } else {
        crate::play::Game::new(task_of(problem)?, settings)
    }
    .map_err(|e| miette::miette!("{e}"))
    .bad_input()?;
    let (accepted, coverage) = (game.accepted(), game.coverage());
    let addr = std::net::SocketAddr::from(([127, 0, 0, 1], a.port));
    let served = crate::play::serve(game, addr)
        .map_err(|e| miette::miette!("{e}"))
        .bad_input()?;
    // Written without println!: a reader that closed the pipe (a test that read the address) must not
    // stop the server.
    use std::io::Write;
    let mut out = std::io::stdout();
    let _ = writeln!(out, "play: http://{}/", served.addr);
    let _ = writeln!(
        out,
        "runs: {} ({accepted} accepted runs there, coverage {:.1} %); Ctrl-C stops",
        a.out.display(),
        100.0 * coverage
    );
    let _ = out.flush();
    served.wait();
    Ok(Exit::Success)
}

/// `xi,xj` (1-based names) to 0-based indices.
fn parse_projection(s: &str) -> Result<[usize; 2], String> {
    let ix: Vec<usize> = s
        .split(',')
        .map(|p| {
            p.trim()
                .strip_prefix('x')
                .and_then(|d| d.parse::<usize>().ok())
                .filter(|&i| i >= 1)
                .map(|i| i - 1)
                .ok_or_else(|| format!("`{}` is not a coordinate name like x1", p.trim()))
        })
        .collect::<Result<_, _>>()?;
    match ix[..] {
        [a, b] => Ok([a, b]),
        _ => Err(format!("give two coordinates like x1,x2, not `{s}`")),
    }
}

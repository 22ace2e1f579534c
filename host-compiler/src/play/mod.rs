//! `host-compiler play`: person-made trajectories, certified live (§1.1.3, §1.3; Example 4.8's video
//! game, issue #15).
//!
//! People steer the task's plant in a browser page; each finished run is certified at once by the same
//! path as `synth --import` and, when accepted, joins the cover and
//! is written into the out directory as a recording that `synth --import DIR` reads.
//!
//! * [`game`] owns the state: the task, the players' sessions, the accepted runs, the coverage samples,
//!   and the JSON each request answers. It knows nothing of HTTP.
//! * `played` is what the game asks of the task: a one-location task with its CAF, or a hybrid automaton
//!   with internal switching (a CAF per location, §4.2.2); how a period is stepped (the same
//!   [`crate::model::Plant`] code as synthesis, the exact flow across events for a hybrid plant) and how a
//!   finished run is certified (the import path of its class: [`crate::cover::certify_recording`] or
//!   [`crate::synth::hybrid::import::certify_recording`]).
//! * [`server`] owns the HTTP side: a small blocking server (`tiny_http`) with a few worker threads,
//!   the routes, bounded request bodies, and the page embedded in the binary (`page/index.html`).
//!
//! As in the text's game, the player's keys set the reference input v of the tracking loop
//! u = K̂ x + v (4.19); the server applies u clipped to the spec's input bound and records the v that was
//! in effect, so the recording's nominal is the run that was played.

pub mod game;
mod played;
pub mod server;

pub use game::{Game, PlayError, PlaySettings};
pub use server::{serve, Served};

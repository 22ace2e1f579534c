//! The firmware's control loop, the same on every board: validate the embedded controller image at boot,
//! then serve control steps: read a COBS-framed request from the board's link, evaluate the controller
//! through `shared_types::eval` ([`app`]), reply with the input, a status and the step's cost ([`serve`]).
//!
//! A board supplies what touches hardware, through the traits in [`board`]: the byte link to the plant
//! ([`board::Link`]), the step-cost meter ([`board::Meter`]) and the stack high-water mark
//! ([`board::StackMeter`]). This crate has no register access and no logging, so it builds and is tested
//! on the host (`cargo test --target <host triple> -p control-loop` from `firmware/`) against a mock board.
//! No heap; every buffer is sized by `shared_types::capacity`.
//!
//! The image is chosen at build time (`CONTROLLER_IMAGE`, see `build.rs`) and embedded here ([`image`]),
//! so every board runs the same bytes the same way.
#![cfg_attr(not(test), no_std)]

pub mod app;
pub mod board;
pub mod image;
pub mod serve;
#[cfg(target_os = "none")]
pub mod stack;

use shared_types::image::{Image, ImageError};

/// Validates the embedded image ([`image::image`]) and makes the loop's state: on failure the app answers
/// every frame with `ImageRejected` and a zero input of dimension [`image::REJECTED_M`]. The decode
/// result is returned for the board to log.
pub fn boot() -> (app::App<'static>, Result<Image<'static>, ImageError>) {
    app::App::new(image::image(), image::REJECTED_M)
}

//! host-compiler: from a task spec to a certified controller image (DESIGN §3).
//!
//! One concept per module; each module's doc comment says what it owns.
#![allow(non_snake_case)]

// The BLAS/LAPACK symbols clarabel's SDP support links against come from this crate.
extern crate lapack_faer;

pub mod benchkit;
pub mod caf;
pub mod certify;
pub mod cli;
pub mod cover;
pub mod csv;
pub mod emit;
pub mod export;
pub mod expr;
pub mod fuzz;
pub mod geometry;
pub mod linalg;
pub mod model;
pub mod monitor;
pub mod optimize;
pub mod play;
pub mod property;
pub mod pwa;
pub mod report;
pub mod robustness;
pub mod settings;
pub mod solver;
pub mod spec;
pub mod synth;
pub mod task;
pub mod terminal;
pub mod text;
pub mod trajectory;
pub mod verification;
pub mod verify;

//! host-compiler: from a task spec to a certified controller image (DESIGN §3).
//!
//! One concept per module; each module's doc comment says what it owns.
#![allow(non_snake_case)]

pub mod benchkit;
pub mod caf;
pub mod cli;
pub mod geometry;
pub mod model;
pub mod robustness;

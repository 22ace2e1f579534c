//! The lapack-faer integration tests, as one test binary (one per crate: clarabel links once): each module
//! is a former `tests/<name>.rs`, and `common` holds the references they share.

mod blas;
mod clarabel_sdp;
mod common;
mod lapack;
mod single;

//! The controller image and the build-time fallback input dimension, as chosen by `build.rs`
//! (`CONTROLLER_IMAGE`, `CONTROLLER_REJECTED_M`).

mod build_config {
    include!(concat!(env!("OUT_DIR"), "/build_config.rs"));
}

/// Input dimension of the zero input applied when the image is rejected at boot.
pub const REJECTED_M: usize = build_config::REJECTED_M;

/// Byte array with the alignment of `f64`, so that the image is stored word-aligned in flash.
#[repr(C, align(8))]
struct Aligned<T: ?Sized>(T);

static ALIGNED: &Aligned<[u8]> = &Aligned(*include_bytes!(concat!(env!("OUT_DIR"), "/image.bin")));

/// The controller image's bytes, 8-byte aligned.
pub fn image() -> &'static [u8] {
    &ALIGNED.0
}

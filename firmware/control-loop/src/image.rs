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

/// The monitor's arena (`build.rs`: sized by the embedded image's program), handed out once.
#[cfg(monitor)]
pub fn monitor_arena() -> Option<&'static mut [u32]> {
    use core::sync::atomic::{AtomicBool, Ordering};
    const WORDS: usize = if build_config::MONITOR_WORDS == 0 {
        1
    } else {
        build_config::MONITOR_WORDS
    };
    static TAKEN: AtomicBool = AtomicBool::new(false);
    static mut ARENA: [u32; WORDS] = [0; WORDS];
    if TAKEN.swap(true, Ordering::AcqRel) {
        return None;
    }
    // SAFETY: the flag hands the array out at most once, so this is its only reference.
    Some(unsafe { &mut *core::ptr::addr_of_mut!(ARENA) })
}

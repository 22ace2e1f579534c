//! Build script of the control loop, the same for every board:
//! 1. embeds the controller image: the file named by `CONTROLLER_IMAGE` (a path; a relative path is taken
//!    from `firmware/`, the firmware workspace's root, whichever folder cargo runs in), else a default test
//!    image generated here (see [`default_image`]);
//! 2. writes the build-time fallback used when the image is rejected at boot: a zero input of dimension
//!    `CONTROLLER_REJECTED_M` if set, else the plant's input dimension of the image if it decodes (`m`, or
//!    `m_plant` with model maps), else the `m` its header declares (if the header is readable at all),
//!    else 0.
//! 3. sets `cfg(model_maps)` when the embedded image has model maps (a feedback-linearizable plant,
//!    `shared_types::maps`), or when `CONTROLLER_MODEL_MAPS=1` (the no-panic check sets it, so that the
//!    path is checked whatever the image). With it the loop runs the evaluator's `step_plant`, and the
//!    program interpreter and `libm` are linked; without it the loop runs `step`, which for an image
//!    without maps is the same function (`step_plant` is `step` there), and the interpreter stays out
//!    of flash. The image is fixed at build time, so the choice cannot disagree with what boots.
//!
//! 4. sets `cfg(monitor)` when the embedded image carries the task's monitor (section 14,
//!    `shared_types::monitor`), or when `CONTROLLER_MONITOR=1`, and writes the words of its arena
//!    (`MONITOR_WORDS`, from the image's program); without it the monitor's evaluator is not linked.
//!
//! 5. sets `cfg(pwa)` when the embedded image's header says PWA feedback (Ch. 6), or when
//!    `CONTROLLER_PWA=1` (the no-panic check); without it the decoder refuses a PWA image and the loop
//!    steps with `step_for::<false>`, so the PWA tables' validation and point location take no flash.
//!
//! Each board's own build script places its memory map (`memory.x`).
//!
//! The default image is generated rather than committed so that it always matches the current image format
//! (a committed file would silently go stale when `FORMAT_VERSION` changes).
#![allow(non_snake_case)]

use shared_types::capacity::{MAX_IMAGE_LEN, MAX_M};
use shared_types::image::{self, Dims, Fallback, Header, Image, Mode, Payload, Segment, Terminal};
use std::path::{Path, PathBuf};

fn main() {
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"));

    // Relative image paths are taken from the firmware workspace's root (this crate's parent), as before
    // the boards moved into their own folders.
    let firmware_root = manifest.join("..");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=CONTROLLER_IMAGE");
    println!("cargo:rerun-if-env-changed=CONTROLLER_REJECTED_M");
    println!("cargo:rerun-if-env-changed=CONTROLLER_MODEL_MAPS");
    println!("cargo::rustc-check-cfg=cfg(model_maps)");
    println!("cargo:rerun-if-env-changed=CONTROLLER_MONITOR");
    println!("cargo::rustc-check-cfg=cfg(monitor)");
    println!("cargo:rerun-if-env-changed=CONTROLLER_PWA");
    println!("cargo::rustc-check-cfg=cfg(pwa)");

    let bytes = match std::env::var_os("CONTROLLER_IMAGE") {
        Some(p) => {
            let path = firmware_root.join(Path::new(&p));
            println!("cargo:rerun-if-changed={}", path.display());
            std::fs::read(&path)
                .unwrap_or_else(|e| panic!("CONTROLLER_IMAGE={}: {e}", path.display()))
        }
        None => default_image(),
    };
    // The image region is sized by the capacities; a larger file cannot be a valid image, but it is still
    // embedded as given so that the firmware's own check refuses it at boot (and says so).
    if bytes.len() > MAX_IMAGE_LEN {
        println!(
            "cargo:warning=controller image is {} bytes, more than MAX_IMAGE_LEN = {MAX_IMAGE_LEN}",
            bytes.len()
        );
    }
    std::fs::write(out.join("image.bin"), &bytes).expect("write image.bin");

    let has_maps = image::decode(&bytes).is_ok_and(|img| img.model_maps().is_some());
    let forced = std::env::var("CONTROLLER_MODEL_MAPS").is_ok_and(|v| v.trim() == "1");
    if has_maps || forced {
        println!("cargo:rustc-cfg=model_maps");
    }

    // The task's monitor: linked only when the image carries one (or CONTROLLER_MONITOR=1, for the
    // no-panic check), with its arena sized by the image's program.
    let monitor_words = image::decode(&bytes)
        .ok()
        .and_then(|img| img.monitor())
        .map(|p| p.words());
    let force_monitor = std::env::var("CONTROLLER_MONITOR").is_ok_and(|v| v.trim() == "1");
    if monitor_words.is_some() || force_monitor {
        println!("cargo:rustc-cfg=monitor");
    }
    let monitor_words = monitor_words.unwrap_or(0);

    // PWA feedback: read from the header, so that an image refused for anything else is still refused
    // for that reason at boot.
    let is_pwa = Header::parse(&bytes).is_ok_and(|h| h.mode == Mode::PwaFeedback as u8);
    let force_pwa = std::env::var("CONTROLLER_PWA").is_ok_and(|v| v.trim() == "1");
    if is_pwa || force_pwa {
        println!("cargo:rustc-cfg=pwa");
    }

    let rejected_m = match std::env::var("CONTROLLER_REJECTED_M") {
        Ok(s) => s
            .trim()
            .parse::<usize>()
            .unwrap_or_else(|e| panic!("CONTROLLER_REJECTED_M={s:?}: {e}")),
        Err(_) => image::decode(&bytes)
            .map(|img| img.plant_m())
            .or_else(|_| Header::parse(&bytes).map(|h| h.dims.m))
            .unwrap_or(0),
    }
    .min(MAX_M);
    std::fs::write(
        out.join("build_config.rs"),
        format!(
            "/// Input dimension of the zero input applied when the image is rejected (set by build.rs).\n\
             pub const REJECTED_M: usize = {rejected_m};\n\
             /// Words of the monitor's arena (0 without a monitor; set by build.rs).\n\
             #[allow(dead_code)]\n\
             pub const MONITOR_WORDS: usize = {monitor_words};\n"
        ),
    )
    .expect("write build_config.rs");
}

fn f32_bytes(xs: &[f32]) -> Vec<u8> {
    xs.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// The default test image: the double integrator `ẍ = u` sampled at h = 0.1 s, under the gain
/// `K = [-4, -3.8]`, which places both closed-loop poles of the zero-order-hold model
/// (`Ad = [[1, h], [0, 1]]`, `Bd = [h²/2, h]`) at 0.8. One trajectory: the ball of radius 10 (metric `P = I`)
/// around the origin, with a one-row table `v = 0` held past its end, so `u = K x` throughout; the fallback
/// is zero input.
fn default_image() -> Vec<u8> {
    let K = f32_bytes(&[-4.0, -3.8]);
    let P = f32_bytes(&[1.0, 0.0, 0.0, 1.0]);
    let seg_end = 1u16.to_le_bytes();
    let centre = f32_bytes(&[0.0, 0.0]);
    let delta = f32_bytes(&[10.0]);
    let v = f32_bytes(&[0.0]);
    let segment = Segment {
        location: 0,
        first_row: 0,
        len: 1,
    }
    .record()
    .expect("segment fits its record");
    let payload = Payload {
        K: &K,
        P: &P,
        seg_end: &seg_end,
        centre: &centre,
        delta: &delta,
        segment: &segment,
        v: &v,
        fallback: Fallback::Zero,
        input_box: None,
        terminal: Terminal::HoldLast,
        exits: &[],
    };
    let dims = Dims {
        n: 2,
        m: 1,
        n_locations: 1,
        n_trajectories: 1,
        n_partitions: 0,
    };
    let img = Image::new(Mode::Feedforward, dims, 0.1, payload).expect("default image is valid");
    let mut buf = vec![0u8; MAX_IMAGE_LEN];
    let len = image::encode(&img, &mut buf).expect("default image encodes");
    buf.truncate(len);
    buf
}

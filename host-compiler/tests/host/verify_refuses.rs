//! `verify` and `simulate` refuse what they cannot vouch for (issue 18), with the documented exit status:
//! an image whose ball radius was enlarged (CRC recomputed) is refused naming the trajectory (1), one
//! whose sample period or dimensions differ from the spec's is refused saying both values (2), a run
//! that would check nothing is refused (2), a missing image file is named (2). The untouched image
//! passes, with its radii re-proved from the bytes.

use host_compiler::synth::{synthesize, SynthOptions};
use host_compiler::task::Task;
use shared_types::image::{compute_crc, decode};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host-compiler"))
}

pub(crate) fn spec() -> &'static str {
    concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/double-integrator.toml"
    )
}

fn dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("hc-verify-refuses-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The double-integrator image, synthesised once for the module.
pub(crate) fn image() -> &'static [u8] {
    static IMAGE: OnceLock<Vec<u8>> = OnceLock::new();
    IMAGE.get_or_init(|| {
        let task = Task::new(host_compiler::spec::load(spec()).unwrap()).unwrap();
        let opts = SynthOptions {
            verify_interior: 200,
            verify_per_ball: 4,
            progress: false,
            ..SynthOptions::default()
        };
        synthesize(&task, &opts).unwrap().image
    })
}

/// Writes `bytes` with its CRC recomputed (as an attacker would) under `name`.
pub(crate) fn write_patched(name: &str, mut bytes: Vec<u8>) -> PathBuf {
    let crc = compute_crc(&bytes).unwrap();
    bytes[28..32].copy_from_slice(&crc.to_le_bytes());
    decode(&bytes).expect("the patched image still decodes");
    let p = dir().join(name);
    std::fs::write(&p, &bytes).unwrap();
    p
}

/// `verify` with `flags`, or a short Monte Carlo when none are given.
pub(crate) fn verify(img: &Path, flags: &[&str]) -> Output {
    let flags = if flags.is_empty() {
        &["--runs", "200", "--per-ball", "4"][..]
    } else {
        flags
    };
    bin()
        .args(["verify", spec()])
        .arg(img)
        .args(flags)
        .output()
        .unwrap()
}

/// Standard output and error as one line of words (miette wraps and frames long messages).
pub(crate) fn text(o: &Output) -> String {
    let all = format!(
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    all.replace('│', " ")
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
}

#[test]
fn the_untouched_image_passes_with_its_radii_reproved() {
    let p = write_patched("ok.img", image().to_vec());
    let o = verify(&p, &[]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(0), "{t}");
    assert!(t.contains("radii re-proved from the bytes"), "{t}");
    assert!(t.contains(" 0 failing"), "{t}");
    assert!(
        !t.contains("inf"),
        "no infinite margin is printed as a result: {t}"
    );
}

#[test]
fn an_enlarged_ball_radius_is_refused_naming_the_trajectory() {
    let bytes = image().to_vec();
    let img = decode(&bytes).unwrap();
    assert!(img.n_trajectories() >= 1);
    // The radius of trajectory 0, located in the bytes, multiplied by 3.
    let t = img.n_trajectories() - 1;
    let at = img.payload().delta.as_ptr() as usize - bytes.as_ptr() as usize + 4 * t;
    let d = f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
    assert!(d > 0.0);
    let mut patched = bytes.clone();
    patched[at..at + 4].copy_from_slice(&(3.0 * d).to_le_bytes());
    let p = write_patched("radius-x3.img", patched);
    let o = verify(&p, &[]);
    let out = text(&o);
    assert_eq!(o.status.code(), Some(1), "{out}");
    assert!(
        out.contains(&format!("trajectory {t}: the stored radius")),
        "{out}"
    );
    assert!(
        out.contains("not certified by the image's own bytes"),
        "{out}"
    );
}

#[test]
fn another_sample_period_is_refused_by_verify_and_simulate_saying_both() {
    let mut bytes = image().to_vec();
    bytes[20..24].copy_from_slice(&0.3f32.to_le_bytes());
    let p = write_patched("period.img", bytes);
    let o = verify(&p, &[]);
    let out = text(&o);
    assert_eq!(o.status.code(), Some(2), "{out}");
    assert!(
        out.contains("sample period is 0.3 s") && out.contains("plant.period is 0.1 s"),
        "{out}"
    );
    let o = bin()
        .args(["simulate", spec()])
        .arg(&p)
        .args(["--x0", "0,0"])
        .output()
        .unwrap();
    let out = text(&o);
    assert_eq!(o.status.code(), Some(2), "{out}");
    assert!(out.contains("sample period is 0.3 s"), "{out}");
}

#[test]
fn other_dimensions_are_refused_saying_both() {
    // The planar vehicle's spec (n = 4, m = 2) against the double integrator's image (n = 2, m = 1).
    let p = write_patched("dims.img", image().to_vec());
    let planar = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/planar-vehicle.toml"
    );
    let o = bin()
        .args(["verify", planar])
        .arg(&p)
        .args(["--runs", "10"])
        .output()
        .unwrap();
    let out = text(&o);
    assert_eq!(o.status.code(), Some(2), "{out}");
    assert!(
        out.contains("n = 2 states") && out.contains("n = 4"),
        "{out}"
    );
}

#[test]
fn a_run_that_checks_nothing_is_refused() {
    let p = write_patched("nothing.img", image().to_vec());
    let o = verify(&p, &["--runs", "0", "--per-ball", "0"]);
    let out = text(&o);
    assert_eq!(o.status.code(), Some(2), "{out}");
    assert!(out.contains("no closed-loop run would be checked"), "{out}");
    assert!(!out.contains("violations 0"), "{out}");
}

#[test]
fn a_missing_image_file_is_named() {
    let p = dir().join("no-such.img");
    let o = verify(&p, &[]);
    let out = text(&o);
    assert_eq!(o.status.code(), Some(2), "{out}");
    assert!(out.contains("no-such.img"), "{out}");
}

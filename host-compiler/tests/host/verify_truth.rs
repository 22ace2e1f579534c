//! Issue 42 ("Truth, round three"), items 1, 2 and 9: `verify` re-derives the stored values no re-proof
//! reads from the spec (a flat plant's ζ0, the input box), refuses a Monte Carlo whose starts the image
//! refuses although its certificate covers them, estimates the image's coverage of the *spec's* Init
//! (exit 3 when short of the target, whatever fingerprint the image carries), and accepts a stored
//! radius only within (n + 2) uκ of the recomputed one.

use crate::verify_refuses::{image, spec, text, verify, write_patched};
use host_compiler::task::Task;
use host_compiler::verify::{feedforward, Judge};
use shared_types::image::decode;

/// The byte offset of `v` (as f32) inside the section of `body` within `bytes`; it must occur once.
fn f32_offset(bytes: &[u8], body: &[u8], v: f32) -> usize {
    let base = body.as_ptr() as usize - bytes.as_ptr() as usize;
    let hits: Vec<usize> = (0..body.len().saturating_sub(3))
        .step_by(4)
        .filter(|&i| body[i..i + 4] == v.to_le_bytes())
        .collect();
    assert_eq!(hits.len(), 1, "{v} occurs {} times", hits.len());
    base + hits[0]
}

#[test]
fn a_changed_input_box_is_refused_naming_it() {
    // The double integrator's input box [-1, 1] stored as [-2, 2]: the evaluator reads it only under a
    // linear fallback, but it is a stored value the spec gives, so it must be the spec's.
    let bytes = image().to_vec();
    let img = decode(&bytes).unwrap();
    let b = img
        .payload()
        .input_box
        .expect("the spec's input set is a box");
    let (lo, hi) = (b.lo.as_ptr() as usize, b.hi.as_ptr() as usize);
    let base = bytes.as_ptr() as usize;
    let mut patched = bytes.clone();
    patched[lo - base..lo - base + 4].copy_from_slice(&(-2.0f32).to_le_bytes());
    patched[hi - base..hi - base + 4].copy_from_slice(&2.0f32.to_le_bytes());
    let p = write_patched("input-box.img", patched);
    let o = verify(&p, &[]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(t.contains("input box is not the one the spec gives"), "{t}");
}

#[test]
fn a_wider_specs_fingerprint_does_not_make_its_init_covered() {
    // The image covers x1 ∈ [−0.1, 0.1]; a spec with x1 ∈ [−0.5, 0.5], whose fingerprint the image is
    // given, is covered on about a fifth of its Init: exit 3, the estimate printed and in the JSON.
    let wide_src = std::fs::read_to_string(spec())
        .unwrap()
        .replace("lo = [-0.1, 0.0]", "lo = [-0.5, 0.0]")
        .replace("hi = [ 0.1, 0.0]", "hi = [ 0.5, 0.0]");
    let dir = std::env::temp_dir().join(format!("hc-verify-truth-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let wide = dir.join("wide.toml");
    std::fs::write(&wide, &wide_src).unwrap();
    let problem = host_compiler::spec::load(&wide).unwrap();
    let mut b = host_compiler::emit::ImageBuilder::from_image(&decode(image()).unwrap());
    b.fingerprint = Some(problem.fingerprint.as_bytes().to_vec());
    let p = write_patched("wide-fingerprint.img", b.to_bytes().unwrap());
    let run = |json: bool| {
        let mut c = std::process::Command::new(env!("CARGO_BIN_EXE_host-compiler"));
        c.args(["verify", wide.to_str().unwrap(), p.to_str().unwrap()])
            .args(["--runs", "100", "--per-ball", "4"]);
        if json {
            c.arg("--json");
        }
        c.output().unwrap()
    };
    let o = run(false);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(3), "{t}");
    assert!(t.contains("coverage target NOT met"), "{t}");
    assert!(t.contains("coverage of the spec's Init 0."), "{t}");
    let o = run(true);
    assert_eq!(o.status.code(), Some(3));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let mean = j["coverage"]["mean"].as_f64().unwrap();
    assert!((0.15..0.3).contains(&mean), "{j}");
    assert_eq!(j["coverage"]["met"], false);
    // Against its own spec the same image covers Init: exit 0, the coverage met.
    let o = verify(&write_patched("own.img", image().to_vec()), &[]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(0), "{t}");
    assert!(t.contains(", met)"), "{t}");
}

#[test]
fn a_radius_enlarged_by_more_than_the_selection_slack_is_not_reproved() {
    // The recomputed radius times 1 + 10uκ: within the former 16uκ, beyond (n + 2)uκ = 4uκ (n = 2).
    let task = Task::new(host_compiler::spec::load(spec()).unwrap()).unwrap();
    let judge = Judge::new(&task);
    let bytes = image().to_vec();
    let img = decode(&bytes).unwrap();
    let rc = feedforward::recheck(&judge, &img).unwrap();
    assert_eq!(rc.failures, 0);
    let n = img.n() as f64;
    let u = f64::powi(2.0, -24);
    let kappa = rc.tolerance / ((n + 2.0) * u);
    let t = 0;
    let target = rc.trajectories[t].certified as f64 * (1.0 + 10.0 * u * kappa);
    let enlarged = target as f32;
    assert!(enlarged as f64 > rc.trajectories[t].certified as f64 * (1.0 + rc.tolerance));
    assert!((enlarged as f64) < rc.trajectories[t].certified as f64 * (1.0 + 16.0 * u * kappa));
    let at = img.payload().delta.as_ptr() as usize - bytes.as_ptr() as usize + 4 * t;
    let mut patched = bytes.clone();
    patched[at..at + 4].copy_from_slice(&enlarged.to_le_bytes());
    let p = write_patched("radius-10ukappa.img", patched);
    let rc = feedforward::recheck(&judge, &decode(&std::fs::read(&p).unwrap()).unwrap()).unwrap();
    assert_eq!(rc.failures, 1, "{:?}", rc.trajectories[t]);
    let o = verify(&p, &[]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
}

/// The flat quadrotor from one state (as `cli_flat`), its stored initial thrust ζ0 changed from 9.81 to
/// 14.7 with the CRC recomputed: refused by the stored-values check (exit 1, naming ζ0), and its Monte
/// Carlo counts the starts the evaluator refuses although the certificate covers them. About a minute on
/// two cores (its one-trajectory synthesis): the flat quadrotor is the only example whose image stores
/// controller states ζ0.
#[test]
fn a_flat_images_changed_initial_thrust_is_refused() {
    let (_, spec_path, img_path) = crate::cli_flat::one_state();
    let bytes = std::fs::read(&img_path).unwrap();
    let img = decode(&bytes).unwrap();
    let maps = img.model_maps().expect("model maps");
    let at = f32_offset(&bytes, maps.body(), 9.81f32);
    let mut patched = bytes.clone();
    patched[at..at + 4].copy_from_slice(&14.7f32.to_le_bytes());
    let p = write_patched("flat-thrust.img", patched);
    let patched = std::fs::read(&p).unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_host-compiler"))
        .args(["verify", spec_path.to_str().unwrap(), p.to_str().unwrap()])
        .args(["--runs", "100", "--per-ball", "8"])
        .output()
        .unwrap();
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(t.contains("ζ0"), "{t}");
    // The Monte Carlo on its own: the spec's ζ0 puts the starts in the ball, the image's refuses them.
    let task = Task::new(host_compiler::spec::load(&spec_path).unwrap()).unwrap();
    let tampered = decode(&patched).unwrap();
    let r = host_compiler::verify::nonlinear::monte_carlo_fl(&task, &tampered, 20, 8, 5).unwrap();
    assert!(r.refused > 0, "{r:?}");
    let r = host_compiler::verify::nonlinear::monte_carlo_fl(&task, &img, 20, 8, 5).unwrap();
    assert_eq!(r.refused, 0, "{r:?}");
    assert_eq!(r.violations, 0, "{r:?}");
}

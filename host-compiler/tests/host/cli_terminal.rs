//! The terminal law from the command line (issue 17, item 2): `synth` on the double integrator stores a
//! certified law (section 11) and its runs, to 2T, stay in Goal; `verify` re-proves it from the bytes and
//! refuses an image whose ellipsoid was enlarged (exit 1, naming the condition); `[synthesis] terminal`
//! chooses: `"invariant"` on a plant without one is bad input before any growth (exit 2, with the
//! figure), `"hold"` stores none, an unknown value is a spec diagnostic.

use crate::spec_fingerprint::text;
use host_compiler::emit::ImageBuilder;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host-compiler"))
}

fn example(name: &str) -> String {
    std::fs::read_to_string(format!("{}/../examples/{name}", env!("CARGO_MANIFEST_DIR"))).unwrap()
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hc-cli-terminal-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn synth(spec: &Path, out: &Path) -> Output {
    bin()
        .args(["synth", spec.to_str().unwrap(), "--out"])
        .arg(out)
        .args(["--verify-runs", "300", "--quiet"])
        .output()
        .unwrap()
}

fn verify(spec: &Path, img: &Path) -> Output {
    bin()
        .args(["verify", spec.to_str().unwrap(), img.to_str().unwrap()])
        .args(["--runs", "300", "--per-ball", "4"])
        .output()
        .unwrap()
}

#[test]
fn the_double_integrator_hands_over_and_verify_re_proves_the_law() {
    let dir = scratch("di");
    let spec = dir.join("spec.toml");
    std::fs::write(&spec, example("double-integrator.toml")).unwrap();
    let out = dir.join("out");
    let o = synth(&spec, &out);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(0), "{t}");
    assert!(t.contains("terminal law certified at x_e"), "{t}");
    // Every accepted run is handed over and none leaves Goal before 2T.
    assert!(
        t.contains(
            "after Goal judged over runs of 80 samples: 0 runs left Goal, 0 entered Unsafe, 0 left the \
             input set, 0 were not handed over within the horizon (each a violation)"
        ),
        "{t}"
    );
    let cert: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("certificate.json")).unwrap())
            .unwrap();
    assert_eq!(cert["terminal"]["law"], "invariant", "{cert}");
    // The report shows the law and draws its ellipsoid in the workspace plot.
    let report = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(report.contains("<h2>After the task: terminal law</h2>"));
    assert!(report.contains("terminal law&#39;s invariant ellipsoid"));
    assert!(report
        .contains("0 not handed over within the horizon, 0 outside Goal again after reaching it."));
    let img = out.join("controller.img");
    let bytes = std::fs::read(&img).unwrap();
    let decoded = shared_types::image::decode(&bytes).unwrap();
    assert!(decoded.terminal_law().is_some());

    let o = verify(&spec, &img);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(0), "{t}");
    assert!(t.contains("terminal law re-proved from the bytes"), "{t}");
    assert!(t.contains("violations 0"), "{t}");

    // The ellipsoid enlarged (P_t / 4: twice the radius), the CRC and everything else valid: the bytes
    // no longer certify it.
    let mut b = ImageBuilder::from_image(&decoded);
    let law = b.terminal_law.as_mut().unwrap();
    law.P = faer::Mat::from_fn(law.P.nrows(), law.P.ncols(), |i, j| law.P[(i, j)] / 4.0);
    let tampered = dir.join("tampered.img");
    std::fs::write(&tampered, b.to_bytes().unwrap()).unwrap();
    let o = verify(&spec, &tampered);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(
        t.contains("the terminal law is not certified by the image's own bytes: inputs of the terminal law leave the input set"),
        "{t}"
    );
}

#[test]
fn terminal_invariant_without_an_equilibrium_in_goal_is_bad_input() {
    let dir = scratch("pv");
    let spec = dir.join("spec.toml");
    let text_spec = example("planar-vehicle.toml")
        .replace("[synthesis]", "[synthesis]\nterminal = \"invariant\"");
    assert!(text_spec.contains("terminal = \"invariant\""));
    std::fs::write(&spec, text_spec).unwrap();
    let out = dir.join("out");
    let o = synth(&spec, &out);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(2), "{t}");
    assert!(
        t.contains("needs an input 0.3142 outside the input set"),
        "{t}"
    );
    assert!(!out.join("controller.img").exists());
}

#[test]
fn terminal_hold_stores_no_law_and_an_unknown_value_is_a_spec_error() {
    let dir = scratch("hold");
    let spec = dir.join("spec.toml");
    std::fs::write(
        &spec,
        format!(
            "{}\n[synthesis]\nterminal = \"hold\"\n",
            example("double-integrator.toml")
        ),
    )
    .unwrap();
    let out = dir.join("out");
    let o = synth(&spec, &out);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(0), "{t}");
    assert!(
        t.contains("terminal law none (the spec's [synthesis] terminal)"),
        "{t}"
    );
    let bytes = std::fs::read(out.join("controller.img")).unwrap();
    assert!(shared_types::image::decode(&bytes)
        .unwrap()
        .terminal_law()
        .is_none());
    let report = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(report.contains("No terminal law: the spec&#39;s [synthesis] terminal asks for none"));

    std::fs::write(
        &spec,
        format!(
            "{}\n[synthesis]\nterminal = \"forever\"\n",
            example("double-integrator.toml")
        ),
    )
    .unwrap();
    let o = synth(&spec, &dir.join("out2"));
    let t = text(&o);
    assert_eq!(o.status.code(), Some(2), "{t}");
    assert!(
        t.contains("synthesis.terminal = \"forever\" is unknown"),
        "{t}"
    );
}

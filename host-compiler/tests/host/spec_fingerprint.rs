//! The spec fingerprint an image stores (issue 18): its parts are unchanged by comments, whitespace, key
//! order and the spelling of numbers and change with any value; `verify` and `simulate` refuse an image
//! whose spec changed since synthesis (exit 2) naming each part, accept one without a fingerprint with a
//! warning; the builders round-trip the section; `inspect` shows it. [`assert_stamped`] is called by the
//! PWA, hybrid and MTL CLI tests on the images their `synth` writes; [`without_fingerprint`] gives the MTL
//! and feedback-linearizable CLI tests an image for the re-proof alone.

use crate::cli_exit::{base, bin, scratch};
use host_compiler::emit::{ImageBuilder, PwaImageBuilder};
use host_compiler::spec::SpecFingerprint;
use shared_types::image::{decode, SPEC_PARTS};
use std::path::Path;
use std::process::Output;

fn fp(src: &str) -> SpecFingerprint {
    SpecFingerprint::of(src).unwrap()
}

/// The image at `img` stores the fingerprint of the spec file at `spec`.
pub(crate) fn assert_stamped(img: &Path, spec: &Path) {
    let bytes = std::fs::read(img).unwrap();
    let image = decode(&bytes).unwrap();
    let want = fp(&std::fs::read_to_string(spec).unwrap());
    assert_eq!(
        image.fingerprint(),
        Some(want.as_bytes()),
        "{} does not store the fingerprint of {}",
        img.display(),
        spec.display()
    );
}

/// A copy of the feedforward image at `img` without its fingerprint, written as `bare.img` beside it
/// (what an image from before the fingerprint looks like: checked by the re-proof alone).
pub(crate) fn without_fingerprint(img: &Path) -> std::path::PathBuf {
    let bytes = std::fs::read(img).unwrap();
    let mut b = ImageBuilder::from_image(&decode(&bytes).unwrap());
    b.fingerprint = None;
    let bare = img.with_file_name("bare.img");
    std::fs::write(&bare, b.to_bytes().unwrap()).unwrap();
    bare
}

#[test]
fn comments_whitespace_key_order_and_number_spelling_do_not_change_it() {
    let src = base();
    let a = fp(&src);
    // Comments stripped, blank lines and indentation added, a BOM in front.
    let stripped: String = src
        .lines()
        .filter(|l| !l.trim_start().starts_with('#'))
        .map(|l| format!("  {l}   \n\n"))
        .collect();
    assert_eq!(fp(&stripped), a);
    assert_eq!(fp(&format!("\u{feff}# a new comment\n{src}")), a);
    // Keys of a table in another order, and a number spelled differently.
    let toml: toml::Table = toml::from_str(&src).unwrap();
    let reordered: String = {
        let mut keys: Vec<&String> = toml.keys().collect();
        keys.reverse();
        let mut t = toml::Table::new();
        for k in keys {
            t.insert(k.clone(), toml[k].clone());
        }
        toml::to_string(&t).unwrap()
    };
    assert_eq!(fp(&reordered), a);
    let h = toml["horizon"].as_float().unwrap();
    let respelled = src.replacen(
        &format!("horizon = {}", toml_number(&src, "horizon")),
        &format!("horizon = {h:e}"),
        1,
    );
    assert_ne!(respelled, src);
    assert_eq!(fp(&respelled), a);
}

/// The text of the top-level `key = …` value in `src`.
fn toml_number(src: &str, key: &str) -> String {
    let line = src
        .lines()
        .find(|l| l.starts_with(&format!("{key} =")))
        .unwrap();
    line.split('=')
        .nth(1)
        .unwrap()
        .split('#')
        .next()
        .unwrap()
        .trim()
        .to_string()
}

#[test]
fn each_changed_part_is_named() {
    let src = base();
    let a = fp(&src);
    let cases: [(&str, String, &[&str]); 5] = [
        (
            "goal",
            src.replacen("lo = [0.95]", "lo = [0.96]", 1),
            &["[goal]"],
        ),
        (
            "horizon",
            src.replacen(
                &format!("horizon = {}", toml_number(&src, "horizon")),
                "horizon = 7.25",
                1,
            ),
            &["horizon"],
        ),
        (
            "seed",
            src.replacen(
                &format!("seed = {}", toml_number(&src, "seed")),
                "seed = 424242",
                1,
            ),
            &["[synthesis] with seed"],
        ),
        (
            "name",
            format!("name = \"renamed\"\n{}", drop_key(&src, "name")),
            &["other top-level keys"],
        ),
        (
            "mtl",
            format!("{src}\n[mtl]\nformula = \"F[0, 1] Goal\"\n"),
            &["[mtl] with [sets]"],
        ),
    ];
    for (what, changed_src, parts) in cases {
        let b = fp(&changed_src);
        let mut want: Vec<&str> = parts.to_vec();
        want.push("spec");
        assert_eq!(b.changed(&a), want, "{what}");
        assert_eq!(a.changed(&b), want, "{what}");
    }
    assert!(a.changed(&a).is_empty());
    assert_eq!(SPEC_PARTS.last(), Some(&"spec"));
}

fn drop_key(src: &str, key: &str) -> String {
    src.lines()
        .filter(|l| !l.starts_with(&format!("{key} =")))
        .map(|l| format!("{l}\n"))
        .collect()
}

#[test]
fn builders_round_trip_the_fingerprint_byte_identically() {
    let f = fp(&base());
    let mut b = ImageBuilder::new(2, 1, 0.1);
    b.add_location(vec![-1.0, -1.5], vec![2.0, 0.5, 0.5, 1.0]);
    b.add_nominal_trajectory(&[0.0, 0.0, 0.1, 0.0], &[0.5, 0.25], &[0, 0], 0.3)
        .unwrap();
    let plain = b.to_bytes().unwrap();
    assert_eq!(decode(&plain).unwrap().fingerprint(), None);
    b.fingerprint = Some(f.as_bytes().to_vec());
    let bytes = b.to_bytes().unwrap();
    let img = decode(&bytes).unwrap();
    assert_eq!(img.fingerprint(), Some(f.as_bytes()));
    let back = ImageBuilder::from_image(&img);
    assert_eq!(back.fingerprint.as_deref(), Some(f.as_bytes()));
    assert_eq!(back.to_bytes().unwrap(), bytes);
    // A fingerprint of the wrong length is refused, not truncated.
    b.fingerprint = Some(vec![1; 7]);
    assert!(b.to_bytes().is_err());
    // PWA: from the cover's feedforward image through a one-ball law, read back and rebuilt.
    let mut p = PwaImageBuilder::new(2, 1, 0.1);
    p.add_location(vec![-1.0, -1.5], vec![2.0, 0.5, 0.5, 1.0]);
    p.add_law(host_compiler::emit::PwaLaw {
        gain: vec![-1.0, -1.5],
        offset: vec![0.0],
    });
    p.add_leaf(host_compiler::emit::PwaLeaf {
        partition: 0,
        balls: vec![0],
    });
    p.add_ball(host_compiler::emit::CertifiedBall {
        centre: vec![0.0, 0.0],
        threshold: 0.25,
        location: 0,
        partition: 0,
    });
    p.fingerprint = Some(f.as_bytes().to_vec());
    let bytes = p.to_bytes().unwrap();
    let img = decode(&bytes).unwrap();
    assert_eq!(img.fingerprint(), Some(f.as_bytes()));
    let back = PwaImageBuilder::from_image(&img).unwrap();
    assert_eq!(back.to_bytes().unwrap(), bytes);
}

fn run(args: &[&str], spec: &Path, img: &Path, extra: &[&str]) -> Output {
    bin()
        .args(args)
        .arg(spec)
        .arg(img)
        .args(extra)
        .output()
        .unwrap()
}

/// Standard output and error, with miette's line wrapping undone (frame characters dropped, runs of
/// whitespace made one space). Shared with the other CLI tests that match wrapped messages.
pub(crate) fn text(o: &Output) -> String {
    let raw = format!(
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    raw.replace(['│', '×'], " ")
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
}

/// One synthesis of the double integrator; then `verify` and `simulate` against the spec as written,
/// reformatted, with its goal or goal and horizon changed, and against an image without a fingerprint.
#[test]
fn verify_and_simulate_refuse_an_image_whose_spec_changed() {
    let dir = scratch("fingerprint");
    let spec = dir.join("spec.toml");
    let src = base();
    std::fs::write(&spec, &src).unwrap();
    let out = dir.join("out");
    let o = bin()
        .arg("synth")
        .arg(&spec)
        .arg("--out")
        .arg(&out)
        .args(["--quiet", "--verify-runs", "100"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let img = out.join("controller.img");
    assert_stamped(&img, &spec);
    let verify = ["verify"];
    let few = ["--runs", "50", "--per-ball", "2"];
    let x0 = ["--x0", "0.05,0", "--steps", "5"];

    // Reformatted: accepted, with no warning.
    let same = dir.join("same.toml");
    std::fs::write(
        &same,
        format!("# reformatted\n\n{}", src.replace(" = ", "   =   ")),
    )
    .unwrap();
    let o = run(&verify, &same, &img, &few);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(!text(&o).contains("fingerprint"), "{}", text(&o));

    // The goal changed: refused as bad input, naming [goal] and nothing else.
    let goal = dir.join("goal.toml");
    std::fs::write(&goal, src.replacen("lo = [0.95]", "lo = [0.96]", 1)).unwrap();
    for (args, extra) in [(&verify[..], &few[..]), (&["simulate"][..], &x0[..])] {
        let o = run(args, &goal, &img, extra);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {t}");
        assert!(
            t.contains("the spec's [goal] changed since this image was synthesised"),
            "{args:?}: {t}"
        );
        assert!(!t.contains("horizon") && !t.contains("[plant]"), "{t}");
    }
    // Goal and horizon: both named.
    let both = dir.join("both.toml");
    std::fs::write(
        &both,
        src.replacen("lo = [0.95]", "lo = [0.96]", 1).replacen(
            &format!("horizon = {}", toml_number(&src, "horizon")),
            "horizon = 7.25",
            1,
        ),
    )
    .unwrap();
    let o = run(&verify, &both, &img, &few);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        text(&o).contains("the spec's [goal] and horizon changed"),
        "{}",
        text(&o)
    );

    // An image without the section (as written before it existed): accepted, with a warning.
    let bytes = std::fs::read(&img).unwrap();
    let mut b = ImageBuilder::from_image(&decode(&bytes).unwrap());
    b.fingerprint = None;
    let old = dir.join("old.img");
    std::fs::write(&old, b.to_bytes().unwrap()).unwrap();
    for (args, extra) in [(&verify[..], &few[..]), (&["simulate"][..], &x0[..])] {
        let o = run(args, &spec, &old, extra);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(0), "{args:?}: {t}");
        assert!(
            t.contains("warning:") && t.contains("stores no spec fingerprint"),
            "{t}"
        );
    }

    // inspect shows it, as text and as JSON.
    let o = bin().arg("inspect").arg(&img).output().unwrap();
    let t = text(&o);
    assert!(
        t.contains("spec_fingerprint") && t.contains("[goal]"),
        "{t}"
    );
    let o = bin()
        .arg("inspect")
        .arg(&img)
        .arg("--json")
        .output()
        .unwrap();
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let parts = j["spec_fingerprint"].as_array().unwrap();
    assert_eq!(parts.len(), SPEC_PARTS.len());
    let f = fp(&src);
    assert_eq!(parts[2]["part"], "[goal]");
    assert_eq!(parts[2]["hash"], f.hex(2));
    let o = bin()
        .arg("inspect")
        .arg(&old)
        .arg("--json")
        .output()
        .unwrap();
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(j["spec_fingerprint"].is_null());
    let _ = std::fs::remove_dir_all(&dir);
}

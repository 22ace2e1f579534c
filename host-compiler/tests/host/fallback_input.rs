//! The fallback input (issue 18): a point of the input set, chosen by the spec (`input.fallback`,
//! validated with its line and column) or the input set's point nearest 0, stored in the image as f32
//! values still in the set, and applied by the shared evaluator whatever the state.
#![allow(non_snake_case)]

use host_compiler::emit::{FallbackLaw, ImageBuilder, TrajectoryEntry};
use host_compiler::spec::{self, ErrorKind, InputSet};
use shared_types::eval::Controller;
use shared_types::image::{decode, Fallback, ImageError};

use crate::spec_bounds::{edit, refused, BASE};

#[test]
fn the_fallback_input_defaults_to_the_input_sets_point_nearest_zero() {
    // 0 admissible: the fallback is 0 (the shipped examples' images are unchanged).
    assert_eq!(spec::parse(BASE, "s").unwrap().fallback_input, vec![0.0]);
    // A box excluding 0: 0 clamped, stored as an f32 inside the box.
    let p = spec::parse(&edit("lo = [-1.0]", "lo = [0.05]"), "s").unwrap();
    let u = &p.fallback_input;
    assert!(p.input.contains(u), "{u:?}");
    assert_eq!(u[0] as f32 as f64, u[0]);
    assert!((u[0] - 0.05).abs() < 1e-7, "{u:?}");
    // A ball excluding 0: 0 projected onto it.
    let src = edit(
        "kind = \"box\"\nlo = [-1.0]\nhi = [1.0]",
        "kind = \"ball\"\ncenter = [3.0]\nradius = 1.0",
    );
    let p = spec::parse(&src, "s").unwrap();
    assert!(p.input.contains(&p.fallback_input));
    assert!(
        (p.fallback_input[0] - 2.0).abs() < 1e-5,
        "{:?}",
        p.fallback_input
    );
    // Rounding to f32 never leaves the set: a face whose f32 lies outside is approached from inside.
    let b = InputSet::Box {
        lo: vec![0.1],
        hi: vec![0.3],
    };
    assert!((0.3f32 as f64) > 0.3, "test premise: 0.3 rounds up in f32");
    let s = b.storable(&[0.3]);
    assert!(b.contains(&s) && s[0] as f32 as f64 == s[0], "{s:?}");
}

#[test]
fn the_spec_may_choose_the_fallback_input_within_the_input_set() {
    let p = spec::parse(&edit("hi = [1.0]", "hi = [1.0]\nfallback = [0.5]"), "s").unwrap();
    assert_eq!(p.fallback_input, vec![0.5]);
    let src = edit("hi = [1.0]", "hi = [1.0]\nfallback = [2.0]");
    let msg = refused(&src, ErrorKind::BadValue, "[2.0]");
    assert!(
        msg.contains("input.fallback") && msg.contains("outside the input set"),
        "{msg}"
    );
    let src = edit("hi = [1.0]", "hi = [1.0]\nfallback = [0.5, 0.5]");
    refused(&src, ErrorKind::Dimension, "[0.5, 0.5]");
}

#[test]
fn the_image_stores_the_fallback_input_and_the_evaluator_applies_it() {
    let p = spec::parse(&edit("lo = [-1.0]", "lo = [0.25]"), "s").unwrap();
    assert_eq!(p.fallback_input, vec![0.25]);
    let law = FallbackLaw::constant(&p.fallback_input);
    assert_eq!(law, FallbackLaw::Constant(vec![0.25]));
    assert_eq!(FallbackLaw::constant(&[0.0]), FallbackLaw::Zero);
    let mut b = ImageBuilder::new(2, 1, 0.1);
    b.add_location(vec![-1.0, -1.0], vec![1.0, 0.0, 0.0, 1.0]);
    b.add_trajectory(TrajectoryEntry {
        x0: vec![0.0, 0.0],
        delta: 0.5,
        v: vec![0.5, 0.5],
        location: vec![0, 0],
    });
    b.input_box = Some((vec![0.25], vec![1.0]));
    b.fallback = law;
    let bytes = b.to_bytes().unwrap();
    let img = decode(&bytes).unwrap();
    assert!(matches!(img.fallback(), Fallback::Constant { .. }));
    let mut ctl = Controller::new(img);
    // Far outside every ball: out of envelope, and the fallback is the stored input, not 0.
    let x = [10.0f32, 10.0];
    assert!(ctl.step(&x).is_err());
    let last = shared_types::eval::Input::zero(1);
    assert_eq!(ctl.fallback(&x, &last).as_slice(), &[0.25]);
    // Even for a state it cannot read (the firmware passes the last one it accepted).
    assert_eq!(ctl.fallback(&[f32::NAN, 0.0], &last).as_slice(), &[0.25]);
    // A constant outside the stored input box is refused by the decoder.
    b.fallback = FallbackLaw::Constant(vec![0.0]);
    let e = b.to_bytes().expect_err("0 is outside the box [0.25, 1]");
    assert!(
        format!("{e}").contains(&ImageError::FallbackOutsideBox { input: 0 }.to_string()),
        "{e}"
    );
}

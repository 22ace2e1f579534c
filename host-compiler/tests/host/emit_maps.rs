//! Images with model maps (section 10) from the host: `ImageBuilder::model_maps` with programs compiled
//! from expressions, read back byte for byte by `ImageBuilder::from_image`, evaluated by `step_plant`
//! as the composition of its parts, refused where the format refuses, and shown by `inspect`.
#![allow(non_snake_case)]

use host_compiler::cli::inspect::render;
use host_compiler::emit::{EmitError, FallbackLaw, ImageBuilder, ModelMapsSpec, TrajectoryEntry};
use host_compiler::expr::compile::compile;
use host_compiler::expr::{parse, Func, Names};
use shared_types::eval::Controller;
use shared_types::image::{decode, ImageError, ModelMap};

fn names(states: &[&str], inputs: &[&str]) -> Names {
    Names {
        states: states.iter().map(|s| s.to_string()).collect(),
        inputs: inputs.iter().map(|s| s.to_string()).collect(),
        params: vec![],
    }
}

fn program(texts: &[&str], states: &[&str], inputs: &[&str]) -> Vec<u8> {
    let nm = names(states, inputs);
    let exprs: Vec<_> = texts.iter().map(|t| parse(t, &nm).unwrap()).collect();
    compile(&exprs, states.len(), inputs.len(), &[])
        .unwrap()
        .bytes
}

/// The maps of a unicycle-like plant (x, y, th): ξ = (x, y), u = (cos th·w0 + sin th·w1, w1 − w0).
fn maps() -> ModelMapsSpec {
    let s = ["x", "y", "th"];
    ModelMapsSpec {
        n_plant: 3,
        m_plant: 2,
        ext_init: Vec::new(),
        coords: program(&["x", "y"], &s, &[]),
        input_map: program(&["cos(th)*w0 + sin(th)*w1", "w1 - w0"], &s, &["w0", "w1"]),
    }
}

/// n = 2, m = 2 in ξ; the table ends with the fallback, a constant plant input in a plant box.
fn builder() -> ImageBuilder {
    let mut b = ImageBuilder::new(2, 2, 0.1);
    b.add_location(vec![-1.0, 0.0, 0.0, -1.0], vec![1.0, 0.0, 0.0, 1.0]);
    b.add_trajectory(TrajectoryEntry {
        x0: vec![0.0, 0.0],
        delta: 1.0,
        v: vec![0.5, -0.5, 0.25, 0.0],
        location: vec![0, 0],
    });
    b.fallback = FallbackLaw::Constant(vec![0.125, -0.25]);
    b.input_box = Some((vec![-1.0, -1.0], vec![1.0, 1.0]));
    b.terminal = host_compiler::emit::Terminal::Fallback;
    b.model_maps(maps());
    b
}

#[test]
fn maps_round_trip_byte_for_byte() {
    let b = builder();
    let bytes = b.to_bytes().unwrap();
    let img = decode(&bytes).unwrap();
    assert_eq!((img.plant_n(), img.plant_m()), (3, 2));
    let back = ImageBuilder::from_image(&img);
    assert_eq!(back.model_maps, b.model_maps);
    assert_eq!(back.fallback, b.fallback);
    assert_eq!(back.input_box, b.input_box);
    assert_eq!(back.to_bytes().unwrap(), bytes);
    // Without maps the builder writes no section 10.
    let mut plain = b.clone();
    plain.model_maps = None;
    plain.fallback = FallbackLaw::Zero;
    plain.input_box = None;
    let plain = plain.to_bytes().unwrap();
    assert!(decode(&plain).unwrap().model_maps().is_none());
}

#[test]
fn step_plant_runs_the_compiled_maps() {
    let bytes = builder().to_bytes().unwrap();
    let img = decode(&bytes).unwrap();
    let mut c = Controller::new(img);
    let x = [0.25f32, -0.5, 0.75];
    let u = c.step_plant(&x).unwrap();
    // w = K ξ + v(0) = (−0.25 + 0.5, 0.5 − 0.5); u as the expressions say, in f32.
    let (w0, w1) = (-0.25f32 + 0.5, 0.5f32 + -0.5);
    let th = x[2];
    let want = [Func::Cos.apply(th) * w0 + Func::Sin.apply(th) * w1, w1 - w0];
    assert_eq!(
        u.as_slice().iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        want.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );
    // Second row, then past the table: the plant-space fallback.
    c.step_plant(&x).unwrap();
    assert_eq!(c.step_plant(&x).unwrap().as_slice(), &[0.125, -0.25]);
}

#[test]
fn maps_refusals_name_what_is_wrong() {
    let mut b = builder();
    b.fallback = FallbackLaw::Linear {
        K: vec![0.0; 4],
        x_ref: vec![0.0; 2],
        u_ref: vec![0.0; 2],
    };
    b.input_box = None;
    let e = b.to_bytes().unwrap_err();
    assert!(e.to_string().contains("linear fallback"), "{e}");
    let mut b = builder();
    b.fallback = FallbackLaw::Constant(vec![0.0; 3]);
    assert!(matches!(b.to_bytes(), Err(EmitError::Shape { .. })));
    let mut b = builder();
    let mut m = maps();
    m.n_plant = 4;
    b.model_maps(m);
    assert!(matches!(
        b.to_bytes(),
        Err(EmitError::Rejected(ImageError::MapInputs {
            map: ModelMap::Coords,
            expected: 4,
            found: 3
        }))
    ));
    let mut b = builder();
    let mut m = maps();
    m.m_plant = 9;
    b.model_maps(m);
    assert!(matches!(b.to_bytes(), Err(EmitError::Capacity { .. })));
}

/// The unicycle with a controller state s (its speed, kept by the controller): ξ = (x, y),
/// u = (s, w1 − w0), s⁺ = s + 0.1·w0.
fn ext_maps(ext_init: Vec<f32>) -> ModelMapsSpec {
    let s = ["x", "y", "th", "s"];
    ModelMapsSpec {
        n_plant: 3,
        m_plant: 2,
        ext_init,
        coords: program(&["x", "y"], &s, &[]),
        input_map: program(&["s", "w1 - w0", "s + 0.1*w0"], &s, &["w0", "w1"]),
    }
}

#[test]
fn controller_states_round_trip_and_are_refused_beyond_capacity() {
    let mut b = builder();
    b.model_maps(ext_maps(vec![0.5]));
    let bytes = b.to_bytes().unwrap();
    let img = decode(&bytes).unwrap();
    let mm = img.model_maps().unwrap();
    assert_eq!((mm.n_plant(), mm.m_plant(), mm.n_ext()), (3, 2, 1));
    assert_eq!(mm.ext_init(0), 0.5);
    let back = ImageBuilder::from_image(&img);
    assert_eq!(back.model_maps, b.model_maps);
    assert_eq!(back.to_bytes().unwrap(), bytes);
    // The controller starts from ζ0, u0 = s, and s advances by 0.1·w0 (w0 = −0.25 + 0.5 at row 0).
    let mut c = Controller::new(img);
    assert_eq!(c.extension(), &[0.5]);
    let u = c.step_plant(&[0.25, -0.5, 0.75]).unwrap();
    assert_eq!(u.as_slice()[0], 0.5);
    assert_eq!(c.extension(), &[0.5f32 + 0.1 * (-0.25f32 + 0.5)]);
    c.reset();
    assert_eq!(c.extension(), &[0.5]);
    // Without controller states the section is the feedback-linearizable one.
    assert_eq!(
        decode(&builder().to_bytes().unwrap())
            .unwrap()
            .model_maps()
            .unwrap()
            .n_ext(),
        0
    );
    // More than MAX_EXT states, a non-finite ζ0, programs that do not read ζ.
    let mut b = builder();
    b.model_maps(ext_maps(vec![0.0; shared_types::capacity::MAX_EXT + 1]));
    assert!(matches!(
        b.to_bytes(),
        Err(EmitError::Capacity {
            what: "number of controller states n_ext",
            ..
        })
    ));
    let mut b = builder();
    b.model_maps(ext_maps(vec![f32::NAN]));
    assert!(matches!(b.to_bytes(), Err(EmitError::NonFinite { .. })));
    let mut b = builder();
    let mut m = maps();
    m.ext_init = vec![0.0];
    b.model_maps(m);
    assert!(matches!(
        b.to_bytes(),
        Err(EmitError::Rejected(ImageError::MapInputs {
            map: ModelMap::Coords,
            expected: 4,
            found: 3
        }))
    ));
}

#[test]
fn inspect_shows_the_model_maps() {
    let b = builder();
    let bytes = b.to_bytes().unwrap();
    let text = render(&bytes, "fl.img", false).unwrap();
    assert!(text.contains("model_maps"), "{text}");
    assert!(text.contains("n_plant = 3, m_plant = 2"), "{text}");
    let mm = b.model_maps.unwrap();
    assert!(
        text.contains(&format!("coords: {} bytes", mm.coords.len())),
        "{text}"
    );
    assert!(text.contains("fallback: the constant input u = [0.125, -0.25]"));
    let json: serde_json::Value =
        serde_json::from_str(&render(&bytes, "fl.img", true).unwrap()).unwrap();
    assert_eq!(json["model_maps"]["n_plant"], 3);
    assert_eq!(json["model_maps"]["input_map"]["bytes"], mm.input_map.len());
    assert_eq!(json["model_maps"]["input_map"]["inputs"], 5);
    assert_eq!(json["input_box"]["lo"].as_array().unwrap().len(), 2);
}

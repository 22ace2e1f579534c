//! The stored values of an image that no re-proof reads, re-derived from the spec and required equal
//! (issue 42, item 1). The re-proofs ([`super::feedforward::recheck`], [`super::temporal::recheck`],
//! [`super::hybrid::recheck`], [`super::pwa::recheck`], [`super::recheck_terminal`]) re-prove a
//! certificate from the stored K̂, P̂, centres, radii, tables, segment locations, guard exits (guard,
//! threshold and the next segment's start), the selection test's factor, whitened centres and
//! thresholds, the PWA laws, tree and balls, and the terminal law, each as stored. Every other stored
//! value the certified behaviour depends on is listed here with how it is checked:
//!
//! | stored value | section | checked by |
//! |---|---|---|
//! | n, m | header | [`super::check_matches`]: the spec's dimensions |
//! | sample period | header | [`super::check_matches`]: the spec's period as f32 |
//! | mode | header | the spec: a hybrid or MTL spec needs a feedforward image; the PWA re-proof only a PWA one |
//! | locations | header | one for a one-location plant ([`super::feedforward::recheck`]), the automaton's for a hybrid one ([`super::hybrid::recheck`]) |
//! | spec fingerprint | 12 | [`super::check_matches`]; not read by the evaluator, and not a proof: the coverage of the spec's Init is estimated ([`super::coverage`]) |
//! | n_plant, m_plant, ζ0 (a flat plant's extension's initial values), the coords and input-map programs | 10 (model maps) | the whole section body rebuilt from the spec's model as `cover::feedforward_image_of` writes it, byte for byte ([`Expected::model_maps`]) |
//! | fallback law and its constants | fallback | re-derived: the spec's `input.fallback` (zero: the `Zero` law) for one-location and PWA images, `Zero` for hybrid ones |
//! | input box | input box | re-derived: the spec's input box (the plant's with model maps; none for a norm bound or a hybrid plant) |
//! | behaviour past the table | header of the table | re-derived: `Fallback` when the spec's `synthesis.terminal = "fallback"` (one-location reach-avoid), else `HoldLast` |
//! | everything else: padding, reserved bytes, directory flags, section order | all | the image must be the canonical encoding of what it decodes to (decoding and encoding again gives the same bytes), so no byte is left that nothing reads |
//!
//! A mismatch is named by the field; nothing the synthesiser computed is trusted.

use crate::emit::{FallbackLaw, ImageBuilder, ModelMapsSpec, PwaImageBuilder};
use shared_types::image::{Image, Mode, Terminal};

/// What the spec says the image stores beyond what the re-proofs read.
#[derive(Clone, Debug, PartialEq)]
pub struct Expected {
    pub fallback: FallbackLaw,
    /// The input box, `(lo, hi)`, if the spec's input set is a box.
    pub input_box: Option<(Vec<f64>, Vec<f64>)>,
    /// Behaviour past the table (feedforward images only).
    pub terminal: Terminal,
    /// The model maps section of a feedback-linearizable or flat plant.
    pub model_maps: Option<ModelMapsSpec>,
}

/// A stored value that is not the one the spec gives.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct StoredMismatch(pub String);

fn input_box(input: &crate::spec::InputSet) -> Option<(Vec<f64>, Vec<f64>)> {
    match input {
        crate::spec::InputSet::Box { lo, hi } => Some((lo.clone(), hi.clone())),
        _ => None,
    }
}

impl Expected {
    /// A one-location task's feedforward image (reach-avoid: `temporal` false; an MTL task's: true,
    /// whose image always holds its last row past the table).
    pub fn feedforward(task: &crate::task::Task, temporal: bool) -> Self {
        let maps = task.plant.linearization();
        let input = maps.map_or(&task.problem.input, |m| &m.input);
        let fallback_past_table =
            !temporal && task.settings().terminal == crate::spec::TerminalChoice::Fallback;
        Expected {
            fallback: FallbackLaw::constant(&task.problem.fallback_input),
            input_box: input_box(input),
            terminal: if fallback_past_table {
                Terminal::Fallback
            } else {
                Terminal::HoldLast
            },
            model_maps: maps.map(ModelMapsSpec::of),
        }
    }

    /// A PWA image of a one-location task.
    pub fn pwa(task: &crate::task::Task) -> Self {
        Expected {
            fallback: FallbackLaw::constant(&task.problem.fallback_input),
            input_box: input_box(&task.problem.input),
            terminal: Terminal::HoldLast,
            model_maps: None,
        }
    }

    /// A hybrid plant's image (`synth::hybrid`): zero fallback, no input box, the last row held.
    pub fn hybrid() -> Self {
        Expected {
            fallback: FallbackLaw::Zero,
            input_box: None,
            terminal: Terminal::HoldLast,
            model_maps: None,
        }
    }
}

/// The stored values of `bytes` against what the spec gives (module doc): the first that differs, named.
pub fn check(bytes: &[u8], expected: &Expected) -> Result<(), StoredMismatch> {
    let img = shared_types::image::decode(bytes)
        .map_err(|e| StoredMismatch(format!("the image is rejected: {e}")))?;
    let differs =
        |what: &str| StoredMismatch(format!("its stored {what} is not the one the spec gives"));
    // Each value the spec gives put in place of the stored one: the bytes must not change.
    let rebuilt = |f: &dyn Fn(&mut Edit)| -> Option<Vec<u8>> {
        let mut e = Edit::of(&img)?;
        f(&mut e);
        e.bytes()
    };
    let same = |b: Option<Vec<u8>>| b.as_deref() == Some(bytes);
    if !same(rebuilt(&|_| {})) {
        return Err(StoredMismatch(
            "the image is not the canonical encoding of its content (bytes nothing reads)".into(),
        ));
    }
    if let Some(mm) = img.model_maps() {
        let Some(want) = &expected.model_maps else {
            return Err(differs("model maps section (the spec's plant has none)"));
        };
        if (mm.n_plant(), mm.m_plant()) != (want.n_plant, want.m_plant) {
            return Err(StoredMismatch(format!(
                "the image's model maps are for a plant with n = {}, m = {}; the spec's has n = {}, m = {}",
                mm.n_plant(),
                mm.m_plant(),
                want.n_plant,
                want.m_plant
            )));
        }
        let zeta: Vec<u32> = mm.ext_inits().map(f32::to_bits).collect();
        let want_zeta: Vec<u32> = want.ext_init.iter().map(|v| v.to_bits()).collect();
        if zeta != want_zeta {
            return Err(StoredMismatch(format!(
                "its stored initial values of the controller's states ζ0 = {:?} are not the spec's {:?}",
                mm.ext_inits().collect::<Vec<_>>(),
                want.ext_init
            )));
        }
        if !same(rebuilt(&|e| e.set_maps(want.clone()))) {
            return Err(differs("model maps section (coords or input map program)"));
        }
    } else if expected.model_maps.is_some() {
        return Err(StoredMismatch(
            "the image has no model maps section; the spec's plant needs its maps x ↦ ξ and (x, w) ↦ u"
                .into(),
        ));
    }
    if !same(rebuilt(&|e| e.set_fallback(expected.fallback.clone()))) {
        return Err(differs("fallback law"));
    }
    if !same(rebuilt(&|e| e.set_input_box(expected.input_box.clone()))) {
        return Err(differs("input box"));
    }
    if img.mode() == Mode::Feedforward && img.terminal() != expected.terminal {
        return Err(differs("behaviour past the table"));
    }
    Ok(())
}

/// An image read back into owned data, to put the spec's values in place of stored ones.
enum Edit {
    Feedforward(Box<ImageBuilder>),
    Pwa(Box<PwaImageBuilder>),
}

impl Edit {
    fn of(img: &Image<'_>) -> Option<Self> {
        Some(match img.mode() {
            Mode::Feedforward => Edit::Feedforward(Box::new(ImageBuilder::from_image(img))),
            _ => Edit::Pwa(Box::new(PwaImageBuilder::from_image(img)?)),
        })
    }
    fn set_fallback(&mut self, f: FallbackLaw) {
        match self {
            Edit::Feedforward(b) => b.fallback = f,
            Edit::Pwa(b) => b.fallback = f,
        }
    }
    fn set_input_box(&mut self, x: Option<(Vec<f64>, Vec<f64>)>) {
        match self {
            Edit::Feedforward(b) => b.input_box = x,
            Edit::Pwa(b) => b.input_box = x,
        }
    }
    fn set_maps(&mut self, m: ModelMapsSpec) {
        if let Edit::Feedforward(b) = self {
            b.model_maps = Some(m);
        }
    }
    fn bytes(&self) -> Option<Vec<u8>> {
        match self {
            Edit::Feedforward(b) => b.to_bytes().ok(),
            Edit::Pwa(b) => b.to_bytes().ok(),
        }
    }
}

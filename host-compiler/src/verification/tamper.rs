//! The tamper campaign (issue 42, item 3): an image's stored fields perturbed one at a time (the CRC
//! recomputed), each perturbed image verified by [`super::verify`] (what `host-compiler verify`
//! runs), and every one that passes judged independently by [`unsound`]: a Monte Carlo through the
//! perturbed image from uniform starts of the spec's Init it accepts and from its balls' boundaries, on
//! the plant, each run judged by the task. A tampering the verification passes although that check
//! finds a violating run is a false claim. Used by `benches/tamper.rs` (the campaign over the examples)
//! and the host suite's small version (`tests/host/verify_tamper.rs`).
//!
//! # The perturbations
//! Every 4-byte word of the image except the CRC (header, section directory and every section), each
//! read as an f32 and changed by each of [`PERTURBATIONS`] (relative changes from 10⁻⁶ to ×2, a sign
//! flip, and for a zero word small values of either sign); words that hold integers (counts, lengths,
//! kinds, program bytes) get the same bit changes, which the decoder mostly refuses. When the image has
//! more words than the budget allows, the step table's rows are taken at even spacing and every other
//! word in full. Seeded; the result does not depend on the thread count.

use super::{verify, Options, Refusal};
use std::collections::BTreeMap;

/// How each word is changed (`x` the word read as f32).
pub const PERTURBATIONS: &[(&str, fn(f32) -> f32)] = &[
    (
        "×(1+1e-6)",
        |x| if x == 0.0 { 1e-6 } else { x * (1.0 + 1e-6) },
    ),
    ("×(1−1e-6)", |x| {
        if x == 0.0 {
            -1e-6
        } else {
            x * (1.0 - 1e-6)
        }
    }),
    (
        "×(1+1e-3)",
        |x| if x == 0.0 { 1e-3 } else { x * (1.0 + 1e-3) },
    ),
    ("×(1−1e-3)", |x| {
        if x == 0.0 {
            -1e-3
        } else {
            x * (1.0 - 1e-3)
        }
    }),
    ("×1.1", |x| if x == 0.0 { 0.1 } else { x * 1.1 }),
    ("×0.5", |x| if x == 0.0 { -0.1 } else { x * 0.5 }),
    ("×2", |x| if x == 0.0 { 1.0 } else { x * 2.0 }),
    ("−x", |x| if x == 0.0 { -1.0 } else { -x }),
];

/// What a campaign found.
#[derive(Clone, Debug, Default)]
pub struct Campaign {
    /// Perturbed images verified.
    pub tamperings: usize,
    /// Passed (exit 0 or 3) and the independent check found nothing.
    pub sound: usize,
    /// Passed although the independent check found the image unsound: what was changed and why.
    pub false_claims: Vec<String>,
    /// Refused, by the first check that refused.
    pub refused: BTreeMap<String, usize>,
}

impl Campaign {
    /// Adds another campaign's counts.
    pub fn merge(&mut self, o: Campaign) {
        self.tamperings += o.tamperings;
        self.sound += o.sound;
        self.false_claims.extend(o.false_claims);
        for (k, v) in o.refused {
            *self.refused.entry(k).or_default() += v;
        }
    }
    /// "re-proof 812, decode 2 004, …", for people.
    pub fn refused_line(&self) -> String {
        self.refused
            .iter()
            .map(|(k, v)| format!("{k} {v}"))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// The section holding byte `at`: "header", "directory", or the section kind's name.
fn section_of(bytes: &[u8], at: usize) -> String {
    const HEADER: usize = shared_types::capacity::HEADER_LEN;
    if at < HEADER {
        return "header".into();
    }
    let count = bytes
        .get(
            shared_types::layout::SECTION_COUNT_OFFSET
                ..shared_types::layout::SECTION_COUNT_OFFSET + 2,
        )
        .map_or(0, |b| u16::from_le_bytes([b[0], b[1]]) as usize);
    let dir_end = HEADER + count * shared_types::layout::DIR_ENTRY_LEN;
    if at < dir_end {
        return "directory".into();
    }
    let u32_at = |i: usize| {
        bytes
            .get(i..i + 4)
            .map_or(0, |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
    };
    for i in 0..count {
        let e = HEADER + i * shared_types::layout::DIR_ENTRY_LEN;
        let kind = bytes
            .get(e..e + 2)
            .map_or(0, |b| u16::from_le_bytes([b[0], b[1]]));
        let (off, len) = (u32_at(e + 4), u32_at(e + 8));
        if (off..off + len).contains(&at) {
            return match shared_types::layout::SectionKind::from_u16(kind) {
                Some(k) => format!("{k:?}"),
                None => format!("section {kind}"),
            };
        }
    }
    "unclaimed".into()
}

/// The perturbed images of `bytes` (module doc), at most about `budget`: (what was changed, the bytes
/// with the CRC recomputed).
pub fn tamperings(bytes: &[u8], budget: usize) -> Vec<(String, Vec<u8>)> {
    let crc = shared_types::layout::CRC_OFFSET;
    let words: Vec<(usize, String)> = (0..bytes.len() / 4)
        .map(|w| 4 * w)
        .filter(|&at| at != crc)
        .map(|at| (at, section_of(bytes, at)))
        .collect();
    let table: Vec<&(usize, String)> = words.iter().filter(|(_, s)| s == "Steps").collect();
    let rest: Vec<&(usize, String)> = words.iter().filter(|(_, s)| s != "Steps").collect();
    let k = PERTURBATIONS.len();
    let room = (budget / k).saturating_sub(rest.len()).max(1);
    let stride = table.len().div_ceil(room).max(1);
    let chosen = rest
        .into_iter()
        .chain(table.into_iter().step_by(stride))
        .collect::<Vec<_>>();
    let mut out = Vec::new();
    for (at, section) in chosen {
        let word = f32::from_le_bytes([bytes[*at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]);
        for (name, f) in PERTURBATIONS {
            let changed = f(word);
            if changed.to_bits() == word.to_bits() {
                continue;
            }
            let mut b = bytes.to_vec();
            b[*at..at + 4].copy_from_slice(&changed.to_le_bytes());
            if let Ok(c) = shared_types::header::compute_crc(&b) {
                b[crc..crc + 4].copy_from_slice(&c.to_le_bytes());
            }
            out.push((format!("{section} word at byte {at}: {word:e} {name}"), b));
        }
    }
    out
}

/// The independent check (module doc): `Some(why)` when a run through the image from a start it accepts
/// violates the task. Starts: `runs` uniform in the spec's Init that the image accepts and `per_ball` on
/// every ball's boundary, seeded.
pub fn unsound(
    problem: &crate::spec::Problem,
    bytes: &[u8],
    runs: usize,
    per_ball: usize,
    seed: u64,
) -> Option<String> {
    let img = shared_types::image::decode(bytes).ok()?;
    let init = crate::cover::estimate::SampleBox {
        lo: problem.init.lo.clone(),
        hi: problem.init.hi.clone(),
    };
    if problem.hybrid.is_some() {
        let task = crate::synth::hybrid::HybridTask::new(problem.clone()).ok()?;
        let starts =
            crate::verify::hybrid::starts_from_image(bytes, &init, runs, per_ball, seed).ok()?;
        let r = crate::verify::hybrid::monte_carlo_hybrid(
            &task.plant,
            &task.property,
            task.formula.as_ref(),
            task.initial,
            task.steps,
            bytes,
            &starts,
        );
        return match r {
            Ok(r) if r.violations == 0 => None,
            Ok(r) => Some(r.first_violation.unwrap_or_else(|| "a violation".into())),
            Err(e) => Some(e),
        };
    }
    let task = crate::task::Task::new(problem.clone()).ok()?;
    if problem.mtl.is_some() {
        let tt = crate::property::TemporalTask::from_problem(&task.problem).ok()?;
        let starts = crate::verify::hybrid::starts_from_image(
            bytes,
            &crate::cover::estimate::SampleBox {
                lo: task.problem.init.lo.clone(),
                hi: task.problem.init.hi.clone(),
            },
            runs,
            per_ball,
            seed,
        )
        .ok()?;
        let r = if task.plant.linearization().is_some() {
            crate::verify::temporal::monte_carlo_temporal_fl(&task, &tt, &img, &starts, seed ^ 1)
                .ok()?
        } else {
            crate::verify::temporal::monte_carlo_temporal(&task, &tt, &img, &starts).ok()?
        };
        return (r.violations > 0).then(|| r.first_violation.unwrap_or_default());
    }
    let judge = crate::verify::Judge::new(&task);
    if img.mode() == shared_types::image::Mode::PwaFeedback {
        let r = crate::verify::pwa::monte_carlo_pwa(&judge, &img, &[], runs, seed, 0).ok()?;
        return (r.violations > 0).then(|| format!("{} violations", r.violations));
    }
    let r = if task.plant.linearization().is_some() {
        crate::verify::nonlinear::monte_carlo_fl(&task, &img, runs, per_ball, seed).ok()?
    } else {
        crate::verify::monte_carlo(&judge, &img, runs, per_ball, seed).ok()?
    };
    (r.violations > 0).then(|| {
        r.first_violations.first().map_or_else(
            || "a violation".into(),
            |v| format!("run from x0 = {:?}", v.x0),
        )
    })
}

/// The verification's options in the campaign: a short Monte Carlo, the coverage estimate, no
/// falsifier, stopping at the first failed check.
pub fn campaign_options(seed: u64) -> Options {
    Options {
        runs: 100,
        per_ball: 4,
        seed: Some(seed),
        attack_evals: None,
        coverage: true,
        stop_early: true,
        progress: None,
    }
}

/// Every tampering of `bytes` (at most about `budget`) verified against `problem`, the passed ones
/// judged by [`unsound`] (module doc).
pub fn campaign(
    problem: &crate::spec::Problem,
    bytes: &[u8],
    budget: usize,
    seed: u64,
) -> Campaign {
    use rayon::prelude::*;
    /// What became of one tampering.
    enum Outcome {
        Refused(String),
        Sound,
        FalseClaim(String),
    }
    // The tamperings are independent and each verification is seeded the same way, so verifying them in
    // parallel gives the same counts, in the same order, as one after another.
    let outcomes: Vec<Outcome> = tamperings(bytes, budget)
        .into_par_iter()
        .map(
            |(what, b)| match verify(problem.clone(), &b, &campaign_options(seed)) {
                Err(Refusal::Rejected(_)) => Outcome::Refused("decode".into()),
                Err(Refusal::Mismatch(_)) => Outcome::Refused("spec mismatch".into()),
                Err(Refusal::BadInput(_)) => Outcome::Refused("bad input".into()),
                Ok(v) => match v.failure {
                    Some(f) => Outcome::Refused(f.check.name().to_string()),
                    None => match unsound(problem, &b, 400, 16, seed ^ 0x1d3e) {
                        Some(why) => Outcome::FalseClaim(format!("{what}: {why}")),
                        None => Outcome::Sound,
                    },
                },
            },
        )
        .collect();
    let mut c = Campaign::default();
    for o in outcomes {
        c.tamperings += 1;
        match o {
            Outcome::Refused(by) => *c.refused.entry(by).or_default() += 1,
            Outcome::Sound => c.sound += 1,
            Outcome::FalseClaim(why) => c.false_claims.push(why),
        }
    }
    c
}

//! The tamper campaign's small version (issue 42, item 3): a few hundred perturbations of the double
//! integrator's image, every stored field of every section (the CRC recomputed), each verified as
//! `host-compiler verify` verifies it. None may pass while the independent Monte Carlo
//! (`verification::tamper::unsound`) finds a violating run; the whole campaign is `benches/tamper.rs`.

use crate::verify_refuses::{image, spec};
use host_compiler::verification::tamper::{campaign, tamperings};

#[test]
fn no_tampering_of_the_double_integrator_image_passes_falsely() {
    let problem = host_compiler::spec::load(spec()).unwrap();
    let bytes = image();
    // TAMPER_BUDGET asks for a larger campaign on the same image (read only; default 320).
    let budget = std::env::var("TAMPER_BUDGET")
        .ok()
        .and_then(|b| b.parse().ok())
        .unwrap_or(320);
    let c = campaign(&problem, bytes, budget, 7);
    println!(
        "double integrator: {} tamperings, {} false claims, {} re-proved sound; refused by {}",
        c.tamperings,
        c.false_claims.len(),
        c.sound,
        c.refused_line()
    );
    assert!(c.tamperings >= 250, "{c:?}");
    assert!(c.false_claims.is_empty(), "{:#?}", c.false_claims);
    // Both outcomes occur: refusals (by several checks) and re-proved sound perturbations.
    assert!(c.refused.len() >= 3, "{c:?}");
    assert!(c.sound > 0, "{c:?}");
}

#[test]
fn every_section_is_perturbed() {
    let t = tamperings(image(), 320);
    for section in [
        "header",
        "directory",
        "Locations",
        "Fallback",
        "Trajectories",
        "Steps",
    ] {
        assert!(
            t.iter().any(|(what, _)| what.starts_with(section)),
            "{section} is not perturbed"
        );
    }
}

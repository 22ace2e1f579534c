//! What an image does after Goal, said in one line from its bytes alone (issue 42, item 4): `synth`,
//! `inspect` and the report print it. It states what `shared_types::eval::Controller` does (and the
//! firmware with it: an answer that is not `Ok` gets the image's fallback), nothing more.
//!
//! * With a terminal law (section 11): its f32 handover test runs first at every step; every certified
//!   run is handed over within the horizon and the law keeps it in Goal (`certify::terminal`).
//! * Feedforward without one: the run's own table rows go on after Goal (segment exits still switch a
//!   hybrid run's location); past the last row, the last row's law `u = K_ℓ x + v(last)` is held, or the
//!   image's fallback applies, as the image's terminal byte says. Not certified after Goal.
//! * PWA without one: the PWA law goes on wherever the state lies in the envelope; elsewhere the
//!   evaluator answers out of envelope and the firmware applies the fallback. Not certified after Goal.

use shared_types::image::{Fallback, Image, Mode, Terminal};

/// The fallback law in words (what the firmware applies when the answer is not `Ok`).
fn fallback_words(image: &Image<'_>) -> String {
    match image.fallback() {
        Fallback::Hold => "the fallback (the last input held)".into(),
        Fallback::Zero => "the fallback (zero input)".into(),
        Fallback::Constant { .. } => {
            let u: Vec<f32> = (0..image.plant_m())
                .map(|j| image.fallback_input(j))
                .collect();
            format!("the fallback (the constant input {u:?})")
        }
        Fallback::Linear { .. } => {
            "the fallback (its linear law K_fb (x − x_ref) + u_ref, saturated to \
                                    the input box where one is stored)"
                .into()
        }
    }
}

/// One line: what the image does after Goal (module doc), starting "after Goal: ".
pub fn after_goal_line(image: &Image<'_>) -> String {
    if image.terminal_law().is_some() {
        return "after Goal: the terminal law (section 11) takes over where its f32 handover test \
                accepts; every certified run is handed over within the horizon and held in Goal, out \
                of Unsafe and within the input set, for ever (certified and judged)"
            .into();
    }
    match image.mode() {
        Mode::Feedforward => {
            let exits = if image.has_exits() {
                " (its segment exits still switching the location)"
            } else {
                ""
            };
            let past = match image.terminal() {
                Terminal::HoldLast => "the last row's law u = K x + v(last) is held".to_string(),
                Terminal::Fallback => format!("{} applies", fallback_words(image)),
            };
            format!(
                "after Goal: no terminal law; the run's table goes on to its last row{exits}, then \
                 {past} (not certified after Goal)"
            )
        }
        _ => format!(
            "after Goal: no terminal law; the PWA law goes on wherever the state lies in the envelope, \
             elsewhere the evaluator answers out of envelope and {} applies (not certified after Goal)",
            fallback_words(image)
        ),
    }
}

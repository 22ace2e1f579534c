//! The C export against the Rust evaluator (#16 item 7): the exported evaluator compiled with the system
//! `cc` under the header's flags, run on 10⁵ seeded states per image mode (feedforward, feedforward with
//! segment exits, PWA feedback: synthetic images of every terminal behaviour and fallback law, one and
//! several locations), compared bit for bit.
//!
//! Rows: `c_export_mismatches` (steps whose status or an input bit differed; 0 expected) and
//! `c_export_states` (steps compared, all modes; the note gives each mode's count, ≥ 10⁵ each).

use host_compiler::benchkit::{write_rows, Row};
use host_compiler::export::harness::{
    exits_image, feedforward_image, pwa_image, scenario, CHarness,
};
use shared_types::image::{decode, Terminal};

fn main() {
    let images = [
        feedforward_image(100, 4, 2, 1, 12, Terminal::HoldLast, 0),
        feedforward_image(101, 5, 2, 3, 20, Terminal::Fallback, 2),
        feedforward_image(102, 3, 1, 2, 8, Terminal::Fallback, 3),
        feedforward_image(103, 12, 6, 1, 6, Terminal::Fallback, 1),
        exits_image(500, 3, 1, 1, 5, Terminal::HoldLast, 0),
        exits_image(501, 4, 2, 2, 10, Terminal::Fallback, 2),
        exits_image(502, 3, 2, 3, 12, Terminal::HoldLast, 3),
        exits_image(503, 5, 1, 3, 8, Terminal::Fallback, 1),
        pwa_image(200, 2, 1, 1, 3, 40, 1),
        pwa_image(201, 4, 2, 3, 5, 80, 2),
        pwa_image(202, 6, 3, 2, 4, 60, 0),
        pwa_image(203, 12, 6, 1, 2, 30, 3),
    ];
    let dir = host_compiler::benchkit::rows_dir()
        .join("..")
        .join("c_export");
    let (mut states, mut mismatches) = (0usize, 0usize);
    // Steps compared per mode: feedforward, feedforward with segment exits, PWA (4 images each).
    let mut per_mode = [0usize; 3];
    for (i, image) in images.iter().enumerate() {
        let sub = dir.join(format!("image{i}"));
        let h = CHarness::build(image, &sub).expect("the exported C compiles");
        let img = decode(image).expect("valid image");
        let ops = scenario(&img, 1000 + i as u64, 25_000);
        let c = h.compare(&ops).expect("the C driver runs");
        assert_eq!(
            c.init_mismatches, 0,
            "image {i}: the exported array is refused"
        );
        if let Some(first) = &c.first {
            eprintln!("image {i}: {first}");
        }
        states += c.states;
        mismatches += c.mismatches;
        per_mode[i / 4] += c.states;
    }
    let rows = [
        Row::new(
            "c_export_mismatches",
            mismatches as f64,
            &format!(
                "steps of {states} (4 feedforward, 4 feedforward with segment exits, 4 PWA images)"
            ),
        ),
        Row::new(
            "c_export_states",
            states as f64,
            &format!(
                "steps compared (feedforward {}, with segment exits {}, PWA {})",
                per_mode[0], per_mode[1], per_mode[2]
            ),
        ),
    ];
    write_rows("c_export", &rows).expect("rows written");
}

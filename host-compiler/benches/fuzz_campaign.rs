//! Bench rows of the last fuzz campaign, read from its record `fuzz/CAMPAIGN.md` (the campaigns run under
//! nightly with cargo-fuzz; this only reports them): `fuzz_execs_min`, the fewest executions of any
//! target, and `fuzz_crashes`, summed over the targets.

use host_compiler::benchkit::{fuzz_campaign, fuzz_rows, write_rows};

fn main() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/CAMPAIGN.md");
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    let targets = fuzz_campaign(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    for t in &targets {
        println!(
            "fuzz target {:<14} {:>12} executions, {} crashes",
            t.target, t.executions, t.crashes
        );
    }
    write_rows("fuzz_campaign", &fuzz_rows(&targets)).unwrap();
}

//! The host-compiler integration tests, as one test binary: each module is a former `tests/<name>.rs`
//! (kept under its old name). One binary links faer, clarabel and plotters once instead of once per file.
//! A new test file goes here as `tests/host/<name>.rs` with a `mod <name>;` below, not in `tests/`.
//!
//! The modules share one process. None of them changes process-wide state (environment variables, the
//! current directory, the global rayon pool's configuration, a Ctrl-C handler, a panic hook or a tracing
//! subscriber): the Ctrl-C handler is installed only by `host-compiler synth`, which the CLI tests run as a
//! child process (`CARGO_BIN_EXE_host-compiler`), and `synth_algorithm4` sets thread counts with local pools
//! (`ThreadPoolBuilder::build` + `install`). Keep it so: a test that needs such state runs the binary in a
//! child process instead. Scratch files are named per test (`CARGO_TARGET_TMPDIR`, or the system temp dir
//! with the process id), so two tests never share one.

mod after_goal;
mod c_export;
mod caf_example33;
mod caf_props;
mod caf_status;
mod certify_bounds;
mod certify_fl;
mod certify_forced;
mod certify_internal;
mod certify_temporal;
mod cli_exit;
mod cli_fl;
mod cli_fl_pendulum;
mod cli_flat;
mod cli_hybrid;
mod cli_limits;
mod cli_mtl;
mod cli_simulate_hybrid;
mod cli_synth;
mod cli_terminal;
mod csv_dialect;
mod emit_image;
mod emit_maps;
mod emit_pwa;
mod fallback_input;
mod forced_schedule;
mod fuzz_corpus;
mod fuzz_smoke;
mod geometry_common;
mod geometry_ellipsoid;
mod geometry_polytope;
mod geometry_regions;
mod hybrid_import;
mod hybrid_routes;
mod image_exits;
mod import_inputs;
mod inspect_certificate;
mod intersample_directional;
mod maze_vehicle;
mod messages;
mod model_hybrid;
mod model_zoh;
mod monitor_program;
mod mtl_cli;
mod mtl_depth;
mod mtl_errors;
mod mtl_props;
mod mtl_semantics;
mod mtl_tube;
mod no_trajectory;
mod optimize_delta;
mod optimize_gradient;
mod optimize_potential;
mod plain_bounds;
mod play_browser;
mod play_plants;
mod play_server;
mod property_semantics;
mod pwa_example_6_4_period;
mod pwa_learn;
mod refactor_fixtures;
mod report_clip;
mod report_html;
mod robustness_safety;
mod route_search;
mod seed_sources;
mod spec_bounds;
mod spec_errors;
mod spec_examples;
mod spec_fingerprint;
mod spec_hybrid;
mod spec_limits;
mod spec_parse;
mod synth_algorithm4;
mod synth_end_to_end;
mod synth_fl_mtl;
mod synth_import_dir;
mod verify_attack;
mod verify_between;
mod verify_refuses;
mod verify_semantics;
mod verify_tamper;
mod verify_truth;

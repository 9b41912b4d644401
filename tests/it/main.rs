//! The integration tests of mfd as one binary: one module per area (the
//! files beside this one), sharing the helpers of `tests/common` and the
//! `*_support` folders. One binary links the library, wgpu, tokio and axum
//! once instead of once per file (53 binaries took 7.4 GB of `target/`).
//! The tests that need a cargo feature are in `tests/hw`.
//!
//! Run one area with a filter: `cargo test --test it console_http::`.

#[path = "../common/mod.rs"]
mod common;
#[path = "../compare_support/mod.rs"]
mod compare_support;
#[path = "../console_support/mod.rs"]
mod console_support;
#[path = "../report_support/mod.rs"]
mod report_support;

mod acquisition_io;
mod architecture;
mod aspect;
mod bad_inputs;
mod bad_sizes;
mod bench_json;
mod budget_cli;
mod budget_fisher;
mod budget_honesty;
mod budget_linear;
mod budget_refine;
mod budget_wrong_station;
mod calibrate_adjust;
mod calibrate_chain;
mod calibrate_cli;
mod calibrate_display_response;
mod calibrate_pictures;
mod calibrate_screen_points;
mod calibrate_session;
mod calibrate_soak;
mod calibrate_weak;
mod cli;
mod cli_ranges;
mod compare_files;
mod console_browser;
mod console_cli;
mod console_hostile;
mod console_http;
mod console_security;
mod convergence;
mod direct_thin;
mod exit_statuses;
mod figures;
mod flat_plate;
mod fuzz_readers;
mod hostile_leftovers;
mod input_ranges;
mod measure_cli;
mod measure_resume;
mod measure_sim;
mod outline;
mod phase_shifting;
mod plan_cli;
mod plan_repeats;
mod plan_schedules;
mod plan_thin;
mod reconstruct_cli;
mod recorder;
mod reliability_results;
mod report_browser;
mod report_html;
mod simulate;
mod spectral_engines;
mod spectral_fixture;
mod spectral_sim;
mod spectral_soak;
mod station_files;
mod station_uncertainty;
mod station_v2;
mod surfaces_exact;
mod surfaces_fixture;
mod surfaces_noise;
mod surfaces_v2;
mod trace_fixture;
mod wedge;

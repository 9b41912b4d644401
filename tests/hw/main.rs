//! The integration tests that need a cargo feature or a hardware stand-in:
//! the fullscreen window under Xvfb (`display`), Aravis's fake GigE Vision
//! camera on loopback (`aravis`), Zygo `.datx` files through HDF5 (`datx`),
//! and the offscreen renderer they share (no feature). Without features only
//! the offscreen module is built. `scripts/test.sh` runs
//! `cargo test --features display,aravis,v4l --test hw` and
//! `cargo test --features datx --test hw compare_datx::`.

#[path = "../common/mod.rs"]
mod common;
#[cfg(feature = "datx")]
#[path = "../compare_support/mod.rs"]
mod compare_support;

#[cfg(feature = "aravis")]
mod aravis_fake;
#[cfg(feature = "datx")]
mod compare_datx;
mod display_offscreen;
#[cfg(feature = "display")]
mod display_xvfb;

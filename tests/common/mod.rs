//! Helpers shared by the integration tests.
#![allow(dead_code)]

pub mod phase;
pub mod spectral;

use std::path::PathBuf;

/// The independent fixture folder, carried in the repository
/// (`tests/fixtures/public-small`, a copy of `shared/fixtures/public-small`;
/// never edited, see `tests/fixtures/README.md`).
pub fn public_small() -> PathBuf {
    repo("tests/fixtures/public-small")
}

/// A whole number from environment variable `name` (a soak test's
/// count or seed), or `None` where it is not set; panics naming the
/// variable where it is not a whole number.
pub fn env_u64(name: &str) -> Option<u64> {
    std::env::var(name).ok().map(|v| {
        v.trim()
            .parse()
            .unwrap_or_else(|_| panic!("{name}={v}: expected a whole number"))
    })
}

/// A file of the repository.
pub fn repo(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(path)
}

/// Runs the `mfd` binary with `args`, fails the test with what it printed
/// unless it succeeds, and returns its standard output and error.
pub fn mfd_ok(args: &[&str]) -> String {
    let out = mfd(args);
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "mfd {args:?} failed:\n{text}");
    text
}

/// Runs the `mfd` binary with `args`: its exit status (-1 for a signal)
/// and what it printed, standard output then error.
pub fn mfd_status(args: &[&str]) -> (i32, String) {
    let out = mfd(args);
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.code().unwrap_or(-1), text)
}

/// Runs the `mfd` binary with `args` and returns what it did.
/// A finished command's stdout and stderr together, as text (what an
/// assertion message shows).
pub fn output_text(out: &std::process::Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

pub fn mfd(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_mfd"))
        .args(args)
        .output()
        .unwrap()
}

/// The patterns that show `frames` (a schedule file's or a design's), in
/// their order.
pub fn patterns_of(
    frames: &[mfd::acquire::acquisition::FrameInfo],
) -> Vec<mfd::acquire::patterns::Pattern> {
    frames
        .iter()
        .map(|f| mfd::acquire::patterns::Pattern {
            direction_deg: f.direction_deg,
            tau: f.tau,
            phase_rad: f.phase_rad,
        })
        .collect()
}

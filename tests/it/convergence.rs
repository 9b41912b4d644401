//! Issue 40, the solver's part: a stage stopped by its iteration limit is
//! said and flagged (exit 5 unless accepted), a converged one is not; the
//! same inputs give the same surfaces bit for bit; a one-surface element
//! (the back reflection absent) gets its terms chosen by the criterion.
//!
//! On the public-small fixture's traced truth (`truth_screen_coords.npy`,
//! noise-free, from a 36-term front and back) with the Cramér–Rao σ
//! (`crb_screen_std.npy`) as the points' σ (see `truth`).

use std::path::{Path, PathBuf};

use crate::common::{self, mfd};
use mfd::formats::npy::{read_f64, write_f64};

fn fixture(path: &str) -> PathBuf {
    common::public_small().join(path)
}

/// `mfd reconstruct` of the screen points `coords` (σ `std`) on the
/// fixture's station into `out`, with `extra` options.
fn reconstruct(coords: &Path, std: &Path, out: &Path, extra: &[&str]) -> (Option<i32>, String) {
    let station = fixture("station.toml");
    let mut args = vec![
        "reconstruct",
        "--screen-coords",
        coords.to_str().unwrap(),
        "--screen-std",
        std.to_str().unwrap(),
        "--station",
        station.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let o = mfd(&args);
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    (o.status.code(), text)
}

/// The fixture's traced points and their Cramér–Rao σ (`[rows, columns,
/// reflection]`, the same σ for u and v) in the spec's `[rows, columns, 2,
/// 2]` layout, written into `dir`; with `front_only`, the back reflection
/// removed. A point without a finite σ is left out.
fn truth(dir: &Path, front_only: bool) -> (PathBuf, PathBuf) {
    let (shape, mut c) = read_f64(&fixture("truth/truth_screen_coords.npy")).unwrap();
    let (_, crb) = read_f64(&fixture("truth/crb_screen_std.npy")).unwrap();
    let mut std = vec![f64::NAN; c.len()];
    for (k, (px, sd)) in c.chunks_mut(4).zip(std.chunks_mut(4)).enumerate() {
        for r in 0..2 {
            let sigma = crb[2 * k + r];
            if !sigma.is_finite() || (front_only && r == 1) {
                px[2 * r..2 * r + 2].fill(f64::NAN);
            } else {
                sd[2 * r..2 * r + 2].fill(sigma);
            }
        }
    }
    let (coords, std_path) = (dir.join("coords.npy"), dir.join("std.npy"));
    write_f64(&coords, &shape, &c).unwrap();
    write_f64(&std_path, &shape, &std).unwrap();
    (coords, std_path)
}

fn summary(out: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(out.join("summary.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

/// The back stage with one trial step (`--max-iter 2`: the start's build
/// and one step) from the nominal flat back, with no joint stage after it:
/// the step is the back's whole departure (60 nm RMS of terms 4–36), far
/// beyond the coefficients' σ at the Cramér–Rao points (sub-nm), so the
/// stage is said, flagged in summary.json, and exits 5; with
/// `--accept-unconverged` it exits 0 and is still flagged.
#[test]
fn a_stage_stopped_by_its_limit_is_said_and_flagged() {
    let dir = tempfile::tempdir().unwrap();
    let (coords, std) = truth(dir.path(), false);
    let out = dir.path().join("limited");
    let limited = ["--terms", "36", "--no-joint", "--max-iter", "2"];
    let (code, text) = reconstruct(&coords, &std, &out, &limited);
    // 5: flagged (src/cli/exit.rs).
    assert_eq!(code, Some(5), "{text}");
    assert!(
        text.contains("back: stopped by iteration limit 2")
            && text.contains("--accept-unconverged"),
        "{text}"
    );
    let s = summary(&out);
    let conv = s["convergence"].as_array().unwrap();
    let back = conv.iter().find(|c| c["stage"] == "back").unwrap();
    assert_eq!(back["converged"], false, "{back}");
    assert_eq!(back["flags_result"], true, "{back}");
    assert_eq!(back["stopped_by"], "iteration limit 2", "{back}");
    let step = back["last_step_nm"].as_f64().unwrap();
    let sigma = back["sigma_nm"].as_f64().unwrap();
    assert!(step > sigma && sigma > 0.0, "{back}");

    let (code, text) = reconstruct(
        &coords,
        &std,
        &out,
        &[&limited[..], &["--accept-unconverged"]].concat(),
    );
    assert_eq!(code, Some(0), "{text}");
    assert!(
        text.contains("not converged, the result is flagged"),
        "{text}"
    );
    assert!(summary(&out)["convergence"]
        .as_array()
        .unwrap()
        .iter()
        .any(|c| c["flags_result"] == true));
}

/// The default settings on the same points: every stage that decides the
/// result converged, nothing flagged, exit 0; and a second run on the same
/// inputs writes the same surfaces.json, byte for byte.
#[test]
fn a_converged_solve_is_not_flagged_and_repeats_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let (coords, std) = truth(dir.path(), false);
    let [a, b] = [dir.path().join("a"), dir.path().join("b")];
    let (code, text) = reconstruct(&coords, &std, &a, &[]);
    assert_eq!(code, Some(0), "{text}");
    let s = summary(&a);
    let conv = s["convergence"].as_array().unwrap();
    assert!(conv.iter().all(|c| c["flags_result"] == false), "{conv:?}");
    let last = conv.last().unwrap();
    assert!(
        last["stage"].as_str().unwrap().starts_with("joint") && last["converged"] == true,
        "{conv:?}"
    );
    let (code, text) = reconstruct(&coords, &std, &b, &[]);
    assert_eq!(code, Some(0), "{text}");
    let [fa, fb] = [&a, &b].map(|d| std::fs::read(d.join("surfaces.json")).unwrap());
    assert!(
        fa == fb,
        "two runs on the same inputs wrote different surfaces.json"
    );
}

/// The whole chain from frames (spectral stage, surface-domain fit) twice
/// on the fixture's acquisition: the same surfaces.json and screen points,
/// byte for byte.
#[test]
fn the_chain_from_frames_repeats_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let acq = common::public_small();
    let runs = [dir.path().join("a"), dir.path().join("b")].map(|out| {
        let o = mfd(&[
            "reconstruct",
            acq.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--accept-inconsistent",
            "--accept-unconverged",
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        out
    });
    for f in ["surfaces.json", "screen_coords.npy"] {
        let [a, b] = [&runs[0], &runs[1]].map(|d| std::fs::read(d.join(f)).unwrap());
        assert!(a == b, "{f} differs between two runs on the same frames");
    }
}

/// A one-surface element: the fixture's points with the back reflection
/// removed (a mirror, an AR-coated back). The front's terms are chosen by
/// the same BIC as a plate's: the truth is 36 terms and the points are
/// noise-free, so every smaller model leaves χ² far above the penalty
/// (ln N per term) and every larger one lowers it by rounding only — the
/// choice is 36 exactly, refitted ("joint (chosen terms)"), and the summary
/// names the criterion, not `--terms`.
#[test]
fn a_one_surface_element_gets_its_terms_chosen() {
    let dir = tempfile::tempdir().unwrap();
    let (coords, std) = truth(dir.path(), true);
    let out = dir.path().join("mirror");
    let (code, text) = reconstruct(&coords, &std, &out, &[]);
    assert_eq!(code, Some(0), "{text}");
    let s = summary(&out);
    let terms = &s["terms"];
    assert!(
        terms["criterion"].as_str().unwrap().starts_with("BIC"),
        "{terms}"
    );
    assert_eq!(terms["front"]["terms"], 36, "{terms}");
    assert!(
        terms.get("back").is_none() && s["back"].is_null(),
        "{terms}"
    );
    let stages: Vec<&str> = s["stages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|st| st["name"].as_str().unwrap())
        .collect();
    assert!(stages.contains(&"joint (chosen terms)"), "{stages:?}");
    assert_eq!(s["front"]["terms"], 36, "{}", s["front"]);
}

/// A flat mirror rendered from frames (`mfd simulate --display-gamma`: the
/// front reflection alone, phase-shifting on an unlinearised display) and
/// reconstructed: the front's terms are chosen by the criterion, not kept
/// at `--max-terms`. The truth is a plane (3 terms); a larger model is
/// chosen only when its extra terms lower χ² by more than their penalty,
/// ln N ≈ 7.8 each (N ≈ 2400 slopes) — for 3 terms of pure noise
/// P(χ²₃ > 23) ≈ 4e-5 — so the choice is the plane.
#[test]
fn a_mirror_from_frames_gets_its_terms_chosen() {
    let dir = tempfile::tempdir().unwrap();
    let (acq, out) = (dir.path().join("acq"), dir.path().join("res"));
    let station = fixture("station.toml");
    common::mfd_ok(&[
        "simulate",
        "--station",
        station.to_str().unwrap(),
        "--display-gamma",
        "2.2",
        "--phases",
        "0,1.5707963,3.1415927,4.712389",
        "--tau-start",
        "1",
        "--tau-stop",
        "16",
        "--tau-step",
        "1",
        "--out",
        acq.to_str().unwrap(),
    ]);
    let text = common::mfd_ok(&[
        "reconstruct",
        acq.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(text.contains("back: not reconstructed"), "{text}");
    let s = summary(&out);
    let terms = &s["terms"];
    assert!(
        terms["criterion"].as_str().unwrap().starts_with("BIC"),
        "{terms}"
    );
    assert_eq!(terms["front"]["terms"], 3, "{terms}");
    assert!(terms.get("back").is_none(), "{terms}");
}

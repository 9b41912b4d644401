//! Surface solvers against the independent fixture `public-small`: its
//! truth surfaces and its own Cramér–Rao bound (`truth/crb.json`).

use crate::common;

use mfd::acquire::acquisition::Acquisition;
use mfd::formats::npy;
use mfd::formats::surfaces_file::{to_surface, SurfacesFile};
use mfd::optics::station::Station;
use mfd::optics::trace::{Plate, TracedView};
use mfd::pipeline;
use mfd::report::metrics::rms_difference_nm;
use mfd::report::summary::Summary;
use mfd::solve::spectral::bound::two_reflection_cov;
use mfd::solve::spectral::{SpectralConfig, SpectralSolver};
use mfd::solve::surfaces::{reconstruct, Observations, SurfaceOptions, Uncertainty};

fn crb_json() -> serde_json::Value {
    let text = std::fs::read_to_string(common::public_small().join("truth/crb.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

fn truth() -> SurfacesFile {
    SurfacesFile::load(&common::public_small().join("truth/truth_surfaces.json")).unwrap()
}

fn scene_f64(key: &str) -> f64 {
    let text = std::fs::read_to_string(common::public_small().join("truth/scene.json")).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v[key].as_f64().unwrap()
}

/// Our surface bound from the fixture's per-pixel σ against the fixture's
/// own bound (front and back Noll 2–36 unknown, RMS over j = 4–36).
///
/// The fixture publishes each pixel's σ (sqrt(var u + var v), var u = var v)
/// but not the correlation of its S1 and S2 errors, which the back bound
/// depends on; we take that correlation from our own spectral bound at the
/// truth (median +0.26 for u1–u2). Measured: front 17.84 nm against 17.77
/// (+0.4 %), back 17.03 against 18.75 (−9 %); without any correlation
/// 18.25 and 16.05. The front is therefore held to 2 %, the back only to
/// lie between the two published-information extremes widened by 5 %.
#[test]
fn our_surface_bound_matches_the_fixture_bound() {
    let dir = common::public_small();
    let station = Station::load(&dir.join("station.toml")).unwrap();
    let acq = Acquisition::open(&dir).unwrap();
    let solver = SpectralSolver::new(&station, acq.frames(), SpectralConfig::default()).unwrap();
    let t = truth();
    let plate = Plate::new(
        &station,
        to_surface(&t, t.front_coefficients()).unwrap(),
        to_surface(&t, t.back_coefficients()).unwrap(),
        3.0,
    );
    let view = TracedView::trace(&station, &plate);
    let (_, combined) = npy::read_f64(&dir.join("truth/crb_screen_std.npy")).unwrap();
    let (gain, noise, tau_max) = (
        scene_f64("gain"),
        scene_f64("noise_sigma_counts"),
        scene_f64("tau_max"),
    );
    let mut cov = vec![f64::NAN; view.pixels.len() * 16];
    for (q, px) in view.pixels.iter().enumerate() {
        let sd = [combined[2 * q], combined[2 * q + 1]].map(|s| s / std::f64::consts::SQRT_2);
        let c = &mut cov[16 * q..16 * q + 16];
        let (Ok(s1), Ok(s2)) = (px.front, px.back) else {
            c[0] = sd[0] * sd[0];
            c[5] = sd[0] * sd[0];
            continue;
        };
        let ours = two_reflection_cov(
            solver.design(),
            [[s1.u, s1.v], [s2.u, s2.v]],
            gain * (0.01 + 0.5 * (s1.weight + s2.weight)),
            [0.5 * gain * s1.weight, 0.5 * gain * s2.weight],
            tau_max.powi(-2),
            noise,
        )
        .unwrap();
        let s = [sd[0], sd[0], sd[1], sd[1]];
        for a in 0..4 {
            for b in 0..4 {
                let rho = ours[a][b] / (ours[a][a] * ours[b][b]).sqrt();
                c[4 * a + b] = rho * s[a] * s[b];
            }
        }
    }
    let coords = view.screen_coords();
    let obs = Observations::from_maps(&station, &coords, Uncertainty::Cov(&cov)).unwrap();
    let opts = SurfaceOptions {
        terms: Some(36),
        covariance_smoothing_px: 0,
        ..SurfaceOptions::default()
    };
    let sol = reconstruct(&obs, &station, &opts).unwrap();
    let crb = crb_json();
    let rms = |s: &[f64]| s[3..].iter().map(|x| x * x).sum::<f64>().sqrt();
    let (front, back) = (rms(&sol.front_std_nm), rms(&sol.back_std_nm));
    let (f_ref, b_ref) = (
        crb["front_rms_nm"].as_f64().unwrap(),
        crb["back_rms_nm"].as_f64().unwrap(),
    );
    println!(
        "bound: front {front:.2} nm (fixture {f_ref:.2}), back {back:.2} nm (fixture {b_ref:.2})"
    );
    assert!(
        (front / f_ref - 1.0).abs() < 0.02,
        "front {front} vs {f_ref}"
    );
    assert!(
        back > 0.95 * 16.05 && back < 1.05 * b_ref,
        "back {back} vs {b_ref}"
    );
}

/// The whole chain on the fixture's frames, through the library pipeline:
/// spectral solver, then surfaces with the term count chosen from the data.
/// The issue asks for errors within 2× the acquisition's bound; measured
/// 17.4 nm (front, bound 17.8) and 14.9 nm (back, bound 18.7). The
/// solution's own uncertainty must cover its error the same way: error ≤ 2 ×
/// reported. The result folder holds every file, and `summary.json` reads
/// back as the summary that was written.
#[test]
fn fixture_frames_reconstruct_within_twice_the_bound() {
    let dir = common::public_small();
    let station = Station::load(&dir.join("station.toml")).unwrap();
    let mut acq = Acquisition::open(&dir).unwrap();
    let options = pipeline::Options {
        surfaces: Some(SurfaceOptions::default()),
        ..pipeline::Options::default()
    };
    let n_frames = acq.frames().len();
    let mut frames_seen = 0;
    let rec = pipeline::reconstruct(
        pipeline::Input::Acquisition(&mut acq),
        &station,
        &options,
        &mut |done, total| {
            assert_eq!(total, n_frames);
            frames_seen = done;
        },
    )
    .unwrap();
    assert_eq!(frames_seen, n_frames, "progress saw every frame");
    let stage = rec.surfaces.as_ref().unwrap().as_ref().unwrap();
    let sol = &stage.solution;
    let t = truth();
    let crb = crb_json();
    let figures = [&stage.summary.front, stage.summary.back.as_ref().unwrap()];
    for (k, (name, coeffs, truth)) in [
        (
            "front",
            sol.front.coefficients_nm(),
            t.front_coefficients().unwrap(),
        ),
        (
            "back",
            sol.back.coefficients_nm(),
            t.back_coefficients().unwrap(),
        ),
    ]
    .into_iter()
    .enumerate()
    {
        let err = rms_difference_nm(coeffs, truth);
        let bound = crb[format!("{name}_rms_nm")].as_f64().unwrap();
        let reported = figures[k].error_rms_nm;
        println!(
            "{name}: {} terms, error {err:.2} nm, fixture bound {bound:.2}, reported {reported:.2}",
            coeffs.len()
        );
        assert!(err < 2.0 * bound, "{name}: {err} nm vs bound {bound}");
        assert!(
            err < 2.0 * reported,
            "{name}: {err} nm vs reported {reported}"
        );
    }
    let out = tempfile::tempdir().unwrap();
    let written = rec.write(out.path()).unwrap();
    for name in [
        "screen_coords.npy",
        "screen_cov.npy",
        "flags.npy",
        "surfaces.json",
        "front_height_nm.npy",
        "back_height_nm.npy",
        "front.png",
        "back_coefficients.png",
        "summary.json",
    ] {
        assert!(out.path().join(name).is_file(), "{name} missing");
    }
    assert!(written.contains(&out.path().join("summary.json")));
    let text = std::fs::read_to_string(out.path().join("summary.json")).unwrap();
    let back: Summary = serde_json::from_str(&text).unwrap();
    assert_eq!(
        serde_json::to_value(&back).unwrap(),
        serde_json::to_value(&stage.summary).unwrap(),
        "summary.json reads back as written"
    );
    assert_eq!(back.format, "mfd-summary/1");
    assert_eq!(back.pixels.s1, stage.summary.pixels.s1);
}

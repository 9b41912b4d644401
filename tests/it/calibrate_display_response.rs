//! A display's measured response curve (a display profile's `response`)
//! in the short phase-shifting decode of the reference flat: issue 14's
//! 32-frame acquisition (τ = 1, 4, 16, 64 × four steps × ±45°, 8-bit) of a
//! mirror on a display whose response is no power law, decoded with the
//! measured table, against the truth, the Cramér–Rao bound and the ripple
//! a best-fit gamma leaves; and the profile reader's checks of the table.

use crate::common;

use mfd::acquire::acquisition::FrameInfo;
use mfd::optics::station::{DisplayProfile, Station};
use mfd::optics::trace::{Plate, TracedView};
use mfd::optics::zernike::ZernikeSurface;
use mfd::sim::{phase_shift_patterns, Luminance, PhaseShiftParams, PhaseShiftRenderer};
use mfd::solve::spectral::phase::{profile_response, PhaseModel, Response, ResponseCurve};
use mfd::solve::spectral::{nominal_plate_prior, SpectralConfig, SpectralSolver};

const TAUS: [f64; 4] = [1.0, 4.0, 16.0, 64.0];

/// A measured-looking S-curve: a power law blended with a smoothstep (a
/// panel with its own tone curve), monotone on [0, 1], 1 at full drive.
fn s_curve(g: f64) -> f64 {
    0.6 * g.powf(2.4) + 0.4 * (3.0 * g * g - 2.0 * g * g * g)
}

const S_CURVE: Luminance = Luminance {
    name: "S-curve",
    at: s_curve,
};

/// What a photometer gives: 17 levels of an 8-bit drive, in cd/m² to
/// 0.01 (a 180 cd/m² panel).
fn measured_rows() -> Vec<[f64; 2]> {
    (0..17)
        .map(|k| {
            let level = (255.0 * k as f64 / 16.0).round();
            [
                level,
                (180.0 * s_curve(level / 255.0) * 100.0).round() / 100.0,
            ]
        })
        .collect()
}

/// The gamma a lab without the table would put in the profile: the least
/// squares power law through the same rows (golden-section search).
fn best_fit_gamma(rows: &[[f64; 2]]) -> f64 {
    let full = rows[rows.len() - 1];
    let cost = |g: f64| -> f64 {
        rows.iter()
            .map(|[l, y]| ((l / full[0]).powf(g) - y / full[1]).powi(2))
            .sum()
    };
    let (mut a, mut b) = (1.0, 4.0);
    let r = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..100 {
        let (c, d) = (b - r * (b - a), a + r * (b - a));
        if cost(c) < cost(d) {
            b = d;
        } else {
            a = c;
        }
    }
    0.5 * (a + b)
}

struct Outcome {
    expected: usize,
    decoded: usize,
    rms_error: f64,
    rms_bound: f64,
    rms_z: f64,
    ripple_px: f64,
}

fn run(params: PhaseShiftParams, gamma: Option<f64>, curve: Option<ResponseCurve>) -> Outcome {
    let station = Station::load(&common::public_small().join("station.toml")).unwrap();
    let e = &station.element;
    let flat = ZernikeSurface::flat(
        e.aperture_radius_mm,
        [e.aperture_center_mm.x, e.aperture_center_mm.y],
    )
    .unwrap();
    let view = TracedView::trace(&station, &Plate::new(&station, flat.clone(), flat, 0.0));
    let cam = PhaseShiftRenderer::new(&view, &station.screen, params).unwrap();
    let patterns = phase_shift_patterns(&[45.0, -45.0], &TAUS, 4);
    let config = SpectralConfig {
        display_gamma: gamma,
        display_response: curve,
        ..SpectralConfig::default()
    };
    let frames = FrameInfo::from_patterns(&patterns);
    let prior = nominal_plate_prior(&station, config.edge_margin_mm).unwrap();
    let mut solver = SpectralSolver::with_prior(&station, &frames, config, prior).unwrap();
    let mut buf = vec![0u16; station.camera.pixel_count()];
    for (k, p) in patterns.iter().enumerate() {
        cam.render(p, k as u64, &mut buf);
        solver.push_frame(k, &buf).unwrap();
    }
    let maps = solver.solve().unwrap();
    let (schedule, response) = solver.phase_schedule().expect("a phase-shifting schedule");
    let model = PhaseModel {
        design: solver.design(),
        schedule,
        response,
    };
    let d = common::phase::score(&view, &maps, &model, &cam, &patterns);
    Outcome {
        expected: d.expected,
        decoded: d.decoded,
        rms_error: d.rms_error,
        rms_bound: d.rms_bound,
        rms_z: d.rms_z,
        ripple_px: common::phase::ripple_px(&station, &d.errors, TAUS[3]),
    }
}

fn report(name: &str, o: &Outcome) {
    eprintln!(
        "{name}: decoded {}/{} ({:.2} %), RMS error {:.4} px, bound {:.4} px, ratio {:.3}, \
         RMS(err/σ) {:.3}, ripple {:.5} px",
        o.decoded,
        o.expected,
        100.0 * o.decoded as f64 / o.expected as f64,
        o.rms_error,
        o.rms_bound,
        o.rms_error / o.rms_bound,
        o.rms_z,
        o.ripple_px
    );
}

#[test]
fn a_measured_response_decodes_at_the_bound() {
    let params = PhaseShiftParams {
        luminance: Some(S_CURVE),
        ..PhaseShiftParams::default()
    };
    let rows = measured_rows();
    let curve = ResponseCurve::new(&rows).unwrap();
    let o = run(params.clone(), None, Some(curve));
    report("S-curve, measured table modelled", &o);
    // The same frames decoded with the best-fit gamma: the ripple at the
    // finest fringe is larger (noise-free, 0.05 px against 0.006 px; the
    // noise adds about 2σ/√N ≈ 0.01 px to each component either way).
    let g = run(params, Some(best_fit_gamma(&rows)), None);
    report("S-curve, best-fit γ modelled", &g);
    assert!(
        o.ripple_px < g.ripple_px,
        "{} px against {} px",
        o.ripple_px,
        g.ripple_px
    );
    // The criteria: ≥ 99 % decoded, within 1.5× the bound.
    assert!(o.decoded as f64 >= 0.99 * o.expected as f64);
    assert!(o.rms_error <= 1.5 * o.rms_bound);
    // err/σ: RMS(z) scatters by 1/√(2N) (two coordinates of a pixel taken
    // as one independent value): 4 of those.
    let tol = 4.0 / (2.0 * o.decoded as f64).sqrt();
    assert!(
        (o.rms_z - 1.0).abs() <= tol,
        "RMS(err/σ) {} ± {tol}",
        o.rms_z
    );
}

#[test]
fn a_measured_response_removes_the_ripple_a_best_fit_gamma_leaves() {
    // Noise-free and 16-bit, so that what is left is the model's, and a
    // Gaussian blur only (which the model's per-group κ represents
    // exactly), so that what is left is the response's. The
    // best-fit gamma (1.65 through the table) has ρ₃ = c₃/c₁ of −0.013
    // against the S-curve's −0.035; four steps alias harmonic 3 onto the
    // first, biasing each τ's phase by ~Δρ₃ M₃/M₁ sin 4x: at τ = 64 (31 px
    // a period, M₃/M₁ ≥ 0.15 here) at least Δρ₃ · 0.15 · 31 / 2π px. The
    // 17-row table gives ρ₃ to 2e-4 (its interpolation error), a hundred
    // times closer: the ripple must fall at least tenfold.
    let params = PhaseShiftParams {
        luminance: Some(S_CURVE),
        bit_depth: 16,
        read_noise_counts: 0.0,
        full_well_electrons: None,
        falloff_per_period: Vec::new(),
        ..PhaseShiftParams::default()
    };
    let rows = measured_rows();
    let curve = ResponseCurve::new(&rows).unwrap();
    let gamma = best_fit_gamma(&rows);
    let with = run(params.clone(), None, Some(curve.clone()));
    let fitted = run(params.clone(), Some(gamma), None);
    report("noise-free S-curve, table modelled", &with);
    report(
        &format!("noise-free S-curve, best-fit γ {gamma:.3}"),
        &fitted,
    );
    assert!(with.decoded == with.expected);
    let rho3 = |r: &Response| r.ratios[2];
    let truth = Response::from_curve(&ResponseCurve::new(&exact_rows()).unwrap());
    let d_rho3 = (rho3(&Response::new(gamma).unwrap()) - rho3(&truth)).abs();
    let table_rho3 = (rho3(&Response::from_curve(&curve)) - rho3(&truth)).abs();
    eprintln!(
        "ρ₃ off by {d_rho3:.2e} (best-fit γ) and {table_rho3:.2e} (table); ripple {:.5} px with \
         the table, {:.5} px with γ",
        with.ripple_px, fitted.ripple_px
    );
    let period_px = 1980.0 / TAUS[3];
    assert!(fitted.ripple_px >= d_rho3 * 0.15 * period_px / std::f64::consts::TAU);
    assert!(with.ripple_px * 10.0 <= fitted.ripple_px);
    // The noise-free bound, 0.01 screen px, holds with the table.
    assert!(with.rms_error <= 0.01, "{}", with.rms_error);
    // With the default blur's exponential falloff per direction (not
    // Gaussian in the harmonic's order, so the model's κ leaves a floor of
    // its own): the table still leaves less ripple than the gamma.
    let blur = PhaseShiftParams {
        falloff_per_period: PhaseShiftParams::default().falloff_per_period,
        ..params
    };
    let with_blur = run(blur.clone(), None, Some(curve));
    let fitted_blur = run(blur, Some(gamma), None);
    report("noise-free S-curve, falloff, table", &with_blur);
    report("noise-free S-curve, falloff, best-fit γ", &fitted_blur);
    assert!(with_blur.ripple_px < fitted_blur.ripple_px);
    assert!(with_blur.rms_error <= 0.01, "{}", with_blur.rms_error);
}

/// The S-curve on 1025 rows: its interpolant is the curve to 1e-9, the
/// reference for the harmonic ratios.
fn exact_rows() -> Vec<[f64; 2]> {
    (0..=1024)
        .map(|k| {
            let g = k as f64 / 1024.0;
            [g, s_curve(g)]
        })
        .collect()
}

#[test]
fn display_profiles_carry_a_checked_response() {
    let dir = tempfile::tempdir().unwrap();
    let head = "format = \"mfd-display-profile/1\"\nmodel = \"test\"\nresolution = [1600, 1200]\n\
                pixel_pitch_mm = 0.27\ndiagonal_in = 21.3\ngamma = 2.2\nsettle_ms = 30.0\n";
    // Gamma only: valid as ever, no curve.
    let (p, curve) = profile_response(&common::repo("hw/display/mtiph-e2m21gm.toml")).unwrap();
    assert!(p.response.is_none() && curve.is_none());
    // The example profile in hw/display/ (sRGB's curve at 17 levels): its
    // interpolant is sRGB's to the monotone cubic's error: a tenth of
    // piecewise linear's h² max L''/8 = 1.5e-3 at h = 1/16 (L'' ≤ 3.02),
    // as in the curve's unit test; the table's rounding to 0.01 cd/m² adds
    // 2e-5 of full scale.
    let (_, curve) =
        profile_response(&common::repo("hw/display/example-measured-response.toml")).unwrap();
    let curve = curve.expect("the example has a response");
    let srgb = |g: f64| ((g + 0.055) / 1.055).powf(2.4);
    for g in [0.3, 0.5, 0.8] {
        assert!(
            (curve.at(g) - srgb(g)).abs() < 1.7e-4,
            "{g}: {}",
            curve.at(g)
        );
    }
    // A measured table reads back as the curve.
    let rows = measured_rows()
        .iter()
        .map(|[l, y]| format!("[{l}, {y}]"))
        .collect::<Vec<_>>()
        .join(", ");
    let good = dir.path().join("good.toml");
    std::fs::write(&good, format!("{head}response = [{rows}]\n")).unwrap();
    let (_, curve) = profile_response(&good).unwrap();
    let curve = curve.unwrap();
    assert!((curve.at(0.5) - s_curve(0.5)).abs() < 1e-3);
    // A table that falls: the error names the file, the field and the row.
    let bad = dir.path().join("falls.toml");
    std::fs::write(
        &bad,
        format!("{head}response = [[0, 0.2], [64, 9.0], [128, 8.5], [255, 180]]\n"),
    )
    .unwrap();
    let e = profile_response(&bad).unwrap_err().to_string();
    assert!(
        e.contains("falls.toml") && e.contains("response") && e.contains("row 2"),
        "{e}"
    );
    // A row of three values (toml would not complain): named too.
    let three = dir.path().join("three.toml");
    std::fs::write(
        &three,
        format!("{head}response = [[0, 0.2], [128, 9, 1], [255, 180]]\n"),
    )
    .unwrap();
    let e = DisplayProfile::load(&three).unwrap_err().to_string();
    assert!(e.contains("three.toml") && e.contains("row 1"), "{e}");
}

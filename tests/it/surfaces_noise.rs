//! Surfaces from noisy simulated acquisitions against the Cramér–Rao bound
//! of the acquisition: the per-pixel bound of the spectral model at the
//! truth (`spectral::bound::truth_cov_map`), propagated through the exact
//! Jacobian of the optics at the true surfaces into the coefficients.

use crate::common;

use mfd::acquire::acquisition::FrameInfo;
use mfd::acquire::patterns::Schedule;
use mfd::optics::station::Station;
use mfd::optics::trace::{Plate, TracedView};
use mfd::report::metrics::rms_difference_nm;
use mfd::sim::{RandomSurfaceSpec, Renderer, SimParams};
use mfd::solve::spectral::bound::truth_cov_map;
use mfd::solve::spectral::{SpectralConfig, SpectralSolver};
use mfd::solve::surfaces::report::figures;
use mfd::solve::surfaces::{reconstruct, Observations, SurfaceOptions, Uncertainty};

struct Outcome {
    error: [f64; 2],
    bound: [f64; 2],
    reported: [f64; 2],
}

fn run(seed: u64, terms: Option<usize>) -> Outcome {
    let station = Station::load(&common::public_small().join("station.toml")).unwrap();
    let (front, back) = RandomSurfaceSpec::default()
        .draw_pair(25.5, [0.0, 0.0], seed)
        .unwrap();
    let view = TracedView::trace(
        &station,
        &Plate::new(&station, front.clone(), back.clone(), 3.0),
    );
    let schedule = Schedule {
        tau_start: 0.5,
        tau_stop: 100.0,
        tau_step: 0.5,
        ..Schedule::default()
    };
    let params = SimParams {
        noise_frac: 0.02,
        seed: seed + 100,
        ..SimParams::default()
    };
    let patterns = schedule.patterns();
    let mut cam = Renderer::new(&view, &station.screen, params.clone()).unwrap();
    let frames = FrameInfo::from_patterns(&patterns);
    let mut solver = SpectralSolver::new(&station, &frames, SpectralConfig::default()).unwrap();
    let mut buf = vec![0u16; station.camera.pixel_count()];
    for (k, p) in patterns.iter().enumerate() {
        cam.render(p, k as u64, &mut buf);
        solver.push_frame(k, &buf).unwrap();
    }
    let maps = solver.solve().unwrap();
    let (coords, cov) = (maps.screen_coords(), maps.screen_cov());
    let obs = Observations::from_maps(&station, &coords, Uncertainty::Cov(&cov)).unwrap();
    let opts = SurfaceOptions {
        terms,
        ..SurfaceOptions::default()
    };
    let sol = reconstruct(&obs, &station, &opts).unwrap();
    // The bound: the same unknowns (36 terms) at the truth, with the
    // spectral bound at the truth as the covariance of every pixel.
    let sigma = params.noise_frac * params.full_scale();
    let crb = truth_cov_map(
        solver.design(),
        &view,
        cam.gain(),
        params.ambient,
        params.tau_max.powi(-2),
        sigma,
    );
    let truth = view.screen_coords();
    let obs_t = Observations::from_maps(&station, &truth, Uncertainty::Cov(&crb)).unwrap();
    let at_truth = SurfaceOptions {
        terms: Some(36),
        covariance_smoothing_px: 0,
        ..SurfaceOptions::default()
    };
    let bound_sol = reconstruct(&obs_t, &station, &at_truth).unwrap();
    Outcome {
        error: [
            rms_difference_nm(sol.front.coefficients_nm(), front.coefficients_nm()),
            rms_difference_nm(sol.back.coefficients_nm(), back.coefficients_nm()),
        ],
        bound: [
            figures(&bound_sol, false).error_rms_nm,
            figures(&bound_sol, true).error_rms_nm,
        ],
        reported: [
            figures(&sol, false).error_rms_nm,
            figures(&sol, true).error_rms_nm,
        ],
    }
}

/// Over three acquisitions (10 mm plate, 2 % noise, 400 frames), the RMS
/// error of each surface is within 2× its bound (the criterion;
/// measured ≈ 1.0× over 8 acquisitions once the weights no longer depend on
/// each pixel's own noise, see `Observations::smoothed_covariance`), and the
/// uncertainty the solver reports is the bound to within 25 % (it is
/// evaluated at the fitted, not the true, points and amplitudes).
#[test]
fn noisy_surfaces_reach_the_bound() {
    let runs: Vec<Outcome> = (1..=3).map(|s| run(s, Some(36))).collect();
    for k in 0..2 {
        let ms = |f: &dyn Fn(&Outcome) -> f64| {
            (runs.iter().map(|r| f(r).powi(2)).sum::<f64>() / runs.len() as f64).sqrt()
        };
        let (err, bound, rep) = (
            ms(&|r| r.error[k]),
            ms(&|r| r.bound[k]),
            ms(&|r| r.reported[k]),
        );
        println!("surface {k}: RMS error {err:.2} nm, bound {bound:.2} nm, reported {rep:.2} nm");
        assert!(err < 2.0 * bound, "surface {k}: {err} vs bound {bound}");
        assert!(
            (rep / bound - 1.0).abs() < 0.25,
            "surface {k}: reported {rep} vs bound {bound}"
        );
    }
}

/// With the term count chosen by BIC (up to 66), the surfaces stay within
/// 2× the 36-term bound: terms whose coefficients the noise hides are
/// dropped, which costs less than fitting them.
#[test]
fn chosen_terms_stay_within_twice_the_bound() {
    let r = run(4, None);
    for k in 0..2 {
        println!(
            "surface {k}: error {:.2} nm, bound {:.2} nm",
            r.error[k], r.bound[k]
        );
        assert!(r.error[k] < 2.0 * r.bound[k]);
    }
}

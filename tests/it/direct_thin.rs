//! The surface-domain estimator (`solve::direct`) through the pipeline, on
//! rendered frames of the paper's schedule at 5 % noise (48×48 bench
//! station): a 3 mm plate that the per-pixel route cannot measure at all,
//! and a 10 mm plate it measures (where `auto` keeps the per-pixel route,
//! and the surface-domain fit asked for agrees with it); each surface's error against the
//! surfaces' Cramér–Rao bound of the acquisition and against what the
//! result reports.

use mfd::acquire::acquisition::FrameInfo;
use mfd::acquire::patterns::Schedule;
use mfd::budget::scene::{scene, Radiometry, SceneOptions};
use mfd::optics::station::{bench_station, Station};
use mfd::optics::trace::{Plate, TracedView};
use mfd::optics::zernike::ZernikeSurface;
use mfd::pipeline::{self, Estimator, Input, Options, SurfaceStage};
use mfd::report::metrics::rms_difference_nm;
use mfd::sim::{RandomSurfaceSpec, Renderer, SimParams};
use mfd::solve::spectral::{SpectralConfig, SpectralSolver};
use mfd::solve::surfaces::report::figures;
use mfd::solve::surfaces::{SurfaceError, SurfaceOptions};

const TERMS: usize = 15;
const NOISE: f64 = 0.05;

struct Case {
    station: Station,
    truth: (ZernikeSurface, ZernikeSurface),
    frames: Vec<FrameInfo>,
}

fn case(thickness_mm: f64, index: f64) -> Case {
    let station = bench_station(thickness_mm, index, 15.0).unwrap();
    let spec = RandomSurfaceSpec {
        n_terms: TERMS,
        ..RandomSurfaceSpec::default()
    };
    let e = &station.element;
    let centre = [e.aperture_center_mm.x, e.aperture_center_mm.y];
    let truth = spec.draw_pair(e.aperture_radius_mm, centre, 31).unwrap();
    let frames = FrameInfo::from_patterns(&Schedule::default().patterns());
    Case {
        station,
        truth,
        frames,
    }
}

/// The frames of `c` rendered with `seed` and streamed into a solver, the
/// third path (two internal round trips) rendered when `third`.
fn solver_with(c: &Case, seed: u64, third: bool) -> SpectralSolver {
    let plate = Plate::new(&c.station, c.truth.0.clone(), c.truth.1.clone(), 3.0);
    let view = TracedView::trace(&c.station, &plate);
    let params = SimParams {
        noise_frac: NOISE,
        seed,
        third_reflection: third,
        ..SimParams::default()
    };
    let mut cam = Renderer::new(&view, &c.station.screen, params).unwrap();
    let mut solver = SpectralSolver::new(&c.station, &c.frames, SpectralConfig::default()).unwrap();
    let mut buf = vec![0u16; c.station.camera.pixel_count()];
    for (k, p) in Schedule::default().patterns().iter().enumerate() {
        cam.render(p, k as u64, &mut buf);
        solver.push_frame(k, &buf).unwrap();
    }
    solver
}

fn run(c: &Case, seed: u64, estimator: Estimator) -> Result<SurfaceStage, SurfaceError> {
    run_with(c, seed, estimator, false)
}

fn run_with(
    c: &Case,
    seed: u64,
    estimator: Estimator,
    third: bool,
) -> Result<SurfaceStage, SurfaceError> {
    let mut s = solver_with(c, seed, third);
    let options = Options {
        surfaces: Some(SurfaceOptions {
            terms: Some(TERMS),
            ..SurfaceOptions::default()
        }),
        estimator,
        ..Options::default()
    };
    let rec = pipeline::reconstruct(
        Input::Streamed(&mut s),
        &c.station,
        &options,
        &mut |_, _| {},
    )
    .unwrap();
    rec.surfaces.unwrap()
}

/// Expected RMS error (j ≥ 4) of each surface at the bound: every pixel's
/// Cramér–Rao covariance at the truth through the surfaces' normal equations.
fn bound_nm(c: &Case) -> [f64; 2] {
    let opts = SceneOptions {
        radiometry: Radiometry {
            noise_frac: NOISE,
            ..Radiometry::default()
        },
        terms: TERMS,
        edge_margin_mm: 3.0,
        bound_stride_px: Some(1),
    };
    let s = scene(&c.station, c.truth.clone(), &c.frames, &opts).unwrap();
    let rms = |back| figures(&s.solution, back).error_rms_nm;
    [rms(false), rms(true)]
}

/// Error and reported expected error of both surfaces, nm.
fn errors(c: &Case, stage: &SurfaceStage) -> ([f64; 2], [f64; 2]) {
    let sol = &stage.solution;
    let err = [
        rms_difference_nm(sol.front.coefficients_nm(), c.truth.0.coefficients_nm()),
        rms_difference_nm(sol.back.coefficients_nm(), c.truth.1.coefficients_nm()),
    ];
    let rep = [
        stage.summary.reported(false).unwrap().1,
        stage.summary.reported(true).unwrap().1,
    ];
    (err, rep)
}

/// Σ over both surfaces' fitted coefficients j ≥ 2 of (error/σ)², and
/// their count.
fn z_squares(c: &Case, stage: &SurfaceStage) -> (f64, usize) {
    let sol = &stage.solution;
    let truth = [c.truth.0.coefficients_nm(), c.truth.1.coefficients_nm()];
    let fitted = [sol.front.coefficients_nm(), sol.back.coefficients_nm()];
    let std = [&sol.front_std_nm, &sol.back_std_nm];
    let (mut z2, mut n) = (0.0, 0);
    for k in 0..2 {
        for j in 1..fitted[k].len() {
            z2 += ((fitted[k][j] - truth[k][j]) / std[k][j]).powi(2);
            n += 1;
        }
    }
    (z2, n)
}

/// One seed: a surface's RMS error over 12 coefficients (j = 4…15) is
/// `σ_rms · sqrt(χ²₁₂/12)`, whose 0.1 %–99.9 % range is 0.40–1.77; the
/// bounds below add the estimator's allowance of the issue (2× the bound
/// for a thin plate, 1.5× for a thick one) on top of that spread.
const SPREAD_LO: f64 = 0.40;
const SPREAD_HI: f64 = 1.77;

#[test]
fn three_mm_plate_is_measured_from_the_frames() {
    let c = case(3.0, 1.5);
    // The per-pixel route: every pixel unresolved, nothing to fit.
    let pp = run(&c, 5, Estimator::PerPixel);
    assert!(
        matches!(pp, Err(SurfaceError::TooFewPoints { .. })),
        "{pp:?}"
    );
    let stage = run(&c, 5, Estimator::Auto).unwrap();
    assert_eq!(stage.summary.estimator, "surface-domain");
    let d = stage.direct.as_ref().unwrap();
    assert!(d.converged, "{:?}", d.iterations);
    assert!(d.per_pixel_failed.is_some());
    let bound = bound_nm(&c);
    let (err, rep) = errors(&c, &stage);
    for k in 0..2 {
        assert!(
            err[k] < 2.0 * SPREAD_HI * bound[k],
            "{k}: {err:?} vs bound {bound:?}"
        );
        let honest = err[k] / rep[k];
        assert!(
            (SPREAD_LO..SPREAD_HI).contains(&honest),
            "{k}: error {err:?} reported {rep:?}"
        );
        // What it reports is the global bound (at the estimate, σ from the
        // residuals): within the bound's own change over the surfaces'
        // uncertainty and σ's estimate, well inside a factor 1.5.
        assert!(
            (rep[k] / bound[k] - 1.0).abs() < 0.5,
            "{rep:?} vs {bound:?}"
        );
    }
}

#[test]
fn ten_mm_plate_matches_the_per_pixel_route() {
    let c = case(10.0, 1.5);
    let bound = bound_nm(&c);
    let direct = run(&c, 6, Estimator::Direct).unwrap();
    assert_eq!(direct.summary.estimator, "surface-domain");
    let per_pixel = run(&c, 6, Estimator::PerPixel).unwrap();
    assert_eq!(per_pixel.summary.estimator, "per-pixel");
    // 0.89 bins apart: `auto` takes the per-pixel route here.
    let auto = run(&c, 6, Estimator::Auto).unwrap();
    assert_eq!(auto.summary.estimator, "per-pixel");
    let (err, rep) = errors(&c, &direct);
    let (err_pp, _) = errors(&c, &per_pixel);
    for k in 0..2 {
        assert!(
            err[k] < 1.5 * SPREAD_HI * bound[k],
            "{k}: {err:?} vs {bound:?}"
        );
        assert!(
            (SPREAD_LO..SPREAD_HI).contains(&(err[k] / rep[k])),
            "{err:?} {rep:?}"
        );
        // Both estimate the same surfaces from the same frames: they differ
        // by less than the bound (each is within ~1σ of the truth, and the
        // two errors are strongly correlated).
        let diff = rms_difference_nm(
            if k == 0 {
                direct.solution.front.coefficients_nm()
            } else {
                direct.solution.back.coefficients_nm()
            },
            if k == 0 {
                per_pixel.solution.front.coefficients_nm()
            } else {
                per_pixel.solution.back.coefficients_nm()
            },
        );
        assert!(
            diff < bound[k],
            "{k}: estimators differ by {diff} nm, bound {bound:?}, per-pixel error {err_pp:?}"
        );
    }
}

/// A 5 mm plate at n = 2.2: bright Fresnel reflections (14 % and 10 %) put
/// the simulator's dark level at 3.6 % of full scale, below the 5 % read
/// noise, so the fringes' troughs clip at 0 in a few percent of the
/// samples, and the two reflections beat (0.29 bins apart) so the clipped
/// troughs come at the same samples in every pixel. Left out, the clipped
/// samples biased the front by 3–12σ of its own σ in defocus, coma and
/// tilts (RMS of error/σ 3.19 over three seeds); taken as censored, the
/// errors follow the reported covariance.
///
/// Over three seeds the 84 z-scores (28 coefficients j ≥ 2) give RMS(z)
/// with a sampling spread of about 1/√(2·84) = 0.077 around 1, so the
/// issue's band 0.8–1.3 sits 2.6σ below and 3.9σ above; each surface's
/// error over what it reports, pooled over the seeds (36 coefficients
/// j = 4…15), lies in 0.59–1.49 (χ²₃₆ at 0.1 % and 99.9 %), inside the
/// issue's 0.67–1.5 only to that spread, so the test asserts the spread.
#[test]
fn high_index_plate_has_no_bias_from_clipped_troughs() {
    let c = case(5.0, 2.2);
    let (mut z2, mut zn) = (0.0, 0usize);
    let (mut e2, mut r2) = ([0.0; 2], [0.0; 2]);
    for seed in [5, 6, 7] {
        let stage = run(&c, seed, Estimator::Auto).unwrap();
        assert_eq!(stage.summary.estimator, "surface-domain");
        let d = stage.direct.as_ref().unwrap();
        assert!(d.converged, "{:?}", d.iterations);
        // The scene does clip: most fitted pixels have a clipped sample.
        assert!(
            d.clipped.pixels * 2 > d.two_reflection_pixels,
            "{:?} of {}",
            d.clipped,
            d.two_reflection_pixels
        );
        assert!(d.iterations.iter().any(|i| i.clipped_imputed));
        // Rendered without a third path, and none modelled: a false
        // detection at the fit's 5σ rule has probability 6e-7.
        assert!(d.third_reflection.is_none(), "{:?}", d.third_reflection);
        let (z, n) = z_squares(&c, &stage);
        z2 += z;
        zn += n;
        let (err, rep) = errors(&c, &stage);
        for k in 0..2 {
            e2[k] += err[k].powi(2);
            r2[k] += rep[k].powi(2);
        }
    }
    let z = (z2 / zn as f64).sqrt();
    assert!((0.8..1.3).contains(&z), "RMS(error/σ) {z}");
    for k in 0..2 {
        let honest = (e2[k] / r2[k]).sqrt();
        assert!(
            (0.59..1.49).contains(&honest),
            "{k}: error/reported {honest}"
        );
    }
}

/// The same index at 8 mm with the third path rendered (two internal round
/// trips, 1.5 % of the front's amplitude at n = 2.2, twice the back's
/// offset from S1). Not modelled, it biased the front and back by up to
/// 6σ (RMS(error/σ) 6.1 over three seeds, back 2.2× its bound). The fit
/// finds it from the frames (γ's step 9σ at γ = 0), estimates its factor,
/// whose truth is 1 for bare glass, within 4σ of its reported σ, and the
/// surfaces then follow their reported covariance. Two seeds: 56 z-scores,
/// RMS(z) spread 1/√112 = 0.094, so 0.8–1.3 is 2.1σ below, 3.2σ above.
#[test]
fn third_reflection_is_found_and_modelled() {
    let c = case(8.0, 2.2);
    let (mut z2, mut zn) = (0.0, 0usize);
    for seed in [5, 6] {
        let stage = run_with(&c, seed, Estimator::Auto, true).unwrap();
        assert_eq!(stage.summary.estimator, "surface-domain");
        let d = stage.direct.as_ref().unwrap();
        assert!(d.converged, "{:?}", d.iterations);
        let third = d.third_reflection.expect("third reflection modelled");
        assert!(
            (third.factor - 1.0).abs() < 4.0 * third.sigma && third.sigma < 0.2,
            "{third:?}"
        );
        let (z, n) = z_squares(&c, &stage);
        z2 += z;
        zn += n;
    }
    let z = (z2 / zn as f64).sqrt();
    assert!((0.8..1.3).contains(&z), "RMS(error/σ) {z}");
}

//! `mfd plan` on a thin plate: a 3 mm plate (n = 1.5) on the 48×48 bench
//! station, whose two reflections lie ~0.3 Fourier bins apart, so that
//! `--estimator auto` fits the surfaces to the frames (`solve::direct`)
//! and the plan predicts with that fit's global bound and its
//! measurability rule. A schedule designed for 2000 frames, rendered by the
//! simulator and reconstructed with `auto`, is measured against the
//! paper's schedule (τ 0.2…200 step 0.2, ±45°, 2000 frames) on the same
//! noise seeds.

use crate::common;

use mfd::acquire::acquisition::FrameInfo;
use mfd::acquire::patterns::Schedule;
use mfd::budget::scene::{scene, Radiometry, SceneOptions};
use mfd::optics::station::{bench_station, Station};
use mfd::optics::trace::{Plate, TracedView};
use mfd::optics::zernike::ZernikeSurface;
use mfd::pipeline::{self, Estimator, Input, Options};
use mfd::plan::{self, BoundKind, Budget, DesignOptions, PlanOptions, Prediction};
use mfd::report::metrics::rms_difference_nm;
use mfd::sim::{RandomSurfaceSpec, SimParams};
use mfd::solve::spectral::SpectralConfig;
use mfd::solve::surfaces::report::figures;
use mfd::solve::surfaces::SurfaceOptions;

const TERMS: usize = 15;
const NOISE: f64 = 0.05;
/// Noise seeds, the same for both schedules.
const SEEDS: [u64; 3] = [21, 22, 23];

fn plan_options() -> PlanOptions {
    PlanOptions {
        radiometry: Radiometry {
            noise_frac: NOISE,
            ..Radiometry::default()
        },
        terms: TERMS,
        ..PlanOptions::default()
    }
}

/// The truth of `tests/it/direct_thin.rs`: 15 terms, j = 4…15 at 60 nm RMS,
/// tilts of 100 nm.
fn truth(station: &Station) -> (ZernikeSurface, ZernikeSurface) {
    let spec = RandomSurfaceSpec {
        n_terms: TERMS,
        ..RandomSurfaceSpec::default()
    };
    let e = &station.element;
    let centre = [e.aperture_center_mm.x, e.aperture_center_mm.y];
    spec.draw_pair(e.aperture_radius_mm, centre, 31).unwrap()
}

fn paper() -> Vec<FrameInfo> {
    FrameInfo::from_patterns(&Schedule::default().patterns())
}

/// `frames` rendered with noise `seed` and reconstructed with `auto`: the
/// RMS error (j ≥ 4) of front and back, nm.
fn achieved(
    station: &Station,
    truth: &(ZernikeSurface, ZernikeSurface),
    frames: &[FrameInfo],
    seed: u64,
) -> [f64; 2] {
    let plate = Plate::new(station, truth.0.clone(), truth.1.clone(), 3.0);
    let view = TracedView::trace(station, &plate);
    let params = SimParams {
        noise_frac: NOISE,
        seed,
        ..SimParams::default()
    };
    let patterns = common::patterns_of(frames);
    let (mut solver, _) =
        common::spectral::fed_solver(station, &view, params, &patterns, SpectralConfig::default());
    let options = Options {
        surfaces: Some(SurfaceOptions {
            terms: Some(TERMS),
            ..SurfaceOptions::default()
        }),
        estimator: Estimator::Auto,
        ..Options::default()
    };
    let rec = pipeline::reconstruct(
        Input::Streamed(&mut solver),
        station,
        &options,
        &mut |_, _| {},
    )
    .unwrap();
    let s = rec.surfaces.unwrap().unwrap();
    assert_eq!(s.summary.estimator, "surface-domain");
    assert!(s.direct.as_ref().is_some_and(|d| d.converged));
    [
        rms_difference_nm(
            s.solution.front.coefficients_nm(),
            truth.0.coefficients_nm(),
        ),
        rms_difference_nm(s.solution.back.coefficients_nm(), truth.1.coefficients_nm()),
    ]
}

/// RMS over the seeds of each surface's achieved error.
fn over_seeds(
    station: &Station,
    truth: &(ZernikeSurface, ZernikeSurface),
    frames: &[FrameInfo],
) -> [f64; 2] {
    let mut s2 = [0.0; 2];
    for seed in SEEDS {
        let e = achieved(station, truth, frames, seed);
        eprintln!("  seed {seed}: front {:.2} nm, back {:.2} nm", e[0], e[1]);
        for k in 0..2 {
            s2[k] += e[k] * e[k];
        }
    }
    s2.map(|v| (v / SEEDS.len() as f64).sqrt())
}

fn predicted(p: &Prediction) -> [(f64, f64); 2] {
    let b = p.back.as_ref().expect("the back is predicted");
    [
        (p.front.rms_nm, p.front.rms_relative_spread(SEEDS.len())),
        (b.rms_nm, b.rms_relative_spread(SEEDS.len())),
    ]
}

#[test]
fn thin_plate_is_predicted_with_the_surface_domain_bound() {
    let station = bench_station(3.0, 1.5, 15.0).unwrap();
    let opts = plan_options();
    let p = plan::predict(&station, &paper(), &opts).unwrap();
    // 3 mm at n = 1.5: ~0.26 bins (docs/figures.md, thin plates), below
    // auto's 0.75; the per-pixel stage separates nothing there.
    assert_eq!(p.bound, BoundKind::SurfaceDomain, "{}", p.separation_bins);
    assert!(p.separation_bins < 0.5, "{}", p.separation_bins);
    assert!(!p.separation.separable);
    assert!(p.not_measurable_because.is_none(), "{p:?}");
    assert!(p.convergence.converges, "{:?}", p.convergence);
    // The bound is `budget::scene`'s at the flat plate: every pixel's full
    // 4×4 bound through the surfaces' normal equations (the same
    // computation, so equal to rounding).
    let s = scene(
        &station,
        mfd::budget::scene::expected_surfaces(None, &station).unwrap(),
        &paper(),
        &SceneOptions {
            radiometry: opts.radiometry.clone(),
            terms: TERMS,
            ..SceneOptions::default()
        },
    )
    .unwrap();
    let want = [
        figures(&s.solution, false).error_rms_nm,
        figures(&s.solution, true).error_rms_nm,
    ];
    let got = [p.front.rms_nm, p.back.as_ref().unwrap().rms_nm];
    for k in 0..2 {
        assert!((got[k] / want[k] - 1.0).abs() < 1e-6, "{got:?} vs {want:?}");
    }
    // A 10 mm plate (0.86 bins) keeps the per-pixel bound and rule.
    let thick = bench_station(10.0, 1.5, 15.0).unwrap();
    let q = plan::predict(&thick, &paper(), &opts).unwrap();
    assert_eq!(q.bound, BoundKind::PerPixel, "{}", q.separation_bins);
}

/// The Done-when: on the 3 mm plate a designed schedule of the
/// paper's 2000 frames beats the paper's schedule, achieved, front and
/// back, reconstructed with `auto` (the surface-domain fit from the flat
/// plate: the per-pixel route measures nothing on either schedule).
///
/// What can fail: a design whose fit does not reach the truth (the pure
/// A-optimum, concentrated at τ ≈ 90–115 and 225–250, left the stage's
/// periodogram without fringes on 92 % of its sample pixels, so the fit
/// had a tenth of the pixels: 93.8 / 51.2 nm on seed 21 against 23.4 /
/// 17.9 predicted), or a design that is not better.
#[test]
fn designed_schedule_beats_the_papers_on_a_3mm_plate() {
    let station = bench_station(3.0, 1.5, 15.0).unwrap();
    let t = truth(&station);
    let opts = plan_options();
    let paper = paper();
    let pp = plan::predict(&station, &paper, &opts).unwrap();
    let d = plan::design(
        &station,
        Budget::Frames(paper.len()),
        &DesignOptions {
            plan: opts.clone(),
            ..DesignOptions::default()
        },
    )
    .unwrap();
    let dp = &d.prediction;
    eprintln!(
        "designed: α {} of τ ≤ {}, {} patterns, {:.1} s; paper {:.1} s",
        d.uniform_share, d.start_tau_max, dp.patterns_shown, dp.seconds, pp.seconds
    );
    assert_eq!(d.frames.len(), paper.len());
    assert_eq!(dp.bound, BoundKind::SurfaceDomain);
    assert!(dp.not_measurable_because.is_none(), "{dp:?}");
    let (want_p, want_d) = (predicted(&pp), predicted(dp));
    let got_p = over_seeds(&station, &t, &paper);
    let got_d = over_seeds(&station, &t, &d.frames);
    for k in 0..2 {
        let name = ["front", "back"][k];
        eprintln!(
            "{name}: paper {:.2} nm (predicted {:.2} ± {:.0} %), designed {:.2} nm (predicted {:.2} ± {:.0} %)",
            got_p[k],
            want_p[k].0,
            100.0 * want_p[k].1,
            got_d[k],
            want_d[k].0,
            100.0 * want_d[k].1
        );
        // Each achieved error is its prediction's within 3 of the seeds'
        // relative spread (`rms_relative_spread`, ±21–23 % over three
        // seeds here): an estimator at its bound fails this with
        // probability ~0.3 %, a fit that missed the truth or used a tenth
        // of the pixels (4× its bound) always.
        for (got, (want, spread)) in [(got_p[k], want_p[k]), (got_d[k], want_d[k])] {
            assert!(
                (got / want - 1.0).abs() < 3.0 * spread,
                "{name}: achieved {got:.2} nm against predicted {want:.2} nm (±{spread:.2})"
            );
        }
        // The Done-when, with no allowance: the design beats the paper's
        // schedule on these seeds. Predicted (the default design over ±45°,
        // 0° and 90°) the ratio is 0.38 front, 0.42 back; with both RMS
        // errors scattering by their spreads (about 0.3 in the log of the
        // ratio) a design at its bound loses on a given set of three seeds
        // with probability below 0.2 %; these seeds were not chosen for it
        // (an earlier session's paper figures were on them).
        assert!(
            got_d[k] < got_p[k],
            "{name}: designed {:.2} nm is not below the paper's {:.2} nm",
            got_d[k],
            got_p[k]
        );
    }
}

/// The planner's convergence rule against the fit, from the flat plate,
/// on the same plate with an extra defocus of both faces (the plan told
/// the same departure, `--surface-nm`, and no station share: the
/// simulated station is exact). Measured with the paper's schedule, seed
/// 21 (docs/figures.md, "The 3 mm plate"): 0.5 µm converged (29.0 / 27.3
/// nm), 1.5 µm did not (579 / 305 nm, the fit's iteration cap hit); the
/// rule must say so before any frame. The fits themselves are not re-run
/// here (their cost is the reconstruction's, 10 s each).
#[test]
fn the_rule_says_where_the_fit_from_the_flat_plate_fails() {
    let station = bench_station(3.0, 1.5, 15.0).unwrap();
    for (defocus_nm, converges) in [(500.0, true), (1500.0, false)] {
        let opts = PlanOptions {
            surface_nm: defocus_nm,
            station_spread_px: 0.0,
            ..plan_options()
        };
        let p = plan::predict(&station, &paper(), &opts).unwrap();
        let c = &p.convergence;
        assert_eq!(c.converges, converges, "{defocus_nm} nm: {c:?}");
        assert_eq!(p.not_measurable_because.is_none(), converges, "{p:?}");
    }
}

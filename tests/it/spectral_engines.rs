//! The spectral solver's seams and engines on simulated acquisitions: the
//! fit backend takes every candidate, the statistics engine gives the
//! series' answers and flags what leaves its band, warm starts give the
//! searched answers, and a prior handed in is the one the solver traces.

use crate::common::spectral::*;
use mfd::acquire::acquisition::FrameInfo;
use mfd::acquire::patterns::Schedule;
use mfd::optics::station::Station;
use mfd::optics::trace::{Plate, TracedView};
use mfd::sim::{RandomSurfaceSpec, Renderer, SimParams};
use mfd::solve::spectral::{
    CpuFits, Engine, FitBackend, FitBatch, PixelFlags, SpectralConfig, SpectralMaps, SpectralSolver,
};

/// A backend that fits on one thread, last run first, and counts.
struct Reversed(std::sync::atomic::AtomicUsize);

impl FitBackend for Reversed {
    fn fit(&self, batch: &mut FitBatch) -> Vec<mfd::solve::spectral::pixel::PixelFits> {
        let n = batch.candidates().len();
        self.0.store(n, std::sync::atomic::Ordering::Relaxed);
        let mut runs: Vec<_> = batch
            .runs()
            .into_iter()
            .rev()
            .map(|r| batch.fit_run(r))
            .collect();
        runs.reverse();
        runs.into_iter().flatten().collect()
    }
}

/// A backend that answers for no pixel.
struct Empty;

impl FitBackend for Empty {
    fn fit(&self, _: &mut FitBatch) -> Vec<mfd::solve::spectral::pixel::PixelFits> {
        Vec::new()
    }
}

#[test]
fn the_fit_backend_seam_takes_every_candidate_and_is_checked() {
    // Short schedule (τ ≤ 60): only the plumbing is under test here.
    let st = station(30.0);
    let schedule = Schedule {
        tau_stop: 60.0,
        ..Schedule::default()
    };
    let view = TracedView::trace(&st, &Plate::new(&st, flat(&st), flat(&st), 3.0));
    let (mut solver, _) = fed_solver(
        &st,
        &view,
        SimParams::default(),
        &schedule.patterns(),
        SpectralConfig::default(),
    );
    // The first solve writes into the arrays prepared while the frames
    // streamed in; the second backend returns arrays of its own.
    let reference = solver.solve_with(&CpuFits).unwrap();
    let counted = Reversed(std::sync::atomic::AtomicUsize::new(0));
    let other = solver.solve_with(&counted).unwrap();
    assert_eq!(
        counted.0.load(std::sync::atomic::Ordering::Relaxed),
        solver.candidate_pixels()
    );
    // The same fits in another order give bit-identical maps (NaN included).
    let bits = |m: &SpectralMaps| -> Vec<u64> {
        m.screen_cov()
            .into_iter()
            .chain(m.screen_coords())
            .map(f64::to_bits)
            .collect()
    };
    assert!(bits(&reference) == bits(&other), "maps differ");
    assert!(reference
        .pixels
        .iter()
        .zip(&other.pixels)
        .all(|(a, b)| a.flags == b.flags));
    assert!(reference.found_both() > 0);
    let err = solver.solve_with(&Empty).unwrap_err().to_string();
    assert!(err.contains("fit backend: returned 0 results"), "{err}");
}

fn flat(st: &Station) -> mfd::optics::zernike::ZernikeSurface {
    let e = &st.element;
    mfd::optics::zernike::ZernikeSurface::flat(
        e.aperture_radius_mm,
        [e.aperture_center_mm.x, e.aperture_center_mm.y],
    )
    .unwrap()
}

/// Two solves of the same frames compared pixel by pixel: the points, in
/// units of the first one's σ (worst), how many were compared, pixels whose
/// flags differ (after `mask` on the second's), and the worst relative
/// difference of the reported σ.
struct Agreement {
    worst: f64,
    compared: usize,
    differ: usize,
    worst_sd: f64,
}

fn agreement(
    a: &SpectralMaps,
    b: &SpectralMaps,
    mask: impl Fn(PixelFlags) -> PixelFlags,
) -> Agreement {
    let mut out = Agreement {
        worst: 0.0,
        compared: 0,
        differ: 0,
        worst_sd: 0.0,
    };
    for (p, q) in a.pixels.iter().zip(&b.pixels) {
        if p.flags != mask(q.flags) {
            out.differ += 1;
            continue;
        }
        for k in 0..2 {
            if p.s[k][0].is_finite() {
                let sd = p.std[k][0].hypot(p.std[k][1]);
                let d = (p.s[k][0] - q.s[k][0]).hypot(p.s[k][1] - q.s[k][1]);
                out.worst = out.worst.max(d / sd);
                let sd_b = q.std[k][0].hypot(q.std[k][1]);
                out.worst_sd = out.worst_sd.max((sd_b / sd - 1.0).abs());
                out.compared += 1;
            }
        }
    }
    out
}

#[test]
fn the_statistics_give_the_series_answers() {
    // The statistics reproduce the series' least squares to the node
    // tolerance (1e-10 of Σ|y|), so both engines take the same LM path. They
    // could part only where a stopping test is borderline: LM stops when χ²
    // falls by < 1e-3, i.e. within ~√1e-3 ≈ 0.03σ of the minimum, so two
    // stopping points lie within 0.05σ (with margin) of each other.
    let params = SimParams {
        noise_frac: 0.05,
        seed: 3,
        ..SimParams::default()
    };
    let a = run(
        &station(10.0),
        params.clone(),
        &paper_schedule(),
        Engine::Series,
    );
    let b = run(
        &station(10.0),
        params,
        &paper_schedule(),
        Engine::Statistics,
    );
    // Where no signal is found the statistics add "maybe outside the band"
    // (512) by design; every other flag must agree.
    let Agreement {
        worst,
        compared,
        differ,
        ..
    } = agreement(&a.maps, &b.maps, |f| {
        if f.intersects(PixelFlags::NO_SIGNAL) {
            f & !PixelFlags::OUT_OF_BAND
        } else {
            f
        }
    });
    eprintln!(
        "statistics vs series: {compared} points, worst difference {worst:.2e} σ; {differ} pixels with other flags"
    );
    assert!(compared > 2000, "{compared}");
    assert!(worst <= 0.05, "{worst} σ");
    assert!(differ * 200 <= a.maps.pixels.len(), "{differ} pixels");
}

#[test]
fn statistics_flag_points_outside_their_band_never_guess() {
    // The frames are rendered with the screen 22.7 mm (84 screen px) to the
    // left of where the solver's station file puts it: every screen point
    // sits 84 px ≈ 6 Fourier bins (14 px per bin along each diagonal on
    // this screen) from its prediction, beyond the default band of 3 bins
    // past the predicted pair. The statistics engine must say so, not fit a
    // sidelobe; with a band of 8 bins it finds the points.
    let nominal = station(10.0);
    let mut shifted = nominal.clone();
    shifted.screen.origin_mm -= shifted.screen.u_axis.into_inner() * 22.7;
    let (front, back) = RandomSurfaceSpec::default()
        .draw_pair(25.5, [0.0, 0.0], 21)
        .unwrap();
    let view = TracedView::trace(&shifted, &Plate::new(&shifted, front, back, 3.0));
    let patterns = paper_schedule().patterns();
    let mut counts = Vec::new();
    for band_bins in [3.0, 8.0] {
        let cfg = SpectralConfig {
            band_bins,
            ..config(Engine::Statistics)
        };
        // The solver renders with `shifted` but predicts with `nominal`.
        let mut cam = Renderer::new(&view, &shifted.screen, SimParams::default()).unwrap();
        let frames: Vec<_> = FrameInfo::from_patterns(&patterns);
        let mut solver = SpectralSolver::new(&nominal, &frames, cfg).unwrap();
        let mut buf = vec![0u16; nominal.camera.pixel_count()];
        for (k, p) in patterns.iter().enumerate() {
            cam.render(p, k as u64, &mut buf);
            solver.push_frame(k, &buf).unwrap();
        }
        let maps = solver.solve().unwrap();
        let (mut total, mut out_of_band, mut found, mut worst) = (0, 0, 0, 0.0f64);
        for (q, px) in view.pixels.iter().enumerate() {
            let (Ok(f), Ok(b)) = (px.front, px.back) else {
                continue;
            };
            let m = &maps.pixels[q];
            total += 1;
            if m.flags.intersects(PixelFlags::OUT_OF_BAND) {
                out_of_band += 1;
            }
            for (k, t) in [f, b].iter().enumerate() {
                if m.s[k][0].is_finite() {
                    worst = worst.max((m.s[k][0] - t.u).hypot(m.s[k][1] - t.v));
                    found += 1;
                }
            }
        }
        eprintln!(
            "band {band_bins} bins: {out_of_band}/{total} flagged out of band, {found} points reported, worst error {worst:.2e} px"
        );
        counts.push((total, out_of_band, found, worst));
    }
    let (total, out_of_band, _, worst) = counts[0];
    // Noise-free: any reported point is exact (0.01 px) or it is a guess.
    assert!(worst <= 0.01, "a guess {worst} px off");
    assert!(out_of_band * 10 >= total * 9, "{out_of_band}/{total}");
    let (total, _, found, worst) = counts[1];
    assert!(worst <= 0.01, "{worst}");
    assert!(found as f64 >= 0.99 * 2.0 * total as f64, "{found}/{total}");
}

#[test]
fn warm_starts_give_the_searched_answers() {
    // A pixel started from its row neighbour's fits converges to the
    // minimum the spectral search finds; only LM's stopping point differs,
    // within ~0.03σ of that minimum either way (χ² falls by < 1e-3), so
    // the two points lie within 0.05σ of each other (with margin); the warm
    // pair's last Gauss–Newton step is not evaluated but taken only where
    // it is predicted to lower χ² by < 0.1 (a step of ≤ 0.3σ, which lands
    // to second order in it), so it adds nothing at that scale. Flags
    // may differ only where a test is borderline (≤ 0.5 % of pixels).
    let params = SimParams {
        noise_frac: 0.05,
        seed: 5,
        ..SimParams::default()
    };
    // 30 mm too: its rim pixels, searched first in every row, see one
    // reflection, so the scene's BIC must count the warm pixels (it chose
    // one reflection when it did not).
    for (engine, t) in [
        (Engine::Statistics, 10.0),
        (Engine::Series, 10.0),
        (Engine::Statistics, 30.0),
    ] {
        let cold = SpectralConfig {
            warm_starts: false,
            ..config(engine)
        };
        let a = run_with(&station(t), params.clone(), &paper_schedule(), cold);
        let b = run(&station(t), params.clone(), &paper_schedule(), engine);
        let Agreement {
            worst,
            compared,
            differ,
            worst_sd,
        } = agreement(&a.maps, &b.maps, |f| f);
        eprintln!(
            "{engine:?}, {t} mm, warm vs searched: {compared} points, worst difference {worst:.2e} σ, σ within {:.2} %; {differ} pixels with other flags; scene models {} {}",
            100.0 * worst_sd,
            a.maps.scene_model, b.maps.scene_model
        );
        assert_eq!((a.maps.scene_model, b.maps.scene_model), (2, 2));
        assert!(compared > 2000, "{compared}");
        assert!(worst <= 0.05, "{worst} σ");
        // σ from JᵀJ at the point one step before the reported one, ≤ 0.3σ
        // away (pixel::ONE_STEP_CHI2); allowing steps up to 1σ gave 2.0 %,
        // and the change is first order in the step: ≤ 0.7 % expected.
        assert!(worst_sd <= 0.01, "σ differs by {worst_sd}");
        assert!(differ * 200 <= a.maps.pixels.len(), "{differ} pixels");
    }
}

/// A prior traced by the caller and handed in gives the solver `new`
/// builds (it traces the same flat plate); a prior of another camera is
/// refused, naming both sizes.
#[test]
fn a_prior_handed_in_is_the_one_new_traces() {
    let st = station(30.0);
    let schedule = Schedule {
        tau_stop: 60.0,
        ..Schedule::default()
    };
    let frames = FrameInfo::from_patterns(&schedule.patterns());
    let cfg = SpectralConfig::default();
    let own = SpectralSolver::new(&st, &frames, cfg.clone()).unwrap();
    let prior = mfd::solve::spectral::nominal_plate_prior(&st, cfg.edge_margin_mm).unwrap();
    let given = SpectralSolver::with_prior(&st, &frames, cfg.clone(), prior.clone()).unwrap();
    assert_eq!(own.candidate_pixels(), given.candidate_pixels());
    assert_eq!(own.series_bytes(), given.series_bytes());
    let hits = |v: &TracedView| -> Vec<Option<[u64; 2]>> {
        v.pixels
            .iter()
            .map(|p| p.front.ok().map(|h| [h.u.to_bits(), h.v.to_bits()]))
            .collect()
    };
    assert!(hits(own.prior()) == hits(given.prior()));
    let mut small = prior;
    small.width -= 1;
    small.pixels.truncate(small.width * small.height);
    let err = SpectralSolver::with_prior(&st, &frames, cfg, small)
        .err()
        .expect("a prior of another camera is refused")
        .to_string();
    assert!(err.contains("geometry prior"), "{err}");
}

/// A full sensor's fits (1 251 936 candidates of `calib/bench-fill.toml`)
/// are held, with the statistics (1.86 GB) and the maps (0.32 GB), until
/// the scene's model is chosen: at 1088 bytes a pixel (every model's
/// result in place) they were 1.36 GB and the peak 3.81 GiB; the 3 GiB of
/// issue 39 leaves them ~0.5 GB, 400 bytes a pixel. A pixel's models are
/// read back as they were set, and the no-model answer carries its flags.
#[test]
fn a_pixels_fits_are_small_and_keep_every_model() {
    use mfd::solve::spectral::pixel::{PixelFits, Scored};
    use mfd::solve::spectral::PixelResult;
    let size = std::mem::size_of::<PixelFits>();
    assert!(size <= 400, "{size} bytes a pixel");
    let mut fits = PixelFits::none();
    assert!((0..3).all(|k| fits.model(k).is_none()));
    for k in 0..3 {
        let mut result = PixelResult::empty();
        result.model = k as u8 + 1;
        fits.set_model(
            k,
            Some(Scored {
                result,
                bic: k as f64,
            }),
        );
    }
    for k in 0..3 {
        let m = fits.model(k).expect("set");
        assert_eq!((m.result.model, m.bic), (k as u8 + 1, k as f64));
    }
    fits.set_model(0, None);
    assert!(fits.model(0).is_none() && fits.model(1).is_some());
    fits.flags = PixelFlags::NO_SIGNAL | PixelFlags::SATURATED;
    let base = fits.base();
    assert_eq!(base.flags, fits.flags);
    assert_eq!(base.model, 0);
    assert!(base.s[0][0].is_nan());
}

//! The spectral solver against the truth of simulated acquisitions: exact on
//! noise-free data, at the Cramér–Rao bound with noise, honest about what it
//! cannot separate, and never a swapped front and back.

use crate::common::spectral::*;
use mfd::optics::trace::{Plate, TracedView};
use mfd::sim::{RandomSurfaceSpec, Renderer, SimParams};
use mfd::solve::spectral::{Engine, PixelFlags, SpectralConfig};

/// The checks that must hold for both engines (the series and the
/// streaming statistics): one test each.
macro_rules! both_engines {
    ($($check:ident),* $(,)?) => {
        $(
            mod $check {
                #[test]
                fn series() {
                    super::$check(mfd::solve::spectral::Engine::Series);
                }
                #[test]
                fn statistics() {
                    super::$check(mfd::solve::spectral::Engine::Statistics);
                }
            }
        )*
    };
}

both_engines!(
    noise_free_is_exact_and_complete,
    five_percent_noise_reaches_the_bound,
    saturated_samples_are_left_out_not_averaged_in,
    an_ar_coated_back_gives_one_reflection,
    thin_plates_are_resolved_or_flagged_never_guessed,
    a_second_internal_round_trip_is_modelled_when_the_data_show_it,
    any_schedule_works_plain_directions_uneven_taus_and_phase_shifts,
    four_directions_under_a_blurs_falloff_reach_the_bound,
);

fn noise_free_is_exact_and_complete(engine: Engine) {
    let r = run(
        &station(10.0),
        SimParams::default(),
        &paper_schedule(),
        engine,
    );
    for (k, (rms, _, worst, found, expected)) in score(&r).into_iter().enumerate() {
        eprintln!(
            "noise-free S{}: RMS {rms:.2e} px, worst {worst:.2e} px, found {found}/{expected}",
            k + 1
        );
        // The bound: 0.01 screen px without noise (16-bit rounding
        // alone leaves ~1e-4 px).
        assert!(worst <= 0.01, "S{}: worst {worst} px", k + 1);
        assert!(
            found as f64 >= 0.99 * expected as f64,
            "S{}: {found}/{expected}",
            k + 1
        );
    }
}

fn five_percent_noise_reaches_the_bound(engine: Engine) {
    let params = SimParams {
        noise_frac: 0.05,
        seed: 3,
        ..SimParams::default()
    };
    let r = run(&station(10.0), params, &paper_schedule(), engine);
    assert_near_the_bound(&r, "5 % noise");
    // The reported uncertainty is the bound at the fitted point: errors
    // divided by it must have unit RMS (±10 % for ~2000 coordinates, 5σ).
    let z = error_over_sigma(&r, &[0]);
    assert!((0.9..1.1).contains(&z), "{z}");
}

/// Per reflection: the points within 1.5× the Cramér–Rao bound (the
/// issue's criterion; with ~1000 pixels the RMS itself scatters by ~2 %,
/// so an efficient estimator sits near 1.0) and found on 99 % of the
/// pixels that have them; `case` names the run in the printout.
fn assert_near_the_bound(r: &Run, case: &str) {
    for (k, (rms, bound, worst, found, expected)) in score(r).into_iter().enumerate() {
        eprintln!("{case} S{}: RMS {rms:.4} px, bound {bound:.4} px, ratio {:.3}, worst {worst:.3}, found {found}/{expected}", k + 1, rms / bound);
        assert!(rms <= 1.5 * bound, "S{}: {rms} vs bound {bound}", k + 1);
        assert!(
            found as f64 >= 0.99 * expected as f64,
            "S{}: {found}/{expected}",
            k + 1
        );
    }
}

/// RMS of error over reported σ over both coordinates of the
/// `reflections` (0 front, 1 back) found, printed with their count.
fn error_over_sigma(r: &Run, reflections: &[usize]) -> f64 {
    let mut z2 = Vec::new();
    for (q, px) in r.view.pixels.iter().enumerate() {
        let p = &r.maps.pixels[q];
        for &k in reflections {
            let truth = [px.front, px.back][k];
            if let (Ok(t), false) = (truth, p.s[k][0].is_nan()) {
                z2.push(((p.s[k][0] - t.u) / p.std[k][0]).powi(2));
                z2.push(((p.s[k][1] - t.v) / p.std[k][1]).powi(2));
            }
        }
    }
    let z = (z2.iter().sum::<f64>() / z2.len() as f64).sqrt();
    eprintln!(
        "RMS of error / reported σ: {z:.3} over {} coordinates",
        z2.len()
    );
    z
}

fn saturated_samples_are_left_out_not_averaged_in(engine: Engine) {
    // The default gain puts the brightest possible sample at 90 % of full
    // scale; 1.6× clips the crests of the low-τ fringes (where e(τ) ≈ 1) of
    // the brighter pixels. Noise-free, the remaining samples determine the
    // points as exactly as before: the same 0.01 px criterion.
    let st = station(10.0);
    let (front, back) = RandomSurfaceSpec::default()
        .draw_pair(25.5, [0.0, 0.0], 21)
        .unwrap();
    let view = TracedView::trace(&st, &Plate::new(&st, front, back, 3.0));
    let g = Renderer::new(&view, &st.screen, SimParams::default())
        .unwrap()
        .gain();
    let params = SimParams {
        gain: Some(1.6 * g),
        ..SimParams::default()
    };
    let r = run(&st, params, &paper_schedule(), engine);
    let saturated = r
        .maps
        .pixels
        .iter()
        .filter(|p| p.flags.intersects(PixelFlags::SATURATED))
        .count();
    let [(rms1, _, worst1, found1, n1), (rms2, _, worst2, found2, n2)] = score(&r);
    eprintln!(
        "1.6x gain: {saturated} pixels with clipped samples; S1 RMS {rms1:.2e} worst {worst1:.2e} \
         px ({found1}/{n1}), S2 RMS {rms2:.2e} worst {worst2:.2e} px ({found2}/{n2})"
    );
    // The scene must really clip: most element pixels reach the crest.
    assert!(saturated as f64 > 0.5 * n1 as f64, "{saturated} of {n1}");
    for (worst, found, n) in [(worst1, found1, n1), (worst2, found2, n2)] {
        assert!(worst <= 0.01, "worst {worst} px");
        assert!(found as f64 >= 0.99 * n as f64, "{found}/{n}");
    }
}

fn an_ar_coated_back_gives_one_reflection(engine: Engine) {
    let params = SimParams {
        path_scale: [1.0, 0.0, 0.0],
        noise_frac: 0.02,
        ..SimParams::default()
    };
    let r = run(&station(10.0), params, &paper_schedule(), engine);
    let (mut one, mut total, mut worst) = (0, 0, 0.0f64);
    for (q, px) in r.view.pixels.iter().enumerate() {
        let Ok(f) = px.front else { continue };
        let p = &r.maps.pixels[q];
        total += 1;
        if p.model == 1 && p.s[1][0].is_nan() && p.s[0][0].is_finite() {
            one += 1;
            worst = worst.max((p.s[0][0] - f.u).hypot(p.s[0][1] - f.v));
        }
    }
    eprintln!(
        "AR-coated back: {one}/{total} pixels with one reflection, worst S1 error {worst:.4} px"
    );
    assert!(one as f64 >= 0.99 * total as f64, "{one}/{total}");
    // 2 % noise on a single 13 000-count fringe: σ(S1) ~ 0.01 px; 0.1 px is 10σ.
    assert!(worst < 0.1);
}

/// Counts over the pixels with both paths: (flagged unresolved or
/// inconsistent, reported both, reported points more than 5 reported σ from
/// the truth, total).
fn thin_plate_counts(
    thickness_mm: f64,
    noise: f64,
    engine: Engine,
) -> (usize, usize, usize, usize) {
    let params = SimParams {
        noise_frac: noise,
        ..SimParams::default()
    };
    let r = run(&station(thickness_mm), params, &paper_schedule(), engine);
    let (mut flagged, mut both, mut confident_wrong, mut total) = (0, 0, 0, 0);
    let mut hist = std::collections::BTreeMap::new();
    for (q, px) in r.view.pixels.iter().enumerate() {
        let (Ok(f), Ok(b)) = (px.front, px.back) else {
            continue;
        };
        let p = &r.maps.pixels[q];
        *hist.entry(p.flags).or_insert(0) += 1;
        total += 1;
        if p.flags
            .intersects(PixelFlags::UNRESOLVED | PixelFlags::OFFSET_MISMATCH)
        {
            flagged += 1;
        }
        if p.s[0][0].is_finite() && p.s[1][0].is_finite() {
            both += 1;
        }
        for (k, t) in [f, b].iter().enumerate() {
            let s = p.s[k];
            if s[0].is_finite() {
                let err = (s[0] - t.u).hypot(s[1] - t.v);
                if err > 5.0 * p.std[k][0].hypot(p.std[k][1]) {
                    confident_wrong += 1;
                }
            }
        }
    }
    eprintln!("{thickness_mm} mm plate, {noise} noise: {both}/{total} both found, {flagged} flagged unresolved, {confident_wrong} points > 5σ off; scene model {}, flags {hist:?}", r.maps.scene_model);
    (flagged, both, confident_wrong, total)
}

fn thin_plates_are_resolved_or_flagged_never_guessed(engine: Engine) {
    // 1 mm: S2 − S1 ≈ 1.3 px ≈ 0.09 Fourier bins of the paper's schedule.
    let (flagged, both, wrong, total) = thin_plate_counts(1.0, 0.02, engine);
    assert_eq!(wrong, 0);
    assert_eq!(
        flagged + both,
        total,
        "every pixel is either found or flagged"
    );
    // 0.2 mm with 5 % noise: ≈ 0.02 bins, below what the data can separate.
    let (flagged, both, wrong, total) = thin_plate_counts(0.2, 0.05, engine);
    assert_eq!(wrong, 0);
    assert_eq!(flagged + both, total);
    assert!(
        flagged as f64 > 0.5 * total as f64,
        "{flagged}/{total} flagged"
    );
}

fn a_second_internal_round_trip_is_modelled_when_the_data_show_it(engine: Engine) {
    // Noise-free 16-bit frames with the third path (paper §5.1b): its
    // amplitude is R² ≈ 0.2 % of the back one's, ~25 counts against 0.29
    // counts of rounding — visible, so the scene's BIC must choose three
    // reflections, and S1, S2 must stay exact.
    let params = SimParams {
        third_reflection: true,
        ..SimParams::default()
    };
    let config = SpectralConfig {
        third_reflection: true,
        ..config(engine)
    };
    let r = run_with(&station(10.0), params.clone(), &paper_schedule(), config);
    assert_eq!(r.maps.scene_model, 3, "BIC sums {:?}", r.maps.bic_sums);
    for (k, (rms, _, worst, found, expected)) in score(&r).into_iter().enumerate() {
        eprintln!("three reflections, S{}: RMS {rms:.2e} px, worst {worst:.2e} px, found {found}/{expected}", k + 1);
        assert!(worst <= 0.01, "S{}: worst {worst} px", k + 1);
        assert!(
            found as f64 >= 0.98 * expected as f64,
            "S{}: {found}/{expected}",
            k + 1
        );
    }
    // Ignoring the third path biases S2: measured, not asserted.
    let r2 = run(&station(10.0), params, &paper_schedule(), engine);
    let s = score(&r2);
    eprintln!(
        "two-reflection model on the same frames: S1 worst {:.3e} px, S2 worst {:.3e} px",
        s[0].2, s[1].2
    );
}

fn any_schedule_works_plain_directions_uneven_taus_and_phase_shifts(engine: Engine) {
    // 0° and 60° fringes, τ on an uneven grid (every third step of 0.2
    // missing), alternating phase shifts of 0 and π/2: the periodogram falls
    // back to a direct DFT and the model carries the phases. (Not 0°/90°:
    // the back reflection's offset lies along u, so 90° fringes cannot tell
    // the two points' v apart — see docs/spectral.md.)
    let mut patterns = Vec::new();
    for direction_deg in [0.0, 60.0] {
        for k in (1..=1000).filter(|k| k % 3 != 0) {
            let phase_rad = if k % 2 == 0 {
                0.0
            } else {
                std::f64::consts::FRAC_PI_2
            };
            patterns.push(mfd::acquire::patterns::Pattern {
                direction_deg,
                tau: 0.2 * k as f64,
                phase_rad,
            });
        }
    }
    let r = run_patterns(
        &station(10.0),
        SimParams::default(),
        &patterns,
        config(engine),
    );
    for (k, (rms, _, worst, found, expected)) in score(&r).into_iter().enumerate() {
        eprintln!("0°/60°, uneven τ, phases: S{}: RMS {rms:.2e} px, worst {worst:.2e} px, found {found}/{expected}", k + 1);
        assert!(worst <= 0.01, "S{}: worst {worst} px", k + 1);
        assert!(
            found as f64 >= 0.99 * expected as f64,
            "S{}: {found}/{expected}",
            k + 1
        );
    }
}

/// Both engines (issue 39). The statistics engine used to find the points
/// on 36 % (screen period) and 39 % (falloff on τ) of these pixels, the
/// rest flagged NO_SIGNAL | OUT_OF_BAND: its detection held the band's
/// periodogram peak against the series' whole variance, signal included,
/// which capped the ratio near n/2 times the falloff's share whatever the
/// noise; the 182 frames of the 90° direction never reached the threshold.
/// It now holds it against the residual of the peak's sinusoid, the noise,
/// as the series engine's whole-spectrum median does. With one κ for every
/// direction (tried by grouping every axis together) this test fails: S1 /
/// S2 at 1.47× / 1.51× their bound.
fn four_directions_under_a_blurs_falloff_reach_the_bound(engine: Engine) {
    // ±45°, 0° and 90°, rendered with the falloff on the fringe's period
    // on the screen (a blur's: on the 1600 × 1200 screen the plain
    // directions' fringes are ℓ = 1.24× and 1.65× finer than the
    // diagonals' at equal τ, so their modulation falls off sooner). The
    // model fits one κ per fringe length; with one κ for all directions
    // the same kind of schedule on the paper's station came out 355 nm off
    // with 2 nm reported (docs/figures.md, "Planned schedules"). Each
    // direction runs τ = 0.5 … 150/ℓ, the same finest screen period as
    // the diagonals' τ = 150 (their κ in τ units still differ by ℓ²);
    // with τ to 150 on every direction the 90° fringes past τ ≈ 91 are
    // finer than any the diagonals show, and the statistics engine's band
    // detection then finds no signal on 4 % of the pixels, the dim ones,
    // where the series engine finds all. The bound is the joint model's at the truth with the physical
    // falloff (`run_patterns`); the criteria are those of
    // `five_percent_noise_reaches_the_bound`.
    let st = station(10.0);
    let (w, h) = (st.screen.width, st.screen.height);
    let mut patterns = Vec::new();
    for direction_deg in [45.0, -45.0, 0.0, 90.0] {
        let l = mfd::acquire::patterns::FringeAxis::new(direction_deg, w, h)
            .stretch_from_diagonal(w, h);
        for k in 1..=(300.0 / l) as usize {
            patterns.push(mfd::acquire::patterns::Pattern {
                direction_deg,
                tau: 0.5 * k as f64,
                phase_rad: 0.0,
            });
        }
    }
    let params = SimParams {
        noise_frac: 0.05,
        seed: 4,
        falloff: mfd::sim::Falloff::ScreenPeriod,
        ..SimParams::default()
    };
    let r = run_patterns(&st, params, &patterns, config(engine));
    assert_near_the_bound(&r, "four directions, screen-period falloff, 5 % noise");
    // Errors over the reported σ, both reflections: unit RMS (±10 % for
    // ~4000 coordinates, 5σ); a falloff wrong on some directions biases
    // the points and shows here first.
    let z = error_over_sigma(&r, &[0, 1]);
    assert!((0.9..1.1).contains(&z), "{z}");
}

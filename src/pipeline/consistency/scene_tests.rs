//! Case 6 of issue 19 on maps built from the independent fixture's
//! station: every pixel measured at its nominal-plate prediction with
//! noise, then some pixels given an alias (30–100 px off) or a residual
//! 25× the noise. Before this pass both were reported as found.

use super::*;
use crate::solve::spectral::{nominal_plate_prior, PixelResult};
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;

/// The paper's kind of schedule: τ 0.5…100 step 0.5, both diagonals.
fn design(station: &Station) -> Design {
    let frames = crate::acquire::acquisition::FrameInfo::from_patterns(
        &crate::acquire::patterns::Schedule {
            directions_deg: vec![45.0, -45.0],
            tau_start: 0.5,
            tau_stop: 100.0,
            tau_step: 0.5,
            phases_rad: vec![0.0],
        }
        .patterns(),
    );
    crate::solve::spectral::design(station, &frames).unwrap()
}

fn scene() -> (Station, TracedView, SpectralMaps) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/public-small/station.toml");
    let station = Station::load(&path).unwrap();
    let prior = nominal_plate_prior(&station, 0.0).unwrap();
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(19);
    let sigma = 0.25;
    let pixels = prior
        .pixels
        .iter()
        .map(|p| {
            let mut r = PixelResult::empty();
            let (Ok(f), Ok(b)) = (p.front, p.back) else {
                return r;
            };
            for (i, hit) in [f, b].iter().enumerate() {
                let n: [f64; 2] = [rng.sample(StandardNormal), rng.sample(StandardNormal)];
                r.s[i] = [hit.u + sigma * n[0], hit.v + sigma * n[1]];
                r.std[i] = [sigma, sigma];
            }
            // Shot noise: variance 1 + A/100 counts², A 50…250.
            let a: f64 = rng.random_range(50.0..250.0);
            let var = 1.0 + a / 100.0;
            let chi2: f64 = (0..400)
                .map(|_| rng.sample::<f64, _>(StandardNormal).powi(2))
                .sum::<f64>()
                / 400.0;
            r.amp = [a, 30.0, 20.0, f64::NAN];
            r.residual_rms = (var * chi2).sqrt();
            r.model = 2;
            r
        })
        .collect();
    let maps = SpectralMaps {
        width: prior.width,
        height: prior.pixels.len() / prior.width,
        pixels,
        preferred: Vec::new(),
        scene_model: 2,
        bic_sums: [0.0; 3],
        saturation_counts: None,
    };
    (station, prior, maps)
}

#[test]
fn aliases_and_fits_far_above_the_noise_are_flagged_and_good_pixels_kept() {
    let (station, prior, mut maps) = scene();
    let measured: Vec<usize> = (0..maps.pixels.len())
        .filter(|&k| maps.pixels[k].s[0][0].is_finite())
        .collect();
    assert!(measured.len() > 500, "{}", measured.len());
    // Every 20th measured pixel on an alias 30–100 px away, every 20th
    // (offset by 10) with a residual 25× the noise.
    let (mut aliased, mut poor) = (Vec::new(), Vec::new());
    for (i, &k) in measured.iter().enumerate() {
        let p = &mut maps.pixels[k];
        if i % 20 == 0 {
            let d = 30.0 + 70.0 * (i as f64 / measured.len() as f64);
            p.s[0][0] += d;
            aliased.push(k);
        } else if i % 20 == 10 {
            p.residual_rms *= 25.0;
            poor.push(k);
        }
    }
    let c = check(
        &mut maps,
        &prior,
        &station,
        &design(&station),
        Limits::default(),
    );
    for &k in &aliased {
        assert!(
            maps.pixels[k].flags.contains(PixelFlags::FAR_FROM_PRIOR),
            "pixel {k}"
        );
        assert!(maps.pixels[k].s[0][0].is_nan());
    }
    for &k in &poor {
        assert!(
            maps.pixels[k].flags.contains(PixelFlags::POOR_FIT),
            "pixel {k}"
        );
    }
    // Good pixels: none lost (5σ plus the spread; a χ² tail of 1e-15).
    let lost = measured
        .iter()
        .filter(|k| !aliased.contains(k) && !poor.contains(k))
        .filter(|&&k| maps.pixels[k].s[0][0].is_nan())
        .count();
    assert_eq!(lost, 0);
    assert_eq!(c.far_pixels, aliased.len());
    assert_eq!(c.poor_fit_pixels, poor.len());
    assert!(c.consistent, "{}", c.note);
}

#[test]
fn a_global_shift_beyond_the_spread_is_inconsistent_and_flags_no_pixel() {
    let (station, prior, mut maps) = scene();
    // Every point 40 px off: a wrong station, not 40 bad pixels.
    for p in &mut maps.pixels {
        p.s[0][0] += 40.0;
        p.s[1][0] += 40.0;
    }
    let c = check(
        &mut maps,
        &prior,
        &station,
        &design(&station),
        Limits::default(),
    );
    assert!(!c.consistent, "{}", c.note);
    assert_eq!(c.far_pixels, 0);
    assert!(
        (c.median_displacement_px.unwrap()[0] - 40.0).abs() < 0.1,
        "{c:?}"
    );
    assert!(c.note.contains("contradict"), "{}", c.note);
    // Within the spread: consistent.
    let (station, prior, mut maps) = scene();
    for p in &mut maps.pixels {
        p.s[0][0] += 1.0;
    }
    let c = check(
        &mut maps,
        &prior,
        &station,
        &design(&station),
        Limits::default(),
    );
    assert!(c.consistent, "{}", c.note);
}

//! The budget's total uncertainty is honest under geometry error (issue 15,
//! second Done-when): on the 48 × 48 bench station, stations drawn from a
//! correlated covariance over camera, screen, element, thickness and index
//! are the truth; frames' points are traced on each through a non-flat
//! element, noise is drawn from the schedule's Cramér–Rao bound, and the
//! points are reconstructed with the nominal station. Per coefficient the
//! RMS of (error / reported total σ) must be within 0.8–1.25, front and
//! back, and per surface the Monte Carlo RMS error must agree with the
//! linear budget's.

use mfd::acquire::acquisition::FrameInfo;
use mfd::acquire::patterns::Schedule;
use mfd::budget::assemble::budget;
use mfd::budget::monte_carlo::monte_carlo;
use mfd::budget::scene::{scene, Radiometry, SceneOptions};
use mfd::budget::table::{rss_j4, total_std_nm};
use mfd::optics::station::{bench_station, Dof, StationUncertainty};
use mfd::sim::RandomSurfaceSpec;
use nalgebra::DMatrix;

/// Draws. The RMS `r` of N standard normal ratios has `r² ~ χ²_N / N`, so
/// `sd(r) ≈ 1/√(2N)`. With N = 160, sd = 0.056: the bounds 0.8 and 1.25
/// sit 3.6σ and 4.5σ from 1, so the 28 free coefficients (j = 2…15, front
/// and back) pass together with probability > 99 % when the σ are right,
/// while a σ 25 % off fails.
const DRAWS: usize = 160;
const TERMS: usize = 15;

/// A correlated covariance over seven degrees of freedom, σ of a careful
/// calibration's order (the camera and screen distances correlated as a
/// joint resection makes them, thickness and index as the back's offset
/// ties them).
fn uncertainty() -> StationUncertainty {
    let names = vec![
        Dof::CameraZ,
        Dof::CameraX,
        Dof::ScreenZ,
        Dof::ScreenRz,
        Dof::ElementRx,
        Dof::Thickness,
        Dof::RefractiveIndex,
    ];
    let std = [0.5, 0.3, 0.5, 0.02, 0.01, 0.005, 5e-4];
    let mut corr = DMatrix::identity(7, 7);
    for (a, b, r) in [(0, 2, 0.6), (1, 3, -0.4), (5, 6, 0.5), (0, 4, 0.2)] {
        corr[(a, b)] = r;
        corr[(b, a)] = r;
    }
    assert!(corr.clone().cholesky().is_some(), "a covariance");
    StationUncertainty {
        station: "bench".into(),
        covariance: DMatrix::from_fn(7, 7, |r, c| corr[(r, c)] * std[r] * std[c]),
        names,
        correlated: 7,
    }
}

#[test]
fn total_uncertainty_is_honest_under_geometry_error() {
    let station = bench_station(10.0, 1.5, 15.0).unwrap();
    let spec = RandomSurfaceSpec {
        n_terms: TERMS,
        ..RandomSurfaceSpec::default()
    };
    let surfaces = spec.draw_pair(25.5, [0.0, 0.0], 7).unwrap();
    let schedule = Schedule {
        tau_start: 0.5,
        tau_stop: 100.0,
        tau_step: 0.5,
        ..Schedule::default()
    };
    let frames = FrameInfo::from_patterns(&schedule.patterns());
    let opts = SceneOptions {
        radiometry: Radiometry {
            noise_frac: 0.02,
            ..Radiometry::default()
        },
        terms: TERMS,
        ..SceneOptions::default()
    };
    let unc = uncertainty();
    let sc = scene(&station, surfaces, &frames, &opts).unwrap();
    let b = budget(
        &sc.observations,
        &station,
        &unc,
        &sc.solution,
        &opts.surface_options(),
    )
    .unwrap();
    let mc = monte_carlo(&station, &unc, &sc, &opts, DRAWS, 11).unwrap();
    for (back, errors, rms) in [
        (false, &mc.front_errors_nm, &mc.front_rms_nm),
        (true, &mc.back_errors_nm, &mc.back_rms_nm),
    ] {
        let sigma = total_std_nm(&b, back);
        let noise = &b.others[0];
        let noise = if back {
            &noise.back_nm
        } else {
            &noise.front_nm
        };
        let mut checked = 0;
        for k in 0..TERMS {
            if sigma[k] == 0.0 {
                continue; // a fixed coefficient (the pistons)
            }
            let z = (errors
                .iter()
                .map(|e| (e[k] / sigma[k]).powi(2))
                .sum::<f64>()
                / DRAWS as f64)
                .sqrt();
            println!(
                "{} j={}: σ {:.3} nm (noise {:.3}), MC RMS {:.3} nm, RMS(error/σ) {z:.3}",
                if back { "back" } else { "front" },
                k + 1,
                sigma[k],
                noise[k],
                rms[k]
            );
            assert!((0.8..1.25).contains(&z), "coefficient {k}: {z}");
            checked += 1;
        }
        assert!(checked >= TERMS - 1);
        // Geometry, not noise, must dominate, or the test would only check
        // the noise's bound: the total over j ≥ 4 at least twice the noise's.
        assert!(
            rss_j4(&sigma) > 2.0 * rss_j4(noise),
            "{} vs {}",
            rss_j4(&sigma),
            rss_j4(noise)
        );
        // The surface's expected RMS error (j ≥ 4): the same spread as one
        // coefficient's at worst (one term dominating), so the same bounds.
        let ratio = rss_j4(rms) / rss_j4(&sigma);
        println!("surface RMS error: Monte Carlo / linear = {ratio:.3}");
        assert!((0.8..1.25).contains(&ratio), "{ratio}");
    }
}

//! `--refine`: degrees of freedom estimated jointly with the surfaces,
//! checked on simulated truth — a station given wrong by a known amount is
//! pulled back to the truth, and the reported posterior σ is the estimates'
//! actual scatter over noise seeds.

use nalgebra::DMatrix;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;

use mfd::budget::refine::{refine, RefineError};
use mfd::optics::station::{bench_station, Dof, Station, StationUncertainty};
use mfd::optics::trace::{Plate, TracedView, DEFAULT_EDGE_MARGIN_MM};
use mfd::sim::RandomSurfaceSpec;
use mfd::solve::surfaces::{Observations, SurfaceOptions, Uncertainty};

/// σ of every screen coordinate, px.
const SIGMA_PX: f64 = 0.05;

/// Screen points traced on the true station `truth` with Gaussian noise,
/// read as the operator does: on the `assumed` station.
fn noisy(truth: &Station, assumed: &Station, seed: u64) -> Observations {
    // The model's own 15 terms: the fit is exact but for the noise (a
    // truncated truth leaves systematic residuals the linear σ ignores).
    let spec = RandomSurfaceSpec {
        n_terms: 15,
        ..RandomSurfaceSpec::default()
    };
    let r = truth.element.aperture_radius_mm;
    let (front, back) = spec.draw_pair(r, [0.0, 0.0], 3).unwrap();
    let plate = Plate::new(truth, front, back, DEFAULT_EDGE_MARGIN_MM);
    let mut coords = TracedView::trace(truth, &plate).screen_coords();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    for c in &mut coords {
        let z: f64 = StandardNormal.sample(&mut rng);
        *c += SIGMA_PX * z;
    }
    let std = vec![SIGMA_PX; coords.len()];
    Observations::from_maps(assumed, &coords, Uncertainty::Std(&std)).unwrap()
}

fn opts() -> SurfaceOptions {
    SurfaceOptions {
        terms: Some(15),
        ..SurfaceOptions::default()
    }
}

fn prior(stds: &[(Dof, f64)]) -> StationUncertainty {
    StationUncertainty {
        station: "station.toml".into(),
        names: stds.iter().map(|d| d.0).collect(),
        covariance: DMatrix::from_diagonal(&nalgebra::DVector::from_iterator(
            stds.len(),
            stds.iter().map(|d| d.1 * d.1),
        )),
        correlated: 0,
    }
}

#[test]
fn a_screen_turn_given_wrong_is_measured_with_its_posterior_sigma() {
    let truth = bench_station(10.0, 1.5, 15.0).unwrap();
    // The screen's turn about its normal known to 0.05° a priori, given
    // wrong by 0.08° (1.6 prior σ).
    let (dof, sigma, wrong) = (Dof::ScreenRz, 0.05, 0.08);
    let assumed = truth.perturbed(dof, wrong);
    let unc = prior(&[(dof, sigma), (Dof::CameraZ, 0.5)]);
    const SEEDS: u64 = 24;
    let (mut sum2, mut var) = (0.0, 0.0);
    for seed in 0..SEEDS {
        let obs = noisy(&truth, &assumed, 40 + seed);
        let r = refine(&obs, &assumed, &unc, &[dof], &opts()).unwrap();
        assert!(r.converged, "seed {seed}: {} iterations", r.iterations);
        let e = &r.estimates[0];
        // The estimate's error: it should undo the 0.08°.
        let err = e.change + wrong;
        sum2 += err * err;
        var += e.posterior_std * e.posterior_std;
        if seed == 0 {
            println!(
                "screen.rz: change {:.5}° (wrong by {wrong}°), posterior σ {:.2e}° (prior {sigma}°), {} iterations",
                e.change, e.posterior_std, r.iterations
            );
            // The data pin it: posterior far below the prior.
            assert!(e.posterior_std < 0.1 * sigma, "{e:?}");
            // The uncertainty handed on carries the posterior.
            assert!((r.uncertainty.covariance[(0, 0)].sqrt() - e.posterior_std).abs() < 1e-15);
            assert_eq!(r.uncertainty.covariance[(1, 1)], 0.25);
        }
    }
    // With the prior's pull negligible (posterior ≪ prior), the errors
    // scatter about 0: n · ratio² ~ χ²(24); its 0.5 % / 99.5 % quantiles
    // 9.89 / 45.56 bound the ratio to [0.64, 1.38] (99 %).
    let n = SEEDS as f64;
    let ratio = (sum2 / var).sqrt();
    println!("screen.rz: RMS error / posterior σ = {ratio:.3} over {SEEDS} seeds");
    assert!(
        (9.89 / n).sqrt() <= ratio && ratio <= (45.56 / n).sqrt(),
        "ratio {ratio}"
    );
}

#[test]
fn a_degree_of_freedom_without_a_prior_is_refused() {
    let s = bench_station(10.0, 1.5, 15.0).unwrap();
    let obs = noisy(&s, &s, 1);
    let unc = prior(&[(Dof::CameraZ, 0.5)]);
    let err = refine(&obs, &s, &unc, &[Dof::Thickness], &opts()).unwrap_err();
    assert!(matches!(err, RefineError::NoPrior { .. }), "{err}");
    assert!(err.to_string().contains("element.thickness_mm"), "{err}");
}

//! What the data pin down, checked on simulated truth: the thickness
//! estimated jointly with the surfaces scatters over noise seeds as its
//! reported data σ says; exact degeneracies (the element's z against the
//! camera's and screen's, the thickness against the back's piston) are
//! reported as such.

use nalgebra::{DMatrix, Vector3};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;

use mfd::budget::assemble::budget;
use mfd::budget::fisher::joint_step;
use mfd::budget::linear::linearise;
use mfd::optics::station::{
    bench_station, CoverGlass, Distortion, Dof, Station, StationUncertainty,
};
use mfd::optics::trace::{Plate, TracedView, DEFAULT_EDGE_MARGIN_MM};
use mfd::sim::RandomSurfaceSpec;
use mfd::solve::surfaces::{reconstruct, Observations, SurfaceOptions, Uncertainty};

/// The bench station with every version-2 feature (as `budget_linear.rs`).
fn v2_bench() -> Station {
    let mut s = bench_station(10.0, 1.5, 15.0).unwrap();
    s.camera.distortion = Some(Distortion {
        k: [-0.12, 0.03, 0.0],
        p: [0.0004, -0.0002],
    });
    s.screen.cover_glass = Some(CoverGlass {
        thickness_mm: 1.8,
        refractive_index: 1.52,
    });
    s.element.pose.tilt_deg = [1.0, -0.3];
    s.element.pose.offset_mm = Vector3::new(0.05, -0.02, 0.012);
    s
}

/// σ of every screen coordinate, px.
const SIGMA_PX: f64 = 0.05;

/// Observations traced on `s` with Gaussian noise of [`SIGMA_PX`] (seeded).
fn noisy(s: &Station, seed: u64) -> Observations {
    // The model's own 15 terms: the fit is exact but for the noise.
    let spec = RandomSurfaceSpec {
        n_terms: 15,
        ..RandomSurfaceSpec::default()
    };
    let (front, back) = spec
        .draw_pair(s.element.aperture_radius_mm, [0.0, 0.0], 1)
        .unwrap();
    let plate = Plate::new(s, front, back, DEFAULT_EDGE_MARGIN_MM);
    let mut coords = TracedView::trace(s, &plate).screen_coords();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    for c in &mut coords {
        let z: f64 = StandardNormal.sample(&mut rng);
        *c += SIGMA_PX * z;
    }
    let std = vec![SIGMA_PX; coords.len()];
    Observations::from_maps(s, &coords, Uncertainty::Std(&std)).unwrap()
}

fn opts() -> SurfaceOptions {
    SurfaceOptions {
        terms: Some(15),
        ..SurfaceOptions::default()
    }
}

fn uncertainty(stds: &[(Dof, f64)]) -> StationUncertainty {
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
fn thickness_estimated_with_the_surfaces_scatters_as_its_data_sigma() {
    let s = v2_bench();
    const SEEDS: u64 = 40;
    let (mut sum2, mut var) = (0.0, 0.0);
    for seed in 0..SEEDS {
        let obs = noisy(&s, 100 + seed);
        let sol = reconstruct(&obs, &s, &opts()).unwrap();
        let lin = linearise(&obs, &s, &sol, &opts()).unwrap();
        // One Gauss–Newton step from the true station: the joint
        // least-squares estimate of the thickness to first order.
        let (step, cov) = joint_step(&lin, &[Dof::Thickness]).unwrap();
        sum2 += step[0] * step[0];
        var += cov[(0, 0)];
        if seed == 0 {
            // The budget's single-DOF entry reports the same σ, in σ units.
            let prior = 0.01;
            let b = budget(
                &obs,
                &s,
                &uncertainty(&[(Dof::Thickness, prior)]),
                &sol,
                &opts(),
            )
            .unwrap();
            let data = b.identifiability[0].data_std.unwrap() * prior;
            assert!((data - cov[(0, 0)].sqrt()).abs() <= 1e-9 * data, "{data}");
            println!("thickness data σ {:.3e} mm", cov[(0, 0)].sqrt());
        }
    }
    let n = SEEDS as f64;
    let ratio = (sum2 / var).sqrt();
    // The estimates scatter about the truth (mean known): n · ratio² is
    // χ² with n = 40 degrees of freedom; its 0.5 % and 99.5 % quantiles
    // 20.71 and 66.77 bound the ratio to [0.72, 1.29] (99 %).
    println!("thickness: RMS error / data σ = {ratio:.3} over {SEEDS} seeds");
    assert!(
        (20.71 / n).sqrt() <= ratio && ratio <= (66.77 / n).sqrt(),
        "ratio {ratio}"
    );
}

#[test]
fn exact_degeneracies_are_reported_as_such() {
    let s = v2_bench();
    let obs = noisy(&s, 7);
    let sol = reconstruct(&obs, &s, &opts()).unwrap();
    // Moving element, camera and screen together by δ along z moves
    // nothing relative to anything: (δ/σe, δ/σc, δ/σs) is invisible.
    let stds = [
        (Dof::ElementZ, 0.01),
        (Dof::CameraZ, 0.1),
        (Dof::ScreenZ, 0.2),
        (Dof::Thickness, 0.002),
    ];
    let b = budget(&obs, &s, &uncertainty(&stds), &sol, &opts()).unwrap();
    for e in &b.identifiability {
        println!("{:?}", e);
    }
    let worst = &b.identifiability[stds.len()];
    assert_eq!(worst.data_std, None, "{worst:?}");
    let null = [1.0 / 0.01, 1.0 / 0.1, 1.0 / 0.2, 0.0];
    let norm = null.iter().map(|x| x * x).sum::<f64>().sqrt();
    let overlap: f64 = worst
        .combination
        .iter()
        .zip(null)
        .map(|((_, w), x)| w * x / norm)
        .sum();
    // The eigenvector of a null eigenvalue separated from the next by
    // many orders: its direction is exact to rounding.
    assert!(overlap.abs() > 1.0 - 1e-6, "overlap {overlap}");
    // Each alone is determined: the S1 data fix the element's z (the
    // front's piston is the reference plane's).
    assert!(b.identifiability[..stds.len()]
        .iter()
        .all(|e| e.data_std.is_some()));

    // The back's piston against its tilt: the solve itself refuses a free
    // back piston (its normal equations are singular to working
    // precision), so the thickness's own degeneracy with it never reaches
    // the budget; with the piston fixed the thickness is determined, if
    // poorly (the entry above).
    let with_piston = SurfaceOptions {
        back_piston: true,
        ..opts()
    };
    let refused = reconstruct(&obs, &s, &with_piston);
    println!("free back piston: {:?}", refused.as_ref().err());
    assert!(matches!(
        refused,
        Err(mfd::solve::surfaces::SurfaceError::IllConditioned { .. })
    ));
}

//! The surfaces' error induced by the station's uncertainty
//! (`mfd-station-uncertainty/1`): the predicted covariance against the
//! actual error of plates traced on stations drawn from that uncertainty
//! and reconstructed on the nominal one.

use std::path::Path;

use mfd::optics::station::{bench_station, Dof, Station, StationUncertainty};
use mfd::optics::trace::{Plate, TracedView, DEFAULT_EDGE_MARGIN_MM};
use mfd::sim::RandomSurfaceSpec;
use mfd::solve::surfaces::station_error::station_induced;
use mfd::solve::surfaces::{reconstruct, Observations, SurfaceOptions, Uncertainty};
use rand::{Rng, SeedableRng};

/// A datasheet-like uncertainty: positions to 0.2–0.5 mm, angles to
/// 0.01–0.02°, the plate to 2 µm and 2e-4.
const UNCERTAINTY: &str = r#"
format = "mfd-station-uncertainty/1"
station = "bench"
[std]
"camera.x_mm" = 0.3
"camera.z_mm" = 0.5
"camera.ry_deg" = 0.01
"screen.z_mm" = 0.5
"screen.rx_deg" = 0.02
"element.z_mm" = 0.002
"element.rx_deg" = 0.003
"element.thickness_mm" = 0.002
"element.refractive_index" = 0.0002
"#;

fn rms_diff(a: &[f64], b: &[f64]) -> f64 {
    (3..a.len().max(b.len()))
        .map(|k| a.get(k).copied().unwrap_or(0.0) - b.get(k).copied().unwrap_or(0.0))
        .map(|d| d * d)
        .sum::<f64>()
        .sqrt()
}

fn opts() -> SurfaceOptions {
    SurfaceOptions {
        terms: Some(21),
        ..SurfaceOptions::default()
    }
}

#[test]
fn induced_error_matches_stations_drawn_from_the_uncertainty() {
    let nominal: Station = bench_station(10.0, 1.5, 15.0).unwrap();
    let unc = StationUncertainty::from_toml_str(UNCERTAINTY, Path::new("u.toml")).unwrap();
    let spec = RandomSurfaceSpec {
        n_terms: 21,
        ..RandomSurfaceSpec::default()
    };
    let (front, back) = spec.draw_pair(25.5, [0.0, 0.0], 3).unwrap();
    let plate = |s: &Station| Plate::new(s, front.clone(), back.clone(), DEFAULT_EDGE_MARGIN_MM);
    let coords = TracedView::trace(&nominal, &plate(&nominal)).screen_coords();
    let obs = Observations::from_maps(&nominal, &coords, Uncertainty::Unknown).unwrap();
    let base = reconstruct(&obs, &nominal, &opts()).unwrap();
    let induced = station_induced(&obs, &nominal, &unc, &base, &opts()).unwrap();
    println!(
        "predicted: front {:.3} nm, back {:.3} nm; largest share {:?}",
        induced.front_rms_nm, induced.back_rms_nm, induced.shares[0]
    );
    // Stations drawn from the uncertainty (independent Gaussian per σ),
    // the plate traced on each and reconstructed on the nominal one.
    let mut rng = rand::rngs::StdRng::seed_from_u64(17);
    let (mut sf, mut sb) = (0.0, 0.0);
    const DRAWS: usize = 48;
    for _ in 0..DRAWS {
        let mut truth = nominal.clone();
        for (k, &dof) in unc.names.iter().enumerate() {
            let z: f64 = rng.sample(rand_distr::StandardNormal);
            truth = truth.perturbed(dof, z * unc.covariance[(k, k)].sqrt());
        }
        let coords = TracedView::trace(&truth, &plate(&truth)).screen_coords();
        let obs = Observations::from_maps(&nominal, &coords, Uncertainty::Unknown).unwrap();
        let sol = reconstruct(&obs, &nominal, &opts()).unwrap();
        sf += rms_diff(sol.front.coefficients_nm(), front.coefficients_nm()).powi(2);
        sb += rms_diff(sol.back.coefficients_nm(), back.coefficients_nm()).powi(2);
    }
    let (af, ab) = ((sf / DRAWS as f64).sqrt(), (sb / DRAWS as f64).sqrt());
    let (rf, rb) = (af / induced.front_rms_nm, ab / induced.back_rms_nm);
    println!("actual RMS: front {af:.3} nm, back {ab:.3} nm; actual / predicted {rf:.3}, {rb:.3}");
    // The squared error summed over the terms j ≥ 4 is a weighted sum of
    // χ² variables; over 48 draws its mean has a relative spread of at
    // most √(2/48) = 0.20 (one dominant direction), so its root within
    // ±0.10 at 1σ; ±30 % is 3σ. Linearity of a one-σ step adds < 1 %.
    assert!((0.7..1.3).contains(&rf), "front actual / predicted {rf}");
    assert!((0.7..1.3).contains(&rb), "back actual / predicted {rb}");
    assert!(unc.names.contains(&Dof::Thickness));
}

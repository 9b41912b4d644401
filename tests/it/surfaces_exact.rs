//! Surface solvers on noise-free screen points from the exact tracer: the
//! reconstruction must converge to the truth (issue: front ≤ 0.1 nm, back
//! ≤ 0.5 nm RMS, piston and tilt removed).

use crate::common;

use mfd::optics::station::Station;
use mfd::optics::trace::{Plate, TracedView, DEFAULT_EDGE_MARGIN_MM};
use mfd::optics::zernike::ZernikeSurface;
use mfd::sim::RandomSurfaceSpec;
use mfd::solve::surfaces::{reconstruct, Observations, SurfaceOptions};

/// RMS over the unit disk of the difference, piston and tilt removed: with
/// RMS-normalised orthonormal Zernike terms, the root sum of squares of the
/// coefficient differences from Noll j = 4 on.
fn rms_err(a: &ZernikeSurface, b: &[f64]) -> f64 {
    let a = a.coefficients_nm();
    let n = a.len().max(b.len());
    (3..n)
        .map(|k| a.get(k).copied().unwrap_or(0.0) - b.get(k).copied().unwrap_or(0.0))
        .map(|d| d * d)
        .sum::<f64>()
        .sqrt()
}

fn run(station: &Station, terms: Option<usize>, seed: u64) -> (f64, f64) {
    let e = &station.element;
    let spec = RandomSurfaceSpec::default();
    let (front, back) = spec
        .draw_pair(
            e.aperture_radius_mm,
            [e.aperture_center_mm.x, e.aperture_center_mm.y],
            seed,
        )
        .unwrap();
    let plate = Plate::new(station, front.clone(), back.clone(), DEFAULT_EDGE_MARGIN_MM);
    let view = TracedView::trace(station, &plate);
    let coords = view.screen_coords();
    let obs = Observations::from_maps(station, &coords, mfd::solve::surfaces::Uncertainty::Unknown)
        .unwrap();
    let opts = SurfaceOptions {
        terms,
        ..SurfaceOptions::default()
    };
    let sol = reconstruct(&obs, station, &opts).unwrap();
    for s in &sol.stages {
        println!("{} {:.2}s {:?} {:?}", s.name, s.seconds, s.front, s.lm);
    }
    println!(
        "choice {:?}",
        sol.choice
            .as_ref()
            .map(|c| (c.front.terms, c.back.as_ref().map(|b| b.terms)))
    );
    println!("cond {:.3e} chi2 {:.3e}", sol.condition_number, sol.chi2);
    let ef = rms_err(&sol.front, front.coefficients_nm());
    let eb = rms_err(&sol.back, back.coefficients_nm());
    println!(
        "front err {ef:.3e} nm, back err {eb:.3e} nm, back piston {:.3e}",
        sol.back.coefficients_nm()[0]
    );
    (ef, eb)
}

/// The 48×48 bench station with another plate and tilt.
fn tilted_station(thickness_mm: f64, index: f64, tilt_deg: f64) -> Station {
    mfd::optics::station::bench_station(thickness_mm, index, tilt_deg).unwrap()
}

#[test]
fn fixture_station_noise_free_36_terms() {
    let station = Station::load(&common::public_small().join("station.toml")).unwrap();
    let (ef, eb) = run(&station, Some(36), 5);
    assert!(ef < 0.1 && eb < 0.5, "front {ef} back {eb}");
}

#[test]
fn fixture_station_noise_free_terms_chosen() {
    let station = Station::load(&common::public_small().join("station.toml")).unwrap();
    let (ef, eb) = run(&station, None, 6);
    assert!(ef < 0.1 && eb < 0.5, "front {ef} back {eb}");
}

/// A 40 mm, n = 2.4 plate at 35°: the back is seen over a small part of
/// the disk. With 231 terms fixed the back stage stops and names the
/// condition number; when the data choose, the back model shrinks until it
/// is determined (and the stage reports the condition number it reached).
#[test]
fn undetermined_back_stops_or_shrinks() {
    let station = tilted_station(40.0, 2.4, 35.0);
    let e = &station.element;
    let spec = RandomSurfaceSpec {
        n_terms: 231,
        ..RandomSurfaceSpec::default()
    };
    let (front, back) = spec.draw_pair(e.aperture_radius_mm, [0.0, 0.0], 9).unwrap();
    let plate = Plate::new(&station, front, back, DEFAULT_EDGE_MARGIN_MM);
    let coords = TracedView::trace(&station, &plate).screen_coords();
    let obs = Observations::from_maps(
        &station,
        &coords,
        mfd::solve::surfaces::Uncertainty::Unknown,
    )
    .unwrap();
    let err = reconstruct(
        &obs,
        &station,
        &SurfaceOptions {
            terms: Some(231),
            ..SurfaceOptions::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("ill-conditioned") && err.contains("condition number"),
        "{err}"
    );
    let sol = reconstruct(
        &obs,
        &station,
        &SurfaceOptions {
            max_terms: 231,
            ..SurfaceOptions::default()
        },
    )
    .unwrap();
    assert!(sol.back.n_terms() < 231);
    assert!(sol.condition_number <= mfd::solve::surfaces::lm::MAX_CONDITION_NUMBER);
}

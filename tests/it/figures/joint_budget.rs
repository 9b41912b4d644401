//! The joint covariance the plate's figures are drawn from, on a solution
//! with an error budget: its front and back blocks are the budget's own
//! totals, and its cross block carries what the faces share, which a
//! per-face covariance would lose.

use nalgebra::DMatrix;

use mfd::budget::assemble::budget;
use mfd::optics::station::{bench_station, Dof, StationUncertainty};
use mfd::optics::trace::{Plate, TracedView, DEFAULT_EDGE_MARGIN_MM};
use mfd::report::figures::joint::{covariance, of_solution};
use mfd::report::figures::{figures, FigureInput};
use mfd::sim::RandomSurfaceSpec;
use mfd::solve::surfaces::{reconstruct, Observations, SurfaceOptions, Uncertainty};

/// The bench station (48 × 48, 10 mm plate of n = 1.5), noise-free points
/// of random 15-term surfaces, and a station uncertainty of the element's
/// tilt alone (0.01° about x and y): a tilt both faces share.
#[test]
fn the_joint_covariance_is_the_budgets_and_keeps_the_shared_tilt_out_of_the_wedge() {
    let s = bench_station(10.0, 1.5, 15.0).unwrap();
    let (front, back) = RandomSurfaceSpec {
        n_terms: 15,
        ..RandomSurfaceSpec::default()
    }
    .draw_pair(s.element.aperture_radius_mm, [0.0, 0.0], 5)
    .unwrap();
    let plate = Plate::new(&s, front, back, DEFAULT_EDGE_MARGIN_MM);
    let coords = TracedView::trace(&s, &plate).screen_coords();
    let obs = Observations::from_maps(&s, &coords, Uncertainty::Unknown).unwrap();
    let opts = SurfaceOptions {
        terms: Some(15),
        ..SurfaceOptions::default()
    };
    let sol = reconstruct(&obs, &s, &opts).unwrap();
    let unc = StationUncertainty {
        station: "station.toml".into(),
        names: vec![Dof::ElementRx, Dof::ElementRy],
        covariance: DMatrix::from_diagonal_element(2, 2, 0.01f64.powi(2)),
        correlated: 0,
    };
    let b = budget(&obs, &s, &unc, &sol, &opts).unwrap();
    let joint = covariance(&sol, Some(&b));
    let nf = sol.front.coefficients_nm().len();
    // The blocks against the budget's totals (the same sums in another
    // order: rounding, 1e-9 of the largest entry).
    let scale = joint.amax();
    let ff = joint.view((0, 0), (nf, nf)).into_owned();
    let bb = joint.view((nf, nf), (nf, nf)).into_owned();
    assert!((ff - &b.front_total_cov_nm2).amax() <= 1e-9 * scale);
    assert!((bb - &b.back_total_cov_nm2).amax() <= 1e-9 * scale);
    // The element's tilt moves both faces' tilts: the wedge's σ with the
    // cross block against the one the faces' blocks alone would give.
    let mut apart = joint.clone();
    apart.view_mut((0, nf), (nf, nf)).fill(0.0);
    apart.view_mut((nf, 0), (nf, nf)).fill(0.0);
    let with = of_solution(&sol, Some(&b), &s, 1053.0, &[None, None]).unwrap();
    let w = with.plate.as_ref().unwrap().wedge_std_arcsec;
    let without = figures(&FigureInput {
        front_nm: sol.front.coefficients_nm(),
        back_nm: sol.back.coefficients_nm(),
        covariance_nm2: &apart,
        radius_mm: sol.front.basis().radius_mm(),
        refractive_index: 1.5,
        wavelength_nm: 1053.0,
        covariance_note: "the faces' blocks alone".into(),
        withheld: [None, None],
        over: None,
    })
    .unwrap();
    let apart_arcsec = without.plate.as_ref().unwrap().wedge_std_arcsec;
    println!("wedge σ {w:.4} arcsec with the cross block, {apart_arcsec:.4} arcsec without");
    assert!(w < 0.5 * apart_arcsec, "{w} vs {apart_arcsec}");
}

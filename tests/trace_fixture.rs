//! `mfd trace`'s forward model against the independent implementation that
//! made `shared/fixtures/public-small`: its truth screen coordinates must be
//! reproduced to 1e-4 screen px, with NaN exactly where the fixture has NaN.

mod common;

use mfd::npy;
use mfd::station::Station;
use mfd::surfaces_file::{self, SurfacesFile};
use mfd::trace::{Plate, TracedView};

#[test]
fn reproduces_the_public_fixture_truth() {
    let dir = common::public_small();
    let station = Station::load(&dir.join("station.toml")).unwrap();
    let truth = SurfacesFile::load(&dir.join("truth/truth_surfaces.json")).unwrap();
    let front = surfaces_file::to_surface(&truth, truth.front_coefficients()).unwrap();
    let back = surfaces_file::to_surface(&truth, truth.back_coefficients()).unwrap();
    // The fixture's scene.json gives plate_radius_mm = 28.5 = aperture + 3 mm,
    // the tracer's default rim margin (no fixture-specific setting here).
    let plate = Plate::new(&station, front, back, mfd::trace::DEFAULT_EDGE_MARGIN_MM);
    let view = TracedView::trace(&station, &plate);
    let ours = view.screen_coords();
    let (shape, theirs) = npy::read_f64(&dir.join("truth/truth_screen_coords.npy")).unwrap();
    assert_eq!(shape, vec![48, 48, 2, 2]);

    let mut worst: f64 = 0.0;
    let mut compared = [0usize; 2];
    for (k, (a, b)) in ours.iter().zip(&theirs).enumerate() {
        let refl = (k / 2) % 2;
        assert_eq!(
            a.is_nan(),
            b.is_nan(),
            "pixel {} reflection {refl}: ours {a}, fixture {b}",
            k / 4
        );
        if !a.is_nan() {
            worst = worst.max((a - b).abs());
            compared[refl] += 1;
        }
    }
    // Both are exact tracers solved to ~1e-12 mm; 1e-4 px (27 nm on the
    // screen) is the agreement the issue asks for, far above rounding.
    eprintln!("fixture truth: worst |Δ| = {worst:.3e} screen px over {compared:?} coordinates");
    assert!(worst < 1e-4, "worst difference {worst:e} px");
    // The fixture has 1216 front and 1106 back points (counted with numpy).
    assert_eq!(compared, [2 * 1216, 2 * 1106]);
}

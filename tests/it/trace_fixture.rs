//! `mfd trace`'s forward model against the independent implementation that
//! made `tests/fixtures/public-small` (a copy of `shared/fixtures/public-small`): its truth screen coordinates must be
//! reproduced to 1e-4 screen px, with NaN exactly where the fixture has NaN.

use crate::common;

use mfd::formats::npy;
use mfd::formats::surfaces_file::{self, SurfacesFile};
use mfd::optics::station::Station;
use mfd::optics::trace::{Plate, TracedView};

#[test]
fn reproduces_the_public_fixture_truth() {
    let dir = common::public_small();
    let station = Station::load(&dir.join("station.toml")).unwrap();
    let truth = SurfacesFile::load(&dir.join("truth/truth_surfaces.json")).unwrap();
    let front = surfaces_file::to_surface(&truth, truth.front_coefficients()).unwrap();
    let back = surfaces_file::to_surface(&truth, truth.back_coefficients()).unwrap();
    // The fixture's scene.json gives plate_radius_mm = 28.5 = aperture + 3 mm,
    // the tracer's default rim margin (no fixture-specific setting here).
    let plate = Plate::new(
        &station,
        front,
        back,
        mfd::optics::trace::DEFAULT_EDGE_MARGIN_MM,
    );
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

/// The carried copy of the independent fixture is byte for byte what
/// `tests/fixtures/SHA256SUMS` lists (a copy of `shared/fixtures`; never
/// edited): a changed, added or missing file fails here.
#[test]
fn fixture_is_unedited() {
    use sha2::{Digest, Sha256};
    let dir = common::public_small();
    let list = std::fs::read_to_string(common::repo("tests/fixtures/SHA256SUMS")).unwrap();
    let mut listed = Vec::new();
    for line in list.lines() {
        let (digest, name) = line.split_once("  ").expect("`DIGEST  ./PATH` per line");
        let bytes = std::fs::read(dir.join(name)).unwrap();
        let ours: String = Sha256::digest(&bytes)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        assert_eq!(ours, digest, "{name} differs from the fixture it copies");
        listed.push(name.trim_start_matches("./").to_string());
    }
    let mut present = Vec::new();
    let mut stack = vec![dir.clone()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let p = entry.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                present.push(p.strip_prefix(&dir).unwrap().to_string_lossy().into_owned());
            }
        }
    }
    listed.sort();
    present.sort();
    assert_eq!(
        listed, present,
        "files added to or missing from the fixture copy"
    );
}

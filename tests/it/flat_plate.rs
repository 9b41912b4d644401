//! The tracer against closed forms of a flat parallel plate: the lateral
//! offset of the back reflection, the parallelism of the outgoing rays, and
//! conservation of energy over the infinite series of internal reflections.

use crate::common;

use mfd::optics::station::{Station, SymmetricLayout};
use mfd::optics::trace::{Plate, ScreenHit, TracedView};
use mfd::optics::zernike::ZernikeSurface;
use proptest::prelude::*;

fn flat_plate(station: &Station) -> Plate {
    let flat = ZernikeSurface::flat(station.element.aperture_radius_mm, [0.0, 0.0]).unwrap();
    Plate::new(station, flat.clone(), flat, 3.0)
}

/// Closed form: the back reflection leaves a flat plate parallel to the front
/// reflection, displaced within the plane z = 0 by `2 t tan θt` along the
/// plane of incidence; the screen is parallel to the plate, so S2 − S1 is that
/// displacement, in screen pixels, along the incidence direction's projection.
fn closed_form_offset(station: &Station, i: u32, j: u32) -> (f64, f64) {
    let d = station.camera.ray_direction(i, j);
    let n = station.element.refractive_index;
    let sin_i = (d.x * d.x + d.y * d.y).sqrt();
    let sin_t = sin_i / n;
    let tan_t = sin_t / (1.0 - sin_t * sin_t).sqrt();
    let shift_mm = 2.0 * station.element.thickness_mm * tan_t;
    let (hx, hy) = (d.x / sin_i, d.y / sin_i);
    let s = &station.screen;
    let du = shift_mm * (hx * s.u_axis.x + hy * s.u_axis.y) / s.pixel_pitch_mm;
    let dv = shift_mm * (hx * s.v_axis.x + hy * s.v_axis.y) / s.pixel_pitch_mm;
    (du, dv)
}

#[test]
fn back_reflection_offset_matches_closed_form_on_the_paper_station() {
    let station = Station::load(&common::repo("calib/paper-sim.toml")).unwrap();
    let view = TracedView::trace(&station, &flat_plate(&station));
    let mut checked = 0;
    let mut worst: f64 = 0.0;
    for (k, p) in view.pixels.iter().enumerate() {
        let (Ok(s1), Ok(s2)) = (p.front, p.back) else {
            continue;
        };
        let (i, j) = ((k % view.width) as u32, (k / view.width) as u32);
        let (du, dv) = closed_form_offset(&station, i, j);
        worst = worst
            .max((s2.u - s1.u - du).abs())
            .max((s2.v - s1.v - dv).abs());
        checked += 1;
    }
    // Rounding of ~1 m paths in f64 is ~1e-13 mm = 4e-13 px; 1e-8 px leaves
    // room for the Newton tolerance (1e-12 mm) and nothing for a wrong model.
    eprintln!("flat plate S2 − S1 vs 2 t tan θt: worst {worst:.3e} px over {checked} pixels");
    assert!(worst < 1e-8, "worst {worst:e} px over {checked} pixels");
    // The paper's 16 mm lens sees the Ø 51 mm element on ~4 % of its sensor.
    assert!(
        checked > 30_000,
        "only {checked} pixels carry both reflections"
    );
}

#[test]
fn energy_is_conserved_over_the_internal_series() {
    let station = Station::load(&common::repo("calib/paper-sim.toml")).unwrap();
    let plate = flat_plate(&station);
    let cam = &station.camera;
    let mut checked = 0;
    for (i, j) in [(648, 483), (600, 450), (700, 520), (640, 400)] {
        let p = plate.trace_ray(&cam.position_mm, &cam.ray_direction(i, j), &station.screen);
        let (Ok(ScreenHit { weight: r1, .. }), Ok(ScreenHit { weight: r2, .. })) =
            (p.front, p.back)
        else {
            continue;
        };
        let r3 = p
            .third
            .expect("a flat plate keeps the second round trip")
            .weight;
        // Reciprocity: every interface of a flat plate reflects R = r1, so the
        // k-th round trip carries r2 (R²)^k, transmission out the back
        // T² R^{2k}: R + r2 / (1 − R²) + T² / (1 − R²) = 1 exactly.
        let big_r = r1;
        assert!((r3 / r2 - big_r * big_r).abs() < 1e-15);
        let t = 1.0 - big_r;
        let total = big_r + r2 / (1.0 - big_r * big_r) + t * t / (1.0 - big_r * big_r);
        assert!((total - 1.0).abs() < 1e-14, "total {total}");
        checked += 1;
    }
    assert_eq!(checked, 4);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(40))]
    #[test]
    fn offset_closed_form_holds_for_any_plate(
        thickness in 0.5f64..40.0, index in 1.4f64..2.4, tilt in 5.0f64..35.0,
        di in -20i32..20, dj in -20i32..20,
    ) {
        let layout = SymmetricLayout {
            camera_height_mm: 825.0,
            screen_height_mm: 825.0,
            tilt_deg: tilt,
            focal_length_mm: 16.0,
            element: mfd::optics::station::Element {
                refractive_index: index,
                thickness_mm: thickness,
                aperture_radius_mm: 25.5,
                aperture_center_mm: nalgebra::Point2::origin(),
                pose: mfd::optics::station::Pose::default(),
                wedge: mfd::optics::station::Wedge::NONE,
                outline: mfd::optics::outline::Shape::Circle,
            },
        };
        let cam = mfd::optics::station::CameraProfile::load(&common::repo("hw/camera/baumer-txg12.toml")).unwrap();
        let disp = mfd::optics::station::DisplayProfile::load(&common::repo("hw/display/mtiph-e2m21gm.toml")).unwrap();
        let station = layout.build(&cam, &disp).unwrap();
        let plate = flat_plate(&station);
        let (i, j) = ((648 + di) as u32, (483 + dj) as u32);
        let p = plate.trace_ray(&station.camera.position_mm, &station.camera.ray_direction(i, j), &station.screen);
        if let (Ok(s1), Ok(s2)) = (p.front, p.back) {
            let (du, dv) = closed_form_offset(&station, i, j);
            prop_assert!((s2.u - s1.u - du).abs() < 1e-8);
            prop_assert!((s2.v - s1.v - dv).abs() < 1e-8);
        }
    }
}

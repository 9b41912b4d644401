//! Wedged windows (station v2's `[element] wedge_arcmin`,
//! `wedge_azimuth_deg`): the station file, the tracer against the closed
//! form of a wedge's back reflection, and the whole chain on a declared and
//! an undeclared wedge ([`chain`]).

use crate::common;
use crate::station_files::{paper_text, rejects};

use std::path::Path;

use mfd::optics::station::{Screen, Station, Wedge};
use mfd::optics::trace::{Plate, DEFAULT_EDGE_MARGIN_MM};
use nalgebra::{Point3, Unit, Vector3};

pub mod chain;
pub mod live;
pub mod soak;

fn v2_with(element_lines: &str) -> String {
    paper_text()
        .replace("format = \"mfd-station/1\"", "format = \"mfd-station/2\"")
        .replace(
            "aperture_center_mm = [0.0, 0.0]",
            &format!("aperture_center_mm = [0.0, 0.0]\n{element_lines}"),
        )
}

#[test]
fn the_wedge_is_read_written_and_checked() {
    let s = Station::from_toml_str(
        &v2_with("wedge_arcmin = 30.0\nwedge_azimuth_deg = 45.0"),
        Path::new("w.toml"),
    )
    .unwrap();
    assert_eq!(
        s.element.wedge,
        Wedge {
            arcmin: 30.0,
            azimuth_deg: 45.0
        }
    );
    // Written as version 2 with both fields, and read back the same.
    let text = s.to_toml_string();
    assert!(text.contains("mfd-station/2") && text.contains("wedge_arcmin = 30.0"));
    assert_eq!(
        Station::from_toml_str(&text, Path::new("w.toml")).unwrap(),
        s
    );
    // A parallel plate stays version 1.
    let flat = Station::load(&common::repo("calib/paper-sim.toml")).unwrap();
    assert!(flat.element.wedge.is_none());
    assert!(flat.to_toml_string().contains("mfd-station/1"));
    // The spec's limits.
    rejects(&v2_with("wedge_arcmin = 121.0"), "element.wedge_arcmin");
    rejects(&v2_with("wedge_arcmin = -1.0"), "element.wedge_arcmin");
    rejects(&v2_with("wedge_arcmin = nan"), "element.wedge_arcmin");
    rejects(
        &v2_with("wedge_arcmin = 1.0\nwedge_azimuth_deg = inf"),
        "element.wedge_azimuth_deg",
    );
    // Version 1 has no wedge.
    rejects(
        &paper_text().replace(
            "aperture_center_mm = [0.0, 0.0]",
            "aperture_center_mm = [0.0, 0.0]\nwedge_arcmin = 1.0",
        ),
        "element.wedge_arcmin",
    );
}

#[test]
fn the_nominal_back_carries_the_wedge_in_its_tilts_as_the_spec_says() {
    let mut s = Station::load(&common::repo("calib/paper-sim.toml")).unwrap();
    s.element.wedge = Wedge {
        arcmin: 30.0,
        azimuth_deg: 120.0,
    };
    let (front, back) = s.element.nominal_surfaces(15).unwrap();
    assert!(front.is_flat());
    let r = s.element.aperture_radius_mm;
    let t = (0.5f64).to_radians().tan();
    let c = back.coefficients_nm();
    // Noll Z2, Z3 = tan(w) R cos φ / 2 · 1e6, tan(w) R sin φ / 2 · 1e6.
    let phi = 120f64.to_radians();
    assert!((c[1] - t * r * phi.cos() / 2.0 * 1e6).abs() < 1e-6);
    assert!((c[2] - t * r * phi.sin() / 2.0 * 1e6).abs() < 1e-6);
    assert!(c
        .iter()
        .enumerate()
        .all(|(k, v)| k == 1 || k == 2 || *v == 0.0));
    // The plate thins along φ: the back rises (z' grows) that way.
    let (dx, dy) = (phi.cos(), phi.sin());
    let h = |d: f64| back.height_mm(d * dx, d * dy);
    assert!((h(10.0) - h(-10.0) - 20.0 * t).abs() < 1e-9);
}

/// A ray straight down at `x0` meets the back plane `z = −t + s x` (wedge
/// along +x), leaves it at 2w from the vertical, refracts out of the flat
/// front to `sin β = n sin 2w`, and rises to a screen parallel to the
/// plate at height `h`: its landing point in closed form.
fn landing_x(x0: f64, t: f64, n: f64, w: f64, h: f64) -> f64 {
    let s = w.tan();
    let zb = -t + s * x0;
    // Reflected direction in the glass: (−2s, 0, 1 − s²) / (1 + s²).
    let (dx, dz) = (-2.0 * s / (1.0 + s * s), (1.0 - s * s) / (1.0 + s * s));
    let x1 = x0 + dx / dz * (0.0 - zb);
    let beta = (n * (2.0 * w).sin()).asin();
    x1 - h * beta.tan()
}

#[test]
fn a_wedges_back_reflection_lands_where_the_closed_form_puts_it() {
    let mut s = Station::load(&common::repo("calib/paper-sim.toml")).unwrap();
    let h = 600.0;
    // A screen parallel to the plate, centred above it, u along +x.
    let screen = Screen {
        width: 2000,
        height: 2000,
        pixel_pitch_mm: 0.25,
        origin_mm: Point3::new(-250.0, -250.0, h),
        u_axis: Unit::new_normalize(Vector3::x()),
        v_axis: Unit::new_normalize(Vector3::y()),
        cover_glass: None,
    };
    let down = Unit::new_normalize(Vector3::new(0.0, 0.0, -1.0));
    let mut worst: f64 = 0.0;
    for arcmin in [1.0, 30.0, 120.0] {
        for x0 in [-12.0, 0.0, 7.5] {
            s.element.wedge = Wedge {
                arcmin,
                azimuth_deg: 0.0,
            };
            let (f, b) = s.element.nominal_surfaces(3).unwrap();
            let plate = Plate::new(&s, f, b, DEFAULT_EDGE_MARGIN_MM);
            let paths = plate.trace_ray(&Point3::new(x0, 0.0, 100.0), &down, &screen);
            let hit = paths.back.unwrap();
            let e = &s.element;
            let x = landing_x(
                x0,
                e.thickness_mm,
                e.refractive_index,
                (arcmin / 60.0f64).to_radians(),
                h,
            );
            let (u, v) = ((x + 250.0) / 0.25, 250.0 / 0.25);
            worst = worst.max((hit.u - u).abs()).max((hit.v - v).abs());
        }
    }
    // Newton's tolerance on the surfaces (1e-12 mm) and f64 rounding of
    // 700 mm paths: ~1e-12 mm, 4e-12 px; 1e-8 px leaves nothing for a wrong
    // model (one arcmin moves the point by 2.2 px).
    assert!(worst < 1e-8, "worst {worst:e} px");
}

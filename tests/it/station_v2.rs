//! Station version 2 through every stage: lens distortion, the screen's
//! cover glass and the element's pose, honoured exactly by the forward
//! tracer and by the surface solvers (front slopes, back inverse trace,
//! joint refinement); and what ignoring each costs.
//!
//! The station is the paper's geometry (825 mm, 15°, f = 16 mm, the
//! 1600 × 1200 LCD) with the sensor binned 8 × 8 (162 × 121 pixels of
//! 30 µm): the same field of view, so the same normalised image radii
//! (0.19 at the corners) and the same distortion, at 1/64 of the pixels.

use crate::common;

use std::path::Path;

use mfd::optics::station::{
    CameraProfile, CoverGlassFile, DisplayProfile, DistortionFile, Station, SymmetricLayout,
};
use mfd::optics::trace::{Plate, TracedView, DEFAULT_EDGE_MARGIN_MM};
use mfd::optics::zernike::ZernikeSurface;
use mfd::sim::RandomSurfaceSpec;
use mfd::solve::surfaces::{reconstruct, Observations, SurfaceOptions, Uncertainty};

fn binned_paper_profiles() -> (CameraProfile, DisplayProfile) {
    let camera = CameraProfile {
        format: "mfd-camera-profile/1".into(),
        model: "paper camera, 8x8 binned".into(),
        resolution: [162, 121],
        pixel_pitch_um: 30.0,
        bit_depth: 12,
        distortion: Some(DistortionFile {
            model: "brown-conrady".into(),
            k: Some([-0.12, 0.03, 0.0]),
            p: Some([0.0004, -0.0002]),
        }),
    };
    let display = DisplayProfile::load(&common::repo("hw/display/mtiph-e2m21gm.toml")).unwrap();
    let display = DisplayProfile {
        cover_glass: Some(CoverGlassFile {
            thickness_mm: 1.8,
            refractive_index: 1.52,
        }),
        ..display
    };
    (camera, display)
}

/// The version-2 station of the Done-when: k1 = −0.12, 1.8 mm of n = 1.52
/// glass, the element tilted by 1° (and 12 µm off the reference plane).
fn v2_station() -> Station {
    let (camera, display) = binned_paper_profiles();
    let layout = SymmetricLayout {
        camera_height_mm: 825.0,
        screen_height_mm: 825.0,
        tilt_deg: 15.0,
        focal_length_mm: 16.0,
        element: SymmetricLayout::paper_element(),
    };
    let mut s = layout.build(&camera, &display).unwrap();
    s.element.pose.tilt_deg = [1.0, 0.0];
    s.element.pose.offset_mm = nalgebra::Vector3::new(0.0, 0.0, 0.012);
    Station::from_file(&s.to_file(), Path::new("<v2 station>")).unwrap()
}

/// RMS of the difference over the aperture, piston and tilt removed.
fn rms_err(a: &ZernikeSurface, b: &ZernikeSurface) -> f64 {
    let (a, b) = (a.coefficients_nm(), b.coefficients_nm());
    (3..a.len().max(b.len()))
        .map(|k| a.get(k).copied().unwrap_or(0.0) - b.get(k).copied().unwrap_or(0.0))
        .map(|d| d * d)
        .sum::<f64>()
        .sqrt()
}

/// Traces the plate on `truth`, reconstructs on `assumed`: (front, back) error, nm.
fn measure_with(truth: &Station, assumed: &Station, seed: u64) -> (f64, f64) {
    let e = &truth.element;
    let (front, back) = RandomSurfaceSpec::default()
        .draw_pair(e.aperture_radius_mm, [0.0, 0.0], seed)
        .unwrap();
    let plate = Plate::new(truth, front.clone(), back.clone(), DEFAULT_EDGE_MARGIN_MM);
    let coords = TracedView::trace(truth, &plate).screen_coords();
    let obs = Observations::from_maps(assumed, &coords, Uncertainty::Unknown).unwrap();
    let opts = SurfaceOptions {
        terms: Some(36),
        ..SurfaceOptions::default()
    };
    let sol = reconstruct(&obs, assumed, &opts).unwrap();
    let errs = (rms_err(&sol.front, &front), rms_err(&sol.back, &back));
    println!(
        "front {:.4} nm, back {:.4} nm, back piston {:.4} nm ({} pixels)",
        errs.0,
        errs.1,
        sol.back.coefficients_nm()[0],
        obs.pixels.len()
    );
    errs
}

#[test]
fn v2_station_reconstructs_noise_free_within_the_issue_bounds() {
    let station = v2_station();
    assert!(station.needs_version_2());
    assert!(station
        .to_toml_string()
        .contains("format = \"mfd-station/2\""));
    // Issue 14: ≤ 0.5 nm front and ≤ 1 nm back on noise-free data; the
    // version-1 station of tests/it/surfaces_exact.rs reaches 0.1 / 0.5 nm,
    // and version 2 only adds exact geometry (Newton to 1e-14, bisection
    // to 2⁻⁶⁰), so the same 0.1 / 0.5 would hold.
    let (ef, eb) = measure_with(&station, &station, 11);
    assert!(ef <= 0.5 && eb <= 1.0, "front {ef} nm, back {eb} nm");
}

#[test]
fn ignoring_each_version_2_field_costs_what_the_docs_say() {
    let truth = v2_station();
    let mut no_distortion = truth.clone();
    no_distortion.camera.distortion = None;
    let mut no_glass = truth.clone();
    no_glass.screen.cover_glass = None;
    let mut no_pose = truth.clone();
    no_pose.element.pose = Default::default();
    let mut v1 = no_distortion.clone();
    v1.screen.cover_glass = None;
    v1.element.pose = Default::default();
    assert!(v1.to_toml_string().contains("format = \"mfd-station/1\""));
    // Each field ignored must cost more than the version-2 bounds (0.5 nm
    // front, 1 nm back) on at least one surface, or it would not be needed
    // on this geometry; docs/figures.md gives the figures this prints.
    for (what, assumed) in [
        ("distortion", &no_distortion),
        ("cover glass", &no_glass),
        ("pose", &no_pose),
        ("all three (v1)", &v1),
    ] {
        let (ef, eb) = measure_with(&truth, assumed, 11);
        println!("ignoring {what}: front {ef:.2} nm, back {eb:.2} nm");
        assert!(
            ef > 0.5 || eb > 1.0,
            "ignoring {what}: front {ef} back {eb}"
        );
    }
}

#[test]
fn camera_rays_and_projection_round_trip_over_the_sensor() {
    let station = v2_station();
    let cam = &station.camera;
    let mut worst = 0.0_f64;
    for j in (0..cam.height).step_by(5) {
        for i in (0..cam.width).step_by(5) {
            let d = cam.ray_direction(i, j);
            let p = cam.position_mm + 500.0 * d.as_ref();
            let px = cam.project(&p).unwrap();
            worst = worst
                .max((px.x - (f64::from(i) + 0.5)).abs())
                .max((px.y - (f64::from(j) + 0.5)).abs());
        }
    }
    // Newton's tolerance (1e-14 normalised) times F = 533 px: 5e-12 px.
    assert!(worst < 1e-9, "round trip {worst:e} px");
}

/// The bench station (48 × 48, whole element in view) made version 2.
fn v2_bench() -> Station {
    let mut s = mfd::optics::station::bench_station(10.0, 1.5, 15.0).unwrap();
    s.camera.distortion = Some(mfd::optics::station::Distortion {
        k: [-0.12, 0.03, 0.0],
        p: [0.0004, -0.0002],
    });
    s.screen.cover_glass = Some(mfd::optics::station::CoverGlass {
        thickness_mm: 1.8,
        refractive_index: 1.52,
    });
    s.element.pose.tilt_deg = [1.0, 0.0];
    Station::from_file(&s.to_file(), Path::new("<v2 bench>")).unwrap()
}

#[test]
fn the_whole_chain_honours_version_2_noise_free() {
    // Rendered frames → spectral stage (its geometry prior from the v2
    // station) → surfaces, all on the v2 station.
    let station = v2_bench();
    let r = common::spectral::run(
        &station,
        mfd::sim::SimParams::default(),
        &common::spectral::paper_schedule(),
        mfd::solve::spectral::Engine::Statistics,
    );
    let [(rms1, _, worst1, found1, exp1), (rms2, _, _, found2, exp2)] = common::spectral::score(&r);
    println!("S1 RMS {rms1:.2e} px (worst {worst1:.2e}), {found1}/{exp1}; S2 RMS {rms2:.2e} px, {found2}/{exp2}");
    // Noise-free: the spectral stage's own bound of 0.01 px, and 99 % found
    // (tests/it/spectral_sim.rs on the version-1 station).
    assert!(worst1 <= 0.01 && found1 as f64 >= 0.99 * exp1 as f64);
    assert!(found2 as f64 >= 0.99 * exp2 as f64);
    let cov = r.maps.screen_cov();
    let obs =
        Observations::from_maps(&station, &r.maps.screen_coords(), Uncertainty::Cov(&cov)).unwrap();
    let sol = reconstruct(
        &obs,
        &station,
        &SurfaceOptions {
            terms: Some(36),
            ..Default::default()
        },
    )
    .unwrap();
    let (front, back) = RandomSurfaceSpec::default()
        .draw_pair(25.5, [0.0, 0.0], 21)
        .unwrap();
    let (ef, eb) = (rms_err(&sol.front, &front), rms_err(&sol.back, &back));
    println!("whole chain, v2 bench station, noise-free: front {ef:.3} nm, back {eb:.3} nm");
    // The Done-when's 0.5 nm front, 1 nm back.
    assert!(ef <= 0.5 && eb <= 1.0, "front {ef} back {eb}");
}

//! The offscreen fringe renderer against the CPU definition of a pattern
//! (`Pattern::intensity_at(FringeAxis::s(u, v))` at pixel centres, through
//! the gamma and dither conventions of `display::levels`), over the whole
//! 1600×1200 screen of the station's display profile. Needs a wgpu adapter:
//! on a machine without a GPU, lavapipe (`apt-get install mesa-vulkan-drivers`,
//! which `scripts/install-deps.sh` does); without one these tests fail saying so.

use crate::common;

use std::time::{Duration, Instant};

use mfd::acquire::display::levels::reference_frame;
use mfd::acquire::display::{Dither, OffscreenDisplay, PatternDisplay, Shading};
use mfd::acquire::patterns::{FringeAxis, Pattern};
use mfd::optics::station::DisplayProfile;

fn profile() -> DisplayProfile {
    DisplayProfile::load(&common::repo("hw/display/mtiph-e2m21gm.toml")).unwrap()
}

fn open(shading: Shading) -> OffscreenDisplay {
    let p = profile();
    let [w, h] = p.resolution;
    OffscreenDisplay::new(w, h, shading, Duration::from_secs_f64(p.settle_ms / 1e3))
        .unwrap_or_else(|e| panic!("cannot open the offscreen display: {e}"))
}

/// ±45°, 0°, 90° and one odd angle; τ at both ends of the paper's schedule
/// (0.2 and 200) and between; phases of all signs.
fn patterns() -> Vec<Pattern> {
    let p = |direction_deg, tau, phase_rad| Pattern {
        direction_deg,
        tau,
        phase_rad,
    };
    vec![
        p(45.0, 0.2, 0.0),
        p(-45.0, 200.0, 0.0),
        p(0.0, 37.5, std::f64::consts::FRAC_PI_2),
        p(90.0, 200.0, 1.0),
        p(45.0, 200.0, -2.5),
        p(-45.0, 0.2, 3.0),
        p(30.0, 77.7, 0.3),
    ]
}

/// The ideal, unquantised levels of `pattern` (f64, pixel centres).
fn ideal_levels(pattern: &Pattern, (w, h): (u32, u32), shading: &Shading) -> Vec<f64> {
    let axis = FringeAxis::new(pattern.direction_deg, w, h);
    let mut out = Vec::with_capacity((w * h) as usize);
    for r in 0..h {
        for c in 0..w {
            let s = axis.s(f64::from(c) + 0.5, f64::from(r) + 0.5);
            out.push(shading.ideal_level(pattern.intensity_at(s)));
        }
    }
    out
}

fn render(display: &mut OffscreenDisplay, pattern: &Pattern) -> Vec<u8> {
    let t = Instant::now();
    let frame = display
        .render(pattern)
        .unwrap_or_else(|e| panic!("{pattern:?}: {e}"));
    println!(
        "{pattern:?}: draw + readback {:.1} ms on {}",
        t.elapsed().as_secs_f64() * 1e3,
        display.adapter()
    );
    frame
}

/// The shader's level may differ from the f64 reference only where the f32
/// error can move `ideal + t` across an integer. 0.05 level bounds that
/// error: about 5× the largest seen (0.009 level at 30°, where cos θ and
/// sin θ are not exact in f32; the other directions agree exactly).
fn assert_near_boundary(shading: &Shading, (w, _): (u32, u32), k: usize, ideal: f64) {
    let (col, row) = ((k % w as usize) as u32, (k / w as usize) as u32);
    let x = ideal + shading.threshold(col, row);
    assert!(
        (x - x.round()).abs() < 0.05,
        "pixel ({col}, {row}): ideal level {ideal} is {} from a rounding boundary",
        (x - x.round()).abs()
    );
}

/// Without dithering every pixel is within one level of the CPU value, for
/// the profile's γ = 2.2 and for γ = 1 (where the level is 255·g itself).
/// One level: rounding costs ½, and the shader's f32 phase (τ·s ≤ 200 with
/// a relative error ~1e-7, ≤ 1e-4 rad) and f32 cos move the level by a few
/// hundredths at most (|d level / d phase| ≤ ~300 levels/rad at γ = 2.2).
#[test]
fn exact_levels_match_the_pattern_function_within_one_level() {
    for gamma in [profile().gamma, 1.0] {
        let shading = Shading::new(gamma, Dither::None).unwrap();
        let mut display = open(shading);
        let size = display.resolution();
        for pattern in patterns() {
            let frame = render(&mut display, &pattern);
            let ideal = ideal_levels(&pattern, size, &shading);
            let reference = reference_frame(&pattern, size.0, size.1, &shading);
            let mut worst = 0.0f64;
            let mut differing = 0usize;
            for (k, ((&got, &want), &exact)) in frame.iter().zip(&reference).zip(&ideal).enumerate()
            {
                worst = worst.max((f64::from(got) - exact).abs());
                if got != want {
                    differing += 1;
                    assert_near_boundary(&shading, size, k, exact);
                }
            }
            println!("γ = {gamma}, {pattern:?}: max |level − ideal| = {worst:.3}, {differing} pixels ≠ f64 reference");
            assert!(worst < 1.0, "γ = {gamma}, {pattern:?}: worst {worst}");
        }
    }
}

/// With 8×8 Bayer dithering: per pixel within one level of the f64
/// reference (same thresholds; f32 vs f64 can flip a floor by one, only
/// next to a boundary), and per
/// aligned 8×8 tile the mean level within `spread + 1/128 + flips/64` of the
/// mean ideal level, where `spread` is the range of the ideal level over the
/// tile and `flips` the tile's pixels that differ from the reference.
/// Derivation: with thresholds (B + ½)/64 the tile mean of floor(x + t) for
/// a constant x is within 1/128 of x (unit test in `levels`); floor is
/// monotone, so for x varying within [x̄ − spread/2, x̄ + spread/2] the mean
/// lies within spread/2 + 1/128 of x̄, as does the mean of x itself within
/// spread/2; each flipped pixel moves the mean by 1/64.
#[test]
fn dithered_levels_match_per_pixel_and_per_tile() {
    let shading = Shading::new(profile().gamma, Dither::Bayer8).unwrap();
    let mut display = open(shading);
    let (w, h) = display.resolution();
    for pattern in patterns() {
        let frame = render(&mut display, &pattern);
        let ideal = ideal_levels(&pattern, (w, h), &shading);
        let reference = reference_frame(&pattern, w, h, &shading);
        for (k, (&got, &want)) in frame.iter().zip(&reference).enumerate() {
            let d = (i32::from(got) - i32::from(want)).abs();
            assert!(d <= 1, "{pattern:?}: pixel {k}: {got} vs {want}");
            if d != 0 {
                assert_near_boundary(&shading, (w, h), k, ideal[k]);
            }
        }
        let mut sq_err = 0.0;
        let mut tiles = 0.0;
        for tr in (0..h as usize).step_by(8) {
            for tc in (0..w as usize).step_by(8) {
                let idx = |k: usize| (tr + k / 8) * w as usize + tc + k % 8;
                let (mut sum_got, mut sum_ideal, mut flips) = (0.0, 0.0, 0.0);
                let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
                for k in 0..64 {
                    let i = idx(k);
                    sum_got += f64::from(frame[i]);
                    sum_ideal += ideal[i];
                    lo = lo.min(ideal[i]);
                    hi = hi.max(ideal[i]);
                    flips += f64::from(u8::from(frame[i] != reference[i]));
                }
                let err = (sum_got - sum_ideal) / 64.0;
                let bound = (hi - lo) + 1.0 / 128.0 + flips / 64.0 + 1e-9;
                assert!(
                    err.abs() <= bound,
                    "{pattern:?}: tile ({tc}, {tr}): mean error {err} > {bound}"
                );
                sq_err += err * err;
                tiles += 1.0;
            }
        }
        let rms = (sq_err / tiles).sqrt();
        println!("{pattern:?}: RMS tile-mean error {rms:.4} levels");
        // τ = 0.2 varies slowly: the dither must carry sub-level intensity.
        // Plain rounding leaves an RMS error of 1/√12 ≈ 0.29 level here.
        if pattern.tau < 1.0 {
            assert!(rms < 0.05, "{pattern:?}: RMS {rms}");
        }
    }
}

#[test]
fn show_reports_presented_and_settled_from_the_profile() {
    let shading = Shading::from_profile(&profile(), Dither::Bayer8).unwrap();
    let mut display = open(shading);
    let pattern = Pattern {
        direction_deg: 45.0,
        tau: 37.5,
        phase_rad: 0.0,
    };
    let before = Instant::now();
    let shown = display.show(7, &pattern).unwrap();
    assert_eq!((shown.index, shown.pattern), (7, pattern));
    assert!(before <= shown.presented && shown.presented <= Instant::now());
    assert_eq!(shown.settled - shown.presented, Duration::from_millis(30));
}

#[test]
fn impossible_sizes_are_refused_by_name() {
    let shading = Shading::new(2.2, Dither::None).unwrap();
    let err = OffscreenDisplay::new(0, 1200, shading, Duration::ZERO)
        .err()
        .expect("a zero-width screen must be refused");
    assert!(err.to_string().contains("resolution"), "{err}");
}

/// `mfd display --offscreen --png` writes the rendered pattern at the
/// profile's resolution and prints its timings.
#[test]
fn cli_writes_the_offscreen_render_as_png() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("fringe.png");
    let png_arg = png.to_str().unwrap();
    let out = common::mfd(&[
        "display",
        "--offscreen",
        "--pattern",
        "-45,12.5,1",
        "--no-dither",
        "--png",
        png_arg,
        "--profile",
        common::repo("hw/display/mtiph-e2m21gm.toml")
            .to_str()
            .unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    println!("{stdout}");
    let line: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    assert!(
        line["render_ms"].as_f64().is_some_and(|ms| ms > 0.0),
        "{line}"
    );
    let image = mfd::formats::image_io::read_gray(&png).unwrap();
    assert_eq!(
        (image.width, image.height, image.bit_depth),
        (1600, 1200, 8)
    );
    let pattern = Pattern {
        direction_deg: -45.0,
        tau: 12.5,
        phase_rad: 1.0,
    };
    let shading = Shading::from_profile(&profile(), Dither::None).unwrap();
    let reference = reference_frame(&pattern, 1600, 1200, &shading);
    let worst = image
        .data
        .iter()
        .zip(&reference)
        .map(|(&a, &b)| (i32::from(a) - i32::from(b)).abs())
        .max()
        .unwrap();
    assert!(worst <= 1, "PNG differs from the pattern by {worst} levels");
}

/// Without feature `display` the window modes say which feature to build.
#[cfg(not(feature = "display"))]
#[test]
fn window_modes_without_the_feature_name_it() {
    for args in [
        &["display", "--list"][..],
        &["display", "--pattern", "45,37.5"][..],
    ] {
        let out = common::mfd(args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?}");
        assert!(err.contains("--features display"), "{args:?}: {err}");
    }
}

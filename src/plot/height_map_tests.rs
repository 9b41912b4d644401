use super::*;
use crate::plot::test_util::{is_dark, Pixels, WHITE};

const W: usize = 50;
const H: usize = 40;
const PEAK: f64 = 45.6;

/// Row 0 outside the aperture (NaN); below it a left-to-right ramp from
/// -PEAK to +PEAK, the same on every row.
fn ramp() -> Vec<f64> {
    (0..W * H)
        .map(|i| {
            let (r, col) = (i / W, i % W);
            if r == 0 {
                f64::NAN
            } else {
                PEAK * (col as f64 - 24.5) / 24.5
            }
        })
        .collect()
}

fn rgb(c: RGBColor) -> [u8; 3] {
    [c.0, c.1, c.2]
}

fn map<'a>(values: &'a [f64], w: usize, h: usize, title: &'a str) -> HeightMap<'a> {
    HeightMap {
        values,
        width: w,
        height: h,
        title,
        unit: "nm",
        extent: None,
    }
}

#[test]
fn display_size_zooms_by_integers_and_caps_large_maps() {
    assert_eq!(display_size(50, 40), (400, 320));
    assert_eq!(display_size(3, 1), (402, 134));
    assert_eq!(display_size(401, 10), (401, 10));
    assert_eq!(display_size(1000, 500), (800, 400));
    assert_eq!(display_size(2000, 1), (800, 1));
}

#[test]
fn bar_ticks_are_symmetric_1_2_5_steps_covering_the_peak() {
    let (limit, ticks) = bar_ticks(PEAK);
    assert_eq!(limit, 60.0);
    assert_eq!(ticks, [-60.0, -40.0, -20.0, 0.0, 20.0, 40.0, 60.0]);
    for m in [1e-3, 0.7, 1.0, 3.3, 12.0, 99.0, 250.0, 1234.5] {
        let (limit, ticks) = bar_ticks(m);
        assert!(
            limit >= m && ticks.len() <= MAX_BAR_TICKS && ticks.len() >= 3,
            "{m}: {ticks:?}"
        );
        assert_eq!(ticks.first(), Some(&-limit));
        assert_eq!(ticks.last(), Some(&limit));
        let step = ticks[1] - ticks[0];
        let mantissa = step / 10f64.powf(step.log10().floor());
        assert!(
            [1.0, 2.0, 5.0].iter().any(|x| (mantissa - x).abs() < 1e-6),
            "{m}: {step}"
        );
    }
}

#[test]
fn written_picture_carries_the_colour_map_where_expected() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("map.png");
    let title = "Front surface, piston and tilt removed: RMS 12.3 nm, PV 45.6 nm, σ ≥ 0.1 µm";
    height_map_png(&p, &ramp(), W, H, title, "nm").unwrap();
    let c = Pixels::read_png(&p);
    let values = ramp();
    let pic = Picture::new(map(&values, W, H, title)).unwrap();
    let l = &pic.layout;
    assert_eq!((c.width as u32, c.height as u32), l.size);
    let (mx, my, mw, mh) = l.map;
    assert_eq!((mw, mh), (400, 320));
    let (mx, my, mw) = (mx as usize, my as usize, mw as usize);

    // Source row 0 (NaN) fills the first 8 drawn rows with the outside grey.
    assert_eq!(c.get(mx + 200, my + 3), rgb(OUTSIDE));
    // The last drawn column shows +PEAK, the first -PEAK (inside the frame).
    let scale = DerivedColorMap::new(&RDBU);
    let mid = my + 200;
    let hi = rgb(scale.get_color_normalized(PEAK, -60.0, 60.0));
    assert_eq!(c.get(mx + mw - 2, mid), hi);
    assert_eq!(
        c.get(mx + 1, mid),
        rgb(scale.get_color_normalized(-PEAK, -60.0, 60.0))
    );
    assert!(
        hi[0] > 150 && hi[2] < 100,
        "the positive end is red: {hi:?}"
    );

    // The bar's top row is the map's top colour, its bottom row the bottom.
    let (bx, by, bw, bh) = l.bar;
    let (bx, by, bw, bh) = (bx as usize, by as usize, bw as usize, bh as usize);
    // (Rows 0 and bh − 1 lie under the frame: look one row inside.)
    let (_, bar) = pic.rasters();
    assert_eq!(bar.rgb[..3], rgb(RDBU[10]), "the bar's top is +limit");
    assert_eq!(
        bar.rgb[bar.rgb.len() - 3..],
        rgb(RDBU[0]),
        "its bottom -limit"
    );
    assert_eq!(c.get(bx + bw / 2, by + 1), bar.rgb[3..6]);
    assert_eq!(
        c.get(bx + bw / 2, by + bh - 2),
        bar.rgb[bar.rgb.len() - 6..bar.rgb.len() - 3]
    );
    let centre = c.get(bx + bw / 2, by + bh / 2);
    assert!(
        centre.iter().all(|&ch| ch > 235),
        "zero is near-white: {centre:?}"
    );

    // Ink: every tick's mark and label, the unit above the bar, the title.
    for &v in &pic.ticks {
        let y = pic.bar_row(v) as usize;
        assert!(is_dark(c.get(bx + bw + 2, y)), "tick {v}");
        let lx = bx + bw + (TICK + LABEL_GAP) as usize;
        assert!(c.ink(lx, y - 7, 40, 14) > 10, "label of {v}");
    }
    assert!(c.ink(bx, by - 30, bw, 24) > 10, "unit");
    let title_band = c.ink(0, MARGIN as usize, c.width, TITLE_PX as usize + 4);
    assert!(title_band > 300, "title: {title_band} dark pixels");
    assert!(c.width as u32 >= font::text_width(title, TITLE_PX) + 2 * MARGIN);
    // Nothing outside the drawn parts: the page corners are white.
    assert_eq!(c.get(0, c.height - 1), WHITE);
}

#[test]
fn extent_gives_axes_in_mm() {
    let values = ramp();
    let m = HeightMap {
        extent: Some(Extent {
            x_mm: (-25.0, 25.0),
            y_mm: (-20.0, 20.0),
        }),
        ..map(&values, W, H, "With axes")
    };
    let pic = Picture::new(m).unwrap();
    let (mx, my, mw, mh) = pic.layout.map;
    assert_eq!((mw, mh), (400, 320));
    let c = Pixels::new(pic.size(), output::render_rgb(&pic).unwrap());
    let (mx, my, mw, mh) = (mx as usize, my as usize, mw as usize, mh as usize);
    // Tick labels below and left of the map, and the axis names.
    assert!(c.ink(mx, my + mh + 4, mw, 24) > 50, "x tick labels");
    assert!(
        c.ink(mx - Y_AXIS_W as usize, my, Y_AXIS_W as usize - 4, mh) > 100,
        "y labels"
    );
    assert!(c.ink(mx, my + mh + 30, mw, 30) > 30, "x (mm)");
    // The map itself is where it was without axes.
    assert_eq!(c.get(mx + 200, my + 3), rgb(OUTSIDE));
    // A tall extent narrows the map.
    let tall = HeightMap {
        extent: Some(Extent {
            x_mm: (0.0, 10.0),
            y_mm: (0.0, 20.0),
        }),
        ..m
    };
    let (_, _, w, h) = Picture::new(tall).unwrap().layout.map;
    assert_eq!((w, h), (160, 320));
}

#[test]
fn svg_holds_the_title_the_map_as_one_image_and_the_bar_labels() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("map.svg");
    let title = "Back surface: RMS 3.2 nm, σ ±0.4 nm";
    let big: Vec<f64> = (0..200 * 200).map(|i| (i % 200) as f64 - 100.0).collect();
    height_map_svg(&p, &big, 200, 200, title, "nm").unwrap();
    let svg = std::fs::read_to_string(&p).unwrap();
    assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
    assert!(svg.contains(title), "title text");
    // Text elements hold their text on a line of its own.
    for text in ["nm", "-100", "0", "100"] {
        assert!(svg.contains(&format!(">\n{text}\n</text>")), "{text}");
    }
    // Map and bar: two images, no placeholders, and a small file.
    assert_eq!(svg.matches("<image").count(), 2);
    assert!(!svg.contains("0.012345"));
    assert!(svg.len() < 200_000, "{} bytes", svg.len());
}

#[test]
fn all_nan_draws_no_data() {
    let values = [f64::NAN; 12];
    let pic = Picture::new(map(&values, 4, 3, "empty")).unwrap();
    let c = Pixels::new(pic.size(), output::render_rgb(&pic).unwrap());
    let (x, y, w, h) = pic.layout.map;
    let (x, y, w, h) = (x as usize, y as usize, w as usize, h as usize);
    assert_eq!(c.get(x + 2, y + 2), rgb(OUTSIDE));
    assert!(
        c.ink(x + w / 2 - 42, y + h / 2 - 9, 84, 18) > 20,
        "no 'no data' note"
    );
}

#[test]
fn bad_input_is_named() {
    let err = Picture::new(map(&[0.0; 5], 2, 3, "t")).err().unwrap();
    assert!(
        matches!(
            err,
            PlotError::LengthMismatch {
                argument: "values",
                expected: 6,
                found: 5
            }
        ),
        "{err}"
    );
    assert!(
        err.to_string().contains("`values` has 5 entries where 6"),
        "{err}"
    );
    let err = Picture::new(map(&[], 0, 3, "t")).err().unwrap();
    assert!(
        matches!(err, PlotError::Empty { argument: "values" }),
        "{err}"
    );
    let bad = HeightMap {
        extent: Some(Extent {
            x_mm: (1.0, 1.0),
            y_mm: (0.0, f64::NAN),
        }),
        ..map(&[1.0], 1, 1, "t")
    };
    assert!(matches!(
        Picture::new(bad).err().unwrap(),
        PlotError::BadExtent { .. }
    ));
    for (p, f) in [("map.png", Format::Png), ("map.svg", Format::Svg)] {
        let p = Path::new("/nonexistent-dir-for-mfd-test").join(p);
        let err = height_map(&p, f, &map(&[1.0], 1, 1, "t")).unwrap_err();
        assert!(matches!(err, PlotError::Io { .. }), "{err}");
        assert!(err.to_string().contains(&p.display().to_string()), "{err}");
    }
}

#[test]
fn colour_map_ends_centre_and_sides() {
    let scale = DerivedColorMap::new(&RDBU);
    let at = |t: f64| rgb(scale.get_color_normalized(t, 0.0, 1.0));
    assert_eq!(at(0.0), rgb(RDBU[0]));
    assert_eq!(at(1.0), rgb(RDBU[10]));
    assert_eq!(at(0.5), [247, 247, 247]);
    // Clamped outside [0, 1].
    assert_eq!(at(-3.0), rgb(RDBU[0]));
    assert_eq!(at(7.0), rgb(RDBU[10]));
    // Halfway between the first two stops: linear in sRGB.
    assert_eq!(at(0.05), [19, 75, 135]);
    for k in 0..50 {
        let d = k as f64 / 100.0;
        let (lo, hi) = (at(0.5 - d - 0.01), at(0.5 + d + 0.01));
        assert!(lo[2] > lo[0], "low side not blue at {d}: {lo:?}");
        assert!(hi[0] > hi[2], "high side not red at {d}: {hi:?}");
    }
}

use super::*;
use crate::report::plot::canvas::read_png;
use crate::report::plot::colormap::OUTSIDE;

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

fn has_ink(c: &Canvas, x0: usize, y0: usize, w: usize, h: usize) -> bool {
    (y0..y0 + h).any(|y| (x0..x0 + w).any(|x| c.get(x, y) == BLACK))
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
fn written_picture_carries_the_colour_map_where_expected() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("map.png");
    let title = "Front surface, piston and tilt removed, RMS 12.3 nm, PV 45.6 nm";
    height_map_png(&p, &ramp(), W, H, title, "nm").unwrap();
    let c = read_png(&p);

    // ±45.6 rounds out to the tick ±60 (steps of 20, 7 ticks).
    let ticks = covering_ticks(-PEAK, PEAK, MAX_TICKS);
    assert_eq!(ticks.values, [-60.0, -40.0, -20.0, 0.0, 20.0, 40.0, 60.0]);
    let labels: Vec<String> = ticks.values.iter().map(|&v| ticks.step.label(v)).collect();
    let l = layout(W, H, title, "nm", &labels);
    assert_eq!((c.width(), c.height()), (l.width, l.height));
    assert_eq!((l.map_w, l.map_h), (400, 320));

    // Source row 0 (NaN) fills the first 8 drawn rows with the outside grey.
    assert_eq!(c.get(l.map_x + 200, l.map_y + 3), OUTSIDE);
    // The last drawn column shows +PEAK, the first -PEAK.
    let mid = l.map_y + 200;
    let hi = diverging((PEAK + 60.0) / 120.0);
    assert_eq!(c.get(l.map_x + l.map_w - 1, mid), hi);
    assert_eq!(c.get(l.map_x, mid), diverging((60.0 - PEAK) / 120.0));
    assert!(
        hi[0] > 150 && hi[2] < 100,
        "the positive end is red: {hi:?}"
    );

    // The bar's top row is the map's top colour, its bottom row the bottom.
    assert_eq!(c.get(l.bar_x + BAR_W / 2, l.bar_y), diverging(1.0));
    assert_eq!(
        c.get(l.bar_x + BAR_W / 2, l.bar_y + l.bar_h - 1),
        diverging(0.0)
    );
    let centre = c.get(l.bar_x + BAR_W / 2, l.bar_y + l.bar_h / 2);
    assert!(
        centre.iter().all(|&ch| ch > 235),
        "zero is near-white: {centre:?}"
    );

    // Ink: every tick's mark and label, the unit above the bar, the title.
    for &v in &ticks.values {
        let y = bar_row(&l, &ticks, v) as usize;
        assert_eq!(c.get(l.bar_x + BAR_W + 1, y), BLACK, "tick {v}");
        let lx = l.bar_x + BAR_W + TICK + LABEL_GAP;
        assert!(has_ink(&c, lx, y - 6, 30, 12), "label of {v}");
    }
    assert!(has_ink(&c, l.bar_x, l.bar_y - 26, BAR_W, 18), "unit");
    assert!(has_ink(&c, 0, l.title_y, l.width, 14), "title");
    assert!(l.width >= text_width(title, TEXT_SCALE) + 2 * MARGIN);
}

#[test]
fn all_nan_draws_no_data() {
    let c = render(&[f64::NAN; 12], 4, 3, "empty", "nm").unwrap();
    let l = layout(4, 3, "empty", "nm", &["-1.0".into()]);
    assert_eq!(c.get(l.map_x + 2, l.map_y + 2), OUTSIDE);
    let (cx, cy) = (l.map_x + l.map_w / 2, l.map_y + l.map_h / 2);
    assert!(has_ink(&c, cx - 42, cy - 7, 84, 14), "no 'no data' note");
}

#[test]
fn bad_input_is_named() {
    let err = render(&[0.0; 5], 2, 3, "t", "nm").unwrap_err();
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
    let err = render(&[], 0, 3, "t", "nm").unwrap_err();
    assert!(
        matches!(err, PlotError::Empty { argument: "values" }),
        "{err}"
    );
    let p = Path::new("/nonexistent-dir-for-mfd-test/map.png");
    let err = height_map_png(p, &[1.0], 1, 1, "t", "nm").unwrap_err();
    assert!(
        err.to_string()
            .contains("/nonexistent-dir-for-mfd-test/map.png"),
        "{err}"
    );
}

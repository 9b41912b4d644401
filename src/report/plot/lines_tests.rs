use super::*;
use crate::report::plot::canvas::read_png;

const LEGEND_BORDER: Rgb = [120, 120, 120];

fn panel<'a>(series: &'a [Series<'a>], log: bool) -> Panel<'a> {
    Panel {
        title: "RMS error",
        x_label: "frames",
        y_label: "nm",
        log_x: log,
        log_y: log,
        series,
    }
}

fn is_background(p: Rgb) -> bool {
    p == WHITE || p == GRID
}

/// The pixel nearest data point `p` of panel geometry `g`.
fn pixel(c: &Canvas, g: &PanelGeom, p: (f64, f64)) -> Rgb {
    let (x, y) = g.to_px(p).unwrap();
    c.get(x.round() as usize, y.round() as usize)
}

#[test]
fn written_plot_has_its_size_and_series_colours_at_their_points() {
    let a = [(0.0, 1.0), (4.0, 3.0), (10.0, 2.0)];
    let b = [(1.0, 8.0), (6.0, 7.0)];
    let series = [
        Series {
            label: "a",
            points: &a,
        },
        Series {
            label: "b",
            points: &b,
        },
    ];
    let panels = [panel(&series, false), panel(&series[..1], true)];
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("lines.png");
    line_plot_png(&path, &panels).unwrap();
    let c = read_png(&path);

    let g = layout(&panels);
    assert_eq!(c.width(), g[1].left + g[1].width);
    assert_eq!(c.height(), picture_height());
    assert!(g[0].width >= PLOT_W && g[1].left == g[0].width);
    // Marker centres: a disc for the first series, a square for the second.
    assert_eq!(pixel(&c, &g[0], (4.0, 3.0)), PALETTE[0]);
    assert_eq!(pixel(&c, &g[0], (6.0, 7.0)), PALETTE[1]);
    // Halfway along a segment, the line's own colour.
    assert_eq!(pixel(&c, &g[0], (3.5, 7.5)), PALETTE[1]);
    // The log panel drops x = 0 and draws the rest.
    assert_eq!(pixel(&c, &g[1], (4.0, 3.0)), PALETTE[0]);
}

#[test]
fn log_axes_place_equal_ratios_at_equal_distances() {
    let pts = [(1.0, 1.0), (10.0, 10.0), (100.0, 100.0)];
    let series = [Series {
        label: "s",
        points: &pts,
    }];
    let panels = [panel(&series, true)];
    let c = render(&panels).unwrap();
    let g = &layout(&panels)[0];
    // 1 and 100 are the axis ends, so 10 lies halfway: 239.5 pixels in.
    let (x1, y1) = g.to_px((1.0, 1.0)).unwrap();
    let (x10, y10) = g.to_px((10.0, 10.0)).unwrap();
    assert_eq!((x1, y1), (g.plot_x as f64, (g.plot_y + PLOT_H - 1) as f64));
    assert_eq!(x10 - x1, 0.5 * (PLOT_W - 1) as f64);
    assert_eq!(y1 - y10, 0.5 * (PLOT_H - 1) as f64);
    let mid = (g.plot_x + PLOT_W / 2, g.plot_y + PLOT_H / 2);
    assert_eq!(c.get(mid.0, mid.1), PALETTE[0]);
    // 3 is log10(3) ≈ 0.477 of a decade along, on the line.
    assert_eq!(pixel(&c, g, (3.0, 3.0)), PALETTE[0]);
}

#[test]
fn nan_and_non_positive_log_points_break_the_line() {
    let with_nan = [(0.0, 0.0), (5.0, f64::NAN), (10.0, 10.0)];
    let unbroken = [(0.0, 0.0), (10.0, 10.0)];
    for (pts, broken) in [(&with_nan[..], true), (&unbroken[..], false)] {
        let series = [Series {
            label: "s",
            points: pts,
        }];
        let panels = [panel(&series, false)];
        let c = render(&panels).unwrap();
        let g = &layout(&panels)[0];
        // (5, 5) lies between the NaN's neighbours, on no grid line.
        assert_eq!(is_background(pixel(&c, g, (5.0, 5.0))), broken);
        assert_eq!(pixel(&c, g, (10.0, 10.0)), PALETTE[0]);
    }
    let with_negative = [(1.0, 1.0), (10.0, -3.0), (100.0, 100.0)];
    let series = [Series {
        label: "s",
        points: &with_negative,
    }];
    let panels = [panel(&series, true)];
    let c = render(&panels).unwrap();
    let g = &layout(&panels)[0];
    assert!(is_background(pixel(&c, g, (10.0, 10.0))));
    assert_eq!(pixel(&c, g, (100.0, 100.0)), PALETTE[0]);
}

#[test]
fn legend_avoids_the_data() {
    // A rising diagonal crosses the top-right and bottom-left corners, so
    // the legend goes top left.
    let pts = [(0.0, 0.0), (10.0, 10.0)];
    let series = [Series {
        label: "rising",
        points: &pts,
    }];
    let panels = [panel(&series, false)];
    let c = render(&panels).unwrap();
    let g = &layout(&panels)[0];
    let inset = LEGEND_INSET;
    assert_eq!(c.get(g.plot_x + inset, g.plot_y + inset), LEGEND_BORDER);
    let (w, _) = legend_size(&series);
    let right_corner = g.plot_x + PLOT_W - inset - w;
    assert_ne!(c.get(right_corner, g.plot_y + inset), LEGEND_BORDER);
}

#[test]
fn series_without_finite_points_still_get_a_legend_entry() {
    let none = [(f64::NAN, 1.0), (2.0, f64::INFINITY)];
    let series = [Series {
        label: "none",
        points: &none,
    }];
    let c = render(&[panel(&series, false)]).unwrap();
    let coloured = (0..c.height())
        .flat_map(|y| (0..c.width()).map(move |x| (x, y)))
        .filter(|&(x, y)| c.get(x, y) == PALETTE[0])
        .count();
    // The legend's sample line and disc, nothing more.
    assert!(coloured > 20 && coloured < 200, "{coloured}");
    assert!(render(&[panel(&[], true)]).is_ok());
}

#[test]
fn empty_and_overfull_inputs_are_errors() {
    assert!(matches!(
        render(&[]),
        Err(PlotError::Empty { argument: "panels" })
    ));
    let pts = [(1.0, 1.0)];
    let series = vec![
        Series {
            label: "s",
            points: &pts
        };
        MAX_SERIES + 1
    ];
    let err = render(&[panel(&series, false)]).unwrap_err();
    assert!(matches!(err, PlotError::TooMany { count: 9, .. }), "{err}");
    let err = line_plot_png(Path::new("/nonexistent-mfd/x.png"), &[panel(&[], false)]);
    assert!(err
        .unwrap_err()
        .to_string()
        .contains("/nonexistent-mfd/x.png"));
}

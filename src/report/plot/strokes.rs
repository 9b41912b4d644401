//! Anti-aliased strokes and markers for line plots, blended over the
//! canvas. Coordinates are in pixels with integer values at pixel centres.

use super::canvas::{Canvas, Rgb};

/// Marker half-size in pixels.
const MARKER_R: f64 = 4.5;
/// Half the stroke width of crosses and rings, in pixels.
const MARKER_HALF_STROKE: f64 = 1.0;
/// Subsamples per pixel side when rasterising markers.
const SUB: usize = 4;

/// Mixes `color` into pixel (`x`, `y`) with weight `alpha` in [0, 1];
/// off-canvas pixels are ignored.
pub(super) fn blend(c: &mut Canvas, x: i64, y: i64, color: Rgb, alpha: f64) {
    if x < 0 || y < 0 || x as usize >= c.width() || y as usize >= c.height() || alpha <= 0.0 {
        return;
    }
    let a = alpha.min(1.0);
    let old = c.get(x as usize, y as usize);
    let mix = |k: usize| (f64::from(old[k]) * (1.0 - a) + f64::from(color[k]) * a).round() as u8;
    c.set(x, y, [mix(0), mix(1), mix(2)]);
}

/// Distance from `p` to the segment `a`–`b`.
fn distance_to_segment(p: (f64, f64), a: (f64, f64), b: (f64, f64)) -> f64 {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((p.0 - a.0) * dx + (p.1 - a.1) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (qx, qy) = (a.0 + t * dx - p.0, a.1 + t * dy - p.1);
    (qx * qx + qy * qy).sqrt()
}

/// A round-capped line from `a` to `b`, `2·half_width` pixels wide, each
/// pixel covered in proportion to how far its centre lies inside the
/// stroke (a one-pixel linear ramp at the edge).
pub(super) fn segment(c: &mut Canvas, a: (f64, f64), b: (f64, f64), half_width: f64, color: Rgb) {
    let reach = half_width + 1.0;
    let x0 = (a.0.min(b.0) - reach).floor() as i64;
    let x1 = (a.0.max(b.0) + reach).ceil() as i64;
    let y0 = (a.1.min(b.1) - reach).floor() as i64;
    let y1 = (a.1.max(b.1) + reach).ceil() as i64;
    for y in y0..=y1 {
        for x in x0..=x1 {
            let d = distance_to_segment((x as f64, y as f64), a, b);
            blend(c, x, y, color, (half_width + 0.5 - d).clamp(0.0, 1.0));
        }
    }
}

/// Marker shapes, in the order series get them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Marker {
    /// Filled disc.
    Circle,
    /// Filled square.
    Square,
    /// Filled triangle, apex up.
    TriangleUp,
    /// Filled square turned 45°.
    Diamond,
    /// Filled triangle, apex down.
    TriangleDown,
    /// Diagonal cross ×.
    Cross,
    /// Upright cross +.
    Plus,
    /// Hollow circle.
    Ring,
}

/// One marker shape per series.
pub(super) const MARKERS: [Marker; 8] = [
    Marker::Circle,
    Marker::Square,
    Marker::TriangleUp,
    Marker::Diamond,
    Marker::TriangleDown,
    Marker::Cross,
    Marker::Plus,
    Marker::Ring,
];

impl Marker {
    /// Whether offset (`dx`, `dy`) from the centre (y down) is inside.
    fn covers(self, dx: f64, dy: f64) -> bool {
        let (r, w) = (MARKER_R, MARKER_HALF_STROKE);
        let (ax, ay) = (dx.abs(), dy.abs());
        match self {
            Marker::Circle => dx * dx + dy * dy <= r * r,
            Marker::Square => ax.max(ay) <= 0.85 * r,
            // Apex at −r, base at +0.7r, base half-width r.
            Marker::TriangleUp => dy <= 0.7 * r && ax <= (dy + r) / 1.7,
            Marker::TriangleDown => -dy <= 0.7 * r && ax <= (r - dy) / 1.7,
            Marker::Diamond => ax + ay <= 1.2 * r,
            Marker::Cross => (ax - ay).abs() <= w * 1.41 && ax.max(ay) <= 0.9 * r,
            Marker::Plus => ax.min(ay) <= w && ax.max(ay) <= 1.1 * r,
            Marker::Ring => ((dx * dx + dy * dy).sqrt() - (r - w)).abs() <= w,
        }
    }
}

/// Draws `shape` centred on `p`, anti-aliased by 4×4 supersampling.
pub(super) fn marker(c: &mut Canvas, p: (f64, f64), shape: Marker, color: Rgb) {
    let reach = (1.2 * MARKER_R).ceil() as i64 + 1;
    let (cx, cy) = (p.0.round() as i64, p.1.round() as i64);
    for y in cy - reach..=cy + reach {
        for x in cx - reach..=cx + reach {
            let mut hits = 0;
            for i in 0..SUB {
                for j in 0..SUB {
                    let sx = x as f64 + (i as f64 + 0.5) / SUB as f64 - 0.5 - p.0;
                    let sy = y as f64 + (j as f64 + 0.5) / SUB as f64 - 0.5 - p.1;
                    hits += usize::from(shape.covers(sx, sy));
                }
            }
            blend(c, x, y, color, hits as f64 / (SUB * SUB) as f64);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::plot::canvas::WHITE;

    const RED: Rgb = [200, 0, 0];

    #[test]
    fn segment_is_solid_on_its_axis_and_clear_beyond_its_width() {
        let mut c = Canvas::new(40, 20, WHITE);
        segment(&mut c, (5.0, 10.0), (35.0, 10.0), 1.0, RED);
        assert_eq!(c.get(20, 10), RED);
        // Edge pixels at distance 1 are half covered; at 2, untouched.
        assert_ne!(c.get(20, 11), WHITE);
        assert_eq!(c.get(20, 12), WHITE);
        assert_eq!(c.get(20, 8), WHITE);
        // Round caps end within 1.5 pixels of the end points.
        assert_eq!(c.get(2, 10), WHITE);
        assert_eq!(c.get(38, 10), WHITE);
    }

    #[test]
    fn every_marker_covers_its_centre_and_stays_small() {
        for shape in MARKERS {
            let mut c = Canvas::new(21, 21, WHITE);
            marker(&mut c, (10.0, 10.0), shape, RED);
            let centre_hit = shape != Marker::Ring;
            assert_eq!(c.get(10, 10) == RED, centre_hit, "{shape:?}");
            assert_eq!(c.get(0, 0), WHITE, "{shape:?}");
            assert_eq!(c.get(10, 18), WHITE, "{shape:?}");
        }
    }

    #[test]
    fn blend_mixes_linearly_and_ignores_off_canvas() {
        let mut c = Canvas::new(2, 2, [0, 0, 0]);
        blend(&mut c, 0, 0, [200, 100, 50], 0.5);
        assert_eq!(c.get(0, 0), [100, 50, 25]);
        blend(&mut c, -1, 5, RED, 1.0);
    }
}

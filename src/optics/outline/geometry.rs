//! Plane polygons: area, inside test, distance outside, simplicity, and
//! ear-clipping triangulation (for the exact quadrature). Written here:
//! a handful of vertices, a few lines each, no crate in the stack does it
//! (`geo` would bring its own number types for forty lines).

/// Twice-halved shoelace area, positive for counter-clockwise vertices.
pub fn signed_area(v: &[[f64; 2]]) -> f64 {
    let n = v.len();
    (0..n)
        .map(|i| {
            let (p, q) = (v[i], v[(i + 1) % n]);
            p[0] * q[1] - q[0] * p[1]
        })
        .sum::<f64>()
        / 2.0
}

/// Whether `(x, y)` is inside (even–odd crossings of a ray to +x).
fn inside(v: &[[f64; 2]], x: f64, y: f64) -> bool {
    let n = v.len();
    let mut odd = false;
    for i in 0..n {
        let (p, q) = (v[i], v[(i + 1) % n]);
        if (p[1] > y) != (q[1] > y) {
            let xc = p[0] + (y - p[1]) / (q[1] - p[1]) * (q[0] - p[0]);
            if x < xc {
                odd = !odd;
            }
        }
    }
    odd
}

/// Distance from `(x, y)` to the segment `p q`.
fn to_segment(p: [f64; 2], q: [f64; 2], x: f64, y: f64) -> f64 {
    let (dx, dy) = (q[0] - p[0], q[1] - p[1]);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((x - p[0]) * dx + (y - p[1]) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (x - p[0] - t * dx).hypot(y - p[1] - t * dy)
}

/// 0 inside the polygon, else the distance to its nearest edge.
pub fn outside_by(v: &[[f64; 2]], x: f64, y: f64) -> f64 {
    if inside(v, x, y) {
        return 0.0;
    }
    let n = v.len();
    (0..n)
        .map(|i| to_segment(v[i], v[(i + 1) % n], x, y))
        .fold(f64::INFINITY, f64::min)
}

/// `(b − a) × (c − a)`.
fn cross(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

/// Whether the closed segments `a b` and `c d` share a point.
fn segments_meet(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let (d1, d2) = (cross(c, d, a), cross(c, d, b));
    let (d3, d4) = (cross(a, b, c), cross(a, b, d));
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    let on = |p: [f64; 2], q: [f64; 2], r: [f64; 2]| {
        cross(p, q, r) == 0.0
            && r[0] >= p[0].min(q[0])
            && r[0] <= p[0].max(q[0])
            && r[1] >= p[1].min(q[1])
            && r[1] <= p[1].max(q[1])
    };
    on(c, d, a) || on(c, d, b) || on(a, b, c) || on(a, b, d)
}

/// At least three finite vertices, an area, no two non-adjacent edges
/// meeting and no repeated vertex.
pub fn check(v: &[[f64; 2]]) -> Result<(), String> {
    let n = v.len();
    if n < 3 {
        return Err(format!("a polygon needs at least 3 vertices, found {n}"));
    }
    if let Some(k) = v
        .iter()
        .position(|p| !(p[0].is_finite() && p[1].is_finite()))
    {
        return Err(format!("vertex {k} is not finite: {:?}", v[k]));
    }
    for i in 0..n {
        for j in i + 1..n {
            if v[i] == v[j] {
                return Err(format!(
                    "vertices {i} and {j} are the same point {:?}",
                    v[i]
                ));
            }
            let adjacent = j == i + 1 || (i == 0 && j == n - 1);
            if !adjacent && segments_meet(v[i], v[(i + 1) % n], v[j], v[(j + 1) % n]) {
                return Err(format!(
                    "edges {i}–{} and {j}–{} cross: the polygon must be simple",
                    (i + 1) % n,
                    (j + 1) % n
                ));
            }
        }
    }
    let area = signed_area(v).abs();
    let span = v
        .iter()
        .flat_map(|p| p.iter())
        .fold(0.0f64, |m, c| m.max(c.abs()));
    if area <= 1e-12 * span.max(1.0).powi(2) {
        return Err("the polygon has no area".into());
    }
    Ok(())
}

/// Triangles covering a simple polygon (ear clipping, O(n³) for the few
/// vertices an outline has).
pub fn triangles(v: &[[f64; 2]]) -> Vec<[[f64; 2]; 3]> {
    let mut idx: Vec<usize> = (0..v.len()).collect();
    if signed_area(v) < 0.0 {
        idx.reverse();
    }
    let mut out = Vec::with_capacity(v.len().saturating_sub(2));
    while idx.len() > 3 {
        let m = idx.len();
        let ear = (0..m).find(|&k| {
            let (a, b, c) = (v[idx[(k + m - 1) % m]], v[idx[k]], v[idx[(k + 1) % m]]);
            if cross(a, b, c) <= 0.0 {
                return false;
            }
            idx.iter().all(|&o| {
                let p = v[o];
                p == a
                    || p == b
                    || p == c
                    || !(cross(a, b, p) >= 0.0 && cross(b, c, p) >= 0.0 && cross(c, a, p) >= 0.0)
            })
        });
        // A simple polygon always has an ear; a numerically degenerate one
        // falls back to clipping the first vertex.
        let k = ear.unwrap_or(0);
        out.push([v[idx[(k + m - 1) % m]], v[idx[k]], v[idx[(k + 1) % m]]]);
        idx.remove(k);
    }
    out.push([v[idx[0]], v[idx[1]], v[idx[2]]]);
    out
}

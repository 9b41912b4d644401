//! Exact quadrature of polynomials over polygons: Gauss–Legendre rules,
//! mapped onto each triangle by the collapsed (Duffy) map.
//!
//! Written here rather than taken from `gauss-quad` (0.3), which brings a
//! second nalgebra (0.35) and four `glam`s for what is Newton's iteration
//! on the Legendre recurrence. An `n`-point rule is exact to degree
//! `2n − 1`; the collapsed map `x = a + u (b − a) + u v (c − b)` has the
//! Jacobian `2 A u`, so a degree-`d` polynomial becomes degree `d + 1` in
//! `u` and `d` in `v`: `n = ⌈(d + 2) / 2⌉` points per axis integrate it
//! exactly.

/// Nodes and weights of the `n`-point Gauss–Legendre rule on `[0, 1]`.
pub fn gauss_legendre_01(n: usize) -> Vec<(f64, f64)> {
    let n = n.max(1);
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        // Tricomi's start for the i-th root of P_n on [−1, 1], then Newton.
        let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            let (mut p0, mut p1) = (1.0, x);
            for k in 2..=n {
                let k = k as f64;
                let p2 = ((2.0 * k - 1.0) * x * p1 - (k - 1.0) * p0) / k;
                p0 = p1;
                p1 = p2;
            }
            let (p, pm1) = if n == 1 { (x, 1.0) } else { (p1, p0) };
            dp = n as f64 * (x * p - pm1) / (x * x - 1.0);
            let step = p / dp;
            x -= step;
            if step.abs() < 1e-15 {
                break;
            }
        }
        let w = 2.0 / ((1.0 - x * x) * dp * dp);
        out.push(((1.0 - x) / 2.0, w / 2.0));
    }
    out
}

/// Points and weights (summing to the triangle's area) of a rule exact
/// for polynomials of total degree `degree` over the triangle `t`.
pub fn triangle_rule(t: &[[f64; 2]; 3], degree: usize) -> Vec<([f64; 2], f64)> {
    let [a, b, c] = *t;
    let area2 = ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])).abs();
    let n = degree.div_ceil(2) + 1;
    let rule = gauss_legendre_01(n);
    let mut out = Vec::with_capacity(n * n);
    for &(u, wu) in &rule {
        for &(v, wv) in &rule {
            let x = a[0] + u * (b[0] - a[0]) + u * v * (c[0] - b[0]);
            let y = a[1] + u * (b[1] - a[1]) + u * v * (c[1] - b[1]);
            out.push(([x, y], wu * wv * area2 * u));
        }
    }
    out
}

/// Points and weights of an exact rule of total degree `degree` over the
/// simple polygon `vertices`.
pub fn polygon_rule(vertices: &[[f64; 2]], degree: usize) -> Vec<([f64; 2], f64)> {
    super::geometry::triangles(vertices)
        .iter()
        .flat_map(|t| triangle_rule(t, degree))
        .collect()
}

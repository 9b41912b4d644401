//! The direct linear transform: the 3 × 4 projection matrix that best maps
//! world points to pixel positions (Hartley & Zisserman, "Multiple View
//! Geometry", 2nd ed., algorithm 7.1, with the normalisation of §4.4.4).
//! A central projection with no distortion is exactly such a matrix, so
//! what it leaves is distortion, noise and wrong readings: the check uses
//! it to tell one wrong target from a rough nominal station, and it is a
//! linear start for a resection.
//!
//! Hand-written: twenty lines over nalgebra's SVD; no crate in the tree
//! has it.

use nalgebra::{DMatrix, Matrix3, Matrix3x4, Matrix4, Point2, Point3, Vector4};

/// The projection matrix `P` (up to scale) with `x ~ P X` for the pairs
/// `(world_mm[k], px[k])`, or `None` with fewer than 6 pairs or a
/// degenerate layout (all points in one plane, collinear pixels).
pub fn dlt(world_mm: &[Point3<f64>], px: &[Point2<f64>]) -> Option<Matrix3x4<f64>> {
    let n = world_mm.len().min(px.len());
    if n < 6 {
        return None;
    }
    let (tw, tp) = (normaliser3(&world_mm[..n]), normaliser2(&px[..n]));
    let mut a = DMatrix::zeros(2 * n, 12);
    for k in 0..n {
        let x = tw * world_mm[k].to_homogeneous();
        let u = tp * px[k].to_homogeneous();
        let (u, v) = (u.x / u.z, u.y / u.z);
        for c in 0..4 {
            a[(2 * k, c)] = x[c];
            a[(2 * k, 8 + c)] = -u * x[c];
            a[(2 * k + 1, 4 + c)] = x[c];
            a[(2 * k + 1, 8 + c)] = -v * x[c];
        }
    }
    // The null vector of A: the right singular vector of the smallest
    // singular value (AᵀA's eigenvector, 12 × 12, well conditioned after
    // the normalisation).
    let ata = a.transpose() * &a;
    let eig = ata.symmetric_eigen();
    let k = eig.eigenvalues.argmin().0;
    let h = eig.eigenvectors.column(k);
    if !h.iter().all(|v| v.is_finite()) {
        return None;
    }
    let p = Matrix3x4::from_fn(|r, c| h[4 * r + c]);
    let p = tp.try_inverse()? * p * tw;
    // A second-smallest eigenvalue near zero means the layout does not fix P.
    let mut ev: Vec<f64> = eig.eigenvalues.iter().copied().collect();
    ev.sort_by(f64::total_cmp);
    (ev[1] > 1e-12 * ev[11]).then_some(p)
}

/// Where `p` sends the world point `x`, px, or `None` at infinity.
pub fn project(p: &Matrix3x4<f64>, x: &Point3<f64>) -> Option<Point2<f64>> {
    let u = p * x.to_homogeneous();
    (u.z.abs() > 0.0).then(|| Point2::new(u.x / u.z, u.y / u.z))
}

/// Centres the points and scales their mean distance from the centre to √3.
fn normaliser3(pts: &[Point3<f64>]) -> Matrix4<f64> {
    let n = pts.len() as f64;
    let c = pts
        .iter()
        .fold(Vector4::zeros(), |acc, p| acc + p.to_homogeneous())
        / n;
    let d = pts.iter().map(|p| (p.coords - c.xyz()).norm()).sum::<f64>() / n;
    let s = if d > 0.0 { 3f64.sqrt() / d } else { 1.0 };
    let mut t = Matrix4::identity() * s;
    t[(3, 3)] = 1.0;
    t.fixed_view_mut::<3, 1>(0, 3).copy_from(&(-s * c.xyz()));
    t
}

/// Centres the points and scales their mean distance from the centre to √2.
fn normaliser2(pts: &[Point2<f64>]) -> Matrix3<f64> {
    let n = pts.len() as f64;
    let c = pts
        .iter()
        .fold(nalgebra::Vector2::zeros(), |acc, p| acc + p.coords)
        / n;
    let d = pts.iter().map(|p| (p.coords - c).norm()).sum::<f64>() / n;
    let s = if d > 0.0 { 2f64.sqrt() / d } else { 1.0 };
    Matrix3::new(s, 0.0, -s * c.x, 0.0, s, -s * c.y, 0.0, 0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Vector3};

    #[test]
    fn a_pinhole_camera_is_recovered_exactly() {
        // A camera 800 mm up, tilted 15°, f = 4000 px, principal point off
        // centre: its projections of a two-height grid come back to 1e-6 px.
        let r = Rotation3::from_axis_angle(&Vector3::y_axis(), 15f64.to_radians())
            * Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
        let c = Point3::new(-200.0, 10.0, 800.0);
        let cam = |x: &Point3<f64>| {
            let q = r.inverse() * (x - c);
            Point2::new(640.0 + 4000.0 * q.x / q.z, 470.0 + 4000.0 * q.y / q.z)
        };
        let world: Vec<_> = (0..18)
            .map(|k| {
                Point3::new(
                    -60.0 + 60.0 * (k % 3) as f64,
                    -40.0 + 40.0 * ((k / 3) % 3) as f64,
                    30.0 * (k / 9) as f64,
                )
            })
            .collect();
        let px: Vec<_> = world.iter().map(cam).collect();
        let p = dlt(&world, &px).unwrap();
        for x in [
            Point3::new(13.0, -7.0, 11.0),
            Point3::new(-50.0, 30.0, 25.0),
        ] {
            assert!((project(&p, &x).unwrap() - cam(&x)).norm() < 1e-6);
        }
        // One plane does not fix a 3 × 4 projection.
        let flat: Vec<_> = world.iter().map(|p| Point3::new(p.x, p.y, 0.0)).collect();
        let px: Vec<_> = flat.iter().map(cam).collect();
        assert!(dlt(&flat, &px).is_none());
    }
}

//! How a set of stage readings spreads in space, judged against the stage's
//! own noise: whether points lie on one line or in one plane, by the
//! singular values of the centred points and the χ² the stage noise alone
//! would give them. Shared by the session's rules and the world frame.
//!
//! Hand-written because the criterion is ours (a χ² test with the
//! Wilson–Hilferty quantile); the SVD is nalgebra's.

use nalgebra::{Matrix3, Point3, Vector3};

/// The centred points' principal directions and spreads.
#[derive(Debug, Clone, PartialEq)]
pub struct Spread {
    /// Mean of the points, same frame and unit as the points.
    pub centroid: Point3<f64>,
    /// Singular values of the centred `N × 3` matrix, largest first (same
    /// unit as the points: `s_k² = Σ` squared distances along direction `k`).
    pub singular: [f64; 3],
    /// The matching unit directions (right singular vectors), columns in
    /// the order of `singular`.
    pub directions: Matrix3<f64>,
    /// Number of points.
    pub count: usize,
}

impl Spread {
    /// The spread of `points` (at least one).
    pub fn of(points: &[Point3<f64>]) -> Spread {
        let n = points.len().max(1) as f64;
        let centroid = Point3::from(
            points
                .iter()
                .fold(Vector3::zeros(), |acc, p| acc + p.coords)
                / n,
        );
        // The scatter matrix Σ d dᵀ has eigenvalues s_k²: a 3 × 3 symmetric
        // eigenproblem instead of an N × 3 SVD.
        let scatter = points.iter().fold(Matrix3::zeros(), |acc, p| {
            let d = p - centroid;
            acc + d * d.transpose()
        });
        let eig = scatter.symmetric_eigen();
        let mut order = [0usize, 1, 2];
        order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
        let singular = order.map(|k| eig.eigenvalues[k].max(0.0).sqrt());
        let directions = Matrix3::from_columns(
            &order.map(|k| -> Vector3<f64> { eig.eigenvectors.column(k).into_owned() }),
        );
        Spread {
            centroid,
            singular,
            directions,
            count: points.len(),
        }
    }

    /// Σ of squared distances from the best line through the points.
    pub fn off_line_ss(&self) -> f64 {
        self.singular[1].powi(2) + self.singular[2].powi(2)
    }

    /// Σ of squared distances from the best plane through the points.
    pub fn off_plane_ss(&self) -> f64 {
        self.singular[2].powi(2)
    }

    /// Whether the points are consistent with one line given an isotropic
    /// noise of `std` per axis (same unit): their squared distances from the
    /// best line, over `std²`, do not exceed the 99.9 % quantile of χ² with
    /// `2 (N − 2)` degrees of freedom (2 N residual coordinates, 4 line
    /// parameters). Fewer than 3 points always lie on a line.
    pub fn on_one_line(&self, std: f64) -> bool {
        if self.count < 3 {
            return true;
        }
        let dof = 2.0 * (self.count as f64 - 2.0);
        self.off_line_ss() <= std * std * chi2_quantile_999(dof)
    }

    /// Whether the points are consistent with one plane given the noise
    /// `std` per axis: χ² with `N − 3` degrees of freedom (N distances, 3
    /// plane parameters), 99.9 % quantile. Fewer than 4 points always do.
    pub fn in_one_plane(&self, std: f64) -> bool {
        if self.count < 4 {
            return true;
        }
        let dof = self.count as f64 - 3.0;
        self.off_plane_ss() <= std * std * chi2_quantile_999(dof)
    }

    /// RMS distance of the points from their best line.
    pub fn off_line_rms(&self) -> f64 {
        (self.off_line_ss() / self.count.max(1) as f64).sqrt()
    }

    /// RMS distance of the points from their best plane.
    pub fn off_plane_rms(&self) -> f64 {
        (self.off_plane_ss() / self.count.max(1) as f64).sqrt()
    }
}

/// The 99.9 % quantile of χ² with `dof` degrees of freedom, by the
/// Wilson–Hilferty cube-root approximation (within 3.1 % of the exact value
/// from 1 degree of freedom on, 0.6 % at 10: far closer than the test
/// needs, whose threshold sits far out in the tail).
pub fn chi2_quantile_999(dof: f64) -> f64 {
    /// The standard normal's 99.9 % quantile.
    const Z_999: f64 = 3.090_232_306;
    let a = 2.0 / (9.0 * dof);
    dof * (1.0 - a + Z_999 * a.sqrt()).powi(3)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wilson_hilferty_matches_tabulated_quantiles() {
        // χ² 99.9 % quantiles from standard tables (e.g. NIST/SEMATECH
        // e-Handbook 1.3.6.7.4): dof 1 → 10.828, 2 → 13.816, 3 → 16.266,
        // 10 → 29.588; the approximation's error shrinks with the dof.
        for (dof, table, tol) in [
            (1.0, 10.828, 0.031),
            (2.0, 13.816, 0.024),
            (3.0, 16.266, 0.02),
            (10.0, 29.588, 0.007),
        ] {
            let q = chi2_quantile_999(dof);
            assert!((q / table - 1.0).abs() < tol, "dof {dof}: {q} vs {table}");
        }
    }

    #[test]
    fn spreads_of_a_line_a_plane_and_a_box() {
        let line: Vec<_> = (0..5)
            .map(|k| Point3::new(k as f64, 2.0 * k as f64, 0.5))
            .collect();
        let s = Spread::of(&line);
        assert!(s.singular[1] < 1e-12 && s.on_one_line(1e-6));
        let plane: Vec<_> = (0..9)
            .map(|k| Point3::new((k % 3) as f64, (k / 3) as f64, 1.0))
            .collect();
        let s = Spread::of(&plane);
        assert!(!s.on_one_line(1e-3) && s.in_one_plane(1e-6));
        assert!(s.directions.column(2).z.abs() > 1.0 - 1e-12);
        let mut cube = plane.clone();
        cube.extend(plane.iter().map(|p| p + Vector3::z()));
        assert!(!Spread::of(&cube).in_one_plane(1e-3));
    }
}

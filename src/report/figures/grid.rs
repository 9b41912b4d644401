//! The aperture sampled for PV figures: the basis values at the centres of
//! a square grid's cells inside the Zernike disk.

use nalgebra::DMatrix;

use crate::optics::zernike::{ZernikeBasis, ZernikeError};

/// Basis values at the grid points inside the disk (points × terms).
#[derive(Debug, Clone)]
pub struct Grid {
    values: DMatrix<f64>,
}

impl Grid {
    /// `terms` Noll terms of radius `radius_mm` at the centres of the
    /// `side × side` cells of the aperture's bounding square that lie in
    /// the disk.
    ///
    /// # Errors
    /// [`ZernikeError`] for a radius that is not positive and finite.
    pub fn new(terms: usize, radius_mm: f64, side: usize) -> Result<Grid, ZernikeError> {
        let basis = ZernikeBasis::new(terms, radius_mm, [0.0, 0.0])?;
        let step = 2.0 * radius_mm / side as f64;
        let mut rows: Vec<f64> = Vec::new();
        let mut z = vec![0.0; terms];
        let mut points = 0;
        for r in 0..side {
            let y = radius_mm - (r as f64 + 0.5) * step;
            for c in 0..side {
                let x = -radius_mm + (c as f64 + 0.5) * step;
                if x * x + y * y <= radius_mm * radius_mm {
                    basis.eval_values_into(x, y, &mut z)?;
                    rows.extend_from_slice(&z);
                    points += 1;
                }
            }
        }
        Ok(Grid {
            values: DMatrix::from_row_slice(points, terms, &rows),
        })
    }

    /// The polynomials orthonormal over `outline` (`set`) at the centres
    /// of the `side × side` cells of its Zernike disk's bounding square
    /// that lie inside the outline: `Q = L⁻¹ Z`, so the PV of a surface is
    /// taken from its orthonormal coefficients, its first terms (the plane
    /// over the outline) left out.
    ///
    /// # Errors
    /// [`ZernikeError`] for a radius that is not positive and finite.
    pub fn over(
        outline: &crate::optics::outline::Outline,
        set: &crate::optics::outline::Orthonormal,
        side: usize,
    ) -> Result<Grid, ZernikeError> {
        let terms = set.terms();
        let (r, [cx, cy]) = (outline.radius_mm, outline.centre_mm);
        let basis = ZernikeBasis::new(terms, r, [cx, cy])?;
        let step = 2.0 * r / side as f64;
        let mut rows: Vec<f64> = Vec::new();
        let mut z = vec![0.0; terms];
        let mut points = 0;
        for row in 0..side {
            let y = cy + r - (row as f64 + 0.5) * step;
            for col in 0..side {
                let x = cx - r + (col as f64 + 0.5) * step;
                if outline.contains(x, y) {
                    basis.eval_values_into(x, y, &mut z)?;
                    rows.extend_from_slice(&z);
                    points += 1;
                }
            }
        }
        let zs = DMatrix::from_row_slice(points, terms, &rows);
        // Rows of Q values: z_row L⁻ᵀ, i.e. solve (Lᵀ)ᵀ-wise: Q = Z (Lᵀ)⁻¹.
        let inv = set
            .matrix()
            .clone()
            .try_inverse()
            .unwrap_or_else(|| DMatrix::identity(terms, terms));
        Ok(Grid { values: zs * inv })
    }

    /// Terms per point.
    pub fn terms(&self) -> usize {
        self.values.ncols()
    }

    /// PV (nm) of the surface with coefficients `c` (nm) whose first
    /// `removed` terms are left out.
    pub fn pv(&self, c: &[f64], removed: usize) -> f64 {
        let m = DMatrix::from_column_slice(c.len(), 1, c);
        self.pv_columns(&m, removed)[0]
    }

    /// PV (nm) of every column of `c` (terms × surfaces), the first
    /// `removed` terms left out; terms beyond the grid's are ignored, those
    /// missing count as zero.
    pub fn pv_columns(&self, c: &DMatrix<f64>, removed: usize) -> Vec<f64> {
        let t = self.terms();
        let mut used = DMatrix::zeros(t, c.ncols());
        for k in removed..t.min(c.nrows()) {
            used.row_mut(k).copy_from(&c.row(k));
        }
        let h = &self.values * used;
        h.column_iter().map(|col| col.max() - col.min()).collect()
    }
}

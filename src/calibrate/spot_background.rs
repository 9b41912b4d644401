//! The background under a target spot and the pixel noise, for the
//! centroid: a quadratic surface fitted to tile medians with the tiles the
//! spot lifts rejected, and the noise from the median absolute residual.
//! Robust statistics of a frame, hand-written: a median and a 6-parameter
//! least-squares fit.

use nalgebra::{SMatrix, SVector};

/// Robust noise of background residuals: 1.4826 MAD, at least the
/// quantisation noise of one count, `1/√12`.
pub(super) fn noise_std(residual: &[f64]) -> f64 {
    let mut v = residual.to_vec();
    let med = median(&mut v);
    let mut dev: Vec<f64> = residual.iter().map(|r| (r - med).abs()).collect();
    (1.4826 * median(&mut dev)).max(1.0 / 12f64.sqrt())
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// A quadratic background surface in coordinates scaled to [-1, 1].
#[derive(Debug, Clone)]
pub(super) struct Background {
    coeffs: SVector<f64, 6>,
    w: f64,
    h: f64,
}

impl Background {
    fn basis(&self, i: f64, j: f64) -> SVector<f64, 6> {
        let (x, y) = (2.0 * i / self.w - 1.0, 2.0 * j / self.h - 1.0);
        SVector::<f64, 6>::from([1.0, x, y, x * x, x * y, y * y])
    }

    pub(super) fn at(&self, i: usize, j: usize) -> f64 {
        self.basis(i as f64 + 0.5, j as f64 + 0.5).dot(&self.coeffs)
    }

    /// Fits tile medians, rejecting tiles more than 3 robust σ off the
    /// surface (those the spot lifts), three times over.
    pub(super) fn fit(values: &[f64], w: usize, h: usize) -> Background {
        let (nx, ny) = (16.min(w), 12.min(h));
        let mut tiles = Vec::with_capacity(nx * ny);
        for ty in 0..ny {
            for tx in 0..nx {
                let (i0, i1) = (tx * w / nx, (tx + 1) * w / nx);
                let (j0, j1) = (ty * h / ny, (ty + 1) * h / ny);
                let mut v: Vec<f64> = (j0..j1)
                    .flat_map(|j| (i0..i1).map(move |i| values[j * w + i]))
                    .collect();
                let m = median(&mut v);
                tiles.push(((i0 + i1) as f64 / 2.0, (j0 + j1) as f64 / 2.0, m));
            }
        }
        let mut bg = Background {
            coeffs: SVector::zeros(),
            w: w as f64,
            h: h as f64,
        };
        let mut keep = vec![true; tiles.len()];
        for _ in 0..3 {
            let (mut ata, mut atb) = (SMatrix::<f64, 6, 6>::zeros(), SVector::<f64, 6>::zeros());
            for (t, _) in tiles.iter().zip(&keep).filter(|(_, k)| **k) {
                let b = bg.basis(t.0, t.1);
                ata += b * b.transpose();
                atb += b * t.2;
            }
            // Too few tiles left for a quadratic: keep the previous surface.
            let Some(c) = ata.try_inverse() else { break };
            bg.coeffs = c * atb;
            let mut res: Vec<f64> = tiles
                .iter()
                .map(|t| t.2 - bg.basis(t.0, t.1).dot(&bg.coeffs))
                .collect();
            let mut abs: Vec<f64> = res.iter().map(|r| r.abs()).collect();
            // Medians of integer counts move in half counts: no tighter scale.
            let scale = (1.4826 * median(&mut abs)).max(0.5);
            for (k, r) in res.iter_mut().enumerate() {
                keep[k] = r.abs() <= 3.0 * scale;
            }
        }
        bg
    }
}

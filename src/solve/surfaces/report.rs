//! Figures of a surface solution: RMS and PV with piston and tilt removed,
//! their uncertainties, height maps on a grid, and the summary that
//! `mfd reconstruct` writes as `summary.json`.

use serde::{Deserialize, Serialize};

use super::solve::SurfaceSolution;
use crate::optics::zernike::ZernikeSurface;

/// Noll terms 1–3 (piston, tilts) are removed from every figure and picture.
pub const REMOVED_TERMS: usize = 3;

/// What the figures and pictures leave out, in words (`summary.json`).
pub const FIGURES_NOTE: &str = "RMS, PV and pictures with piston and tilt (Noll 1-3) removed; \
     front piston fixed at 0 by the reference plane; back piston fixed at the nominal thickness";

/// One surface's figures.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SurfaceFigures {
    /// Number of Zernike terms.
    pub terms: usize,
    /// RMS over the aperture disk, piston and tilt removed, nm
    /// (root sum of squares of the coefficients from j = 4).
    pub rms_nm: f64,
    /// σ of `rms_nm` from the coefficient covariance (delta method), nm.
    pub rms_std_nm: f64,
    /// Expected RMS of the surface error from the noise,
    /// `sqrt(Σ_{j≥4} σ_j²)`, nm: the surface's uncertainty as one number.
    pub error_rms_nm: f64,
    /// Peak-to-valley over the height grid, piston and tilt removed, nm.
    pub pv_nm: f64,
    /// Coefficients, nm (Noll j = k + 1 at index k).
    pub coefficients_nm: Vec<f64>,
    /// Their standard deviations, nm (0 where fixed).
    pub std_nm: Vec<f64>,
}

/// Heights (nm, piston and tilt removed) on an `n × n` grid over the
/// aperture's bounding square: row 0 at `+y` (top), column 0 at `−x`;
/// NaN outside the aperture disk.
pub fn height_grid(surface: &ZernikeSurface, n: usize) -> Vec<f64> {
    let b = surface.basis();
    let (r, [cx, cy]) = (b.radius_mm(), b.center_mm());
    let mut c = surface.coefficients_nm().to_vec();
    c.iter_mut().take(REMOVED_TERMS).for_each(|x| *x = 0.0);
    let Ok(s) = ZernikeSurface::new(b.clone(), c) else {
        return vec![f64::NAN; n * n];
    };
    let step = 2.0 * r / n as f64;
    let mut out = Vec::with_capacity(n * n);
    for row in 0..n {
        let y = cy + r - (row as f64 + 0.5) * step;
        for col in 0..n {
            let x = cx - r + (col as f64 + 0.5) * step;
            let inside = (x - cx).powi(2) + (y - cy).powi(2) <= r * r;
            out.push(if inside {
                s.height_mm(x, y) * 1e6
            } else {
                f64::NAN
            });
        }
    }
    out
}

/// Figures of the front (`back` false) or back surface of `sol`.
pub fn figures(sol: &SurfaceSolution, back: bool) -> SurfaceFigures {
    let (surface, std) = if back {
        (&sol.back, &sol.back_std_nm)
    } else {
        (&sol.front, &sol.front_std_nm)
    };
    let c = surface.coefficients_nm();
    let rms = c
        .iter()
        .skip(REMOVED_TERMS)
        .map(|x| x * x)
        .sum::<f64>()
        .sqrt();
    let col = |k: usize| {
        if back {
            sol.layout.back_col(k)
        } else {
            sol.layout.front_col(k)
        }
    };
    // δRMS = Σ (c_j / RMS) δc_j over j ≥ 4.
    let mut var = 0.0;
    for (k1, c1) in c.iter().enumerate().skip(REMOVED_TERMS) {
        for (k2, c2) in c.iter().enumerate().skip(REMOVED_TERMS) {
            if let (Some(a), Some(b)) = (col(k1), col(k2)) {
                var += c1 * c2 * sol.covariance[(a, b)];
            }
        }
    }
    let rms_std = if rms > 0.0 {
        var.max(0.0).sqrt() / rms
    } else {
        0.0
    };
    let error_rms = std
        .iter()
        .skip(REMOVED_TERMS)
        .map(|s| s * s)
        .sum::<f64>()
        .sqrt();
    let grid = height_grid(surface, 256);
    let (lo, hi) = grid
        .iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    SurfaceFigures {
        terms: c.len(),
        rms_nm: rms,
        rms_std_nm: rms_std,
        error_rms_nm: error_rms,
        pv_nm: if hi >= lo { hi - lo } else { f64::NAN },
        coefficients_nm: c.to_vec(),
        std_nm: std.clone(),
    }
}

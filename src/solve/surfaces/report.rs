//! Figures of a surface solution: RMS and PV with piston and tilt removed,
//! their uncertainties, height maps on a grid, and the summary that
//! `mfd reconstruct` writes as `summary.json`.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use super::solve::SurfaceSolution;
use crate::optics::outline::Outline;
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
    /// RMS over the element's outline (the aperture disk unless the
    /// station gives another), its best-fit plane removed, nm (root sum of
    /// squares of the orthonormal coefficients from the fourth; for the
    /// disk, of the Zernike coefficients from j = 4).
    pub rms_nm: f64,
    /// σ of `rms_nm` from the coefficient covariance (delta method), nm.
    pub rms_std_nm: f64,
    /// Expected RMS over the outline of the surface error, the plane
    /// removed, nm: the surface's uncertainty as one number: the noise's
    /// (for the disk `sqrt(Σ_{j≥4} σ_j²)`) and the truncation's
    /// ([`SurfaceFigures::truncation_rms_nm`]) in quadrature.
    pub error_rms_nm: f64,
    /// The part of `error_rms_nm` from terms the criterion dropped, nm:
    /// what the largest model saw in them (0 when none were dropped).
    #[serde(default)]
    pub truncation_rms_nm: f64,
    /// Peak-to-valley over the height grid inside the outline, the plane
    /// removed, nm.
    pub pv_nm: f64,
    /// Coefficients, nm (Noll j = k + 1 at index k).
    pub coefficients_nm: Vec<f64>,
    /// Their standard deviations, nm (0 where fixed).
    pub std_nm: Vec<f64>,
    /// The outline the figures are over, in words, where it is not the
    /// aperture disk.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub outline: Option<String>,
    /// The coefficients in the polynomials orthonormal over that outline
    /// (`optics::outline::orthonormal`), nm; absent for the disk.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub orthonormal_nm: Option<Vec<f64>>,
    /// Their standard deviations, nm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub orthonormal_std_nm: Option<Vec<f64>>,
}

/// Heights (nm, the best-fit plane over the outline removed) on an
/// `n × n` grid over the Zernike disk's bounding square: row 0 at `+y`
/// (top), column 0 at `−x`; NaN outside the outline (for the disk, outside
/// the disk).
pub fn height_grid(surface: &ZernikeSurface, outline: &Outline, n: usize) -> Vec<f64> {
    let b = surface.basis();
    let (r, [cx, cy]) = (b.radius_mm(), b.center_mm());
    let c = match outline.orthonormal(b.n_terms()) {
        Ok(q) => q.without_first(surface.coefficients_nm(), REMOVED_TERMS),
        Err(_) => return vec![f64::NAN; n * n],
    };
    let Ok(s) = ZernikeSurface::new(b.clone(), c) else {
        return vec![f64::NAN; n * n];
    };
    let step = 2.0 * r / n as f64;
    let mut out = Vec::with_capacity(n * n);
    for row in 0..n {
        let y = cy + r - (row as f64 + 0.5) * step;
        for col in 0..n {
            let x = cx - r + (col as f64 + 0.5) * step;
            let inside = if outline.vertices().is_some() {
                outline.contains(x, y)
            } else {
                (x - cx).powi(2) + (y - cy).powi(2) <= r * r
            };
            out.push(if inside {
                s.height_mm(x, y) * 1e6
            } else {
                f64::NAN
            });
        }
    }
    out
}

/// The covariance of one surface's coefficients (terms × terms, nm²;
/// zero where fixed) out of the solution's joint one.
pub fn surface_covariance(sol: &SurfaceSolution, back: bool) -> DMatrix<f64> {
    let (n, col): (usize, &dyn Fn(usize) -> Option<usize>) = if back {
        (sol.layout.back_terms, &|k| sol.layout.back_col(k))
    } else {
        (sol.layout.front_terms, &|k| sol.layout.front_col(k))
    };
    DMatrix::from_fn(n, n, |i, j| match (col(i), col(j)) {
        (Some(a), Some(b)) => sol.covariance[(a, b)],
        _ => 0.0,
    })
}

/// Figures of the front (`back` false) or back surface of `sol`, over the
/// element's outline: through the polynomials orthonormal over it, so the
/// disk's formulas hold on their coefficients (`optics::outline`). For the
/// disk they are the Zernike coefficients themselves.
pub fn figures(sol: &SurfaceSolution, back: bool) -> SurfaceFigures {
    let (surface, std) = if back {
        (&sol.back, &sol.back_std_nm)
    } else {
        (&sol.front, &sol.front_std_nm)
    };
    let c = surface.coefficients_nm();
    let cov = surface_covariance(sol, back);
    let Ok(q) = sol.outline.orthonormal(c.len()) else {
        // `reconstruct` refuses such an outline before fitting.
        return SurfaceFigures {
            terms: c.len(),
            rms_nm: f64::NAN,
            rms_std_nm: f64::NAN,
            error_rms_nm: f64::NAN,
            truncation_rms_nm: f64::NAN,
            pv_nm: f64::NAN,
            coefficients_nm: c.to_vec(),
            std_nm: std.clone(),
            outline: Some(sol.outline.shape.describe()),
            orthonormal_nm: None,
            orthonormal_std_nm: None,
        };
    };
    let a = q.coefficients(c);
    let cov_a = q.covariance(&cov);
    // `+ 0.0`: a plane's empty sum comes out −0.0, printed "-0.0 nm".
    let rms = q.rms(c, REMOVED_TERMS) + 0.0;
    // δRMS = Σ (a_k / RMS) δa_k over the terms after the plane.
    let mut var = 0.0;
    for i in REMOVED_TERMS..a.len() {
        for j in REMOVED_TERMS..a.len() {
            var += a[i] * a[j] * cov_a[(i, j)];
        }
    }
    let rms_std = if rms > 0.0 {
        var.max(0.0).sqrt() / rms
    } else {
        0.0
    };
    // The noise's part, and the truncation's where the criterion dropped
    // terms the largest model saw (`select::dropped_rms_nm`).
    let truncation = sol.choice.as_ref().map_or(0.0, |c| {
        if back {
            c.back.as_ref().map_or(0.0, |b| b.dropped_rms_nm)
        } else {
            c.front.dropped_rms_nm
        }
    });
    let error_rms = q.expected_rms(&cov, REMOVED_TERMS).hypot(truncation);
    let grid = height_grid(surface, &sol.outline, 256);
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
        truncation_rms_nm: truncation,
        pv_nm: if hi >= lo { hi - lo } else { f64::NAN },
        coefficients_nm: c.to_vec(),
        std_nm: std.clone(),
        outline: (!q.is_identity()).then(|| sol.outline.shape.describe()),
        orthonormal_nm: (!q.is_identity()).then(|| a.clone()),
        orthonormal_std_nm: (!q.is_identity()).then(|| {
            (0..a.len())
                .map(|k| cov_a[(k, k)].max(0.0).sqrt())
                .collect()
        }),
    }
}

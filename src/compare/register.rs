//! Registration of an interferometer map on the measured aperture.
//!
//! A map pixel (column `c`, row `r`; row 0 at the top) has the offset
//!
//! ```text
//! dx = (c + 0.5 − cx) · p        dy = (cy − (r + 0.5)) · p
//! ```
//!
//! from the aperture's centre `(cx, cy)` (continuous map pixel
//! coordinates), `p` the pixel size in mm. A flip mirrors `dx → −dx`; the
//! rotation `θ` then turns the offset counter-clockwise (from `+x` towards
//! `+y`) onto the world frame, around the aperture centre of
//! `surfaces.json`:
//!
//! ```text
//! x = x0 + dx cos θ − dy sin θ   y = y0 + dx sin θ + dy cos θ
//! ```
//!
//! Each of the centre, the aperture's radius in map pixels (which sets `p`
//! when the file does not), the rotation and the flip is given or fitted:
//! the centre as the centroid of the valid pixels, the radius from their
//! area, the rotation and flip by the closest coefficients to mfd's (a
//! closed-form turn of the cos/sin pairs, [`turn`]).

use serde::{Deserialize, Serialize};

use super::{CompareError, InterferometerMap};
use crate::optics::zernike::{nm_to_noll, noll_to_nm};

/// What the caller fixes; `None` is fitted.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RegistrationOptions {
    /// The aperture centre in the map, `(column, row)`, pixel centres at
    /// `+0.5`.
    pub center_px: Option<[f64; 2]>,
    /// The measured aperture's radius in map pixels (sets the pixel size
    /// when neither the file nor `pixel_mm` does).
    pub radius_px: Option<f64>,
    /// The map's pixel size, mm (overrides the file's).
    pub pixel_mm: Option<f64>,
    /// Rotation from the map onto the world frame, degrees.
    pub rotation_deg: Option<f64>,
    /// Mirror the map's columns before rotating.
    pub flip: Option<bool>,
}

/// A registration: where the map lies on the measured aperture.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Registration {
    /// The aperture centre in the map, `(column, row)`.
    pub center_px: [f64; 2],
    /// Pixel size, mm.
    pub pixel_mm: f64,
    /// Rotation, degrees.
    pub rotation_deg: f64,
    /// Whether the columns are mirrored.
    pub flip: bool,
    /// The world point of the aperture centre, mm (`surfaces.json`'s).
    pub aperture_center_mm: [f64; 2],
    /// Which of `center_px`, `pixel_mm`, `rotation_deg`, `flip` were fitted.
    pub fitted: Vec<String>,
}

impl Registration {
    /// The offset of map pixel `(column, row)` from the aperture centre
    /// before flip and rotation, mm.
    pub fn offset_mm(&self, column: usize, row: usize) -> (f64, f64) {
        let [cx, cy] = self.center_px;
        (
            (column as f64 + 0.5 - cx) * self.pixel_mm,
            (cy - (row as f64 + 0.5)) * self.pixel_mm,
        )
    }

    /// The world point of an offset, mm.
    pub fn world_of_offset(&self, (dx, dy): (f64, f64)) -> (f64, f64) {
        let dx = if self.flip { -dx } else { dx };
        let (s, c) = self.rotation_deg.to_radians().sin_cos();
        let [x0, y0] = self.aperture_center_mm;
        (x0 + dx * c - dy * s, y0 + dx * s + dy * c)
    }

    /// The world point of map pixel `(column, row)`, mm.
    pub fn world_mm(&self, column: usize, row: usize) -> (f64, f64) {
        self.world_of_offset(self.offset_mm(column, row))
    }

    /// The continuous map coordinates `(column, row)` of a world point (the
    /// inverse of [`Registration::world_mm`], pixel centres at `+0.5`).
    pub fn map_px(&self, x_mm: f64, y_mm: f64) -> (f64, f64) {
        let [x0, y0] = self.aperture_center_mm;
        let (s, c) = self.rotation_deg.to_radians().sin_cos();
        let (ux, uy) = (x_mm - x0, y_mm - y0);
        let (dx, dy) = (ux * c + uy * s, -ux * s + uy * c);
        let dx = if self.flip { -dx } else { dx };
        let [cx, cy] = self.center_px;
        (cx + dx / self.pixel_mm, cy - dy / self.pixel_mm)
    }
}

/// The centre and scale of `map` on an aperture of `radius_mm` around
/// `center_mm`, rotation 0 and no flip (set by the caller afterwards).
///
/// # Errors
/// [`CompareError::Coverage`] for a map without a valid pixel;
/// [`CompareError::Content`] for a non-positive given size.
pub fn place(
    map: &InterferometerMap,
    options: &RegistrationOptions,
    radius_mm: f64,
    center_mm: [f64; 2],
) -> Result<Registration, CompareError> {
    let mut fitted = Vec::new();
    let (mut sc, mut sr, mut n) = (0.0, 0.0, 0usize);
    for (k, h) in map.heights_nm.iter().enumerate() {
        if h.is_finite() {
            sc += (k % map.width) as f64 + 0.5;
            sr += (k / map.width) as f64 + 0.5;
            n += 1;
        }
    }
    if n == 0 {
        return Err(CompareError::Coverage {
            path: map.path.clone(),
            points: 0,
            fraction: 0.0,
        });
    }
    let center_px = options.center_px.unwrap_or_else(|| {
        fitted.push("center_px".to_string());
        [sc / n as f64, sr / n as f64]
    });
    let pixel_mm = match (options.pixel_mm, map.pixel_mm) {
        (Some(p), _) | (None, Some(p)) => p,
        (None, None) => {
            fitted.push("pixel_mm".to_string());
            let r_px = options
                .radius_px
                .unwrap_or_else(|| (n as f64 / std::f64::consts::PI).sqrt());
            radius_mm / r_px
        }
    };
    if !(pixel_mm.is_finite() && pixel_mm > 0.0) {
        return Err(CompareError::Content {
            path: map.path.clone(),
            item: "pixel size".into(),
            reason: format!("{pixel_mm} mm, expected a positive size"),
        });
    }
    Ok(Registration {
        center_px,
        pixel_mm,
        rotation_deg: 0.0,
        flip: false,
        aperture_center_mm: center_mm,
        fitted,
    })
}

/// Zernike coefficients (Noll, RMS-normalised; index k is j = k + 1) of a
/// map fitted without flip and rotation, turned into those of the same map
/// flipped (`dx → −dx`) and rotated by `rotation_deg` as
/// [`Registration::world_of_offset`] does: each cos/sin pair of azimuthal
/// order m turns by m·θ; a flip multiplies the cos term by (−1)^m and the
/// sin term by −(−1)^m. A pair cut by the end of the list turns with its
/// missing partner taken as 0.
pub fn turn(coefficients_nm: &[f64], rotation_deg: f64, flip: bool) -> Vec<f64> {
    let theta = rotation_deg.to_radians();
    let len = coefficients_nm.len();
    let mut out = coefficients_nm.to_vec();
    for k in 0..len {
        let Ok((n, m)) = noll_to_nm(k + 1) else {
            continue;
        };
        if m <= 0 {
            continue;
        }
        let partner = nm_to_noll(n, -m).ok().map(|j| j - 1).filter(|&i| i < len);
        let a = coefficients_nm[k];
        let b = partner.map_or(0.0, |i| coefficients_nm[i]);
        let sign = if m % 2 == 0 { 1.0 } else { -1.0 };
        let (a, b) = if flip { (sign * a, -sign * b) } else { (a, b) };
        let (s, c) = (f64::from(m) * theta).sin_cos();
        out[k] = a * c - b * s;
        if let Some(i) = partner {
            out[i] = a * s + b * c;
        }
    }
    out
}

/// The rotation and flip (where not given) that bring `map_coefficients_nm`
/// (fitted at rotation 0, no flip) closest to `ours_nm` over Noll j ≥ 4,
/// weighted by `1/σ²` (`std_nm`, where positive; else 1): a search over
/// whole degrees, then a golden-section refinement within ±1°.
pub fn best_turn(
    map_coefficients_nm: &[f64],
    ours_nm: &[f64],
    std_nm: Option<&[f64]>,
    rotation_deg: Option<f64>,
    flip: Option<bool>,
) -> (f64, bool) {
    let weight = |k: usize| {
        std_nm
            .and_then(|s| s.get(k))
            .filter(|s| **s > 0.0)
            .map_or(1.0, |s| 1.0 / (s * s))
    };
    let cost = |theta: f64, f: bool| -> f64 {
        let t = turn(map_coefficients_nm, theta, f);
        (3..t.len().min(ours_nm.len()))
            .map(|k| weight(k) * (t[k] - ours_nm[k]).powi(2))
            .sum()
    };
    let flips: Vec<bool> = flip.map_or(vec![false, true], |f| vec![f]);
    let mut best = (f64::INFINITY, 0.0, false);
    for &f in &flips {
        let Some(theta) = rotation_deg else {
            let mut t0 = (0..360)
                .map(f64::from)
                .min_by(|a, b| cost(*a, f).total_cmp(&cost(*b, f)))
                .unwrap_or(0.0);
            t0 = golden(|t| cost(t, f), t0 - 1.0, t0 + 1.0);
            let c = cost(t0, f);
            if c < best.0 {
                // In (−180°, 180°].
                let t = t0.rem_euclid(360.0);
                best = (c, if t > 180.0 { t - 360.0 } else { t }, f);
            }
            continue;
        };
        let c = cost(theta, f);
        if c < best.0 {
            best = (c, theta, f);
        }
    }
    (best.1, best.2)
}

/// The minimum of `f` on `[lo, hi]` by golden-section search to 1e-9.
fn golden(f: impl Fn(f64) -> f64, mut lo: f64, mut hi: f64) -> f64 {
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut a, mut b) = (hi - g * (hi - lo), lo + g * (hi - lo));
    let (mut fa, mut fb) = (f(a), f(b));
    while hi - lo > 1e-9 {
        if fa < fb {
            hi = b;
            b = a;
            fb = fa;
            a = hi - g * (hi - lo);
            fa = f(a);
        } else {
            lo = a;
            a = b;
            fa = fb;
            b = lo + g * (hi - lo);
            fb = f(b);
        }
    }
    0.5 * (lo + hi)
}

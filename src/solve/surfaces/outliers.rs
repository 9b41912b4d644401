//! Outliers of a surface fit: pixels whose whitened χ² is far beyond what
//! their noise allows (a wrong point from the spectral stage), found at the
//! joint fit and left out before it is refitted.

use super::problem::Layout;
use super::Observations;
use crate::optics::station::Station;
use crate::optics::trace::Plate;

/// A pixel whose whitened χ² exceeds this (times the fit's scale, below)
/// is an outlier: a wrong point from the spectral stage, e.g. a mislabelled
/// pair at the rim. For a correct pixel χ² follows χ²(≤ 4 dof):
/// P(χ²₄ > 49) ≈ 6e-10, so on 10⁵ pixels the rule rejects an honest one
/// with probability < 1e-4.
pub const OUTLIER_CHI2: f64 = 49.0;

/// At most this fraction of the pixels is left out: beyond it the model,
/// not a few points, is wrong, and the residuals say so (χ²/dof).
const MAX_OUTLIER_FRACTION: f64 = 0.01;

/// The outlier rule in words, for reports (`summary.json`).
pub const OUTLIER_RULE: &str = "pixel chi2 of its whitened residuals > 49 x max(1, median chi2 \
     per component / 0.75), at most 1 % of the pixels";

/// Pixels (indices into `obs.pixels`) whose χ² at the current fit exceeds
/// [`OUTLIER_CHI2`] times the fit's scale: the median of χ²/(components)
/// over the pixels divided by its expectation (≈ 0.75 for 2–4 components),
/// at least 1 — so a model that fits every pixel equally badly rejects
/// nothing, and neither does σ estimated from the residuals.
pub(super) fn outliers(
    obs: &Observations,
    station: &Station,
    plate: &Plate,
    layout: &Layout,
) -> Vec<usize> {
    let chi2 = super::problem::pixel_chi2(obs, station, plate, layout);
    let mut per: Vec<f64> = chi2
        .iter()
        .zip(&obs.pixels)
        .filter(|(c, _)| c.is_finite())
        .map(|(c, p)| {
            let m = 2
                * (usize::from(p.has(0) && layout.use_s1) + usize::from(p.has(1) && layout.use_s2));
            c / m.max(1) as f64
        })
        .collect();
    if per.is_empty() {
        return Vec::new();
    }
    per.sort_by(f64::total_cmp);
    let scale = (per[per.len() / 2] / 0.75).max(1.0);
    let out: Vec<usize> = chi2
        .iter()
        .enumerate()
        .filter(|(_, c)| **c > OUTLIER_CHI2 * scale)
        .map(|(k, _)| k)
        .collect();
    if out.len() as f64 > MAX_OUTLIER_FRACTION * obs.pixels.len() as f64 {
        return Vec::new();
    }
    out
}

pub(super) fn without(obs: &Observations, rejected: &[usize]) -> Observations {
    let mut keep = vec![true; obs.pixels.len()];
    rejected.iter().for_each(|&k| keep[k] = false);
    Observations {
        camera: obs.camera,
        pixels: obs
            .pixels
            .iter()
            .zip(&keep)
            .filter(|(_, k)| **k)
            .map(|(p, _)| *p)
            .collect(),
        sigma_known: obs.sigma_known,
        rejected: obs
            .rejected
            .iter()
            .copied()
            .chain(rejected.iter().map(|&k| obs.pixels[k].pixel))
            .collect(),
    }
}

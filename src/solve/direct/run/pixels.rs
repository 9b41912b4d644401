//! The pixels of the fit: their state (parameters and linearisation),
//! the start of each, the screen points the plate predicts for them, and
//! what they hand the surface solver and the maps.

use nalgebra::Vector3;
use rayon::prelude::*;

use crate::optics::station::Station;
use crate::optics::trace::Plate;
use crate::solve::direct::pixel::{linearise_tied, start, Linear, Tie};
use crate::solve::spectral::model::Params;
use crate::solve::spectral::{PixelFlags, SpectralMaps, SpectralSolver};
use crate::solve::surfaces::path::{back_path, front_path};
use crate::solve::surfaces::{Observation, Observations};

/// One pixel of the fit.
#[derive(Debug, Clone, Copy)]
pub(super) struct Pix {
    /// Candidate index in the spectral solver.
    pub(super) q: usize,
    /// Camera pixel `(column, row)`.
    pub(super) cam: [u32; 2],
    /// Camera ray, element frame.
    pub(super) dir: Vector3<f64>,
    /// Current parameters (K = 1 or 2 reflections).
    pub(super) p: Params,
    /// Linearisation at `p`.
    pub(super) lin: Linear,
    /// The back's share of the traced Fresnel weights `w_b / (w_f + w_b)`
    /// (0 with one reflection).
    pub(super) back_share: f64,
    /// Samples the camera clipped (0 or saturated): these stand at their
    /// conditional means under the pixel's current model
    /// ([`crate::solve::spectral::model::censored`]), refreshed at every
    /// linearisation, so that the fit's fixed point is the censored
    /// likelihood's and no clipped trough biases the surfaces.
    pub(super) clipped: usize,
}

impl Pix {
    pub(super) fn objective(&self) -> f64 {
        self.lin.samples as f64 * self.lin.rss.max(f64::MIN_POSITIVE).ln()
    }

    /// The pixel's noise σ from its last linearisation, counts.
    pub(super) fn sigma(&self) -> f64 {
        let dof = self.lin.samples.saturating_sub(self.p.len()).max(1);
        (self.lin.rss / dof as f64).sqrt()
    }
}

/// Candidate `q` linearised at `p`: with `imputed` = `Some(σ)` its
/// clipped samples stand at their conditional means under `p` with noise σ,
/// else they are left out.
pub(super) fn linearise_at(
    solver: &SpectralSolver,
    q: usize,
    p: &Params,
    imputed: Option<f64>,
    tie: Option<&Tie>,
) -> Option<Linear> {
    let lin =
        |samples: &dyn crate::solve::spectral::model::Samples, _| linearise_tied(samples, p, tie);
    match imputed {
        None => solver.with_samples(q, lin)?,
        Some(sigma) => solver.with_samples_at(q, p, sigma, lin)?,
    }
}

/// The pixels to fit: candidates with fringes; with `two`, two
/// reflections where the plate's back path exists, else one; rim pixels with a borrowed back offset left out.
pub(super) fn initial_pixels(
    solver: &SpectralSolver,
    maps: &SpectralMaps,
    station: &Station,
    plate: &Plate,
    two: bool,
) -> Vec<Pix> {
    let kappa0 = median_kappa(maps).map_or_else(
        || solver.kappa_start(),
        |k| solver.design().uniform_falloff(k),
    );
    let cam = &station.camera;
    let w = cam.width as usize;
    let skip = PixelFlags::NO_DATA | PixelFlags::NO_SIGNAL;
    let candidates = solver.candidates();
    (0..candidates.len())
        .into_par_iter()
        .filter_map(|q| {
            let c = candidates[q] as usize;
            if maps.pixels[c].flags.intersects(skip) {
                return None;
            }
            let prior = &solver.prior().pixels[c];
            let wf = prior.front.as_ref().ok()?.weight;
            let back_share = prior
                .back
                .as_ref()
                .map_or(0.0, |b| b.weight / (wf + b.weight));
            let k = match (two, prior.back.is_ok()) {
                (true, true) => 2,
                (true, false) if solver.borrowed(q) => return None,
                _ => 1,
            };
            let ij = [(c % w) as u32, (c / w) as u32];
            let dir = cam.ray_direction(ij[0], ij[1]).into_inner();
            let s = predict(plate, station, &dir, k)?;
            let (p, clipped) = solver.with_samples(q, |samples, clipped| {
                (start(samples, k, &s, kappa0), clipped)
            })?;
            let lin = linearise_at(solver, q, &p, None, None)?;
            Some(Pix {
                q,
                cam: ij,
                dir,
                p,
                lin,
                back_share,
                clipped,
            })
        })
        .collect()
}

/// The median κ the per-pixel fits found, where they reported one.
fn median_kappa(maps: &SpectralMaps) -> Option<f64> {
    let mut k: Vec<f64> = maps
        .pixels
        .iter()
        .map(|p| p.tau_max)
        .filter(|t| t.is_finite() && *t > 0.0)
        .map(|t| t.powi(-2))
        .collect();
    if k.is_empty() {
        return None;
    }
    let mid = k.len() / 2;
    Some(*k.select_nth_unstable_by(mid, f64::total_cmp).1)
}

/// The `k` screen points `plate` predicts for the camera ray `dir`.
pub(super) fn predict(
    plate: &Plate,
    station: &Station,
    dir: &Vector3<f64>,
    k: usize,
) -> Option<[f64; 4]> {
    let cam = &station.camera.position_mm;
    let f = front_path(plate, cam, dir, &station.screen).ok()?;
    let mut s = [f.uv[0].v, f.uv[1].v, f64::NAN, f64::NAN];
    if k == 2 {
        let b = back_path(plate, cam, dir, &station.screen).ok()?;
        s[2] = b.uv[0].v;
        s[3] = b.uv[1].v;
    }
    Some(s)
}

/// The surface solver's input: every pixel's pseudo-observation.
pub(super) fn pseudo_observations(station: &Station, pix: &[Pix]) -> Observations {
    let pixels = pix
        .iter()
        .map(|x| Observation {
            pixel: x.cam,
            dir: x.dir,
            s: [
                [x.lin.s_star[0], x.lin.s_star[1]],
                [x.lin.s_star[2], x.lin.s_star[3]],
            ],
            cov: x.lin.cov,
        })
        .collect();
    Observations {
        camera: station.camera.position_mm,
        pixels,
        sigma_known: true,
        rejected: Vec::new(),
    }
}

/// The predicted points and χ² of every fitted pixel, as camera maps.
pub(super) fn maps_of(pix: &[Pix], w: usize, h: usize) -> (Vec<f64>, Vec<f64>) {
    let mut predicted = vec![f64::NAN; w * h * 4];
    let mut chi2 = vec![f64::NAN; w * h];
    for x in pix {
        let c = x.cam[1] as usize * w + x.cam[0] as usize;
        predicted[4 * c..4 * c + 4].copy_from_slice(&x.lin.s0);
        chi2[c] = x.lin.chi2;
    }
    (predicted, chi2)
}

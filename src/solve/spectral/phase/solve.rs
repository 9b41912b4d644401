//! Every candidate pixel of a phase-shifting acquisition decoded in two
//! passes (the [parent module](super)'s steps): unwrapped and fitted
//! unweighted, the camera's noise law from the pooled residuals, then
//! refitted weighted by it, with the covariance and flags.

use rayon::prelude::*;

use super::model::{PhaseFit, PhaseModel};
use super::unwrap::{unwrap_direction, wrapped, Unwrapped};
use super::{AMBIGUITY_CHI2, DETECTION_CHI2};
use crate::solve::spectral::pixel::{PixelFits, Scored};
use crate::solve::spectral::{PixelFlags, PixelResult};

/// The camera's noise law `var = a + b·μ`, counts², μ the model's value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseLaw {
    /// Variance at zero signal (read noise, quantisation), counts².
    pub a: f64,
    /// Variance per count of signal (shot noise: 1 / electrons per count).
    pub b: f64,
}

/// Fewest decoded pixels for the pooled noise law (two parameters from
/// ≥ 20 × 32 residuals: their relative error is then below ~10 %); with
/// fewer each pixel's own residual variance is used.
const MIN_POOLED_PIXELS: usize = 20;

/// One pixel's samples: used frames, their values, the values by frame
/// (NaN excluded) and how many were excluded.
struct PixelSamples {
    index: Vec<u32>,
    y: Vec<f64>,
    by_frame: Vec<f64>,
    excluded: usize,
}

fn samples(raw: &[u16], saturation: Option<u16>) -> PixelSamples {
    let mut excluded = 0;
    let by_frame: Vec<f64> = raw
        .iter()
        .map(|&v| {
            if v == 0 || saturation.is_some_and(|s| v >= s) {
                excluded += 1;
                f64::NAN
            } else {
                f64::from(v)
            }
        })
        .collect();
    let index: Vec<u32> = (0..raw.len() as u32)
        .filter(|&i| by_frame[i as usize].is_finite())
        .collect();
    let y = index.iter().map(|&i| by_frame[i as usize]).collect();
    PixelSamples {
        index,
        y,
        by_frame,
        excluded,
    }
}

/// The first pass of one pixel: unwrapped directions and the unweighted fit.
struct First {
    unwrapped: Vec<Unwrapped>,
    fit: PhaseFit,
    /// Whether every direction shows a fringe at the pixel's own residual
    /// noise: only those pixels inform the noise law (a fit to noise
    /// alone is no sample of the model's residuals).
    detected: bool,
}

/// The settings the fits share.
#[derive(Debug, Clone, Copy)]
pub(in crate::solve::spectral) struct PhaseSettings {
    /// Samples at or above this count (and at 0) are excluded.
    pub saturation: Option<u16>,
    /// Starting κ.
    pub kappa0: f64,
    /// Levenberg–Marquardt iteration cap.
    pub max_iter: usize,
}

/// Decodes every candidate of `series` (pixel-major, `frames` samples each).
pub(in crate::solve::spectral) fn solve_all(
    model: &PhaseModel,
    series: &[u16],
    settings: PhaseSettings,
) -> Vec<PixelFits> {
    let n = model.design.frames.len();
    let firsts: Vec<(PixelSamples, Option<First>)> = series
        .par_chunks(n.max(1))
        .map(|raw| {
            let s = samples(raw, settings.saturation);
            let first = first_pass(model, &s, settings);
            (s, first)
        })
        .collect();
    let law = noise_law(model, &firsts);
    log::info!(
        "phase-shifting decode: noise law var = {:.4} + {:.5}·μ counts² from the pooled residuals",
        law.map_or(f64::NAN, |l| l.a),
        law.map_or(f64::NAN, |l| l.b)
    );
    firsts
        .par_iter()
        .map(|(s, first)| match first {
            Some(first) => second_pass(model, s, first, law, settings),
            None => {
                let mut out = PixelFits::none();
                out.flags = PixelFlags::NO_SIGNAL;
                if s.excluded > 0 {
                    out.flags |= PixelFlags::SATURATED;
                }
                if s.index.len() <= model.len() {
                    out.flags = PixelFlags::NO_DATA | (out.flags & PixelFlags::SATURATED);
                }
                out
            }
        })
        .collect()
}

/// Unwrapping and the unweighted joint fit; `None` where a direction has
/// no measurable phase or the frames cannot determine the model.
fn first_pass(model: &PhaseModel, s: &PixelSamples, settings: PhaseSettings) -> Option<First> {
    if s.index.len() <= model.len() {
        return None;
    }
    let sched = model.schedule;
    let phases: Vec<_> = sched
        .groups
        .iter()
        .map(|g| wrapped(model.design, g, &s.by_frame))
        .collect();
    let unwrapped: Vec<Unwrapped> = (0..sched.directions)
        .map(|d| unwrap_direction(sched, d, &phases))
        .collect::<Option<_>>()?;
    let mus: Vec<f64> = unwrapped.iter().map(|u| u.s).collect();
    let uv = model.design.screen_point(&mus)?;
    let ones = vec![1.0; s.index.len()];
    let kappa = if model.fits_kappa() {
        settings.kappa0
    } else {
        0.0
    };
    let start = model.linear_start(&s.index, &s.y, &ones, uv, kappa)?;
    let fit = model.fit(&s.index, &s.y, &ones, start, settings.max_iter);
    let rss: f64 = residuals(model, s, &fit).iter().map(|(_, r)| r * r).sum();
    let sigma2 = rss / (s.index.len() - model.len()) as f64;
    let detected = fit
        .jtj
        .clone()
        .cholesky()
        .is_some_and(|c| detected(model, &fit, &(c.inverse() * sigma2)));
    Some(First {
        unwrapped,
        fit,
        detected,
    })
}

/// Model values and residuals of frames `index` at `fit`.
fn residuals(model: &PhaseModel, s: &PixelSamples, fit: &PhaseFit) -> Vec<(f64, f64)> {
    let mut row = vec![0.0; model.len()];
    s.index
        .iter()
        .zip(&s.y)
        .map(|(&i, &y)| {
            let mu = model.eval(i as usize, &fit.params, &mut row);
            (mu, y - mu)
        })
        .collect()
}

/// Per sample of an unweighted fit, the squared residual and what its
/// expectation is made of: with `H = J (JᵀJ)⁻¹ Jᵀ` and noise variances
/// `σ_j² = a + b μ_j`, `E[r_i²] = Σ_j (I − H)_ij² σ_j² = a f1_i + b f2_i`,
/// `f1_i = Σ_j (I − H)_ij²`, `f2_i = Σ_j (I − H)_ij² μ_j`. (With 20
/// parameters in 32 samples the leverages are ~0.6: the plain correction
/// `r²/(1 − h)` mixes the noise of bright and dark samples and flattens the
/// law.) Returns `(r², f1, f2)` per sample.
fn residual_features(
    model: &PhaseModel,
    s: &PixelSamples,
    fit: &PhaseFit,
) -> Option<Vec<(f64, f64, f64)>> {
    let inv = fit.jtj.clone().cholesky()?.inverse();
    let n = s.index.len();
    let p = model.len();
    let mut jac = nalgebra::DMatrix::zeros(n, p);
    let mut row = vec![0.0; p];
    let mut mu = vec![0.0; n];
    let mut r2 = vec![0.0; n];
    for (k, (&i, &y)) in s.index.iter().zip(&s.y).enumerate() {
        mu[k] = model.eval(i as usize, &fit.params, &mut row);
        r2[k] = (y - mu[k]).powi(2);
        jac.row_mut(k).copy_from_slice(&row);
    }
    let hat = &jac * inv * jac.transpose();
    Some(
        (0..n)
            .map(|i| {
                let (mut f1, mut f2) = (0.0, 0.0);
                for j in 0..n {
                    let m = (if i == j { 1.0 } else { 0.0 } - hat[(i, j)]).powi(2);
                    f1 += m;
                    f2 += m * mu[j];
                }
                (r2[i], f1, f2)
            })
            .collect(),
    )
}

/// The pooled noise law: the squared residuals of every converged first
/// pass that shows a fringe, regressed on their expectations
/// ([`residual_features`]), summed in a fixed order (the same law on every
/// run). `None` with too few pixels.
fn noise_law(model: &PhaseModel, firsts: &[(PixelSamples, Option<First>)]) -> Option<NoiseLaw> {
    // Σ f1², Σ f1 f2, Σ f2², Σ f1 z, Σ f2 z, pixels.
    let sums: Vec<[f64; 6]> = firsts
        .par_iter()
        .map(|(s, first)| {
            let mut acc = [0.0; 6];
            let Some(first) = first.as_ref().filter(|f| f.fit.converged && f.detected) else {
                return acc;
            };
            let Some(samples) = residual_features(model, s, &first.fit) else {
                return acc;
            };
            for (z, f1, f2) in samples {
                acc[0] += f1 * f1;
                acc[1] += f1 * f2;
                acc[2] += f2 * f2;
                acc[3] += f1 * z;
                acc[4] += f2 * z;
            }
            acc[5] = 1.0;
            acc
        })
        .collect();
    let t = sums
        .iter()
        .fold([0.0; 6], |a, b| std::array::from_fn(|k| a[k] + b[k]));
    if (t[5] as usize) < MIN_POOLED_PIXELS {
        return None;
    }
    let det = t[0] * t[2] - t[1] * t[1];
    let (mut a, mut b) = if det > 0.0 {
        (
            (t[2] * t[3] - t[1] * t[4]) / det,
            (t[0] * t[4] - t[1] * t[3]) / det,
        )
    } else {
        (t[3] / t[0], 0.0)
    };
    if b < 0.0 {
        (a, b) = (t[3] / t[0], 0.0);
    }
    if a <= 0.0 {
        // All of it proportional to the signal.
        (a, b) = (1e-9 * (t[4] / t[2]).max(1e-12), t[4] / t[2]);
    }
    Some(NoiseLaw { a, b })
}

/// The weighted refit of one pixel, its covariance and flags.
fn second_pass(
    model: &PhaseModel,
    s: &PixelSamples,
    first: &First,
    law: Option<NoiseLaw>,
    settings: PhaseSettings,
) -> PixelFits {
    let fit = match law {
        Some(l) => {
            let w: Vec<f64> = residuals(model, s, &first.fit)
                .iter()
                .map(|(mu, _)| 1.0 / (l.a + l.b * mu.max(0.0)))
                .collect();
            model.fit(
                &s.index,
                &s.y,
                &w,
                first.fit.params.clone(),
                settings.max_iter,
            )
        }
        None => first.fit.clone(),
    };
    let n = s.index.len();
    let p = model.len();
    let res = residuals(model, s, &fit);
    let rss: f64 = res.iter().map(|(_, r)| r * r).sum();
    // σ² of one sample, counts²: the law's mean over the pixel's frames, or
    // (no law) the pixel's own residual variance, which then scales JᵀJ.
    let (scale, sigma2) = match law {
        Some(l) => (
            1.0,
            res.iter()
                .map(|(mu, _)| l.a + l.b * mu.max(0.0))
                .sum::<f64>()
                / n as f64,
        ),
        None => {
            let v = rss / (n - p) as f64;
            (v, v)
        }
    };
    let mut out = PixelFits::none();
    if s.excluded > 0 {
        out.flags |= PixelFlags::SATURATED;
    }
    let Some(cov) = fit.jtj.clone().cholesky().map(|c| c.inverse() * scale) else {
        out.flags |= PixelFlags::NO_SIGNAL;
        return out;
    };
    let flags = pixel_flags(model, &fit, &cov, &first.unwrapped, sigma2);
    if flags.contains(PixelFlags::NO_SIGNAL) {
        // Without a fringe, unwrapping has nothing to be ambiguous about.
        out.flags |= flags - PixelFlags::UNRESOLVED;
        return out;
    }
    let mut r = PixelResult::empty();
    r.flags = out.flags | flags | PixelFlags::ONE_REFLECTION;
    r.model = 1;
    r.iterations = (first.fit.iterations + fit.iterations) as u16;
    r.residual_rms = (rss / n as f64).sqrt();
    let par = &fit.params;
    r.amp[0] = par.offset.iter().sum::<f64>() / par.offset.len() as f64;
    r.amp[1] = par.amp.iter().sum::<f64>() / par.amp.len() as f64;
    // τ_max of the harmonics' falloff, from the groups' mean κ.
    let kappa = par.kappa.iter().sum::<f64>() / par.kappa.len() as f64;
    r.tau_max = if model.fits_kappa() && kappa > 0.0 {
        kappa.powf(-0.5)
    } else {
        f64::INFINITY
    };
    if !r.flags.contains(PixelFlags::UNRESOLVED) {
        r.s[0] = par.uv;
        r.std[0] = [cov[(0, 0)].max(0.0).sqrt(), cov[(1, 1)].max(0.0).sqrt()];
        for a in 0..2 {
            for b in 0..2 {
                r.cov[a][b] = cov[(a, b)];
            }
        }
    }
    let bic = n as f64 * (rss / n as f64).max(1e-300).ln() + p as f64 * (n as f64).ln();
    out.set_model(0, Some(Scored { result: r, bic }));
    out
}

/// Whether every direction's amplitudes are significant under `cov`:
/// `Σ_τ B_τ²/σ²(B_τ) ≥` [`DETECTION_CHI2`].
fn detected(model: &PhaseModel, fit: &PhaseFit, cov: &nalgebra::DMatrix<f64>) -> bool {
    let sched = model.schedule;
    let first_amp = model.nonlinear() + sched.directions;
    (0..sched.directions).all(|d| {
        let chi2: f64 = sched
            .of_direction(d)
            .map(|g| fit.params.amp[g].powi(2) / cov[(first_amp + g, first_amp + g)])
            .sum();
        chi2 >= DETECTION_CHI2
    })
}

/// Detection (every direction's amplitudes significant), ambiguity of the
/// unwrapping, convergence.
fn pixel_flags(
    model: &PhaseModel,
    fit: &PhaseFit,
    cov: &nalgebra::DMatrix<f64>,
    unwrapped: &[Unwrapped],
    sigma2: f64,
) -> PixelFlags {
    let mut flags = PixelFlags::empty();
    if !detected(model, fit, cov) {
        flags |= PixelFlags::NO_SIGNAL;
    }
    let ambiguous = unwrapped.iter().any(|u| {
        let gap = 2.0 * std::f64::consts::PI.powi(2) * (u.runner_up - u.score) / sigma2;
        gap < AMBIGUITY_CHI2
    });
    if ambiguous {
        flags |= PixelFlags::UNRESOLVED;
    }
    if !fit.converged {
        flags |= PixelFlags::NOT_CONVERGED;
    }
    flags
}

//! The design's candidate frames (every τ of a grid on each direction),
//! their per-pixel gradients at the traced flat plate, the continuous
//! A-optimal weights over them (the multiplicative algorithm) and the
//! rounding of weights to frames.

use rayon::prelude::*;

use crate::acquire::acquisition::FrameInfo;
use crate::budget::scene;
use crate::optics::station::Station;
use crate::solve::spectral::model::{normal_equations, Design};

use super::super::predict::{sample_pixels, traced_view};
use super::super::{invalid, PlanError};
use super::DesignOptions;

/// The per-pixel gradients of every candidate at the sample pixels.
pub(super) struct Problem {
    /// Candidate frames (direction-major, τ ascending).
    pub(super) candidates: Vec<FrameInfo>,
    /// Per sample pixel: the parameter count and the indices of u, v.
    pub(super) pixels: Vec<(usize, Vec<usize>)>,
    /// Per sample pixel, per candidate, the gradient (length of the pixel's
    /// parameters), scaled by 1/σ.
    pub(super) grads: Vec<Vec<Vec<f64>>>,
}

fn candidates(opts: &DesignOptions) -> Result<Vec<FrameInfo>, PlanError> {
    let tau_max = opts.plan.radiometry.tau_max;
    let hi = opts.tau_hi.unwrap_or(2.0 * tau_max);
    if !(opts.tau_step.is_finite() && opts.tau_step > 0.0 && hi > 2.0 * opts.tau_step) {
        return Err(invalid(
            "--tau-step",
            format!(
                "expected a step > 0 well below the largest τ {hi}, found {}",
                opts.tau_step
            ),
        ));
    }
    let n = (hi / opts.tau_step).floor() as usize;
    let mut out = Vec::new();
    for &d in &opts.directions_deg {
        for k in 1..=n {
            out.push(FrameInfo {
                index: out.len(),
                direction_deg: d,
                tau: k as f64 * opts.tau_step,
                phase_rad: 0.0,
            });
        }
    }
    Ok(out)
}

pub(super) fn problem(
    station: &Station,
    opts: &DesignOptions,
) -> Result<(Problem, Design), PlanError> {
    let candidates = candidates(opts)?;
    let design = scene::design(station, &candidates)?;
    let view = traced_view(station, opts.plan.back_scale)?;
    let r = &opts.plan.radiometry;
    let gain = r.gain(&view);
    let sigma = r.sigma_counts();
    let mut pixels = Vec::new();
    let mut grads = Vec::new();
    for q in sample_pixels(&view, opts.pixels, false) {
        // The truth with the physical falloff (a blur on the screen
        // period, [`Design::physical_falloff`]); the fit's κ per falloff
        // group is among the parameters, as in reconstruction.
        let p = super::super::stage::truth_params(&design, &view.pixels[q], gain, r);
        let k = p.k;
        // The model's gradient row has ∂/∂A = 1 first, so a one-frame JᵀJ's
        // first column is the row itself.
        let g: Vec<Vec<f64>> = (0..candidates.len() as u32)
            .map(|c| {
                let m = normal_equations(&design, &[c], &[0.0], &p).jtj;
                (0..p.len()).map(|a| m[(a, 0)] / sigma).collect()
            })
            .collect();
        let uv: Vec<usize> = (0..k)
            .flat_map(|j| [p.u_index(j), p.u_index(j) + 1])
            .collect();
        pixels.push((p.len(), uv));
        grads.push(g);
    }
    Ok((
        Problem {
            candidates,
            pixels,
            grads,
        },
        design,
    ))
}

impl Problem {
    /// Φ(w) and d_c for one frame in total (`Σ w = 1`); `None` when some
    /// pixel's information is singular.
    pub(super) fn criterion(&self, w: &[f64]) -> Option<(f64, Vec<f64>)> {
        // Each pixel's share on every core; then summed in pixel order, each
        // term added as a sequential loop adds it (the same bits at any
        // thread count).
        let shares: Vec<Option<(f64, Vec<f64>)>> = self
            .pixels
            .par_iter()
            .zip(&self.grads)
            .map(|((n, uv), g)| pixel_share(*n, uv, g, w))
            .collect();
        let mut phi = 0.0;
        let mut d = vec![0.0; w.len()];
        for (share, (_, uv)) in shares.into_iter().zip(&self.pixels) {
            let (p, zz) = share?;
            phi += p;
            if uv.is_empty() {
                continue;
            }
            // d_c = Σ_a (F⁻¹ J_c)_a² over the picked a, per pixel.
            for (dc, z) in d.iter_mut().zip(zz.chunks_exact(uv.len())) {
                for zi in z {
                    *dc += zi;
                }
            }
        }
        Some((phi, d))
    }

    /// The continuous A-optimal weights and the equivalence bound of their Φ.
    pub(super) fn optimum(&self, iterations: usize) -> Result<(Vec<f64>, f64), PlanError> {
        let n = self.candidates.len();
        let mut w = vec![1.0 / n as f64; n];
        let singular = || {
            invalid("the design", "the information of the candidate frames is singular at a sample pixel: check the station and the τ grid")
        };
        let mut lower = 0.0;
        for it in 0..iterations {
            let (phi, d) = self.criterion(&w).ok_or_else(singular)?;
            let dmax = d.iter().copied().fold(0.0, f64::max);
            lower = (2.0 * phi - dmax).max(lower);
            if dmax <= 1.001 * phi {
                log::debug!("design: converged after {it} iterations");
                break;
            }
            let mut sum = 0.0;
            for (wc, dc) in w.iter_mut().zip(&d) {
                *wc *= (dc / phi).sqrt();
                sum += *wc;
            }
            w.iter_mut().for_each(|x| *x /= sum);
        }
        Ok((w, lower))
    }
}

/// One pixel's `tr(K F⁻¹ Kᵀ)` and, per candidate c and picked parameter a,
/// `(F⁻¹ J_c)_a²` (candidate-major), for `n` parameters, the picked `uv`,
/// gradients `g` and weights `w`; `None` where F is singular. F is built in
/// its lower triangle only (all the Cholesky factorisation reads), each
/// element rounded as `f += (w_c J_c) J_cᵀ` rounds it: the product
/// `(w_c J_ci) J_cj`, then the sum.
fn pixel_share(n: usize, uv: &[usize], g: &[Vec<f64>], w: &[f64]) -> Option<(f64, Vec<f64>)> {
    let mut f = nalgebra::DMatrix::<f64>::zeros(n, n);
    let fs = f.as_mut_slice();
    let mut s = vec![0.0; n];
    for (gc, &wc) in g.iter().zip(w) {
        if wc > 0.0 {
            for (si, &gi) in s.iter_mut().zip(gc) {
                *si = wc * gi;
            }
            for (j, (col, &gj)) in fs.chunks_exact_mut(n).zip(gc).enumerate() {
                for (fij, &si) in col[j..].iter_mut().zip(&s[j..]) {
                    *fij += si * gj;
                }
            }
        }
    }
    let inv = f.cholesky()?.inverse();
    let phi = uv.iter().map(|&a| inv[(a, a)]).sum::<f64>();
    let rows: Vec<nalgebra::DVector<f64>> = uv.iter().map(|&a| inv.row(a).transpose()).collect();
    let mut zz = Vec::with_capacity(g.len() * rows.len());
    for gc in g {
        for r in &rows {
            let z: f64 = r.iter().zip(gc).map(|(x, y)| x * y).sum();
            zz.push(z * z);
        }
    }
    Some((phi, zz))
}

/// Frames for weights `w` over the candidates: cumulative (systematic)
/// rounding, `n_c = ⌊N W_c + ½⌋ − ⌊N W_{c−1} + ½⌋` with `W` the running
/// sum, which keeps every stretch of τ at its share of the frames even
/// where single weights are below 1/N; repeats of a candidate follow one
/// another.
pub(super) fn round(candidates: &[FrameInfo], w: &[f64], n: usize) -> Vec<FrameInfo> {
    let total: f64 = w.iter().sum();
    let mut cum = 0.0;
    let mut prev = 0usize;
    let mut out = Vec::with_capacity(n);
    for (c, &wc) in candidates.iter().zip(w) {
        cum += wc / total;
        let upto = ((n as f64 * cum + 0.5).floor() as usize).min(n);
        for _ in prev..upto {
            out.push(FrameInfo {
                index: out.len(),
                ..*c
            });
        }
        prev = upto.max(prev);
    }
    out
}

/// The weights of a rounded schedule over the candidates (Σ = 1): each
/// frame counted at the first candidate of its direction and τ (equal as
/// numbers: keyed by their bits with −0 as 0; NaN matches none), looked up
/// in a map, not searched (100 000 frames over thousands of candidates).
pub(super) fn weights_of(candidates: &[FrameInfo], frames: &[FrameInfo]) -> Vec<f64> {
    let key = |f: &FrameInfo| {
        let (d, t) = (f.direction_deg + 0.0, f.tau + 0.0);
        (!d.is_nan() && !t.is_nan()).then_some((d.to_bits(), t.to_bits()))
    };
    let mut first = std::collections::HashMap::new();
    for (c, cand) in candidates.iter().enumerate() {
        if let Some(k) = key(cand) {
            first.entry(k).or_insert(c);
        }
    }
    let mut w = vec![0.0; candidates.len()];
    for f in frames {
        if let Some(&c) = key(f).and_then(|k| first.get(&k)) {
            w[c] += 1.0 / frames.len() as f64;
        }
    }
    w
}

//! A pixel's result under one model: labels from physics (which point is
//! the front, which the back), the checks that decide whether a pair is
//! resolved and consistent with the station's prediction, and the
//! uncertainties from the Fisher information at the residuals' noise level.

use std::cell::OnceCell;

use nalgebra::DMatrix;

use super::{spd_inverse, start, Candidate, PixelContext, RESOLVE_SIGMAS};
use crate::optics::trace::{Miss, ScreenHit};
use crate::solve::spectral::model::{Params, Samples};
use crate::solve::spectral::{PixelFlags, PixelResult};

/// The pixel's result under the candidate's model: labels from physics,
/// checks, uncertainties.
/// `merged` is the one-reflection fit (on a warm pixel, the pair's
/// amplitude-weighted centre and total amplitude): its amplitude and
/// falloff describe the pixel's signal robustly, so they judge whether a
/// pair is separable; `unit_sd` caches that judgement's σ at unit noise.
pub(super) fn finalize<S: Samples + ?Sized>(
    ctx: &PixelContext,
    cand: &Candidate,
    data: &S,
    d12: Option<[f64; 2]>,
    merged: &Params,
    unit_sd: &OnceCell<f64>,
    base: PixelResult,
) -> PixelResult {
    let expected_sd = |d: &[f64; 2], sigma2: f64| {
        unit_sd.get_or_init(|| {
            expected_separation_std(ctx, data, merged, merged.uv[0], merged.amp[0], d, 1.0)
        }) * sigma2.sqrt()
    };
    let mut out = base;
    let fit = &cand.fit;
    let p = fit.params;
    let n = data.count();
    if p.amp[..p.k].iter().any(|&b| b <= 0.0) {
        out.flags |= PixelFlags::NEGATIVE_AMPLITUDE;
        return out;
    }
    if !data.within_band(&p) {
        out.flags |= PixelFlags::OUT_OF_BAND;
        return out;
    }
    out.model = p.k as u8;
    out.iterations = fit.iterations as u16;
    out.residual_rms = (fit.rss / n as f64).sqrt();
    // The first direction's group: the diagonals' on the paper's schedules.
    out.tau_max = if p.kappa[0] > 0.0 {
        p.kappa[0].sqrt().recip()
    } else {
        f64::INFINITY
    };
    out.amp[0] = p.offset;
    if !fit.converged {
        out.flags |= PixelFlags::NOT_CONVERGED;
    }
    let sigma2 = fit.sigma2(n);
    let cov = cand.inv.as_ref().map(|m| m * sigma2);
    let fitted = Fitted {
        p: &p,
        cov: cov.as_ref(),
        sigma2,
    };
    if p.k == 1 {
        label_one(ctx, &fitted, d12, expected_sd, out)
    } else {
        label_pair(ctx, &fitted, d12, expected_sd, out)
    }
}

/// A model's fit as the labelling reads it.
struct Fitted<'a> {
    p: &'a Params,
    /// The parameters' covariance at the residuals' noise level.
    cov: Option<&'a DMatrix<f64>>,
    /// That noise level, counts².
    sigma2: f64,
}

/// [`finalize`] of a one-reflection fit: which of the station's paths it
/// is, and whether a second one could have been told apart.
fn label_one(
    ctx: &PixelContext,
    fit: &Fitted,
    d12: Option<[f64; 2]>,
    expected_sd: impl Fn(&[f64; 2], f64) -> f64,
    mut out: PixelResult,
) -> PixelResult {
    let (p, cov) = (fit.p, fit.cov);
    out.flags |= PixelFlags::ONE_REFLECTION;
    // No back path predicted: the one reflection is the front.
    let Some(d) = d12 else {
        out.set(0, p, 0, cov);
        out.amp[1] = p.amp[0];
        return out;
    };
    // One reflection, or two this schedule cannot tell apart? Only if a
    // back reflection of the expected strength at the expected offset
    // would have been resolved is its absence real (AR-coated back).
    out.separation_bins = separation_bins(ctx, &d);
    // The expected pair judged on the merged signal ([`super::merged_signal`]).
    let sd = expected_sd(&d, fit.sigma2);
    if RESOLVE_SIGMAS * sd > d[0].hypot(d[1]) {
        out.flags |= PixelFlags::UNRESOLVED;
        return out;
    }
    let dist = |q: Result<ScreenHit, Miss>| {
        q.map_or(f64::INFINITY, |h| {
            (p.uv[0][0] - h.u).hypot(p.uv[0][1] - h.v)
        })
    };
    let slot = usize::from(dist(ctx.prior.back) < dist(ctx.prior.front));
    out.set(slot, p, 0, cov);
    out.amp[1 + slot] = p.amp[0];
    out
}

/// [`finalize`] of a fit with two (or three) reflections: which point is
/// the front, and whether the pair is resolved and where the station
/// expects it.
fn label_pair(
    ctx: &PixelContext,
    fit: &Fitted,
    d12: Option<[f64; 2]>,
    expected_sd: impl Fn(&[f64; 2], f64) -> f64,
    mut out: PixelResult,
) -> PixelResult {
    let (p, cov) = (fit.p, fit.cov);
    if p.k == 3 {
        out.flags |= PixelFlags::THREE_REFLECTIONS;
        out.amp[3] = p.amp[2];
    }
    let d = d12.unwrap_or([1.0, 0.0]);
    let sep = [p.uv[1][0] - p.uv[0][0], p.uv[1][1] - p.uv[0][1]];
    let (i0, i1) = if sep[0] * d[0] + sep[1] * d[1] >= 0.0 {
        (0, 1)
    } else {
        (1, 0)
    };
    let sep = [p.uv[i1][0] - p.uv[i0][0], p.uv[i1][1] - p.uv[i0][1]];
    out.separation_bins = separation_bins(ctx, &sep);
    // Resolved: the expected separation exceeds RESOLVE_SIGMAS standard
    // deviations, both of the fitted separation and of the separation the
    // data could give for the expected pair (the local bound at a poor fit
    // can be too optimistic). Consistent: the fitted offset is within half
    // the expected one (plus three σ) of it — farther, it could be a swap or
    // a spurious pair, and neither point is reported.
    let sd = cov.map_or(f64::INFINITY, |c| separation_std(c, p, i0, i1));
    let sd_expected = expected_sd(&d, fit.sigma2);
    let expected = d[0].hypot(d[1]);
    if RESOLVE_SIGMAS * sd.max(sd_expected) > expected {
        out.flags |= PixelFlags::UNRESOLVED;
        return out;
    }
    if (sep[0] - d[0]).hypot(sep[1] - d[1]) > 0.5 * expected + 3.0 * sd {
        out.flags |= PixelFlags::OFFSET_MISMATCH;
        return out;
    }
    out.set(0, p, i0, cov);
    out.set(1, p, i1, cov);
    out.set_cross(p, i0, i1, cov);
    out.amp[1] = p.amp[i0];
    out.amp[2] = p.amp[i1];
    out
}

/// The Cramér–Rao σ of |S2 − S1| for a pair with the predicted offset `d`
/// and Fresnel amplitude ratio, centred (amplitude-weighted) on `centre`,
/// with total amplitude `amp`, at noise `sigma2`: how well this pixel's data
/// could separate the reflections the geometry expects, whatever the fit found.
pub(super) fn expected_separation_std<S: Samples + ?Sized>(
    ctx: &PixelContext,
    data: &S,
    fitted: &Params,
    centre: [f64; 2],
    amp: f64,
    d: &[f64; 2],
    sigma2: f64,
) -> f64 {
    let w = match (ctx.prior.front, ctx.prior.back) {
        (Ok(f), Ok(b)) => b.weight / (f.weight + b.weight),
        _ => 0.5,
    };
    let c = centre;
    let pair = [
        [c[0] - w * d[0], c[1] - w * d[1]],
        [c[0] + (1.0 - w) * d[0], c[1] + (1.0 - w) * d[1]],
    ];
    let mut p = start(2, &pair, fitted.kappa);
    p.offset = fitted.offset;
    p.amp[0] = amp * (1.0 - w);
    p.amp[1] = amp * w;
    spd_inverse(&data.information(&p)).map_or(f64::INFINITY, |inv| {
        separation_std(&(inv * sigma2), &p, 0, 1)
    })
}

/// Separation in Fourier bins of two screen points `d` apart, that of the
/// best pair of directions
/// ([`crate::solve::spectral::model::Design::pair_separation`]).
fn separation_bins(ctx: &PixelContext, d: &[f64; 2]) -> f64 {
    let seps: Vec<f64> = ctx
        .design
        .axes
        .iter()
        .enumerate()
        .map(|(k, ax)| (ax.a * d[0] + ax.b * d[1]).abs() / ctx.plans.bin(k))
        .collect();
    ctx.design.pair_separation(&seps).unwrap_or(f64::INFINITY)
}

/// Standard deviation of |S_i1 − S_i0| from the covariance.
fn separation_std(cov: &DMatrix<f64>, p: &Params, i0: usize, i1: usize) -> f64 {
    let (a, b) = (p.u_index(i0), p.u_index(i1));
    let var = |x: usize, y: usize| cov[(x, x)] + cov[(y, y)] - 2.0 * cov[(x, y)];
    (var(a, b) + var(a + 1, b + 1)).max(0.0).sqrt()
}

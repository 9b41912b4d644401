//! One pixel from its series to its screen points: starting values from the
//! spectrum and the station geometry, fits with one, two and (optionally)
//! three reflections, a choice among them by the Bayesian information
//! criterion, labels from physics, and uncertainties from the Fisher
//! information at the residuals' noise level.

use std::cell::OnceCell;

use nalgebra::DMatrix;

use super::model::{
    levenberg_marquardt, Design, Falloff, Fit, ParamCholesky, Params, Samples, MAX_REFLECTIONS,
};
use super::periodogram::SpectrumPlans;
use super::{PixelFlags, PixelResult};
use crate::optics::trace::PixelPaths;

mod finalize;
mod warm;

use finalize::finalize;
pub use warm::Seed;
use warm::{warm_fits, UNIT_SD_REUSE};

/// Peak-to-median power below which a direction carries no fringe signal.
/// For pure noise the periodogram's maximum over ~10³ bins sits ~10× the
/// median (exponential order statistics: ln 1000 / ln 2); 30 is far above it.
pub const DETECTION_RATIO: f64 = 30.0;

/// The expected separation must exceed this many standard deviations of the
/// fitted one for the two points to be reported. Below ~5σ the fit's local
/// (Cramér–Rao) uncertainty no longer describes its error: with 3σ the
/// reported σ underestimated the error 2–4× at 0.15–0.3 Fourier bins
/// (`mfd bench thickness`).
pub const RESOLVE_SIGMAS: f64 = 5.0;

/// What the pixel fit needs besides the series.
pub struct PixelContext<'a> {
    /// The schedule.
    pub design: &'a Design,
    /// Periodogram plans.
    pub plans: &'a SpectrumPlans,
    /// The station's prediction for this pixel (flat surfaces).
    pub prior: &'a PixelPaths,
    /// Where the prior has a front but no back path (the flat plate's back
    /// ray leaves through the rim), the back-minus-front offset of the
    /// nearest pixel that has both, within the candidates' margin: the real
    /// plate can still send a back reflection here, and a one-reflection fit
    /// of two would be wrong.
    pub borrowed_offset: Option<[f64; 2]>,
    /// Starting κ = 1/τ_max², per falloff group.
    pub kappa0: Falloff,
    /// Whether a third reflection may be modelled.
    pub allow_third: bool,
    /// LM iteration cap.
    pub max_iter: usize,
}

fn start(k: usize, uv: &[[f64; 2]], kappa: Falloff) -> Params {
    let mut p = Params {
        k,
        offset: 0.0,
        amp: [0.0; MAX_REFLECTIONS],
        uv: [[0.0; 2]; MAX_REFLECTIONS],
        kappa,
    };
    p.uv[..k].copy_from_slice(&uv[..k]);
    p
}

/// Starting pair for two reflections. Per direction d, the merged peak μ_d
/// lies between the two (or on one when they are resolved): scan the pair
/// `(μ_d + t δ_d, μ_d + (t + 1) δ_d)`, δ_d the expected offset projected on
/// the direction, t ∈ [−1.25, 0.25], and keep the best linear fit with
/// positive amplitudes on that direction's frames alone. Directions are
/// scanned apart because each one's peak is biased along its own axis.
/// Where the direction's window has strong sidelobes near its peak (a τ
/// grid with a gap: [`crate::solve::spectral::periodogram::Aliases::near`]),
/// the peak may be a sidelobe's, and the scan is repeated about `μ_d − δ`
/// for each of them: the fringes' own place fits that direction's frames
/// best.
fn pair_start<S: Samples + ?Sized>(
    ctx: &PixelContext,
    data: &S,
    mus: &[f64],
    d: &[f64; 2],
    kappa: Falloff,
) -> Params {
    let mut pair_mu = vec![[0.0; 2]; mus.len()];
    for (dir, ax) in ctx.design.axes.iter().enumerate() {
        let delta = ax.a * d[0] + ax.b * d[1];
        let norm2 = ax.a * ax.a + ax.b * ax.b;
        // A screen point whose coordinate on this axis is μ (the other is free).
        let point = |mu: f64| [(mu - ax.c) * ax.a / norm2, (mu - ax.c) * ax.b / norm2];
        let mut best = (f64::INFINITY, [mus[dir], mus[dir] + delta]);
        let near = ctx.plans.aliases(dir).map_or(&[][..], |a| &a.near[..]);
        for centre in std::iter::once(mus[dir]).chain(near.iter().map(|d| mus[dir] - d)) {
            let scan = data.pair_scan(
                dir,
                [centre - 1.25 * delta, 0.125 * delta, delta],
                13,
                kappa,
                &point,
            );
            for (k, (amp, rss)) in scan.into_iter().enumerate() {
                let t = -1.25 + 0.125 * k as f64;
                let m = [centre + t * delta, centre + (t + 1.0) * delta];
                if amp[0] > 0.0 && amp[1] > 0.0 && rss < best.0 {
                    best = (rss, m);
                }
            }
        }
        pair_mu[dir] = best.1;
    }
    let s1 = ctx
        .design
        .screen_point(&pair_mu.iter().map(|m| m[0]).collect::<Vec<_>>())
        .unwrap_or_default();
    let s2 = ctx
        .design
        .screen_point(&pair_mu.iter().map(|m| m[1]).collect::<Vec<_>>())
        .unwrap_or_default();
    start(2, &[s1, s2], kappa)
}

struct Candidate {
    fit: Fit,
    bic: f64,
    /// (JᵀJ)⁻¹: the covariance at unit noise.
    inv: Option<DMatrix<f64>>,
}

/// The inverse of a symmetric positive definite matrix (Cholesky), or of
/// any invertible one (LU) when it is not.
fn spd_inverse(m: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    match ParamCholesky::new(m) {
        Some(c) => Some(c.inverse()),
        None => m.clone().try_inverse(),
    }
}

fn fit_from<S: Samples + ?Sized>(ctx: &PixelContext, data: &S, starts: &[Params]) -> Candidate {
    // The best start with physical (positive) amplitudes; a start whose
    // linear fit needs a negative one sits in an unphysical basin.
    let scored: Vec<(Params, f64)> = starts.iter().map(|s| data.linear(s, None)).collect();
    let positive = |p: &Params| p.amp[..p.k].iter().all(|&b| b > 0.0);
    let (best_start, _) = scored
        .iter()
        .filter(|(p, _)| positive(p))
        .chain(scored.iter())
        .min_by(|a, b| {
            (!positive(&a.0), a.1)
                .partial_cmp(&(!positive(&b.0), b.1))
                .unwrap_or(std::cmp::Ordering::Equal)
        })
        .copied()
        .expect("at least one start");
    candidate(data, levenberg_marquardt(data, best_start, ctx.max_iter))
}

/// A fit with its BIC, `N ln(RSS/N) + p ln N`.
fn candidate<S: Samples + ?Sized>(data: &S, fit: Fit) -> Candidate {
    let n = data.count() as f64;
    let bic = n * (fit.rss / n).max(1e-300).ln() + fit.params.len() as f64 * n.ln();
    let inv = spd_inverse(&fit.jtj);
    Candidate { fit, bic, inv }
}

fn offset(prior: &PixelPaths, a: usize, b: usize) -> Option<[f64; 2]> {
    let paths = [prior.front, prior.back, prior.third];
    match (paths[a], paths[b]) {
        (Ok(p), Ok(q)) => Some([q.u - p.u, q.v - p.v]),
        _ => None,
    }
}

/// A pixel's result under one model, with that model's BIC.
#[derive(Debug, Clone, Copy)]
pub struct Scored {
    /// The result if this model is chosen.
    pub result: PixelResult,
    /// `N ln(RSS/N) + p ln N`.
    pub bic: f64,
}

/// A pixel fitted with every model that applies (index K − 1,
/// [`PixelFits::model`]), or the reason none could be: `flags` carries the
/// flags that hold whatever the model.
///
/// One per candidate pixel, held for the whole sensor until the scene's
/// model is chosen, so kept small: the pair's result in place (every pixel
/// whose two points were found has it), the one- and three-reflection
/// results on the heap where they were fitted (a warm pixel fits only the
/// pair), the no-model answer as its flags alone: 312 bytes a pixel instead
/// of 1088 with all three in place and a whole result for the flags (0.39
/// against 1.36 GB on a full 1296 × 966 sensor).
#[derive(Debug, Clone)]
pub struct PixelFits {
    one: Option<Box<Scored>>,
    two: Option<Scored>,
    three: Option<Box<Scored>>,
    /// The flags when no model applies (no data, no signal), else the
    /// flags common to every model.
    pub flags: PixelFlags,
    /// On a warm pixel (one-reflection model not fitted), that model's BIC
    /// as the weaker amplitude's Wald statistic z puts it, `BIC₂ + z² −
    /// 3 ln N` (z² approximates the likelihood ratio of dropping that
    /// reflection): the pixel's share of the scene's BIC sums.
    pub one_bic: Option<f64>,
}

impl PixelFits {
    /// No model, no flags (a placeholder).
    pub fn none() -> Self {
        PixelFits {
            one: None,
            two: None,
            three: None,
            flags: PixelFlags::empty(),
            one_bic: None,
        }
    }

    /// The result with `k + 1` reflections, where that model was fitted.
    pub fn model(&self, k: usize) -> Option<&Scored> {
        match k {
            0 => self.one.as_deref(),
            1 => self.two.as_ref(),
            2 => self.three.as_deref(),
            _ => None,
        }
    }

    /// Sets the result with `k + 1` reflections (`k` < [`MAX_REFLECTIONS`]).
    pub fn set_model(&mut self, k: usize, scored: Option<Scored>) {
        match k {
            0 => self.one = scored.map(Box::new),
            1 => self.two = scored,
            _ => self.three = scored.map(Box::new),
        }
    }

    /// The answer when no model applies: nothing found, with [`Self::flags`].
    pub fn base(&self) -> PixelResult {
        PixelResult {
            flags: self.flags,
            ..PixelResult::empty()
        }
    }
}

/// Fits one pixel with one, two and (when allowed) three reflections, on
/// any form of its samples (`excluded` of them left out as saturated),
/// starting from a neighbour's fits when `seed` is given,
/// moved by the change of the station's prediction: one evaluated
/// Gauss–Newton step for the pair and a second one taken unevaluated where
/// it is small ([`warm::ONE_STEP_CHI2`]; LM from there otherwise) — 2 evaluations
/// instead of the ~15 and two pair scans of the search from the spectrum.
/// The warm fit is kept only where the search would have ended in the same
/// place: both amplitudes far above detection and above what the BIC asks
/// of a second reflection ([`warm::WARM_AMPLITUDE_SIGMAS`]; the one-reflection
/// model is then not fitted, its BIC for the scene's sums taken from the
/// Wald statistic: [`PixelFits::one_bic`]) and the noise level the
/// neighbour's ([`warm::WARM_NOISE_RATIO`]);
/// otherwise the pixel is searched from scratch. Writes the fits to `out`
/// (in place) and returns, where both points were found,
/// the seed for the next pixel.
pub fn fit_samples_seeded<S: Samples + ?Sized>(
    ctx: &PixelContext,
    data: &S,
    excluded: usize,
    seed: Option<&Seed>,
    out: &mut PixelFits,
) -> Option<Seed> {
    *out = PixelFits::none();
    if excluded > 0 {
        out.flags |= PixelFlags::SATURATED;
    }
    if data.count() < 4 * (3 * MAX_REFLECTIONS + 2) {
        out.flags |= PixelFlags::NO_DATA;
        return None;
    }
    let d12 = offset(ctx.prior, 0, 1).or(ctx.borrowed_offset);
    let warm = seed.and_then(|s| warm_fits(ctx, data, s));
    let reuse = seed.filter(|_| warm.is_some()).and_then(|s| s.unit_sd);
    let (one, two, three) = match warm {
        Some((two, z2)) => {
            let n = data.count() as f64;
            out.one_bic = Some(two.bic + z2 - 3.0 * n.ln());
            (None, Some(two), None)
        }
        None => match searched_fits(ctx, data, d12, &mut out.flags) {
            Some((one, two, three)) => (Some(one), two, three),
            None => return None,
        },
    };
    let merged = merged_signal(ctx, data, one.as_ref(), two.as_ref());
    let n = data.count();
    let next = two
        .as_ref()
        .and_then(|two| Seed::from_fit(ctx, &two.fit, n));
    let unit_sd = OnceCell::new();
    let worst = [one.as_ref(), two.as_ref()]
        .into_iter()
        .flatten()
        .map(|c| c.fit.sigma2(n))
        .fold(0.0, f64::max);
    let carried = reused_unit_sd(reuse, d12, &merged, worst, &unit_sd);
    let base = out.base();
    for (k, cand) in [one, two, three].into_iter().enumerate() {
        let scored = cand.map(|c| Scored {
            result: finalize(ctx, &c, data, d12, &merged, &unit_sd, base),
            bic: c.bic,
        });
        out.set_model(k, scored);
    }
    let unit_sd = carried.or_else(|| unit_sd.get().map(|&v| (v, merged.amp[0], 0)));
    // Seed the next pixel only from a pair found and reported, front first.
    out.model(1)
        .and_then(|two| next?.handed_on(&two.result, unit_sd))
}

/// Of the μ that direction `d`'s periodogram cannot tell from the peak at
/// `mu` (its copies on a τ grid, [`crate::solve::spectral::periodogram::Aliases`]:
/// `±mu + k/Δ` with one phase throughout, and the copies that alternating
/// phases and gaps add), the one nearest the station's prediction for the
/// pixel (its two points' midpoint). A direction whose τ step is coarse
/// shows a fringe as strongly at its copies as where it is, and the
/// strongest of them is a matter of noise and the window; on a fine grid
/// with one phase every copy lies beyond the search and `mu` is kept.
fn nearest_alias(ctx: &PixelContext, d: usize, mu: f64) -> f64 {
    let (Some(aliases), Ok(f)) = (ctx.plans.aliases(d), ctx.prior.front) else {
        return mu;
    };
    let ax = ctx.design.axes[d];
    let predicted = match ctx.prior.back {
        Ok(b) => 0.5 * (ax.s(f.u, f.v) + ax.s(b.u, b.v)),
        Err(_) => ax.s(f.u, f.v),
    };
    if !(predicted.is_finite() && mu.is_finite()) {
        return mu;
    }
    // The fringe coordinate runs over [0, 1] across the screen (the
    // search's 1.05 beyond it): copies outside are no screen point.
    aliases
        .of(mu, 0.0, 1.05)
        .into_iter()
        .min_by(|a, b| (a - predicted).abs().total_cmp(&(b - predicted).abs()))
        .unwrap_or(mu)
}

/// The pixel's signal as one reflection, which judges whether the expected
/// pair is separable: the one-reflection fit, or the pair's
/// amplitude-weighted centre, total amplitude and falloff where the pair
/// was fitted (in the band, both amplitudes positive) and the
/// one-reflection fit took its beat for falloff ([`BEAT_KAPPA`]; on a warm
/// pixel, which fits only the pair, always the pair).
fn merged_signal<S: Samples + ?Sized>(
    ctx: &PixelContext,
    data: &S,
    one: Option<&Candidate>,
    two: Option<&Candidate>,
) -> Params {
    let pair = match (one, two) {
        (Some(one), Some(two)) => {
            let (o, p) = (&one.fit.params, &two.fit.params);
            let beat = o.amp[0] <= 0.0
                || (0..p.kappa.groups)
                    .any(|g| o.kappa[g] - p.kappa[g] > BEAT_KAPPA * ctx.kappa0[g]);
            if !(beat
                && p.amp[0] > 0.0
                && p.amp[1] > 0.0
                && p.kappa.values().iter().all(|k| k.is_finite())
                && data.within_band(p))
            {
                return *o;
            }
            *p
        }
        (Some(one), None) => return one.fit.params,
        (None, Some(two)) => two.fit.params,
        (None, None) => unreachable!("a warm pixel has its pair"),
    };
    let b = pair.amp[0] + pair.amp[1];
    let mut m = start(1, &[[0.0; 2]], pair.kappa);
    m.offset = pair.offset;
    m.amp[0] = b;
    for c in 0..2 {
        m.uv[0][c] = (pair.amp[0] * pair.uv[0][c] + pair.amp[1] * pair.uv[1][c]) / b;
    }
    m
}

/// The one-reflection fit's falloff κ exceeding the pair's by this many
/// times κ0 = 1/τ_max² (its envelope at τ_max under e⁻² ≈ 0.14 of the
/// pair's) is the beat of a pair about a bin apart taken for falloff, not
/// the pixel's (soak seed 39058: κ 0.0017–0.0069 against the pair's 4·10⁻⁵,
/// κ0 7·10⁻⁵; or a negative amplitude). Judged at that κ the expected σ
/// came out 2–20× its neighbours' and resolved pairs were withheld. Judged
/// on the pair wherever the pair was the better fit, spurious pairs of
/// thin plates passed (seed 39041: 20 σ off) and a 13.8 mm plate's back
/// came out 2× its reported error (wedge soak 36048).
const BEAT_KAPPA: f64 = 2.0;

/// The expected pair's separation σ at unit noise is the same for every
/// model (it is built on `merged`), so computed once (into `unit_sd`). A
/// warm pixel takes its row's last value `reuse` (σ, the merged amplitude
/// it was computed at, pixels since), scaled by the merged amplitude (σ ∝
/// 1/B), where even twice that leaves the resolution test
/// ([`RESOLVE_SIGMAS`] σ below the expected separation `d12`) passed at
/// the worst model's noise level `worst_sigma2`: there the approximation
/// cannot change a decision. Returns the value carried on, one pixel older.
fn reused_unit_sd(
    reuse: Option<(f64, f64, u32)>,
    d12: Option<[f64; 2]>,
    merged: &Params,
    worst_sigma2: f64,
    unit_sd: &OnceCell<f64>,
) -> Option<(f64, f64, u32)> {
    let (Some((sd0, amp0, age)), Some(d)) = (reuse, d12) else {
        return None;
    };
    // Both amplitudes positive: carried over a sign change, σ came out
    // negative and the resolution test fell to the fit's own σ alone.
    let approx = sd0 * amp0 / merged.amp[0];
    if age < UNIT_SD_REUSE
        && amp0 > 0.0
        && merged.amp[0] > 0.0
        && approx.is_finite()
        && 2.0 * RESOLVE_SIGMAS * approx * worst_sigma2.sqrt() < d[0].hypot(d[1])
    {
        let _ = unit_sd.set(approx);
        return Some((sd0, amp0, age + 1));
    }
    None
}

/// The fits from the spectrum and the station geometry: the one-reflection
/// fit from the periodogram's centre, the pair from the scans, the third
/// reflection when allowed. `None` (with the reason in `base`, the pixel's flags) where no
/// model applies.
#[allow(clippy::type_complexity)]
fn searched_fits<S: Samples + ?Sized>(
    ctx: &PixelContext,
    data: &S,
    d12: Option<[f64; 2]>,
    base: &mut PixelFlags,
) -> Option<(Candidate, Option<Candidate>, Option<Candidate>)> {
    let mut mus = Vec::new();
    for d in 0..ctx.design.axes.len() {
        match data.peak(d) {
            Some((mu, ratio)) if ratio >= DETECTION_RATIO && mu.is_nan() => {
                *base |= PixelFlags::OUT_OF_BAND;
                return None;
            }
            Some((mu, ratio)) if ratio >= DETECTION_RATIO => mus.push(nearest_alias(ctx, d, mu)),
            _ => {
                *base |= PixelFlags::NO_SIGNAL;
                if data.band_limited() {
                    // No signal within the band: it may lie outside.
                    *base |= PixelFlags::OUT_OF_BAND;
                }
                return None;
            }
        }
    }
    let Some(centre) = ctx.design.screen_point(&mus) else {
        *base |= PixelFlags::NO_DATA;
        return None;
    };
    let one = fit_from(ctx, data, &[start(1, &[centre], ctx.kappa0)]);
    let mut two = None;
    let mut three = None;
    if let Some(d) = d12 {
        let mut best = fit_from(ctx, data, &[pair_start(ctx, data, &mus, &d, ctx.kappa0)]);
        if best.bic >= one.bic {
            // Search for the pair once more around the single point, so that
            // a pair the first search missed is not scored as one reflection.
            let p = one.fit.params.uv[0];
            let mus1: Vec<f64> = ctx.design.axes.iter().map(|ax| ax.s(p[0], p[1])).collect();
            let again = fit_from(ctx, data, &[pair_start(ctx, data, &mus1, &d, ctx.kappa0)]);
            if again.fit.rss < best.fit.rss {
                best = again;
            }
        }
        if ctx.allow_third {
            if let Some(d3) = offset(ctx.prior, 1, 2) {
                let p = best.fit.params;
                let s3 = [p.uv[1][0] + d3[0], p.uv[1][1] + d3[1]];
                three = Some(fit_from(
                    ctx,
                    data,
                    &[start(3, &[p.uv[0], p.uv[1], s3], p.kappa)],
                ));
            }
        }
        two = Some(best);
    }
    Some((one, two, three))
}

//! One pixel from its series to its screen points: starting values from the
//! spectrum and the station geometry, fits with one, two and (optionally)
//! three reflections, a choice among them by the Bayesian information
//! criterion, labels from physics, and uncertainties from the Fisher
//! information at the residuals' noise level.

use nalgebra::DMatrix;

use super::model::{
    gauss_newton_step, levenberg_marquardt, Design, Fit, Params, Samples, SeriesSamples,
    SmallCholesky, MAX_REFLECTIONS,
};
use super::periodogram::SpectrumPlans;
use super::{flags, PixelResult};
use crate::optics::trace::PixelPaths;

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
    /// Starting κ = 1/τ_max².
    pub kappa0: f64,
    /// Whether a third reflection may be modelled.
    pub allow_third: bool,
    /// LM iteration cap.
    pub max_iter: usize,
}

fn solve_centre(ctx: &PixelContext, mus: &[f64]) -> Option<[f64; 2]> {
    // Least squares of a_d u + b_d v = μ_d − c_d over the directions.
    let (mut saa, mut sab, mut sbb, mut sar, mut sbr) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (ax, &mu) in ctx.design.axes.iter().zip(mus) {
        let r = mu - ax.c;
        saa += ax.a * ax.a;
        sab += ax.a * ax.b;
        sbb += ax.b * ax.b;
        sar += ax.a * r;
        sbr += ax.b * r;
    }
    let det = saa * sbb - sab * sab;
    if det.abs() < 1e-12 * (saa * sbb).max(1e-300) {
        return None;
    }
    Some([(sbb * sar - sab * sbr) / det, (saa * sbr - sab * sar) / det])
}

fn start(k: usize, uv: &[[f64; 2]], kappa: f64) -> Params {
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
fn pair_start<S: Samples + ?Sized>(
    ctx: &PixelContext,
    data: &S,
    mus: &[f64],
    d: &[f64; 2],
    kappa: f64,
) -> Params {
    let mut pair_mu = vec![[0.0; 2]; mus.len()];
    for (dir, ax) in ctx.design.axes.iter().enumerate() {
        let delta = ax.a * d[0] + ax.b * d[1];
        let norm2 = ax.a * ax.a + ax.b * ax.b;
        // A screen point whose coordinate on this axis is μ (the other is free).
        let point = |mu: f64| [(mu - ax.c) * ax.a / norm2, (mu - ax.c) * ax.b / norm2];
        let mut best = (f64::INFINITY, [mus[dir], mus[dir] + delta]);
        let scan = data.pair_scan(
            dir,
            [mus[dir] - 1.25 * delta, 0.125 * delta, delta],
            13,
            kappa,
            &point,
        );
        for (k, (amp, rss)) in scan.into_iter().enumerate() {
            let t = -1.25 + 0.125 * k as f64;
            let m = [mus[dir] + t * delta, mus[dir] + (t + 1.0) * delta];
            if amp[0] > 0.0 && amp[1] > 0.0 && rss < best.0 {
                best = (rss, m);
            }
        }
        pair_mu[dir] = best.1;
    }
    let s1 =
        solve_centre(ctx, &pair_mu.iter().map(|m| m[0]).collect::<Vec<_>>()).unwrap_or_default();
    let s2 =
        solve_centre(ctx, &pair_mu.iter().map(|m| m[1]).collect::<Vec<_>>()).unwrap_or_default();
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
    match SmallCholesky::new(m) {
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

/// A pixel fitted with every model that applies (index K − 1), or the
/// reason none could be: `base` carries the flags that hold whatever the model.
#[derive(Debug, Clone, Copy)]
pub struct PixelFits {
    /// Results per number of reflections.
    pub per_model: [Option<Scored>; MAX_REFLECTIONS],
    /// Result when no model applies (no data, no signal), else the common flags.
    pub base: PixelResult,
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
            per_model: [None; MAX_REFLECTIONS],
            base: PixelResult::empty(),
            one_bic: None,
        }
    }
}

/// Fits one pixel with one, two and (when allowed) three reflections. `y`
/// is indexed by frame, NaN where a sample is excluded.
pub fn fit_pixel(ctx: &PixelContext, y_by_frame: &[f64], excluded: usize) -> PixelFits {
    let data = SeriesSamples::new(ctx.design, ctx.plans, y_by_frame, ctx.kappa0);
    fit_samples(ctx, &data, excluded)
}

/// [`fit_pixel`] on any form of the pixel's samples.
pub fn fit_samples<S: Samples + ?Sized>(
    ctx: &PixelContext,
    data: &S,
    excluded: usize,
) -> PixelFits {
    let mut out = PixelFits::none();
    fit_samples_seeded(ctx, data, excluded, None, &mut out);
    out
}

/// What a pixel whose two reflections were found hands the next pixel of
/// its camera row: its two-reflection fit (front first) and the station's
/// prediction there, so that the neighbour's fit starts where this pixel's
/// ended, moved by the prediction's change.
#[derive(Debug, Clone, Copy)]
pub struct Seed {
    two: Params,
    front: [f64; 2],
    back: [f64; 2],
    /// The two-reflection fit's noise variance, counts².
    sigma2: f64,
    /// The last separability σ at unit noise computed along the row, the
    /// merged amplitude it was computed at, and pixels since.
    unit_sd: Option<(f64, f64, u32)>,
}

/// A warm pixel may reuse the separability σ of a pixel at most this many
/// places before it in its row (then it is computed again).
const UNIT_SD_REUSE: u32 = 32;

/// The warm path accepts a pixel's fits only if its noise variance is within
/// this factor of the seed's. Adjacent pixels see nearly the same intensity,
/// so their read and shot noise agree to a few percent (the variance
/// estimate itself scatters by √(2/N) ≈ 3 % at N = 2000); a fit in a wrong
/// basin leaves the misfit in its residuals and fails this.
const WARM_NOISE_RATIO: f64 = 1.2;

/// A warm pixel's amplitudes and falloff κ must lie within this fraction of
/// its neighbour's: they follow the illumination and the optics, smooth
/// across one camera pixel, and a 10σ amplitude carries ≤ 10 % of noise
/// (typically ~1 %). Where they jump, the data do not follow the smooth
/// scene the warm start assumes, and the pixel is searched.
const WARM_CHANGE: f64 = 0.2;

/// Each warm amplitude must exceed this many of its standard deviations.
/// That is far above detection (a periodogram peak [`DETECTION_RATIO`]
/// times the median corresponds to ~6σ), so skipping the periodogram skips
/// nothing; and it decides one against two reflections more strictly than
/// the BIC, whose penalty for the second reflection's three parameters,
/// 3 ln N ≈ 23 at N = 2000, is met by a Wald statistic z² = 23 (z ≈ 4.8):
/// where the weaker amplitude is ≥ 10σ, the one-reflection fit is not needed.
const WARM_AMPLITUDE_SIGMAS: f64 = 10.0;

/// The warm pair's second Gauss–Newton step is taken without evaluating
/// its end point where it is predicted to lower χ² by less than this: a
/// step of ≤ √0.1 ≈ 0.3σ, which lands to second order in it (the points
/// within 0.03σ of the searched fit's, `tests/spectral_sim.rs`); RSS is
/// then the predicted one and JᵀJ the start's, whose σ differs by ≤ 0.7 %
/// there (2 % for steps up to 1σ, hence not more).
const ONE_STEP_CHI2: f64 = 0.1;

/// [`fit_samples`], starting from a neighbour's fits when `seed` is given,
/// moved by the change of the station's prediction: one evaluated
/// Gauss–Newton step for the pair and a second one taken unevaluated where
/// it is small ([`ONE_STEP_CHI2`]; LM from there otherwise) — 2 evaluations
/// instead of the ~15 and two pair scans of the search from the spectrum.
/// The warm fit is kept only where the search would have ended in the same
/// place: both amplitudes far above detection and above what the BIC asks
/// of a second reflection ([`WARM_AMPLITUDE_SIGMAS`]; the one-reflection
/// model is then not fitted, its BIC for the scene's sums taken from the
/// Wald statistic: [`PixelFits::one_bic`]) and the noise level the
/// neighbour's ([`WARM_NOISE_RATIO`]);
/// otherwise the pixel is searched from scratch. Writes the fits to `out`
/// (in place: they are ~1 kB) and returns, where both points were found,
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
        out.base.flags |= flags::SATURATED;
    }
    if data.count() < 4 * (3 * MAX_REFLECTIONS + 2) {
        out.base.flags |= flags::NO_DATA;
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
        None => match searched_fits(ctx, data, d12, &mut out.base) {
            Some((one, two, three)) => (Some(one), two, three),
            None => return None,
        },
    };
    // The pixel's signal as one reflection: the one-reflection fit, or on a
    // warm pixel the pair's amplitude-weighted centre and total amplitude.
    let merged = match (&one, &two) {
        (Some(one), _) => one.fit.params,
        (None, Some(two)) => {
            let p = two.fit.params;
            let b = p.amp[0] + p.amp[1];
            let mut m = start(1, &[[0.0; 2]], p.kappa);
            m.offset = p.offset;
            m.amp[0] = b;
            for c in 0..2 {
                m.uv[0][c] = (p.amp[0] * p.uv[0][c] + p.amp[1] * p.uv[1][c]) / b;
            }
            m
        }
        (None, None) => unreachable!("a warm pixel has its pair"),
    };
    let next = two.as_ref().and_then(|two| {
        let (Ok(f), Ok(b)) = (ctx.prior.front, ctx.prior.back) else {
            return None;
        };
        let n = data.count();
        Some(Seed {
            two: two.fit.params,
            front: [f.u, f.v],
            back: [b.u, b.v],
            sigma2: two.fit.sigma2(n),
            unit_sd: None,
        })
    });
    // The expected pair's separation σ at unit noise: the same for every
    // model (it is built on `merged`), so computed once. A warm pixel takes
    // its row's last value, scaled by the merged amplitude (σ ∝ 1/B), where
    // even twice that leaves the resolution test (RESOLVE_SIGMAS σ below
    // the expected separation) passed at every model's noise level: there
    // the approximation cannot change a decision.
    let unit_sd = std::cell::OnceCell::new();
    let mut carried = None;
    if let (Some((sd0, amp0, age)), Some(d)) = (reuse, d12) {
        let approx = sd0 * amp0 / merged.amp[0];
        let n = data.count();
        let worst = [one.as_ref(), two.as_ref()]
            .into_iter()
            .flatten()
            .map(|c| c.fit.sigma2(n))
            .fold(0.0, f64::max);
        if age < UNIT_SD_REUSE
            && approx.is_finite()
            && 2.0 * RESOLVE_SIGMAS * approx * worst.sqrt() < d[0].hypot(d[1])
        {
            let _ = unit_sd.set(approx);
            carried = Some((sd0, amp0, age + 1));
        }
    }
    for (k, cand) in [one, two, three].into_iter().enumerate() {
        out.per_model[k] = cand.map(|c| Scored {
            result: finalize(ctx, &c, data, d12, &merged, &unit_sd, out.base),
            bic: c.bic,
        });
    }
    let unit_sd = carried.or_else(|| unit_sd.get().map(|&v| (v, merged.amp[0], 0)));
    // Seed the next pixel only from a pair found and reported, front first.
    out.per_model[1].and_then(|two| {
        let r = two.result;
        (r.model == 2 && r.s[1][0].is_finite()).then_some(())?;
        let mut s = next?;
        s.unit_sd = unit_sd;
        let p = s.two;
        let front_first = (p.uv[0][0] - r.s[0][0]).hypot(p.uv[0][1] - r.s[0][1])
            <= (p.uv[1][0] - r.s[0][0]).hypot(p.uv[1][1] - r.s[0][1]);
        if !front_first {
            s.two.uv.swap(0, 1);
            s.two.amp.swap(0, 1);
        }
        Some(s)
    })
}

/// The two-reflection fit started from the neighbour's, or `None` where the
/// pixel must be searched (see [`fit_samples_seeded`]).
fn warm_fits<S: Samples + ?Sized>(
    ctx: &PixelContext,
    data: &S,
    seed: &Seed,
) -> Option<(Candidate, f64)> {
    if ctx.allow_third && ctx.prior.third.is_ok() {
        return None;
    }
    let (Ok(f), Ok(b)) = (ctx.prior.front, ctx.prior.back) else {
        return None;
    };
    let mut two = seed.two;
    for c in 0..2 {
        two.uv[0][c] += [f.u, f.v][c] - seed.front[c];
        two.uv[1][c] += [b.u, b.v][c] - seed.back[c];
    }
    let n = data.count();
    let (fit, next, remaining) = gauss_newton_step(data, two)?;
    let sigma2 = fit.sigma2(n);
    let two = if fit.converged {
        fit
    } else if remaining <= ONE_STEP_CHI2 * sigma2 {
        Fit {
            params: fit.params.add(&next),
            rss: fit.rss - remaining,
            iterations: 2,
            converged: true,
            ..fit
        }
    } else {
        let fit = levenberg_marquardt(data, fit.params, ctx.max_iter);
        if !fit.converged {
            return None;
        }
        fit
    };
    let two = candidate(data, two);
    let p = two.fit.params;
    let sigma2 = two.fit.sigma2(n);
    if sigma2 > WARM_NOISE_RATIO * seed.sigma2 {
        return None;
    }
    let near = |a: f64, b: f64| (a - b).abs() <= WARM_CHANGE * b.abs();
    let q = &seed.two;
    if !(near(p.amp[0], q.amp[0]) && near(p.amp[1], q.amp[1]) && near(p.kappa, q.kappa)) {
        return None;
    }
    let inv = two.inv.as_ref()?;
    // The weaker amplitude's Wald statistic z = B / σ_B.
    let z = (0..2)
        .map(|k| p.amp[k] / (inv[(1 + k, 1 + k)] * sigma2).max(0.0).sqrt())
        .fold(f64::INFINITY, f64::min);
    (z > WARM_AMPLITUDE_SIGMAS).then_some((two, z * z))
}

/// The fits from the spectrum and the station geometry: the one-reflection
/// fit from the periodogram's centre, the pair from the scans, the third
/// reflection when allowed. `None` (with the reason in `base`) where no
/// model applies.
#[allow(clippy::type_complexity)]
fn searched_fits<S: Samples + ?Sized>(
    ctx: &PixelContext,
    data: &S,
    d12: Option<[f64; 2]>,
    base: &mut PixelResult,
) -> Option<(Candidate, Option<Candidate>, Option<Candidate>)> {
    let mut mus = Vec::new();
    for d in 0..ctx.design.axes.len() {
        match data.peak(d) {
            Some((mu, ratio)) if ratio >= DETECTION_RATIO && mu.is_nan() => {
                base.flags |= flags::OUT_OF_BAND;
                return None;
            }
            Some((mu, ratio)) if ratio >= DETECTION_RATIO => mus.push(mu),
            _ => {
                base.flags |= flags::NO_SIGNAL;
                if data.band_limited() {
                    // No signal within the band: it may lie outside.
                    base.flags |= flags::OUT_OF_BAND;
                }
                return None;
            }
        }
    }
    let Some(centre) = solve_centre(ctx, &mus) else {
        base.flags |= flags::NO_DATA;
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

/// The pixel's result under the candidate's model: labels from physics,
/// checks, uncertainties.
/// `merged` is the one-reflection fit (on a warm pixel, the pair's
/// amplitude-weighted centre and total amplitude): its amplitude and
/// falloff describe the pixel's signal robustly, so they judge whether a
/// pair is separable; `unit_sd` caches that judgement's σ at unit noise.
fn finalize<S: Samples + ?Sized>(
    ctx: &PixelContext,
    cand: &Candidate,
    data: &S,
    d12: Option<[f64; 2]>,
    merged: &Params,
    unit_sd: &std::cell::OnceCell<f64>,
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
        out.flags |= flags::NEGATIVE_AMPLITUDE;
        return out;
    }
    if !data.within_band(&p) {
        out.flags |= flags::OUT_OF_BAND;
        return out;
    }
    out.model = p.k as u8;
    out.iterations = fit.iterations as u16;
    out.residual_rms = (fit.rss / n as f64).sqrt();
    out.tau_max = if p.kappa > 0.0 {
        p.kappa.sqrt().recip()
    } else {
        f64::INFINITY
    };
    out.amp[0] = p.offset;
    if !fit.converged {
        out.flags |= flags::NOT_CONVERGED;
    }
    let sigma2 = fit.sigma2(n);
    let cov = cand.inv.as_ref().map(|m| m * sigma2);
    if p.k == 1 {
        out.flags |= flags::ONE_REFLECTION;
        // No back path predicted: the one reflection is the front.
        let Some(d) = d12 else {
            out.set(0, &p, 0, cov.as_ref());
            out.amp[1] = p.amp[0];
            return out;
        };
        // One reflection, or two this schedule cannot tell apart? Only if a
        // back reflection of the expected strength at the expected offset
        // would have been resolved is its absence real (AR-coated back).
        out.separation_bins = separation_bins(ctx, &d);
        // Here p is `merged` itself (the one-reflection fit).
        let sd = expected_sd(&d, sigma2);
        if RESOLVE_SIGMAS * sd > d[0].hypot(d[1]) {
            out.flags |= flags::UNRESOLVED;
            return out;
        }
        let dist = |q: Result<crate::optics::trace::ScreenHit, crate::optics::trace::Miss>| {
            q.map_or(f64::INFINITY, |h| {
                (p.uv[0][0] - h.u).hypot(p.uv[0][1] - h.v)
            })
        };
        let slot = usize::from(dist(ctx.prior.back) < dist(ctx.prior.front));
        out.set(slot, &p, 0, cov.as_ref());
        out.amp[1 + slot] = p.amp[0];
        return out;
    }
    if p.k == 3 {
        out.flags |= flags::THREE_REFLECTIONS;
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
    let sd = cov
        .as_ref()
        .map_or(f64::INFINITY, |c| separation_std(c, &p, i0, i1));
    let sd_expected = expected_sd(&d, sigma2);
    let expected = d[0].hypot(d[1]);
    if RESOLVE_SIGMAS * sd.max(sd_expected) > expected {
        out.flags |= flags::UNRESOLVED;
        return out;
    }
    if (sep[0] - d[0]).hypot(sep[1] - d[1]) > 0.5 * expected + 3.0 * sd {
        out.flags |= flags::OFFSET_MISMATCH;
        return out;
    }
    out.set(0, &p, i0, cov.as_ref());
    out.set(1, &p, i1, cov.as_ref());
    out.set_cross(&p, i0, i1, cov.as_ref());
    out.amp[1] = p.amp[i0];
    out.amp[2] = p.amp[i1];
    out
}

/// The Cramér–Rao σ of |S2 − S1| for a pair with the predicted offset `d`
/// and Fresnel amplitude ratio, centred (amplitude-weighted) on `centre`,
/// with total amplitude `amp`, at noise `sigma2`: how well this pixel's data
/// could separate the reflections the geometry expects, whatever the fit found.
fn expected_separation_std<S: Samples + ?Sized>(
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

/// Smallest separation over the directions, in Fourier bins, of two screen
/// points `d` apart.
fn separation_bins(ctx: &PixelContext, d: &[f64; 2]) -> f64 {
    ctx.design
        .axes
        .iter()
        .enumerate()
        .map(|(k, ax)| (ax.a * d[0] + ax.b * d[1]).abs() / ctx.plans.bin(k))
        .fold(f64::INFINITY, f64::min)
}

/// Standard deviation of |S_i1 − S_i0| from the covariance.
fn separation_std(cov: &DMatrix<f64>, p: &Params, i0: usize, i1: usize) -> f64 {
    let (a, b) = (p.u_index(i0), p.u_index(i1));
    let var = |x: usize, y: usize| cov[(x, x)] + cov[(y, y)] - 2.0 * cov[(x, y)];
    (var(a, b) + var(a + 1, b + 1)).max(0.0).sqrt()
}

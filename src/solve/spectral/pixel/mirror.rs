//! The pair's other pairing across directions, and what it does to the
//! pair's uncertainty.
//!
//! Each direction sees the two points as two frequencies. Which frequency
//! of one direction goes with which of another's is told only by the
//! amplitudes (front and back share theirs across directions), and a
//! window's two reflections are nearly as bright (B₂/B₁ ≈ 0.8). Where a
//! direction sees the pair a fraction of a Fourier bin apart it determines
//! little more than their amplitude-weighted mean and spread, and the pair
//! mirrored about that mean on that direction fits almost as well. The
//! likelihood then has two maxima a few pixels apart, and the curvature at
//! one (the reported σ, a tenth of a pixel) knows nothing of the other.
//!
//! Measured on the spectral soak's 60° / −60° draw (seed 39008, 12 mm,
//! n 1.89, the fixture's station): the mirrored pair fitted within Δχ² of
//! 0.0–0.5 on the three pixels whose points were 10–22 σ off, −12 in the
//! median over the sensor. The station's prediction could not tell them
//! apart there: at the aperture's rim the surfaces move the back point 6 px
//! from it, and the truth's offset had, on −60°, the opposite sign to the
//! prediction's.
//!
//! So the other maximum is fitted, from the mirrored pair, on every
//! direction where its points lie within [`REACH_FACTOR`] times the fit's
//! departure from the prediction (farther, the station excludes it).
//! The more likely of the two is the answer, and where the other's
//! posterior weight `w = 1/(1 + e^{−Δχ²/2})` (flat prior, equal
//! curvatures) exceeds [`AMBIGUOUS_WEIGHT`] the pair is not reported
//! ([`crate::solve::spectral::PixelFlags::UNRESOLVED`]). Widening the
//! covariance by `w D Dᵀ` instead (`D` the two maxima's difference) was
//! tried: it is right on average over both outcomes, but the pixels it
//! keeps then report 1.3× their error (soak 39008: RMS error/σ 0.76) and
//! the ambiguous ones fail the resolve test anyway.
//!
//! The test costs a Levenberg–Marquardt fit per direction. A warm pixel
//! skips it where the last pixel of its row that made it, at most
//! [`super::UNIT_SD_REUSE`] places before, found every other maximum below
//! [`SKIP_CHI2`]: the Δχ² follows the amplitudes and the separations,
//! smooth along a row, and its noise (√(4|Δχ²|)) cannot lift such a maximum
//! to a weight that matters.

use super::{candidate, Candidate, PixelContext, UNIT_SD_REUSE};
use crate::solve::spectral::model::{levenberg_marquardt, Params, Samples};

/// A mirrored pair is another maximum to weigh only where each of its
/// points lies within this many times the fit's own departure from the
/// station's prediction (plus [`NOISE_SIGMAS`] of the point's σ). The
/// prediction is as good as the station and the surfaces let it be, and
/// the fit's departure shows how good that is at this pixel: on the
/// independent fixture (`spectral_fixture`, pairs 0.45 bins apart) the
/// points lie a few tenths of a pixel from it and the mirrored pairs
/// several pixels, which the station excludes although the data alone
/// cannot (they fit within Δχ² of 13.8 on 89 % of its pixels); at the soak
/// 39008's rim the surfaces move the back point 6 px from it and the
/// mirrored pair, the true one, lies 1.4× farther than the fit.
const REACH_FACTOR: f64 = 3.0;

/// The point's noise in that reach: where the fit lies on the prediction,
/// a mirrored pair within this many of its σ is not excluded.
const NOISE_SIGMAS: f64 = 3.0;

/// The other maximum's posterior weight `1/(1 + e^{−Δχ²/2})` above which
/// the pair is not reported: where it is reported, the chance that it is
/// the mirrored one is below 10⁻³ (Δχ² below −13.8).
const AMBIGUOUS_WEIGHT: f64 = 1e-3;

/// A fit from the mirrored start this many σ or less from the pair (on
/// every point coordinate) has come back to the pair's own maximum.
const DISTINCT_SIGMAS: f64 = 3.0;

/// Iterations of the fit from the mirrored start: it starts next to the
/// other maximum (the spread about the mean kept), which the soak's fits
/// reached in 2–3; one that wanders farther is going back to the pair's.
const ALT_ITERATIONS: usize = 10;

/// A row skips the test while its last test's nearest other maximum lay
/// this far below (Δχ²): at −100, with the difference's noise σ of
/// √(4·100) = 20, even a 3σ excursion leaves it at −40, a weight of 2·10⁻⁹.
const SKIP_CHI2: f64 = -100.0;

/// What a row carries to its next pixel: the nearest other maximum's Δχ²
/// at the last test, and pixels since (`None`: no other maximum in reach).
pub(super) type Carried = Option<(f64, u32)>;

/// The more likely of the pair `two` and its mirrored pairings in reach,
/// whether another of them is too likely for the pair to be reported
/// ([`AMBIGUOUS_WEIGHT`]), and what the row carries on. `carried` is the
/// row's value where this pixel was started from its neighbour.
pub(super) fn weighed<S: Samples + ?Sized>(
    ctx: &PixelContext,
    data: &S,
    two: Candidate,
    carried: Carried,
) -> (Candidate, bool, Carried) {
    if let Some((chi2, age)) = carried {
        if chi2 < SKIP_CHI2 && age < UNIT_SD_REUSE {
            return (two, false, Some((chi2, age + 1)));
        }
    }
    let n = data.count();
    let mut best = two;
    // Δχ² of the nearest other maximum (negative: less likely than `best`).
    let mut nearest = f64::NEG_INFINITY;
    for d in 0..ctx.design.axes.len() {
        let p = best.fit.params;
        if p.k != 2 {
            return (best, false, None);
        }
        let sigma2 = best.fit.sigma2(n);
        let Some(start) = mirrored(ctx, &p, d).filter(|q| within_reach(ctx, &best, sigma2, q))
        else {
            continue;
        };
        let (start, _) = data.linear(&start, None);
        let alt = candidate(
            data,
            levenberg_marquardt(data, start, ALT_ITERATIONS.min(ctx.max_iter)),
        );
        let q = matched(&p, alt.fit.params);
        if q.amp[..2].iter().any(|&b| b <= 0.0)
            || !data.within_band(&q)
            || !within_reach(ctx, &best, sigma2, &q)
            || !distinct(&best, &q, best.fit.sigma2(n))
        {
            continue;
        }
        let gain = (best.fit.rss - alt.fit.rss) / best.fit.sigma2(n);
        if gain > 0.0 && alt.fit.converged {
            // The mirrored pair is the more likely: it is the answer, and
            // the maxima found before lie `gain` further below it. (A fit
            // stopped short of its maximum only bounds its Δχ² from below:
            // it can show the pair ambiguous, never be the answer.)
            best = alt;
            nearest = (nearest - gain).max(-gain);
        } else {
            nearest = nearest.max(gain);
        }
    }
    let weight = 1.0 / (1.0 + (-0.5 * nearest).exp());
    let carried = (nearest > f64::NEG_INFINITY).then_some((nearest, 0));
    (best, weight > AMBIGUOUS_WEIGHT, carried)
}

/// Whether `q` is another maximum than `c`'s fit: a point coordinate
/// more than [`DISTINCT_SIGMAS`] of its σ away (a fit from the mirrored
/// start may come back to the same one).
fn distinct(c: &Candidate, q: &Params, sigma2: f64) -> bool {
    let p = &c.fit.params;
    let Some(inv) = c.inv.as_ref() else {
        return false;
    };
    (0..2).any(|k| {
        (0..2).any(|a| {
            let i = p.u_index(k) + a;
            (q.uv[k][a] - p.uv[k][a]).abs()
                > DISTINCT_SIGMAS * (inv[(i, i)] * sigma2).max(0.0).sqrt()
        })
    })
}

/// `q` with its points labelled as `p`'s: the order whose points lie
/// nearer `p`'s (a fit from the mirrored start may end with the labels
/// exchanged, the same pair).
fn matched(p: &Params, mut q: Params) -> Params {
    let d = |a: &[f64; 2], b: &[f64; 2]| (a[0] - b[0]).hypot(a[1] - b[1]);
    let kept = d(&q.uv[0], &p.uv[0]) + d(&q.uv[1], &p.uv[1]);
    let swapped = d(&q.uv[1], &p.uv[0]) + d(&q.uv[0], &p.uv[1]);
    if swapped < kept {
        q.uv.swap(0, 1);
        q.amp.swap(0, 1);
    }
    q
}

/// Whether each point of `q` lies within [`REACH_FACTOR`] times `p`'s
/// departure from the station's prediction, plus [`NOISE_SIGMAS`] of its
/// σ (`c`'s fit is `p`; `p` and `q` labelled alike; the prediction's
/// front and back matched to the labels by the offset's direction).
fn within_reach(ctx: &PixelContext, c: &Candidate, sigma2: f64, q: &Params) -> bool {
    let (Ok(f), Ok(b)) = (ctx.prior.front, ctx.prior.back) else {
        return true;
    };
    let (p, Some(inv)) = (&c.fit.params, c.inv.as_ref()) else {
        return false;
    };
    let mut pred = [[f.u, f.v], [b.u, b.v]];
    let o = [p.uv[1][0] - p.uv[0][0], p.uv[1][1] - p.uv[0][1]];
    if o[0] * (b.u - f.u) + o[1] * (b.v - f.v) < 0.0 {
        pred.swap(0, 1);
    }
    (0..2).all(|k| {
        let i = p.u_index(k);
        let sd = ((inv[(i, i)] + inv[(i + 1, i + 1)]) * sigma2)
            .max(0.0)
            .sqrt();
        let from = |x: &[f64; 2]| (x[0] - pred[k][0]).hypot(x[1] - pred[k][1]);
        from(&q.uv[k]) <= REACH_FACTOR * from(&p.uv[k]) + NOISE_SIGMAS * sd
    })
}

/// The pair `p` with its two frequencies on direction `d` exchanged about
/// their amplitude-weighted mean (the spread about it kept), the other
/// directions' kept: `None` where the directions do not fix a point.
fn mirrored(ctx: &PixelContext, p: &Params, d: usize) -> Option<Params> {
    let axes = &ctx.design.axes;
    let (b0, b1) = (p.amp[0], p.amp[1]);
    if b0 + b1 <= 0.0 {
        return None;
    }
    let mus: Vec<[f64; 2]> = axes
        .iter()
        .map(|ax| [ax.s(p.uv[0][0], p.uv[0][1]), ax.s(p.uv[1][0], p.uv[1][1])])
        .collect();
    let delta = mus[d][0] - mus[d][1];
    let shift = [-2.0 * b1 / (b0 + b1) * delta, 2.0 * b0 / (b0 + b1) * delta];
    let point = |k: usize| {
        let m: Vec<f64> = mus
            .iter()
            .enumerate()
            .map(|(e, m)| if e == d { m[k] + shift[k] } else { m[k] })
            .collect();
        ctx.design.screen_point(&m)
    };
    let mut q = *p;
    q.uv[0] = point(0)?;
    q.uv[1] = point(1)?;
    Some(q)
}

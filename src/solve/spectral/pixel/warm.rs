//! The warm start of a pixel from its neighbour in the camera row: what a
//! pixel hands on ([`Seed`]), the fit started there, and the tests that
//! decide whether it stands or the pixel is searched from the spectrum.

use super::{candidate, Candidate, PixelContext};
use crate::solve::spectral::model::{
    gauss_newton_step, levenberg_marquardt_at, Fit, Normal, Params, Samples,
};
use crate::solve::spectral::PixelResult;

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
    pub(super) unit_sd: Option<(f64, f64, u32)>,
}

impl Seed {
    /// The seed a pixel's two-reflection fit `two` (of `n` samples) hands
    /// on, before it is known to be reported; `None` where the station
    /// predicts no pair there.
    pub(super) fn from_fit(ctx: &PixelContext, two: &Fit, n: usize) -> Option<Seed> {
        let (Ok(f), Ok(b)) = (ctx.prior.front, ctx.prior.back) else {
            return None;
        };
        Some(Seed {
            two: two.params,
            front: [f.u, f.v],
            back: [b.u, b.v],
            sigma2: two.sigma2(n),
            unit_sd: None,
        })
    }

    /// This seed for the next pixel once the pair is reported as `r`
    /// (front first) with the row's separability σ `unit_sd`; `None` unless
    /// both points were found.
    pub(super) fn handed_on(
        mut self,
        r: &PixelResult,
        unit_sd: Option<(f64, f64, u32)>,
    ) -> Option<Seed> {
        (r.model == 2 && r.s[1][0].is_finite()).then_some(())?;
        self.unit_sd = unit_sd;
        let p = self.two;
        let front_first = (p.uv[0][0] - r.s[0][0]).hypot(p.uv[0][1] - r.s[0][1])
            <= (p.uv[1][0] - r.s[0][0]).hypot(p.uv[1][1] - r.s[0][1]);
        if !front_first {
            self.two.uv.swap(0, 1);
            self.two.amp.swap(0, 1);
        }
        Some(self)
    }
}

/// A warm pixel may reuse the separability σ of a pixel at most this many
/// places before it in its row (then it is computed again).
pub(super) const UNIT_SD_REUSE: u32 = 32;

/// The warm path accepts a pixel's fits only if its noise variance is within
/// this factor of the seed's. Adjacent pixels see nearly the same intensity,
/// so their read and shot noise agree to a few percent (the variance
/// estimate itself scatters by √(2/N) ≈ 3 % at N = 2000); a fit in a wrong
/// basin leaves the misfit in its residuals and fails this.
pub(super) const WARM_NOISE_RATIO: f64 = 1.2;

/// A warm pixel's amplitudes and falloff κ must lie within this fraction of
/// its neighbour's (κ may instead lie within [`WARM_KAPPA_SIGMAS`]): they
/// follow the illumination and the optics, smooth across one camera pixel, and a 10σ amplitude carries ≤ 10 % of noise
/// (typically ~1 %). Where they jump, the data do not follow the smooth
/// scene the warm start assumes, and the pixel is searched.
const WARM_CHANGE: f64 = 0.2;

/// A falloff κ the data determine poorly may also differ from the
/// neighbour's by up to this many of its standard deviations: two
/// neighbours' estimates of one smooth κ differ by √2 σ in RMS, so this is
/// a 5 σ difference. On a designed four-direction schedule (three falloff
/// groups, some with few frames where the falloff is deep) the 20 % rule
/// alone sent 19 % of the pixels, well fitted, to the search (bench
/// station, 200 704 pixels): it judged noise as a change of scene.
const WARM_KAPPA_SIGMAS: f64 = 5.0 * std::f64::consts::SQRT_2;

/// Each warm amplitude must exceed this many of its standard deviations.
/// That is far above detection (a periodogram peak [`super::DETECTION_RATIO`]
/// times the median corresponds to ~6σ), so skipping the periodogram skips
/// nothing; and it decides one against two reflections more strictly than
/// the BIC, whose penalty for the second reflection's three parameters,
/// 3 ln N ≈ 23 at N = 2000, is met by a Wald statistic z² = 23 (z ≈ 4.8):
/// where the weaker amplitude is ≥ 10σ, the one-reflection fit is not needed.
pub(super) const WARM_AMPLITUDE_SIGMAS: f64 = 10.0;

/// The warm pair's second Gauss–Newton step is taken without evaluating
/// its end point where it is predicted to lower χ² by less than this: a
/// step of ≤ √0.1 ≈ 0.3σ, which lands to second order in it (the points
/// within 0.03σ of the searched fit's, `tests/it/spectral_sim.rs`); RSS is
/// then the predicted one and JᵀJ the start's, whose σ differs by ≤ 0.7 %
/// there (2 % for steps up to 1σ, hence not more).
pub(super) const ONE_STEP_CHI2: f64 = 0.1;

/// The two-reflection fit started from the neighbour's, or `None` where the
/// pixel must be searched (see [`super::fit_samples_seeded`]).
pub(super) fn warm_fits<S: Samples + ?Sized>(
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
    let (fit, next, remaining, jtr) = gauss_newton_step(data, two)?;
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
        let at = Normal {
            rss: fit.rss,
            jtj: fit.jtj,
            jtr,
        };
        let fit = levenberg_marquardt_at(data, fit.params, at, ctx.max_iter);
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
    let inv = two.inv.as_ref()?;
    let kappas_near = (0..p.kappa.groups).all(|g| {
        let x = p.kappa_index(g);
        let sd = (inv[(x, x)] * sigma2).max(0.0).sqrt();
        near(p.kappa[g], q.kappa[g]) || (p.kappa[g] - q.kappa[g]).abs() <= WARM_KAPPA_SIGMAS * sd
    });
    if !(near(p.amp[0], q.amp[0]) && near(p.amp[1], q.amp[1]) && kappas_near) {
        return None;
    }
    // The weaker amplitude's Wald statistic z = B / σ_B.
    let z = (0..2)
        .map(|k| p.amp[k] / (inv[(1 + k, 1 + k)] * sigma2).max(0.0).sqrt())
        .fold(f64::INFINITY, f64::min);
    (z > WARM_AMPLITUDE_SIGMAS).then_some((two, z * z))
}

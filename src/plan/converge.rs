//! Whether the surface-domain fit ([`crate::solve::direct`]) reaches the
//! truth from its start, the flat plate the station describes. Two
//! checks, both the fit's own iteration on noise-free data: (a) its
//! Gauss–Newton step with halving on one reflection's profiled
//! likelihood along each fringe direction, from every start offset up to
//! the prior's spread ([`basin`], derived below); (b) its per-pixel step
//! itself, both reflections, on sample pixels of the expected plate
//! ([`pixels_converge`]). (a) alone passed the paper's schedule on a 3 mm
//! plate with 1–2.5 µm of defocus, where the fit fails; (b) tells those
//! from the 0.5–0.75 µm plates where it converges (docs/figures.md).
//!
//! **Derivation.** Along one direction a pixel's reflection contributes
//! `B e_f cos(k_f s + φ)` to frame f, `k_f = 2π τ_f`, `e_f = exp(−κ τ_f²)`,
//! s its fringe coordinate (screen px over the axis length). The fit holds
//! s at the current surfaces' prediction `s0 = s_t − δ` and profiles the
//! amplitude: `B̂ = Σ y m / Σ m² = B R(δ)` with
//! `R(δ) = Σ w_f cos(k_f δ) / Σ w_f`, `w_f = e_f²` (the ambiguity function
//! of [`super::ambiguity::ambiguity_at`]), the terms in `cos(k_f(s_t + s0))`
//! averaging out over the pixels (whose s spans many fringes), which the
//! global step sums. The profiled residual is then
//! `RSS(δ) = RSS(0) + ½ B² Σ w (1 − R(δ)²)`, the objective the fit halves
//! its steps on, and its Gauss–Newton step in s (gradient
//! `½ B̂ B Σ w k sin(kδ)` over the Gauss–Newton curvature `½ B̂² Σ w k²`) is
//!
//!   `Δ(δ) = Σ w k sin(kδ) / (R(δ) Σ w k²)`,  `δ ← δ − Δ(δ)`,
//!
//! exactly δ for small δ (one step to the truth), and pointing away from
//! it beyond the main lobe, where R changes sign or rises again (the
//! amplitude fitted to a neighbouring fringe). The global step is the
//! surface solver's least squares over these per-pixel steps, so it moves
//! the surfaces towards the truth when the pixels' steps do, and the fit
//! reaches the truth within its iteration cap when this map, from each
//! pixel's offset, does. A schedule whose information sits at one high τ
//! has a narrow main lobe (its first zero at `1/(4τ)`): a start farther out
//! is pulled to a wrong fringe and the fit stalls there (the A-optimal
//! design of a 3 mm plate did: 914 / 538 nm). Low τ widen the lobe.
//!
//! Converged means within 1 % of the information-weighted fringe period
//! (`|δ| ≤ 0.01/τ_w`, `τ_w² = Σ w τ² / Σ w`), where the phase error
//! `k δ ≤ 0.063` leaves the next step's error at `≈ (kδ)²/6 ≈ 7·10⁻⁴` of
//! δ: the fit's own criterion (steps below 0.05 of the coefficients' σ)
//! is met one iteration later whatever the noise. Hence one iteration of
//! the cap is kept for that.

use serde::Serialize;

use crate::acquire::acquisition::FrameInfo;
use crate::acquire::patterns::FringeAxis;
use crate::optics::station::Station;
use crate::optics::trace::{PixelPaths, TracedView};
use crate::solve::direct::pixel::{linearise, moved, start};
use crate::solve::direct::DirectOptions;
use crate::solve::spectral::model::{Design, RepeatSamples, Repeats, Samples};
use crate::solve::spectral::periodogram::SpectrumPlans;

/// Grid of starts scanned per direction, between 0 and twice the prior's
/// spread: a pixel's offset may be anything up to the spread, and the map
/// may converge from the spread yet not from a smaller offset (a start on
/// a sidelobe's inner flank).
const STARTS: usize = 64;

/// One direction's basin.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DirectionBasin {
    /// The direction, degrees.
    pub direction_deg: f64,
    /// Largest offset from the truth (screen px along the fringe axis) up
    /// to which every start converges within the fit's iteration cap,
    /// scanned up to twice the prior's spread (that value when all do).
    pub basin_px: f64,
}

/// The surface-domain fit's convergence from the flat plate.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Convergence {
    /// Per direction.
    pub directions: Vec<DirectionBasin>,
    /// How far the true points may lie from the nominal-plate prediction, px.
    pub prior_spread_px: f64,
    /// Fraction of the sample pixels whose own iteration, both
    /// reflections, noise-free, reaches their true points from the flat
    /// plate's ([`pixels_converge`]).
    pub pixel_fraction: f64,
    /// Every direction's basin covers the prior's spread and the pixels'
    /// iterations reach the truth on at least [`PIXEL_FRACTION`] of them.
    pub converges: bool,
}

/// Fraction of the sample pixels on which the two-reflection iteration
/// must reach the truth: all of them. A pixel that runs to another fringe
/// or a merged pair hands the surface solver a pseudo-observation off by
/// a fraction of a fringe, Δ ≫ its σ; among N pixels, m such shift the
/// coefficients by ≈ m Δ/(σ √N) of their σ, ≫ 1 for m = 1 at N ~ 10³
/// and Δ/σ ~ 10². Measured (3 mm, n = 1.5, 48×48 bench, the paper's
/// schedule, 15-term truth plus a defocus of both faces, seed 21): 0.75
/// µm of defocus, all sample pixels reach the truth and the fit converges
/// (39.5 / 24.8 nm); 1 µm, 90 % of them and the fit does not (167 / 71
/// nm, not converged); 1.5 µm, 56 % (579 / 305 nm).
pub const PIXEL_FRACTION: f64 = 1.0;

/// The fit's per-pixel iteration ([`crate::solve::direct::pixel`]: the
/// nuisance profiled at the predicted points, the pseudo-observation's
/// step, the nuisance moved with it, a step that raises the RSS halved)
/// on the noise-free series of each of `pixels`, its reflections where
/// `truth` puts them, started where `prior` (the flat plate) puts them:
/// the fraction that ends within `tol_px` of the truth on every
/// coordinate. Unlike [`gauss_newton_converges`] this keeps both
/// reflections, the two directions and the nuisance coupling: where the
/// reflections are a fraction of a bin apart, their difference is
/// determined only through the slow change of the composite fringe's
/// amplitude and phase over τ, and a start whose error in the difference
/// is comparable to the difference itself can run to a merged or swapped
/// pair, which the one-reflection map does not see. The global step is
/// the surface solver's least squares over these per-pixel steps, so the
/// fit reaches the truth when they do on nearly every pixel.
#[allow(clippy::too_many_arguments)]
pub fn pixels_converge(
    design: &Design,
    prior: &TracedView,
    truth: &TracedView,
    pixels: &[usize],
    gain: f64,
    radiometry: &crate::budget::scene::Radiometry,
    opts: &DirectOptions,
    tol_px: f64,
) -> f64 {
    let plans = SpectrumPlans::new(design);
    let repeats = Repeats::new(design);
    let mut ok = 0usize;
    let mut n = 0usize;
    for &q in pixels {
        let Some(hit) = pixel_converges(
            design,
            (&plans, &repeats),
            (&prior.pixels[q], &truth.pixels[q]),
            gain,
            radiometry,
            opts,
            tol_px,
        ) else {
            continue;
        };
        n += 1;
        ok += usize::from(hit);
    }
    if n == 0 {
        1.0
    } else {
        ok as f64 / n as f64
    }
}

fn pixel_converges(
    design: &Design,
    (plans, repeats): (&SpectrumPlans, &Repeats),
    (prior, truth): (&PixelPaths, &PixelPaths),
    gain: f64,
    radiometry: &crate::budget::scene::Radiometry,
    opts: &DirectOptions,
    tol_px: f64,
) -> Option<bool> {
    let t = super::stage::truth_params(design, truth, gain, radiometry);
    let s = super::stage::truth_params(design, prior, gain, radiometry);
    if t.k != s.k || t.k == 0 {
        return None;
    }
    // The noise-free series: one model value per distinct frame, summed
    // over its repeats (the series' least squares; see `RepeatSamples`).
    let means = repeats.model_values(design, &t);
    let y: Vec<f64> = repeats
        .of_frame
        .iter()
        .map(|&g| means[g as usize])
        .collect();
    let samples = RepeatSamples::new(design, plans, repeats, &y, t.kappa);
    let k = t.k;
    let mut s0 = [f64::NAN; 4];
    for j in 0..k {
        s0[2 * j] = s.uv[j][0];
        s0[2 * j + 1] = s.uv[j][1];
    }
    let close = |p: &crate::solve::spectral::model::Params| {
        (0..k).all(|j| (0..2).all(|c| (p.uv[j][c] - t.uv[j][c]).abs() <= tol_px))
    };
    let mut p = start(&samples, k, &s0, t.kappa);
    for _ in 0..opts.max_iter {
        if close(&p) {
            return Some(true);
        }
        // Noise-free: at the truth the RSS is 0 and the linearisation
        // undefined; before it, a singular block means no step.
        let Some(lin) = linearise(&samples, &p) else {
            return Some(close(&p));
        };
        let mut frac = 1.0;
        let mut next = p;
        for h in 0..=opts.max_halvings {
            let mut target = [f64::NAN; 4];
            for (i, t) in target.iter_mut().enumerate().take(2 * k) {
                *t = lin.s0[i] + frac * (lin.s_star[i] - lin.s0[i]);
            }
            next = moved(&p, &lin, &target);
            if h == opts.max_halvings || samples.normal(&next).rss <= lin.rss {
                break;
            }
            frac *= 0.5;
        }
        p = next;
    }
    Some(close(&p))
}

/// The map `δ ← δ − Δ(δ)` of the module's derivation with the fit's step
/// halving (a step that lowers `R²`, i.e. raises the profiled RSS, is
/// halved up to `halvings` times, then taken), iterated `iterations`
/// times from `delta0` (fringe coordinate); whether it ends within
/// `0.01/τ_w` of the truth.
pub fn gauss_newton_converges(
    taus: &[f64],
    kappa: f64,
    delta0: f64,
    iterations: usize,
    halvings: usize,
) -> bool {
    let w: Vec<f64> = taus.iter().map(|t| (-2.0 * kappa * t * t).exp()).collect();
    let k: Vec<f64> = taus.iter().map(|t| std::f64::consts::TAU * t).collect();
    let sw: f64 = w.iter().sum();
    let swk2: f64 = w.iter().zip(&k).map(|(w, k)| w * k * k).sum();
    if !(sw > 0.0 && swk2 > 0.0) {
        return false;
    }
    let tau_w = (swk2 / sw).sqrt() / std::f64::consts::TAU;
    let tol = 0.01 / tau_w;
    let r = |d: f64| {
        w.iter()
            .zip(&k)
            .map(|(w, k)| w * (k * d).cos())
            .sum::<f64>()
            / sw
    };
    let mut d = delta0;
    for _ in 0..iterations {
        if d.abs() <= tol {
            return true;
        }
        let rd = r(d);
        if rd.abs() < 1e-12 {
            return false;
        }
        let g: f64 = w.iter().zip(&k).map(|(w, k)| w * k * (k * d).sin()).sum();
        let step = g / (rd * swk2);
        let mut frac = 1.0;
        for _ in 0..halvings {
            if r(d - frac * step).powi(2) >= rd * rd {
                break;
            }
            frac *= 0.5;
        }
        d -= frac * step;
    }
    d.abs() <= tol
}

/// The largest offset (fringe coordinate) up to which every start on the
/// grid of [`STARTS`] up to `limit` converges: `limit` when all do.
pub fn basin(taus: &[f64], kappa: f64, limit: f64, opts: &DirectOptions) -> f64 {
    // The last iteration is kept for the fit's own criterion (module doc).
    let iterations = opts.max_iter.saturating_sub(1);
    for j in 1..=STARTS {
        let d = limit * j as f64 / STARTS as f64;
        if !gauss_newton_converges(taus, kappa, d, iterations, opts.max_halvings) {
            return limit * (j - 1) as f64 / STARTS as f64;
        }
    }
    limit
}

/// What [`convergence`] is checked on: the schedule's model, the flat
/// plate (the start) and the expected plate (the truth), the sample
/// pixels with both reflections, and the camera's gain and radiometry.
pub struct Scene<'a> {
    /// The schedule's spectral model.
    pub design: &'a Design,
    /// The flat plate traced: the fit's start.
    pub flat: &'a TracedView,
    /// The expected plate traced: the truth.
    pub bent: &'a TracedView,
    /// Sample pixels.
    pub pixels: &'a [usize],
    /// Counts per unit radiance.
    pub gain: f64,
    /// Noise, falloff, ambient.
    pub radiometry: &'a crate::budget::scene::Radiometry,
}

/// The convergence of `frames` on `station` from a start `prior_spread_px`
/// away, with the fit's default iteration cap and halvings: the
/// one-reflection basin per direction ([`basin`]) and the two-reflection
/// iteration on the sample pixels of `scene` ([`pixels_converge`]).
pub fn convergence(
    station: &Station,
    frames: &[FrameInfo],
    scene: &Scene,
    prior_spread_px: f64,
) -> Convergence {
    let opts = DirectOptions::default();
    let kappa = scene.radiometry.tau_max.powi(-2);
    let mut tol_px = f64::INFINITY;
    let directions: Vec<DirectionBasin> = scene
        .design
        .directions_deg
        .iter()
        .map(|&dir| {
            let taus: Vec<f64> = frames
                .iter()
                .filter(|f| f.direction_deg == dir)
                .map(|f| f.tau)
                .collect();
            let (w, h) = (station.screen.width, station.screen.height);
            let axis = FringeAxis::new(dir, w, h);
            // The physical falloff of this direction's fringe length.
            let kappa = axis.physical_kappa(kappa, w, h);
            let limit = 2.0 * prior_spread_px / axis.length_px;
            tol_px = tol_px.min(0.01 * axis.length_px / tau_w(&taus, kappa));
            DirectionBasin {
                direction_deg: dir,
                basin_px: basin(&taus, kappa, limit, &opts) * axis.length_px,
            }
        })
        .collect();
    let pixel_fraction = pixels_converge(
        scene.design,
        scene.flat,
        scene.bent,
        scene.pixels,
        scene.gain,
        scene.radiometry,
        &opts,
        tol_px,
    );
    let converges = directions.iter().all(|d| d.basin_px >= prior_spread_px)
        && pixel_fraction >= PIXEL_FRACTION;
    Convergence {
        directions,
        prior_spread_px,
        pixel_fraction,
        converges,
    }
}

/// The information-weighted τ, `τ_w² = Σ w τ² / Σ w`, `w = exp(−2κτ²)`.
fn tau_w(taus: &[f64], kappa: f64) -> f64 {
    let (a, b) = taus.iter().fold((0.0, 0.0), |(a, b), t| {
        let w = (-2.0 * kappa * t * t).exp();
        (a + w * t * t, b + w)
    });
    (a / b).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_tau_converges_inside_its_quarter_period_only() {
        // One τ, no falloff: R = cos(kδ), Δ = tan(kδ)/k. Inside half the
        // quarter period (kδ = π/4: tan = 1) one step lands at
        // kδ' = π/4 − 1, then the map's cubic contraction (x − tan x ≈
        // −x³/3) finishes; beyond the quarter period 1/(4τ) R < 0 and the
        // step points to the next fringe.
        let taus = [100.0; 10];
        let o = DirectOptions::default();
        assert!(gauss_newton_converges(
            &taus,
            0.0,
            0.5 / 400.0,
            o.max_iter,
            o.max_halvings
        ));
        assert!(!gauss_newton_converges(
            &taus,
            0.0,
            1.2 / 400.0,
            o.max_iter,
            o.max_halvings
        ));
    }

    #[test]
    fn low_tau_widen_the_basin() {
        // A high ladder (τ 90…129) alone: R crosses 0 near 1/(4 · 110) =
        // 0.0023, where the profiled amplitude changes sign; from within
        // a quarter of that the first step (∝ 1/R) overshoots to another
        // fringe, so the basin ends near 0.0017 (measured). With a low
        // ladder (τ 1…40) of equal count added R stays positive, and the
        // basin ends only where the step's numerator Σ w k sin(kδ), which
        // the high τ dominate (k² weights), changes sign: near their half
        // period 1/(2 · 110) = 0.0045. Low τ widen the basin, by at most
        // about 2 here: they cannot undo what the high τ's gradient says.
        let o = DirectOptions::default();
        let high: Vec<f64> = (0..40).map(|k| 90.0 + k as f64).collect();
        let mut mixed = high.clone();
        mixed.extend((1..=40).map(|k| k as f64));
        // Scanned to 0.01 in 64 steps: 1.6·10⁻⁴ resolution.
        let a = basin(&high, 0.0, 0.01, &o);
        let b = basin(&mixed, 0.0, 0.01, &o);
        assert!((0.0012..0.0025).contains(&a), "{a}");
        assert!(b > 1.5 * a && b < 0.0047, "{a} {b}");
    }
}

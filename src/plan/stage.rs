//! What the spectral stage itself does with a schedule: its own per-pixel
//! search and fit ([`fit_samples_seeded`], the series or statistics engine
//! the stage would pick, the statistics' band around the station's
//! prediction) run on simulated samples of pixels spread over the sensor,
//! at the planned noise, with the true points where the expected surfaces
//! put them. The planner's measurability constraint is this, not a
//! stand-in: a schedule is measurable when the stage finds the true points
//! on the sample pixels, and an alias outside the range the stage searches
//! cannot be chosen by it, so it costs the design nothing.
//!
//! Why run the stage rather than a criterion on the schedule's spectral
//! window: the stage's start is a Hann-windowed periodogram (over the τ
//! ranks of one phase with the series engine, over τ within the band with
//! the statistics engine), its detection ratio, a pair scan along each
//! direction, a Levenberg–Marquardt fit and the 5σ resolution test; any
//! closed-form stand-in for that chain (the information-weighted
//! ambiguity function of [`super::ambiguity`]) is either stricter than the
//! stage (it forbade designs the stage measures) or looser (a 200-frame
//! design it passed measured nothing, the detection failing in noise).

use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use serde::Serialize;

use crate::optics::trace::{PixelPaths, TracedView};
use crate::solve::spectral::model::{Design, Params, SeriesSamples, MAX_PARAMS, MAX_REFLECTIONS};
use crate::solve::spectral::periodogram::SpectrumPlans;
use crate::solve::spectral::pixel::{fit_samples_seeded, PixelContext, PixelFits};
use crate::solve::spectral::statistics::{Statistics, STATS_BLOCK};
use crate::solve::spectral::{Engine, SpectralConfig, SERIES_LIMIT_BYTES};

use super::PlanOptions;

/// Fraction of the sample pixels on which the stage must find the true
/// points for the schedule to count as measurable: nine in ten, the
/// separability rule's [`super::predict::SEPARABLE_FRACTION`] (a tenth
/// lost costs √(10/9) − 1 = 5 % of the bound at most, most of them lost
/// leave nothing).
pub const STAGE_FRACTION: f64 = 0.9;

/// A found point is the true one when every coordinate lies within this
/// many of its reported σ: a Gaussian error passes 6σ on all four
/// coordinates except with probability 4 × 2 × 10⁻⁹, while a wrong fringe
/// or alias is off by a fringe period, hundreds of σ.
pub const FOUND_SIGMAS: f64 = 6.0;

/// The stage run on sample pixels.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StageCheck {
    /// The engine the stage picks for this schedule on this station.
    pub engine: &'static str,
    /// Sample pixels fitted.
    pub pixels: usize,
    /// Fraction of them whose fit found every present reflection at its
    /// true point (within [`FOUND_SIGMAS`] of its reported σ).
    pub found_fraction: f64,
    /// Fraction whose periodogram detected no signal in some direction.
    pub no_signal_fraction: f64,
    /// At least [`STAGE_FRACTION`] found.
    pub measurable: bool,
}

/// The spectral model's parameters of a pixel whose paths are `truth`
/// (the reflections with a weight), at the camera gain `gain` and the
/// radiometry `r`, with `design`'s falloff groups at the physical falloff
/// ([`Design::physical_falloff`], τ_max the diagonals'): the simulator's
/// intensities as the fits see them.
pub(super) fn truth_params(
    design: &Design,
    truth: &PixelPaths,
    gain: f64,
    r: &crate::budget::scene::Radiometry,
) -> Params {
    let hits: Vec<_> = [truth.front, truth.back]
        .into_iter()
        .filter_map(|h| h.ok().filter(|h| h.weight > 0.0))
        .collect();
    let mut p = Params {
        k: hits.len(),
        offset: gain * (r.ambient + 0.5 * hits.iter().map(|h| h.weight).sum::<f64>()),
        amp: [0.0; MAX_REFLECTIONS],
        uv: [[0.0; 2]; MAX_REFLECTIONS],
        kappa: design.physical_falloff(r.tau_max.powi(-2)),
    };
    for (j, h) in hits.iter().enumerate() {
        p.amp[j] = 0.5 * gain * h.weight;
        p.uv[j] = [h.u, h.v];
    }
    p
}

/// The candidates the stage fits (the count decides the engine): the
/// spectral stage's own candidate mask.
fn candidate_count(prior: &TracedView, margin: i64) -> usize {
    crate::solve::spectral::prior_candidates(prior, margin).len()
}

/// Whether the stage keeps statistics for `frames` frames on `prior`
/// (the rule of `SpectralSolver`: the series above [`SERIES_LIMIT_BYTES`]).
pub fn uses_statistics(prior: &TracedView, frames: usize, config: &SpectralConfig) -> bool {
    match config.engine {
        Engine::Series => false,
        Engine::Statistics => true,
        Engine::Auto => {
            candidate_count(prior, i64::from(config.margin_px)) * frames * 2 > SERIES_LIMIT_BYTES
        }
    }
}

/// The statistics engine's band: per direction, each pixel's centre (the
/// middle of its predicted points) and the half-width, half the widest
/// predicted spread over the prior plus `band_bins` bins (what
/// `spectral::prior::band_centres` computes for the stage).
fn band(
    design: &Design,
    prior: &TracedView,
    pixels: &[usize],
    config: &SpectralConfig,
    plans: &SpectrumPlans,
) -> (Vec<Vec<f64>>, Vec<f64>) {
    let points = |p: &PixelPaths| -> Vec<[f64; 2]> {
        [p.front, p.back]
            .iter()
            .filter_map(|h| h.ok().map(|h| [h.u, h.v]))
            .collect()
    };
    let span = |pts: &[[f64; 2]], d: usize| {
        let ax = design.axes[d];
        pts.iter()
            .map(|p| ax.s(p[0], p[1]))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), m| {
                (a.min(m), b.max(m))
            })
    };
    let nd = design.axes.len();
    let mut half = vec![0.0f64; nd];
    for p in &prior.pixels {
        let pts = points(p);
        if pts.is_empty() {
            continue;
        }
        for (d, h) in half.iter_mut().enumerate() {
            let (lo, hi) = span(&pts, d);
            *h = h.max(0.5 * (hi - lo));
        }
    }
    let centres = (0..nd)
        .map(|d| {
            pixels
                .iter()
                .map(|&q| {
                    let (lo, hi) = span(&points(&prior.pixels[q]), d);
                    0.5 * (lo + hi)
                })
                .collect()
        })
        .collect();
    let band = (0..nd)
        .map(|d| half[d] + config.band_bins * plans.bin(d))
        .collect();
    (centres, band)
}

/// One pixel's noisy series under `design`: the truth's reflections
/// `truth` with the radiometry of `opts` (counts, rounded, within the
/// camera's range as the simulator writes them).
fn series(
    design: &Design,
    truth: &PixelPaths,
    gain: f64,
    opts: &PlanOptions,
    rng: &mut rand_xoshiro::Xoshiro256PlusPlus,
) -> Vec<u16> {
    let r = &opts.radiometry;
    let p = truth_params(design, truth, gain, r);
    let full = f64::from((1u32 << r.bit_depth.min(16)) - 1);
    let sigma = r.sigma_counts();
    let mut row = [0.0; MAX_PARAMS];
    design
        .frames
        .iter()
        .map(|f| {
            let mean = crate::solve::spectral::model::eval_row(design, f, &p, &mut row);
            let z: f64 = StandardNormal.sample(rng);
            (mean + sigma * z).round().clamp(0.0, full) as u16
        })
        .collect()
}

/// Whether `fits` (one pixel) found every reflection of `truth` at its
/// true point, under the scene's model (`two`: the pair, else one).
fn found(fits: &PixelFits, truth: &PixelPaths, two: bool) -> bool {
    let Some(scored) = fits.per_model[usize::from(two)] else {
        return false;
    };
    let r = scored.result;
    let want: Vec<(usize, [f64; 2])> = [truth.front, truth.back]
        .iter()
        .enumerate()
        .filter_map(|(k, h)| h.ok().filter(|h| h.weight > 0.0).map(|h| (k, [h.u, h.v])))
        .collect();
    want.iter().all(|&(k, t)| {
        (0..2).all(|c| {
            let e = (r.s[k][c] - t[c]).abs();
            e.is_finite() && e <= FOUND_SIGMAS * r.std[k][c]
        })
    })
}

/// Runs the stage on `pixels` of `prior` (the station's flat-plate
/// prediction, as the stage holds it) with their true points from `truth`
/// (the expected surfaces), one noise draw each from `seed`.
pub fn stage_check(
    design: &Design,
    prior: &TracedView,
    truth: &TracedView,
    pixels: &[usize],
    gain: f64,
    opts: &PlanOptions,
    seed: u64,
) -> StageCheck {
    let config = &opts.spectral;
    let plans = SpectrumPlans::new(design);
    let kappa0 = config
        .tau_max_guess
        .unwrap_or_else(|| design.frames.iter().map(|f| f.tau).fold(0.0, f64::max))
        .powi(-2);
    let two = truth
        .pixels
        .iter()
        .any(|p| p.back.is_ok_and(|h| h.weight > 0.0));
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(seed);
    let ys: Vec<Vec<u16>> = pixels
        .iter()
        .map(|&q| series(design, &truth.pixels[q], gain, opts, &mut rng))
        .collect();
    let statistics = uses_statistics(prior, design.frames.len(), config);
    let stats = statistics
        .then(|| {
            let (centres, band) = band(design, prior, pixels, config, &plans);
            let mut s = Statistics::new(
                design,
                &centres,
                &band,
                [-kappa0, 16.0 * kappa0],
                config.saturation_counts,
            )
            .ok()?;
            let n = design.frames.len();
            let mut first = 0;
            while first < n {
                let rows = STATS_BLOCK.min(n - first);
                let mut block = Vec::with_capacity(rows * ys.len());
                for r in 0..rows {
                    block.extend(ys.iter().map(|y| y[first + r]));
                }
                s.ingest(first, rows, &block);
                first += rows;
            }
            s.seal();
            Some(s)
        })
        .flatten();
    let full = ((1u32 << opts.radiometry.bit_depth.min(16)) - 1) as u16;
    let sat = config.saturation_counts.unwrap_or(full);
    let falloff0 = design.uniform_falloff(kappa0);
    // Each pixel's fit on its own series (drawn above, in order, from one
    // generator): independent, so on every core; the counts are sums.
    let (ok, silent) = pixels
        .par_iter()
        .enumerate()
        .map(|(i, &q)| {
            let ctx = PixelContext {
                design,
                plans: &plans,
                prior: &prior.pixels[q],
                borrowed_offset: None,
                kappa0: falloff0,
                allow_third: false,
                max_iter: config.max_iter,
            };
            let mut fits = PixelFits::none();
            if statistics {
                match stats.as_ref().and_then(|s| s.samples(design, i, Some(sat))) {
                    Some((data, excluded)) => {
                        fit_samples_seeded(&ctx, &data, excluded, None, &mut fits);
                    }
                    None => return (0, 0),
                }
            } else {
                let y: Vec<f64> = ys[i]
                    .iter()
                    .map(|&v| {
                        if v == 0 || v >= sat {
                            f64::NAN
                        } else {
                            f64::from(v)
                        }
                    })
                    .collect();
                let excluded = y.iter().filter(|v| v.is_nan()).count();
                let data = SeriesSamples::new(design, &plans, &y, falloff0);
                fit_samples_seeded(&ctx, &data, excluded, None, &mut fits);
            }
            (
                usize::from(found(&fits, &truth.pixels[q], two)),
                usize::from(
                    fits.base
                        .flags
                        .contains(crate::solve::spectral::PixelFlags::NO_SIGNAL),
                ),
            )
        })
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    let n = pixels.len().max(1) as f64;
    let found_fraction = ok as f64 / n;
    StageCheck {
        engine: if statistics { "statistics" } else { "series" },
        pixels: pixels.len(),
        found_fraction,
        no_signal_fraction: silent as f64 / n,
        measurable: !pixels.is_empty() && found_fraction >= STAGE_FRACTION,
    }
}

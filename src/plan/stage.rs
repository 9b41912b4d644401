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
use crate::solve::spectral::model::{
    Design, Falloff, Params, RepeatSamples, Repeats, Samples, MAX_REFLECTIONS,
};
use crate::solve::spectral::periodogram::SpectrumPlans;
use crate::solve::spectral::pixel::{fit_samples_seeded, PixelContext, PixelFits, Seed};
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
    /// The fraction the stage reaches along camera rows, where each pixel
    /// starts from its left neighbour's fit and is searched where that
    /// fails: `s / (1 − w + s)`, the steady state of a row, with `s` the
    /// searched [`Self::found_fraction`] and `w` the fraction found among
    /// the right neighbours of found sample pixels, each started from its
    /// neighbour's fit. The measurability rule keeps to the searched
    /// fraction (the rows' start and a row after a loss are searched).
    /// `None` where not asked for (the design's candidates: it would
    /// double their fits for a figure nothing decides on).
    pub found_fraction_in_rows: Option<f64>,
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

/// One pixel's noisy series under `design` (whose distinct frames are
/// `repeats`): the truth's reflections `truth` with the radiometry of
/// `opts` (counts, rounded, within the camera's range as the simulator
/// writes them), one draw per frame. The model's value is a function of
/// the frame's direction, τ and phase alone, so it is evaluated once per
/// distinct frame (the same bits).
fn series(
    design: &Design,
    repeats: &Repeats,
    truth: &PixelPaths,
    gain: f64,
    opts: &PlanOptions,
    rng: &mut rand_xoshiro::Xoshiro256PlusPlus,
) -> Vec<u16> {
    let r = &opts.radiometry;
    let p = truth_params(design, truth, gain, r);
    let full = f64::from((1u32 << r.bit_depth.min(16)) - 1);
    let sigma = r.sigma_counts();
    let means = repeats.model_values(design, &p);
    repeats
        .of_frame
        .iter()
        .map(|&g| {
            let mean = means[g as usize];
            let z: f64 = StandardNormal.sample(rng);
            (mean + sigma * z).round().clamp(0.0, full) as u16
        })
        .collect()
}

/// Whether `fits` (one pixel) found every reflection of `truth` at its
/// true point, under the scene's model (`two`: the pair, else one).
fn found(fits: &PixelFits, truth: &PixelPaths, two: bool) -> bool {
    let Some(scored) = fits.model(usize::from(two)) else {
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

/// The statistics engine's sums of the series `ys` (one per pixel of
/// `pixels`, in order) over its band around `prior`'s prediction, sealed;
/// `None` where the band cannot be held.
fn statistics_of(
    design: &Design,
    prior: &TracedView,
    pixels: &[usize],
    config: &SpectralConfig,
    plans: &SpectrumPlans,
    kappa0: f64,
    ys: &[Vec<u16>],
) -> Option<Statistics> {
    let (centres, band) = band(design, prior, pixels, config, plans);
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
}

/// What every sample pixel's fit shares: the schedule, its periodogram
/// plans and distinct frames, the views, and the stage's settings.
struct Judge<'a> {
    design: &'a Design,
    plans: SpectrumPlans,
    repeats: Repeats,
    prior: &'a TracedView,
    truth: &'a TracedView,
    /// Whether the scene has two reflections (the model judged).
    two: bool,
    /// Samples at 0 or at/above this are excluded (clipped).
    sat: u16,
    falloff0: Falloff,
    max_iter: usize,
}

/// One sample pixel's fit as the stage check counts it.
struct Judged {
    found: bool,
    no_signal: bool,
    /// What the fit hands its right neighbour (a pair found and reported).
    seed: Option<Seed>,
}

impl Judge<'_> {
    /// Pixel `q`'s fit on `data` (`excluded` samples clipped), started
    /// from `seed` where given.
    fn fit<S: Samples>(&self, q: usize, data: &S, excluded: usize, seed: Option<&Seed>) -> Judged {
        let ctx = PixelContext {
            design: self.design,
            plans: &self.plans,
            prior: &self.prior.pixels[q],
            borrowed_offset: None,
            kappa0: self.falloff0,
            allow_third: false,
            max_iter: self.max_iter,
        };
        let mut fits = PixelFits::none();
        let next = fit_samples_seeded(&ctx, data, excluded, seed, &mut fits);
        Judged {
            found: found(&fits, &self.truth.pixels[q], self.two),
            no_signal: fits
                .flags
                .contains(crate::solve::spectral::PixelFlags::NO_SIGNAL),
            seed: next,
        }
    }

    /// Pixel `q`'s fit on its series `raw`, summed over the repeated
    /// frames (the same least squares at a cost in distinct frames).
    fn fit_series(&self, q: usize, raw: &[u16], seed: Option<&Seed>) -> Judged {
        let y: Vec<f64> = raw
            .iter()
            .map(|&v| {
                if v == 0 || v >= self.sat {
                    f64::NAN
                } else {
                    f64::from(v)
                }
            })
            .collect();
        let excluded = y.iter().filter(|v| v.is_nan()).count();
        let data = RepeatSamples::new(self.design, &self.plans, &self.repeats, &y, self.falloff0);
        self.fit(q, &data, excluded, seed)
    }

    /// Every pixel of `pixels` fitted on its series `ys[i]`, started from
    /// `seeds[i]` where given, on every core: with the statistics engine
    /// on their statistics, else on the series.
    fn fit_all(
        &self,
        pixels: &[usize],
        ys: &[Vec<u16>],
        seeds: &[Option<Seed>],
        statistics: Option<(&SpectralConfig, f64)>,
    ) -> Vec<Judged> {
        let blank = || Judged {
            found: false,
            no_signal: false,
            seed: None,
        };
        let Some((config, kappa0)) = statistics else {
            return (0..pixels.len())
                .into_par_iter()
                .map(|i| self.fit_series(pixels[i], &ys[i], seeds[i].as_ref()))
                .collect();
        };
        let design = self.design;
        let stats = statistics_of(design, self.prior, pixels, config, &self.plans, kappa0, ys);
        (0..pixels.len())
            .into_par_iter()
            .map(|i| {
                match stats
                    .as_ref()
                    .and_then(|s| s.samples(design, i, Some(self.sat)))
                {
                    Some((data, excluded)) => {
                        self.fit(pixels[i], &data, excluded, seeds[i].as_ref())
                    }
                    None => blank(),
                }
            })
            .collect()
    }
}

/// Runs the stage on `pixels` of `prior` (the station's flat-plate
/// prediction, as the stage holds it) with their true points from `truth`
/// (the expected surfaces), one noise draw each from `seed`; with `rows`,
/// also on the found pixels' right neighbours
/// ([`StageCheck::found_fraction_in_rows`]).
pub fn stage_check(
    design: &Design,
    prior: &TracedView,
    truth: &TracedView,
    pixels: &[usize],
    gain: f64,
    opts: &PlanOptions,
    seed: u64,
    rows: bool,
) -> StageCheck {
    let config = &opts.spectral;
    let kappa0 = config
        .tau_max_guess
        .unwrap_or_else(|| design.frames.iter().map(|f| f.tau).fold(0.0, f64::max))
        .powi(-2);
    let full = ((1u32 << opts.radiometry.bit_depth.min(16)) - 1) as u16;
    let judge = Judge {
        design,
        plans: SpectrumPlans::new(design),
        repeats: Repeats::new(design),
        prior,
        truth,
        two: truth
            .pixels
            .iter()
            .any(|p| p.back.is_ok_and(|h| h.weight > 0.0)),
        sat: config.saturation_counts.unwrap_or(full),
        falloff0: design.uniform_falloff(kappa0),
        max_iter: config.max_iter,
    };
    // One generator, one pixel after another: every pixel's draws are
    // those of this order, whatever runs when.
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut draw = |q: usize| {
        series(
            design,
            &judge.repeats,
            &truth.pixels[q],
            gain,
            opts,
            &mut rng,
        )
    };
    let statistics = uses_statistics(prior, design.frames.len(), config);
    let engine = statistics.then_some((config, kappa0));
    // The sample pixels' draws first, in order, then their neighbours'.
    let ys: Vec<Vec<u16>> = pixels.iter().map(|&q| draw(q)).collect();
    let fits = judge.fit_all(pixels, &ys, &vec![None; pixels.len()], engine);
    let ok = fits.iter().filter(|f| f.found).count();
    let silent = fits.iter().filter(|f| f.no_signal).count();
    // Each found sample pixel's right neighbour in its camera row, started
    // from its fit as the stage's row does.
    let width = prior.width;
    let n = pixels.len().max(1) as f64;
    let s = ok as f64 / n;
    let found_fraction_in_rows = rows.then(|| {
        let (next, seeds): (Vec<usize>, Vec<Option<Seed>>) = pixels
            .iter()
            .zip(&fits)
            .filter(|(&q, f)| {
                f.found
                    && f.seed.is_some()
                    && (q + 1) % width != 0
                    && prior.pixels.get(q + 1).is_some_and(|p| p.front.is_ok())
            })
            .map(|(&q, f)| (q + 1, f.seed))
            .unzip();
        let ys: Vec<Vec<u16>> = next.iter().map(|&q| draw(q)).collect();
        let warm = judge.fit_all(&next, &ys, &seeds, engine);
        if next.is_empty() || s == 0.0 {
            s
        } else {
            let w = warm.iter().filter(|f| f.found).count() as f64 / next.len() as f64;
            s / (1.0 - w + s)
        }
    });
    let found_fraction = s;
    StageCheck {
        engine: if statistics { "statistics" } else { "series" },
        pixels: pixels.len(),
        found_fraction,
        found_fraction_in_rows,
        no_signal_fraction: silent as f64 / n,
        measurable: !pixels.is_empty() && found_fraction >= STAGE_FRACTION,
    }
}

//! The per-pixel fits of one acquisition as a batch ([`FitBatch`]), and
//! where they run ([`FitBackend`]): on all CPU cores ([`CpuFits`]), or on
//! any data-parallel device that keeps the seam's contract.

use rayon::prelude::*;

use super::model::{Design, Falloff, SeriesSamples};
use super::periodogram::SpectrumPlans;
use super::pixel::{fit_samples_seeded, PixelContext, PixelFits, Seed};
use super::prior::GeometryPrior;
use super::statistics::{prefetch_lines, Statistics};
use super::PixelFlags;
use crate::optics::trace::TracedView;

/// How the fits of a batch are run: the settings they share.
#[derive(Debug, Clone, Copy)]
pub(super) struct FitSettings {
    /// Samples at or above this count (and at 0) are excluded.
    pub(super) saturation: Option<u16>,
    /// Starting κ = 1/τ_max², per falloff group.
    pub(super) kappa0: Falloff,
    /// Whether a third reflection may be modelled.
    pub(super) allow_third: bool,
    /// Levenberg–Marquardt iteration cap.
    pub(super) max_iter: usize,
    /// Whether a pixel's fits start from its left neighbour's.
    pub(super) warm_starts: bool,
}

/// Everything the per-pixel fits of one acquisition need: the schedule, the
/// geometry prior and either the series of the candidate pixels,
/// pixel-major (the `frames` samples of candidate q at
/// `series[q * frames..]`, raw counts), or their statistics (with the
/// statistics engine; the series is then empty).
pub struct FitBatch<'a> {
    design: &'a Design,
    plans: &'a SpectrumPlans,
    prior: &'a GeometryPrior,
    series: &'a [u16],
    stats: Option<&'a Statistics>,
    settings: FitSettings,
    /// The output array prepared during the stream ([`Self::output`]).
    output: Option<Vec<PixelFits>>,
}

impl<'a> FitBatch<'a> {
    /// The batch over `prior`'s candidates, their `series` or `stats`,
    /// writing into `output` (one [`PixelFits::none`] per candidate) when
    /// one was prepared.
    pub(super) fn new(
        design: &'a Design,
        plans: &'a SpectrumPlans,
        prior: &'a GeometryPrior,
        (series, stats): (&'a [u16], Option<&'a Statistics>),
        settings: FitSettings,
        output: Option<Vec<PixelFits>>,
    ) -> Self {
        FitBatch {
            design,
            plans,
            prior,
            series,
            stats,
            settings,
            output,
        }
    }

    /// The schedule.
    pub fn design(&self) -> &'a Design {
        self.design
    }

    /// Periodogram plans.
    pub fn plans(&self) -> &'a SpectrumPlans {
        self.plans
    }

    /// The nominal-plate prediction of every camera pixel.
    pub fn prior(&self) -> &'a TracedView {
        &self.prior.view
    }

    /// Camera pixel index of each candidate, row-major.
    pub fn candidates(&self) -> &'a [u32] {
        &self.prior.candidates
    }

    /// Per candidate, the back-minus-front offset borrowed at the rim.
    pub fn borrowed(&self) -> &'a [Option<[f64; 2]>] {
        &self.prior.borrowed
    }

    /// The series, pixel-major (empty with the statistics engine).
    pub fn series(&self) -> &'a [u16] {
        self.series
    }

    /// The statistics, with the statistics engine.
    pub fn stats(&self) -> Option<&'a Statistics> {
        self.stats
    }

    /// Samples at or above this count (and at 0) are excluded.
    pub fn saturation(&self) -> Option<u16> {
        self.settings.saturation
    }

    /// Starting κ = 1/τ_max², per falloff group.
    pub fn kappa0(&self) -> Falloff {
        self.settings.kappa0
    }

    /// Whether a third reflection may be modelled.
    pub fn allow_third(&self) -> bool {
        self.settings.allow_third
    }

    /// Levenberg–Marquardt iteration cap.
    pub fn max_iter(&self) -> usize {
        self.settings.max_iter
    }

    /// Whether a pixel's fits start from its left neighbour's ([`Self::fit_run`]).
    pub fn warm_starts(&self) -> bool {
        self.settings.warm_starts
    }

    /// Frames per series.
    pub fn frames(&self) -> usize {
        self.design.frames.len()
    }

    /// One [`PixelFits::none`] per candidate, for a backend to write its
    /// results into: the array the solver prepared (memory already touched)
    /// while the frames streamed in, on the first call; a new one after.
    pub fn output(&mut self) -> Vec<PixelFits> {
        let n = self.prior.candidates.len();
        if let Some(v) = self.output.take() {
            if v.len() == n {
                return v;
            }
        }
        let mut out = Vec::with_capacity(n);
        out.par_extend(rayon::iter::repeat_n(PixelFits::none(), n));
        out
    }

    /// The candidates in runs of camera-row neighbours, in order: the units
    /// of work ([`Self::fit_run`]).
    pub fn runs(&self) -> Vec<std::ops::Range<usize>> {
        let w = self.prior.view.width as u32;
        let candidates = &self.prior.candidates;
        let mut runs = Vec::new();
        let mut from = 0;
        for q in 1..=candidates.len() {
            let adjacent = q < candidates.len() && {
                let (a, b) = (candidates[q - 1], candidates[q]);
                b == a + 1 && b % w != 0
            };
            if !adjacent {
                runs.push(from..q);
                from = q;
            }
        }
        runs
    }

    /// The candidates of `run` (one of [`Self::runs`]) fitted in order, each
    /// started from the fits of the one before where those found both
    /// points and warm starts are on, else searched from its spectrum.
    pub fn fit_run(&self, run: std::ops::Range<usize>) -> Vec<PixelFits> {
        let mut out = vec![PixelFits::none(); run.len()];
        self.fit_run_into(run, &mut out);
        out
    }

    /// [`Self::fit_run`] written into `out` (one slot per candidate of `run`).
    fn fit_run_into(&self, run: std::ops::Range<usize>, out: &mut [PixelFits]) {
        let mut seed = None;
        let end = run.end;
        let warm = self.settings.warm_starts;
        for (i, q) in run.enumerate() {
            // The next pixel's statistics and result slot, read and written
            // once each from memory, are fetched while this one is fitted.
            if q + 1 < end {
                if let Some(stats) = self.stats {
                    stats.prefetch(q + 1);
                }
                prefetch_lines(std::slice::from_ref(&out[i + 1]));
            }
            seed = self.fit_seeded(q, seed.as_ref().filter(|_| warm), &mut out[i]);
        }
    }

    /// Candidate `q` fitted into `out`, from `seed` when given; returns the
    /// seed for its right neighbour.
    fn fit_seeded(&self, q: usize, seed: Option<&Seed>, out: &mut PixelFits) -> Option<Seed> {
        let s = &self.settings;
        let ctx = PixelContext {
            design: self.design,
            plans: self.plans,
            prior: &self.prior.view.pixels[self.prior.candidates[q] as usize],
            borrowed_offset: self.prior.borrowed[q],
            kappa0: s.kappa0,
            allow_third: s.allow_third,
            max_iter: s.max_iter,
        };
        if let Some(stats) = self.stats {
            return match stats.samples(self.design, q, s.saturation) {
                Some((data, excluded)) => fit_samples_seeded(&ctx, &data, excluded, seed, out),
                None => {
                    *out = PixelFits::none();
                    out.flags = PixelFlags::SATURATED | PixelFlags::NO_DATA;
                    None
                }
            };
        }
        let n = self.frames();
        let raw = &self.series[q * n..(q + 1) * n];
        let mut excluded = 0;
        let y: Vec<f64> = raw
            .iter()
            .map(|&v| {
                if v == 0 || s.saturation.is_some_and(|sat| v >= sat) {
                    excluded += 1;
                    f64::NAN
                } else {
                    f64::from(v)
                }
            })
            .collect();
        let data = SeriesSamples::new(ctx.design, ctx.plans, &y, ctx.kappa0);
        fit_samples_seeded(&ctx, &data, excluded, seed, out)
    }
}

/// Where the per-pixel fits run. The runs of row neighbours are independent
/// (within a run, a pixel starts from the one before), so the batch can go to
/// any data-parallel device: this is the seam for a GPU (wgpu compute)
/// backend, which must return one [`PixelFits`] per candidate, in order,
/// matching [`FitBatch::fit_run`] over [`FitBatch::runs`], and may write
/// them into [`FitBatch::output`] (the batch hands that array over once,
/// hence `&mut`). [`CpuFits`] is the path CI tests.
pub trait FitBackend: Sync {
    /// Fits every candidate of `batch`.
    fn fit(&self, batch: &mut FitBatch) -> Vec<PixelFits>;
}

/// The per-pixel fits on all CPU cores (rayon).
#[derive(Debug, Clone, Copy, Default)]
pub struct CpuFits;

impl FitBackend for CpuFits {
    fn fit(&self, batch: &mut FitBatch) -> Vec<PixelFits> {
        // Written in place, run by run: the results of a full sensor are
        // ~0.4 GB, too much to hold twice.
        let mut out = batch.output();
        let batch = &*batch;
        let mut parts = Vec::new();
        let mut rest = out.as_mut_slice();
        for r in batch.runs() {
            let (part, tail) = rest.split_at_mut(r.len());
            parts.push((r, part));
            rest = tail;
        }
        parts.into_par_iter().for_each(|(r, part)| {
            batch.fit_run_into(r, part);
        });
        out
    }
}

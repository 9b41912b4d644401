//! The solver's driver: frames arrive in capture order, the samples of the
//! pixels that can see the element are kept (pixel-major, 2 bytes each),
//! and every pixel is fitted on all cores once its series is complete.

use std::path::Path;
use std::sync::Mutex;
use std::thread::JoinHandle;

use rayon::prelude::*;

use super::compact::{prefetch_lines, CompactStats, FULL_SCALES, STATS_BLOCK};
use super::init::SpectrumPlans;
use super::model::SeriesSamples;
use super::model::{Axis, Design, FrameMeta};
use super::pixel::{fit_samples_seeded, PixelContext, PixelFits, Scored, Seed};
use super::{flags, PixelResult};
use crate::acquire::acquisition::FrameInfo;
use crate::acquire::patterns::FringeAxis;
use crate::formats::npy::{self, NpyError};
use crate::optics::station::Station;
use crate::optics::trace::{Plate, TracedView, DEFAULT_EDGE_MARGIN_MM};
use crate::optics::zernike::ZernikeSurface;

/// Frames buffered frame-major before they are transposed into the
/// pixel-major series (keeps the scatter cache-friendly).
const BLOCK: usize = 32;

/// What can go wrong in the spectral stage.
#[derive(Debug, thiserror::Error)]
pub enum SpectralError {
    /// The schedule cannot locate screen points.
    #[error("schedule: {problem}")]
    Schedule {
        /// What is wrong.
        problem: String,
    },
    /// A setting is out of range.
    #[error("spectral setting {field}: {problem}")]
    Config {
        /// The setting.
        field: &'static str,
        /// What is wrong.
        problem: String,
    },
    /// A fit backend broke its contract.
    #[error("fit backend: {problem}")]
    Backend {
        /// What it did.
        problem: String,
    },
    /// A frame does not fit the acquisition.
    #[error("frame {frame}: {problem}")]
    Frame {
        /// Frame index.
        frame: usize,
        /// What is wrong.
        problem: String,
    },
    /// Writing a map failed.
    #[error(transparent)]
    Npy(#[from] NpyError),
}

/// How the solver keeps the pixels' data between frames and fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Engine {
    /// Statistics when the series would exceed [`SERIES_LIMIT_BYTES`], else series.
    #[default]
    Auto,
    /// Every sample (2 bytes per pixel and frame); fits anywhere on the screen.
    Series,
    /// Per-pixel sufficient statistics ([`super::compact`]): fixed memory per
    /// pixel, fits within a band around the station's prediction.
    Statistics,
}

/// Above this size of the series, [`Engine::Auto`] keeps statistics.
pub const SERIES_LIMIT_BYTES: usize = 1 << 31;

/// Settings of the spectral stage.
#[derive(Debug, Clone, PartialEq)]
pub struct SpectralConfig {
    /// Series or statistics.
    pub engine: Engine,
    /// Statistics engine: how far (Fourier bins) beyond the predicted points
    /// the band of kept screen positions reaches, per direction.
    pub band_bins: f64,
    /// Starting τ_max of the modulation falloff; `None`: the schedule's largest τ.
    pub tau_max_guess: Option<f64>,
    /// Allow a third reflection (second internal round trip).
    pub third_reflection: bool,
    /// Samples at or above this count are excluded; `None`: the largest count
    /// seen, when it is a full scale 2^b − 1 (b = 8, 10, 12, 14, 16).
    pub saturation_counts: Option<u16>,
    /// Pixels within this many camera pixels of where the station predicts the
    /// element are fitted; farther ones are reported as no data.
    pub margin_px: u32,
    /// Rim of the element beyond the aperture, mm (for the prediction).
    pub edge_margin_mm: f64,
    /// Levenberg–Marquardt iteration cap.
    pub max_iter: usize,
    /// Start each pixel's fits from its left neighbour's where that one found
    /// both points ([`super::pixel::fit_samples_seeded`]); `false`: search
    /// every pixel from its spectrum.
    pub warm_starts: bool,
    /// Only fit camera pixels in `[x0, x1) × [y0, y1)` (columns, rows).
    pub roi: Option<[u32; 4]>,
}

impl Default for SpectralConfig {
    fn default() -> Self {
        SpectralConfig {
            engine: Engine::Auto,
            band_bins: 3.0,
            tau_max_guess: None,
            third_reflection: false,
            saturation_counts: None,
            margin_px: 4,
            edge_margin_mm: DEFAULT_EDGE_MARGIN_MM,
            max_iter: 100,
            warm_starts: true,
            roi: None,
        }
    }
}

/// The per-pixel results of a whole image.
#[derive(Debug, Clone)]
pub struct SpectralMaps {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Row-major results under the scene's model.
    pub pixels: Vec<PixelResult>,
    /// Per pixel, the number of reflections its own BIC prefers (0: none fitted).
    pub preferred: Vec<u8>,
    /// Reflections in the model chosen for the scene.
    pub scene_model: u8,
    /// BIC summed over the compared pixels for 1, 2, 3 reflections (0 when not compared).
    pub bic_sums: [f64; 3],
    /// Saturation level used, counts.
    pub saturation_counts: Option<u16>,
}

/// The streaming spectral solver of one acquisition.
pub struct SpectralSolver {
    width: usize,
    height: usize,
    design: Design,
    plans: SpectrumPlans,
    prior: TracedView,
    candidates: Vec<u32>,
    /// Per candidate, the back-minus-front offset borrowed at the rim.
    borrowed: Vec<Option<[f64; 2]>>,
    series: Vec<u16>,
    stats: Option<Box<CompactStats>>,
    block: Vec<u16>,
    block_start: usize,
    received: usize,
    max_seen: u16,
    config: SpectralConfig,
    /// The solve's output arrays, allocated and written (their pages
    /// faulted in) on a thread of their own while the frames stream in,
    /// not after the last one: ~1.7 GB for a full sensor, whose maps'
    /// assembly took 0.7 s after the fits when it allocated them (0.17 s now).
    prepared: Mutex<Option<JoinHandle<Prepared>>>,
}

/// The solve's output arrays, blank: one [`PixelFits::none`] per candidate
/// and one no-data [`PixelResult`] per camera pixel.
struct Prepared {
    fits: Vec<PixelFits>,
    pixels: Vec<PixelResult>,
}

impl Prepared {
    fn new(candidates: usize, pixels: usize) -> Self {
        Prepared {
            fits: vec![PixelFits::none(); candidates],
            pixels: vec![no_data(); pixels],
        }
    }
}

/// The answer of a pixel that is not fitted.
fn no_data() -> PixelResult {
    PixelResult {
        flags: flags::NO_DATA,
        ..PixelResult::empty()
    }
}

impl SpectralSolver {
    /// Prepares for `frames` (capture order) of `station`.
    ///
    /// # Errors
    /// [`SpectralError::Schedule`] when fewer than two non-parallel directions.
    pub fn new(
        station: &Station,
        frames: &[FrameInfo],
        config: SpectralConfig,
    ) -> Result<Self, SpectralError> {
        let design = design(station, frames)?;
        let plans = SpectrumPlans::new(&design);
        let e = &station.element;
        let flat = ZernikeSurface::flat(
            e.aperture_radius_mm,
            [e.aperture_center_mm.x, e.aperture_center_mm.y],
        )
        .map_err(|err| SpectralError::Schedule {
            problem: err.to_string(),
        })?;
        let plate = Plate::new(station, flat.clone(), flat, config.edge_margin_mm);
        let prior = TracedView::trace(station, &plate);
        let mut candidates = candidates(&prior, config.margin_px as i64);
        if let Some([x0, y0, x1, y1]) = config.roi {
            let w = prior.width as u32;
            candidates.retain(|&p| (x0..x1).contains(&(p % w)) && (y0..y1).contains(&(p / w)));
        }
        let borrowed = borrowed_offsets(&prior, &candidates, i64::from(config.margin_px));
        let series_bytes = candidates.len() * frames.len() * 2;
        let use_stats = match config.engine {
            Engine::Series => false,
            Engine::Statistics => true,
            Engine::Auto => series_bytes > SERIES_LIMIT_BYTES,
        };
        if use_stats && !(config.band_bins.is_finite() && config.band_bins > 0.0) {
            return Err(SpectralError::Config {
                field: "band_bins",
                problem: format!(
                    "expected a number of Fourier bins > 0, found {}",
                    config.band_bins
                ),
            });
        }
        let stats = if use_stats {
            let kappa0 = kappa_start(&config, &design);
            let (centres, band) =
                band_centres(&design, &prior, &candidates, &borrowed, &config, &plans);
            let stats = CompactStats::new(
                &design,
                &centres,
                &band,
                // κ from −κ0 (no falloff, or a rising one: the fit may say
                // so) to 16 κ0 (τ_max down to a quarter of the starting one).
                [-kappa0, 16.0 * kappa0],
                config.saturation_counts,
            )
            .map_err(|problem| SpectralError::Config {
                field: "band_bins",
                problem,
            })?;
            Some(Box::new(stats))
        } else {
            None
        };
        let block_len = if use_stats { STATS_BLOCK } else { BLOCK };
        let (c, wh) = (candidates.len(), prior.width * prior.height);
        let prepared = std::thread::Builder::new()
            .name("mfd-prepare".into())
            .spawn(move || Prepared::new(c, wh))
            .ok();
        Ok(SpectralSolver {
            width: prior.width,
            height: prior.height,
            series: if use_stats {
                Vec::new()
            } else {
                vec![0; series_bytes / 2]
            },
            stats,
            block: Vec::with_capacity(block_len * candidates.len()),
            block_start: 0,
            candidates,
            borrowed,
            design,
            plans,
            prior,
            received: 0,
            max_seen: 0,
            config,
            prepared: Mutex::new(prepared),
        })
    }

    /// Pixels that will be fitted.
    pub fn candidate_pixels(&self) -> usize {
        self.candidates.len()
    }

    /// Frames expected.
    pub fn frames(&self) -> usize {
        self.design.frames.len()
    }

    /// Bytes held for the series (or, with the statistics engine, the statistics).
    pub fn series_bytes(&self) -> usize {
        self.series.len() * 2 + self.stats.as_ref().map_or(0, |s| s.bytes())
    }

    /// Whether the statistics engine is in use, with its node counts per
    /// direction (data, products).
    pub fn statistics_nodes(&self) -> Option<Vec<(usize, usize)>> {
        self.stats.as_ref().map(|s| s.tables().nodes())
    }

    /// Takes frame `index`, which must be the next in capture order.
    ///
    /// # Errors
    /// [`SpectralError::Frame`] for an out-of-order or wrongly sized frame.
    pub fn push_frame(&mut self, index: usize, frame: &[u16]) -> Result<(), SpectralError> {
        if index != self.received || index >= self.frames() {
            return Err(SpectralError::Frame {
                frame: index,
                problem: format!("expected frame {} of {}", self.received, self.frames()),
            });
        }
        if frame.len() != self.width * self.height {
            return Err(SpectralError::Frame {
                frame: index,
                problem: format!(
                    "{} pixels, expected {}x{}",
                    frame.len(),
                    self.width,
                    self.height
                ),
            });
        }
        for &p in &self.candidates {
            let v = frame[p as usize];
            self.max_seen = self.max_seen.max(v);
            self.block.push(v);
        }
        self.received += 1;
        let block = if self.stats.is_some() {
            STATS_BLOCK
        } else {
            BLOCK
        };
        if self.received - self.block_start == block || self.received == self.frames() {
            self.flush();
        }
        if self.received == self.frames() {
            if let Some(stats) = self.stats.as_mut() {
                stats.seal();
            }
            // The block buffer (32 frames of the candidates, 80 MB on a
            // full sensor) is not needed again: freed before the solve.
            self.block = Vec::new();
        }
        Ok(())
    }

    fn flush(&mut self) {
        if let Some(stats) = self.stats.as_mut() {
            stats.ingest(
                self.block_start,
                self.received - self.block_start,
                &self.block,
            );
            self.block.clear();
            self.block_start = self.received;
            return;
        }
        let n = self.frames();
        let c = self.candidates.len();
        let rows = self.received - self.block_start;
        for q in 0..c {
            let dst = &mut self.series[q * n + self.block_start..q * n + self.received];
            for (r, d) in dst.iter_mut().enumerate().take(rows) {
                *d = self.block[r * c + q];
            }
        }
        self.block.clear();
        self.block_start = self.received;
    }

    fn saturation(&self) -> Option<u16> {
        self.config
            .saturation_counts
            .or_else(|| FULL_SCALES.into_iter().find(|&fs| fs == self.max_seen))
    }

    /// Fits every pixel (all cores) once all frames are in.
    ///
    /// # Errors
    /// [`SpectralError::Frame`] when frames are missing.
    pub fn solve(&self) -> Result<SpectralMaps, SpectralError> {
        self.solve_with(&CpuFits)
    }

    /// [`SpectralSolver::solve`] with the per-pixel fits run by `backend`.
    ///
    /// # Errors
    /// [`SpectralError::Frame`] when frames are missing;
    /// [`SpectralError::Backend`] when the backend answers for the wrong
    /// number of pixels.
    pub fn solve_with(&self, backend: &dyn FitBackend) -> Result<SpectralMaps, SpectralError> {
        if self.received != self.frames() {
            return Err(SpectralError::Frame {
                frame: self.received,
                problem: format!(
                    "missing: only {} of {} frames arrived",
                    self.received,
                    self.frames()
                ),
            });
        }
        let sat = self.saturation();
        let kappa0 = kappa_start(&self.config, &self.design);
        // The prepared arrays serve the first solve; later ones allocate.
        let prepared = self
            .prepared
            .lock()
            .ok()
            .and_then(|mut h| h.take())
            .and_then(|h| h.join().ok());
        let (fits_out, pixels_out) = match prepared {
            Some(p) => (Some(p.fits), Some(p.pixels)),
            None => (None, None),
        };
        let batch = FitBatch {
            design: &self.design,
            plans: &self.plans,
            prior: &self.prior,
            candidates: &self.candidates,
            borrowed: &self.borrowed,
            series: &self.series,
            stats: self.stats.as_deref(),
            saturation: sat,
            kappa0,
            allow_third: self.config.third_reflection,
            max_iter: self.config.max_iter,
            warm_starts: self.config.warm_starts,
            output: Mutex::new(fits_out),
        };
        let fits = backend.fit(&batch);
        if fits.len() != self.candidates.len() {
            return Err(SpectralError::Backend {
                problem: format!(
                    "returned {} results for {} pixels",
                    fits.len(),
                    self.candidates.len()
                ),
            });
        }
        let (scene_model, bic_sums) = scene_model(&fits, self.config.third_reflection);
        // Every camera pixel's answer, in parallel: its candidate's chosen
        // model, or no data.
        let mut index = vec![u32::MAX; self.width * self.height];
        for (q, &p) in self.candidates.iter().enumerate() {
            index[p as usize] = q as u32;
        }
        let own = |models: &[Option<Scored>]| {
            models
                .iter()
                .enumerate()
                .filter_map(|(k, c)| c.map(|c| (k, c)))
                .min_by(|a, b| a.1.bic.total_cmp(&b.1.bic))
        };
        let mut pixels = pixels_out
            .filter(|v| v.len() == index.len())
            .unwrap_or_else(|| vec![no_data(); index.len()]);
        let mut preferred = vec![0u8; index.len()];
        pixels
            .par_iter_mut()
            .zip(preferred.par_iter_mut())
            .zip(index.par_iter())
            .enumerate()
            .for_each(|(p, ((out, pref), &q))| {
                // Not a candidate: the prepared no-data answer stands.
                let Some(fits) = fits.get(q as usize) else {
                    return;
                };
                // The scene's model where it applies; where the geometry
                // allows fewer reflections (the back path leaves through the
                // rim), the largest model that applies. Where the flat
                // plate's back path leaves through the rim but the real one
                // may not (the offset is borrowed), the pixel's own BIC decides.
                let rim = self.prior.pixels[p].back.is_err();
                let chosen = if rim {
                    own(&fits.per_model[..scene_model]).map(|(_, c)| c)
                } else {
                    fits.per_model[..scene_model]
                        .iter()
                        .rev()
                        .flatten()
                        .next()
                        .copied()
                };
                *out = chosen.map_or(fits.base, |c| c.result);
                *pref = own(&fits.per_model).map_or(0, |(k, _)| k as u8 + 1);
            });
        // The fits (~1 kB per pixel) are freed off the caller's path.
        std::thread::spawn(move || drop(fits));
        Ok(SpectralMaps {
            width: self.width,
            height: self.height,
            pixels,
            preferred,
            scene_model: scene_model as u8,
            bic_sums,
            saturation_counts: sat,
        })
    }

    /// The model's view of the schedule.
    pub fn design(&self) -> &Design {
        &self.design
    }

    /// The geometry prior (flat surfaces through the nominal station).
    pub fn prior(&self) -> &TracedView {
        &self.prior
    }
}

/// Everything the per-pixel fits of one acquisition need: the schedule, the
/// geometry prior and either the series of the candidate pixels,
/// pixel-major (the `frames` samples of candidate q at
/// `series[q * frames..]`, raw counts), or their statistics (`stats`, with
/// the statistics engine; `series` is then empty).
pub struct FitBatch<'a> {
    /// The schedule.
    pub design: &'a Design,
    /// Periodogram plans.
    pub plans: &'a SpectrumPlans,
    /// The flat-plate prediction of every camera pixel.
    pub prior: &'a TracedView,
    /// Camera pixel index of each candidate, row-major.
    pub candidates: &'a [u32],
    /// Per candidate, the back-minus-front offset borrowed at the rim.
    pub borrowed: &'a [Option<[f64; 2]>],
    /// The series, pixel-major (empty with the statistics engine).
    pub series: &'a [u16],
    /// The statistics, with the statistics engine.
    pub stats: Option<&'a CompactStats>,
    /// Samples at or above this count (and at 0) are excluded.
    pub saturation: Option<u16>,
    /// Starting κ = 1/τ_max².
    pub kappa0: f64,
    /// Whether a third reflection may be modelled.
    pub allow_third: bool,
    /// Levenberg–Marquardt iteration cap.
    pub max_iter: usize,
    /// Whether a pixel's fits start from its left neighbour's ([`Self::fit_run`]).
    pub warm_starts: bool,
    /// The output array prepared during the stream ([`Self::output`]).
    output: Mutex<Option<Vec<PixelFits>>>,
}

impl FitBatch<'_> {
    /// One [`PixelFits::none`] per candidate, for a backend to write its
    /// results into: the array the solver prepared (memory already touched)
    /// while the frames streamed in, on the first call; a new one after.
    pub fn output(&self) -> Vec<PixelFits> {
        let n = self.candidates.len();
        if let Some(v) = self.output.lock().ok().and_then(|mut o| o.take()) {
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
        let w = self.prior.width as u32;
        let mut runs = Vec::new();
        let mut from = 0;
        for q in 1..=self.candidates.len() {
            let adjacent = q < self.candidates.len() && {
                let (a, b) = (self.candidates[q - 1], self.candidates[q]);
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
    /// points and warm starts are on, else searched like [`Self::fit_one`].
    pub fn fit_run(&self, run: std::ops::Range<usize>) -> Vec<PixelFits> {
        let mut out = vec![PixelFits::none(); run.len()];
        self.fit_run_into(run, &mut out);
        out
    }

    fn fit_run_into(&self, run: std::ops::Range<usize>, out: &mut [PixelFits]) {
        let mut seed = None;
        let end = run.end;
        for (i, q) in run.enumerate() {
            // The next pixel's statistics and result slot, read and written
            // once each from memory, are fetched while this one is fitted.
            if q + 1 < end {
                if let Some(stats) = self.stats {
                    stats.prefetch(q + 1);
                }
                prefetch_lines(std::slice::from_ref(&out[i + 1]));
            }
            seed = self.fit_seeded(q, seed.as_ref().filter(|_| self.warm_starts), &mut out[i]);
        }
    }
    /// Frames per series.
    pub fn frames(&self) -> usize {
        self.design.frames.len()
    }

    /// Candidate `q` fitted on this thread (the reference every backend must
    /// reproduce).
    pub fn fit_one(&self, q: usize) -> PixelFits {
        let mut out = PixelFits::none();
        self.fit_seeded(q, None, &mut out);
        out
    }

    fn fit_seeded(&self, q: usize, seed: Option<&Seed>, out: &mut PixelFits) -> Option<Seed> {
        let ctx = PixelContext {
            design: self.design,
            plans: self.plans,
            prior: &self.prior.pixels[self.candidates[q] as usize],
            borrowed_offset: self.borrowed[q],
            kappa0: self.kappa0,
            allow_third: self.allow_third,
            max_iter: self.max_iter,
        };
        if let Some(stats) = self.stats {
            return match stats.samples(self.design, q, self.saturation) {
                Some((data, excluded)) => fit_samples_seeded(&ctx, &data, excluded, seed, out),
                None => {
                    *out = PixelFits::none();
                    out.base.flags = flags::SATURATED | flags::NO_DATA;
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
                if v == 0 || self.saturation.is_some_and(|s| v >= s) {
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
/// matching [`FitBatch::fit_run`] over [`FitBatch::runs`]. [`CpuFits`] is
/// the path CI tests.
pub trait FitBackend: Sync {
    /// Fits every candidate of `batch`.
    fn fit(&self, batch: &FitBatch) -> Vec<PixelFits>;
}

/// The per-pixel fits on all CPU cores (rayon).
#[derive(Debug, Clone, Copy, Default)]
pub struct CpuFits;

impl FitBackend for CpuFits {
    fn fit(&self, batch: &FitBatch) -> Vec<PixelFits> {
        // Written in place, run by run: the results of a full sensor are
        // ~1.3 GB, too much to hold twice.
        let mut out = batch.output();
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

/// The scene's number of reflections: the model with the smallest BIC summed
/// over the pixels where every compared model was fitted (a pixel's
/// log-likelihoods add up over the scene). Returns it with the sums.
fn scene_model(results: &[PixelFits], allow_third: bool) -> (usize, [f64; 3]) {
    let top = if allow_third { 3 } else { 2 };
    // Fixed chunks, summed in order: the same sums on every run.
    let partial: Vec<[f64; 3]> = results
        .par_chunks(4096)
        .map(|chunk| {
            let mut sums = [0.0; 3];
            for f in chunk {
                if f.per_model[..top].iter().all(Option::is_some) {
                    for (k, c) in f.per_model[..top].iter().enumerate() {
                        sums[k] += c.map_or(0.0, |c| c.bic);
                    }
                } else if let (2, Some(one), Some(two)) = (top, f.one_bic, f.per_model[1]) {
                    // A warm pixel: the one-reflection BIC from its pair's
                    // weaker amplitude.
                    sums[0] += one;
                    sums[1] += two.bic;
                }
            }
            sums
        })
        .collect();
    let sums = partial
        .iter()
        .fold([0.0; 3], |a, b| [a[0] + b[0], a[1] + b[1], a[2] + b[2]]);
    let best = (1..top).fold(0, |b, k| if sums[k] < sums[b] { k } else { b });
    // With no pixel fitted under every model, fall back to the largest.
    let chosen = if sums.iter().all(|&v| v == 0.0) {
        top
    } else {
        best + 1
    };
    (chosen, sums)
}

fn design(station: &Station, frames: &[FrameInfo]) -> Result<Design, SpectralError> {
    let mut directions_deg: Vec<f64> = Vec::new();
    let mut metas = Vec::with_capacity(frames.len());
    for f in frames {
        let dir = match directions_deg.iter().position(|&d| d == f.direction_deg) {
            Some(d) => d,
            None => {
                directions_deg.push(f.direction_deg);
                directions_deg.len() - 1
            }
        };
        metas.push(FrameMeta {
            tau: f.tau,
            phase_cycles: f.phase_rad / std::f64::consts::TAU,
            dir,
        });
    }
    let axes: Vec<Axis> = directions_deg
        .iter()
        .map(|&d| {
            Axis::from_fringe(&FringeAxis::new(
                d,
                station.screen.width,
                station.screen.height,
            ))
        })
        .collect();
    let spread = axes
        .iter()
        .flat_map(|a| {
            axes.iter()
                .map(move |b| (a.a * b.b - a.b * b.a).abs() / (a.a.hypot(a.b) * b.a.hypot(b.b)))
        })
        .fold(0.0, f64::max);
    if spread < 0.1 {
        return Err(SpectralError::Schedule {
            problem: format!(
                "directions {directions_deg:?} are (nearly) parallel: two non-parallel fringe \
                 directions are needed to locate a screen point in u and v"
            ),
        });
    }
    Ok(Design {
        frames: metas,
        axes,
        directions_deg,
    })
}

/// For each candidate whose prior has a front but no back path, the
/// back-minus-front offset averaged over the nearest ring (up to `radius`
/// px) of pixels that have both; the offset varies slowly over the element,
/// so the nearest ring predicts it well. The radius is the candidates'
/// margin: how far the real element may sit from where the station puts it,
/// and so how far the real edge of the back reflection may lie from the
/// flat plate's. Farther in, the back path really leaves through the rim.
fn borrowed_offsets(prior: &TracedView, candidates: &[u32], radius: i64) -> Vec<Option<[f64; 2]>> {
    let (w, h) = (prior.width as i64, prior.height as i64);
    let both = |x: i64, y: i64| -> Option<[f64; 2]> {
        if !(0..w).contains(&x) || !(0..h).contains(&y) {
            return None;
        }
        let p = &prior.pixels[(y * w + x) as usize];
        match (p.front, p.back) {
            (Ok(f), Ok(b)) => Some([b.u - f.u, b.v - f.v]),
            _ => None,
        }
    };
    candidates
        .iter()
        .map(|&k| {
            let p = &prior.pixels[k as usize];
            if p.front.is_err() || p.back.is_ok() {
                return None;
            }
            let (x, y) = (i64::from(k) % w, i64::from(k) / w);
            (1..=radius).find_map(|r| {
                let ring = (-r..=r).flat_map(|d| {
                    [
                        (x + d, y - r),
                        (x + d, y + r),
                        (x - r, y + d),
                        (x + r, y + d),
                    ]
                });
                let (mut sum, mut n) = ([0.0; 2], 0.0);
                for (i, j) in ring {
                    if let Some(d) = both(i, j) {
                        sum[0] += d[0];
                        sum[1] += d[1];
                        n += 1.0;
                    }
                }
                (n > 0.0).then(|| [sum[0] / n, sum[1] / n])
            })
        })
        .collect()
}

/// Starting κ = 1/τ_max²: the configured guess or the schedule's largest τ.
fn kappa_start(config: &SpectralConfig, design: &Design) -> f64 {
    config
        .tau_max_guess
        .unwrap_or_else(|| design.frames.iter().map(|f| f.tau).fold(0.0, f64::max))
        .powi(-2)
}

/// Per direction, each candidate's demodulation centre (μ) — the middle of
/// the screen points the station predicts for it (front, back or its
/// borrowed offset, third when allowed), taken from the nearest pixel with
/// a prediction within the margin for candidates without one — and the
/// band half-width: half the widest predicted spread plus `band_bins`.
fn band_centres(
    design: &Design,
    prior: &TracedView,
    candidates: &[u32],
    borrowed: &[Option<[f64; 2]>],
    config: &SpectralConfig,
    plans: &SpectrumPlans,
) -> (Vec<Vec<f64>>, Vec<f64>) {
    let w = prior.width as i64;
    let h = prior.height as i64;
    let points = |k: usize, borrow: Option<[f64; 2]>| -> Vec<[f64; 2]> {
        let p = &prior.pixels[k];
        let mut pts = Vec::new();
        for (i, path) in [p.front, p.back, p.third].iter().enumerate() {
            if i == 2 && !config.third_reflection {
                continue;
            }
            if let Ok(hit) = path {
                pts.push([hit.u, hit.v]);
            }
        }
        if let (Ok(f), Err(_), Some(d)) = (p.front, p.back, borrow) {
            pts.push([f.u + d[0], f.v + d[1]]);
        }
        pts
    };
    let nd = design.axes.len();
    let mut centres = vec![Vec::with_capacity(candidates.len()); nd];
    let mut half = vec![0.0f64; nd];
    for (c, &k) in candidates.iter().enumerate() {
        let mut pts = points(k as usize, borrowed[c]);
        if pts.is_empty() {
            let (x, y) = (i64::from(k) % w, i64::from(k) / w);
            pts = (1..=i64::from(config.margin_px))
                .find_map(|r| {
                    (-r..=r)
                        .flat_map(|d| {
                            [
                                (x + d, y - r),
                                (x + d, y + r),
                                (x - r, y + d),
                                (x + r, y + d),
                            ]
                        })
                        .filter(|&(i, j)| (0..w).contains(&i) && (0..h).contains(&j))
                        .map(|(i, j)| points((j * w + i) as usize, None))
                        .find(|p| !p.is_empty())
                })
                .unwrap_or_else(|| vec![[0.0, 0.0]]);
        }
        for (d, ax) in design.axes.iter().enumerate() {
            let mus = pts.iter().map(|p| ax.s(p[0], p[1]));
            let lo = mus.clone().fold(f64::INFINITY, f64::min);
            let hi = mus.fold(f64::NEG_INFINITY, f64::max);
            centres[d].push(0.5 * (lo + hi));
            half[d] = half[d].max(0.5 * (hi - lo));
        }
    }
    let band = (0..nd)
        .map(|d| half[d] + config.band_bins * plans.bin(d))
        .collect();
    (centres, band)
}

/// Pixels whose front or back path exists in the prior, grown by `margin` px.
fn candidates(prior: &TracedView, margin: i64) -> Vec<u32> {
    let (w, h) = (prior.width as i64, prior.height as i64);
    let mut mask = vec![false; prior.pixels.len()];
    for (k, p) in prior.pixels.iter().enumerate() {
        if p.front.is_err() && p.back.is_err() {
            continue;
        }
        let (i, j) = (k as i64 % w, k as i64 / w);
        for dj in -margin..=margin {
            for di in -margin..=margin {
                let (x, y) = (i + di, j + dj);
                if (0..w).contains(&x) && (0..h).contains(&y) {
                    mask[(y * w + x) as usize] = true;
                }
            }
        }
    }
    (0..mask.len() as u32)
        .filter(|&k| mask[k as usize])
        .collect()
}

impl SpectralMaps {
    /// `[rows, columns, 2, 2]` screen coordinates (spec layout).
    pub fn screen_coords(&self) -> Vec<f64> {
        self.pixels
            .iter()
            .flat_map(|p| [p.s[0][0], p.s[0][1], p.s[1][0], p.s[1][1]])
            .collect()
    }

    /// `[rows, columns, 2, 2]` standard deviations of the screen coordinates, px.
    pub fn screen_std(&self) -> Vec<f64> {
        self.pixels
            .iter()
            .flat_map(|p| [p.std[0][0], p.std[0][1], p.std[1][0], p.std[1][1]])
            .collect()
    }

    /// `[rows, columns, 4, 4]` covariance of `(u1, v1, u2, v2)`, px².
    pub fn screen_cov(&self) -> Vec<f64> {
        self.pixels
            .iter()
            .flat_map(|p| p.cov.into_iter().flatten())
            .collect()
    }

    /// Writes `screen_coords.npy` and the quality maps into `dir`.
    ///
    /// # Errors
    /// [`SpectralError::Npy`] naming the file.
    pub fn write(&self, dir: &Path) -> Result<(), SpectralError> {
        let (h, w) = (self.height, self.width);
        let px = &self.pixels;
        npy::write_f64(
            &dir.join("screen_coords.npy"),
            &[h, w, 2, 2],
            &self.screen_coords(),
        )?;
        npy::write_f64(
            &dir.join("screen_std.npy"),
            &[h, w, 2, 2],
            &self.screen_std(),
        )?;
        npy::write_f64(
            &dir.join("screen_cov.npy"),
            &[h, w, 4, 4],
            &self.screen_cov(),
        )?;
        let amp: Vec<f64> = px.iter().flat_map(|p| p.amp).collect();
        npy::write_f64(&dir.join("amplitudes.npy"), &[h, w, 4], &amp)?;
        let scalar = |f: fn(&PixelResult) -> f64| px.iter().map(f).collect::<Vec<f64>>();
        npy::write_f64(&dir.join("tau_max.npy"), &[h, w], &scalar(|p| p.tau_max))?;
        npy::write_f64(
            &dir.join("residual_rms.npy"),
            &[h, w],
            &scalar(|p| p.residual_rms),
        )?;
        npy::write_f64(
            &dir.join("separation_bins.npy"),
            &[h, w],
            &scalar(|p| p.separation_bins),
        )?;
        npy::write_u8(
            &dir.join("reflections.npy"),
            &[h, w],
            &px.iter().map(|p| p.model).collect::<Vec<u8>>(),
        )?;
        npy::write_u8(
            &dir.join("preferred_reflections.npy"),
            &[h, w],
            &self.preferred,
        )?;
        npy::write_u16(
            &dir.join("flags.npy"),
            &[h, w],
            &px.iter().map(|p| p.flags).collect::<Vec<u16>>(),
        )?;
        npy::write_u16(
            &dir.join("iterations.npy"),
            &[h, w],
            &px.iter().map(|p| p.iterations).collect::<Vec<u16>>(),
        )?;
        Ok(())
    }

    /// Pixels with both screen points found.
    pub fn found_both(&self) -> usize {
        self.pixels
            .iter()
            .filter(|p| p.s[0][0].is_finite() && p.s[1][0].is_finite())
            .count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::trace::{Miss, PixelPaths, ScreenHit};

    fn hit(u: f64, v: f64) -> Result<ScreenHit, Miss> {
        Ok(ScreenHit { u, v, weight: 0.04 })
    }

    #[test]
    fn rim_pixels_borrow_the_nearest_ring_offset() {
        // 5×3 view: columns 0–2 have both paths with offsets (10, x), column
        // 3 only the front, column 4 nothing.
        let (w, h) = (5usize, 3usize);
        let pixels = (0..w * h)
            .map(|k| {
                let x = (k % w) as f64;
                let miss = Err(Miss::ElementMissed);
                let (front, back) = match k % w {
                    0..=2 => (hit(x, 0.0), hit(x + 10.0, x)),
                    3 => (hit(x, 0.0), miss),
                    _ => (miss, miss),
                };
                PixelPaths {
                    front,
                    back,
                    third: miss,
                }
            })
            .collect();
        let view = TracedView {
            width: w,
            height: h,
            pixels,
        };
        let all: Vec<u32> = (0..(w * h) as u32).collect();
        // Within one ring only column 3 reaches a pixel with both paths.
        let near = borrowed_offsets(&view, &all, 1);
        assert!(near
            .iter()
            .enumerate()
            .all(|(k, g)| g.is_some() == (k % w == 3)));
        let got = borrowed_offsets(&view, &all, 4);
        for (k, g) in got.iter().enumerate() {
            match k % w {
                // The nearest ring of (3, 1) holds column 2 at three rows
                // (offset (10, 2)); of (3, 0) and (3, 2), two of them.
                3 => assert_eq!(*g, Some([10.0, 2.0]), "pixel {k}"),
                // Both paths, or no front: nothing borrowed.
                _ => assert_eq!(*g, None, "pixel {k}"),
            }
        }
    }
}

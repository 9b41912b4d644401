//! The solver's driver: frames arrive in capture order, the samples of the
//! pixels that can see the element are kept (pixel-major, 2 bytes each) or
//! reduced to their statistics, and every pixel is fitted on all cores
//! once its series is complete ([`SpectralSolver::solve`]).

use std::thread::JoinHandle;

use super::batch::{CpuFits, FitBackend, FitBatch, FitSettings};
use super::maps::SpectralMaps;
use super::model::censored::Clip;
use super::model::{
    eval_row, Axis, Design, Falloff, FrameMeta, Params, Samples, SeriesSamples, MAX_PARAMS,
};
use super::periodogram::SpectrumPlans;
use super::phase::{self, PhaseModel, PhaseSchedule, PhaseSettings, Response};
use super::pixel::PixelFits;
use super::prior::{flat_plate_prior, GeometryPrior};
use super::scene::{no_data, pixel_answers, scene_model};
use super::statistics::{Statistics, FULL_SCALES, STATS_BLOCK};
use super::{Engine, PixelResult, SpectralConfig, SpectralError, SERIES_LIMIT_BYTES};
use crate::acquire::acquisition::FrameInfo;
use crate::acquire::patterns::FringeAxis;
use crate::optics::station::Station;
use crate::optics::trace::TracedView;

/// Frames buffered frame-major before they are transposed into the
/// pixel-major series (keeps the scatter cache-friendly).
const BLOCK: usize = 32;

/// The streaming spectral solver of one acquisition.
pub struct SpectralSolver {
    width: usize,
    height: usize,
    design: Design,
    plans: SpectrumPlans,
    prior: GeometryPrior,
    series: Vec<u16>,
    stats: Option<Box<Statistics>>,
    block: Vec<u16>,
    block_start: usize,
    received: usize,
    max_seen: u16,
    config: SpectralConfig,
    /// A phase-shifting schedule's groups and the display's response: the
    /// one-reflection path of [`phase`] instead of the periodogram's.
    phase: Option<(PhaseSchedule, Response)>,
    /// The solve's output arrays, allocated and written (their pages
    /// faulted in) on a thread of their own while the frames stream in,
    /// not after the last one; the first solve takes them.
    prepared: Option<JoinHandle<Prepared>>,
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

impl SpectralSolver {
    /// Prepares for `frames` (capture order) of `station`, with the flat
    /// plate traced through it as the prior ([`flat_plate_prior`], the rim
    /// `config.edge_margin_mm`).
    ///
    /// # Errors
    /// [`SpectralError::Schedule`] when fewer than two non-parallel
    /// directions; as [`Self::with_prior`].
    pub fn new(
        station: &Station,
        frames: &[FrameInfo],
        config: SpectralConfig,
    ) -> Result<Self, SpectralError> {
        let design = design(station, frames)?;
        let prior = flat_plate_prior(station, config.edge_margin_mm)?;
        Self::with_design(station, design, config, prior)
    }

    /// Prepares for `frames` (capture order) of `station` with `prior`, the
    /// nominal flat plate traced through the station ([`flat_plate_prior`]
    /// or [`TracedView::trace`]), one path set per camera pixel.
    ///
    /// # Errors
    /// [`SpectralError::Schedule`] when fewer than two non-parallel
    /// directions; [`SpectralError::Prior`] when `prior` does not hold one
    /// entry per pixel of the station's camera; [`SpectralError::Config`] and
    /// [`SpectralError::Statistics`] when the statistics engine cannot be
    /// built with these settings.
    pub fn with_prior(
        station: &Station,
        frames: &[FrameInfo],
        config: SpectralConfig,
        prior: TracedView,
    ) -> Result<Self, SpectralError> {
        let design = design(station, frames)?;
        Self::with_design(station, design, config, prior)
    }

    fn with_design(
        station: &Station,
        design: Design,
        config: SpectralConfig,
        view: TracedView,
    ) -> Result<Self, SpectralError> {
        let camera = &station.camera;
        if view.pixels.len() != view.width * view.height
            || view.width != camera.width as usize
            || view.height != camera.height as usize
        {
            return Err(SpectralError::Prior {
                pixels: view.pixels.len(),
                width: view.width,
                height: view.height,
                camera_width: camera.width,
                camera_height: camera.height,
            });
        }
        let phase = match PhaseSchedule::detect(&design) {
            Some(s) => Some((
                s,
                Response::of(config.display_gamma, config.display_response.as_ref())?,
            )),
            None => None,
        };
        let plans = SpectrumPlans::new(&design);
        let prior = GeometryPrior::new(view, &config);
        let series_bytes = prior.candidates.len() * design.frames.len() * 2;
        let use_stats = match config.engine {
            _ if phase.is_some() => {
                if config.engine == Engine::Statistics {
                    log::info!("phase-shifting schedule: the series engine is used (a few frames per pixel)");
                }
                false
            }
            Engine::Series => false,
            Engine::Statistics => true,
            Engine::Auto => series_bytes > SERIES_LIMIT_BYTES,
        };
        let stats = if use_stats {
            Some(Box::new(statistics(&design, &prior, &config, &plans)?))
        } else {
            None
        };
        let block_len = if use_stats { STATS_BLOCK } else { BLOCK };
        let (c, wh) = (prior.candidates.len(), prior.view.width * prior.view.height);
        let prepared = std::thread::Builder::new()
            .name("mfd-prepare".into())
            .spawn(move || Prepared::new(c, wh))
            .ok();
        Ok(SpectralSolver {
            width: prior.view.width,
            height: prior.view.height,
            series: if use_stats {
                Vec::new()
            } else {
                vec![0; series_bytes / 2]
            },
            stats,
            block: Vec::with_capacity(block_len * c),
            block_start: 0,
            design,
            plans,
            prior,
            received: 0,
            max_seen: 0,
            config,
            phase,
            prepared,
        })
    }

    /// Pixels that will be fitted.
    pub fn candidate_pixels(&self) -> usize {
        self.prior.candidates.len()
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
        for &p in &self.prior.candidates {
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
        let c = self.prior.candidates.len();
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
    pub fn solve(&mut self) -> Result<SpectralMaps, SpectralError> {
        self.solve_with(&CpuFits)
    }

    /// [`SpectralSolver::solve`] with the per-pixel fits run by `backend`.
    /// The first solve takes the output arrays prepared while the frames
    /// streamed in; later ones allocate their own.
    ///
    /// # Errors
    /// [`SpectralError::Frame`] when frames are missing;
    /// [`SpectralError::Backend`] when the backend answers for the wrong
    /// number of pixels.
    pub fn solve_with(&mut self, backend: &dyn FitBackend) -> Result<SpectralMaps, SpectralError> {
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
        if let Some((schedule, response)) = &self.phase {
            return Ok(self.solve_phase(schedule, response, sat));
        }
        let prepared = self.prepared.take().and_then(|h| h.join().ok());
        let (fits_out, pixels_out) = match prepared {
            Some(p) => (Some(p.fits), Some(p.pixels)),
            None => (None, None),
        };
        let settings = FitSettings {
            saturation: sat,
            kappa0: self.config.falloff_start(&self.design),
            allow_third: self.config.third_reflection,
            max_iter: self.config.max_iter,
            warm_starts: self.config.warm_starts,
        };
        let mut batch = FitBatch::new(
            &self.design,
            &self.plans,
            &self.prior,
            (&self.series, self.stats.as_deref()),
            settings,
            fits_out,
        );
        let fits = backend.fit(&mut batch);
        let candidates = self.prior.candidates.len();
        if fits.len() != candidates {
            return Err(SpectralError::Backend {
                problem: format!("returned {} results for {candidates} pixels", fits.len()),
            });
        }
        let (scene_model, bic_sums) = scene_model(&fits, self.config.third_reflection);
        let (pixels, preferred) = pixel_answers(&fits, &self.prior, scene_model, pixels_out);
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

    /// The phase-shifting path ([`phase`]): one reflection per pixel.
    fn solve_phase(
        &self,
        schedule: &PhaseSchedule,
        response: &Response,
        saturation: Option<u16>,
    ) -> SpectralMaps {
        let model = PhaseModel {
            design: &self.design,
            schedule,
            response,
        };
        let settings = PhaseSettings {
            saturation,
            kappa0: self.config.kappa_start(&self.design),
            max_iter: self.config.max_iter,
        };
        let fits = phase::solve_all(&model, &self.series, settings);
        let bic_one = fits
            .iter()
            .filter_map(|f| f.per_model[0].map(|s| s.bic))
            .sum();
        let (pixels, preferred) = pixel_answers(&fits, &self.prior, 1, None);
        SpectralMaps {
            width: self.width,
            height: self.height,
            pixels,
            preferred,
            scene_model: 1,
            bic_sums: [bic_one, 0.0, 0.0],
            saturation_counts: saturation,
        }
    }

    /// The phase-shifting schedule's groups and the display response, when
    /// the schedule is one ([`PhaseSchedule::detect`]).
    pub fn phase_schedule(&self) -> Option<(&PhaseSchedule, &Response)> {
        self.phase.as_ref().map(|(s, r)| (s, r))
    }

    /// The model's view of the schedule.
    pub fn design(&self) -> &Design {
        &self.design
    }

    /// The geometry prior (flat surfaces through the nominal station).
    pub fn prior(&self) -> &TracedView {
        &self.prior.view
    }

    /// Camera pixel index (row-major) of every candidate, in candidate order.
    pub fn candidates(&self) -> &[u32] {
        &self.prior.candidates
    }

    /// Whether candidate `q`'s back offset was borrowed from its neighbours
    /// at the rim (the flat plate's back path leaves through the edge there).
    pub fn borrowed(&self, q: usize) -> bool {
        self.prior.borrowed[q].is_some()
    }

    /// Starting κ = 1/τ_max² of the fits, in every falloff group.
    pub fn kappa_start(&self) -> Falloff {
        self.config.falloff_start(&self.design)
    }

    /// [`Self::with_samples`] with the clipped samples standing at their
    /// conditional means under the model at `p` with noise `sigma`
    /// ([`super::model::censored`]) instead of left out: a least-squares fit on them has
    /// the censored likelihood's gradient at `p`.
    pub fn with_samples_at<R>(
        &self,
        q: usize,
        p: &Params,
        sigma: f64,
        f: impl FnOnce(&dyn Samples, usize) -> R,
    ) -> Option<R> {
        if self.phase.is_some() || q >= self.prior.candidates.len() {
            return None;
        }
        let sat = self.saturation();
        let clip = Clip::new(sat);
        let level = |i: usize, v: u16| {
            let mut row = [0.0; MAX_PARAMS];
            let mu = eval_row(&self.design, &self.design.frames[i], p, &mut row);
            clip.imputed(v, mu, sigma)
        };
        if let Some(stats) = &self.stats {
            let (data, clipped) = stats.samples_imputed(&self.design, q, sat, &level)?;
            return Some(f(&data, clipped));
        }
        let n = self.frames();
        let mut clipped = 0;
        let y: Vec<f64> = self.series[q * n..(q + 1) * n]
            .iter()
            .enumerate()
            .map(|(i, &v)| {
                if v == 0 || sat.is_some_and(|s| v >= s) {
                    clipped += 1;
                    level(i, v)
                } else {
                    f64::from(v)
                }
            })
            .collect();
        let data = SeriesSamples::new(&self.design, &self.plans, &y, self.kappa_start());
        Some(f(&data, clipped))
    }

    /// `f` of candidate `q`'s samples as the fits see them (its series, or
    /// its statistics with that engine; clipped samples left out), with
    /// the number left out; `None` where the pixel has too many clipped
    /// samples to be fitted, or the schedule is a phase-shifting one (its
    /// path keeps no per-pixel model of this kind).
    pub fn with_samples<R>(&self, q: usize, f: impl FnOnce(&dyn Samples, usize) -> R) -> Option<R> {
        if self.phase.is_some() || q >= self.prior.candidates.len() {
            return None;
        }
        let sat = self.saturation();
        if let Some(stats) = &self.stats {
            let (data, excluded) = stats.samples(&self.design, q, sat)?;
            return Some(f(&data, excluded));
        }
        let n = self.frames();
        let mut excluded = 0;
        let y: Vec<f64> = self.series[q * n..(q + 1) * n]
            .iter()
            .map(|&v| {
                if v == 0 || sat.is_some_and(|s| v >= s) {
                    excluded += 1;
                    f64::NAN
                } else {
                    f64::from(v)
                }
            })
            .collect();
        let data = SeriesSamples::new(&self.design, &self.plans, &y, self.kappa_start());
        Some(f(&data, excluded))
    }
}

/// The statistics of the prior's candidates, their band around the
/// prior's prediction; κ from −κ0 (no falloff, or a rising one: the fit
/// may say so) to 16 κ0 (τ_max down to a quarter of the starting one).
fn statistics(
    design: &Design,
    prior: &GeometryPrior,
    config: &SpectralConfig,
    plans: &SpectrumPlans,
) -> Result<Statistics, SpectralError> {
    if !(config.band_bins.is_finite() && config.band_bins > 0.0) {
        return Err(SpectralError::Config {
            field: "band_bins",
            problem: format!(
                "expected a number of Fourier bins > 0, found {}",
                config.band_bins
            ),
        });
    }
    let kappa0 = config.kappa_start(design);
    let (centres, band) = prior.band_centres(design, config, plans);
    Statistics::new(
        design,
        &centres,
        &band,
        [-kappa0, 16.0 * kappa0],
        config.saturation_counts,
    )
    .map_err(|source| SpectralError::Statistics { source })
}

/// The spectral model's view of a schedule (`frames` in capture order) on
/// `station`'s screen: each frame's τ, phase and direction index, and the
/// fringe axis of every direction.
///
/// # Errors
/// [`SpectralError::Schedule`] when the directions are (nearly) parallel.
pub fn design(station: &Station, frames: &[FrameInfo]) -> Result<Design, SpectralError> {
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
            let (w, h) = (station.screen.width, station.screen.height);
            Axis::from_fringe(&FringeAxis::new(d, w, h), w, h)
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
    Ok(Design::new(metas, axes, directions_deg))
}

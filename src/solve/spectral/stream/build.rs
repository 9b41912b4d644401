//! Building the solver: the schedule's design on the station's screen, the
//! prior's candidates, the engine (series or statistics) and the output
//! arrays prepared on a thread of their own.

use super::{Prepared, SpectralSolver, BLOCK};
use crate::acquire::acquisition::FrameInfo;
use crate::acquire::patterns::FringeAxis;
use crate::optics::station::Station;
use crate::optics::trace::TracedView;
use crate::solve::spectral::model::{Axis, Design, FrameMeta};
use crate::solve::spectral::periodogram::SpectrumPlans;
use crate::solve::spectral::phase::{PhaseSchedule, Response};
use crate::solve::spectral::prior::{nominal_plate_prior, GeometryPrior};
use crate::solve::spectral::statistics::{Statistics, STATS_BLOCK};
use crate::solve::spectral::{Engine, SpectralConfig, SpectralError, SERIES_LIMIT_BYTES};

impl SpectralSolver {
    /// Prepares for `frames` (capture order) of `station`, with the nominal
    /// plate traced through it as the prior ([`nominal_plate_prior`], the rim
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
        let prior = nominal_plate_prior(station, config.edge_margin_mm)?;
        Self::with_design(station, design, config, prior)
    }

    /// Prepares for `frames` (capture order) of `station` with `prior`, the
    /// nominal plate (flat, or wedged as declared) traced through the station ([`nominal_plate_prior`]
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
            spans: spans(&prior.candidates),
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

/// The candidates (increasing camera indices) as spans `(first, length)`
/// of consecutive camera pixels: a frame's candidates are gathered span by
/// span, each one copy.
fn spans(candidates: &[u32]) -> Vec<(usize, usize)> {
    let mut spans: Vec<(usize, usize)> = Vec::new();
    for &p in candidates {
        let p = p as usize;
        match spans.last_mut() {
            Some((first, len)) if *first + *len == p => *len += 1,
            _ => spans.push((p, 1)),
        }
    }
    spans
}

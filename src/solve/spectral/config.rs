//! The spectral stage's settings and errors: which engine keeps the
//! pixels' data ([`Engine`]), the fit's settings ([`SpectralConfig`]) and
//! what can go wrong ([`SpectralError`]).

use super::model::Design;
use super::statistics::StatisticsError;
use crate::formats::npy::NpyError;
use crate::optics::trace::DEFAULT_EDGE_MARGIN_MM;

/// What can go wrong in the spectral stage.
#[derive(Debug, thiserror::Error)]
pub enum SpectralError {
    /// The schedule cannot locate screen points.
    #[error("schedule: {problem}")]
    Schedule {
        /// What is wrong.
        problem: String,
    },
    /// The station's aperture admits no surface (radius not positive or not
    /// finite), so no geometry prior can be traced.
    #[error("the element's aperture: {source}")]
    Aperture {
        /// The Zernike basis's refusal.
        #[source]
        source: crate::optics::zernike::ZernikeError,
    },
    /// The declared wedge sends the back reflection off the screen (or out
    /// through the rim) on most of the element: the station cannot show it.
    #[error(
        "element.wedge_arcmin = {arcmin} (azimuth {azimuth_deg}°): the back reflection of \
         the wedged plate reaches the screen on {seen} camera pixels, against {parallel} \
         for parallel faces; this station cannot show that wedge's back face (a larger \
         screen, a screen closer to the element, or the element turned so that the back \
         reflection comes back onto the screen)"
    )]
    WedgeOffScreen {
        /// The declared wedge, arcmin.
        arcmin: f64,
        /// Its azimuth, degrees.
        azimuth_deg: f64,
        /// Pixels whose back path reaches the screen on the wedged plate.
        seen: usize,
        /// The same for parallel faces.
        parallel: usize,
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
    /// The statistics engine cannot be built for these settings.
    #[error("spectral setting band_bins: {source}")]
    Statistics {
        /// Why.
        #[source]
        source: StatisticsError,
    },
    /// A geometry prior handed in does not describe this station's camera.
    #[error(
        "geometry prior: {width}x{height} pixels ({pixels} traced) for a \
         {camera_width}x{camera_height} camera; trace it through this station \
         (spectral::nominal_plate_prior)"
    )]
    Prior {
        /// Pixels traced in the prior.
        pixels: usize,
        /// Its columns.
        width: usize,
        /// Its rows.
        height: usize,
        /// The camera's columns.
        camera_width: u32,
        /// The camera's rows.
        camera_height: u32,
    },
    /// Writing a map failed.
    #[error(transparent)]
    Npy(#[from] NpyError),
}

impl crate::outcome::Classify for SpectralError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        match self {
            SpectralError::Schedule { .. }
            | SpectralError::Config { .. }
            | SpectralError::Statistics { .. }
            // The element's aperture is the station file's; a frame out
            // of order, missing or of another size is the acquisition's.
            | SpectralError::Aperture { .. }
            | SpectralError::WedgeOffScreen { .. }
            | SpectralError::Frame { .. } => Some(Outcome::Input),
            SpectralError::Npy(e) => e.outcome(),
            // The backend or the prior disagreeing with the solver is a bug.
            SpectralError::Backend { .. } | SpectralError::Prior { .. } => None,
        }
    }
}

/// How the solver keeps the pixels' data between frames and fit (also the
/// command line's `--engine`: `auto`, `series`, `statistics` or `stats`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Engine {
    /// Statistics when the series would exceed [`SERIES_LIMIT_BYTES`], else series.
    #[default]
    Auto,
    /// Every sample (2 bytes per pixel and frame); fits anywhere on the screen.
    Series,
    /// Per-pixel sufficient statistics ([`super::statistics`]): fixed memory per
    /// pixel, fits within a band around the station's prediction.
    #[value(alias = "stats")]
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
    /// The display's response, emitted luminance ∝ level^γ (the `gamma` of
    /// `hw/display/*.toml`), modelled on phase-shifting schedules
    /// ([`super::phase`]); `None`: a linearised display (γ = 1). Long
    /// multi-frequency schedules do not use it.
    pub display_gamma: Option<f64>,
    /// The display's measured response (a display profile's `response`),
    /// modelled on phase-shifting schedules in place of `display_gamma`.
    pub display_response: Option<super::phase::ResponseCurve>,
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
            display_gamma: None,
            display_response: None,
        }
    }
}

impl SpectralConfig {
    /// Starting κ = 1/τ_max²: the configured guess or the schedule's largest τ.
    pub(super) fn kappa_start(&self, design: &Design) -> f64 {
        self.tau_max_guess
            .unwrap_or_else(|| design.frames.iter().map(|f| f.tau).fold(0.0, f64::max))
            .powi(-2)
    }

    /// [`SpectralConfig::kappa_start`] in every falloff group of `design`.
    pub(super) fn falloff_start(&self, design: &Design) -> super::model::Falloff {
        design.uniform_falloff(self.kappa_start(design))
    }
}

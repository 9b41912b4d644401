//! Subcommands of the `mfd` binary.

pub mod bench;
pub mod budget;
pub mod calibrate;
pub mod calibrate_solve;
pub mod check;
pub mod compare;
pub mod compare_interferometer;
pub mod display;
pub mod exit;
pub mod measure;
pub mod output;
pub mod plan;
pub mod reconstruct;
pub mod report;
pub mod serve;
pub mod simulate;
pub mod station;
pub mod surfaces_stage;
pub mod trace;
pub mod tradeoff;

use std::path::Path;

use mfd::optics::station::Station;
use mfd::optics::zernike::ZernikeSurface;
use mfd::solve::spectral::Engine;

/// Front and back surfaces from a `surfaces.json`, or flat surfaces over the
/// station's aperture when none is given. A `null` surface is flat.
pub fn load_surfaces(
    path: Option<&Path>,
    station: &Station,
) -> anyhow::Result<(ZernikeSurface, ZernikeSurface)> {
    Ok(mfd::formats::surfaces_file::surfaces_or_flat(
        path, station,
    )?)
}

/// How the spectral stage keeps and fits the pixels' data: the options
/// `mfd reconstruct` and `mfd measure` share.
#[derive(clap::Args, Clone)]
pub struct SpectralArgs {
    /// How the spectral stage keeps the pixels' data until the fit: series
    /// (every sample, 2 bytes per pixel and frame; points anywhere on the
    /// screen), statistics (~1.5 kB per pixel whatever the frame count,
    /// points within --band-bins of the station's prediction), or auto
    /// (statistics when the series would exceed 2 GiB).
    #[arg(long, value_enum, default_value_t = Engine::Auto, hide_possible_values = true)]
    engine: Engine,
    /// Statistics engine: how many Fourier bins beyond the predicted screen
    /// points (per direction) the kept band reaches.
    #[arg(long, value_parser = self::check::positive, default_value_t = 3.0)]
    band_bins: f64,
    /// Search every pixel's fits from its spectrum, instead of starting
    /// each from its row neighbour's where that one found both points (the
    /// same answers within 0.03σ, 3–4× slower; for scenes with many
    /// discontinuities).
    #[arg(long)]
    search_every_pixel: bool,
    /// Display gamma (emitted luminance ∝ level^γ) modelled on
    /// phase-shifting schedules (a few τ, each at ≥ 3 phase steps); without
    /// it (or --display-profile) the display is taken as linearised.
    #[arg(long, value_parser = self::check::gamma, conflicts_with = "display_profile")]
    display_gamma: Option<f64>,
    /// The display profile (`hw/display/*.toml`) whose measured `response`
    /// (where it has one) or `gamma` is modelled, as --display-gamma.
    #[arg(long, value_parser = profile_response, value_name = "TOML")]
    display_profile: Option<ProfileResponse>,
}

/// What a display profile says of the display's response.
#[derive(Debug, Clone)]
pub struct ProfileResponse {
    gamma: f64,
    curve: Option<mfd::solve::spectral::phase::ResponseCurve>,
}

/// The `gamma` and `response` of a display profile file.
fn profile_response(path: &str) -> Result<ProfileResponse, String> {
    mfd::solve::spectral::phase::profile_response(Path::new(path))
        .map(|(p, curve)| ProfileResponse {
            gamma: p.gamma,
            curve,
        })
        .map_err(|e| e.to_string())
}

impl SpectralArgs {
    /// The default configuration with these options.
    pub fn config(&self) -> mfd::solve::spectral::SpectralConfig {
        mfd::solve::spectral::SpectralConfig {
            engine: self.engine,
            band_bins: self.band_bins,
            warm_starts: !self.search_every_pixel,
            display_gamma: self
                .display_gamma
                .or(self.display_profile.as_ref().map(|p| p.gamma)),
            display_response: self.display_profile.as_ref().and_then(|p| p.curve.clone()),
            ..mfd::solve::spectral::SpectralConfig::default()
        }
    }
}

/// The checks of the spectral stage's points against the noise and the
/// station, shared by `mfd reconstruct` and `mfd measure`.
#[derive(clap::Args, Clone)]
pub struct CheckArgs {
    /// Largest departure of either surface from flat, nm RMS of defocus,
    /// that the check of the screen points against the station allows:
    /// points displaced from the station's nominal-plate prediction by more
    /// than such surfaces (and the station's tolerance) explain flag the
    /// result as inconsistent, and single pixels as far from the station.
    #[arg(long, default_value_t = mfd::pipeline::DEFAULT_MAX_DEPARTURE_NM, value_parser = check::positive)]
    pub max_departure_nm: f64,
    /// The station's own share of that spread (calibration, the element's
    /// placement), screen px.
    #[arg(long, default_value_t = 3.0, value_parser = check::non_negative)]
    pub station_spread_px: f64,
    /// Exit 0 even when the screen points contradict the station (the
    /// result is still flagged in consistency.json and summary.json).
    #[arg(long)]
    pub accept_inconsistent: bool,
    /// Exit 0 even when a stage of the surface solvers stopped at its
    /// iteration limit with a last step larger than its σ (the result is
    /// still flagged in summary.json's "convergence").
    #[arg(long)]
    pub accept_unconverged: bool,
}

impl CheckArgs {
    /// The pipeline's limits.
    pub fn limits(&self) -> mfd::pipeline::Limits {
        mfd::pipeline::Limits {
            max_departure_nm: self.max_departure_nm,
            station_spread_px: self.station_spread_px,
        }
    }
}

/// The pattern schedule flags, shared by every command that shows patterns.
#[derive(clap::Args, Clone)]
pub struct ScheduleArgs {
    /// Fringe directions, degrees, comma-separated (±45 diagonals, 0, 90).
    #[arg(long, value_parser = self::check::range(-360.0, 360.0, "a fringe direction in degrees"), value_delimiter = ',', default_values_t = [45.0, -45.0], allow_hyphen_values = true)]
    pub directions: Vec<f64>,
    /// First τ (fringe periods across the screen).
    #[arg(long, value_parser = self::check::positive, default_value_t = 0.2)]
    pub tau_start: f64,
    /// Last τ.
    #[arg(long, value_parser = self::check::positive, default_value_t = 200.0)]
    pub tau_stop: f64,
    /// τ step.
    #[arg(long, value_parser = self::check::positive, default_value_t = 0.2)]
    pub tau_step: f64,
    /// Phase shifts shown at every τ, radians, comma-separated.
    #[arg(long, value_parser = self::check::finite, value_delimiter = ',', default_values_t = [0.0], allow_hyphen_values = true)]
    pub phases: Vec<f64>,
}

impl ScheduleArgs {
    /// The patterns to show, in order: those of the schedule file `file`
    /// (`mfd-schedule/1`) where one is given, else of these flags; checked
    /// before expansion (frame count, τ against what the station's screen
    /// can show). Shared by `mfd measure` and `mfd simulate`.
    ///
    /// # Errors
    /// The file's or the schedule's error, classed as bad input.
    pub fn patterns(
        &self,
        file: Option<&Path>,
        station: &Station,
    ) -> anyhow::Result<Vec<mfd::acquire::patterns::Pattern>> {
        let (sw, sh) = (station.screen.width, station.screen.height);
        let input = |e: anyhow::Error| exit::classified(exit::Class::Input, e);
        match file {
            Some(p) => {
                let file = mfd::acquire::schedule_file::load(p).map_err(|e| input(e.into()))?;
                file.check_against_screen(p, sw, sh)
                    .map_err(|e| input(e.into()))?;
                Ok(file.patterns())
            }
            None => {
                let schedule = self.schedule();
                schedule.validate().map_err(|e| input(e.into()))?;
                schedule
                    .check_against_screen(sw, sh)
                    .map_err(|e| input(e.into()))?;
                Ok(schedule.patterns())
            }
        }
    }

    /// The schedule these flags describe.
    pub fn schedule(&self) -> mfd::acquire::patterns::Schedule {
        mfd::acquire::patterns::Schedule {
            directions_deg: self.directions.clone(),
            tau_start: self.tau_start,
            tau_stop: self.tau_stop,
            tau_step: self.tau_step,
            phases_rad: self.phases.clone(),
        }
    }
}

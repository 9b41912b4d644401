//! `mfd reconstruct`: every reconstruction stage that exists, from an
//! acquisition folder.

use std::path::PathBuf;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use mfd::acquire::acquisition::Acquisition;
use mfd::optics::station::{Dof, Station, StationUncertainty};
use mfd::optics::trace::DEFAULT_EDGE_MARGIN_MM;
use mfd::pipeline::find_station_uncertainty;
use mfd::pipeline::result_dir::sha256_file;
use mfd::pipeline::{self, Input, InputFile, Inputs, Options, ScreenPoints};
use mfd::solve::spectral::{PixelFlags, SpectralConfig};

/// Arguments of `mfd reconstruct`.
#[derive(Args)]
pub struct ReconstructArgs {
    /// Acquisition folder (mfd-acquisition/1); or give --screen-coords.
    #[arg(required_unless_present = "screen_coords")]
    acquisition: Option<PathBuf>,
    /// Rerun only the surface stage from these screen points
    /// ([rows, columns, 2, 2] float64, spec layout; e.g. from `mfd trace` or
    /// an earlier reconstruction); needs --station.
    #[arg(long, conflicts_with = "acquisition", requires = "station")]
    screen_coords: Option<PathBuf>,
    /// Their standard deviations, same layout; default: screen_cov.npy
    /// ([rows, columns, 4, 4], covariance of u1, v1, u2, v2) or else
    /// screen_std.npy beside --screen-coords when one exists; without
    /// either the scale is estimated from the residuals.
    #[arg(long, requires = "screen_coords")]
    screen_std: Option<PathBuf>,
    /// Output folder: the spectral maps (screen_coords.npy, screen_std.npy,
    /// screen_cov.npy, quality maps, flags.npy) and the surfaces
    /// (surfaces.json, height maps, pictures, summary.json).
    #[arg(long, long_help = out_help())]
    out: PathBuf,
    /// Station file; default: the one the acquisition names.
    #[arg(long)]
    station: Option<PathBuf>,
    /// The station's uncertainty (mfd-station-uncertainty/1, e.g. from
    /// `mfd calibrate solve`); default: station_uncertainty.toml beside the
    /// station file when there is one. Its `station` field must name the
    /// station used. surfaces.json's σ then include the station's
    /// geometry, and summary.json and uncertainty_breakdown.png give each
    /// surface's noise, station and total error and the degrees of freedom
    /// that contribute most (the exact model's sensitivities). Without
    /// one the geometry counts as exact, and the results say so.
    #[arg(long)]
    uncertainty: Option<PathBuf>,
    /// Estimate these degrees of freedom (spec names, comma-separated,
    /// e.g. screen.rz_deg,element.thickness_mm) jointly with the surfaces,
    /// the uncertainty file's σ their prior; writes station_refined.toml
    /// and its uncertainty, and the estimates into summary.json. What the
    /// data pin down (and what not): `mfd budget --json`'s identifiability.
    #[arg(long, value_delimiter = ',', value_parser = parse_dof)]
    refine: Vec<Dof>,
    /// Allow a third reflection (second internal round trip, paper §5.1b).
    #[arg(long)]
    third_reflection: bool,
    /// Exclude samples at or above this count; default: the full scale
    /// (2^b − 1) when the data reach it.
    #[arg(long, value_parser = super::check::positive_int::<u16>)]
    saturation: Option<u16>,
    /// Starting τ_max of the modulation falloff; default: the largest τ.
    #[arg(long, value_parser = super::check::positive)]
    tau_max_guess: Option<f64>,
    /// Fit pixels up to this many camera pixels beyond where the station
    /// predicts the element.
    #[arg(long, value_parser = super::check::int_range(0u32, 4096, "camera pixels beyond the predicted element"), default_value_t = 4)]
    margin_px: u32,
    /// Rim of the element beyond the aperture radius, mm.
    #[arg(long, value_parser = super::check::non_negative, default_value_t = DEFAULT_EDGE_MARGIN_MM)]
    edge_margin_mm: f64,
    /// Only this region of camera pixels: x0,y0,x1,y1 (columns x0..x1, rows y0..y1).
    #[arg(long, value_delimiter = ',')]
    roi: Option<Vec<u32>>,
    #[command(flatten)]
    spectral: super::SpectralArgs,
    #[command(flatten)]
    surfaces: super::surfaces_stage::SurfaceArgs,
    #[command(flatten)]
    checks: super::CheckArgs,
    /// Start from the station's wedge (element.wedge_arcmin, 0 when absent)
    /// without first looking in the frames for where the back reflection
    /// lies. By default a few hundred sample pixels are searched over the
    /// full spectrum first, and a wedge the station does not declare is
    /// measured from (and named), or refused with the wedge seen.
    #[arg(long)]
    keep_station_wedge: bool,
}

/// Runs `mfd reconstruct`.
pub fn run(args: &ReconstructArgs) -> anyhow::Result<()> {
    if args.roi.as_ref().is_some_and(|r| r.len() != 4) {
        return Err(super::exit::usage(anyhow::anyhow!(
            "--roi takes four numbers x0,y0,x1,y1"
        )));
    }
    if let Some(&[x0, y0, x1, y1]) = args.roi.as_deref() {
        anyhow::ensure!(
            x1 > x0 && y1 > y0,
            super::exit::classified(
                super::exit::Class::Input,
                anyhow::anyhow!(
                    "--roi {x0},{y0},{x1},{y1}: an empty or reversed region (columns x0..x1, \
                     rows y0..y1: x1 must exceed x0 and y1 must exceed y0)"
                )
            )
        );
    }
    let surface_opts = args.surfaces.options(args.edge_margin_mm)?;
    let surfaces = (!args.surfaces.no_surfaces).then_some(surface_opts);
    let Some(acq_dir) = &args.acquisition else {
        return from_screen_coords(args, surfaces);
    };
    let mut acq = Acquisition::open(acq_dir)?;
    let station_path = args
        .station
        .clone()
        .unwrap_or_else(|| acq.station_path().to_path_buf());
    let station = Station::load(&station_path)?;
    let station_uncertainty = uncertainty(args, &station_path, &station, surfaces.is_some())?;
    let (estimator, max_expected_nm) = args.surfaces.estimator()?;
    let options = Options {
        spectral: SpectralConfig {
            tau_max_guess: args.tau_max_guess,
            third_reflection: args.third_reflection,
            saturation_counts: args.saturation,
            margin_px: args.margin_px,
            edge_margin_mm: args.edge_margin_mm,
            roi: args.roi.as_ref().map(|r| [r[0], r[1], r[2], r[3]]),
            ..args.spectral.config()
        },
        surfaces,
        station_uncertainty,
        refine: args.refine.clone(),
        estimator,
        max_expected_nm,
        limits: args.checks.limits(),
        wavelength_nm: args.surfaces.wavelength_nm,
        skip_wedge_search: args.keep_station_wedge,
    };
    let bar = ProgressBar::new(acq.frames().len() as u64).with_style(
        ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} frames, {per_sec}, eta {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_message("reading");
    let result = pipeline::reconstruct(
        Input::Acquisition(&mut acq),
        &station,
        &options,
        &mut |done, _| bar.set_position(done as u64),
    );
    bar.finish_and_clear();
    let mut rec = result?;
    let mut inputs = Inputs::new();
    inputs.acquisition = Some(InputFile {
        path: acq_dir.display().to_string(),
        sha256: sha256_file(acq.manifest_path())?,
    });
    inputs.frames = Some(acq.frames().len());
    inputs.station = Some(InputFile::of(&station_path)?);
    inputs.uncertainty =
        uncertainty_path(args, &station_path, options.station_uncertainty.is_some());
    rec.inputs = Some(inputs);
    super::output::write_and_print(&rec, &args.out, &args.checks)
}

/// The surface stage alone, from a screen_coords.npy.
fn from_screen_coords(
    args: &ReconstructArgs,
    surfaces: Option<mfd::solve::surfaces::SurfaceOptions>,
) -> anyhow::Result<()> {
    let (Some(coords_path), Some(station_path)) = (&args.screen_coords, &args.station) else {
        return Err(super::exit::usage(anyhow::anyhow!(
            "give an acquisition folder, or --screen-coords with --station"
        )));
    };
    let station = Station::load(station_path)?;
    let station_uncertainty = uncertainty(args, station_path, &station, surfaces.is_some())?;
    let (points, source) = ScreenPoints::load(coords_path, args.screen_std.as_deref(), &station)?;
    match source {
        Some(p) => println!("uncertainty of the screen points from {}", p.display()),
        None => println!("no screen_std.npy: the residuals set the uncertainty scale"),
    }
    let options = Options {
        surfaces,
        station_uncertainty,
        refine: args.refine.clone(),
        wavelength_nm: args.surfaces.wavelength_nm,
        ..Options::default()
    };
    let mut rec = pipeline::reconstruct(
        Input::ScreenPoints(points),
        &station,
        &options,
        &mut |_, _| {},
    )?;
    let mut inputs = Inputs::new();
    inputs.screen_coords = Some(InputFile::of(coords_path)?);
    inputs.station = Some(InputFile::of(station_path)?);
    inputs.uncertainty =
        uncertainty_path(args, station_path, options.station_uncertainty.is_some());
    rec.inputs = Some(inputs);
    super::output::write_and_print(&rec, &args.out, &args.checks)
}

/// The station's uncertainty: `--uncertainty`, else the calibration's file
/// beside the station file, else none; printed either way. Not looked for
/// when the surface stage does not run.
fn uncertainty(
    args: &ReconstructArgs,
    station_path: &std::path::Path,
    station: &Station,
    surfaces: bool,
) -> anyhow::Result<Option<StationUncertainty>> {
    if !surfaces {
        return Ok(None);
    }
    let found = find_station_uncertainty(station_path, station, args.uncertainty.as_deref())?;
    super::output::print_uncertainty_source(found.as_ref(), station_path);
    Ok(found.map(|f| f.uncertainty))
}

/// The uncertainty file used, with its digest: `--uncertainty`, else the
/// calibration's file beside the station.
fn uncertainty_path(
    args: &ReconstructArgs,
    station_path: &std::path::Path,
    used: bool,
) -> Option<InputFile> {
    if !used {
        return None;
    }
    let path = args
        .uncertainty
        .clone()
        .unwrap_or_else(|| station_path.with_file_name(mfd::pipeline::STATION_UNCERTAINTY_FILE));
    InputFile::of(&path).ok()
}

/// `--out`'s long help: every file, with the flag bits of `flags.npy` from
/// the library's own table.
fn out_help() -> String {
    let bits: Vec<String> = PixelFlags::MEANINGS
        .iter()
        .map(|(bit, meaning)| format!("{} {meaning}", bit.bits()))
        .collect();
    format!(
        "Output folder: screen_coords.npy [rows, cols, 2, 2] (u, v of front and back, screen \
         px, NaN where not found), screen_std.npy (their standard deviations, px), \
         screen_cov.npy [rows, cols, 4, 4] (covariance of u1, v1, u2, v2, px²), amplitudes.npy \
         [rows, cols, 4] (A, B1, B2, B3 in counts), tau_max.npy, residual_rms.npy (counts), \
         separation_bins.npy (front–back separation in Fourier bins), reflections.npy (u8: \
         model chosen, 0–3), flags.npy (u16 bits: {}); then surfaces.json (mfd-surfaces/2: \
         coefficients, their 1σ of everything known, the expected RMS error), \
         front/back_height_nm.npy, front/back.png and *_coefficients.png, \
         uncertainty_breakdown.png (noise and station σ per Zernike term), summary.json.",
        bits.join(", ")
    )
}

/// A degree of freedom by its spec name (`--refine`).
pub(super) fn parse_dof(name: &str) -> Result<Dof, String> {
    Dof::parse(name).ok_or_else(|| {
        format!(
            "\"{name}\" is not a degree of freedom of mfd-station-uncertainty/1 (e.g. {}, {})",
            Dof::Thickness.name(),
            Dof::ScreenRz.name()
        )
    })
}

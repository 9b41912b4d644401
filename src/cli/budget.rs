//! `mfd budget`: the error budget of a station, schedule (or acquisition)
//! and expected surfaces, in the paper's form (§5.1, Tables 1–4), before
//! any frame is taken.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;

use mfd::acquire::acquisition::Acquisition;
use mfd::budget::scene::{self, Radiometry, SceneOptions};
use mfd::budget::{assemble, monte_carlo, picture, table};
use mfd::optics::station::{Station, StationUncertainty};

/// Arguments of `mfd budget`.
#[derive(Args)]
pub struct BudgetArgs {
    /// Station geometry (mfd-station/1 or /2).
    #[arg(long)]
    station: PathBuf,
    /// The station's uncertainty (mfd-station-uncertainty/1).
    #[arg(long)]
    uncertainty: Option<PathBuf>,
    /// A degree of freedom's 1σ by its spec name, e.g. camera.z_mm=0.5
    /// (repeatable; adds to or replaces the file's).
    #[arg(long = "std", value_name = "NAME=SIGMA", value_parser = parse_std)]
    stds: Vec<(String, f64)>,
    /// The patterns to be shown (mfd-schedule/1).
    #[arg(
        long,
        conflicts_with = "acquisition",
        required_unless_present = "acquisition"
    )]
    schedule: Option<PathBuf>,
    /// An acquisition folder (mfd-acquisition/1): its frames are the schedule.
    #[arg(long)]
    acquisition: Option<PathBuf>,
    /// The element's expected surfaces (mfd-surfaces/1 or /2); flat when omitted.
    #[arg(long)]
    surfaces: Option<PathBuf>,
    /// Read noise, fraction of full scale, as `mfd simulate --noise`.
    #[arg(long, value_parser = super::check::noise_fraction, default_value_t = 0.05)]
    noise: f64,
    /// The camera's bits per sample (the station file does not carry it).
    #[arg(long, value_parser = super::check::sim_bit_depth, default_value_t = 16)]
    bit_depth: u32,
    /// Modulation falloff τ_max, as `mfd simulate --tau-max`.
    #[arg(long, value_parser = super::check::positive, default_value_t = 150.0)]
    tau_max: f64,
    /// Ambient light, as `mfd simulate --ambient`.
    #[arg(long, value_parser = super::check::fraction, default_value_t = 0.01)]
    ambient: f64,
    /// Zernike terms per surface, fixed.
    #[arg(long, value_parser = super::check::budget_terms, default_value_t = 36)]
    terms: usize,
    /// The bound is evaluated on blocks of this many pixels square
    /// (default: 1 up to 20000 lit pixels, larger beyond).
    #[arg(long, value_parser = super::check::positive_int::<usize>)]
    bound_stride: Option<usize>,
    /// Write the tables as markdown.
    #[arg(long)]
    markdown: Option<PathBuf>,
    /// Write the tables as CSV.
    #[arg(long)]
    csv: Option<PathBuf>,
    /// Write the budget as JSON.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Draw the budget (PNG): stacked bars per Zernike term.
    #[arg(long)]
    picture: Option<PathBuf>,
    /// Check the linear budget with this many stations drawn from the
    /// covariance, re-traced and reconstructed with the nominal station.
    #[arg(long, value_parser = super::check::positive_int::<usize>, value_name = "N")]
    monte_carlo: Option<usize>,
    /// Seed of the Monte Carlo draws.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

fn parse_std(s: &str) -> Result<(String, f64), String> {
    let (name, value) = s
        .split_once('=')
        .ok_or_else(|| format!("expected NAME=SIGMA (e.g. camera.z_mm=0.5), found `{s}`"))?;
    let v: f64 = value
        .trim()
        .parse()
        .map_err(|_| format!("`{value}` is not a number (in `{s}`)"))?;
    if !(v.is_finite() && v >= 0.0) {
        return Err(format!(
            "`{s}`: a standard deviation must be finite and at least 0"
        ));
    }
    Ok((name.trim().to_string(), v))
}

/// Runs `mfd budget`.
pub fn run(args: &BudgetArgs) -> anyhow::Result<()> {
    check_options(args)?;
    let station = Station::load(&args.station)?;
    let file = match &args.uncertainty {
        Some(p) => {
            let u = StationUncertainty::load(p)?;
            scene::check_station(p, &u.station, &args.station)?;
            Some(u)
        }
        None => None,
    };
    let name = args
        .station
        .file_name()
        .map_or(String::new(), |n| n.to_string_lossy().into_owned());
    let uncertainty = scene::merge_std(file, &args.stds, &name)?;
    let frames = match (&args.schedule, &args.acquisition) {
        (Some(s), _) => scene::load_schedule_for(s, &station).map_err(|e| {
            // A schedule file that is not valid input, as `plan` says.
            super::exit::classified(super::exit::Class::Input, e.into())
        })?,
        (None, Some(a)) => {
            // τ beyond the screen: refused as `reconstruct` refuses it.
            let acq = Acquisition::open(a)?;
            mfd::acquire::acquisition::check_against_station(&acq, &station)?;
            acq.frames().to_vec()
        }
        (None, None) => anyhow::bail!("give --schedule FILE or --acquisition DIR"),
    };
    let opts = SceneOptions {
        radiometry: Radiometry {
            noise_frac: args.noise,
            bit_depth: args.bit_depth,
            ambient: args.ambient,
            tau_max: args.tau_max,
        },
        terms: args.terms,
        bound_stride_px: args.bound_stride,
        ..SceneOptions::default()
    };
    let surfaces = scene::expected_surfaces(args.surfaces.as_deref(), &station)?;
    let start = std::time::Instant::now();
    let sc = scene::scene(&station, surfaces, &frames, &opts)?;
    log::info!(
        "scene: {} pixels traced, bound on {}×{} px blocks, reconstructed in {:.1} s",
        sc.observations.pixels.len(),
        sc.bound_stride_px,
        sc.bound_stride_px,
        start.elapsed().as_secs_f64()
    );
    let b = assemble::budget(
        &sc.observations,
        &station,
        &uncertainty,
        &sc.solution,
        &opts.surface_options(),
    )
    .context("computing the budget's sensitivities")?;
    log::info!(
        "budget of {} degrees of freedom, {} terms, in {:.1} s",
        b.dofs.len(),
        args.terms,
        start.elapsed().as_secs_f64()
    );
    let mc = match args.monte_carlo {
        Some(n) => Some(monte_carlo::monte_carlo(
            &station,
            &uncertainty,
            &sc,
            &opts,
            n,
            args.seed,
        )?),
        None => None,
    };
    let md = table::markdown(&b, mc.as_ref());
    let write = |path: &PathBuf, text: String| {
        std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
    };
    if let Some(p) = &args.markdown {
        write(p, md.clone())?;
    }
    if let Some(p) = &args.csv {
        write(p, table::csv(&b, mc.as_ref()))?;
    }
    if let Some(p) = &args.json {
        write(
            p,
            serde_json::to_string_pretty(&table::json(&b, mc.as_ref()))? + "\n",
        )?;
    }
    if let Some(p) = &args.picture {
        picture::budget_png(&b, p, 15)?;
    }
    if args.markdown.is_none()
        && args.csv.is_none()
        && args.json.is_none()
        && args.picture.is_none()
    {
        print!("{md}");
    }
    Ok(())
}

/// The flags' ranges, each error naming its flag.
fn check_options(args: &BudgetArgs) -> anyhow::Result<()> {
    if args.monte_carlo == Some(0) {
        anyhow::bail!("--monte-carlo 0: expected at least 1 draw");
    }
    if let Some(n) = args.monte_carlo {
        // Refused before the scene is traced: a number out of range.
        monte_carlo::check_draws(n, args.terms)
            .map_err(|e| super::exit::classified(super::exit::Class::Usage, e.into()))?;
    }
    if args.bound_stride == Some(0) {
        anyhow::bail!("--bound-stride 0: expected at least 1 pixel");
    }
    Ok(())
}

//! `mfd simulate`: a simulated acquisition with its truth.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;

use mfd::acquire::acquisition::FrameLayout;
use mfd::formats::surfaces_file::SurfacesFile;
use mfd::optics::station::Station;
use mfd::optics::trace::{Plate, DEFAULT_EDGE_MARGIN_MM};
use mfd::optics::zernike::ZernikeSurface;
use mfd::sim::{
    simulate, simulate_mirror, PhaseShiftParams, RandomSurfaceSpec, SimParams, Simulation,
};

/// Arguments of `mfd simulate`.
#[derive(Args)]
pub struct SimulateArgs {
    /// Station geometry (mfd-station/1).
    #[arg(long)]
    station: PathBuf,
    /// True front and back surfaces (mfd-surfaces/1 or /2); flat when omitted.
    #[arg(long, conflicts_with = "random_surfaces")]
    surfaces: Option<PathBuf>,
    /// Draw random surfaces with this seed instead: Noll terms 4–36 at
    /// 60 nm RMS each face, tilts of 100 nm standard deviation (on the back,
    /// beside the tilts of the wedge the station declares).
    #[arg(long, value_name = "SEED")]
    random_surfaces: Option<u64>,
    /// Output acquisition folder.
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    schedule: super::ScheduleArgs,
    /// Show exactly the patterns of this schedule file (mfd-schedule/1, as
    /// `mfd plan` writes), in its order, instead of the schedule flags.
    #[arg(long = "schedule", value_name = "TOML", conflicts_with_all = ["directions", "tau_start", "tau_stop", "tau_step", "phases"])]
    schedule_file: Option<PathBuf>,
    /// Read noise, standard deviation as a fraction of full scale (0 = exact).
    #[arg(long, value_parser = super::check::fraction, default_value_t = 0.0)]
    noise: f64,
    /// Full-well capacity, electrons at full scale, to add shot noise.
    #[arg(long, value_parser = super::check::positive)]
    full_well: Option<f64>,
    /// Modulation falloff τ_max of exp(−(τ/τ_max)²) (paper Eq. 5).
    #[arg(long, value_parser = super::check::positive, default_value_t = 150.0)]
    tau_max: f64,
    /// What the falloff acts on: tau (every direction alike, the fixtures'
    /// forward model) or screen-period (a plain direction's finer fringes
    /// fall off sooner, as a blur acts; τ_max is the diagonals'). The
    /// model fits a falloff per fringe length and takes either.
    #[arg(long, value_enum, default_value_t = mfd::sim::Falloff::Tau)]
    falloff: mfd::sim::Falloff,
    /// Ambient light, in units of full-white screen radiance.
    #[arg(long, value_parser = super::check::fraction, default_value_t = 0.01)]
    ambient: f64,
    /// Camera counts per unit radiance; default puts the brightest pixel at 90 % of full scale.
    #[arg(long, value_parser = super::check::positive)]
    gain: Option<f64>,
    /// Bits per sample: 8, 12 or 16.
    #[arg(long, value_parser = super::check::sim_bit_depth, default_value_t = 16)]
    bit_depth: u32,
    /// Seed of the camera noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Also render the path with two internal round trips (S3, paper §5.1b).
    #[arg(long)]
    third_reflection: bool,
    /// Factors on the back and third paths' Fresnel weights: 0 models an
    /// AR-coated back face (the front reflection alone).
    #[arg(long, value_parser = super::check::non_negative, default_value_t = 1.0)]
    back_scale: f64,
    /// Write one PNG per frame (frames/NNNNNN.png) instead of one frames.npy stack.
    #[arg(long)]
    png: bool,
    /// Distance of the element's rim beyond the aperture radius, mm.
    #[arg(long, value_parser = super::check::non_negative, default_value_t = DEFAULT_EDGE_MARGIN_MM)]
    edge_margin_mm: f64,
    /// Replace an existing acquisition in --out.
    #[arg(long)]
    overwrite: bool,
    /// Simulate a mirror (the front reflection alone) on a display that is
    /// not linearised, emitted luminance ∝ level^γ, with the blur acting on
    /// every harmonic of the displayed curve (for phase-shifting schedules).
    #[arg(long, value_parser = super::check::gamma, conflicts_with_all = ["gain", "third_reflection"])]
    display_gamma: Option<f64>,
}

/// Runs `mfd simulate`.
pub fn run(args: &SimulateArgs) -> anyhow::Result<()> {
    let station = Station::load(&args.station)?;
    let (front, back) = match args.random_surfaces {
        Some(seed) => random_pair(&station, seed)?,
        None => super::load_surfaces(args.surfaces.as_deref(), &station)?,
    };
    let truth = SurfacesFile::from_surfaces(&front, &back);
    let plate = Plate::new(&station, front, back, args.edge_margin_mm);
    let params = SimParams {
        ambient: args.ambient,
        tau_max: args.tau_max,
        bit_depth: args.bit_depth,
        gain: args.gain,
        noise_frac: args.noise,
        full_well_electrons: args.full_well,
        third_reflection: args.third_reflection,
        path_scale: [1.0, args.back_scale, args.back_scale],
        seed: args.seed,
        falloff: args.falloff,
    };
    let layout = match (args.png, args.bit_depth) {
        (true, 8) => FrameLayout::Png { bit_depth: 8 },
        (true, _) => FrameLayout::Png { bit_depth: 16 },
        (false, 8) => FrameLayout::Stack {
            dtype: mfd::formats::npy::StackDtype::U8,
        },
        (false, _) => FrameLayout::Stack {
            dtype: mfd::formats::npy::StackDtype::U16,
        },
    };
    let patterns = args
        .schedule
        .patterns(args.schedule_file.as_deref(), &station)?;
    let sim = Simulation {
        station: &station,
        plate: &plate,
        truth: &truth,
        patterns: &patterns,
        params,
        layout,
        overwrite: args.overwrite,
    };
    anyhow::ensure!(
        args.display_gamma.is_none() || args.falloff == mfd::sim::Falloff::Tau,
        super::exit::usage(anyhow::anyhow!("--falloff screen-period: the phase-shifting renderer (--display-gamma) has its own falloff; give one or the other"))
    );
    let report = match args.display_gamma {
        Some(gamma) => {
            let phase = PhaseShiftParams {
                gamma,
                luminance: None,
                tau_max: args.tau_max,
                falloff_per_period: Vec::new(),
                ambient: args.ambient,
                bit_depth: args.bit_depth,
                read_noise_counts: args.noise * f64::from((1u32 << args.bit_depth.min(16)) - 1),
                full_well_electrons: args.full_well,
                seed: args.seed,
            };
            simulate_mirror(&sim, phase, &args.out)
        }
        None => simulate(&sim, &args.out),
    }
    .with_context(|| format!("simulating into {}", args.out.display()))?;
    println!(
        "simulated {} frames of {}x{} ({} pixels see the element: front {}, back {}, third {})",
        report.frames,
        station.camera.width,
        station.camera.height,
        report.lit_pixels,
        report.paths[0],
        report.paths[1],
        report.paths[2]
    );
    println!(
        "trace {:.2} s, render {:.2} ms/frame, gain {:.1} counts per unit radiance",
        report.trace_s,
        report.render_s_per_frame * 1e3,
        report.gain
    );
    println!(
        "wrote {} (truth in {})",
        args.out.display(),
        args.out.join("truth").display()
    );
    Ok(())
}

fn random_pair(station: &Station, seed: u64) -> anyhow::Result<(ZernikeSurface, ZernikeSurface)> {
    let e = &station.element;
    let centre = [e.aperture_center_mm.x, e.aperture_center_mm.y];
    let (front, back) =
        RandomSurfaceSpec::default().draw_pair(e.aperture_radius_mm, centre, seed)?;
    // Drawn departures on the plate as made: the declared wedge in the back's tilts.
    Ok((front, e.wedge.added_to(&back)?))
}

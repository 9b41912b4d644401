//! `mfd calibrate solve` (from a session folder to a calibrated station, its
//! uncertainty and a report) and `mfd calibrate simulate` (a whole simulated
//! session, for trying the chain).

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;

use mfd::calibrate::from_session::solve_session;
use mfd::calibrate::simulate::flat::write_flat_acquisition;
use mfd::calibrate::simulate::{example_truth, simulate_session, write_session, SessionSpec};
use mfd::sim::PhaseShiftParams;

/// Arguments of `mfd calibrate solve`.
#[derive(Args)]
pub struct SolveArgs {
    /// The session folder (or its session.toml).
    session: PathBuf,
    /// Where to write station.toml (mfd-station/2), station_uncertainty.toml
    /// (mfd-station-uncertainty/1), report.json and the pictures
    /// (targets.png: each target's reprojection residual;
    /// targets_on_sensor.png: measured and reprojected targets per height;
    /// flat_residuals.png, flat_residuals_v.png: the reference flat's
    /// fringe-map residual in u and v over the sensor).
    #[arg(long)]
    out: PathBuf,
    /// How the reference flat's acquisition is decoded (its display's gamma
    /// or measured response for a phase-shifting schedule: --display-gamma
    /// or --display-profile).
    #[command(flatten)]
    spectral: super::SpectralArgs,
}

/// Runs `mfd calibrate solve`.
pub fn solve(args: &SolveArgs) -> anyhow::Result<()> {
    let solved = solve_session(&args.session, &args.spectral.config())?;
    let f = &solved.flat;
    println!(
        "reference flat: {} frames, {} pixels decoded ({} with two reflections), {} used",
        f.frames, f.decoded, f.two_reflections, f.used
    );
    if solved.given_centroids > 0 {
        println!(
            "{} targets give their centroid (image_px): σ {} px assumed per axis",
            solved.given_centroids,
            mfd::calibrate::from_session::GIVEN_CENTROID_STD_PX
        );
    }
    print!("{}", solved.calibration.report.summary());
    solved
        .calibration
        .write(&args.out)
        .with_context(|| format!("writing the calibration into {}", args.out.display()))?;
    mfd::calibrate::pictures::write_pictures(&solved.calibration, &solved.input, &args.out)?;
    println!(
        "wrote {}/station.toml, station_uncertainty.toml, report.json, targets.png, \
         targets_on_sensor.png, flat_residuals.png, flat_residuals_v.png; measure with \
         `mfd reconstruct ACQ --station {0}/station.toml --uncertainty {0}/station_uncertainty.toml`",
        args.out.display()
    );
    Ok(())
}

/// Arguments of `mfd calibrate simulate`.
#[derive(Args)]
pub struct SimulateArgs {
    /// The session folder to write (session.toml, nominal.toml, targets/,
    /// flat/) and, beside it in truth/, the true station.
    #[arg(long)]
    out: PathBuf,
    /// Seed of every draw.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// 1σ of a stage reading, µm.
    #[arg(long, value_parser = super::check::positive, default_value_t = 1.0)]
    stage_std_um: f64,
    /// Marked screen pixels (`[[screen_point]]`) on an N × N grid over the
    /// screen, read with the stage's noise; 0: none.
    #[arg(long, default_value_t = 0)]
    screen_points: u32,
    /// The display's gamma for the flat's phase-shifting frames.
    #[arg(long, value_parser = super::check::gamma, default_value_t = 2.0)]
    display_gamma: f64,
    /// Bin the true camera's sensor by this factor (the same field of view
    /// and distortion in fewer, larger pixels: a quicker session).
    #[arg(long, value_parser = super::check::positive_int::<u32>, default_value_t = 1)]
    bin: u32,
}

/// Runs `mfd calibrate simulate`.
pub fn simulate(args: &SimulateArgs) -> anyhow::Result<()> {
    let mut truth = example_truth()?;
    if args.bin > 1 {
        let (c, b) = (&mut truth.camera, f64::from(args.bin));
        c.width /= args.bin;
        c.height /= args.bin;
        c.pixel_pitch_mm *= b;
        c.principal_point_px = nalgebra::Point2::from(c.principal_point_px.coords / b);
        truth = mfd::optics::station::Station::from_file(&truth.to_file(), &args.out)?;
    }
    let spec = SessionSpec {
        seed: args.seed,
        stage_std_mm: args.stage_std_um * 1e-3,
        screen_points: [args.screen_points; 2],
        ..SessionSpec::default()
    };
    let session = simulate_session(&truth, &spec)?;
    write_session(&session, &args.out)?;
    let phase = PhaseShiftParams {
        gamma: args.display_gamma,
        seed: args.seed,
        ..PhaseShiftParams::default()
    };
    write_flat_acquisition(
        &truth,
        &session.input.nominal,
        spec.flat_radius_mm,
        phase,
        &args.out,
    )?;
    let truth_dir = args.out.join("truth");
    std::fs::create_dir_all(&truth_dir)?;
    truth.save(&truth_dir.join("station.toml"))?;
    println!(
        "wrote the session {} (reference flat: 32 phase-shifting frames, gamma {}); the true \
         station in {}",
        args.out.display(),
        args.display_gamma,
        truth_dir.display()
    );
    Ok(())
}

//! `mfd calibrate`: making and checking a calibration session
//! (`mfd-calibration/1`): `template`, `targets`, `check`, `capture`, and `solve` / `simulate`
//! (in `calibrate_solve`).

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use clap::{Args, Subcommand};

use mfd::acquire::camera::{CameraConfig, CameraSpec, PixelFormat};
use mfd::calibrate::check::{check, Severity};
use mfd::calibrate::frame::WorldFrame;
use mfd::calibrate::make::{self, PlannedTarget};
use mfd::calibrate::session::{read_file, session_toml};
use mfd::optics::station::Station;
use mfd::sim::{SpotCamera, SpotScene};

/// Arguments of `mfd calibrate`.
#[derive(Args)]
pub struct CalibrateArgs {
    #[command(subcommand)]
    command: CalibrateCommand,
}

/// The steps of a calibration session.
#[derive(Subcommand)]
enum CalibrateCommand {
    /// Write a session folder: session.toml with each step explained, targets/, flat/.
    Template(TemplateArgs),
    /// List target positions to visit, as [[target_point]] stanzas ready to paste.
    Targets(TargetsArgs),
    /// Say what is missing or wrong in a session before solving it.
    Check(CheckArgs),
    /// Grab one target frame from a camera into the session and append its entry.
    Capture(CaptureArgs),
    /// Solve a session: DIR/station.toml (mfd-station/2), station_uncertainty.toml, report.json.
    Solve(super::calibrate_solve::SolveArgs),
    /// Write a whole simulated session (targets, flat points, reference flat) with its truth.
    Simulate(super::calibrate_solve::SimulateArgs),
}

/// Arguments of `mfd calibrate template`.
#[derive(Args)]
struct TemplateArgs {
    /// The session folder to create.
    dir: PathBuf,
    /// A nominal station (mfd-station/1 or /2) to copy in as nominal.toml.
    #[arg(long)]
    nominal: Option<PathBuf>,
}

/// Arguments of `mfd calibrate targets`.
#[derive(Args)]
struct TargetsArgs {
    /// The nominal station.
    #[arg(long)]
    nominal: PathBuf,
    /// Heights above the reference plane, mm, comma-separated (two or more).
    #[arg(long, value_parser = super::check::finite, value_delimiter = ',', default_values_t = [0.0, 20.0, 40.0], allow_hyphen_values = true)]
    heights: Vec<f64>,
    /// Targets per height across and down the sensor.
    #[arg(long, value_parser = super::check::positive_int::<u32>, value_delimiter = ',', default_values_t = [3, 3])]
    grid: Vec<u32>,
    /// A session with 3 or more flat points: positions as its stage
    /// readings (else in the nominal station's world frame).
    #[arg(long)]
    session: Option<PathBuf>,
}

/// Arguments of `mfd calibrate check`.
#[derive(Args)]
struct CheckArgs {
    /// The session folder (or its session.toml).
    session: PathBuf,
}

/// Arguments of `mfd calibrate capture`.
#[derive(Args)]
struct CaptureArgs {
    /// The session folder (or its session.toml).
    session: PathBuf,
    /// The stage reading of the target, mm: X,Y,Z.
    #[arg(
        long,
        value_delimiter = ',',
        allow_hyphen_values = true,
        required = true
    )]
    stage_mm: Vec<f64>,
    /// Camera: `sim` (a simulated target where the nominal station puts
    /// it), `aravis` (first found), `aravis:ID`, `aravis:fake` (the
    /// simulated target behind a GigE Vision fake camera on loopback),
    /// `v4l:/dev/videoN`.
    #[arg(long, default_value = "sim")]
    camera: String,
    /// Exposure time, µs (the device's value when omitted).
    #[arg(long, value_parser = super::check::positive)]
    exposure_us: Option<f64>,
    /// Gain, dB (real cameras).
    #[arg(long, value_parser = super::check::finite)]
    gain_db: Option<f64>,
    /// Longest wait for the frame, ms.
    #[arg(long, value_parser = super::check::positive_int::<u64>, default_value_t = 5000)]
    frame_timeout_ms: u64,
    /// Simulated camera: read noise as a fraction of full scale.
    #[arg(long, value_parser = super::check::fraction, default_value_t = 0.003)]
    sim_noise: f64,
    /// Simulated camera: seed of the noise.
    #[arg(long, default_value_t = 1)]
    sim_seed: u64,
}

/// Runs `mfd calibrate`.
pub fn run(args: &CalibrateArgs) -> anyhow::Result<()> {
    match &args.command {
        CalibrateCommand::Template(a) => template(a),
        CalibrateCommand::Targets(a) => targets(a),
        CalibrateCommand::Check(a) => run_check(a),
        CalibrateCommand::Capture(a) => capture(a),
        CalibrateCommand::Solve(a) => super::calibrate_solve::solve(a),
        CalibrateCommand::Simulate(a) => super::calibrate_solve::simulate(a),
    }
}

fn template(args: &TemplateArgs) -> anyhow::Result<()> {
    let station = match &args.nominal {
        Some(p) => Some((p.as_path(), Station::load(p)?)),
        None => None,
    };
    let path = make::write_template(&args.dir, station.as_ref().map(|(p, s)| (*p, s)))?;
    println!("wrote {} (and targets/, flat/)", path.display());
    if station.is_none() {
        println!(
            "  put the nominal station in as {}",
            args.dir.join("nominal.toml").display()
        );
    }
    println!(
        "  next: fill in [element], then `mfd calibrate check {}`",
        args.dir.display()
    );
    Ok(())
}

fn targets(args: &TargetsArgs) -> anyhow::Result<()> {
    let station = Station::load(&args.nominal)?;
    let frame = match &args.session {
        Some(dir) => {
            let path = session_toml(dir);
            let file = read_file(&path)?;
            let flat: Vec<_> = file
                .flat_point
                .iter()
                .map(|p| nalgebra::Point3::from(p.stage_mm))
                .collect();
            let frame = WorldFrame::from_flat_points(
                &flat,
                file.element.center_stage_mm,
                file.stage_std_um * 1e-3,
            )
            .with_context(|| {
                format!("{}: the world frame needs its flat points", path.display())
            })?;
            Some((frame, file.target_point.len()))
        }
        None => None,
    };
    let grid = match args.grid[..] {
        [n] => (n, n),
        [nx, ny] => (nx, ny),
        _ => {
            return Err(super::exit::usage(anyhow::anyhow!(
                "--grid: expected N or NX,NY"
            )))
        }
    };
    let planned = make::plan_targets(
        &station,
        frame.as_ref().map(|(f, _)| f),
        &args.heights,
        grid,
    )
    .map_err(|e| match e {
        // A number out of range on the command line.
        make::MakeError::Grid { .. } => {
            super::exit::classified(super::exit::Class::Usage, e.into())
        }
        e => e.into(),
    })?;
    let first = frame.as_ref().map_or(0, |(_, n)| *n);
    print!("{}", stanzas(&planned, first, frame.is_some()));
    Ok(())
}

/// The planned targets as TOML ready to paste, numbered from `first`.
fn stanzas(planned: &[PlannedTarget], first: usize, in_stage: bool) -> String {
    let mut out = format!(
        "# {} target positions, {}; each lands where `# px` says on the nominal sensor.\n",
        planned.len(),
        if in_stage {
            "as stage readings of this session's frame"
        } else {
            "in the nominal world frame (stage = world until the session has flat points: pass --session)"
        }
    );
    // A reading that rounds to zero is written as 0.000, not −0.000.
    let mm = |x: f64| if (x * 1000.0).round() == 0.0 { 0.0 } else { x };
    for (k, t) in planned.iter().enumerate() {
        let s = t.stage_mm.map(mm);
        out.push_str(&format!(
            "\n[[target_point]]  # px ({:.0}, {:.0}), world z {:.1} mm\nstage_mm = [{:.3}, {:.3}, {:.3}]\nimage = \"targets/{:03}.png\"\n",
            t.expected_px.x,
            t.expected_px.y,
            t.world_mm.z,
            s.x,
            s.y,
            s.z,
            first + k
        ));
    }
    out
}

fn run_check(args: &CheckArgs) -> anyhow::Result<()> {
    let report = check(&args.session);
    for f in &report.findings {
        let tag = match f.severity {
            Severity::Error => "error",
            Severity::Warning => "warning",
            Severity::Note => "note",
        };
        match &f.entry {
            Some(e) => println!("{tag}: [{e}] {}", f.message),
            None => println!("{tag}: {}", f.message),
        }
    }
    for t in report.targets.iter().filter(|t| t.found_px.is_some()) {
        let (f, p) = (t.found_px.unwrap_or_default(), t.predicted_px);
        let pred = p.map_or("behind the camera".to_string(), |p| {
            format!("({:.1}, {:.1}) px", p.x, p.y)
        });
        println!(
            "target {:3}: spot ({:.2}, {:.2}) px, nominal {pred}",
            t.index, f.x, f.y
        );
    }
    let (e, w) = (
        report.count(Severity::Error),
        report.count(Severity::Warning),
    );
    println!(
        "{}: {e} error(s), {w} warning(s){}",
        report.path.display(),
        if report.ready() {
            "; ready to solve"
        } else {
            ""
        }
    );
    // The findings name the entries at fault: a session not ready to
    // solve is input that is not valid yet (exit 3).
    anyhow::ensure!(
        report.ready(),
        super::exit::input(anyhow::anyhow!(
            "{e} errors in the session: fix them, then check again"
        ))
    );
    Ok(())
}

fn capture(args: &CaptureArgs) -> anyhow::Result<()> {
    let stage: [f64; 3] = args
        .stage_mm
        .as_slice()
        .try_into()
        .ok()
        .filter(|s: &[f64; 3]| s.iter().all(|v| v.is_finite()))
        .ok_or_else(|| {
            super::exit::usage(anyhow::anyhow!(
                "--stage-mm: expected three finite numbers X,Y,Z in mm"
            ))
        })?;
    let spec: CameraSpec = args.camera.parse()?;
    let mut camera = if spec.is_simulated() {
        mfd::live::camera::open_for_target(&spec, simulated_target(args, stage)?)?
    } else {
        mfd::live::camera::open(&spec, None)?
    };
    let config = CameraConfig {
        exposure_us: args.exposure_us,
        gain_db: args.gain_db,
        ..CameraConfig::default()
    };
    let timeout = Duration::from_millis(args.frame_timeout_ms);
    let got = make::capture_target(&args.session, stage, camera.as_mut(), &config, timeout)?;
    println!(
        "target_point[{}]: wrote {} and appended its entry",
        got.index, got.image
    );
    match (&got.centroid, got.predicted_px) {
        (Ok(c), p) => {
            let s = c.std_px();
            println!(
                "  spot at ({:.2} ± {:.2}, {:.2} ± {:.2}) px, peak {:.0} counts over {:.0}, noise {:.1}",
                c.position_px.x, s[0], c.position_px.y, s[1], c.peak_counts, c.background_counts, c.noise_counts
            );
            if let Some(p) = p {
                println!(
                    "  the nominal station puts it at ({:.1}, {:.1}) px, {:.1} px away",
                    p.x,
                    p.y,
                    (p - c.position_px).norm()
                );
            }
            if c.saturated_px > 0 {
                log::warn!(
                    "{} saturated pixels in the spot: lower the exposure and capture again",
                    c.saturated_px
                );
            }
        }
        (Err(e), _) => log::warn!("{e}"),
    }
    Ok(())
}

/// The simulated target camera: a spot where the nominal station images
/// the reading (through the session's frame when it has flat points, else
/// at the sensor's centre).
fn simulated_target(args: &CaptureArgs, stage: [f64; 3]) -> anyhow::Result<SpotCamera> {
    let path = session_toml(&args.session);
    let file = read_file(&path)?;
    let dir = path.parent().map(PathBuf::from).unwrap_or_default();
    let station = Station::load(&dir.join(&file.nominal_station))?;
    let cam = &station.camera;
    let flat: Vec<_> = file
        .flat_point
        .iter()
        .map(|p| nalgebra::Point3::from(p.stage_mm))
        .collect();
    let centre = WorldFrame::from_flat_points(
        &flat,
        file.element.center_stage_mm,
        file.stage_std_um * 1e-3,
    )
    .ok()
    .and_then(|f| cam.project(&f.to_world(&nalgebra::Point3::from(stage))))
    .unwrap_or(nalgebra::Point2::new(
        f64::from(cam.width) / 2.0,
        f64::from(cam.height) / 2.0,
    ));
    let full = f64::from(u16::MAX);
    anyhow::ensure!(
        (0.0..0.5).contains(&args.sim_noise),
        super::exit::usage(anyhow::anyhow!(
            "--sim-noise {}: expected a fraction in [0, 0.5)",
            args.sim_noise
        ))
    );
    let scene = SpotScene {
        resolution: (cam.width, cam.height),
        bit_depth: PixelFormat::Mono16.bit_depth(),
        centre_px: Some(centre),
        sigma_px: 1.5,
        peak_counts: 0.5 * full,
        ambient_counts: 0.05 * full,
        gradient_counts_per_px: [0.0, 0.0],
        noise_counts: args.sim_noise * full,
    };
    Ok(SpotCamera::new(scene, args.sim_seed))
}

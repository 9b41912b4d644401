//! `mfd plan`: a schedule's predicted accuracy, separability, ambiguity and
//! acquisition time before any frame is taken; or, with a budget (`--frames`,
//! `--time-s`, `--target-nm`), the schedule designed for it.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;

use mfd::acquire::acquisition::FrameInfo;
use mfd::acquire::schedule_file;
use mfd::budget::scene::Radiometry;
use mfd::optics::station::{DisplayProfile, Station};
use mfd::plan::{self, Budget, DesignOptions, PlanOptions, Prediction, Timing};

/// Arguments of `mfd plan`.
#[derive(Args)]
pub struct PlanArgs {
    /// Station geometry (mfd-station/1 or /2).
    #[arg(long)]
    station: PathBuf,
    /// The schedule to predict (mfd-schedule/1); without it and without a
    /// budget, the schedule flags below.
    #[arg(long, conflicts_with_all = ["frames", "time_s", "target_nm"])]
    schedule: Option<PathBuf>,
    #[command(flatten)]
    flags: super::ScheduleArgs,
    /// Design a schedule of this many frames.
    #[arg(long, value_parser = super::check::positive_int::<usize>, conflicts_with_all = ["time_s", "target_nm"])]
    frames: Option<usize>,
    /// Design a schedule that takes at most this many seconds.
    #[arg(long, value_parser = super::check::positive, conflicts_with = "target_nm")]
    time_s: Option<f64>,
    /// Design the shortest schedule whose predicted RMS error of both
    /// surfaces is at most this, nm.
    #[arg(long, value_parser = super::check::positive)]
    target_nm: Option<f64>,
    /// Where the designed schedule is written (mfd-schedule/1); needed with a budget.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write the prediction as JSON (`frames`, `seconds`, `predicted.front_rms_nm`, ...).
    #[arg(long)]
    json: Option<PathBuf>,
    /// Read noise, fraction of full scale, as `mfd simulate --noise`.
    #[arg(long, value_parser = super::check::noise_fraction, default_value_t = 0.05)]
    noise: f64,
    /// Modulation falloff τ_max, as `mfd simulate --tau-max`.
    #[arg(long, value_parser = super::check::positive, default_value_t = 150.0)]
    tau_max: f64,
    /// The camera's bits per sample.
    #[arg(long, value_parser = super::check::sim_bit_depth, default_value_t = 16)]
    bit_depth: u32,
    /// Ambient light, as `mfd simulate --ambient`.
    #[arg(long, value_parser = super::check::fraction, default_value_t = 0.01)]
    ambient: f64,
    /// Zernike terms per surface.
    #[arg(long, value_parser = super::check::budget_terms, default_value_t = 36)]
    terms: usize,
    /// The element's thickness, mm (default: the station's).
    #[arg(long, value_parser = super::check::positive)]
    thickness_mm: Option<f64>,
    /// The element's refractive index (default: the station's).
    #[arg(long, value_parser = super::check::refractive_index)]
    index: Option<f64>,
    /// Expected departure of either surface from flat, nm RMS (sets the prior's spread).
    #[arg(long, value_parser = super::check::positive, default_value_t = 200.0)]
    surface_nm: f64,
    /// The station's share of the prior's spread (calibration, placement), screen px.
    #[arg(long, value_parser = super::check::non_negative, default_value_t = 3.0)]
    station_spread_px: f64,
    /// Factor on the back reflection's weight: 0 for an AR-coated back.
    #[arg(long, value_parser = super::check::non_negative, default_value_t = 1.0)]
    back_scale: f64,
    /// Display profile (hw/display/*.toml) whose settle time is used
    /// (default: 30 ms, the paper's LCD).
    #[arg(long)]
    display_profile: Option<PathBuf>,
    /// The display's refresh rate, Hz.
    #[arg(long, value_parser = super::check::positive, default_value_t = 60.0)]
    display_rate_hz: f64,
    /// The camera's exposure, ms.
    #[arg(long, value_parser = super::check::positive, default_value_t = 10.0)]
    exposure_ms: f64,
    /// The camera's largest frame rate, Hz.
    #[arg(long, value_parser = super::check::positive, default_value_t = 30.0)]
    camera_rate_hz: f64,
    /// The spectral stage's engine the schedule will be reconstructed with
    /// (as `mfd reconstruct --engine`): the planner runs that stage on
    /// sample pixels (auto: statistics when the series would exceed 2 GiB).
    #[arg(long, value_enum, default_value_t = mfd::solve::spectral::Engine::Auto, hide_possible_values = true)]
    engine: mfd::solve::spectral::Engine,
    /// The statistics engine's band, Fourier bins beyond the predicted
    /// points (as `mfd reconstruct --band-bins`).
    #[arg(long, value_parser = super::check::positive, default_value_t = 3.0)]
    band_bins: f64,
    /// Largest candidate τ of a design (default 2 τ_max).
    #[arg(long, value_parser = super::check::positive)]
    tau_hi: Option<f64>,
    /// Fringe directions a design may use, degrees, comma-separated; the
    /// design weighs each (`--directions` sets the schedule predicted
    /// without a budget). 0 and 90 see the reflections' separation along
    /// the screen's axes where the diagonals see √½ of it; the model fits
    /// a falloff per fringe length, so they hold whether a blur acts on τ
    /// or on the screen period (docs/figures.md, "Planned schedules").
    #[arg(long, value_parser = super::check::range(-360.0, 360.0, "a fringe direction in degrees"), value_delimiter = ',', default_values_t = [45.0, -45.0, 0.0, 90.0], allow_hyphen_values = true)]
    design_directions: Vec<f64>,
}

/// Runs `mfd plan`.
pub fn run(args: &PlanArgs) -> anyhow::Result<()> {
    let mut station = Station::load(&args.station)?;
    if let Some(t) = args.thickness_mm {
        anyhow::ensure!(
            t.is_finite() && t > 0.0,
            "--thickness-mm {t}: expected a thickness > 0 mm"
        );
        station.element.thickness_mm = t;
    }
    if let Some(n) = args.index {
        anyhow::ensure!(
            n.is_finite() && n > 1.0,
            "--index {n}: expected a refractive index > 1"
        );
        station.element.refractive_index = n;
    }
    let opts = plan_options(args)?;
    let start = std::time::Instant::now();
    let budget = match (args.frames, args.time_s, args.target_nm) {
        (Some(n), _, _) => Some(Budget::Frames(n)),
        (_, Some(t), _) => Some(Budget::Seconds(t)),
        (_, _, Some(x)) => Some(Budget::TargetNm(x)),
        _ => None,
    };
    if let Some(b) = budget {
        // A budget above the frames a schedule may have, or than memory
        // holds: refused before anything is designed, as out of range.
        plan::design::budget_frames(b, &opts.timing)
            .map_err(|e| super::exit::classified(super::exit::Class::Usage, e.into()))?;
    }
    let (prediction, extra) = match budget {
        Some(b) => {
            let dopts = DesignOptions {
                plan: opts,
                directions_deg: args.design_directions.clone(),
                tau_hi: args.tau_hi,
                ..DesignOptions::default()
            };
            let d = plan::design(&station, b, &dopts)?;
            let out = args
                .out
                .as_ref()
                .context("--out is needed to write the designed schedule")?;
            let comment = format!(
                "Designed by `mfd plan` for {b:?} on {}: {} frames, {:.1} s, predicted RMS front {:.2} nm, back {}.",
                args.station.display(),
                d.frames.len(),
                d.prediction.seconds,
                d.prediction.front.rms_nm,
                d.prediction.back.as_ref().map_or("not measured".into(), |b| format!("{:.2} nm", b.rms_nm)),
            );
            schedule_file::write(out, &d.frames, &comment)?;
            println!("wrote {} ({} frames)", out.display(), d.frames.len());
            let extra = serde_json::json!({
                "design": {
                    "uniform_share": d.uniform_share,
                    "start_tau_max": d.start_tau_max,
                    "efficiency": d.efficiency,
                    "criterion_px2": d.criterion_px2,
                    "distinct_taus": distinct_taus(&d.frames),
                }
            });
            (d.prediction, Some(extra))
        }
        None => {
            // The schedule checked as `measure` and `simulate` check it:
            // frame count, then τ against what the screen can show.
            let patterns = args.flags.patterns(args.schedule.as_deref(), &station)?;
            let frames = FrameInfo::from_patterns(&patterns);
            (plan::predict(&station, &frames, &opts)?, None)
        }
    };
    print_summary(&prediction);
    if let Some(e) = &extra {
        println!("design: {}", e["design"]);
    }
    println!("planned in {:.1} s", start.elapsed().as_secs_f64());
    if let Some(p) = &args.json {
        let mut j = prediction.json();
        if let (Some(obj), Some(serde_json::Value::Object(e))) = (j.as_object_mut(), extra) {
            obj.extend(e);
        }
        std::fs::write(p, serde_json::to_string_pretty(&j)? + "\n")
            .with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(())
}

fn plan_options(args: &PlanArgs) -> anyhow::Result<PlanOptions> {
    let timing = match &args.display_profile {
        Some(p) => Timing::with_profile(&DisplayProfile::load(p)?),
        None => Timing::default(),
    };
    let opts = PlanOptions {
        radiometry: Radiometry {
            noise_frac: args.noise,
            bit_depth: args.bit_depth,
            ambient: args.ambient,
            tau_max: args.tau_max,
        },
        terms: args.terms,
        back_scale: args.back_scale,
        surface_nm: args.surface_nm,
        station_spread_px: args.station_spread_px,
        timing: Timing {
            display_rate_hz: args.display_rate_hz,
            exposure_ms: args.exposure_ms,
            camera_rate_hz: args.camera_rate_hz,
            ..timing
        },
        bound_stride_px: None,
        spectral: mfd::solve::spectral::SpectralConfig {
            engine: args.engine,
            band_bins: args.band_bins,
            ..mfd::solve::spectral::SpectralConfig::default()
        },
    };
    opts.validate()?;
    Ok(opts)
}

fn distinct_taus(frames: &[FrameInfo]) -> usize {
    let mut t: Vec<(u64, u64)> = frames
        .iter()
        .map(|f| (f.direction_deg.to_bits(), f.tau.to_bits()))
        .collect();
    t.sort_unstable();
    t.dedup();
    t.len()
}

fn print_summary(p: &Prediction) {
    println!(
        "{} frames ({} patterns shown), {:.1} s of acquisition",
        p.frames, p.patterns_shown, p.seconds
    );
    let bound = match p.bound {
        mfd::plan::BoundKind::PerPixel => "per-pixel bound",
        mfd::plan::BoundKind::SurfaceDomain => "surface-domain bound",
    };
    println!(
        "predicted RMS error (Cramér–Rao, {bound}; reflections {:.2} bins apart): front {:.3} nm",
        p.separation_bins, p.front.rms_nm
    );
    match (&p.back, &p.back_not_measured_because) {
        (Some(b), _) => println!(
            "                                           back  {:.3} nm",
            b.rms_nm
        ),
        (None, Some(why)) => println!("back not measured: {why}"),
        (None, None) => println!("back not measured"),
    }
    let s = &p.separation;
    println!(
        "separable on {:.0} % of {} two-reflection pixels (median separation {:.1} px): {}",
        100.0 * s.separable_fraction,
        s.pixels,
        s.median_separation_px,
        if s.separable { "yes" } else { "no" }
    );
    let a = &p.ambiguity;
    for d in &a.directions {
        println!(
            "direction {:+.0}°: main lobe ±{:.1} px, unambiguous range {}",
            d.direction_deg,
            d.main_lobe_px,
            match (d.unambiguous_range_px, d.false_maximum_height) {
                (Some(r), Some(h)) => format!("{r:.1} px (a false maximum of height {h:.2})"),
                (Some(r), None) => format!("{r:.1} px"),
                _ => "the whole screen".into(),
            }
        );
    }
    println!(
        "prior spread {:.1} px: start {} (spectral start found on {:.0} % of sample pixels)",
        a.prior_spread_px,
        if a.unambiguous {
            "unambiguous"
        } else {
            "AMBIGUOUS"
        },
        100.0 * a.start_found_fraction
    );
    let st = &p.stage;
    // Where the surface-domain fit makes the surfaces it takes the pixels
    // with fringes; the stage's own points are only its start.
    let detected = if p.bound == plan::BoundKind::SurfaceDomain {
        format!(
            "fringes detected on {:.0} % (the surface-domain fit's pixels), true points found per pixel",
            100.0 * (1.0 - st.no_signal_fraction)
        )
    } else {
        "true points found".to_string()
    };
    let rows = st.found_fraction_in_rows.map_or(String::new(), |f| {
        format!(
            ", {:.0} % along camera rows (each pixel started from its neighbour's fit)",
            100.0 * f
        )
    });
    println!(
        "spectral stage ({} engine) on {} sample pixels at this noise: {detected} on {:.0} % \
         searched{rows}",
        st.engine,
        st.pixels,
        100.0 * st.found_fraction,
    );
    if p.bound == mfd::plan::BoundKind::SurfaceDomain {
        let c = &p.convergence;
        for d in &c.directions {
            println!(
                "direction {:+.0}°: the surface-domain fit converges from ±{:.1} px of the truth{} (one reflection)",
                d.direction_deg,
                d.basin_px,
                if d.basin_px >= 2.0 * c.prior_spread_px {
                    " or more"
                } else {
                    ""
                }
            );
        }
        println!(
            "the surface-domain fit's iteration from the flat plate reaches the truth on {:.0} % of the sample pixels (needs {:.0} %)",
            100.0 * c.pixel_fraction,
            100.0 * mfd::plan::converge::PIXEL_FRACTION
        );
    }
    if let Some(why) = &p.not_measurable_because {
        println!("NOT MEASURABLE: {why}");
    }
}

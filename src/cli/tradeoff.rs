//! `mfd tradeoff`: speed against accuracy, measured. The simulated station
//! over a grid of schedules (frames per direction), Zernike term counts and
//! iteration limits; surface errors against the truth, the solver's own
//! uncertainty, and compute time; a CSV, a markdown table and a plot.
//! With `--designed`, also the schedules `mfd plan` designs for the same
//! frame budgets (predicted bound, achieved error, acquisition time).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use clap::Args;

use mfd::acquire::acquisition::FrameInfo;
use mfd::optics::station::Station;
use mfd::optics::trace::{Plate, TracedView};
use mfd::optics::zernike::ZernikeSurface;
use mfd::sim::RandomSurfaceSpec;

mod designed;
mod output;
mod row;
mod solve;

use designed::designed_rows;
use output::write_outputs;
use row::Row;
use solve::{spectral, surfaces, uniform, Render};

/// Arguments of `mfd tradeoff`.
#[derive(Args)]
pub struct TradeoffArgs {
    /// Station; default: the 48×48 bench station (10 mm, n = 1.5), whose
    /// every pixel samples the Ø 51 mm aperture, so a grid runs in minutes.
    #[arg(long)]
    station: Option<PathBuf>,
    /// Frames per direction (τ from 0.5 in steps of 0.5: τ_stop = 0.5 N).
    #[arg(long, value_parser = super::check::positive_int::<usize>, value_delimiter = ',', default_value = "50,100,200,400")]
    frames: Vec<usize>,
    /// Zernike terms per surface.
    #[arg(long, value_parser = super::check::terms, value_delimiter = ',', default_value = "15,36,66")]
    terms: Vec<usize>,
    /// Iteration limits (spectral and surface Levenberg–Marquardt alike).
    #[arg(long, value_parser = super::check::positive_int::<usize>, value_delimiter = ',', default_value = "3,30")]
    max_iter: Vec<usize>,
    /// Read noise, fraction of full scale.
    #[arg(long, value_parser = super::check::non_negative, default_value_t = 0.02)]
    noise: f64,
    /// Seed of the surfaces (36 terms, 60 nm RMS) and the noise.
    #[arg(long, default_value_t = 5)]
    seed: u64,
    /// Output folder: tradeoff.csv, tradeoff.md, tradeoff.png.
    #[arg(long)]
    out: PathBuf,
    /// Also a schedule designed by `mfd plan` for each frame budget (the
    /// same frames in total), at the largest term count and iteration
    /// limit; its note gives the predicted bound and the acquisition time.
    #[arg(long)]
    designed: bool,
    /// Noise seeds of each designed row (the surfaces stay those of
    /// --seed): the achieved error is the RMS over them; default: --seed.
    #[arg(long, value_delimiter = ',')]
    seeds: Vec<u64>,
    /// What the rendered falloff acts on, as `mfd simulate --falloff`:
    /// tau (every direction alike) or screen-period (a blur's: a plain
    /// direction's finer fringes fall off sooner).
    #[arg(long, value_enum, default_value_t = mfd::sim::Falloff::Tau)]
    falloff: mfd::sim::Falloff,
}

/// Runs `mfd tradeoff`.
pub fn run(args: &TradeoffArgs) -> anyhow::Result<()> {
    let station = match &args.station {
        Some(p) => Station::load(p)?,
        None => mfd::optics::station::bench_station(10.0, 1.5, 15.0)?,
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let e = &station.element;
    let centre = [e.aperture_center_mm.x, e.aperture_center_mm.y];
    let (front, back) =
        RandomSurfaceSpec::default().draw_pair(e.aperture_radius_mm, centre, args.seed)?;
    let view = TracedView::trace(
        &station,
        &Plate::new(&station, front.clone(), back.clone(), 3.0),
    );
    let mut rows = Vec::new();
    uniform_rows(&station, &view, (&front, &back), args, &mut rows)?;
    if args.designed {
        designed_rows(&station, &view, (&front, &back), args, &mut rows)?;
    }
    write_outputs(&rows, args)
}

/// The rows of the uniform family: every frame count, iteration limit and
/// term count, each with the planner's prediction of its schedule.
fn uniform_rows(
    station: &Station,
    view: &TracedView,
    truth: (&ZernikeSurface, &ZernikeSurface),
    args: &TradeoffArgs,
    rows: &mut Vec<Row>,
) -> anyhow::Result<()> {
    let mut popts = mfd::plan::PlanOptions::default();
    popts.radiometry.noise_frac = args.noise;
    for &n in &args.frames {
        let frames = FrameInfo::from_patterns(&uniform(n).patterns());
        let acquisition_s = popts.timing.seconds(&frames);
        for &it in &args.max_iter {
            let t = Instant::now();
            let solved = spectral(station, view, n, it, args.render(), args.seed)?;
            let spectral_s = t.elapsed().as_secs_f64();
            for &terms in &args.terms {
                let mut row = surfaces(station, &solved, truth, (n, terms, it), spectral_s);
                row.acquisition_s = acquisition_s;
                let p = mfd::plan::predict(
                    station,
                    &frames,
                    &mfd::plan::PlanOptions {
                        terms,
                        ..popts.clone()
                    },
                )?;
                row.predicted_nm = [
                    p.front.rms_nm,
                    p.back.as_ref().map_or(f64::NAN, |b| b.rms_nm),
                ];
                row.measurable = p.not_measurable_because.is_none();
                if !row.measurable {
                    row.note = format!("PLANNER: not measurable; {}", row.note);
                }
                rows.push(row);
                let r = rows.last().expect("just pushed");
                eprintln!(
                    "frames/dir {n}, terms {terms}, max_iter {it}: front {:.2} nm, back {:.2} nm, {:.1} s {}",
                    r.error_nm[0], r.error_nm[1], r.spectral_s + r.surfaces_s, r.note
                );
            }
        }
    }
    Ok(())
}

impl TradeoffArgs {
    /// How the frames are rendered: `--noise`, `--falloff`.
    fn render(&self) -> Render {
        Render {
            noise: self.noise,
            falloff: self.falloff,
        }
    }
}

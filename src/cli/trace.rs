//! `mfd trace`: the ideal screen coordinates of a station and scene.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use clap::Args;

use mfd::formats::npy;
use mfd::optics::station::Station;
use mfd::optics::trace::{Plate, TracedView, DEFAULT_EDGE_MARGIN_MM};

/// Arguments of `mfd trace`.
#[derive(Args)]
pub struct TraceArgs {
    /// Station geometry (mfd-station/1).
    #[arg(long)]
    station: PathBuf,
    /// Front and back surfaces (mfd-surfaces/1 or /2); flat surfaces when omitted.
    #[arg(long)]
    surfaces: Option<PathBuf>,
    /// Output folder: screen_coords.npy [rows, cols, 2, 2] (u, v of front and
    /// back, NaN where a path does not exist), screen_coords_s3.npy [rows, cols, 2]
    /// (second internal round trip), fresnel_weights.npy [rows, cols, 3] and
    /// path_status.npy [rows, cols, 3] (u8: 0 hit, 1 misses the element,
    /// 2 leaves through the rim, 3 total internal reflection, 4 no convergence,
    /// 5 never reaches the screen plane, 6 lands off the screen).
    #[arg(long)]
    out: PathBuf,
    /// Distance of the element's physical rim beyond the aperture radius, mm:
    /// paths touching a surface beyond it are lost.
    #[arg(long, value_parser = super::check::non_negative, default_value_t = DEFAULT_EDGE_MARGIN_MM)]
    edge_margin_mm: f64,
}

/// Runs `mfd trace`.
pub fn run(args: &TraceArgs) -> anyhow::Result<()> {
    let station = Station::load(&args.station)?;
    let (front, back) = super::load_surfaces(args.surfaces.as_deref(), &station)?;
    let plate = Plate::new(&station, front, back, args.edge_margin_mm);
    let start = Instant::now();
    let view = TracedView::trace(&station, &plate);
    let elapsed = start.elapsed().as_secs_f64();
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let (h, w) = (view.height, view.width);
    let out = |name: &str| args.out.join(name);
    npy::write_f64(
        &out("screen_coords.npy"),
        &[h, w, 2, 2],
        &view.screen_coords(),
    )?;
    npy::write_f64(
        &out("screen_coords_s3.npy"),
        &[h, w, 2],
        &view.third_coords(),
    )?;
    npy::write_f64(&out("fresnel_weights.npy"), &[h, w, 3], &view.weights())?;
    npy::write_u8(&out("path_status.npy"), &[h, w, 3], &view.status())?;
    println!(
        "traced {w}x{h} pixels in {elapsed:.2} s: front {}, back {}, third {} pixels",
        view.count(0),
        view.count(1),
        view.count(2)
    );
    if let Some(st) = view.offset_stats() {
        let [lo, med, hi] = st.min_median_max_px;
        // Separation in Fourier bins of the paper's schedule: a ±45° fringe
        // spans L = (W + H)/√2 screen px, and τ 0.2…200 resolves 1/199.8 in s.
        let l = (f64::from(station.screen.width) + f64::from(station.screen.height))
            / std::f64::consts::SQRT_2;
        println!(
            "S2 - S1: min {lo:.2} / median {med:.2} / max {hi:.2} screen px \
             (median {:.2} mm; ~{:.2} Fourier bins of the paper's ±45° schedule along a diagonal)",
            med * station.screen.pixel_pitch_mm,
            med / std::f64::consts::SQRT_2 / l * 199.8
        );
    }
    println!("wrote {}", out("screen_coords.npy").display());
    Ok(())
}

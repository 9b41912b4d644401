//! `mfd bench thickness`: the spectral stage's error against the
//! Cramér–Rao bound over plate thickness and refractive index.

use clap::Args;

use mfd::acquire::acquisition::FrameInfo;
use mfd::acquire::patterns::Schedule;
use mfd::optics::station::Station;
use mfd::optics::trace::{Plate, TracedView};
use mfd::sim::{RandomSurfaceSpec, Renderer, SimParams};
use mfd::solve::spectral::bound::two_reflection_bound;
use mfd::solve::spectral::{PixelFlags, SpectralConfig, SpectralSolver};

/// Arguments of `mfd bench thickness`.
#[derive(Args)]
pub struct TableArgs {
    /// Plate thicknesses, mm.
    #[arg(long, value_parser = crate::cli::check::positive, value_delimiter = ',', default_values_t = [1.0, 2.0, 3.0, 5.0, 10.0, 30.0])]
    thickness_mm: Vec<f64>,
    /// Refractive indices.
    #[arg(long, value_parser = crate::cli::check::refractive_index, value_delimiter = ',', default_values_t = [1.46, 1.5, 2.2])]
    index: Vec<f64>,
    /// Read noise, fraction of full scale.
    #[arg(long, value_parser = crate::cli::check::non_negative, default_value_t = 0.05)]
    noise: f64,
    /// Spectral engine: auto, series or statistics.
    #[arg(long, value_enum, default_value_t = mfd::solve::spectral::Engine::Auto, hide_possible_values = true)]
    engine: mfd::solve::spectral::Engine,
    /// Print a markdown table instead of one JSON line per row.
    #[arg(long)]
    markdown: bool,
}

/// The 48 × 48 bench station ([`mfd::optics::station::bench_station`]) at 15°.
pub fn small_station(thickness_mm: f64, index: f64) -> anyhow::Result<Station> {
    Ok(mfd::optics::station::bench_station(
        thickness_mm,
        index,
        15.0,
    )?)
}

/// Runs `mfd bench thickness`: one JSON line per plate, or a markdown table.
pub fn run(args: &TableArgs) -> anyhow::Result<()> {
    if args.markdown {
        println!(
        "| t (mm) | n | S2−S1 (bins) | found | S1 error/bound | S2 error/bound | S1 RMS error (px) | \
         RMS(error/reported σ) | flagged |"
    );
        println!("|---|---|---|---|---|---|---|---|---|");
    }
    let engine = args.engine;
    for &n in &args.index {
        for &t in &args.thickness_mm {
            row(t, n, args.noise, engine, args.markdown)?;
        }
    }
    Ok(())
}

fn row(
    t: f64,
    n: f64,
    noise: f64,
    engine: mfd::solve::spectral::Engine,
    markdown: bool,
) -> anyhow::Result<()> {
    let station = small_station(t, n)?;
    let (front, back) = RandomSurfaceSpec::default().draw_pair(25.5, [0.0, 0.0], 31)?;
    let view = TracedView::trace(&station, &Plate::new(&station, front, back, 3.0));
    let params = SimParams {
        noise_frac: noise,
        seed: 5,
        ..SimParams::default()
    };
    let (solver, maps, g) = render_and_solve(&station, &view, &params, engine)?;
    let sigma = noise * params.full_scale();
    let (mut total, mut found, mut flagged) = (0usize, 0usize, 0usize);
    let (mut e2, mut b2, mut seps) = ([0.0f64; 2], [0.0f64; 2], Vec::new());
    let mut z2 = 0.0;
    for (q, px) in view.pixels.iter().enumerate() {
        let (Ok(f), Ok(b)) = (px.front, px.back) else {
            continue;
        };
        total += 1;
        let r = &maps.pixels[q];
        if r.flags
            .intersects(PixelFlags::UNRESOLVED | PixelFlags::OFFSET_MISMATCH)
        {
            flagged += 1;
        }
        let ax = solver.design().axes[0];
        seps.push((ax.a * (b.u - f.u) + ax.b * (b.v - f.v)).abs() * 199.8);
        if r.s[0][0].is_nan() || r.s[1][0].is_nan() {
            continue;
        }
        let Some(bound) = two_reflection_bound(
            solver.design(),
            [[f.u, f.v], [b.u, b.v]],
            g * (params.ambient + 0.5 * (f.weight + b.weight)),
            [0.5 * g * f.weight, 0.5 * g * b.weight],
            params.tau_max.powi(-2),
            sigma,
        ) else {
            continue;
        };
        found += 1;
        for (k, truth) in [f, b].iter().enumerate() {
            e2[k] += (r.s[k][0] - truth.u).powi(2) + (r.s[k][1] - truth.v).powi(2);
            b2[k] += bound[k] * bound[k];
            z2 += ((r.s[k][0] - truth.u) / r.std[k][0]).powi(2)
                + ((r.s[k][1] - truth.v) / r.std[k][1]).powi(2);
        }
    }
    seps.sort_by(f64::total_cmp);
    let median_sep = seps.get(seps.len() / 2).copied().unwrap_or(f64::NAN);
    let ratio = [(e2[0] / b2[0]).sqrt(), (e2[1] / b2[1]).sqrt()];
    let rms_s1 = (e2[0] / found.max(1) as f64).sqrt();
    let z = (z2 / (4 * found.max(1)) as f64).sqrt();
    print_row(
        [t, n],
        median_sep,
        [found, total, flagged],
        ratio,
        rms_s1,
        z,
        markdown,
    );
    Ok(())
}

/// Renders the paper's schedule on the plate of `view` and runs the
/// spectral solver on it; returns the solver, its maps and the renderer's
/// gain (counts per unit of normalised intensity).
pub(super) fn render_and_solve(
    station: &Station,
    view: &TracedView,
    params: &SimParams,
    engine: mfd::solve::spectral::Engine,
) -> anyhow::Result<(SpectralSolver, mfd::solve::spectral::SpectralMaps, f64)> {
    let mut cam = Renderer::new(view, &station.screen, params.clone())?;
    let patterns = Schedule::default().patterns();
    let frames: Vec<FrameInfo> = FrameInfo::from_patterns(&patterns);
    let config = SpectralConfig {
        engine,
        ..SpectralConfig::default()
    };
    let mut solver = SpectralSolver::new(station, &frames, config)?;
    solver.push_made(|k, buf| cam.render(&patterns[k], k as u64, buf))?;
    let maps = solver.solve()?;
    Ok((solver, maps, cam.gain()))
}

/// One row: a markdown table row or a JSON line. `counts` are found, total
/// and flagged pixels; `ratio` the error over the bound of S1 and S2.
fn print_row(
    [t, n]: [f64; 2],
    median_sep: f64,
    [found, total, flagged]: [usize; 3],
    ratio: [f64; 2],
    rms_s1: f64,
    z: f64,
    markdown: bool,
) {
    if markdown {
        println!(
            "| {t} | {n} | {median_sep:.2} | {found}/{total} | {:.2} | {:.2} | {rms_s1:.3} | {z:.2} | {flagged} |",
            ratio[0], ratio[1],
        );
        return;
    }
    use super::{print_json, round};
    print_json(&serde_json::json!({
        "bench": "thickness",
        "thickness_mm": t,
        "index": n,
        "median_separation_bins": round(median_sep, 2),
        "found": found,
        "pixels": total,
        "s1_error_over_bound": round(ratio[0], 3),
        "s2_error_over_bound": round(ratio[1], 3),
        "s1_rms_error_px": round(rms_s1, 4),
        "rms_error_over_reported_sigma": round(z, 3),
        "flagged": flagged,
    }));
}

//! `mfd compare`: screen coordinates against a truth, with figures.

use std::path::{Path, PathBuf};

use clap::Args;

use mfd::formats::npy;
use mfd::formats::surfaces_file::SurfacesFile;
use mfd::report::metrics::{rms_difference_nm, score_screen_points};

/// Arguments of `mfd compare`.
#[derive(Args)]
pub struct CompareArgs {
    /// Screen coordinates to judge ([rows, cols, 2, 2], e.g. a reconstruction's).
    #[arg(long, requires = "truth", required_unless_present = "surfaces")]
    screen_coords: Option<PathBuf>,
    /// The truth in the same layout (e.g. a simulation's truth/truth_screen_coords.npy).
    #[arg(long, requires = "screen_coords")]
    truth: Option<PathBuf>,
    /// Surfaces to judge (surfaces.json): RMS difference from
    /// --truth-surfaces over the aperture, piston and tilt removed.
    #[arg(long)]
    surfaces: Option<PathBuf>,
    /// The true surfaces (e.g. a simulation's truth/truth_surfaces.json).
    #[arg(long, requires = "surfaces")]
    truth_surfaces: Option<PathBuf>,
    /// The reconstruction's summary.json, to set the error against the
    /// surface uncertainty it reported.
    #[arg(long, requires = "surfaces")]
    summary: Option<PathBuf>,
    /// The reported standard deviations ([rows, cols, 2, 2], screen_std.npy),
    /// to check that the errors match them.
    #[arg(long)]
    std: Option<PathBuf>,
    #[command(flatten)]
    interferometer: super::compare_interferometer::InterferometerArgs,
}

/// Runs `mfd compare`.
pub fn run(args: &CompareArgs) -> anyhow::Result<()> {
    if let (Some(a), Some(b)) = (&args.screen_coords, &args.truth) {
        compare_points(args, a, b)?;
    }
    if let (Some(a), Some(b)) = (&args.surfaces, &args.truth_surfaces) {
        compare_surfaces(a, b, args.summary.as_deref())?;
    }
    match (&args.surfaces, &args.interferometer.interferometer) {
        (Some(s), Some(_)) => super::compare_interferometer::run(&args.interferometer, s)?,
        (None, Some(_)) => {
            return Err(super::exit::usage(anyhow::anyhow!(
                "--interferometer needs --surfaces (the surfaces.json to compare)"
            )))
        }
        (Some(_), None) if args.truth_surfaces.is_none() => {
            return Err(super::exit::usage(anyhow::anyhow!(
                "--surfaces needs --truth-surfaces or --interferometer"
            )))
        }
        _ => {}
    }
    Ok(())
}

fn compare_surfaces(ours: &Path, truth: &Path, summary: Option<&Path>) -> anyhow::Result<()> {
    let (a, b) = (SurfacesFile::load(ours)?, SurfacesFile::load(truth)?);
    let reported: Option<serde_json::Value> = match summary {
        Some(p) => {
            // A summary that cannot be read or is not JSON: bad input.
            let text = std::fs::read_to_string(p)
                .map_err(|e| super::exit::input(anyhow::anyhow!("{}: {e}", p.display())))?;
            Some(serde_json::from_str(&text).map_err(|e| {
                super::exit::input(anyhow::anyhow!("{}: not JSON: {e}", p.display()))
            })?)
        }
        None => None,
    };
    for (name, x, y) in [
        ("front", a.front_coefficients(), b.front_coefficients()),
        ("back", a.back_coefficients(), b.back_coefficients()),
    ] {
        let (Some(x), Some(y)) = (x, y) else {
            println!("{name}: not reconstructed (null)");
            continue;
        };
        let err = rms_difference_nm(x, y);
        print!("{name} surface: RMS error {err:.4} nm over the aperture (piston and tilt removed), {} terms", x.len());
        // Noise and station together where the summary has the station's part.
        let total = reported
            .as_ref()
            .and_then(|r| r["station"][name]["total_rms_nm"].as_f64());
        let noise = reported
            .as_ref()
            .and_then(|r| r[name]["error_rms_nm"].as_f64());
        if let Some(u) = total.or(noise) {
            let what = if total.is_some() {
                " (noise and station)"
            } else {
                ""
            };
            print!(
                "; reported uncertainty{what} {u:.4} nm (error/uncertainty {:.2})",
                err / u
            );
        }
        println!();
    }
    if let Some(r) = &reported {
        print_figures(r, &b)?;
    }
    Ok(())
}

/// The summary's figures (when it has them) beside those of the true
/// surfaces, each difference in units of its σ.
fn print_figures(summary: &serde_json::Value, truth: &SurfacesFile) -> anyhow::Result<()> {
    use mfd::report::figures::{of_truth, table, Figures};
    let Some(f) = summary.get("figures").filter(|f| !f.is_null()) else {
        println!("figures: the summary has none (written before them)");
        return Ok(());
    };
    let f: Figures = serde_json::from_value(f.clone())
        .map_err(|e| super::exit::input(anyhow::anyhow!("summary figures: {e}")))?;
    for line in table::lines(&f) {
        println!("{line}");
    }
    let (Some(tf), Some(tb)) = (truth.front_coefficients(), truth.back_coefficients()) else {
        return Ok(());
    };
    let n = f.plate.as_ref().map_or(1.5, |p| p.refractive_index);
    let wl = f
        .plate
        .as_ref()
        .map_or(mfd::report::figures::DEFAULT_WAVELENGTH_NM, |p| {
            p.wavelength_nm
        });
    let t = of_truth(tf, tb, truth.zernike.radius_mm, n, wl)?;
    let scores = table::scores(&f, &t);
    println!("figures against the truth (z = (value - truth) / sigma):");
    for s in &scores {
        println!(
            "  {:<40} {:>12.4} truth {:>12.4} sigma {:>10.4} z {:>6.2}",
            s.key, s.value, s.truth, s.std, s.z
        );
    }
    let zs: Vec<f64> = scores
        .iter()
        .map(|s| s.z)
        .filter(|z| z.is_finite())
        .collect();
    if !zs.is_empty() {
        let rms = (zs.iter().map(|z| z * z).sum::<f64>() / zs.len() as f64).sqrt();
        let worst = zs.iter().fold(0.0f64, |m, z| m.max(z.abs()));
        println!(
            "  {} figures: RMS z {rms:.2}, largest |z| {worst:.2}",
            zs.len()
        );
    }
    Ok(())
}

fn compare_points(
    args: &CompareArgs,
    screen_coords: &Path,
    truth_path: &Path,
) -> anyhow::Result<()> {
    let (shape, ours) = npy::read_f64(screen_coords)?;
    let (tshape, truth) = npy::read_f64(truth_path)?;
    if shape != tshape || shape.len() != 4 || shape[2..] != [2, 2] {
        return Err(super::exit::input(anyhow::anyhow!(
            "{} has shape {shape:?} and {} {tshape:?}: expected the same [rows, cols, 2, 2]",
            screen_coords.display(),
            truth_path.display()
        )));
    }
    let std = match &args.std {
        Some(p) => {
            let (s, v) = npy::read_f64(p)?;
            if s != shape {
                return Err(super::exit::input(anyhow::anyhow!(
                    "{} has shape {s:?}, expected {shape:?}",
                    p.display()
                )));
            }
            Some(v)
        }
        None => None,
    };
    let scores = score_screen_points(&ours, &truth, std.as_deref());
    for (score, name) in scores.iter().zip(["S1 (front)", "S2 (back)"]) {
        print!(
            "{name}: found {}/{} ({:.2} %), RMS error {:.4} px, worst {:.4} px",
            score.found,
            score.expected,
            100.0 * score.found_fraction(),
            score.rms_error_px(),
            score.worst_px()
        );
        if std.is_some() {
            print!(
                ", RMS reported σ {:.4} px, RMS(error/σ) per coordinate {:.3}",
                score.rms_reported_px(),
                score.rms_error_over_sigma()
            );
        }
        println!();
    }
    Ok(())
}

//! `mfd compare`: screen coordinates against a truth, with figures.

use std::path::PathBuf;

use anyhow::bail;
use clap::Args;

use mfd::npy;

/// Arguments of `mfd compare`.
#[derive(Args)]
pub struct CompareArgs {
    /// Screen coordinates to judge ([rows, cols, 2, 2], e.g. a reconstruction's).
    #[arg(long)]
    screen_coords: PathBuf,
    /// The truth in the same layout (e.g. a simulation's truth/truth_screen_coords.npy).
    #[arg(long)]
    truth: PathBuf,
    /// The reported standard deviations ([rows, cols, 2, 2], screen_std.npy),
    /// to check that the errors match them.
    #[arg(long)]
    std: Option<PathBuf>,
}

/// Runs `mfd compare`.
pub fn run(args: &CompareArgs) -> anyhow::Result<()> {
    let (shape, ours) = npy::read_f64(&args.screen_coords)?;
    let (tshape, truth) = npy::read_f64(&args.truth)?;
    if shape != tshape || shape.len() != 4 || shape[2..] != [2, 2] {
        bail!(
            "{} has shape {shape:?} and {} {tshape:?}: expected the same [rows, cols, 2, 2]",
            args.screen_coords.display(),
            args.truth.display()
        );
    }
    let std = match &args.std {
        Some(p) => {
            let (s, v) = npy::read_f64(p)?;
            if s != shape {
                bail!("{} has shape {s:?}, expected {shape:?}", p.display());
            }
            Some(v)
        }
        None => None,
    };
    for (k, name) in ["S1 (front)", "S2 (back)"].iter().enumerate() {
        let (mut expected, mut found, mut e2, mut s2, mut z2, mut worst) =
            (0usize, 0usize, 0.0, 0.0, 0.0, 0.0f64);
        for p in 0..ours.len() / 4 {
            let at = p * 4 + 2 * k;
            if truth[at].is_nan() {
                continue;
            }
            expected += 1;
            if ours[at].is_nan() {
                continue;
            }
            found += 1;
            let (du, dv) = (ours[at] - truth[at], ours[at + 1] - truth[at + 1]);
            e2 += du * du + dv * dv;
            worst = worst.max(du.hypot(dv));
            if let Some(s) = &std {
                s2 += s[at] * s[at] + s[at + 1] * s[at + 1];
                z2 += (du / s[at]).powi(2) + (dv / s[at + 1]).powi(2);
            }
        }
        let n = found.max(1) as f64;
        print!(
            "{name}: found {found}/{expected} ({:.2} %), RMS error {:.4} px, worst {worst:.4} px",
            100.0 * found as f64 / expected.max(1) as f64,
            (e2 / n).sqrt()
        );
        if std.is_some() {
            print!(
                ", RMS reported σ {:.4} px, RMS(error/σ) per coordinate {:.3}",
                (s2 / n).sqrt(),
                (z2 / (2.0 * n)).sqrt()
            );
        }
        println!();
    }
    Ok(())
}

//! `mfd report RESULT_DIR`: the measurement report, one self-contained HTML
//! file.

use std::path::PathBuf;

use clap::Args;

use mfd::report::page::{self, ReportOptions};

/// Arguments of `mfd report`.
#[derive(Args)]
pub struct ReportArgs {
    /// A result folder (`mfd reconstruct --out`, or `mfd measure`'s
    /// `OUT/result`).
    result: PathBuf,
    /// The HTML file to write; default RESULT_DIR/report.html.
    #[arg(long)]
    out: Option<PathBuf>,
    /// The acquisition folder; default RESULT_DIR/../acquisition when it exists.
    #[arg(long)]
    acquisition: Option<PathBuf>,
    /// The calibration's folder (report.json, targets.png, flat_residuals.png);
    /// default: the folder of the station file the acquisition names.
    #[arg(long)]
    calibration: Option<PathBuf>,
    /// Compare with an interferometer map too (its options as `mfd compare`'s).
    #[command(flatten)]
    interferometer: super::compare_interferometer::InterferometerArgs,
}

/// Runs `mfd report`.
pub fn run(args: &ReportArgs) -> anyhow::Result<()> {
    let surfaces = args.result.join("surfaces.json");
    let comparison = super::compare_interferometer::comparison(&args.interferometer, &surfaces)?;
    let options = ReportOptions {
        acquisition: args.acquisition.clone(),
        calibration: args.calibration.clone(),
        comparison: comparison.as_ref(),
    };
    let path = page::write(&args.result, args.out.as_deref(), &options)?;
    println!("wrote the report {}", path.display());
    Ok(())
}

//! `mfd measure --repeat N`: N measurements in a row, each written into
//! its own folder, then `repeatability.json` from their summaries.

use anyhow::Context;

use mfd::report::repeatability::repeatability;
use mfd::report::summary::Summary;

use super::devices::open_display;
use super::{run_with, MeasureArgs, StationInput};

/// Runs the measurement `args.repeat` times into `--out/run-K` and writes
/// `--out/repeatability.json`.
pub(super) fn run_repeated(args: &MeasureArgs, input: &StationInput) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.display == "offscreen",
        "--repeat runs on the offscreen display only; measure on a monitor one run at a time"
    );
    let n = args.repeat;
    let (mut folders, mut summaries) = (Vec::new(), Vec::new());
    for k in 0..n {
        println!("run {} of {n}", k + 1);
        let mut one = args.clone();
        one.out = args.out.join(format!("run-{}", k + 1));
        one.repeat = 1;
        one.run_index = k as u64;
        let display = open_display(&one.display, &input.station, one.settle_ms, one.gamma)?;
        run_with(&one, input, display)?;
        let path = one.out.join("result/summary.json");
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("run {} of {n}: {}", k + 1, path.display()))?;
        let summary: Summary = serde_json::from_str(&text)
            .with_context(|| format!("run {} of {n}: {}", k + 1, path.display()))?;
        folders.push(one.out.join("result").display().to_string());
        summaries.push(summary);
    }
    let r = repeatability(&folders, &summaries);
    let path = args.out.join("repeatability.json");
    std::fs::write(&path, serde_json::to_string_pretty(&r)? + "\n")
        .with_context(|| format!("writing {}", path.display()))?;
    // Each run's report again, now with the repeatability beside it.
    let calibration = args
        .station
        .parent()
        .filter(|dir| dir.join("report.json").is_file())
        .map(std::path::Path::to_path_buf);
    for f in &folders {
        let options = mfd::report::page::ReportOptions {
            calibration: calibration.clone(),
            ..Default::default()
        };
        mfd::report::page::write(std::path::Path::new(f), None, &options)?;
    }
    println!("repeatability over {n} runs ({}):", path.display());
    for (name, s) in [("front", &r.front), ("back", &r.back)] {
        match s {
            Some(s) => println!(
                "  {name}: spread {:.3} nm RMS over the runs, reported {:.3} nm: spread over \
                 reported {:.2}",
                s.departure_rms_nm, s.mean_expected_error_rms_nm, s.spread_over_reported
            ),
            None => println!("  {name}: not reported by every run"),
        }
    }
    for (key, s) in &r.figures {
        if let Some(ratio) = s.ratio {
            println!(
                "  {key:<40} mean {:>10.3} spread {:>8.3} reported σ {:>8.3} ratio {ratio:.2}",
                s.mean, s.spread, s.mean_reported_std
            );
        }
    }
    Ok(())
}

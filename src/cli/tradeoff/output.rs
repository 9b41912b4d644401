//! What `mfd tradeoff` writes: the rows as CSV and a markdown table, the
//! error and compute time against frames, and the error against
//! acquisition time.

use std::fmt::Write as _;

use anyhow::Context;

use mfd::plot::{line_plot_png, Panel, Series};

use super::row::Row;
use super::TradeoffArgs;

/// Writes tradeoff.csv, tradeoff.md and the two plots into `--out`, and
/// prints the table.
pub(super) fn write_outputs(rows: &[Row], args: &TradeoffArgs) -> anyhow::Result<()> {
    let mut csv = String::from(
        "frames_per_direction,terms,max_iter,s1_found,s2_found,front_err_nm,back_err_nm,\
         front_reported_nm,back_reported_nm,spectral_s,surfaces_s,acquisition_s,\
         front_predicted_nm,back_predicted_nm,designed,note\n",
    );
    let mut md = String::from(
        "| frames/dir | terms | max iter | S1 / S2 found | front error (nm) | back error (nm) | \
         reported σ front / back (nm) | spectral (s) | surfaces (s) | acquisition (s) | \
         predicted front / back (nm) | note |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        writeln!(
            csv,
            "{},{},{},{},{},{:.4},{:.4},{:.4},{:.4},{:.3},{:.3},{:.2},{:.4},{:.4},{},{}",
            r.frames,
            r.terms,
            r.max_iter,
            r.found[0],
            r.found[1],
            r.error_nm[0],
            r.error_nm[1],
            r.reported_nm[0],
            r.reported_nm[1],
            r.spectral_s,
            r.surfaces_s,
            r.acquisition_s,
            r.predicted_nm[0],
            r.predicted_nm[1],
            r.designed,
            r.note.replace(',', ";")
        )?;
        writeln!(
            md,
            "| {} | {} | {} | {} / {} | {:.2} | {:.2} | {:.2} / {:.2} | {:.2} | {:.2} | {:.1} | {:.2} / {:.2} | {} |",
            r.frames,
            r.terms,
            r.max_iter,
            r.found[0],
            r.found[1],
            r.error_nm[0],
            r.error_nm[1],
            r.reported_nm[0],
            r.reported_nm[1],
            r.spectral_s,
            r.surfaces_s,
            r.acquisition_s,
            r.predicted_nm[0],
            r.predicted_nm[1],
            r.note
        )?;
    }
    let write = |name: &str, text: &str| {
        let p = args.out.join(name);
        std::fs::write(&p, text).with_context(|| format!("writing {}", p.display()))
    };
    write("tradeoff.csv", &csv)?;
    write("tradeoff.md", &md)?;
    plot(rows, args)?;
    plot_time(rows, args)?;
    println!("{md}");
    println!(
        "wrote {} and tradeoff-time.png",
        args.out.join("tradeoff.{csv,md,png}").display()
    );
    Ok(())
}

/// Error (front and back) and compute time against frames, one series per
/// term count at the largest iteration limit.
fn plot(rows: &[Row], args: &TradeoffArgs) -> anyhow::Result<()> {
    let it = args.max_iter.iter().copied().max().unwrap_or(30);
    let mut labels = Vec::new();
    let mut data: Vec<[Vec<(f64, f64)>; 3]> = Vec::new();
    for &terms in &args.terms {
        let pick = |f: &dyn Fn(&Row) -> f64| -> Vec<(f64, f64)> {
            rows.iter()
                .filter(|r| r.terms == terms && r.max_iter == it && !r.designed)
                .map(|r| ((2 * r.frames) as f64, f(r)))
                .collect()
        };
        labels.push(format!("{terms} terms"));
        data.push([
            pick(&|r| r.error_nm[0]),
            pick(&|r| r.error_nm[1]),
            pick(&|r| r.spectral_s + r.surfaces_s),
        ]);
    }
    let series = |k: usize| -> Vec<Series> {
        labels
            .iter()
            .zip(&data)
            .map(|(l, d)| Series {
                label: l,
                points: &d[k],
            })
            .collect()
    };
    let (s0, s1, s2) = (series(0), series(1), series(2));
    let panel = |title, y, series, log_y| Panel {
        title,
        x_label: "frames (both directions)",
        y_label: y,
        log_x: true,
        log_y,
        series,
    };
    line_plot_png(
        &args.out.join("tradeoff.png"),
        &[
            panel("Front surface error", "RMS error (nm)", &s0, true),
            panel("Back surface error", "RMS error (nm)", &s1, true),
            panel("Compute time", "seconds (spectral + surfaces)", &s2, true),
        ],
    )?;
    Ok(())
}

/// Error against acquisition time (the planner's timing), front and back:
/// the uniform family and the designed schedules, achieved and their
/// Cramér–Rao bound, at the largest term count and iteration limit.
fn plot_time(rows: &[Row], args: &TradeoffArgs) -> anyhow::Result<()> {
    let it = args.max_iter.iter().copied().max().unwrap_or(30);
    let terms = args.terms.iter().copied().max().unwrap_or(36);
    let pick = |designed: bool, f: &dyn Fn(&Row) -> f64| -> Vec<(f64, f64)> {
        let mut v: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| r.terms == terms && r.max_iter == it && r.designed == designed)
            .map(|r| (r.acquisition_s, f(r)))
            .collect();
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
        v
    };
    // The bound only where the planner says the stage measures the
    // schedule: elsewhere it is no prediction of what will be achieved.
    let bound = |r: &Row, k: usize| {
        if r.measurable {
            r.predicted_nm[k]
        } else {
            f64::NAN
        }
    };
    let data: Vec<[Vec<(f64, f64)>; 4]> = (0..2)
        .map(|k| {
            [
                pick(false, &|r| r.error_nm[k]),
                pick(false, &|r| bound(r, k)),
                pick(true, &|r| r.error_nm[k]),
                pick(true, &|r| bound(r, k)),
            ]
        })
        .collect();
    let labels = [
        "uniform, achieved",
        "uniform, bound",
        "designed, achieved",
        "designed, bound",
    ];
    let series = |k: usize| -> Vec<Series> {
        labels
            .iter()
            .zip(&data[k])
            .map(|(l, d)| Series {
                label: l,
                points: d,
            })
            .collect()
    };
    let (s0, s1) = (series(0), series(1));
    let panel = |title, series| Panel {
        title,
        x_label: "acquisition time (s)",
        y_label: "RMS error (nm)",
        log_x: true,
        log_y: true,
        series,
    };
    line_plot_png(
        &args.out.join("tradeoff-time.png"),
        &[
            panel("Front surface error against time", &s0),
            panel("Back surface error against time", &s1),
        ],
    )?;
    Ok(())
}

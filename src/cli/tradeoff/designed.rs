//! The `--designed` rows: for each frame budget the schedule `mfd plan`
//! designs, measured over the noise seeds and set beside its prediction.

use std::time::Instant;

use mfd::optics::station::Station;
use mfd::optics::trace::TracedView;
use mfd::optics::zernike::ZernikeSurface;
use mfd::plan::Designed;

use super::row::{combine, Row};
use super::solve::{solve_frames, surfaces};
use super::TradeoffArgs;

/// One row per frame budget for the schedule `mfd plan` designs.
pub(super) fn designed_rows(
    station: &Station,
    view: &TracedView,
    truth: (&ZernikeSurface, &ZernikeSurface),
    args: &TradeoffArgs,
    rows: &mut Vec<Row>,
) -> anyhow::Result<()> {
    let terms = args.terms.iter().copied().max().unwrap_or(36);
    let it = args.max_iter.iter().copied().max().unwrap_or(30);
    let mut opts = mfd::plan::DesignOptions::default();
    opts.plan.radiometry.noise_frac = args.noise;
    opts.plan.terms = terms;
    let seeds = if args.seeds.is_empty() {
        vec![args.seed]
    } else {
        args.seeds.clone()
    };
    for &n in &args.frames {
        let t = Instant::now();
        let d = mfd::plan::design(station, mfd::plan::Budget::Frames(2 * n), &opts)?;
        let design_s = t.elapsed().as_secs_f64();
        let mut per_seed = Vec::new();
        for &seed in &seeds {
            let t = Instant::now();
            let solved =
                solve_frames(station, view, &d.frames, it, args.render(), seed + n as u64)?;
            let row = surfaces(
                station,
                &solved,
                truth,
                (n, terms, it),
                t.elapsed().as_secs_f64(),
            );
            eprintln!(
                "designed {} frames, noise seed {}: front {:.2} nm, back {:.2} nm {}",
                2 * n,
                seed + n as u64,
                row.error_nm[0],
                row.error_nm[1],
                row.note
            );
            per_seed.push(row);
        }
        let mut row = combine(&per_seed);
        let p = &d.prediction;
        row.acquisition_s = p.seconds;
        row.designed = true;
        row.measurable = p.not_measurable_because.is_none();
        row.predicted_nm = [
            p.front.rms_nm,
            p.back.as_ref().map_or(f64::NAN, |b| b.rms_nm),
        ];
        row.note = note(&row, &d, design_s, &per_seed);
        eprintln!("designed {} frames: {}", 2 * n, row.note);
        rows.push(row);
    }
    Ok(())
}

/// The note of a designed row `row` (its seeds combined, the prediction
/// set): the design's start share and stage check, predicted against
/// achieved with the seeds' expected spread, each seed's errors, the
/// planner's verdict and the seeds' own notes.
fn note(row: &Row, d: &Designed, design_s: f64, per_seed: &[Row]) -> String {
    let p = &d.prediction;
    let ratio = |k: usize| row.error_nm[k] / row.predicted_nm[k];
    let spread = |s: Option<&mfd::plan::SurfacePrediction>| {
        s.map_or(f64::NAN, |s| 100.0 * s.rms_relative_spread(per_seed.len()))
    };
    format!(
        "designed (plan {design_s:.1} s, start share {:.2} of τ ≤ {:.0}, stage {:.0} % found): predicted {:.2} / {} nm; achieved/predicted ×{:.2} / ×{:.2} (RMS of {} noise seeds, expected seed spread ±{:.0} % / ±{:.0} %: {}){}{}",
        d.uniform_share,
        d.start_tau_max,
        100.0 * p.stage.found_fraction,
        p.front.rms_nm,
        p.back
            .as_ref()
            .map_or("—".into(), |b| format!("{:.2}", b.rms_nm)),
        ratio(0),
        ratio(1),
        per_seed.len(),
        spread(Some(&p.front)),
        spread(p.back.as_ref()),
        per_seed
            .iter()
            .map(|r| format!("{:.2}/{:.2}", r.error_nm[0], r.error_nm[1]))
            .collect::<Vec<_>>()
            .join(", "),
        p.not_measurable_because
            .as_ref()
            .map_or(String::new(), |w| format!("; PLANNER: not measurable ({w})")),
        if row.note.is_empty() {
            String::new()
        } else {
            format!("; {}", row.note)
        }
    )
}

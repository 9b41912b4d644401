//! The plates and pixels a prediction is made on: the flat plate traced
//! through the station, the sample pixels spread over it, and the spectral
//! stage run on some of them at the planned noise.

use crate::budget::scene;
use crate::optics::station::Station;
use crate::optics::trace::{Miss, Plate, TracedView, DEFAULT_EDGE_MARGIN_MM};
use crate::solve::spectral::model::Design;

use super::super::stage::{self, StageCheck};
use super::super::{PlanError, PlanOptions};
use super::STAGE_SEED;

/// The traced nominal plate (flat, or wedged as declared) with the back's weight scaled (0: the back path
/// removed, an AR-coated back).
pub fn traced_view(station: &Station, back_scale: f64) -> Result<TracedView, PlanError> {
    let (front, back) = station
        .element
        .nominal_surfaces(1)
        .map_err(scene::BudgetError::from)?;
    let plate = Plate::new(station, front, back, DEFAULT_EDGE_MARGIN_MM);
    let mut view = TracedView::trace(station, &plate);
    for p in &mut view.pixels {
        if back_scale == 0.0 {
            p.back = Err(Miss::ElementMissed);
        } else if let Ok(h) = &mut p.back {
            h.weight *= back_scale;
        }
        p.third = Err(Miss::ElementMissed);
    }
    Ok(view)
}

/// Up to `n` lit pixels spread evenly over the view (every k-th), those
/// with both reflections when `both`.
pub fn sample_pixels(view: &TracedView, n: usize, both: bool) -> Vec<usize> {
    let lit: Vec<usize> = (0..view.pixels.len())
        .filter(|&q| {
            let p = &view.pixels[q];
            if both {
                p.front.is_ok() && p.back.is_ok_and(|h| h.weight > 0.0)
            } else {
                p.front.is_ok() || p.back.is_ok_and(|h| h.weight > 0.0)
            }
        })
        .collect();
    let step = lit.len().div_ceil(n.max(1)).max(1);
    lit.into_iter().step_by(step).collect()
}

/// Up to `n` pixels spread evenly over the sensor whose reflections in
/// the expected plate `bent` are those of the flat prediction `flat` (no
/// path appears or leaves at the rim between them), with both reflections
/// when `both`: the pixels the stage is run on.
pub fn stage_pixels(flat: &TracedView, bent: &TracedView, n: usize, both: bool) -> Vec<usize> {
    let same = |q: usize| {
        let (a, b) = (&flat.pixels[q], &bent.pixels[q]);
        a.front.is_ok() == b.front.is_ok() && a.back.is_ok() == b.back.is_ok()
    };
    let lit: Vec<usize> = (0..flat.pixels.len())
        .filter(|&q| {
            let p = &flat.pixels[q];
            let ok = if both {
                p.front.is_ok() && p.back.is_ok_and(|h| h.weight > 0.0)
            } else {
                p.front.is_ok()
            };
            ok && same(q)
        })
        .collect();
    let step = lit.len().div_ceil(n.max(1)).max(1);
    lit.into_iter().step_by(step).collect()
}

/// The stage run on `n` sample pixels of `frames`' design (see
/// [`stage::stage_check`]; with `rows`, also what it finds along camera
/// rows): the prior is the station's flat plate with both paths (what
/// the stage holds, AR-coated or not), the truth the expected plate.
pub fn run_stage(
    station: &Station,
    design: &Design,
    view: &TracedView,
    bent: &TracedView,
    n: usize,
    opts: &PlanOptions,
    rows: bool,
) -> Result<StageCheck, PlanError> {
    let full;
    let prior = if opts.back_scale == 1.0 {
        view
    } else {
        full = traced_view(station, 1.0)?;
        &full
    };
    let both = opts.back_scale > 0.0;
    let pixels = stage_pixels(view, bent, n, both);
    let gain = opts.radiometry.gain(view);
    Ok(stage::stage_check(
        design, prior, bent, &pixels, gain, opts, STAGE_SEED, rows,
    ))
}

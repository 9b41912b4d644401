//! Whether the per-pixel stage can tell the two reflections apart: each
//! sample pixel's front–back distance against [`RESOLVE_SIGMAS`] times its
//! Cramér–Rao bound, the spectral stage's own test.

use serde::Serialize;

use crate::optics::trace::TracedView;
use crate::solve::spectral::bound::truth_cov_map_repeated;
use crate::solve::spectral::model::Design;
use crate::solve::spectral::model::Repeats;
use crate::solve::spectral::pixel::RESOLVE_SIGMAS;

use super::super::PlanOptions;

/// Fraction of the pixels with both reflections that must be separable
/// for the schedule to measure the back: nine in ten (the surface solver
/// fits the back from the pixels it is given; a tenth lost at the rim
/// costs little, most of them lost leave the back to the front's slopes).
pub const SEPARABLE_FRACTION: f64 = 0.9;

/// Whether the per-pixel stage can tell the two reflections apart.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Separation {
    /// Sample pixels with both reflections.
    pub pixels: usize,
    /// Their median front–back distance on the screen, px.
    pub median_separation_px: f64,
    /// Fraction of them whose separation exceeds [`RESOLVE_SIGMAS`] times
    /// its bound (the spectral stage's own test for reporting both points).
    pub separable_fraction: f64,
    /// At least [`SEPARABLE_FRACTION`] of them are separable (true when no
    /// pixel has two reflections: there is nothing to separate).
    pub separable: bool,
}

/// The bound's covariance of one pixel (`screen_cov.npy` layout, 16 values);
/// `repeats` are `design`'s distinct frames ([`Repeats::new`]).
pub fn pixel_cov(
    design: &Design,
    repeats: &Repeats,
    view: &TracedView,
    q: usize,
    gain: f64,
    opts: &PlanOptions,
) -> Vec<f64> {
    let r = &opts.radiometry;
    let one = TracedView {
        width: 1,
        height: 1,
        pixels: vec![view.pixels[q]],
    };
    truth_cov_map_repeated(
        design,
        repeats,
        &one,
        gain,
        r.ambient,
        r.tau_max.powi(-2),
        r.sigma_counts(),
    )
}

/// Separability on the sample pixels `both` (pixels with two reflections).
pub fn separation(
    design: &Design,
    view: &TracedView,
    both: &[usize],
    gain: f64,
    opts: &PlanOptions,
) -> Separation {
    let repeats = Repeats::new(design);
    let mut seps = Vec::new();
    let mut good = 0usize;
    for &q in both {
        let p = &view.pixels[q];
        let (Ok(f), Ok(b)) = (p.front, p.back) else {
            continue;
        };
        let d = [b.u - f.u, b.v - f.v];
        let dist = d[0].hypot(d[1]);
        seps.push(dist);
        let c = pixel_cov(design, &repeats, view, q, gain, opts);
        // Var of the separation along d: Var(Δ) with Δ = (u2 − u1, v2 − v1).
        let at = |a: usize, b: usize| c[4 * a + b];
        let mut var = 0.0;
        for (a, wa) in [(0, -d[0]), (1, -d[1]), (2, d[0]), (3, d[1])] {
            for (b, wb) in [(0, -d[0]), (1, -d[1]), (2, d[0]), (3, d[1])] {
                var += wa * wb * at(a, b);
            }
        }
        let sd = (var / (dist * dist).max(1e-300)).sqrt();
        if sd.is_finite() && RESOLVE_SIGMAS * sd < dist {
            good += 1;
        }
    }
    seps.sort_by(f64::total_cmp);
    let n = seps.len();
    let frac = if n == 0 { 1.0 } else { good as f64 / n as f64 };
    Separation {
        pixels: n,
        median_separation_px: seps.get(n / 2).copied().unwrap_or(f64::NAN),
        separable_fraction: frac,
        separable: frac >= SEPARABLE_FRACTION,
    }
}

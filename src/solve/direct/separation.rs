//! How far apart the two reflections are in the spectral domain, and the
//! rule that reads it: below [`DIRECT_BELOW_BINS`] Fourier bins the
//! surfaces are fitted to the frames. One computation for a schedule that
//! was acquired (`--estimator auto`, `pipeline`) and one not yet acquired
//! (`mfd plan`), so that both decide alike.

use crate::optics::trace::TracedView;
use crate::solve::spectral::model::{Axis, Design};
use crate::solve::spectral::SpectralSolver;

/// Median front–back separation (Fourier bins) below which `auto` fits the
/// surfaces to the frames. Measured (`mfd bench thin`, 48×48 bench, paper
/// schedule, 5 % noise, 3 seeds; docs/figures.md): at 0.43–0.45 bins the
/// per-pixel route's front is 1.4–2.0× its bound, the surface-domain fit's
/// 0.83–0.84×; at 0.89–2.75 bins the per-pixel route is at 0.93–1.09× and
/// the surface-domain fit at 1.12–1.21× (its weights follow each pixel's
/// own amplitudes and noise, which the per-pixel route smooths); 0.58 bins
/// (10 mm, n = 2.2): both at 1.1×. Between those, 0.75.
pub const DIRECT_BELOW_BINS: f64 = 0.75;

/// Whether the reflections, `median_bins` apart
/// ([`median_separation_bins`]), are close enough for `auto` to fit
/// the surfaces to the frames: the one rule `auto` and `mfd plan` (which
/// bound a schedule is predicted with) share. False for NaN (no pixel sees
/// two reflections).
pub fn surface_domain_preferred(median_bins: f64) -> bool {
    median_bins < DIRECT_BELOW_BINS
}

/// Median over the pixels that see both reflections of their predicted
/// front–back separation in Fourier bins, over the schedule's τ span, from
/// the flat plate the station describes; NaN where no pixel sees both.
///
/// A pixel's separation is that of its best pair of non-parallel
/// directions, the smaller of the two: the per-pixel fit is joint over the
/// directions, and two that each see the reflections apart fix both
/// points in the plane, while a direction along which they coincide adds
/// only their blend. With the two diagonals alone it is the smaller of
/// their two; with the plain directions too, a pixel whose reflections
/// lie along a plain axis is separated by the other plain one and the
/// diagonals.
pub fn median_separation_bins(solver: &SpectralSolver) -> f64 {
    median_separation_bins_of(
        solver.design(),
        solver.prior(),
        solver.candidates().iter().map(|&c| c as usize),
    )
}

/// [`median_separation_bins`] of a schedule's `design` over the `pixels`
/// of a traced `prior` (the planner's view of a schedule not yet
/// acquired): one computation, so that `mfd plan` and `--estimator auto`
/// decide alike.
pub fn median_separation_bins_of(
    design: &Design,
    prior: &TracedView,
    pixels: impl Iterator<Item = usize>,
) -> f64 {
    let (lo, hi) = design
        .frames
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), f| {
            (l.min(f.tau), h.max(f.tau))
        });
    let span = hi - lo;
    let mut seps: Vec<f64> = pixels
        .filter_map(|c| {
            let p = &prior.pixels[c];
            let (f, b) = (p.front.as_ref().ok()?, p.back.as_ref().ok()?);
            let along = |ax: &Axis| (ax.a * (b.u - f.u) + ax.b * (b.v - f.v)).abs() * span;
            let seps: Vec<f64> = design.axes.iter().map(along).collect();
            design.pair_separation(&seps)
        })
        .collect();
    if seps.is_empty() {
        return f64::NAN;
    }
    let mid = seps.len() / 2;
    *seps.select_nth_unstable_by(mid, f64::total_cmp).1
}

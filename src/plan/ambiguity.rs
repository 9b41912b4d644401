//! Whether a schedule's fit can start unambiguously: per fringe direction,
//! the schedule's ambiguity function (its spectral window over the
//! fringe coordinate), the unambiguous range it gives against the prior's
//! spread (how far the true screen points may lie from the station's
//! nominal-plate prediction), and the spectral stage's own start (its
//! periodogram peak) on noise-free series of sample pixels.

use serde::Serialize;

use crate::acquire::acquisition::FrameInfo;
use crate::acquire::patterns::FringeAxis;
use crate::optics::station::Station;
use crate::optics::trace::{Plate, TracedView, DEFAULT_EDGE_MARGIN_MM};
use crate::optics::zernike::{ZernikeBasis, ZernikeSurface};
use crate::solve::spectral::model::{Design, Repeats};
use crate::solve::spectral::periodogram::SpectrumPlans;

use super::{PlanError, PlanOptions};

mod scan;
use scan::Scan;

/// Height of a false maximum of the ambiguity function, relative to the
/// true one, at which a start may pick it: half (with the noise a bound
/// allows on a measured pixel, a secondary peak at half the power of the
/// main one is not confused with it, one at nearly full power can be).
pub const SIDELOBE_MAX: f64 = 0.5;

/// One direction's ambiguity.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DirectionAmbiguity {
    /// The direction, degrees.
    pub direction_deg: f64,
    /// Half width of the main lobe (to half height), screen px.
    pub main_lobe_px: f64,
    /// Distance to the nearest false maximum of at least [`SIDELOBE_MAX`],
    /// screen px; `None` when there is none on the screen.
    pub unambiguous_range_px: Option<f64>,
    /// That false maximum's height relative to the true one.
    pub false_maximum_height: Option<f64>,
}

/// The ambiguity of a schedule.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Ambiguity {
    /// Per direction.
    pub directions: Vec<DirectionAmbiguity>,
    /// How far the true points may lie from the prediction, screen px.
    pub prior_spread_px: f64,
    /// Every direction's unambiguous range exceeds twice the spread.
    pub unambiguous: bool,
    /// Fraction of sample pixels whose spectral-stage start (the
    /// periodogram's peak, noise-free) lies at their true points.
    pub start_found_fraction: f64,
}

/// `Σ_f e_f² cos(2π τ_f Δ) / Σ_f e_f²` over one direction's frames,
/// `e_f = exp(−κ τ_f²)` the modulation of frame f: the correlation of the
/// noise-free fringe signal of a screen point with that of a point `Δ`
/// (fringe coordinate) away, each frame weighted by its information. Its
/// false maxima are where a fit's start can lock onto the wrong fringe.
pub fn ambiguity_at(taus: &[f64], kappa: f64, delta: f64) -> f64 {
    let (mut re, mut sum) = (0.0, 0.0);
    for &t in taus {
        let e2 = (-2.0 * kappa * t * t).exp();
        re += e2 * (std::f64::consts::TAU * t * delta).cos();
        sum += e2;
    }
    if sum > 0.0 {
        re / sum
    } else {
        0.0
    }
}

/// A false maximum of the ambiguity function: where a fit's start can lock
/// onto the wrong fringe.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FalseMaximum {
    /// Its distance from the true point along the fringe coordinate, screen
    /// px: the schedule's alias spacing in this direction.
    pub distance_px: f64,
    /// Its height relative to the true maximum (1).
    pub height: f64,
}

/// The main lobe (half width to [`SIDELOBE_MAX`], screen px) and the
/// nearest strong false maximum of one direction, scanned over the whole
/// screen (Δ up to 1.05 in fringe coordinate) at 1/32 of the finest fringe
/// period ([`ambiguity_at`]'s values, by the linear-time [`scan`]). The
/// false maximum is the highest point of the first excursion back above
/// [`SIDELOBE_MAX`] beyond the main lobe (refined by the parabola through
/// the highest step and its neighbours): where the copy of every screen
/// point lies, not where the function first climbs towards it.
pub fn direction_ambiguity(
    taus: &[f64],
    kappa: f64,
    axis: &FringeAxis,
) -> (f64, Option<FalseMaximum>) {
    let tau_hi = taus.iter().copied().fold(1.0, f64::max);
    let step = 1.0 / (32.0 * tau_hi);
    let n = (1.05 / step).ceil() as usize;
    let mut lobe = None;
    // The excursion above SIDELOBE_MAX: its highest step (k, value) and the
    // values before and after it.
    let mut best: Option<(usize, f64)> = None;
    let (mut before, mut after) = (f64::NAN, f64::NAN);
    let mut prev = 1.0;
    let mut scan = Scan::new(taus, kappa, step);
    for k in 1..=n {
        let a = scan.next_value();
        match (lobe, best) {
            (None, _) if a < SIDELOBE_MAX => lobe = Some(k as f64 * step),
            (Some(_), None) if a >= SIDELOBE_MAX => {
                best = Some((k, a));
                before = prev;
            }
            (Some(_), Some((_, top))) => {
                if a < SIDELOBE_MAX {
                    if after.is_nan() {
                        after = a;
                    }
                    break;
                }
                if a > top {
                    best = Some((k, a));
                    before = prev;
                    after = f64::NAN;
                } else if after.is_nan() {
                    after = a;
                }
            }
            _ => {}
        }
        prev = a;
    }
    let px = |d: f64| d * axis.length_px;
    let false_max = best.map(|(k, top)| {
        // The vertex of the parabola through (k−1, k, k+1), within a step.
        let curve = before - 2.0 * top + after;
        let shift = if curve < 0.0 && after.is_finite() {
            (0.5 * (before - after) / curve).clamp(-0.5, 0.5)
        } else {
            0.0
        };
        let height = if curve < 0.0 && after.is_finite() {
            top - 0.125 * (before - after) * (before - after) / curve
        } else {
            top
        };
        FalseMaximum {
            distance_px: px((k as f64 + shift) * step),
            height: height.min(1.0),
        }
    });
    (px(lobe.unwrap_or(1.05)), false_max)
}

/// The plate the plan expects: both faces bent by a defocus of
/// `surface_nm` RMS (the largest shift of the screen points the prior's
/// spread allows for), traced through `station`, the back's weight scaled
/// by `back_scale` (0: removed) and no third path, as
/// [`super::predict::traced_view`] does for the flat plate.
pub fn expected_view(station: &Station, opts: &PlanOptions) -> Result<TracedView, PlanError> {
    let e = &station.element;
    let centre = [e.aperture_center_mm.x, e.aperture_center_mm.y];
    let mut c = vec![0.0; 4];
    c[3] = opts.surface_nm;
    let bent = ZernikeBasis::new(4, e.aperture_radius_mm, centre)
        .and_then(|b| ZernikeSurface::new(b, c))
        .map_err(crate::budget::scene::BudgetError::from)?;
    // On the plate as made: the declared wedge stays in the back's tilts.
    let back = e
        .wedge
        .added_to(&bent)
        .map_err(crate::budget::scene::BudgetError::from)?;
    let mut view = TracedView::trace(
        station,
        &Plate::new(station, bent, back, DEFAULT_EDGE_MARGIN_MM),
    );
    for p in &mut view.pixels {
        if opts.back_scale == 0.0 {
            p.back = Err(crate::optics::trace::Miss::ElementMissed);
        } else if let Ok(h) = &mut p.back {
            h.weight *= opts.back_scale;
        }
        p.third = Err(crate::optics::trace::Miss::ElementMissed);
    }
    Ok(view)
}

/// How far the true screen points may lie from the nominal-plate prediction:
/// the station's share plus the largest shift a defocus of
/// `surface_nm` RMS on both faces makes (traced).
pub fn prior_spread_px(
    station: &Station,
    flat: &TracedView,
    opts: &PlanOptions,
) -> Result<f64, PlanError> {
    Ok(spread_between(flat, &expected_view(station, opts)?, opts))
}

/// [`prior_spread_px`] with the expected plate `bent` ([`expected_view`])
/// already traced.
pub fn spread_between(flat: &TracedView, bent: &TracedView, opts: &PlanOptions) -> f64 {
    let mut worst: f64 = 0.0;
    for (a, b) in flat.pixels.iter().zip(&bent.pixels) {
        for (p, q) in [(a.front, b.front), (a.back, b.back)] {
            if let (Ok(p), Ok(q)) = (p, q) {
                worst = worst.max((p.u - q.u).hypot(p.v - q.v));
            }
        }
    }
    opts.station_spread_px + worst
}

/// The fraction of `pixels` (of `view`) whose noise-free series under
/// `design` puts the periodogram's peak (the spectral stage's start) within
/// one Fourier bin of the span of its true points, in every direction.
pub fn start_found_fraction(
    design: &Design,
    view: &TracedView,
    pixels: &[usize],
    kappa: f64,
) -> f64 {
    let plans = SpectrumPlans::new(design);
    // A blur on the screen period: each falloff group's physical κ.
    let falloff = design.physical_falloff(kappa);
    let mut found = 0usize;
    // A frame's value depends on its direction, τ and phase alone: one
    // evaluation per distinct frame, copied to its repeats (the same bits).
    let repeats = Repeats::new(design);
    let mut distinct = vec![0.0; repeats.len()];
    let mut y = vec![0.0; design.frames.len()];
    for &q in pixels {
        let px = &view.pixels[q];
        let hits: Vec<_> = [px.front, px.back]
            .into_iter()
            .filter_map(|h| h.ok().filter(|h| h.weight > 0.0))
            .collect();
        for (&i, yf) in repeats.first.iter().zip(distinct.iter_mut()) {
            let f = &design.frames[i as usize];
            let ax = design.axes[f.dir];
            let e = (-design.kappa_of(f, &falloff) * f.tau * f.tau).exp();
            *yf = 1.0
                + hits
                    .iter()
                    .map(|h| {
                        h.weight
                            * e
                            * (std::f64::consts::TAU * (f.tau * ax.s(h.u, h.v) + f.phase_cycles))
                                .cos()
                    })
                    .sum::<f64>();
        }
        for (yf, &g) in y.iter_mut().zip(&repeats.of_frame) {
            *yf = distinct[g as usize];
        }
        let ok = (0..design.axes.len()).all(|d| {
            let ax = design.axes[d];
            let mus: Vec<f64> = hits.iter().map(|h| ax.s(h.u, h.v)).collect();
            let (lo, hi) = mus
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &m| {
                    (a.min(m), b.max(m))
                });
            let bin = plans.bin(d);
            plans
                .peak(d, &y)
                .is_some_and(|(mu, _)| mu >= lo - bin && mu <= hi + bin)
        });
        found += usize::from(ok);
    }
    if pixels.is_empty() {
        0.0
    } else {
        found as f64 / pixels.len() as f64
    }
}

/// The ambiguity of `frames` on `station`.
pub fn ambiguity(
    station: &Station,
    frames: &[FrameInfo],
    design: &Design,
    sample: (&TracedView, &[usize]),
    prior_spread_px: f64,
    kappa: f64,
) -> Ambiguity {
    let directions: Vec<DirectionAmbiguity> = design
        .directions_deg
        .iter()
        .map(|&d| {
            let taus: Vec<f64> = frames
                .iter()
                .filter(|f| f.direction_deg == d)
                .map(|f| f.tau)
                .collect();
            let (w, h) = (station.screen.width, station.screen.height);
            let axis = FringeAxis::new(d, w, h);
            // The physical falloff of this direction's fringe length.
            let (lobe, alias) = direction_ambiguity(&taus, axis.physical_kappa(kappa, w, h), &axis);
            DirectionAmbiguity {
                direction_deg: d,
                main_lobe_px: lobe,
                unambiguous_range_px: alias.map(|a| a.distance_px),
                false_maximum_height: alias.map(|a| a.height),
            }
        })
        .collect();
    let unambiguous = directions.iter().all(|d| {
        d.unambiguous_range_px
            .is_none_or(|r| r > 2.0 * prior_spread_px)
    });
    Ambiguity {
        directions,
        prior_spread_px,
        unambiguous,
        start_found_fraction: start_found_fraction(design, sample.0, sample.1, kappa),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_schedule_has_no_alias_on_the_screen() {
        // τ = 0.5 … 50 step 0.5 without falloff: ≈ sin(2π T Δ)/(2π T Δ),
        // T = 50 (the sum is the integral over [0, T] to O(1/N)), which
        // halves at 2π T Δ = 1.8955; periodic with period 1/0.5 = 2, so no
        // false maximum at Δ ≤ 1.05.
        let taus: Vec<f64> = (1..=100).map(|k| 0.5 * k as f64).collect();
        let axis = FringeAxis::new(45.0, 1600, 1200);
        let (lobe, range) = direction_ambiguity(&taus, 0.0, &axis);
        assert!(range.is_none(), "{range:?}");
        let want = 1.8955 / (std::f64::consts::TAU * 50.0) * axis.length_px;
        // The scan's step is 1/(32·50) in Δ (1.2 px here); the discrete
        // sum's endpoint terms shift the crossing by ~1 % of the lobe.
        let tol = axis.length_px / 1600.0 + 0.02 * want;
        assert!((lobe - want).abs() < tol, "{lobe} vs {want}");
    }

    #[test]
    fn one_tau_aliases_at_its_period() {
        // cos(2π τ Δ) with τ = 100: below 0.5 from Δ = 1/600, back at its
        // full height 1 at Δ = 1/100.
        let axis = FringeAxis::new(45.0, 1600, 1200);
        let (lobe, alias) = direction_ambiguity(&[100.0, 100.0], 0.0, &axis);
        let step = axis.length_px / 3200.0;
        assert!((lobe - axis.length_px / 600.0).abs() <= step, "{lobe}");
        let a = alias.expect("aliases");
        // The scan's grid holds Δ = 1/100 exactly (32 steps), so the
        // parabola's vertex is the sample itself, to rounding.
        assert!(
            (a.distance_px - 0.01 * axis.length_px).abs() < 1e-6 * step,
            "{a:?}"
        );
        assert!((a.height - 1.0).abs() < 1e-9, "{a:?}");
    }

    /// The nearest strong false maximum by brute force: `Σ cos(2π τ_k Δ)/K`
    /// on a grid of 1e-6 screen lengths, the first local maximum of at least
    /// [`SIDELOBE_MAX`] after the value first fell below it.
    fn brute_force_alias(taus: &[f64]) -> (f64, f64) {
        let value = |d: f64| {
            taus.iter()
                .map(|t| (std::f64::consts::TAU * t * d).cos())
                .sum::<f64>()
                / taus.len() as f64
        };
        let h = 1e-6;
        let mut k = 1;
        while value(k as f64 * h) >= SIDELOBE_MAX {
            k += 1;
        }
        loop {
            let (a, b, c) = (
                value((k - 1) as f64 * h),
                value(k as f64 * h),
                value((k + 1) as f64 * h),
            );
            if b >= SIDELOBE_MAX && b > a && b >= c {
                return (k as f64 * h, b);
            }
            k += 1;
        }
    }

    #[test]
    fn the_alias_is_the_false_maximum_not_the_climb_towards_it() {
        // Issue 37: τ ∈ {0.9, 3.9, 15.9, 63.9} climbs back to 0.5 at Δ ≈
        // 0.0105 but its copy lies at the false maximum, Δ ≈ 0.0150 of height
        // ≈ 0.74 (the result said "8 px away" for the climb).
        let taus = [0.9, 3.9, 15.9, 63.9];
        let axis = FringeAxis::new(45.0, 1600, 1200);
        let (want_d, want_h) = brute_force_alias(&taus);
        assert!((want_d - 0.0150).abs() < 1e-4 && (want_h - 0.742).abs() < 1e-3);
        let (_, alias) = direction_ambiguity(&taus, 0.0, &axis);
        let a = alias.expect("aliases");
        // The scan samples every 1/(32·63.9) of the screen and refines with a
        // parabola; the brute force's grid is 1e-6: a tenth of the scan's
        // step bounds both (the parabola's error on a peak sampled 32 times
        // per finest period is far below it).
        let step = 1.0 / (32.0 * 63.9);
        assert!(
            (a.distance_px / axis.length_px - want_d).abs() < 0.1 * step,
            "{a:?} vs {want_d}"
        );
        // Height: the quartic term the parabola leaves out at one step of the
        // finest component, (2π/32)⁴/24 ≈ 6e-5, with margin.
        assert!((a.height - want_h).abs() < 1e-3, "{a:?} vs {want_h}");
    }
}

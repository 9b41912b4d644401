//! The spectral stage's results checked against the noise and the station,
//! between the spectral and the surface stage:
//!
//! - **Why nothing was measured**, in words, before the surface stage fails
//!   on its absence: dark frames, no pixel where the station puts the
//!   element, fringes nowhere near the station's prediction.
//! - **Fits far above the noise** (a χ² test per pixel, [`PixelFlags::POOR_FIT`]):
//!   the noise variance at each brightness is the median residual variance
//!   of the pixels of that brightness (shot noise grows with the count, so
//!   pixels are compared with those as bright), and a pixel whose residual
//!   variance exceeds it by [`POOR_FIT_FACTOR`] (or the χ² quantile at
//!   [`POOR_FIT_FALSE_ALARM`] where few frames make that larger) is not
//!   reported. The medians hold while fewer than half of a brightness's
//!   pixels are bad; beyond that the global test below catches the result.
//! - **Points far from the station's prediction** ([`PixelFlags::FAR_FROM_PRIOR`]):
//!   relative to the median displacement of all pixels from the flat-plate
//!   prediction, a pixel displaced by more than its own 5σ beyond the
//!   spread the surfaces and the station may cause (the planner's prior spread: the station's share
//!   plus the largest shift a defocus of `max_departure_nm` on both faces
//!   makes, traced) has locked onto a wrong fringe or an alias.
//! - **The result against the station** (global): the median displacement
//!   itself, and the share of pixels far from the prediction. A median
//!   displacement beyond the spread, or more than half the pixels far from
//!   it, means the data contradict the station (a wrong τ scale, a
//!   relabelled direction, a wrong station file): the result is flagged.
//!
//! Written by hand: it is a few robust statistics over the maps.

use crate::acquire::patterns::FringeAxis;
use crate::optics::station::Station;
use crate::optics::trace::TracedView;
use crate::plan::PlanOptions;
pub use crate::report::records::Consistency;
use crate::solve::spectral::model::Design;
use crate::solve::spectral::{PixelFlags, SpectralMaps};

/// Residual variance over the noise variance above which a fit is poor: a
/// residual RMS twice the noise. For the ≥ 30 degrees of freedom of any
/// schedule the spectral stage fits, the χ² false-alarm probability at 4×
/// is below 1e-15, so no good pixel is lost to noise; the margin is for
/// what the median noise model does not follow (pixel-to-pixel gain
/// differences of a few per cent, the modulation model's small misfit on
/// real optics).
pub const POOR_FIT_FACTOR: f64 = 4.0;

/// False-alarm probability of the χ² test where the frame count is small
/// enough for its quantile to exceed [`POOR_FIT_FACTOR`].
pub const POOR_FIT_FALSE_ALARM: f64 = 1e-9;

/// The largest departure of either surface from flat, nm RMS of defocus,
/// that the station check allows by default: λ/0.6 at 633 nm, beyond any
/// planar optic this instrument is for (a λ/4 PV window is ~40 nm RMS).
pub const DEFAULT_MAX_DEPARTURE_NM: f64 = 1000.0;

/// A pixel's own σ counted in the reach of the far test: the spectral
/// stage's resolve criterion (`RESOLVE_SIGMAS`), so that a point is far only
/// where no noise of its fit reaches the allowed spread.
pub const FAR_SIGMAS: f64 = 5.0;

/// Fewest measured pixels for the global test to be made.
pub const MIN_TESTED_PIXELS: usize = 50;

/// What the quality pass takes.
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    /// Largest surface departure allowed, nm RMS defocus.
    pub max_departure_nm: f64,
    /// The station's own share of the spread, screen px.
    pub station_spread_px: f64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_departure_nm: DEFAULT_MAX_DEPARTURE_NM,
            station_spread_px: PlanOptions::default().station_spread_px,
        }
    }
}

/// The largest count at or below which frames are dark: a sixteenth of an
/// 8-bit camera's full scale. Such a frame can hold a fringe of at most 8
/// counts' amplitude (half its range), within the quantisation and read
/// noise of the 8-bit cameras mfd reads; any brighter frame can show
/// fringes, so their absence is not the light's fault.
pub const DARK_COUNT: u16 = 16;

/// Why nothing was measured, when no pixel has a front point: `None` when
/// something was, or when the pixels say only that the reflections were
/// not separable (the surface-domain estimator's case). `max_count` is the
/// largest count of any frame; `design` the manifest's schedule, whose
/// frames per direction are named when bright frames show no fringe.
pub fn why_nothing(
    maps: &SpectralMaps,
    candidates: usize,
    max_count: Option<u16>,
    design: &Design,
) -> Option<String> {
    let found = maps.pixels.iter().filter(|p| p.s[0][0].is_finite()).count();
    if found > 0 {
        return None;
    }
    if candidates == 0 {
        return Some(
            "no camera pixel sees the element where the station puts it (or the region of \
             interest leaves none): wrong station file, or a region outside the element?"
                .into(),
        );
    }
    let fitted: Vec<PixelFlags> = maps
        .pixels
        .iter()
        .map(|p| p.flags)
        .filter(|f| !f.contains(PixelFlags::NO_DATA))
        .collect();
    let n = fitted.len().max(1);
    let share = |f: PixelFlags| fitted.iter().filter(|x| x.intersects(f)).count() as f64 / n as f64;
    let counts = max_count.map_or(String::new(), |m| {
        format!(" (largest count in any frame: {m})")
    });
    // Flat frames leave every pixel without data (no sample varies) or
    // without signal.
    if fitted.is_empty() || share(PixelFlags::NO_SIGNAL) > 0.99 {
        return Some(match max_count {
            Some(m) if m > DARK_COUNT => format!(
                "no fringe signal at the manifest's τ and directions in any of the \
                 {candidates} pixels where the station puts the element, although the frames \
                 are bright (they reach {m} counts): the manifest's directions, τ or phases \
                 do not match the frames (a relabelled frame, τ values out of order?), or \
                 the screen shows no fringes; {}",
                frames_per_direction(design)
            ),
            _ => format!(
                "no fringe signal in any of the {candidates} pixels where the station puts \
                 the element: are the frames dark, or the screen not in view?{counts}"
            ),
        });
    }
    if share(PixelFlags::OUT_OF_BAND | PixelFlags::OFFSET_MISMATCH | PixelFlags::FAR_FROM_PRIOR)
        > 0.5
    {
        return Some(format!(
            "no pixel's fringes lie where the station predicts them ({candidates} pixels \
             tried): wrong station file, or a manifest whose τ or directions do not match \
             the frames?{counts}"
        ));
    }
    if share(PixelFlags::POOR_FIT) > 0.5 {
        return Some(format!(
            "no pixel's fringes fit the model within the noise ({candidates} pixels tried): \
             frames that do not match the manifest's schedule?{counts}"
        ));
    }
    None
}

/// The manifest's frames per direction and their τ range, in words
/// ("frames per direction: 45°: 200 (τ 0.5–100), 30°: 1 (τ 37)").
/// The τ of direction `d`'s frames, in capture order.
fn taus_of(design: &Design, d: usize) -> Vec<f64> {
    design
        .frames
        .iter()
        .filter(|f| f.dir == d)
        .map(|f| f.tau)
        .collect()
}

fn frames_per_direction(design: &Design) -> String {
    let each: Vec<String> = design
        .directions_deg
        .iter()
        .enumerate()
        .map(|(d, deg)| {
            let taus = taus_of(design, d);
            let lo = taus.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = taus.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let range = if lo == hi {
                format!("τ {lo}")
            } else {
                format!("τ {lo}–{hi}")
            };
            format!("{deg}°: {} ({range})", taus.len())
        })
        .collect();
    format!("frames per direction: {}", each.join(", "))
}

/// The χ² threshold on residual variance over noise variance for `dof`
/// degrees of freedom: the larger of [`POOR_FIT_FACTOR`] and the
/// Wilson–Hilferty quantile at [`POOR_FIT_FALSE_ALARM`].
pub fn poor_fit_threshold(dof: f64) -> f64 {
    // z of a one-sided 1e-9 tail.
    let z = 5.997807;
    let a = 2.0 / (9.0 * dof.max(1.0));
    let q = (1.0 - a + z * a.sqrt()).powi(3);
    q.max(POOR_FIT_FACTOR)
}

/// Flags fits far above the noise ([`PixelFlags::POOR_FIT`]) and points
/// far from the prediction ([`PixelFlags::FAR_FROM_PRIOR`]) in `maps`
/// (their points set to NaN), and returns the global test.
pub fn check(
    maps: &mut SpectralMaps,
    prior: &TracedView,
    station: &Station,
    design: &Design,
    limits: Limits,
) -> Consistency {
    let poor_fit_pixels = flag_poor_fits(maps, design.frames.len());
    let alias_spacing_px = alias_spacing(station, design);
    let allowed_px = allowed_spread(station, prior, limits);
    // Displacements from the prediction, per reflection.
    let front = displacements(maps, prior, 0);
    let back = displacements(maps, prior, 1);
    let m_front = median_displacement(&front);
    let m_back = median_displacement(&back);
    let far_pixels = flag_far(maps, [(&front, m_front), (&back, m_back)], allowed_px);
    let pixels = front.len();
    let tested = pixels >= MIN_TESTED_PIXELS;
    let size = |m: [f64; 2]| m[0].hypot(m[1]);
    let worst = m_front.map_or(0.0, size).max(m_back.map_or(0.0, size));
    let far_share = far_pixels as f64 / pixels.max(1) as f64;
    let consistent = !tested || (worst <= allowed_px && far_share <= 0.5);
    let mut c = Consistency {
        consistent,
        tested,
        pixels,
        median_displacement_px: m_front,
        median_back_displacement_px: m_back,
        allowed_px,
        max_departure_nm: limits.max_departure_nm,
        far_pixels,
        poor_fit_pixels,
        alias_spacing_px,
        note: String::new(),
    };
    c.note = note(&c, worst, far_share);
    c
}

/// A measured point's displacement from the prediction: (pixel,
/// displacement in screen px, the point's own σ).
type Displacement = (usize, [f64; 2], f64);

/// The displacement of every pixel's measured point of reflection `r`
/// (0 front, 1 back) from its predicted one.
fn displacements(maps: &SpectralMaps, prior: &TracedView, r: usize) -> Vec<Displacement> {
    maps.pixels
        .iter()
        .enumerate()
        .filter_map(|(k, p)| {
            let hit = if r == 0 {
                prior.pixels.get(k)?.front.as_ref().ok()?
            } else {
                prior.pixels.get(k)?.back.as_ref().ok()?
            };
            let s = p.s[r];
            let sigma = p.std[r][0].hypot(p.std[r][1]);
            (s[0].is_finite() && s[1].is_finite()).then(|| (k, [s[0] - hit.u, s[1] - hit.v], sigma))
        })
        .collect()
}

/// The per-component median of `d`; `None` when empty.
fn median_displacement(d: &[Displacement]) -> Option<[f64; 2]> {
    (!d.is_empty())
        .then(|| [0, 1].map(|c| median(&mut d.iter().map(|x| x.1[c]).collect::<Vec<_>>())))
}

/// [`PixelFlags::FAR_FROM_PRIOR`] (points set to NaN) on every pixel whose
/// front or back point lies farther from its reflection's median
/// displacement than `allowed_px` plus [`FAR_SIGMAS`] of its own σ;
/// returns how many.
fn flag_far(
    maps: &mut SpectralMaps,
    reflections: [(&[Displacement], Option<[f64; 2]>); 2],
    allowed_px: f64,
) -> usize {
    let mut far = vec![false; maps.pixels.len()];
    for (d, m) in reflections {
        let Some(m) = m else { continue };
        for (k, x, sigma) in d {
            // The spread the scene allows plus the pixel's own noise at
            // the spectral stage's resolve criterion (5σ): a point within
            // it may be a noisy measure of a true one.
            let reach = allowed_px + FAR_SIGMAS * sigma.max(0.0);
            let d = (x[0] - m[0]).hypot(x[1] - m[1]);
            if d > reach || d.is_nan() {
                far[*k] = true;
            }
        }
    }
    let mut far_pixels = 0;
    for (p, far) in maps.pixels.iter_mut().zip(&far) {
        if *far {
            p.flags |= PixelFlags::FAR_FROM_PRIOR;
            p.s = [[f64::NAN; 2]; 2];
            p.std = [[f64::NAN; 2]; 2];
            p.cov = [[f64::NAN; 4]; 4];
            far_pixels += 1;
        }
    }
    far_pixels
}

/// The global test in words: untested, agreeing or contradicting (`worst`
/// the larger median displacement, `far_share` the share of pixels far
/// from the prediction), and the schedule's alias spacing where a pixel
/// was far or the result contradicts the station.
fn note(c: &Consistency, worst: f64, far_share: f64) -> String {
    let (pixels, allowed_px, far_pixels) = (c.pixels, c.allowed_px, c.far_pixels);
    let poor_fit_pixels = c.poor_fit_pixels;
    let aliases = match c.alias_spacing_px {
        Some(d) if far_pixels > 0 || !c.consistent => format!(
            "; this schedule repeats every screen point {d:.0} px away (its τ spacing), so a \
             fit can lock onto a copy: a schedule without aliases on the screen (finer τ \
             steps, mfd plan) avoids it"
        ),
        _ => String::new(),
    };
    let note = if !c.tested {
        format!(
            "not tested: {pixels} pixels with a measured front point (needs {MIN_TESTED_PIXELS})"
        )
    } else if c.consistent {
        format!(
            "the screen points agree with the station: median displacement {worst:.2} px \
             from its nominal-plate prediction, within the {allowed_px:.1} px that surfaces of up \
             to {:.0} nm RMS and the station's tolerance allow; {far_pixels} pixels flagged \
             far from it, {poor_fit_pixels} with a residual far above the noise",
            c.max_departure_nm
        )
    } else {
        format!(
            "the screen points contradict the station: median displacement {worst:.1} px from \
             its nominal-plate prediction (allowed {allowed_px:.1} px for surfaces of up to {:.0} \
             nm RMS and the station's tolerance), {:.0} % of {pixels} pixels far from it: a \
             wrong station file, τ scale or direction label in the manifest?",
            c.max_departure_nm,
            100.0 * far_share
        )
    };
    note + &aliases
}

/// The shortest distance to a strong false maximum of the schedule's ambiguity
/// function over the screen, any direction, without the modulation falloff
/// (the planner's [`crate::plan::ambiguity::direction_ambiguity`]).
fn alias_spacing(station: &Station, design: &Design) -> Option<f64> {
    design
        .directions_deg
        .iter()
        .enumerate()
        .filter_map(|(d, &deg)| {
            let taus = taus_of(design, d);
            let axis = FringeAxis::new(deg, station.screen.width, station.screen.height);
            crate::plan::ambiguity::direction_ambiguity(&taus, 0.0, &axis)
                .1
                .map(|a| a.distance_px)
        })
        .reduce(f64::min)
}

/// The planner's prior spread for `limits` (station share plus the largest
/// shift a defocus of the allowed departure makes); the station share
/// alone when the trace fails.
fn allowed_spread(station: &Station, prior: &TracedView, limits: Limits) -> f64 {
    let opts = PlanOptions {
        surface_nm: limits.max_departure_nm,
        station_spread_px: limits.station_spread_px,
        ..PlanOptions::default()
    };
    crate::plan::ambiguity::prior_spread_px(station, prior, &opts)
        .unwrap_or(limits.station_spread_px)
}

/// [`PixelFlags::POOR_FIT`] on every fit whose residual variance exceeds
/// the noise variance at its brightness by [`poor_fit_threshold`]; returns
/// how many.
fn flag_poor_fits(maps: &mut SpectralMaps, frames: usize) -> usize {
    // (background, residual variance, pixel) of every fit with points.
    let mut fits: Vec<(f64, f64, usize)> = maps
        .pixels
        .iter()
        .enumerate()
        .filter(|(_, p)| {
            p.model > 0
                && p.s[0][0].is_finite()
                && p.residual_rms.is_finite()
                && p.amp[0].is_finite()
        })
        .map(|(k, p)| (p.amp[0], p.residual_rms * p.residual_rms, k))
        .collect();
    if fits.len() < MIN_TESTED_PIXELS {
        return 0;
    }
    fits.sort_by(|a, b| a.0.total_cmp(&b.0));
    // Brightness classes of ≥ 50 pixels, at most 16: each class's median
    // residual variance is its noise variance.
    let classes = (fits.len() / MIN_TESTED_PIXELS).clamp(1, 16);
    let per = fits.len().div_ceil(classes);
    // Parameters of the largest model: A, and per direction B, u, φ per
    // reflection and τ_max — about 8 per direction for two reflections.
    let dof = frames.saturating_sub(16) as f64;
    let limit = poor_fit_threshold(dof);
    let mut flagged = 0;
    for chunk in fits.chunks(per) {
        let noise = median(&mut chunk.iter().map(|c| c.1).collect::<Vec<_>>());
        if noise.is_nan() || noise <= 0.0 {
            continue;
        }
        for &(_, var, k) in chunk {
            if var > limit * noise {
                let p = &mut maps.pixels[k];
                p.flags |= PixelFlags::POOR_FIT;
                p.s = [[f64::NAN; 2]; 2];
                p.std = [[f64::NAN; 2]; 2];
                p.cov = [[f64::NAN; 4]; 4];
                flagged += 1;
            }
        }
    }
    flagged
}

/// Median of `x` (reordered); NaN when empty.
fn median(x: &mut [f64]) -> f64 {
    if x.is_empty() {
        return f64::NAN;
    }
    let mid = x.len() / 2;
    let (_, m, _) = x.select_nth_unstable_by(mid, f64::total_cmp);
    *m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_chi2_threshold_is_the_factor_for_many_frames_and_the_quantile_for_few() {
        assert_eq!(poor_fit_threshold(2000.0), POOR_FIT_FACTOR);
        // 4 degrees of freedom: the 1e-9 quantile of χ²₄ is 47.6 (tables),
        // 11.9 per degree of freedom; Wilson–Hilferty is within 15 % there.
        let q = poor_fit_threshold(4.0);
        assert!((q - 11.9).abs() < 0.15 * 11.9, "{q}");
    }
}

#[cfg(test)]
mod scene_tests;

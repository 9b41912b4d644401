//! Where the back reflection lies when nobody said: a coarse search of the
//! full spectrum on sample pixels for the wedge between the element's faces.
//!
//! The spectral stage looks for the back reflection near the point the
//! station predicts (its band, its pair start along the predicted
//! front-to-back offset). A wedge the station does not declare moves that
//! point by `≈ 2 n w L` (a 30-arcmin window 850 mm from the screen: ~80
//! screen px, eight Fourier bins of the paper's schedule), and the stage
//! then finds the back on a few per cent of the pixels. This search finds
//! the wedge first, from the frames themselves:
//!
//! 1. On each sample pixel, each direction's periodogram over μ (the
//!    frames' own τ and phases: any schedule), divided by its median, with
//!    the front's peak (at the station's prediction) masked.
//! 2. The back's predicted point as a function of the back's slope
//!    `s = tan(w) (cos φ, sin φ)`, linearised on the pixel by two traced
//!    rays beside the nominal one.
//! 3. The slope that puts the most periodogram power under every sample
//!    pixel's predicted back point at once (`Σ ln(1 + P/median)`), on a grid
//!    fine enough for a quarter of a Fourier bin, over every wedge a station
//!    may declare; then again around the best with the pixels retraced
//!    there (the linearisation's curvature).
//!
//! Written by hand: a 2-D grid search over a sum of periodograms is a few
//! loops; no crate does it.

use crate::optics::station::{Station, Wedge, MAX_WEDGE_ARCMIN};
use crate::optics::trace::Plate;

use super::model::Design;

mod periodogram;
use periodogram::periodogram;

/// A peak counts as seen where its periodogram power is this many times
/// the median: the spectral stage's own detection threshold.
pub const SEEN_RATIO: f64 = super::pixel::DETECTION_RATIO;

/// Slope step of the Jacobian's finite differences (3.4 arcmin: small
/// against the search range, large against rounding).
const SLOPE_STEP: f64 = 1e-3;

/// μ grid step, in Fourier bins.
const GRID_BINS: f64 = 0.25;

/// The front's peak is masked within this many bins of its prediction: the
/// Hann window's main lobe (±2 bins) and a bin for the front's own tilt and
/// the station's error.
const FRONT_MASK_BINS: f64 = 3.0;

/// How far beyond the front's masked lobe (centred on the front's own
/// peak) a found back point must lie for it to refute a declared back
/// point inside the lobe: beyond the Hann main lobe (2 bins) and the mask's
/// bin of slack, a peak of a twentieth of the front's power is no sidelobe
/// (−31 dB), half a bin more keeps the lobe's edge out.
const CLEAR_BINS: f64 = 0.5;

/// What the search found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WedgeSearch {
    /// The wedge whose back reflection the frames show.
    pub wedge: Wedge,
    /// Sample pixels with a back path searched.
    pub pixels: usize,
    /// Of those, the share whose periodogram shows a peak at the found back
    /// point in every direction ([`SEEN_RATIO`]).
    pub seen_share: f64,
    /// The same share at the back point of the station's declared wedge.
    pub declared_seen_share: f64,
    /// The share of sample pixels whose front peak stands where the station
    /// puts it (within the masked lobe, every direction): where it does not,
    /// the station or the manifest is off, and the back says nothing of the
    /// wedge.
    pub front_seen_share: f64,
    /// Median over the sample pixels of the back point's move from the
    /// declared wedge's to the found one's, in Fourier bins (the largest
    /// over the directions).
    pub shift_bins: f64,
}

/// One sample pixel: its periodograms (the front's lobe masked).
struct Sample {
    /// Per direction: normalised power on the μ grid.
    power: Vec<Vec<f64>>,
    /// Per direction: the least normalised power a back peak must have, a
    /// tenth of what the front's peak and the traced weights predict: a
    /// peak much weaker than the back's (the third reflection, R² of the
    /// front's; a display harmonic) is not the back.
    least: Vec<f64>,
    /// Per direction: the front's fringe coordinate μ (the mask's centre).
    front_mu: Vec<f64>,
    /// Whether the front's peak stands within the mask of its prediction
    /// in every direction.
    front_seen: bool,
}

/// One sample pixel's back point at a slope, and its Jacobian per unit slope.
#[derive(Clone, Copy)]
struct Lin {
    back: [f64; 2],
    jac: [[f64; 2]; 2],
    /// (back weight / front weight)², the power ratio of the two peaks.
    ratio2: f64,
}

/// A back peak counts where it has at least 1/this of the power the
/// front's peak and the traced weights predict (an amplitude 3× lower:
/// room for the falloff differing between the two points).
const BACK_POWER_SLACK: f64 = 10.0;

/// Per direction: the μ grid's step and one Fourier bin.
struct Grid {
    step: Vec<f64>,
    bins: Vec<f64>,
}

/// Searches the wedge on the sample pixels `series` (camera pixel index,
/// one value per frame of `design` in capture order) of `station` (in the
/// element's frame). `None` when no sample pixel has a front and a back
/// path.
pub fn search_wedge(
    station: &Station,
    design: &Design,
    series: &[(usize, Vec<f64>)],
    edge_margin_mm: f64,
) -> Option<WedgeSearch> {
    let grid = mu_grid(design);
    let declared = station.element.wedge.slope();
    let lin0 = linearised(station, series, declared, edge_margin_mm)?;
    let samples: Vec<Option<Sample>> = series
        .iter()
        .zip(&lin0)
        .map(|((_, y), l)| {
            let (lin, front) = l.as_ref()?;
            let mut power = Vec::new();
            let mut least = Vec::new();
            let mut front_mu = Vec::new();
            let mut front_seen = true;
            for d in 0..design.axes.len() {
                let predicted = design.axes[d].s(front[0], front[1]);
                let (p, peak, mu) = periodogram(design, y, d, &grid, predicted);
                power.push(p);
                least.push((peak * lin.ratio2 / BACK_POWER_SLACK).max(SEEN_RATIO));
                front_seen &= peak >= SEEN_RATIO;
                front_mu.push(mu);
            }
            Some(Sample {
                power,
                least,
                front_mu,
                front_seen,
            })
        })
        .collect();
    let strip = |lin: Vec<Option<(Lin, [f64; 2])>>| -> Vec<Option<Lin>> {
        lin.into_iter().map(|l| l.map(|l| l.0)).collect()
    };
    let lin0 = strip(lin0);
    let reach = (MAX_WEDGE_ARCMIN / 60.0).to_radians().tan();
    // The grid step: a quarter bin of back-point movement on the pixel that
    // moves most.
    let step = slope_step(design, &lin0, &grid);
    let coarse = best_on_grid(
        design,
        &samples,
        &lin0,
        &grid,
        declared,
        [0.0, 0.0],
        reach,
        step,
    );
    // Around the best, with the pixels retraced there (the curvature the
    // linear model leaves out).
    let lin1 = strip(linearised(station, series, coarse, edge_margin_mm)?);
    let fine = best_on_grid(
        design,
        &samples,
        &lin1,
        &grid,
        coarse,
        coarse,
        4.0 * step,
        step / 4.0,
    );
    let lin_found = strip(linearised(station, series, fine, edge_margin_mm)?);
    let seen_share = seen(design, &samples, &lin_found, None, &grid);
    let with_front = samples.iter().flatten().filter(|s| s.front_seen).count();
    let front_seen_share = with_front as f64 / samples.iter().flatten().count().max(1) as f64;
    let declared_seen_share = seen(design, &samples, &lin0, Some(&lin_found), &grid);
    let mut shifts: Vec<f64> = lin_found
        .iter()
        .zip(&lin0)
        .filter_map(|(a, b)| {
            let (a, b) = (a.as_ref()?, b.as_ref()?);
            Some(
                (0..design.axes.len())
                    .map(|d| {
                        let ax = design.axes[d];
                        (ax.s(a.back[0], a.back[1]) - ax.s(b.back[0], b.back[1])).abs()
                            / grid.bins[d]
                    })
                    .fold(0.0, f64::max),
            )
        })
        .collect();
    if shifts.is_empty() {
        return None;
    }
    shifts.sort_by(f64::total_cmp);
    Some(WedgeSearch {
        wedge: Wedge::from_slope(fine),
        pixels: lin_found.iter().filter(|l| l.is_some()).count(),
        seen_share,
        declared_seen_share,
        front_seen_share,
        shift_bins: shifts[shifts.len() / 2],
    })
}

/// The μ grid of every direction: a quarter of its Fourier bin (1 / τ span).
fn mu_grid(design: &Design) -> Grid {
    let mut step = Vec::new();
    let mut bins = Vec::new();
    for d in 0..design.axes.len() {
        let taus = design.frames.iter().filter(|f| f.dir == d).map(|f| f.tau);
        let (lo, hi) = taus.fold((f64::INFINITY, 0.0f64), |(lo, hi), t| {
            (lo.min(t), hi.max(t))
        });
        let bin = 1.0 / (hi - lo).max(1e-9);
        step.push(GRID_BINS * bin);
        bins.push(bin);
    }
    Grid { step, bins }
}

/// Per sample pixel: its back point's linear model and its front point
/// (`None` for a pixel without both paths).
type Linearised = Vec<Option<(Lin, [f64; 2])>>;

/// Each sample pixel traced at slope `at` and at two slopes beside it: its
/// back point's linear model and its front point; `None` for a pixel
/// without both paths. `None` overall when the plate makes no surface.
fn linearised(
    station: &Station,
    series: &[(usize, Vec<f64>)],
    at: [f64; 2],
    edge_margin_mm: f64,
) -> Option<Linearised> {
    let plates = [[0.0, 0.0], [SLOPE_STEP, 0.0], [0.0, SLOPE_STEP]].map(|ds| {
        let mut s = station.clone();
        s.element.wedge = Wedge::from_slope([at[0] + ds[0], at[1] + ds[1]]);
        s.element
            .nominal_surfaces(3)
            .ok()
            .map(|(f, b)| Plate::new(&s, f, b, edge_margin_mm))
    });
    let [Some(p0), Some(px), Some(py)] = plates else {
        return None;
    };
    let cam = &station.camera;
    let w = cam.width as usize;
    let lin = series
        .iter()
        .map(|(k, _)| {
            let (i, j) = ((k % w) as u32, (k / w) as u32);
            let ray = cam.ray_direction(i, j);
            let trace = |p: &Plate| p.trace_ray(&cam.position_mm, &ray, &station.screen);
            let (t0, tx, ty) = (trace(&p0), trace(&px), trace(&py));
            let (Ok(front), Ok(b0), Ok(bx), Ok(by)) = (t0.front, t0.back, tx.back, ty.back) else {
                return None;
            };
            let jac = [
                [(bx.u - b0.u) / SLOPE_STEP, (by.u - b0.u) / SLOPE_STEP],
                [(bx.v - b0.v) / SLOPE_STEP, (by.v - b0.v) / SLOPE_STEP],
            ];
            Some((
                Lin {
                    back: [b0.u, b0.v],
                    jac,
                    ratio2: (b0.weight / front.weight).powi(2),
                },
                [front.u, front.v],
            ))
        })
        .collect();
    Some(lin)
}

/// The slope step that moves the most-moving pixel's back point by a
/// quarter of a bin in the direction where that is most.
fn slope_step(design: &Design, lin: &[Option<Lin>], grid: &Grid) -> f64 {
    let mut worst: f64 = 0.0;
    for l in lin.iter().flatten() {
        for (d, ax) in design.axes.iter().enumerate() {
            for c in 0..2 {
                let ds = (ax.a * l.jac[0][c] + ax.b * l.jac[1][c]).abs() / grid.step[d];
                worst = worst.max(ds);
            }
        }
    }
    if worst > 0.0 {
        1.0 / worst
    } else {
        SLOPE_STEP
    }
}

/// The slope on a square grid of `step` within `reach` of `centre` (and
/// within the spec's largest wedge) whose back points carry the most power;
/// `lin` is linearised at the slope `at`.
#[allow(clippy::too_many_arguments)]
fn best_on_grid(
    design: &Design,
    samples: &[Option<Sample>],
    lin: &[Option<Lin>],
    grid: &Grid,
    at: [f64; 2],
    centre: [f64; 2],
    reach: f64,
    step: f64,
) -> [f64; 2] {
    let max = (MAX_WEDGE_ARCMIN / 60.0).to_radians().tan();
    let n = (reach / step).ceil() as i64;
    let mut best = (f64::NEG_INFINITY, at);
    for a in -n..=n {
        for b in -n..=n {
            let s = [centre[0] + a as f64 * step, centre[1] + b as f64 * step];
            if s[0].hypot(s[1]) > max * 1.02 {
                continue;
            }
            let score = score(design, samples, lin, grid, [s[0] - at[0], s[1] - at[1]]);
            if score > best.0 {
                best = (score, s);
            }
        }
    }
    best.1
}

/// `Σ ln(1 + P/median)` under every sample's back point moved by `ds`.
fn score(
    design: &Design,
    samples: &[Option<Sample>],
    lin: &[Option<Lin>],
    grid: &Grid,
    ds: [f64; 2],
) -> f64 {
    samples
        .iter()
        .zip(lin)
        .filter_map(|(s, l)| Some((s.as_ref()?, l.as_ref()?)))
        .map(|(s, l)| {
            let (u, v) = moved(l, ds);
            (0..design.axes.len())
                .map(|d| lookup(&s.power[d], design.axes[d].s(u, v) / grid.step[d]).ln_1p())
                .sum::<f64>()
        })
        .sum()
}

/// The share of samples whose back point (unmoved) is seen: outside the
/// front's lobe in at least one direction, and a peak of at least the
/// sample's least power in every direction where it is outside. A back
/// point inside the front's lobe in every direction cannot be told from
/// the front: with `against` (the found back points) it counts as seen
/// unless the found one stands clear of the lobe ([`CLEAR_BINS`] beyond
/// it in some direction), so that a lobe's shoulder never refutes it.
fn seen(
    design: &Design,
    samples: &[Option<Sample>],
    lin: &[Option<Lin>],
    against: Option<&[Option<Lin>]>,
    grid: &Grid,
) -> f64 {
    let mut n = 0usize;
    let mut total = 0usize;
    for (k, (s, l)) in samples.iter().zip(lin).enumerate() {
        let (Some(s), Some(l)) = (s, l) else {
            continue;
        };
        total += 1;
        let offset = |l: &Lin, d: usize| {
            (design.axes[d].s(l.back[0], l.back[1]) - s.front_mu[d]).abs() / grid.bins[d]
        };
        let dirs = 0..design.axes.len();
        let outside: Vec<usize> = dirs
            .clone()
            .filter(|&d| offset(l, d) > FRONT_MASK_BINS)
            .collect();
        let ok = if outside.is_empty() {
            against.and_then(|a| a[k].as_ref()).is_some_and(|f| {
                dirs.clone()
                    .all(|d| offset(f, d) <= FRONT_MASK_BINS + CLEAR_BINS)
            })
        } else {
            outside.iter().all(|&d| {
                let x = design.axes[d].s(l.back[0], l.back[1]) / grid.step[d];
                // The peak's top within two grid steps (half a bin) either side.
                (-2..=2).any(|i| lookup(&s.power[d], x + f64::from(i)) >= s.least[d])
            })
        };
        n += usize::from(ok);
    }
    n as f64 / total.max(1) as f64
}

fn moved(l: &Lin, ds: [f64; 2]) -> (f64, f64) {
    (
        l.back[0] + l.jac[0][0] * ds[0] + l.jac[0][1] * ds[1],
        l.back[1] + l.jac[1][0] * ds[0] + l.jac[1][1] * ds[1],
    )
}

/// Linear interpolation of `p` at the fractional index `x` (1 outside).
fn lookup(p: &[f64], x: f64) -> f64 {
    if x.is_nan() || x < 0.0 || x >= (p.len() - 1) as f64 {
        return 1.0;
    }
    let i = x as usize;
    let f = x - i as f64;
    p[i] * (1.0 - f) + p[i + 1] * f
}

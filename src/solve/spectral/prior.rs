//! The geometry prior: the nominal plate (flat, or wedged as declared) traced through the nominal station
//! (a [`TracedView`] built by the trace module and handed in), and what the
//! solver takes from it — the pixels worth fitting, the back-minus-front
//! offsets borrowed at the rim, and the statistics' band centres.

use super::model::Design;
use super::periodogram::SpectrumPlans;
use super::{SpectralConfig, SpectralError};
use crate::optics::station::Station;
use crate::optics::trace::{Plate, TracedView};

/// The nominal plate (a flat front; the back flat, or the plane of the
/// wedge the station declares) traced through `station`, with a rim of `edge_margin_mm` beyond the aperture:
/// the prior [`super::SpectralSolver::new`] uses, for callers that prepare
/// it themselves ([`super::SpectralSolver::with_prior`]).
///
/// # Errors
/// [`SpectralError::Schedule`] when the element's aperture does not make a
/// flat surface.
pub fn nominal_plate_prior(
    station: &Station,
    edge_margin_mm: f64,
) -> Result<TracedView, SpectralError> {
    let (front, back) = station
        .element
        .nominal_surfaces(1)
        .map_err(|source| SpectralError::Aperture { source })?;
    let plate = Plate::new(station, front.clone(), back, edge_margin_mm);
    let view = TracedView::trace(station, &plate);
    let wedge = station.element.wedge;
    if !wedge.is_none() {
        let parallel = TracedView::trace(
            station,
            &Plate::new(station, front.clone(), front, edge_margin_mm),
        );
        let (seen, parallel) = (backs(&view), backs(&parallel));
        // A quarter of the parallel plate's back pixels: below it the back
        // face would be reported from a sliver of its aperture, if at all.
        if seen * WEDGE_VISIBLE_SHARE < parallel {
            return Err(SpectralError::WedgeOffScreen {
                arcmin: wedge.arcmin,
                azimuth_deg: wedge.azimuth_deg,
                seen,
                parallel,
            });
        }
    }
    Ok(view)
}

/// The wedged plate's back pixels must be at least 1 / this of the
/// parallel plate's.
const WEDGE_VISIBLE_SHARE: usize = 4;

/// Camera pixels whose back path reaches the screen.
fn backs(view: &TracedView) -> usize {
    view.pixels.iter().filter(|p| p.back.is_ok()).count()
}

/// The prior with the solver's view of it: the candidate pixels and, per
/// candidate, the back-minus-front offset borrowed at the rim.
pub(super) struct GeometryPrior {
    /// The nominal-plate prediction of every camera pixel.
    pub(super) view: TracedView,
    /// Camera pixel index of each candidate, row-major.
    pub(super) candidates: Vec<u32>,
    /// Per candidate, the back-minus-front offset borrowed at the rim.
    pub(super) borrowed: Vec<Option<[f64; 2]>>,
}

impl GeometryPrior {
    /// The candidates of `view` (grown by the configured margin, within
    /// the region of interest) and their borrowed offsets.
    pub(super) fn new(view: TracedView, config: &SpectralConfig) -> Self {
        let mut candidates = candidates(&view, i64::from(config.margin_px));
        if let Some([x0, y0, x1, y1]) = config.roi {
            let w = view.width as u32;
            candidates.retain(|&p| (x0..x1).contains(&(p % w)) && (y0..y1).contains(&(p / w)));
        }
        let borrowed = borrowed_offsets(&view, &candidates, i64::from(config.margin_px));
        GeometryPrior {
            view,
            candidates,
            borrowed,
        }
    }

    /// The screen points the prior predicts for camera pixel `k`: front,
    /// back and (when allowed) third, and the front plus `borrow` where
    /// the back path leaves through the rim.
    fn predicted(&self, k: usize, borrow: Option<[f64; 2]>, third: bool) -> Vec<[f64; 2]> {
        let p = &self.view.pixels[k];
        let mut pts = Vec::new();
        for (i, path) in [p.front, p.back, p.third].iter().enumerate() {
            if i == 2 && !third {
                continue;
            }
            if let Ok(hit) = path {
                pts.push([hit.u, hit.v]);
            }
        }
        if let (Ok(f), Err(_), Some(d)) = (p.front, p.back, borrow) {
            pts.push([f.u + d[0], f.v + d[1]]);
        }
        pts
    }

    /// Per direction, each candidate's demodulation centre (μ) — the middle
    /// of the screen points the station predicts for it ([`Self::predicted`]),
    /// taken from the nearest pixel with a prediction within the margin for
    /// candidates without one — and the band half-width: half the widest
    /// predicted spread plus `band_bins`.
    pub(super) fn band_centres(
        &self,
        design: &Design,
        config: &SpectralConfig,
        plans: &SpectrumPlans,
    ) -> (Vec<Vec<f64>>, Vec<f64>) {
        let (w, h) = (self.view.width as i64, self.view.height as i64);
        let third = config.third_reflection;
        let nd = design.axes.len();
        let mut centres = vec![Vec::with_capacity(self.candidates.len()); nd];
        let mut half = vec![0.0f64; nd];
        for (c, &k) in self.candidates.iter().enumerate() {
            let mut pts = self.predicted(k as usize, self.borrowed[c], third);
            if pts.is_empty() {
                let (x, y) = (i64::from(k) % w, i64::from(k) / w);
                pts = (1..=i64::from(config.margin_px))
                    .find_map(|r| {
                        ring(w, h, x, y, r)
                            .map(|(i, j)| self.predicted((j * w + i) as usize, None, third))
                            .find(|p| !p.is_empty())
                    })
                    .unwrap_or_else(|| vec![[0.0, 0.0]]);
            }
            for (d, ax) in design.axes.iter().enumerate() {
                let mus = pts.iter().map(|p| ax.s(p[0], p[1]));
                let lo = mus.clone().fold(f64::INFINITY, f64::min);
                let hi = mus.fold(f64::NEG_INFINITY, f64::max);
                centres[d].push(0.5 * (lo + hi));
                half[d] = half[d].max(0.5 * (hi - lo));
            }
        }
        let band = (0..nd)
            .map(|d| half[d] + config.band_bins * plans.bin(d))
            .collect();
        (centres, band)
    }
}

/// The square ring of pixels at distance `r` (in x or y) around `(x, y)`,
/// those inside the `w × h` image, in the one order every walk uses: side
/// by side along `d = −r..=r` (the corners come twice).
fn ring(w: i64, h: i64, x: i64, y: i64, r: i64) -> impl Iterator<Item = (i64, i64)> {
    (-r..=r)
        .flat_map(move |d| {
            [
                (x + d, y - r),
                (x + d, y + r),
                (x - r, y + d),
                (x + r, y + d),
            ]
        })
        .filter(move |&(i, j)| (0..w).contains(&i) && (0..h).contains(&j))
}

/// For each candidate whose prior has a front but no back path, the
/// back-minus-front offset averaged over the nearest ring (up to `radius`
/// px) of pixels that have both; the offset varies slowly over the element,
/// so the nearest ring predicts it well. The radius is the candidates'
/// margin: how far the real element may sit from where the station puts it,
/// and so how far the real edge of the back reflection may lie from the
/// flat plate's. Farther in, the back path really leaves through the rim.
fn borrowed_offsets(prior: &TracedView, candidates: &[u32], radius: i64) -> Vec<Option<[f64; 2]>> {
    let (w, h) = (prior.width as i64, prior.height as i64);
    let both = |x: i64, y: i64| -> Option<[f64; 2]> {
        let p = &prior.pixels[(y * w + x) as usize];
        match (p.front, p.back) {
            (Ok(f), Ok(b)) => Some([b.u - f.u, b.v - f.v]),
            _ => None,
        }
    };
    candidates
        .iter()
        .map(|&k| {
            let p = &prior.pixels[k as usize];
            if p.front.is_err() || p.back.is_ok() {
                return None;
            }
            let (x, y) = (i64::from(k) % w, i64::from(k) / w);
            (1..=radius).find_map(|r| {
                let (mut sum, mut n) = ([0.0; 2], 0.0);
                for (i, j) in ring(w, h, x, y, r) {
                    if let Some(d) = both(i, j) {
                        sum[0] += d[0];
                        sum[1] += d[1];
                        n += 1.0;
                    }
                }
                (n > 0.0).then(|| [sum[0] / n, sum[1] / n])
            })
        })
        .collect()
}

/// Pixels whose front or back path exists in the prior, grown by `margin` px.
pub(crate) fn candidates(prior: &TracedView, margin: i64) -> Vec<u32> {
    let (w, h) = (prior.width as i64, prior.height as i64);
    let mut mask = vec![false; prior.pixels.len()];
    for (k, p) in prior.pixels.iter().enumerate() {
        if p.front.is_err() && p.back.is_err() {
            continue;
        }
        let (i, j) = (k as i64 % w, k as i64 / w);
        for dj in -margin..=margin {
            for di in -margin..=margin {
                let (x, y) = (i + di, j + dj);
                if (0..w).contains(&x) && (0..h).contains(&y) {
                    mask[(y * w + x) as usize] = true;
                }
            }
        }
    }
    (0..mask.len() as u32)
        .filter(|&k| mask[k as usize])
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::trace::{Miss, PixelPaths, ScreenHit};

    fn hit(u: f64, v: f64) -> Result<ScreenHit, Miss> {
        Ok(ScreenHit { u, v, weight: 0.04 })
    }

    #[test]
    fn rim_pixels_borrow_the_nearest_ring_offset() {
        // 5×3 view: columns 0–2 have both paths with offsets (10, x), column
        // 3 only the front, column 4 nothing.
        let (w, h) = (5usize, 3usize);
        let pixels = (0..w * h)
            .map(|k| {
                let x = (k % w) as f64;
                let miss = Err(Miss::ElementMissed);
                let (front, back) = match k % w {
                    0..=2 => (hit(x, 0.0), hit(x + 10.0, x)),
                    3 => (hit(x, 0.0), miss),
                    _ => (miss, miss),
                };
                PixelPaths {
                    front,
                    back,
                    third: miss,
                }
            })
            .collect();
        let view = TracedView {
            width: w,
            height: h,
            pixels,
        };
        let all: Vec<u32> = (0..(w * h) as u32).collect();
        // Within one ring only column 3 reaches a pixel with both paths.
        let near = borrowed_offsets(&view, &all, 1);
        assert!(near
            .iter()
            .enumerate()
            .all(|(k, g)| g.is_some() == (k % w == 3)));
        let got = borrowed_offsets(&view, &all, 4);
        for (k, g) in got.iter().enumerate() {
            match k % w {
                // The nearest ring of (3, 1) holds column 2 at three rows
                // (offset (10, 2)); of (3, 0) and (3, 2), two of them.
                3 => assert_eq!(*g, Some([10.0, 2.0]), "pixel {k}"),
                // Both paths, or no front: nothing borrowed.
                _ => assert_eq!(*g, None, "pixel {k}"),
            }
        }
    }
}

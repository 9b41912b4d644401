//! The target spot's centroid in a camera frame, with its covariance.
//!
//! 1. Background: the median of each tile of a 16 × 12 grid, fitted by a
//!    quadratic surface with the tiles the spot lifts rejected (3 robust σ,
//!    iterated): ambient light, a gradient, vignetting.
//! 2. Noise: 1.4826 × the median absolute residual of all pixels (the spot
//!    is a small fraction of them), at least the quantisation's `1/√12`.
//! 3. Detection: pixels above the background by `k σ`, with `k` chosen so
//!    that pure noise lights on average 0.01 pixel of the whole frame;
//!    8-connected regions of at least [`MIN_SPOT_PX`] pixels. Exactly one
//!    must remain (smaller ones — hot pixels — are ignored); one touching
//!    the sensor's edge, or too near it for its window, is refused.
//! 4. Centre: the background-subtracted first moment over a square window
//!    of ±4 spot σ, re-centred on its own result (so a residual background
//!    error cancels to first order), pixel-centre convention (pixel
//!    `(i, j)` spans `[i, i+1) × [j, j+1)`, its centre at `(i + 0.5, j + 0.5)`).
//! 5. Covariance: first order in the pixel noise, `C = σ² Σ d dᵀ / F²` over
//!    the window (`d` the pixel's offset from the centre, `F` the flux).
//! 6. Then the maximum-likelihood fit of a pixel-integrated Gaussian over
//!    the same window ([`super::centroid_fit`]), at the Cramér–Rao bound
//!    (the moments leave 3.7× it on a Gaussian spot), with its covariance
//!    widened by the fit's reduced χ² where the read noise does not explain
//!    the residuals (shot noise, a spot's shape); a saturated spot, or one
//!    the fit does not converge on, keeps the moments.
//!
//! Hand-written: no crate in the tree finds spots; the steps are a few
//! dozen lines each and are tested on rendered spots against their truth.

use std::path::{Path, PathBuf};

use nalgebra::{Matrix2, Point2};

use super::centroid_fit::{fit_spot, Window};
use super::spot_background::{noise_std, Background};

use crate::formats::image_io::{self, GrayImage, ImageError};

/// Regions smaller than this are taken as hot pixels or noise, not a spot.
pub const MIN_SPOT_PX: usize = 4;

/// Why a frame gives no centroid. Each names the entry and the file.
#[derive(Debug, thiserror::Error)]
pub enum CentroidError {
    /// The frame could not be read.
    #[error("`{entry}`: {source}")]
    Image {
        /// The entry, e.g. `target_point[3]`.
        entry: String,
        /// The reading error, which names the file.
        #[source]
        source: ImageError,
    },
    /// The frame is not the nominal camera's size.
    #[error(
        "`{entry}`: {file}: the frame is {}x{} px, the nominal camera's sensor is {}x{} px; \
         capture it with the station's camera at full resolution (no region of interest, no binning)",
        found.0, found.1, expected.0, expected.1
    )]
    WrongSize {
        /// The entry.
        entry: String,
        /// The frame's file.
        file: PathBuf,
        /// Its `(width, height)`.
        found: (u32, u32),
        /// The nominal camera's.
        expected: (u32, u32),
    },
    /// No bright spot above the noise.
    #[error(
        "`{entry}`: {file}: no spot: the brightest pixel is {peak_sigma:.1} σ above the \
         background (noise {noise_counts:.1} counts), a spot needs {threshold_sigma:.1} σ over \
         {MIN_SPOT_PX} px; check the target is lit and in the camera's view, or expose longer"
    )]
    NoSpot {
        /// The entry.
        entry: String,
        /// The frame's file.
        file: PathBuf,
        /// The brightest pixel above the background, in noise σ.
        peak_sigma: f64,
        /// The detection threshold, in noise σ.
        threshold_sigma: f64,
        /// The noise, counts.
        noise_counts: f64,
    },
    /// More than one bright spot.
    #[error(
        "`{entry}`: {file}: {count} bright spots (near {positions:?} px), one is needed; \
         shade stray light or reflections and capture again"
    )]
    TwoSpots {
        /// The entry.
        entry: String,
        /// The frame's file.
        file: PathBuf,
        /// How many spots.
        count: usize,
        /// Rough centres of the brightest ones, px.
        positions: Vec<[f64; 2]>,
    },
    /// The spot touches, or is too near, the sensor's edge.
    #[error(
        "`{entry}`: {file}: the spot near ({:.0}, {:.0}) px is {distance_px} px from the \
         sensor's edge, its centroid needs {needed_px} px; move the target further into the view",
        position[0], position[1]
    )]
    OnEdge {
        /// The entry.
        entry: String,
        /// The frame's file.
        file: PathBuf,
        /// Rough centre, px.
        position: [f64; 2],
        /// Its distance from the nearest edge, px.
        distance_px: u32,
        /// What its window needs, px.
        needed_px: u32,
    },
}

impl crate::outcome::Classify for CentroidError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        match self {
            CentroidError::Image { source, .. } => source.outcome(),
            // A target frame without one clean spot is a session entry to
            // capture again: the session is not valid input yet.
            _ => Some(Outcome::Input),
        }
    }
}

/// A spot's centroid.
#[derive(Debug, Clone, PartialEq)]
pub struct Centroid {
    /// The centre, pixel-centre convention, px.
    pub position_px: Point2<f64>,
    /// Its covariance from the pixel noise, px².
    pub covariance_px2: Matrix2<f64>,
    /// Background-subtracted flux in the window, counts.
    pub flux_counts: f64,
    /// The brightest pixel above the background, counts.
    pub peak_counts: f64,
    /// Background under the spot, counts.
    pub background_counts: f64,
    /// Pixel noise, 1 σ, counts.
    pub noise_counts: f64,
    /// The spot's RMS radius per axis (second moments), px.
    pub sigma_px: [f64; 2],
    /// Pixels at the frame's full scale in the window (a saturated spot is
    /// still centred if it is symmetric, but its σ is not to be trusted).
    pub saturated_px: usize,
}

impl Centroid {
    /// 1 σ of x and y, px.
    pub fn std_px(&self) -> [f64; 2] {
        [
            self.covariance_px2[(0, 0)].sqrt(),
            self.covariance_px2[(1, 1)].sqrt(),
        ]
    }
}

/// Reads `file` and finds its spot; `entry` names it in errors, `expected`
/// is the nominal camera's `(width, height)`.
///
/// # Errors
/// [`CentroidError`] naming the entry and the file.
pub fn centroid_of_file(
    file: &Path,
    entry: &str,
    expected: Option<(u32, u32)>,
) -> Result<Centroid, CentroidError> {
    let image = image_io::read_gray(file).map_err(|source| CentroidError::Image {
        entry: entry.into(),
        source,
    })?;
    find_centroid(&image, file, entry, expected)
}

/// The spot of `image` (read from `file`, named `entry` in errors).
///
/// # Errors
/// [`CentroidError`]: wrong size, no spot, two spots, a spot on the edge.
pub fn find_centroid(
    image: &GrayImage,
    file: &Path,
    entry: &str,
    expected: Option<(u32, u32)>,
) -> Result<Centroid, CentroidError> {
    let found = (image.width, image.height);
    if let Some(expected) = expected.filter(|&e| e != found) {
        return Err(CentroidError::WrongSize {
            entry: entry.into(),
            file: file.to_path_buf(),
            found,
            expected,
        });
    }
    let (w, h) = (image.width as usize, image.height as usize);
    let values: Vec<f64> = image.data.iter().map(|&v| f64::from(v)).collect();
    let background = Background::fit(&values, w, h);
    let residual: Vec<f64> = (0..w * h)
        .map(|k| values[k] - background.at(k % w, k / w))
        .collect();
    let noise = noise_std(&residual);
    let threshold_sigma = detection_threshold(w * h);
    let regions = regions_above(&residual, w, h, threshold_sigma * noise);
    let ctx = Context { file, entry, w, h };
    let spot = ctx.single_spot(&regions, &residual, noise, threshold_sigma)?;
    let full = f64::from((1u32 << image.bit_depth) - 1);
    ctx.measure(&spot, &residual, &values, noise, full, &background)
}

struct Context<'a> {
    file: &'a Path,
    entry: &'a str,
    w: usize,
    h: usize,
}

/// A connected region above the threshold.
#[derive(Debug, Clone)]
struct Region {
    pixels: Vec<usize>,
    flux: f64,
}

impl Context<'_> {
    fn rough_centre(&self, r: &Region, residual: &[f64]) -> [f64; 2] {
        let (mut sx, mut sy, mut s) = (0.0, 0.0, 0.0);
        for &k in &r.pixels {
            let v = residual[k].max(0.0);
            sx += v * ((k % self.w) as f64 + 0.5);
            sy += v * ((k / self.w) as f64 + 0.5);
            s += v;
        }
        [sx / s, sy / s]
    }

    fn single_spot(
        &self,
        regions: &[Region],
        residual: &[f64],
        noise: f64,
        threshold_sigma: f64,
    ) -> Result<Region, CentroidError> {
        let mut spots: Vec<&Region> = regions
            .iter()
            .filter(|r| r.pixels.len() >= MIN_SPOT_PX)
            .collect();
        spots.sort_by(|a, b| b.flux.total_cmp(&a.flux));
        let Some(main) = spots.first() else {
            let peak = residual.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            return Err(CentroidError::NoSpot {
                entry: self.entry.into(),
                file: self.file.to_path_buf(),
                peak_sigma: peak / noise,
                threshold_sigma,
                noise_counts: noise,
            });
        };
        // Fragments of one spot (its ring, a noisy flank) lie within its own
        // window; anything further is a second spot.
        let c = self.rough_centre(main, residual);
        let reach = 4.0 * region_sigma(main, self.w, c) + 2.0;
        let apart: Vec<&&Region> = spots[1..]
            .iter()
            .filter(|r| {
                let p = self.rough_centre(r, residual);
                (p[0] - c[0]).abs().max((p[1] - c[1]).abs())
                    > reach + region_sigma(r, self.w, p) * 4.0
            })
            .collect();
        if !apart.is_empty() {
            let mut positions = vec![c];
            positions.extend(apart.iter().take(2).map(|r| self.rough_centre(r, residual)));
            return Err(CentroidError::TwoSpots {
                entry: self.entry.into(),
                file: self.file.to_path_buf(),
                count: 1 + apart.len(),
                positions,
            });
        }
        let mut merged = (*main).clone();
        for r in &spots[1..] {
            merged.pixels.extend_from_slice(&r.pixels);
            merged.flux += r.flux;
        }
        Ok(merged)
    }

    fn edge_error(&self, c: [f64; 2], distance_px: u32, needed_px: u32) -> CentroidError {
        CentroidError::OnEdge {
            entry: self.entry.into(),
            file: self.file.to_path_buf(),
            position: c,
            distance_px,
            needed_px,
        }
    }

    /// The windowed first moment, re-centred until the window stands still.
    fn measure(
        &self,
        spot: &Region,
        residual: &[f64],
        values: &[f64],
        noise: f64,
        full: f64,
        background: &Background,
    ) -> Result<Centroid, CentroidError> {
        let (w, h) = (self.w, self.h);
        let touches = spot.pixels.iter().any(|&k| {
            let (i, j) = (k % w, k / w);
            i == 0 || j == 0 || i + 1 == w || j + 1 == h
        });
        let mut c = self.rough_centre(spot, residual);
        if touches {
            return Err(self.edge_error(c, 0, 1));
        }
        let mut sigma = [region_sigma(spot, w, c); 2];
        let mut m = Moments::default();
        let (mut origin, mut size) = ([0, 0], 0);
        for _ in 0..4 {
            let half = (4.0 * sigma[0].max(sigma[1]) + 1.0).ceil() as usize;
            let (ci, cj) = (c[0].floor() as usize, c[1].floor() as usize);
            let room = ci.min(cj).min(w - 1 - ci).min(h - 1 - cj);
            if room < half {
                return Err(self.edge_error(c, room as u32, half as u32));
            }
            (origin, size) = ([ci - half, cj - half], 2 * half + 1);
            m = Moments::of(residual, values, w, origin, size, full);
            c = m.centre;
            sigma = m.sigma;
        }
        let var = noise * noise / (m.flux * m.flux);
        let mut covariance = Matrix2::new(m.sxx, m.sxy, m.sxy, m.syy) * var;
        // The fit where it holds (a saturated spot's flat top is no
        // Gaussian: its moments stay).
        let window = Window {
            residual,
            width: w,
            origin,
            size,
            noise,
        };
        if m.saturated == 0 {
            if let Some(f) = fit_spot(&window, c, sigma, m.flux) {
                c = f.centre;
                covariance = f.covariance;
                sigma = f.sigma;
            }
        }
        Ok(Centroid {
            position_px: Point2::new(c[0], c[1]),
            covariance_px2: covariance,
            flux_counts: m.flux,
            peak_counts: m.peak,
            background_counts: background.at(c[0] as usize, c[1] as usize),
            noise_counts: noise,
            sigma_px: sigma,
            saturated_px: m.saturated,
        })
    }
}

/// Background-subtracted moments over a square window.
#[derive(Debug, Clone, Default)]
struct Moments {
    centre: [f64; 2],
    sigma: [f64; 2],
    flux: f64,
    peak: f64,
    /// Σ dx², Σ dy², Σ dx dy over the window's pixels (unweighted: the
    /// centroid's sensitivity to each pixel's noise).
    sxx: f64,
    syy: f64,
    sxy: f64,
    saturated: usize,
}

impl Moments {
    fn of(
        residual: &[f64],
        values: &[f64],
        w: usize,
        origin: [usize; 2],
        size: usize,
        full: f64,
    ) -> Moments {
        let pixels = || {
            (origin[1]..origin[1] + size)
                .flat_map(move |j| (origin[0]..origin[0] + size).map(move |i| (i, j, j * w + i)))
        };
        let (mut f, mut fx, mut fy, mut peak, mut saturated) =
            (0.0, 0.0, 0.0, f64::NEG_INFINITY, 0);
        for (i, j, k) in pixels() {
            let v = residual[k];
            f += v;
            fx += v * (i as f64 + 0.5);
            fy += v * (j as f64 + 0.5);
            peak = peak.max(v);
            saturated += usize::from(values[k] >= full);
        }
        let centre = [fx / f, fy / f];
        let (mut mxx, mut myy, mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (i, j, k) in pixels() {
            let (dx, dy) = (i as f64 + 0.5 - centre[0], j as f64 + 0.5 - centre[1]);
            mxx += residual[k] * dx * dx;
            myy += residual[k] * dy * dy;
            sxx += dx * dx;
            syy += dy * dy;
            sxy += dx * dy;
        }
        // A pixel's own width adds 1/12 px² to the second moment.
        let sig = |m: f64| (m / f - 1.0 / 12.0).max(0.25).sqrt();
        Moments {
            centre,
            sigma: [sig(mxx), sig(myy)],
            flux: f,
            peak,
            sxx,
            syy,
            sxy,
            saturated,
        }
    }
}

/// The RMS radius of a region about `c` (at least 0.5 px).
fn region_sigma(r: &Region, w: usize, c: [f64; 2]) -> f64 {
    let n = r.pixels.len() as f64;
    let ss: f64 = r
        .pixels
        .iter()
        .map(|&k| ((k % w) as f64 + 0.5 - c[0]).powi(2) + ((k / w) as f64 + 0.5 - c[1]).powi(2))
        .sum();
    (ss / (2.0 * n)).sqrt().max(0.5)
}

/// The threshold in noise σ at which Gaussian noise alone lights on average
/// 0.01 of the frame's `n` pixels: the upper tail `Q(k) = 0.01 / n`, from
/// its asymptotic inverse `k² = t − ln(2π t)`, `t = 2 ln(n / 0.01)`
/// (within 0.01 σ at these tails).
pub fn detection_threshold(n: usize) -> f64 {
    let t = 2.0 * (n.max(1) as f64 / 0.01).ln();
    (t - (2.0 * std::f64::consts::PI * t).ln()).sqrt()
}

/// 8-connected regions of `residual > threshold`.
fn regions_above(residual: &[f64], w: usize, h: usize, threshold: f64) -> Vec<Region> {
    let mut seen = vec![false; w * h];
    let mut regions = Vec::new();
    let mut stack = Vec::new();
    for start in 0..w * h {
        if seen[start] || residual[start] <= threshold {
            continue;
        }
        seen[start] = true;
        stack.push(start);
        let mut region = Region {
            pixels: Vec::new(),
            flux: 0.0,
        };
        while let Some(k) = stack.pop() {
            region.pixels.push(k);
            region.flux += residual[k];
            let (i, j) = ((k % w) as isize, (k / w) as isize);
            for (di, dj) in [
                (-1, -1),
                (0, -1),
                (1, -1),
                (-1, 0),
                (1, 0),
                (-1, 1),
                (0, 1),
                (1, 1),
            ] {
                let (ni, nj) = (i + di, j + dj);
                if ni < 0 || nj < 0 || ni >= w as isize || nj >= h as isize {
                    continue;
                }
                let n = nj as usize * w + ni as usize;
                if !seen[n] && residual[n] > threshold {
                    seen[n] = true;
                    stack.push(n);
                }
            }
        }
        regions.push(region);
    }
    regions
}

#[cfg(test)]
#[path = "centroid_tests.rs"]
mod tests;

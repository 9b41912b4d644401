//! Exact ray tracing of the station: for every camera pixel, where its
//! rays land on the screen after the front reflection (S1), after one
//! internal reflection off the back (S2) and after two (S3), with each path's
//! Fresnel weight. This is the forward model that the simulator renders and
//! that the surface solvers invert.

mod intersect;
mod paths;

use rayon::prelude::*;

pub use intersect::{intersect, surface_normal, IntersectFailure, SurfaceHit, INTERSECT_TOL_MM};
pub use paths::{to_screen, Miss, PathOutcome, PixelPaths, ScreenHit};

use crate::optics::outline::Outline;
use crate::optics::station::Station;
use crate::optics::zernike::ZernikeSurface;

/// How far the element's physical rim lies beyond the reported aperture, mm,
/// unless told otherwise. The station format does not carry the rim; 3 mm is
/// the margin the shared fixtures were made with (their `scene.json`).
pub const DEFAULT_EDGE_MARGIN_MM: f64 = 3.0;

/// The element as the tracer sees it: both surfaces, the index, and the rim.
#[derive(Debug, Clone)]
pub struct Plate {
    /// Front surface `z = W1(x, y)`.
    pub front: ZernikeSurface,
    /// Back surface `z = −thickness_mm + W2(x, y)`.
    pub back: ZernikeSurface,
    /// Refractive index.
    pub refractive_index: f64,
    /// Nominal thickness, mm.
    pub thickness_mm: f64,
    /// The reported outline (the element's disk, rectangle or polygon).
    pub outline: Outline,
    /// How far the physical rim lies beyond the outline, mm: a path
    /// touching a surface beyond it is lost.
    pub edge_margin_mm: f64,
}

impl Plate {
    /// The station's element with the given surfaces and a rim
    /// `edge_margin_mm` beyond the aperture.
    pub fn new(
        station: &Station,
        front: ZernikeSurface,
        back: ZernikeSurface,
        edge_margin_mm: f64,
    ) -> Self {
        let e = &station.element;
        Plate {
            front,
            back,
            refractive_index: e.refractive_index,
            thickness_mm: e.thickness_mm,
            outline: e.outline(),
            edge_margin_mm,
        }
    }

    /// Whether `(x, y)` (element frame, mm) lies beyond the physical rim.
    pub fn outside_edge_xy(&self, x: f64, y: f64) -> bool {
        if self.outline.vertices().is_some() {
            return self.outline.outside_by_mm(x, y) > self.edge_margin_mm;
        }
        // The disk without a root, as the tracer did before outlines.
        let [cx, cy] = self.outline.centre_mm;
        let r = self.outline.radius_mm + self.edge_margin_mm;
        (x - cx).powi(2) + (y - cy).powi(2) > r * r
    }
}

/// The traced paths of every camera pixel, row-major `[row][column]`.
#[derive(Debug, Clone)]
pub struct TracedView {
    /// Camera width in pixels.
    pub width: usize,
    /// Camera height in pixels.
    pub height: usize,
    /// One entry per pixel, row-major.
    pub pixels: Vec<PixelPaths>,
}

impl TracedView {
    /// Traces every pixel of the station's camera through `plate` (all cores).
    pub fn trace(station: &Station, plate: &Plate) -> Self {
        // The plate is traced in the element's own frame (station v2's pose).
        let station = &station.element_frame();
        let cam = &station.camera;
        let (w, h) = (cam.width as usize, cam.height as usize);
        let pixels: Vec<PixelPaths> = (0..w * h)
            .into_par_iter()
            .with_min_len(256)
            .map(|k| {
                let (i, j) = ((k % w) as u32, (k / w) as u32);
                plate.trace_ray(&cam.position_mm, &cam.ray_direction(i, j), &station.screen)
            })
            .collect();
        TracedView {
            width: w,
            height: h,
            pixels,
        }
    }

    /// Screen coordinates in the spec's `screen_coords.npy` layout
    /// `[rows, columns, reflection (0 front, 1 back), (u, v)]`, NaN where a
    /// path does not exist.
    pub fn screen_coords(&self) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.pixels.len() * 4);
        for p in &self.pixels {
            for path in [&p.front, &p.back] {
                match path {
                    Ok(hit) => out.extend([hit.u, hit.v]),
                    Err(_) => out.extend([f64::NAN, f64::NAN]),
                }
            }
        }
        out
    }

    /// `[rows, columns, 2]` screen coordinates of the third path (NaN where absent).
    pub fn third_coords(&self) -> Vec<f64> {
        self.pixels
            .iter()
            .flat_map(|p| match p.third {
                Ok(hit) => [hit.u, hit.v],
                Err(_) => [f64::NAN, f64::NAN],
            })
            .collect()
    }

    /// `[rows, columns, 3]` Fresnel weights of the three paths (0 where absent).
    pub fn weights(&self) -> Vec<f64> {
        self.pixels
            .iter()
            .flat_map(|p| [p.front, p.back, p.third].map(|o| o.map_or(0.0, |h| h.weight)))
            .collect()
    }

    /// `[rows, columns, 3]` status codes: 0 hit, else [`Miss::code`].
    pub fn status(&self) -> Vec<u8> {
        self.pixels
            .iter()
            .flat_map(|p| [p.front, p.back, p.third].map(|o| o.err().map_or(0, Miss::code)))
            .collect()
    }

    /// Number of pixels whose path `k` (0 front, 1 back, 2 third) exists.
    pub fn count(&self, k: usize) -> usize {
        self.pixels
            .iter()
            .filter(|p| [p.front, p.back, p.third][k].is_ok())
            .count()
    }
}

/// Statistics of the back reflection's offset from the front one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OffsetStats {
    /// Pixels carrying both reflections.
    pub pixels: usize,
    /// Smallest, median and largest |S2 − S1|, screen pixels.
    pub min_median_max_px: [f64; 3],
}

impl TracedView {
    /// |S2 − S1| over the pixels that carry both reflections.
    pub fn offset_stats(&self) -> Option<OffsetStats> {
        let mut d: Vec<f64> = self
            .pixels
            .iter()
            .filter_map(|p| match (p.front, p.back) {
                (Ok(a), Ok(b)) => Some((b.u - a.u).hypot(b.v - a.v)),
                _ => None,
            })
            .collect();
        if d.is_empty() {
            return None;
        }
        d.sort_by(f64::total_cmp);
        Some(OffsetStats {
            pixels: d.len(),
            min_median_max_px: [d[0], d[d.len() / 2], d[d.len() - 1]],
        })
    }
}

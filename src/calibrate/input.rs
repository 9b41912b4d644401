//! What the joint adjustment reads: a session reduced to numbers (stage
//! readings in the stage frame, target centroids, the reference flat's
//! decoded screen points), independent of how they were loaded. The lead's
//! session loader builds it from a session folder; the simulated sessions
//! (`crate::calibrate::simulate`) build it from a known truth.

use nalgebra::{Matrix2, Point2, Vector3};

use crate::optics::station::Station;

/// One point target: where the stage put it and where the camera saw it.
#[derive(Debug, Clone, PartialEq)]
pub struct Target {
    /// Stage reading of the target, mm (stage frame).
    pub stage_mm: Vector3<f64>,
    /// Its centroid, continuous pixel position (pixel-centre convention:
    /// the centre of pixel `(i, j)` is `(i + 0.5, j + 0.5)`).
    pub pixel: Point2<f64>,
    /// The centroid's covariance, px².
    pub pixel_cov_px2: Matrix2<f64>,
}

/// One camera pixel of the reference flat's acquisition and the screen
/// point its reflection was decoded at.
#[derive(Debug, Clone, PartialEq)]
pub struct FlatPixel {
    /// Camera pixel (column `i`, row `j`); its ray is the one through the
    /// pixel's centre.
    pub pixel: [u32; 2],
    /// Decoded screen coordinate `(u, v)`, screen px (spec convention).
    pub screen_px: Point2<f64>,
    /// Its covariance, screen px².
    pub screen_cov_px2: Matrix2<f64>,
}

/// One marked screen pixel (`[[screen_point]]`): the PSM focused on it.
#[derive(Debug, Clone, PartialEq)]
pub struct MarkedPixel {
    /// Stage reading of the PSM's focus, mm (stage frame).
    pub stage_mm: Vector3<f64>,
    /// The mark's screen coordinate `(u, v)`, screen px (spec convention).
    pub screen_px: Point2<f64>,
}

/// Everything one calibration session says, in the stage frame.
#[derive(Debug, Clone)]
pub struct CalibrationInput {
    /// Starting values (v1 or v2): sensor and screen resolutions and
    /// pitches, the element's aperture, a rough geometry.
    pub nominal: Station,
    /// 1 σ of one stage reading, each axis, mm.
    pub stage_std_mm: f64,
    /// Stage x, y of the element's centre, mm: the world origin.
    pub element_center_stage_mm: [f64; 2],
    /// The element's measured thickness, mm, and its 1 σ (taken as given).
    pub thickness_mm: (f64, f64),
    /// The element's measured refractive index and its 1 σ (taken as given).
    pub refractive_index: (f64, f64),
    /// The PSM focused on the reference flat, stage frame, mm.
    pub flat_points_stage_mm: Vec<Vector3<f64>>,
    /// The PSM focused on the element's front, stage frame, mm (may be empty).
    pub element_points_stage_mm: Vec<Vector3<f64>>,
    /// The point targets.
    pub targets: Vec<Target>,
    /// The reference flat's decoded screen points.
    pub flat_screen: Vec<FlatPixel>,
    /// The marked screen pixels the PSM was focused on (may be empty).
    pub screen_points: Vec<MarkedPixel>,
}

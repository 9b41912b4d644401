//! The surface-domain fit's account of itself, for `summary.json` and the
//! maps: what `pipeline` reports of a fit and `report` reads.

use super::{Clipped, Iteration, Starts, ThirdReflection};

/// What the surface-domain fit did, for `summary.json` and the maps.
#[derive(Debug, Clone)]
pub struct DirectReport {
    /// Its iterations.
    pub iterations: Vec<Iteration>,
    /// Whether it converged.
    pub converged: bool,
    /// Pixels fitted with two reflections.
    pub two_reflection_pixels: usize,
    /// The fitted pixels' clipped samples (fitted at their conditional means).
    pub clipped: Clipped,
    /// The third reflection's factor and σ, where the frames showed it.
    pub third_reflection: Option<ThirdReflection>,
    /// The second start's comparison, where there was one.
    pub starts: Option<Starts>,
    /// Wall time, s.
    pub seconds: f64,
    /// Camera width, pixels (the maps' row length).
    pub width: usize,
    /// `[rows, columns, 2, 2]`: S1, S2 the fitted surfaces predict.
    pub predicted: Vec<f64>,
    /// `[rows, columns]`: each pixel's χ² against that prediction.
    pub chi2_map: Vec<f64>,
    /// What the per-pixel route gave, for comparison: its error message
    /// when it measured nothing.
    pub per_pixel_failed: Option<String>,
}

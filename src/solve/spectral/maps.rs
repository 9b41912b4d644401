//! The per-pixel results of a whole image ([`SpectralMaps`]) and their NPY
//! files (the spec's layout).

use std::path::Path;

use super::{PixelResult, SpectralError};
use crate::formats::npy;

/// The per-pixel results of a whole image.
#[derive(Debug, Clone)]
pub struct SpectralMaps {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Row-major results under the scene's model.
    pub pixels: Vec<PixelResult>,
    /// Per pixel, the number of reflections its own BIC prefers (0: none fitted).
    pub preferred: Vec<u8>,
    /// Reflections in the model chosen for the scene.
    pub scene_model: u8,
    /// BIC summed over the compared pixels for 1, 2, 3 reflections (0 when not compared).
    pub bic_sums: [f64; 3],
    /// Saturation level used, counts.
    pub saturation_counts: Option<u16>,
}

impl SpectralMaps {
    /// `[rows, columns, 2, 2]` screen coordinates (spec layout).
    pub fn screen_coords(&self) -> Vec<f64> {
        self.pixels
            .iter()
            .flat_map(|p| [p.s[0][0], p.s[0][1], p.s[1][0], p.s[1][1]])
            .collect()
    }

    /// `[rows, columns, 2, 2]` standard deviations of the screen coordinates, px.
    pub fn screen_std(&self) -> Vec<f64> {
        self.pixels
            .iter()
            .flat_map(|p| [p.std[0][0], p.std[0][1], p.std[1][0], p.std[1][1]])
            .collect()
    }

    /// `[rows, columns, 4, 4]` covariance of `(u1, v1, u2, v2)`, px².
    pub fn screen_cov(&self) -> Vec<f64> {
        self.pixels
            .iter()
            .flat_map(|p| p.cov.into_iter().flatten())
            .collect()
    }

    /// Writes `screen_coords.npy` and the quality maps into `dir`.
    ///
    /// # Errors
    /// [`SpectralError::Npy`] naming the file.
    pub fn write(&self, dir: &Path) -> Result<(), SpectralError> {
        let (h, w) = (self.height, self.width);
        let px = &self.pixels;
        npy::write_f64(
            &dir.join("screen_coords.npy"),
            &[h, w, 2, 2],
            &self.screen_coords(),
        )?;
        npy::write_f64(
            &dir.join("screen_std.npy"),
            &[h, w, 2, 2],
            &self.screen_std(),
        )?;
        npy::write_f64(
            &dir.join("screen_cov.npy"),
            &[h, w, 4, 4],
            &self.screen_cov(),
        )?;
        let amp: Vec<f64> = px.iter().flat_map(|p| p.amp).collect();
        npy::write_f64(&dir.join("amplitudes.npy"), &[h, w, 4], &amp)?;
        let scalar = |f: fn(&PixelResult) -> f64| px.iter().map(f).collect::<Vec<f64>>();
        npy::write_f64(&dir.join("tau_max.npy"), &[h, w], &scalar(|p| p.tau_max))?;
        npy::write_f64(
            &dir.join("residual_rms.npy"),
            &[h, w],
            &scalar(|p| p.residual_rms),
        )?;
        npy::write_f64(
            &dir.join("separation_bins.npy"),
            &[h, w],
            &scalar(|p| p.separation_bins),
        )?;
        npy::write_u8(
            &dir.join("reflections.npy"),
            &[h, w],
            &px.iter().map(|p| p.model).collect::<Vec<u8>>(),
        )?;
        npy::write_u8(
            &dir.join("preferred_reflections.npy"),
            &[h, w],
            &self.preferred,
        )?;
        npy::write_u16(
            &dir.join("flags.npy"),
            &[h, w],
            &px.iter().map(|p| p.flags.bits()).collect::<Vec<u16>>(),
        )?;
        npy::write_u16(
            &dir.join("iterations.npy"),
            &[h, w],
            &px.iter().map(|p| p.iterations).collect::<Vec<u16>>(),
        )?;
        Ok(())
    }

    /// Pixels with both screen points found.
    pub fn found_both(&self) -> usize {
        self.pixels
            .iter()
            .filter(|p| p.s[0][0].is_finite() && p.s[1][0].is_finite())
            .count()
    }
}

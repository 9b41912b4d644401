//! From normalised intensity `g` to the 8-bit level a display is sent: the
//! gamma convention, the dither, and the CPU oracle of a whole frame.
//!
//! **Gamma.** A display profile's `gamma` γ says that emitted luminance is
//! ∝ `(level / 255)^γ`. To make the luminance ∝ `g` the ideal (unquantised)
//! level is `255 · g^(1/γ)`; γ = 1 sends `255 · g` unchanged.
//!
//! **Quantisation.** The sent level is `min(floor(ideal + t), 255)`: with
//! [`Dither::None`] `t = 1/2` (round half up, within ½ level of the ideal);
//! with [`Dither::Bayer8`] `t = (B(c, r) + ½) / 64` from the 8×8 Bayer matrix
//! at screen column `c`, row `r`, so that over a Bayer tile where the ideal
//! level is constant the mean sent level is within 1/128 level of the ideal.
//!
//! The GPU shader (`fringe.wgsl`) computes the same in `f32`; this module is
//! the `f64` reference the tests hold it to.

use crate::acquire::patterns::{FringeAxis, Pattern};
use crate::optics::station::DisplayProfile;

use super::DisplayError;

/// How the 8-bit levels are quantised.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dither {
    /// Round to the nearest level: exact, reproducible levels.
    None,
    /// Ordered dithering with the 8×8 Bayer matrix: the mean over a tile
    /// carries fractions of a level (finer effective intensity steps).
    Bayer8,
}

/// The intensity-to-level mapping of one display.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shading {
    /// Display gamma γ (emitted luminance ∝ (level / 255)^γ), > 0.
    pub gamma: f64,
    /// Quantisation.
    pub dither: Dither,
}

impl Shading {
    /// A shading with gamma `gamma`.
    ///
    /// # Errors
    /// [`DisplayError::Invalid`] when `gamma` is not a finite number > 0.
    pub fn new(gamma: f64, dither: Dither) -> Result<Self, DisplayError> {
        if !(gamma.is_finite() && gamma > 0.0) {
            return Err(DisplayError::Invalid {
                field: "gamma",
                problem: format!("expected a finite number > 0, found {gamma}"),
            });
        }
        Ok(Shading { gamma, dither })
    }

    /// The shading of a display profile (its `gamma`).
    ///
    /// # Errors
    /// [`DisplayError::Invalid`] when the profile's gamma is not > 0.
    pub fn from_profile(profile: &DisplayProfile, dither: Dither) -> Result<Self, DisplayError> {
        Shading::new(profile.gamma, dither)
    }

    /// The ideal, unquantised level `255 · g^(1/γ)` of intensity `g ∈ [0, 1]`.
    pub fn ideal_level(&self, g: f64) -> f64 {
        255.0 * g.clamp(0.0, 1.0).powf(1.0 / self.gamma)
    }

    /// The dither threshold `t ∈ (0, 1)` at screen column `col`, row `row`.
    pub fn threshold(&self, col: u32, row: u32) -> f64 {
        match self.dither {
            Dither::None => 0.5,
            Dither::Bayer8 => (f64::from(bayer8(col, row)) + 0.5) / 64.0,
        }
    }

    /// The level sent for intensity `g` at screen pixel (`col`, `row`).
    pub fn level(&self, g: f64, col: u32, row: u32) -> u8 {
        (self.ideal_level(g) + self.threshold(col, row))
            .floor()
            .min(255.0) as u8
    }
}

/// The 8×8 Bayer index `B ∈ 0..64` of screen pixel (`col`, `row`): the bits
/// of `col ⊕ row` and `row` interleaved, most significant from the lowest.
/// Its 2×2 corner is `[[0, 2], [3, 1]]` (rows of `row`).
pub fn bayer8(col: u32, row: u32) -> u32 {
    let (x, y) = (col & 7, row & 7);
    let xy = x ^ y;
    let mut b = 0;
    for k in 0..3 {
        b |= ((xy >> k) & 1) << (2 * (2 - k) + 1);
        b |= ((y >> k) & 1) << (2 * (2 - k));
    }
    b
}

/// The frame a `width × height` display shows for `pattern`: one level per
/// pixel, row-major, each computed in `f64` from [`Pattern::intensity_at`] at
/// the pixel centre `(c + ½, r + ½)` (spec, "Fringe patterns"). The slow,
/// obvious reference the GPU renderer is tested against.
pub fn reference_frame(pattern: &Pattern, width: u32, height: u32, shading: &Shading) -> Vec<u8> {
    let axis = FringeAxis::new(pattern.direction_deg, width, height);
    let mut out = Vec::with_capacity(width as usize * height as usize);
    for row in 0..height {
        for col in 0..width {
            let s = axis.s(f64::from(col) + 0.5, f64::from(row) + 0.5);
            out.push(shading.level(pattern.intensity_at(s), col, row));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bayer8_is_a_permutation_with_the_classic_corners() {
        let mut seen = [false; 64];
        for r in 0..8 {
            for c in 0..8 {
                seen[bayer8(c, r) as usize] = true;
            }
        }
        assert!(seen.iter().all(|&s| s));
        // The textbook matrices: 2×2 [[0,2],[3,1]] (× 16 in the 8×8 one); the
        // 4×4 one is the 8×8 one's even rows and columns (its first row is
        // 0 32 8 40 2 34 10 42).
        assert_eq!(
            [bayer8(0, 0), bayer8(1, 0), bayer8(0, 1), bayer8(1, 1)],
            [0, 32, 48, 16]
        );
        let classic4 = [[0, 8, 2, 10], [12, 4, 14, 6], [3, 11, 1, 9], [15, 7, 13, 5]];
        let first_row: Vec<u32> = (0..8).map(|c| bayer8(c, 0)).collect();
        assert_eq!(first_row, [0, 32, 8, 40, 2, 34, 10, 42]);
        for (r, line) in classic4.iter().enumerate() {
            for (c, &v) in line.iter().enumerate() {
                assert_eq!(bayer8(2 * c as u32, 2 * r as u32), v, "({c}, {r})");
            }
        }
    }

    #[test]
    fn dithered_tile_mean_is_within_1_128_of_a_constant_level() {
        let shading = Shading::new(2.2, Dither::Bayer8).unwrap();
        for k in 0..=1000 {
            let g = f64::from(k) / 1000.0;
            let ideal = shading.ideal_level(g);
            let mut sum = 0.0;
            for r in 0..8 {
                for c in 0..8 {
                    sum += f64::from(shading.level(g, c, r));
                }
            }
            // Thresholds (B + ½)/64 split [0, 1) into 64 equal steps: the count
            // of levels rounded up is round(64 · frac): error ≤ 1/128.
            assert!((sum / 64.0 - ideal).abs() <= 1.0 / 128.0 + 1e-12, "g = {g}");
        }
    }

    #[test]
    fn gamma_convention_makes_luminance_proportional_to_g() {
        let shading = Shading::new(2.2, Dither::None).unwrap();
        for g in [0.0, 0.01, 0.25, 0.5, 1.0] {
            let lum = (shading.ideal_level(g) / 255.0).powf(2.2);
            assert!((lum - g).abs() < 1e-12, "{g}");
        }
        assert_eq!(shading.level(1.0, 3, 5), 255);
        assert_eq!(shading.level(0.0, 3, 5), 0);
        assert!(Shading::new(0.0, Dither::None).is_err());
        assert!(Shading::new(f64::NAN, Dither::None).is_err());
    }
}

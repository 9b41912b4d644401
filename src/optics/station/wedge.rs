//! The element's wedge (station v2, `[element] wedge_arcmin`,
//! `wedge_azimuth_deg`): the angle the plate was made with between its
//! faces, a prior like the rest of the station.
//!
//! In the element's frame the nominal back is the plane
//! `z' = −t + tan(w) ((x' − cx) cos φ + (y' − cy) sin φ)`, so the plate
//! thins along `φ` and `t` is its thickness at the aperture centre. The
//! reported back stays measured from `z' = −t`: the wedge is its tilt terms,
//! Noll Z2 and Z3 = `tan(w) R cos φ / 2`, `tan(w) R sin φ / 2` (RMS-normalised
//! `Z2 = 2ρ cos θ` has slope `2/R`), in nm. Every stage that starts from the
//! nominal plate starts from these ([`Wedge::back_tilt_nm`]).

use crate::optics::zernike::{ZernikeBasis, ZernikeError, ZernikeSurface};

/// The most a station may declare, arcmin (the spec's limit).
pub const MAX_WEDGE_ARCMIN: f64 = 120.0;

/// The wedge between the element's faces.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Wedge {
    /// The angle between the faces, arcmin (0: a parallel plate).
    pub arcmin: f64,
    /// The direction in the element's frame along which the plate thins,
    /// degrees from +x' towards +y'.
    pub azimuth_deg: f64,
}

impl Wedge {
    /// A parallel plate.
    pub const NONE: Wedge = Wedge {
        arcmin: 0.0,
        azimuth_deg: 0.0,
    };

    /// Whether the faces are nominally parallel.
    pub fn is_none(&self) -> bool {
        self.arcmin == 0.0
    }

    /// The back plane's slope `(∂z'/∂x', ∂z'/∂y')`: `tan(w) (cos φ, sin φ)`.
    pub fn slope(&self) -> [f64; 2] {
        let t = (self.arcmin / 60.0).to_radians().tan();
        let phi = self.azimuth_deg.to_radians();
        [t * phi.cos(), t * phi.sin()]
    }

    /// The wedge of a back whose plane has slope `s` (the inverse of
    /// [`Wedge::slope`]; the azimuth in `[0, 360)`, 0 for a parallel plate).
    pub fn from_slope(s: [f64; 2]) -> Wedge {
        let t = s[0].hypot(s[1]);
        if t == 0.0 {
            return Wedge::NONE;
        }
        Wedge {
            arcmin: t.atan().to_degrees() * 60.0,
            azimuth_deg: s[1].atan2(s[0]).to_degrees().rem_euclid(360.0),
        }
    }

    /// The back's Noll Z2 and Z3 in nm on a Zernike radius `radius_mm`.
    pub fn back_tilt_nm(&self, radius_mm: f64) -> [f64; 2] {
        self.slope().map(|s| s * radius_mm / 2.0 * 1e6)
    }

    /// The wedge whose back tilt terms are `z2_z3_nm` on `radius_mm`.
    pub fn from_back_tilt_nm(z2_z3_nm: [f64; 2], radius_mm: f64) -> Wedge {
        Wedge::from_slope(z2_z3_nm.map(|a| 2.0 * a / (radius_mm * 1e6)))
    }

    /// Nominal back coefficients (nm) of `terms` Noll terms: zero but for
    /// the wedge's tilts (a single piston term stays flat: no room for a
    /// tilt means a caller that wants one asks for three).
    pub fn back_coefficients_nm(&self, terms: usize, radius_mm: f64) -> Vec<f64> {
        let mut c = vec![0.0; terms];
        let [z2, z3] = self.back_tilt_nm(radius_mm);
        if terms >= 3 {
            c[1] = z2;
            c[2] = z3;
        }
        c
    }
}

impl Wedge {
    /// `back` with this wedge's tilts added to its Z2 and Z3 (a drawn or
    /// designed departure on the plate as made); a back of fewer than three
    /// terms is widened to three.
    ///
    /// # Errors
    /// [`ZernikeError`] for a basis that cannot be widened.
    pub fn added_to(&self, back: &ZernikeSurface) -> Result<ZernikeSurface, ZernikeError> {
        if self.is_none() {
            return Ok(back.clone());
        }
        let b = back.basis();
        let mut c = back.coefficients_nm().to_vec();
        c.resize(c.len().max(3), 0.0);
        let [z2, z3] = self.back_tilt_nm(b.radius_mm());
        c[1] += z2;
        c[2] += z3;
        let basis = ZernikeBasis::new(c.len(), b.radius_mm(), b.center_mm())?;
        ZernikeSurface::new(basis, c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn back_tilt_is_the_spec_closed_form() {
        // One arcmin on a 25 mm radius: tan(1') · 25 / 2 mm = 3.636 µm.
        let w = Wedge {
            arcmin: 1.0,
            azimuth_deg: 0.0,
        };
        let [z2, z3] = w.back_tilt_nm(25.0);
        let expect = (1.0f64 / 60.0).to_radians().tan() * 25.0 / 2.0 * 1e6;
        assert!((z2 - expect).abs() < 1e-9 && z3.abs() < 1e-9, "{z2} {z3}");
        assert!((expect - 3636.1).abs() < 0.1);
    }

    #[test]
    fn slope_round_trips_through_the_tilt_terms() {
        for (a, phi) in [(30.0, 0.0), (1.0, 90.0), (60.0, 225.0), (0.5, 359.0)] {
            let w = Wedge {
                arcmin: a,
                azimuth_deg: phi,
            };
            let back = Wedge::from_back_tilt_nm(w.back_tilt_nm(12.5), 12.5);
            assert!((back.arcmin - a).abs() < 1e-9 * a, "{back:?}");
            assert!((back.azimuth_deg - phi).abs() < 1e-7, "{back:?}");
        }
        assert!(Wedge::from_slope([0.0, 0.0]).is_none());
    }
}

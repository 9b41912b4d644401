//! Seeded random surfaces for simulated scenes.

use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;

use super::{ZernikeBasis, ZernikeError, ZernikeSurface};

/// How to draw a random surface: tilt terms and a band of higher Noll terms
/// scaled to a given RMS.
#[derive(Debug, Clone, PartialEq)]
pub struct RandomSurfaceSpec {
    /// Number of coefficients in the result (Noll j = 1 … n_terms).
    pub n_terms: usize,
    /// First Noll index of the random band (4 = defocus).
    pub first_term: usize,
    /// RMS of the band over the unit disk, nm (Noll normalisation makes this
    /// the root sum of squares of its coefficients).
    pub rms_nm: f64,
    /// Standard deviation of each tilt coefficient (j = 2, 3), nm.
    pub tilt_std_nm: f64,
}

impl Default for RandomSurfaceSpec {
    /// What the shared fixtures use: terms 4–36 at 60 nm RMS, tilts of 100 nm.
    fn default() -> Self {
        RandomSurfaceSpec {
            n_terms: 36,
            first_term: 4,
            rms_nm: 60.0,
            tilt_std_nm: 100.0,
        }
    }
}

impl RandomSurfaceSpec {
    /// A front (seed) and a back (seed + 1) surface on the disk of
    /// `radius_mm` about `center_mm`.
    ///
    /// # Errors
    /// [`ZernikeError`] for an invalid radius.
    pub fn draw_pair(
        &self,
        radius_mm: f64,
        center_mm: [f64; 2],
        seed: u64,
    ) -> Result<(ZernikeSurface, ZernikeSurface), ZernikeError> {
        let basis = ZernikeBasis::new(self.n_terms, radius_mm, center_mm)?;
        Ok((
            ZernikeSurface::new(basis.clone(), self.draw(seed))?,
            ZernikeSurface::new(basis, self.draw(seed.wrapping_add(1)))?,
        ))
    }

    /// Draws coefficients (nm, Noll j = k + 1 at index k, piston 0).
    pub fn draw(&self, seed: u64) -> Vec<f64> {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let mut c = vec![0.0; self.n_terms];
        let mut normal = || -> f64 { StandardNormal.sample(&mut rng) };
        for (k, ck) in c.iter_mut().enumerate().skip(1) {
            let j = k + 1;
            if j <= 3 {
                *ck = self.tilt_std_nm * normal();
            } else if j >= self.first_term {
                *ck = normal();
            }
        }
        let start = self.first_term.max(4) - 1;
        let band = c
            .get(start..)
            .map_or(0.0, |b| b.iter().map(|x| x * x).sum::<f64>().sqrt());
        if band > 0.0 {
            for ck in c.iter_mut().skip(start) {
                *ck *= self.rms_nm / band;
            }
        }
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn band_has_the_requested_rms_and_is_seeded() {
        let spec = RandomSurfaceSpec::default();
        let a = spec.draw(7);
        let rms: f64 = a[3..].iter().map(|x| x * x).sum::<f64>().sqrt();
        assert!((rms - 60.0).abs() < 1e-9);
        assert_eq!(a[0], 0.0);
        assert_eq!(a, spec.draw(7));
        assert_ne!(a, spec.draw(8));
    }
}

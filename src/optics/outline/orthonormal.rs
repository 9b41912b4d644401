//! Polynomials orthonormal over an outline: the Noll Zernike terms on the
//! circumscribing disk, Gram–Schmidt orthonormalised over the outline in
//! Noll order (for a rectangle inscribed in the disk, Mahajan & Dai's
//! rectangular polynomials, J. Opt. Soc. Am. A 24, 2994 (2007)).
//!
//! With `G = ⟨Z Zᵀ⟩` the Gram matrix (mean over the outline's area, exact
//! quadrature) and `G = L Lᵀ`, the orthonormal set is `Q = L⁻¹ Z`, so a
//! surface `Σ c_j Z_j` is `Σ a_k Q_k` with `a = Lᵀ c`. Each `Q_k` spans the
//! first `k` Zernike terms: `Q1` is piston, `Q1–Q3` the plane, `Q1–Q4`
//! piston, plane and `x² + y²`. So the RMS over the outline with the
//! best-fit plane removed is `‖a_{4…}‖`, and the expected RMS error is
//! `√tr((Lᵀ Σ L)_{4…})`: the same formulas as the disk's, on `a`. For the
//! disk itself `G = I` and `a = c` exactly.

use nalgebra::DMatrix;

use super::{quadrature, Outline};
use crate::optics::zernike::{ZernikeBasis, ZernikeError};

/// What went wrong building the orthonormal set.
#[derive(Debug, thiserror::Error)]
pub enum OutlineError {
    /// The Zernike basis could not be made.
    #[error(transparent)]
    Zernike(#[from] ZernikeError),
    /// The Gram matrix is not (numerically) positive definite.
    #[error(
        "the {shape} outline is too narrow for {terms} Zernike terms on its {radius_mm} mm disk: \
         term {term} is {ratio:.1e} of the first over it (give fewer terms)"
    )]
    TooNarrow {
        /// The shape in words.
        shape: String,
        /// Terms asked for.
        terms: usize,
        /// The disk's radius, mm.
        radius_mm: f64,
        /// The first Noll term (1-based) that is not independent.
        term: usize,
        /// Its remaining norm over the first's.
        ratio: f64,
    },
}

impl crate::outcome::Classify for OutlineError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        Some(crate::outcome::Outcome::Input)
    }
}

/// The least remaining norm a term may keep after the earlier ones are
/// projected out (relative to piston's): below it the set is numerically
/// dependent over the outline (f64 leaves ~8 digits after Cholesky's
/// squaring of the condition).
const LEAST_PIVOT: f64 = 1e-6;

/// The change of basis to polynomials orthonormal over an outline.
#[derive(Debug, Clone, PartialEq)]
pub struct Orthonormal {
    /// `Lᵀ`: `a = Lᵀ c` (upper triangular, terms × terms).
    lt: DMatrix<f64>,
    identity: bool,
}

impl Orthonormal {
    /// The set for `terms` Noll terms on `outline`'s disk.
    ///
    /// # Errors
    /// [`OutlineError`] for an invalid basis or an outline too narrow.
    pub fn new(outline: &Outline, terms: usize) -> Result<Self, OutlineError> {
        let Some(vertices) = outline.vertices() else {
            return Ok(Self::identity(terms));
        };
        let basis = ZernikeBasis::new(terms, outline.radius_mm, outline.centre_mm)?;
        let degree = 2 * basis.max_order() as usize;
        let rule = quadrature::polygon_rule(vertices, degree);
        let area: f64 = rule.iter().map(|r| r.1).sum();
        let mut g = DMatrix::zeros(terms, terms);
        let mut z = vec![0.0; terms];
        for ([x, y], w) in rule {
            basis.eval_values_into(x, y, &mut z)?;
            let zv = nalgebra::DVectorView::from_slice(&z, terms);
            g.ger(w / area, &zv, &zv, 1.0);
        }
        // Cholesky by hand so that the first dependent term can be named.
        let mut l = DMatrix::<f64>::zeros(terms, terms);
        for j in 0..terms {
            let mut d = g[(j, j)];
            for k in 0..j {
                d -= l[(j, k)] * l[(j, k)];
            }
            let ratio = if d > 0.0 { d.sqrt() } else { 0.0 } / g[(0, 0)].sqrt();
            let independent = ratio > LEAST_PIVOT;
            if !independent {
                return Err(OutlineError::TooNarrow {
                    shape: outline.shape.describe(),
                    terms,
                    radius_mm: outline.radius_mm,
                    term: j + 1,
                    ratio,
                });
            }
            l[(j, j)] = d.sqrt();
            for i in j + 1..terms {
                let mut s = g[(i, j)];
                for k in 0..j {
                    s -= l[(i, k)] * l[(j, k)];
                }
                l[(i, j)] = s / l[(j, j)];
            }
        }
        Ok(Orthonormal {
            lt: l.transpose(),
            identity: false,
        })
    }

    /// The disk's own set: `a = c`.
    pub fn identity(terms: usize) -> Self {
        Orthonormal {
            lt: DMatrix::identity(terms, terms),
            identity: true,
        }
    }

    /// Whether `a = c` (the outline is the Zernike disk).
    pub fn is_identity(&self) -> bool {
        self.identity
    }

    /// Number of terms.
    pub fn terms(&self) -> usize {
        self.lt.nrows()
    }

    /// `Lᵀ`, the matrix taking Zernike coefficients to orthonormal ones.
    pub fn matrix(&self) -> &DMatrix<f64> {
        &self.lt
    }

    /// The orthonormal coefficients `a = Lᵀ c` of Zernike coefficients `c`
    /// (missing terms count as zero, terms beyond the set are ignored).
    pub fn coefficients(&self, c: &[f64]) -> Vec<f64> {
        let n = self.terms();
        if self.identity {
            let mut a = c.to_vec();
            a.resize(n, 0.0);
            return a;
        }
        (0..n)
            .map(|i| (i..n.min(c.len())).map(|j| self.lt[(i, j)] * c[j]).sum())
            .collect()
    }

    /// `Lᵀ Σ L` of a Zernike coefficient covariance `Σ` (terms × terms;
    /// a smaller one is padded with zeros).
    pub fn covariance(&self, cov: &DMatrix<f64>) -> DMatrix<f64> {
        let n = self.terms();
        let mut s = DMatrix::zeros(n, n);
        let m = n.min(cov.nrows()).min(cov.ncols());
        s.view_mut((0, 0), (m, m))
            .copy_from(&cov.view((0, 0), (m, m)));
        if self.identity {
            return s;
        }
        &self.lt * s * self.lt.transpose()
    }

    /// The Zernike coefficients of `c` with its first `removed` orthonormal
    /// terms taken out (3: the best-fit plane over the outline). Only the
    /// first `removed` coefficients change: `Q1…Q_removed` span `Z1…Z_removed`.
    pub fn without_first(&self, c: &[f64], removed: usize) -> Vec<f64> {
        let a = self.coefficients(c);
        let r = removed.min(self.terms()).min(c.len());
        let mut x = vec![0.0; r];
        for i in (0..r).rev() {
            let s: f64 = (i + 1..r).map(|j| self.lt[(i, j)] * x[j]).sum();
            x[i] = (a[i] - s) / self.lt[(i, i)];
        }
        let mut out = c.to_vec();
        for (o, x) in out.iter_mut().zip(&x) {
            *o -= x;
        }
        out
    }

    /// RMS over the outline of the surface `c` with its first `removed`
    /// orthonormal terms left out (3: the best-fit plane), nm.
    pub fn rms(&self, c: &[f64], removed: usize) -> f64 {
        self.coefficients(c)
            .iter()
            .skip(removed)
            .map(|a| a * a)
            .sum::<f64>()
            .sqrt()
    }

    /// Expected RMS over the outline of an error of covariance `cov`
    /// (Zernike coefficients, nm²), its first `removed` orthonormal terms
    /// left out, nm.
    pub fn expected_rms(&self, cov: &DMatrix<f64>, removed: usize) -> f64 {
        let s = self.covariance(cov);
        (removed..s.nrows())
            .map(|k| s[(k, k)].max(0.0))
            .sum::<f64>()
            .sqrt()
    }
}

//! The spot's centre by maximum likelihood: a pixel-integrated Gaussian
//! (centre, flux, a width per axis, a local background offset) fitted by
//! the shared damped least squares ([`crate::kernels::lm`]) to the
//! background-subtracted pixels of the moment centroid's window.
//!
//! Why: the window's first moment weighs every pixel alike, so the noise of
//! the window's far pixels, which carry no signal, enters its centre; on a
//! spot of width `s` in a ±4 s window that leaves 3.7× the Cramér–Rao bound
//! `σ_n s² √(8π) / F` (read noise σ_n, flux F). The least-squares fit
//! weighs each pixel by its slope: for a Gaussian spot in white noise it is
//! at the bound, and for any spot symmetric about its centre it stays
//! unbiased (the model's odd part, the centre, is orthogonal to its even
//! part, the shape).
//!
//! Its covariance is `σ_n² (JᵀJ)⁻¹` at the fit, scaled by the residuals'
//! pixel-scale variance over σ_n² where that exceeds 1 (the spot's own shot
//! noise). A spot whose residuals lie far above the noise is not a
//! Gaussian: its fit is refused and the caller keeps the model-free
//! moments.
//!
//! Hand-written: the model and its Jacobian are a few lines over `libm`'s
//! erf; the loop is the crate's own.

use nalgebra::{DMatrix, DVector, Matrix2};

use crate::kernels::lm::{minimise, Damping, LeastSquares, NormalEquations};

/// The loop's schedule: a start near the optimum (the moment centroid and
/// widths), a small problem whose evaluation is one pass over the window:
/// Gauss–Newton from the first step, damping only where a step overshoots.
const DAMPING: Damping = Damping {
    start: 1e-3,
    up: 10.0,
    down: 10.0,
    floor: 1e-12,
    cap: 1e8,
    trust_prediction_below: None,
    stall: None,
};

/// Trial steps; the fit converges in 3–6 from the moment start.
const MAX_TRIALS: usize = 60;

/// The largest pixel-scale residual variance over the read noise's at
/// which the fit stands: a Gaussian spot's shot noise at one count per
/// electron and a 1500-count peak over 25 counts of read noise gives 1.2
/// over the window; a uniform disk's edges against the Gaussian give 36.
const MAX_NOISE_RATIO: f64 = 3.0;

/// A fitted spot.
#[derive(Debug, Clone, PartialEq)]
pub struct SpotFit {
    /// The centre, pixel-centre convention, px.
    pub centre: [f64; 2],
    /// Its covariance, px².
    pub covariance: Matrix2<f64>,
    /// The Gaussian's σ per axis, px.
    pub sigma: [f64; 2],
    /// The fit's reduced χ² against the read noise.
    pub chi2_per_dof: f64,
}

/// The window: its pixels' background-subtracted values, row-major, with
/// its origin (column, row) and side.
pub struct Window<'a> {
    /// The frame's residual after the background, row-major.
    pub residual: &'a [f64],
    /// The frame's width.
    pub width: usize,
    /// Top-left pixel `[column, row]`.
    pub origin: [usize; 2],
    /// Side, px.
    pub size: usize,
    /// Read noise, 1 σ, counts.
    pub noise: f64,
}

/// `[cx, cy, flux, sx, sy, offset]`.
pub type Params = [f64; 6];

fn pdf(u: f64) -> f64 {
    (-0.5 * u * u).exp() / (2.0 * std::f64::consts::PI).sqrt()
}

fn cdf(u: f64) -> f64 {
    0.5 * libm::erfc(-u * std::f64::consts::FRAC_1_SQRT_2)
}

/// A pixel's share `G` of a unit 1-D Gaussian (centre `c`, σ `s`) over
/// `[i, i + 1)`, with `∂G/∂c` and `∂G/∂s`.
fn share(i: usize, c: f64, s: f64) -> [f64; 3] {
    let (u0, u1) = ((i as f64 - c) / s, (i as f64 + 1.0 - c) / s);
    let (p0, p1) = (pdf(u0), pdf(u1));
    [cdf(u1) - cdf(u0), (p0 - p1) / s, (p0 * u0 - p1 * u1) / s]
}

impl LeastSquares for Window<'_> {
    type Params = Params;
    type Normal = NormalEquations;
    type Error = ();

    fn evaluate(&self, p: &Params) -> NormalEquations {
        let [cx, cy, flux, sx, sy, offset] = *p;
        let gx: Vec<[f64; 3]> = (0..self.size)
            .map(|a| share(self.origin[0] + a, cx, sx))
            .collect();
        let gy: Vec<[f64; 3]> = (0..self.size)
            .map(|b| share(self.origin[1] + b, cy, sy))
            .collect();
        let w2 = 1.0 / (self.noise * self.noise);
        let mut jtj = DMatrix::zeros(6, 6);
        let mut jtr = DVector::zeros(6);
        let mut cost = 0.0;
        for (b, y) in gy.iter().enumerate() {
            let row = (self.origin[1] + b) * self.width + self.origin[0];
            for (a, x) in gx.iter().enumerate() {
                let model = offset + flux * x[0] * y[0];
                let r = self.residual[row + a] - model;
                let j = [
                    flux * x[1] * y[0],
                    flux * x[0] * y[1],
                    x[0] * y[0],
                    flux * x[2] * y[0],
                    flux * x[0] * y[2],
                    1.0,
                ];
                cost += r * r * w2;
                for m in 0..6 {
                    jtr[m] += j[m] * r * w2;
                    for n in 0..=m {
                        jtj[(m, n)] += j[m] * j[n] * w2;
                    }
                }
            }
        }
        for m in 0..6 {
            for n in 0..m {
                jtj[(n, m)] = jtj[(m, n)];
            }
        }
        NormalEquations { cost, jtj, jtr }
    }

    fn moved(&self, p: &Params, step: &DVector<f64>) -> Result<Params, ()> {
        let q: Params = std::array::from_fn(|k| p[k] + step[k]);
        // A width of a tenth of a pixel or less is a hot pixel's, not an
        // image of the target; a centre off the window is no fit.
        let inside = |c: f64, o: usize| c > o as f64 && c < (o + self.size) as f64;
        let ok = q[3] > 0.1
            && q[4] > 0.1
            && q[2] > 0.0
            && inside(q[0], self.origin[0])
            && inside(q[1], self.origin[1]);
        if ok {
            Ok(q)
        } else {
            Err(())
        }
    }

    fn small_step(&self, step: &DVector<f64>) -> bool {
        step[0].abs().max(step[1].abs()) < 1e-7
    }

    fn decrease_tolerance(&self, _at: &NormalEquations) -> Option<f64> {
        // χ² units: a fall of 1e-8 moves the centre by 1e-4 of its σ.
        Some(1e-8)
    }
}

impl Window<'_> {
    /// The residuals' variance from neighbours' differences over the
    /// read noise's: `Σ (r_k − r_k')² / 2` over horizontal and vertical
    /// pairs, per pair. Noise is white at the pixel scale, the spot's own
    /// shot noise included, and a pair's difference carries twice its
    /// variance; a spot shape the Gaussian does not have leaves residuals
    /// smooth at that scale, which the differences cancel. So it is the
    /// noise the centre sees, not the misfit, which (even about the centre)
    /// does not move it.
    fn local_noise_ratio(&self, p: &Params) -> f64 {
        let [cx, cy, flux, sx, sy, offset] = *p;
        let n = self.size;
        let gx: Vec<f64> = (0..n)
            .map(|a| share(self.origin[0] + a, cx, sx)[0])
            .collect();
        let gy: Vec<f64> = (0..n)
            .map(|b| share(self.origin[1] + b, cy, sy)[0])
            .collect();
        let r = |a: usize, b: usize| {
            let k = (self.origin[1] + b) * self.width + self.origin[0] + a;
            self.residual[k] - offset - flux * gx[a] * gy[b]
        };
        let (mut ss, mut pairs) = (0.0, 0usize);
        for b in 0..n {
            for a in 0..n {
                if a + 1 < n {
                    ss += (r(a + 1, b) - r(a, b)).powi(2);
                    pairs += 1;
                }
                if b + 1 < n {
                    ss += (r(a, b + 1) - r(a, b)).powi(2);
                    pairs += 1;
                }
            }
        }
        ss / (2.0 * pairs.max(1) as f64) / (self.noise * self.noise)
    }
}

/// The fit from the moment centroid's `centre`, `sigma` (px) and `flux`
/// (counts); `None` where it does not converge or leaves the window, so
/// the caller keeps the moments.
pub fn fit_spot(window: &Window, centre: [f64; 2], sigma: [f64; 2], flux: f64) -> Option<SpotFit> {
    let start: Params = [centre[0], centre[1], flux, sigma[0], sigma[1], 0.0];
    let at_start = window.evaluate(&start);
    let out = minimise(window, start, at_start, &DAMPING, MAX_TRIALS).ok()?;
    if !out.stop.converged() {
        return None;
    }
    let p = out.params;
    let inv = out.normal.jtj.clone().try_inverse()?;
    let dof = (window.size * window.size).saturating_sub(6).max(1) as f64;
    let chi2_per_dof = out.normal.cost / dof;
    // A spot the Gaussian does not describe (a defocused disk, a ring)
    // leaves residuals far above the noise: its covariance would be the
    // model's, not the spot's, so it keeps the moments (model-free).
    let scale = window.local_noise_ratio(&p);
    if scale > MAX_NOISE_RATIO {
        return None;
    }
    let scale = scale.max(1.0);
    let covariance = Matrix2::new(inv[(0, 0)], inv[(0, 1)], inv[(1, 0)], inv[(1, 1)]) * scale;
    (covariance[(0, 0)] > 0.0 && covariance[(1, 1)] > 0.0).then_some(SpotFit {
        centre: [p[0], p[1]],
        covariance,
        sigma: [p[3], p[4]],
        chi2_per_dof,
    })
}

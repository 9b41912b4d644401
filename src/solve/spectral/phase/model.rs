//! The joint model of a phase-shifting pixel with analytic derivatives, and
//! its weighted Levenberg–Marquardt fit on the shared loop
//! ([`crate::kernels::lm`]).
//!
//! Sample i of group g (direction d, τ) at phase φ_i:
//! `y_i = A_d + B_g h_τ(τ s_d(u, v) + φ_i)`, with
//! `h_g(x) = Σ_n ρ_n e^{−κ_g (n² − 1) τ²} cos(2π n x)` (x in cycles), ρ_n the
//! display response's harmonic ratios ([`super::Response`]) and κ_g the
//! camera blur's falloff of harmonic n against the first, Gaussian within
//! the group. κ is one per group, not one per pixel: the blur's transfer
//! function need not be Gaussian over the schedule's frequencies (a shared
//! κ left a ripple of 0.3σ locked to the fringes where the contrast falls
//! faster). Parameters, in this order:
//! `[u, v, (κ_0 … κ_{G−1}), A_0 … A_{D−1}, B_0 … B_{G−1}]`; κ only where the
//! response has harmonics beyond the first (else it is not identifiable).

use std::convert::Infallible;

use nalgebra::{DMatrix, DVector};

use super::{PhaseSchedule, Response};
use crate::kernels::lm::{minimise, Damping, LeastSquares};
use crate::solve::spectral::model::{Design, Normal};

/// The damping schedule: the fits start from an unwrapped phase already
/// within a small fraction of the finest fringe, so a nearly Gauss–Newton
/// start is safe; every step is evaluated (the fits are few).
const DAMPING: Damping = Damping {
    start: 1e-4,
    up: 4.0,
    down: 3.0,
    floor: 1e-12,
    cap: 1e12,
    trust_prediction_below: None,
    stall: None,
};

/// A step moving (u, v) by less than this (screen px) has converged: 10⁻³
/// of the smallest σ an 8–16-bit camera reaches here (~0.01 px).
const STEP_TOL_PX: f64 = 1e-5;

/// Width of the prior on `κ_g τ²`: harmonic 2's falloff `e^{−3 κ τ²}` is
/// 10⁻⁴ at κ τ² = 3, beyond anything an 8–16-bit camera resolves.
const KAPPA_PRIOR: f64 = 3.0;

/// A pixel's parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct PhaseParams {
    /// Screen point (u, v), screen px.
    pub uv: [f64; 2],
    /// κ of the harmonics' falloff per group, per τ² (0 where not fitted).
    pub kappa: Vec<f64>,
    /// Background per direction, counts.
    pub offset: Vec<f64>,
    /// Amplitude of the first harmonic per group, counts.
    pub amp: Vec<f64>,
}

/// The model of one schedule and display response.
#[derive(Debug, Clone, Copy)]
pub struct PhaseModel<'a> {
    /// The schedule as the model sees it.
    pub design: &'a Design,
    /// Its groups.
    pub schedule: &'a PhaseSchedule,
    /// The display's response.
    pub response: &'a Response,
}

impl PhaseModel<'_> {
    /// Whether κ is a parameter.
    pub fn fits_kappa(&self) -> bool {
        self.response.harmonics() > 1
    }

    /// Number of nonlinear parameters: (u, v) and the κ_g where fitted.
    pub fn nonlinear(&self) -> usize {
        if self.fits_kappa() {
            2 + self.schedule.groups.len()
        } else {
            2
        }
    }

    /// Number of parameters.
    pub fn len(&self) -> usize {
        self.nonlinear() + self.schedule.directions + self.schedule.groups.len()
    }

    /// Never empty (a screen point at least).
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Model value of frame `i` at `p`, its gradient into `row` (length [`Self::len`]).
    pub fn eval(&self, i: usize, p: &PhaseParams, row: &mut [f64]) -> f64 {
        let f = &self.design.frames[i];
        let g = self.schedule.group_of_frame[i] as usize;
        let ax = self.design.axes[f.dir];
        let t = f.tau;
        let x = t * ax.s(p.uv[0], p.uv[1]) + f.phase_cycles;
        let (s1, c1) = (std::f64::consts::TAU * x).sin_cos();
        let (mut c_prev, mut s_prev) = (1.0, 0.0);
        let (mut c_n, mut s_n) = (c1, s1);
        let (mut h, mut dh, mut dk) = (0.0, 0.0, 0.0);
        for (k, &rho) in self.response.ratios.iter().enumerate() {
            let n = (k + 1) as f64;
            let q = (n * n - 1.0) * t * t;
            let e = rho * (-p.kappa[g] * q).exp();
            h += e * c_n;
            dh -= n * e * s_n;
            dk -= q * e * c_n;
            let c_next = 2.0 * c1 * c_n - c_prev;
            let s_next = 2.0 * c1 * s_n - s_prev;
            (c_prev, s_prev, c_n, s_n) = (c_n, s_n, c_next, s_next);
        }
        let b = p.amp[g];
        row.iter_mut().for_each(|r| *r = 0.0);
        let gx = b * dh * std::f64::consts::TAU * t;
        row[0] = gx * ax.a;
        row[1] = gx * ax.b;
        let nl = self.nonlinear();
        if nl > 2 {
            row[2 + g] = b * dk;
        }
        row[nl + f.dir] = 1.0;
        row[nl + self.schedule.directions + g] = h;
        p.offset[f.dir] + b * h
    }

    /// Weighted normal equations over frames `index` with values `y` and
    /// weights `w` (1/variance): χ², JᵀWJ, JᵀWr.
    pub fn normal(&self, index: &[u32], y: &[f64], w: &[f64], p: &PhaseParams) -> Normal {
        let n = self.len();
        let mut jtj = DMatrix::zeros(n, n);
        let mut jtr = DVector::zeros(n);
        let mut rss = 0.0;
        let mut row = vec![0.0; n];
        for ((&i, &yi), &wi) in index.iter().zip(y).zip(w) {
            let r = yi - self.eval(i as usize, p, &mut row);
            rss += wi * r * r;
            for a in 0..n {
                if row[a] == 0.0 {
                    continue;
                }
                jtr[a] += wi * row[a] * r;
                for b in a..n {
                    jtj[(a, b)] += wi * row[a] * row[b];
                }
            }
        }
        for a in 0..n {
            for b in 0..a {
                jtj[(a, b)] = jtj[(b, a)];
            }
        }
        if self.fits_kappa() {
            // The weak prior κ_g τ² ~ N(0, KAPPA_PRIOR²): where a harmonic
            // is too weak to show its falloff (a dark pixel, a blurred-out
            // fringe), κ_g stays finite and the information invertible;
            // elsewhere the data outweigh it by orders of magnitude.
            for (k, g) in self.schedule.groups.iter().enumerate() {
                let scale = g.tau * g.tau / KAPPA_PRIOR;
                let r = -p.kappa[k] * scale;
                rss += r * r;
                jtr[2 + k] += scale * r;
                jtj[(2 + k, 2 + k)] += scale * scale;
            }
        }
        Normal { rss, jtj, jtr }
    }

    /// `p` moved by `step`. κ_g is not kept ≥ 0: where the true falloff is
    /// nearly none, a bound would hold about half the fits at it and the
    /// residuals would no longer be those of a linearised least squares
    /// (the noise law reads them; [`super::NoiseLaw`]).
    pub fn moved(&self, p: &PhaseParams, step: &DVector<f64>) -> PhaseParams {
        let mut q = p.clone();
        q.uv[0] += step[0];
        q.uv[1] += step[1];
        let nl = self.nonlinear();
        if nl > 2 {
            for (k, kappa) in q.kappa.iter_mut().enumerate() {
                *kappa += step[2 + k];
            }
        }
        let d = self.schedule.directions;
        for (k, a) in q.offset.iter_mut().enumerate() {
            *a += step[nl + k];
        }
        for (k, b) in q.amp.iter_mut().enumerate() {
            *b += step[nl + d + k];
        }
        q
    }

    /// The least-squares backgrounds and amplitudes at the screen point
    /// `uv` and falloff `kappa` in every group (the model is linear in them). `None` where
    /// the frames cannot determine them.
    pub fn linear_start(
        &self,
        index: &[u32],
        y: &[f64],
        w: &[f64],
        uv: [f64; 2],
        kappa: f64,
    ) -> Option<PhaseParams> {
        let zero = PhaseParams {
            uv,
            kappa: vec![kappa; self.schedule.groups.len()],
            offset: vec![0.0; self.schedule.directions],
            amp: vec![0.0; self.schedule.groups.len()],
        };
        // At zero linear parameters the residual is y and the linear
        // columns do not depend on them: one solve gives them.
        let nl = self.nonlinear();
        let m = self.len() - nl;
        let full = self.normal(index, y, w, &zero);
        let jtj = full.jtj.view((nl, nl), (m, m)).into_owned();
        let jtr = full.jtr.rows(nl, m).into_owned();
        let sol = jtj.cholesky()?.solve(&jtr);
        let d = self.schedule.directions;
        let mut p = zero;
        p.offset.copy_from_slice(&sol.as_slice()[..d]);
        p.amp.copy_from_slice(&sol.as_slice()[d..]);
        Some(p)
    }

    /// Levenberg–Marquardt from `start` over frames `index` (values `y`,
    /// weights `w`), at most `max_iter` evaluated steps.
    pub fn fit(
        &self,
        index: &[u32],
        y: &[f64],
        w: &[f64],
        start: PhaseParams,
        max_iter: usize,
    ) -> PhaseFit {
        // First at the starting κ (the point and amplitudes settle where
        // the harmonics' falloff cannot pull them: a free κ_g of a weak
        // harmonic lets a Gauss–Newton step from the unwrapped start jump
        // away), then with every κ_g free.
        let mut problem = Problem {
            model: self,
            index,
            y,
            w,
            frozen_kappa: self.fits_kappa(),
        };
        let mut trials = 0;
        let mut start = start;
        if problem.frozen_kappa {
            let at = problem.evaluate(&start);
            let Ok(out) = minimise(&problem, start, at, &DAMPING, max_iter);
            trials += out.trials;
            start = out.params;
            problem.frozen_kappa = false;
        }
        let at = problem.evaluate(&start);
        let Ok(out) = minimise(&problem, start, at, &DAMPING, max_iter);
        PhaseFit {
            converged: out.stop.converged(),
            iterations: trials + out.trials,
            chi2: out.normal.rss,
            jtj: out.normal.jtj,
            params: out.params,
        }
    }
}

/// A finished fit.
#[derive(Debug, Clone)]
pub struct PhaseFit {
    /// The parameters.
    pub params: PhaseParams,
    /// Weighted residual sum of squares (χ² where the weights are 1/variance).
    pub chi2: f64,
    /// JᵀWJ at the fit: the Fisher information at the weights' noise.
    pub jtj: DMatrix<f64>,
    /// Evaluated steps.
    pub iterations: usize,
    /// Whether the loop stopped at a minimum.
    pub converged: bool,
}

struct Problem<'a> {
    model: &'a PhaseModel<'a>,
    index: &'a [u32],
    y: &'a [f64],
    w: &'a [f64],
    /// κ held where it is (its rows of the normal equations replaced by
    /// the identity's, so that a step leaves it).
    frozen_kappa: bool,
}

impl LeastSquares for Problem<'_> {
    type Params = PhaseParams;
    type Normal = Normal;
    type Error = Infallible;

    fn evaluate(&self, p: &PhaseParams) -> Normal {
        let mut n = self.model.normal(self.index, self.y, self.w, p);
        if self.frozen_kappa {
            for k in 2..self.model.nonlinear() {
                n.jtj.row_mut(k).fill(0.0);
                n.jtj.column_mut(k).fill(0.0);
                n.jtj[(k, k)] = 1.0;
                n.jtr[k] = 0.0;
            }
        }
        n
    }

    fn moved(&self, p: &PhaseParams, step: &DVector<f64>) -> Result<PhaseParams, Infallible> {
        Ok(self.model.moved(p, step))
    }

    fn small_step(&self, step: &DVector<f64>) -> bool {
        step[0].abs() < STEP_TOL_PX && step[1].abs() < STEP_TOL_PX
    }

    /// A χ² decrease of 10⁻⁶ per sample moves nothing that matters.
    fn decrease_tolerance(&self, _at: &Normal) -> Option<f64> {
        Some(1e-6 * self.index.len() as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solve::spectral::model::{Axis, FrameMeta};

    fn design() -> Design {
        let mut frames = Vec::new();
        for dir in 0..2 {
            for tau in [1.0, 4.0, 16.0] {
                for k in 0..4 {
                    frames.push(FrameMeta {
                        tau,
                        phase_cycles: k as f64 / 4.0,
                        dir,
                    });
                }
            }
        }
        let axes = vec![
            Axis {
                a: 1e-3,
                b: 0.5e-3,
                c: 0.1,
                stretch: 1.0,
            },
            Axis {
                a: -0.4e-3,
                b: 1e-3,
                c: 0.6,
                stretch: 1.0,
            },
        ];
        Design::new(frames, axes, vec![0.0, 90.0])
    }

    /// The analytic gradient against central differences (the oracle).
    #[test]
    fn gradient_matches_finite_differences() {
        let d = design();
        let s = PhaseSchedule::detect(&d).unwrap();
        let r = Response::new(2.2).unwrap();
        let m = PhaseModel {
            design: &d,
            schedule: &s,
            response: &r,
        };
        let p = PhaseParams {
            uv: [310.0, 170.0],
            kappa: (0..6).map(|k| 1e-3 * (1.0 + k as f64)).collect(),
            offset: vec![50.0, 60.0],
            amp: (0..6).map(|k| 40.0 - k as f64).collect(),
        };
        let n = m.len();
        let mut row = vec![0.0; n];
        let mut scratch = vec![0.0; n];
        for i in 0..d.frames.len() {
            m.eval(i, &p, &mut row);
            for a in 0..n {
                let h = if a < 2 { 1e-4 } else { 1e-6 };
                let mut step = DVector::zeros(n);
                step[a] = h;
                let up = m.eval(i, &m.moved(&p, &step), &mut scratch);
                step[a] = -h;
                let down = m.eval(i, &m.moved(&p, &step), &mut scratch);
                let fd = (up - down) / (2.0 * h);
                assert!(
                    (fd - row[a]).abs() <= 1e-6 * (1.0 + fd.abs()),
                    "frame {i} param {a}: {fd} vs {}",
                    row[a]
                );
            }
        }
    }
}

//! Chebyshev nodes on a τ interval, their cardinal polynomials, and the
//! fewest nodes that interpolate the model's smooth factor to [`NODE_TOL`].

use super::C64;
use crate::kernels::sincos_cycles;

/// Interpolation tolerance of the node sets, relative to the largest value
/// of the interpolated function: the statistics reproduce the series' sums
/// to this fraction of `Σ|y|` (far below the noise: 1e-10 of a sum of 10³
/// samples is 1e-7 counts per sample; quantisation alone is 0.29).
pub(super) const NODE_TOL: f64 = 1e-10;

/// Chebyshev nodes on a τ interval and their cardinal polynomials.
#[derive(Debug, Clone)]
pub(super) struct Nodes {
    pub(super) tau: Vec<f64>,
    /// `T_q(s_j)` = cos(q θ_j), row j.
    tq: Vec<f64>,
    mid: f64,
    half: f64,
}

impl Nodes {
    pub(super) fn new(lo: f64, hi: f64, q: usize) -> Nodes {
        let mid = 0.5 * (lo + hi);
        let half = (0.5 * (hi - lo)).max(1e-9);
        let mut tau = Vec::with_capacity(q);
        let mut tq = vec![0.0; q * q];
        for j in 0..q {
            let th = std::f64::consts::PI * (j as f64 + 0.5) / q as f64;
            tau.push(mid + half * th.cos());
            for k in 0..q {
                tq[j * q + k] = (k as f64 * th).cos();
            }
        }
        Nodes { tau, tq, mid, half }
    }

    pub(super) fn len(&self) -> usize {
        self.tau.len()
    }

    /// `L_j(τ)` for every node j: `Σ_j L_j(τ) f(τ_j)` is the degree-(Q−1)
    /// interpolant of f. `L_j = (1/Q)[1 + 2 Σ_{q≥1} T_q(s_j) T_q(s)]`.
    pub(super) fn cardinal(&self, tau: f64, out: &mut [f64]) {
        let q = self.len();
        let s = ((tau - self.mid) / self.half).clamp(-1.0, 1.0);
        let mut t = vec![0.0; q];
        t[0] = 1.0;
        if q > 1 {
            t[1] = s;
        }
        for k in 2..q {
            t[k] = 2.0 * s * t[k - 1] - t[k - 2];
        }
        for (j, o) in out.iter_mut().enumerate().take(q) {
            let row = &self.tq[j * q..(j + 1) * q];
            let mut acc = 0.5;
            for k in 1..q {
                acc += row[k] * t[k];
            }
            *o = 2.0 * acc / q as f64;
        }
    }

    /// Largest interpolation error over the τ interval of
    /// `(τ/hi)^deg e^{−κτ²} e^{2πiδτ}`, relative to its largest value, for
    /// `|δ| ≤ delta`, `κ ∈ kappas`, `deg ≤ degree`.
    fn error(&self, delta: f64, kappas: [f64; 2], degree: i32) -> f64 {
        let q = self.len();
        let lo = self.mid - self.half;
        let hi = self.mid + self.half;
        let mut card = vec![0.0; q];
        let mut worst: f64 = 0.0;
        let tests: Vec<f64> = (0..=96).map(|k| lo + (hi - lo) * k as f64 / 96.0).collect();
        for &dl in &[delta, -delta, 0.61 * delta, 0.0] {
            for &kappa in &kappas {
                for deg in [0, degree] {
                    let f = |t: f64| {
                        let (c, s) = sincos_cycles(dl * t);
                        C64::new(c, s) * ((t / hi).powi(deg) * (-kappa * t * t).exp())
                    };
                    let fj: Vec<C64> = self.tau.iter().map(|&t| f(t)).collect();
                    let scale = tests.iter().map(|&t| f(t).norm()).fold(1e-300, f64::max);
                    for &t in &tests {
                        self.cardinal(t, &mut card);
                        let v: C64 = fj.iter().zip(&card).map(|(a, &l)| a * l).sum();
                        worst = worst.max((v - f(t)).norm() / scale);
                    }
                }
            }
        }
        worst
    }

    /// The fewest nodes (multiple of 4, ≤ 256) meeting [`NODE_TOL`];
    /// `None` when 256 do not.
    pub(super) fn enough(
        lo: f64,
        hi: f64,
        delta: f64,
        kappas: [f64; 2],
        degree: i32,
    ) -> Option<Nodes> {
        (8..=256)
            .step_by(4)
            .map(|q| Nodes::new(lo, hi, q))
            .find(|n| n.error(delta, kappas, degree) < NODE_TOL)
    }
}

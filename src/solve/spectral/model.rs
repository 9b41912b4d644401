//! The per-pixel signal model (paper Eq. 7, joint over fringe directions)
//! with analytic derivatives; its fits (Levenberg–Marquardt on the shared
//! loop, a warm start's Gauss–Newton step) are in [`fit`]; the schedule
//! it is evaluated on ([`Design`]) and the samples it is fitted to
//! ([`Samples`]) in modules of their own.
//!
//! Sample i, shown with direction d_i, τ_i and phase φ_i, is modelled as
//! `y_i = A + e_i Σ_k B_k cos(2π (τ_i s_{d_i}(u_k, v_k)) + φ_i)`,
//! `e_i = exp(−κ_{g(d_i)} τ_i²)` (κ = 1/τ_max²), `s_d(u, v) = a_d u + b_d v + c_d`
//! the spec's fringe coordinate. Parameters, in this order:
//! `[A, B_1 … B_K, u_1, v_1, … u_K, v_K, κ_1 … κ_G]`.
//!
//! The falloff has one κ per *falloff group* g: the directions whose fringe
//! runs the same length L across the screen (±45° share one; 0° and 90°
//! each have their own on a screen that is not square). A blur acts on the
//! fringe's period in screen pixels, L/τ, so directions of equal L fall off
//! alike whatever the blur, and directions of different L do not: one κ
//! for all of them is wrong by the factor (L₄₅/L)² in the exponent, which
//! on the paper's station moves the points by hundreds of nm (the plain
//! directions' falloff then pulls the fit). A κ per length instead holds
//! under any convention a renderer uses (falloff on τ or on the screen
//! period), at the cost of one parameter per extra length. A schedule on
//! ±45° alone has one group, the paper's model.

use nalgebra::{DMatrix, DVector};

use crate::kernels::sincos_cycles;

pub mod censored;
mod design;
pub mod fit;
mod repeats;
mod samples;

pub use design::{Axis, Design, Falloff, FrameMeta};
pub(crate) use fit::ParamCholesky;
pub use fit::{gauss_newton_step, levenberg_marquardt, levenberg_marquardt_at, Fit, DAMPING};
pub use repeats::{RepeatSamples, Repeats};
pub use samples::{envelope, linear_amplitudes, linear_amplitudes_in, Samples, SeriesSamples};

/// Largest number of reflections modelled.
pub const MAX_REFLECTIONS: usize = 3;

/// Largest number of falloff groups (fringe lengths) fitted; a schedule
/// with more distinct lengths shares one κ over all of them.
pub const MAX_GROUPS: usize = 4;

/// Largest number of model parameters, `3 K + 1 + G`.
pub const MAX_PARAMS: usize = 3 * MAX_REFLECTIONS + 1 + MAX_GROUPS;

/// Model parameters for K reflections.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    /// Number of reflections, 1 ≤ K ≤ 3.
    pub k: usize,
    /// Background A, counts.
    pub offset: f64,
    /// Modulation amplitudes B_k, counts.
    pub amp: [f64; MAX_REFLECTIONS],
    /// Screen points (u_k, v_k), screen px.
    pub uv: [[f64; 2]; MAX_REFLECTIONS],
    /// κ = 1/τ_max² of each falloff group.
    pub kappa: Falloff,
}

impl Params {
    /// Number of free parameters, 3K + 1 + G.
    pub fn len(&self) -> usize {
        3 * self.k + 1 + self.kappa.groups
    }

    /// Index of falloff group g's κ in the parameter vector.
    pub fn kappa_index(&self, g: usize) -> usize {
        1 + 3 * self.k + g
    }

    /// Always false (a model has at least A, B_1, u_1, v_1, κ).
    pub fn is_empty(&self) -> bool {
        false
    }

    pub(crate) fn add(&self, d: &DVector<f64>) -> Params {
        let mut p = *self;
        let k = self.k;
        p.offset += d[0];
        for j in 0..k {
            p.amp[j] += d[1 + j];
            p.uv[j][0] += d[1 + k + 2 * j];
            p.uv[j][1] += d[2 + k + 2 * j];
        }
        for g in 0..self.kappa.groups {
            p.kappa[g] += d[1 + 3 * k + g];
        }
        p
    }

    /// Index of u_j in the parameter vector (v_j follows).
    pub fn u_index(&self, j: usize) -> usize {
        1 + self.k + 2 * j
    }
}

/// Normal equations of one linearisation.
pub struct Normal {
    /// Residual sum of squares at the linearisation point.
    pub rss: f64,
    /// JᵀJ.
    pub jtj: DMatrix<f64>,
    /// Jᵀr.
    pub jtr: DVector<f64>,
}

/// Model value and its gradient row for frame `f` (gradient into `row`).
#[inline]
pub(crate) fn eval_row(design: &Design, f: &FrameMeta, p: &Params, row: &mut [f64]) -> f64 {
    let ax = design.axes[f.dir];
    let t = f.tau;
    let group = design.falloff_group[f.dir];
    let e = (-p.kappa[group] * t * t).exp();
    let k = p.k;
    let mut sum_bc = 0.0;
    row[0] = 1.0;
    for j in 0..k {
        let x = t * ax.s(p.uv[j][0], p.uv[j][1]) + f.phase_cycles;
        let (c, s) = sincos_cycles(x);
        row[1 + j] = e * c;
        let g = -p.amp[j] * e * s * std::f64::consts::TAU * t;
        row[1 + k + 2 * j] = g * ax.a;
        row[2 + k + 2 * j] = g * ax.b;
        sum_bc += p.amp[j] * c;
    }
    for g in 0..p.kappa.groups {
        row[1 + 3 * k + g] = 0.0;
    }
    row[1 + 3 * k + group] = -t * t * e * sum_bc;
    p.offset + e * sum_bc
}

/// One pass over the used samples: RSS, JᵀJ and Jᵀr at `p`.
pub fn normal_equations(design: &Design, index: &[u32], y: &[f64], p: &Params) -> Normal {
    // Fixed sizes let the compiler unroll the JᵀJ update (the hot loop).
    match p.len() {
        5 => normal_fixed::<5>(design, index, y, p),
        6 => normal_fixed::<6>(design, index, y, p),
        7 => normal_fixed::<7>(design, index, y, p),
        8 => normal_fixed::<8>(design, index, y, p),
        9 => normal_fixed::<9>(design, index, y, p),
        10 => normal_fixed::<10>(design, index, y, p),
        11 => normal_fixed::<11>(design, index, y, p),
        12 => normal_fixed::<12>(design, index, y, p),
        13 => normal_fixed::<13>(design, index, y, p),
        _ => normal_fixed::<MAX_PARAMS>(design, index, y, p),
    }
}

fn normal_fixed<const N: usize>(design: &Design, index: &[u32], y: &[f64], p: &Params) -> Normal {
    debug_assert_eq!(N, p.len());
    let mut jtj = [[0.0; N]; N];
    let mut jtr = [0.0; N];
    let mut rss = 0.0;
    let mut full = [0.0; MAX_PARAMS];
    for (&i, &yi) in index.iter().zip(y) {
        let f = eval_row(design, &design.frames[i as usize], p, &mut full);
        let row: [f64; N] = full[..N].try_into().expect("N ≤ MAX_PARAMS");
        let r = yi - f;
        rss += r * r;
        for a in 0..N {
            jtr[a] += row[a] * r;
            for b in a..N {
                jtj[a][b] += row[a] * row[b];
            }
        }
    }
    Normal {
        rss,
        jtj: DMatrix::from_fn(N, N, |a, b| jtj[a.min(b)][a.max(b)]),
        jtr: DVector::from_column_slice(&jtr),
    }
}

//! The per-pixel signal model (paper Eq. 7, joint over fringe directions)
//! with analytic derivatives; its fits (Levenberg–Marquardt on the shared
//! loop, a warm start's Gauss–Newton step) are in [`fit`].
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

use crate::acquire::patterns::FringeAxis;
use crate::kernels::{cos_cycles, sincos_cycles};

pub mod censored;
pub mod fit;

pub(crate) use fit::ParamCholesky;
pub use fit::{gauss_newton_step, levenberg_marquardt, Fit, DAMPING};

/// Largest number of reflections modelled.
pub const MAX_REFLECTIONS: usize = 3;

/// Largest number of falloff groups (fringe lengths) fitted; a schedule
/// with more distinct lengths shares one κ over all of them.
pub const MAX_GROUPS: usize = 4;

/// Largest number of model parameters, `3 K + 1 + G`.
pub const MAX_PARAMS: usize = 3 * MAX_REFLECTIONS + 1 + MAX_GROUPS;

/// The modulation falloff: κ = 1/τ_max² of each falloff group
/// ([`Design::falloff_group`]); indexed by group.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Falloff {
    /// Groups in use, 1 ≤ G ≤ [`MAX_GROUPS`].
    pub groups: usize,
    /// κ per group (entries past `groups` unused).
    pub kappa: [f64; MAX_GROUPS],
}

impl Falloff {
    /// The same κ in each of `groups` groups.
    pub fn uniform(groups: usize, kappa: f64) -> Self {
        Falloff {
            groups: groups.clamp(1, MAX_GROUPS),
            kappa: [kappa; MAX_GROUPS],
        }
    }

    /// κ of the groups in use.
    pub fn values(&self) -> &[f64] {
        &self.kappa[..self.groups]
    }

    /// Whether every group's κ lies in `[lo, hi]`.
    pub fn within(&self, lo: f64, hi: f64) -> bool {
        self.values().iter().all(|&k| k >= lo && k <= hi)
    }
}

impl std::ops::Index<usize> for Falloff {
    type Output = f64;
    #[inline]
    fn index(&self, g: usize) -> &f64 {
        &self.kappa[g]
    }
}

impl std::ops::IndexMut<usize> for Falloff {
    #[inline]
    fn index_mut(&mut self, g: usize) -> &mut f64 {
        &mut self.kappa[g]
    }
}

/// What the model needs of one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameMeta {
    /// Fringe periods across the screen.
    pub tau: f64,
    /// Phase offset in cycles (φ / 2π).
    pub phase_cycles: f64,
    /// Index of the frame's direction in the design's axes.
    pub dir: usize,
}

/// `s = a u + b v + c` of one direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Axis {
    /// ∂s/∂u, per screen px.
    pub a: f64,
    /// ∂s/∂v, per screen px.
    pub b: f64,
    /// s at (0, 0).
    pub c: f64,
    /// `L₄₅ / L`: how much finer this direction's fringes are on the screen
    /// than the diagonals' at equal τ ([`FringeAxis::stretch_from_diagonal`]).
    pub stretch: f64,
}

impl Axis {
    /// The axis of a [`FringeAxis`] on a `width × height` screen.
    pub fn from_fringe(f: &FringeAxis, width: u32, height: u32) -> Self {
        let (a, b) = f.gradient();
        Axis {
            a,
            b,
            c: f.s(0.0, 0.0),
            stretch: f.stretch_from_diagonal(width, height),
        }
    }

    /// `s(u, v)`.
    #[inline]
    pub fn s(&self, u: f64, v: f64) -> f64 {
        self.a * u + self.b * v + self.c
    }
}

/// The schedule as the model sees it: every frame and every direction.
#[derive(Debug, Clone, PartialEq)]
pub struct Design {
    /// Frames in capture order.
    pub frames: Vec<FrameMeta>,
    /// Fringe axes, indexed by [`FrameMeta::dir`].
    pub axes: Vec<Axis>,
    /// Directions in degrees, same order.
    pub directions_deg: Vec<f64>,
    /// Falloff group of each axis (see the module doc): axes of equal
    /// fringe length share one.
    pub falloff_group: Vec<usize>,
}

impl Design {
    /// The design of `frames` on `axes` (directions `directions_deg`), with
    /// the axes grouped by fringe length (equal [`Axis::stretch`] to 1e-9).
    /// More than [`MAX_GROUPS`] lengths share one group (logged).
    pub fn new(frames: Vec<FrameMeta>, axes: Vec<Axis>, directions_deg: Vec<f64>) -> Design {
        let mut lengths: Vec<f64> = Vec::new();
        let mut falloff_group: Vec<usize> = axes
            .iter()
            .map(|ax| {
                match lengths
                    .iter()
                    .position(|&l| (l - ax.stretch).abs() <= 1e-9 * l.abs())
                {
                    Some(g) => g,
                    None => {
                        lengths.push(ax.stretch);
                        lengths.len() - 1
                    }
                }
            })
            .collect();
        if lengths.len() > MAX_GROUPS {
            log::warn!(
                "directions {directions_deg:?} have {} fringe lengths; more than {MAX_GROUPS} \
                 share one modulation falloff κ",
                lengths.len()
            );
            falloff_group.fill(0);
        }
        Design {
            frames,
            axes,
            directions_deg,
            falloff_group,
        }
    }

    /// Number of falloff groups (1 without axes).
    pub fn falloff_groups(&self) -> usize {
        self.falloff_group.iter().max().map_or(1, |&g| g + 1)
    }

    /// The falloff groups' κ of a blur that acts on the screen period, with
    /// `kappa` that of the diagonals: `κ (L₄₅/L_g)²` (what a physical scene
    /// shows, for the bounds and predictions; the fits estimate each group's).
    pub fn physical_falloff(&self, kappa: f64) -> Falloff {
        let mut f = Falloff::uniform(self.falloff_groups(), kappa);
        for (ax, &g) in self.axes.iter().zip(&self.falloff_group) {
            f[g] = kappa * ax.stretch * ax.stretch;
        }
        f
    }

    /// The same starting κ in every falloff group.
    pub fn uniform_falloff(&self, kappa: f64) -> Falloff {
        Falloff::uniform(self.falloff_groups(), kappa)
    }

    /// κ of frame `f`'s group in `falloff`.
    #[inline]
    pub fn kappa_of(&self, f: &FrameMeta, falloff: &Falloff) -> f64 {
        falloff[self.falloff_group[f.dir]]
    }

    /// A pixel's separation of its reflections given `seps`, that along
    /// each axis: over the pairs of non-parallel axes, the largest of the
    /// pair's smaller one (two directions that each see the reflections
    /// apart fix both points in the plane; one along which they coincide
    /// adds only their blend); with no such pair (one direction, or
    /// parallel ones), the smallest. `None` without axes.
    pub fn pair_separation(&self, seps: &[f64]) -> Option<f64> {
        let mut best: Option<f64> = None;
        for (i, p) in self.axes.iter().enumerate() {
            for (j, q) in self.axes.iter().enumerate().skip(i + 1) {
                // |sin| of the angle between the two fringe gradients.
                let cross = (p.a * q.b - p.b * q.a).abs() / (p.a.hypot(p.b) * q.a.hypot(q.b));
                if cross > 1e-6 {
                    let m = seps[i].min(seps[j]);
                    best = Some(best.map_or(m, |b| b.max(m)));
                }
            }
        }
        best.or_else(|| seps.iter().copied().reduce(f64::min))
    }

    /// The screen point `(u, v)` whose fringe coordinate along each
    /// direction is `mus[d]`: least squares of `a_d u + b_d v = μ_d − c_d`
    /// over the directions; `None` when the directions do not span the plane.
    pub fn screen_point(&self, mus: &[f64]) -> Option<[f64; 2]> {
        let (mut saa, mut sab, mut sbb, mut sar, mut sbr) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (ax, &mu) in self.axes.iter().zip(mus) {
            let r = mu - ax.c;
            saa += ax.a * ax.a;
            sab += ax.a * ax.b;
            sbb += ax.b * ax.b;
            sar += ax.a * r;
            sbr += ax.b * r;
        }
        let det = saa * sbb - sab * sab;
        if det.abs() < 1e-12 * (saa * sbb).max(1e-300) {
            return None;
        }
        Some([(sbb * sar - sab * sbr) / det, (saa * sbr - sab * sar) / det])
    }
}

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

/// A pixel's samples as the fits see them: the series itself
/// ([`SeriesSamples`]) or its sufficient statistics
/// ([`super::statistics::StatisticsSamples`]). Both give the same least squares.
pub trait Samples {
    /// Samples used.
    fn count(&self) -> usize;
    /// RSS, JᵀJ and Jᵀr at `p`.
    fn normal(&self, p: &Params) -> Normal;
    /// JᵀJ at `p` (the schedule's part of the Fisher information; no data).
    fn information(&self, p: &Params) -> DMatrix<f64>;
    /// Least-squares background and amplitudes at `p`'s screen points and κ,
    /// over direction `dir`'s samples alone when given; with the RSS.
    fn linear(&self, p: &Params, dir: Option<usize>) -> (Params, f64);
    /// Strongest periodogram peak of direction `d` and its power over the
    /// noise's median power: `(μ, ratio)`; μ is NaN when the peak lies at
    /// the edge of the band the samples describe.
    fn peak(&self, d: usize) -> Option<(f64, f64)>;
    /// Whether the samples describe the model at `p` (statistics hold only
    /// within a band around the station's prediction; a series everywhere).
    fn within_band(&self, _p: &Params) -> bool {
        true
    }
    /// The linear fits of [`Samples::linear`] on direction `dir` alone for
    /// `count` pairs of points on that direction's axis: the first at
    /// μ = `mu0 + k·step`, the second `offset` beyond, at κ = `kappa`;
    /// `point(μ)` is a screen point with that axis coordinate. Per pair:
    /// the amplitudes (B1, B2) and the RSS.
    fn pair_scan(
        &self,
        dir: usize,
        [mu0, step, offset]: [f64; 3],
        count: usize,
        kappa: Falloff,
        point: &dyn Fn(f64) -> [f64; 2],
    ) -> Vec<([f64; 2], f64)> {
        (0..count)
            .map(|k| {
                let m0 = mu0 + k as f64 * step;
                let p = Params {
                    k: 2,
                    offset: 0.0,
                    amp: [0.0; MAX_REFLECTIONS],
                    uv: [point(m0), point(m0 + offset), [0.0; 2]],
                    kappa,
                };
                let (p, rss) = self.linear(&p, Some(dir));
                ([p.amp[0], p.amp[1]], rss)
            })
            .collect()
    }
    /// Whether the samples describe only a band of screen positions (a
    /// signal they do not show may lie outside it).
    fn band_limited(&self) -> bool {
        false
    }
}

/// The series of one pixel: used frames `index` with values `y`.
pub struct SeriesSamples<'a> {
    design: &'a Design,
    plans: &'a super::periodogram::SpectrumPlans,
    index: Vec<u32>,
    y: Vec<f64>,
    y_by_frame: &'a [f64],
    /// Per direction: its used frames, values and envelope at `kappa_dir`.
    dirs: Vec<(Vec<u32>, Vec<f64>, Vec<f64>)>,
    kappa_dir: Falloff,
}

impl<'a> SeriesSamples<'a> {
    /// The finite samples of `y_by_frame` (NaN: excluded); per-direction
    /// envelopes are kept for `kappa0`, the κ the starting scans use.
    pub fn new(
        design: &'a Design,
        plans: &'a super::periodogram::SpectrumPlans,
        y_by_frame: &'a [f64],
        kappa0: Falloff,
    ) -> Self {
        let index: Vec<u32> = (0..y_by_frame.len() as u32)
            .filter(|&i| y_by_frame[i as usize].is_finite())
            .collect();
        let y: Vec<f64> = index.iter().map(|&i| y_by_frame[i as usize]).collect();
        let dirs = (0..design.axes.len())
            .map(|dir| {
                let (idx, yd): (Vec<u32>, Vec<f64>) = index
                    .iter()
                    .zip(&y)
                    .filter(|(&i, _)| design.frames[i as usize].dir == dir)
                    .map(|(&i, &v)| (i, v))
                    .unzip();
                let env = envelope(design, &idx, &kappa0);
                (idx, yd, env)
            })
            .collect();
        SeriesSamples {
            design,
            plans,
            index,
            y,
            y_by_frame,
            dirs,
            kappa_dir: kappa0,
        }
    }
}

impl Samples for SeriesSamples<'_> {
    fn count(&self) -> usize {
        self.index.len()
    }

    fn normal(&self, p: &Params) -> Normal {
        normal_equations(self.design, &self.index, &self.y, p)
    }

    fn information(&self, p: &Params) -> DMatrix<f64> {
        let zeros = vec![0.0; self.index.len()];
        normal_equations(self.design, &self.index, &zeros, p).jtj
    }

    fn linear(&self, p: &Params, dir: Option<usize>) -> (Params, f64) {
        match dir {
            None => linear_amplitudes(self.design, &self.index, &self.y, p),
            Some(d) => {
                let (idx, yd, env) = &self.dirs[d];
                if p.kappa == self.kappa_dir {
                    linear_amplitudes_in(self.design, idx, yd, env, p)
                } else {
                    linear_amplitudes(self.design, idx, yd, p)
                }
            }
        }
    }

    fn peak(&self, d: usize) -> Option<(f64, f64)> {
        self.plans.peak(d, self.y_by_frame)
    }
}

/// `exp(−κ_g τ_i²)` of the frames in `index`: the envelope [`linear_amplitudes_in`]
/// reuses across the screen points it is asked about.
pub fn envelope(design: &Design, index: &[u32], kappa: &Falloff) -> Vec<f64> {
    index
        .iter()
        .map(|&i| {
            let f = &design.frames[i as usize];
            (-design.kappa_of(f, kappa) * f.tau * f.tau).exp()
        })
        .collect()
}

/// Least-squares background and amplitudes at fixed screen points and κ
/// (the linear part of the model), by normal equations on (1 + K) columns;
/// returns them with the residual sum of squares.
pub fn linear_amplitudes(design: &Design, index: &[u32], y: &[f64], p: &Params) -> (Params, f64) {
    linear_amplitudes_in(design, index, y, &envelope(design, index, &p.kappa), p)
}

/// [`linear_amplitudes`] with the envelope `env` of `p.kappa` given.
pub fn linear_amplitudes_in(
    design: &Design,
    index: &[u32],
    y: &[f64],
    env: &[f64],
    p: &Params,
) -> (Params, f64) {
    let k = p.k;
    let n = 1 + k;
    let mut g = [[0.0; MAX_REFLECTIONS + 1]; MAX_REFLECTIONS + 1];
    let mut h = [0.0; MAX_REFLECTIONS + 1];
    let mut row = [1.0; MAX_REFLECTIONS + 1];
    let mut yy = 0.0;
    for ((&i, &yi), &e) in index.iter().zip(y).zip(env) {
        let f = &design.frames[i as usize];
        let ax = design.axes[f.dir];
        for j in 0..k {
            row[1 + j] = e * cos_cycles(f.tau * ax.s(p.uv[j][0], p.uv[j][1]) + f.phase_cycles);
        }
        yy += yi * yi;
        for a in 0..n {
            h[a] += row[a] * yi;
            for b in a..n {
                g[a][b] += row[a] * row[b];
            }
        }
    }
    let g = DMatrix::from_fn(n, n, |a, b| g[a.min(b)][a.max(b)]);
    let h = DVector::from_column_slice(&h[..n]);
    let mut out = *p;
    let mut rss = f64::INFINITY;
    if let Some(sol) = g.cholesky().map(|c| c.solve(&h)) {
        out.offset = sol[0];
        for j in 0..k {
            out.amp[j] = sol[1 + j];
        }
        // RSS of a least-squares solution: yᵀy − hᵀβ.
        rss = (yy - h.dot(&sol)).max(0.0);
    }
    (out, rss)
}

#[cfg(test)]
impl Design {
    /// The axes of `dirs` on a `width × height` screen, no frames: what
    /// tests of direction geometry need.
    pub(crate) fn of_directions(dirs: &[f64], width: u32, height: u32) -> Design {
        use crate::acquire::patterns::FringeAxis;
        Design::new(
            Vec::new(),
            dirs.iter()
                .map(|&d| Axis::from_fringe(&FringeAxis::new(d, width, height), width, height))
                .collect(),
            dirs.to_vec(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn design(dirs: &[f64]) -> Design {
        Design::of_directions(dirs, 1600, 1200)
    }

    #[test]
    fn pair_separation_takes_the_best_non_parallel_pair() {
        // Reflections 10 px apart along v: 0° sees nothing, 90° all of it
        // (10/1200 of s), each diagonal √½ of it (10·√½/1979.9).
        let d = [0.0, 10.0];
        let along = |x: &Design| -> Vec<f64> {
            x.axes
                .iter()
                .map(|a| (a.a * d[0] + a.b * d[1]).abs())
                .collect()
        };
        let diag = 10.0 * std::f64::consts::FRAC_1_SQRT_2 / 1979.898987322333;
        let two = design(&[45.0, -45.0]);
        let s = two.pair_separation(&along(&two)).unwrap();
        assert!((s - diag).abs() < 1e-12, "{s} {diag}");
        // With the plain ones: the pair (90°, a diagonal), the diagonal's.
        let four = design(&[45.0, -45.0, 0.0, 90.0]);
        let s = four.pair_separation(&along(&four)).unwrap();
        assert!((s - diag).abs() < 1e-12, "{s} {diag}");
        // 0° and 90° alone: the pair's smaller, 0.
        let plain = design(&[0.0, 90.0]);
        assert_eq!(plain.pair_separation(&along(&plain)), Some(0.0));
        // Parallel directions have no pair: the smallest.
        let par = design(&[90.0, 270.0]);
        let s = par.pair_separation(&along(&par)).unwrap();
        assert!((s - 10.0 / 1200.0).abs() < 1e-12, "{s}");
        assert_eq!(design(&[]).pair_separation(&[]), None);
    }
}

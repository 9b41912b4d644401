//! A pixel's samples as the fits see them ([`Samples`]), the series form of
//! them ([`SeriesSamples`]), and the linear part of the model: background
//! and amplitudes by least squares at fixed screen points and κ.

use nalgebra::{DMatrix, DVector};

use super::{normal_equations, Design, Falloff, Normal, Params, MAX_REFLECTIONS};
use crate::kernels::cos_cycles;
use crate::solve::spectral::periodogram::SpectrumPlans;

/// A pixel's samples as the fits see them: the series itself
/// ([`SeriesSamples`]) or its sufficient statistics
/// ([`crate::solve::spectral::statistics::StatisticsSamples`]). Both give the same least squares.
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
    plans: &'a SpectrumPlans,
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
        plans: &'a SpectrumPlans,
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

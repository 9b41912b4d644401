//! A series whose frames repeat ([`RepeatSamples`]): the distinct frames
//! (direction, τ, phase) with, per pixel, each one's count of used samples,
//! their sum and their sum of squares. The least squares of the model
//! depends on a pixel's samples only through these: for the samples
//! `y_1 … y_n` of one distinct frame, whose model value and gradient `f`,
//! `J` they share,
//!
//!   `Σ (y_i − f)² = W + n (ȳ − f)²`,  `Σ J (y_i − f) = n J (ȳ − f)`,
//!   `Σ J Jᵀ = n J Jᵀ`,
//!
//! with `ȳ` their mean and `W = Σ (y_i − ȳ)²` their scatter, which no
//! parameter moves. So RSS, JᵀJ, Jᵀr and the linear fits are those of the
//! series, in exact arithmetic, at a cost in distinct frames, not frames: a
//! planned schedule of 100 000 frames has a few hundred. A schedule without
//! repeats gives the series' sums bit for bit (n = 1 multiplies exactly,
//! W = 0, the same order). The periodogram, which windows each frame by its
//! rank in τ, is taken from the series itself ([`SpectrumPlans::peak`]).

use nalgebra::{DMatrix, DVector};

use super::{eval_row, Design, Falloff, Normal, Params, Samples, MAX_PARAMS, MAX_REFLECTIONS};
use crate::kernels::cos_cycles;
use crate::solve::spectral::periodogram::SpectrumPlans;

/// The distinct frames of a design, each the first frame showing it, in
/// the order they first appear, and each frame's distinct index.
#[derive(Debug, Clone)]
pub struct Repeats {
    /// Per distinct frame: the first frame showing it.
    pub first: Vec<u32>,
    /// Per frame: its distinct frame's index in [`Self::first`].
    pub of_frame: Vec<u32>,
    /// Every distinct frame with its count of frames (no data).
    schedule: Groups,
}

impl Repeats {
    /// The distinct (direction, τ, phase) of `design`'s frames, compared
    /// bit for bit.
    pub fn new(design: &Design) -> Self {
        let mut seen = std::collections::HashMap::new();
        let mut first = Vec::new();
        let of_frame = design
            .frames
            .iter()
            .enumerate()
            .map(|(i, f)| {
                let key = (f.dir, f.tau.to_bits(), f.phase_cycles.to_bits());
                *seen.entry(key).or_insert_with(|| {
                    first.push(i as u32);
                    (first.len() - 1) as u32
                })
            })
            .collect::<Vec<u32>>();
        let mut count = vec![0.0; first.len()];
        for &g in &of_frame {
            count[g as usize] += 1.0;
        }
        let zeros = vec![0.0; first.len()];
        let schedule = Groups {
            frame: first.clone(),
            n: count,
            sy: zeros.clone(),
            syy: zeros,
            scatter: 0.0,
        };
        Repeats {
            first,
            of_frame,
            schedule,
        }
    }

    /// JᵀJ of the model at `p` over every frame of `design` (the
    /// schedule's Fisher information × σ²), summed over the distinct frames
    /// with their counts: [`super::normal_equations`]'s over all frames,
    /// bit for bit without repeats.
    pub fn information(&self, design: &Design, p: &Params) -> DMatrix<f64> {
        normal_equations_repeated(design, &self.schedule, p, false).jtj
    }

    /// The model's value at `p` on each distinct frame of `design` (the
    /// frame's direction, τ and phase decide it: every repeat has it).
    pub fn model_values(&self, design: &Design, p: &Params) -> Vec<f64> {
        let mut row = [0.0; MAX_PARAMS];
        self.first
            .iter()
            .map(|&f| eval_row(design, &design.frames[f as usize], p, &mut row))
            .collect()
    }

    /// Distinct frames.
    pub fn len(&self) -> usize {
        self.first.len()
    }

    /// Whether the design has no frames.
    pub fn is_empty(&self) -> bool {
        self.first.is_empty()
    }
}

/// One set of distinct frames of a pixel (all of them, or one
/// direction's): the frame standing for each, its used samples `n`, their
/// sum `sy` and sum of squares `syy`, and the sum of the scatters `W`.
#[derive(Debug, Clone, Default)]
struct Groups {
    frame: Vec<u32>,
    n: Vec<f64>,
    sy: Vec<f64>,
    syy: Vec<f64>,
    scatter: f64,
}

impl Groups {
    fn push(&mut self, frame: u32, n: f64, sy: f64, syy: f64) {
        self.frame.push(frame);
        self.n.push(n);
        self.sy.push(sy);
        self.syy.push(syy);
        // W = Σy² − ȳ Σy (0 exactly for one sample).
        self.scatter += (syy - sy * (sy / n)).max(0.0);
    }
}

/// A pixel's series summed over its repeated frames; see the module doc.
pub struct RepeatSamples<'a> {
    design: &'a Design,
    plans: &'a SpectrumPlans,
    y_by_frame: &'a [f64],
    used: usize,
    all: Groups,
    /// Per direction: its groups and their envelope at `kappa_dir`.
    dirs: Vec<(Groups, Vec<f64>)>,
    kappa_dir: Falloff,
}

impl<'a> RepeatSamples<'a> {
    /// The finite samples of `y_by_frame` (NaN: excluded) summed over the
    /// distinct frames `repeats` of `design`; per-direction envelopes kept
    /// for `kappa0`, the κ the starting scans use (as
    /// [`super::SeriesSamples::new`]).
    pub fn new(
        design: &'a Design,
        plans: &'a SpectrumPlans,
        repeats: &Repeats,
        y_by_frame: &'a [f64],
        kappa0: Falloff,
    ) -> Self {
        let m = repeats.len();
        let (mut n, mut sy, mut syy) = (vec![0.0; m], vec![0.0; m], vec![0.0; m]);
        let mut used = 0;
        for (&g, &y) in repeats.of_frame.iter().zip(y_by_frame) {
            if y.is_finite() {
                let g = g as usize;
                n[g] += 1.0;
                sy[g] += y;
                syy[g] += y * y;
                used += 1;
            }
        }
        let nd = design.axes.len();
        let mut all = Groups::default();
        let mut per_dir = vec![Groups::default(); nd];
        for (g, &f) in repeats.first.iter().enumerate() {
            if n[g] > 0.0 {
                all.push(f, n[g], sy[g], syy[g]);
                per_dir[design.frames[f as usize].dir].push(f, n[g], sy[g], syy[g]);
            }
        }
        let dirs = per_dir
            .into_iter()
            .map(|g| {
                let env = super::envelope(design, &g.frame, &kappa0);
                (g, env)
            })
            .collect();
        RepeatSamples {
            design,
            plans,
            y_by_frame,
            used,
            all,
            dirs,
            kappa_dir: kappa0,
        }
    }

    /// Distinct frames with a used sample.
    pub fn distinct(&self) -> usize {
        self.all.frame.len()
    }
}

impl Samples for RepeatSamples<'_> {
    fn count(&self) -> usize {
        self.used
    }

    fn normal(&self, p: &Params) -> Normal {
        normal_equations_repeated(self.design, &self.all, p, true)
    }

    fn information(&self, p: &Params) -> DMatrix<f64> {
        normal_equations_repeated(self.design, &self.all, p, false).jtj
    }

    fn linear(&self, p: &Params, dir: Option<usize>) -> (Params, f64) {
        match dir {
            None => {
                let env = super::envelope(self.design, &self.all.frame, &p.kappa);
                linear_repeated(self.design, &self.all, &env, p)
            }
            Some(d) => {
                let (g, env) = &self.dirs[d];
                if p.kappa == self.kappa_dir {
                    linear_repeated(self.design, g, env, p)
                } else {
                    let env = super::envelope(self.design, &g.frame, &p.kappa);
                    linear_repeated(self.design, g, &env, p)
                }
            }
        }
    }

    fn peak(&self, d: usize) -> Option<(f64, f64)> {
        self.plans.peak(d, self.y_by_frame)
    }
}

/// [`super::normal_equations`] over `groups` (each distinct frame weighted
/// by its samples); with `data` false, JᵀJ alone (the data taken as 0).
fn normal_equations_repeated(design: &Design, groups: &Groups, p: &Params, data: bool) -> Normal {
    match p.len() {
        5 => normal_fixed::<5>(design, groups, p, data),
        6 => normal_fixed::<6>(design, groups, p, data),
        7 => normal_fixed::<7>(design, groups, p, data),
        8 => normal_fixed::<8>(design, groups, p, data),
        9 => normal_fixed::<9>(design, groups, p, data),
        10 => normal_fixed::<10>(design, groups, p, data),
        11 => normal_fixed::<11>(design, groups, p, data),
        12 => normal_fixed::<12>(design, groups, p, data),
        13 => normal_fixed::<13>(design, groups, p, data),
        _ => normal_fixed::<MAX_PARAMS>(design, groups, p, data),
    }
}

fn normal_fixed<const N: usize>(design: &Design, g: &Groups, p: &Params, data: bool) -> Normal {
    debug_assert_eq!(N, p.len());
    let mut jtj = [[0.0; N]; N];
    let mut jtr = [0.0; N];
    let mut rss = 0.0;
    let mut full = [0.0; MAX_PARAMS];
    for ((&i, &n), &sy) in g.frame.iter().zip(&g.n).zip(&g.sy) {
        let f = eval_row(design, &design.frames[i as usize], p, &mut full);
        let row: [f64; N] = full[..N].try_into().expect("N ≤ MAX_PARAMS");
        // n (ȳ − f): the residuals' sum over the frame's samples.
        let (r, nr) = if data {
            let r = sy / n - f;
            (r, n * r)
        } else {
            (-f, n * -f)
        };
        rss += nr * r;
        for a in 0..N {
            jtr[a] += row[a] * nr;
            let w = n * row[a];
            for b in a..N {
                jtj[a][b] += w * row[b];
            }
        }
    }
    Normal {
        rss: rss + if data { g.scatter } else { 0.0 },
        jtj: DMatrix::from_fn(N, N, |a, b| jtj[a.min(b)][a.max(b)]),
        jtr: DVector::from_column_slice(&jtr),
    }
}

/// [`super::linear_amplitudes_in`] over `groups` with their envelope `env`.
fn linear_repeated(design: &Design, groups: &Groups, env: &[f64], p: &Params) -> (Params, f64) {
    let k = p.k;
    let m = 1 + k;
    let mut g = [[0.0; MAX_REFLECTIONS + 1]; MAX_REFLECTIONS + 1];
    let mut h = [0.0; MAX_REFLECTIONS + 1];
    let mut row = [1.0; MAX_REFLECTIONS + 1];
    let mut yy = 0.0;
    let sums = groups.frame.iter().zip(&groups.n).zip(&groups.sy);
    for ((((&i, &n), &sy), &syy), &e) in sums.zip(&groups.syy).zip(env) {
        let f = &design.frames[i as usize];
        let ax = design.axes[f.dir];
        for j in 0..k {
            row[1 + j] = e * cos_cycles(f.tau * ax.s(p.uv[j][0], p.uv[j][1]) + f.phase_cycles);
        }
        yy += syy;
        for a in 0..m {
            h[a] += row[a] * sy;
            let w = n * row[a];
            for b in a..m {
                g[a][b] += w * row[b];
            }
        }
    }
    let g = DMatrix::from_fn(m, m, |a, b| g[a.min(b)][a.max(b)]);
    let h = DVector::from_column_slice(&h[..m]);
    let mut out = *p;
    let mut rss = f64::INFINITY;
    if let Some(sol) = g.cholesky().map(|c| c.solve(&h)) {
        out.offset = sol[0];
        out.amp[..k].copy_from_slice(&sol.as_slice()[1..m]);
        rss = (yy - h.dot(&sol)).max(0.0);
    }
    (out, rss)
}

#[cfg(test)]
#[path = "repeats_tests.rs"]
mod tests;

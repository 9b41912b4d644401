//! One pixel's part of the surface-domain fit: its exact likelihood,
//! linearised at the screen points the current surfaces predict, with the
//! per-pixel nuisance (background, amplitudes, κ) profiled out in closed
//! form.
//!
//! For a pixel with parameters θ = (n, s) — nuisance n, screen points s —
//! the Gauss–Newton model of its residual sum of squares about θ is
//! `RSS(θ + δ) ≈ RSS − 2 gᵀδ + δᵀHδ` with `H = JᵀJ`, `g = Jᵀr` (the
//! spectral model's normal equations, [`Samples::normal`], on either
//! engine). Minimising over δn for a given δs leaves
//!
//!   `δn = H_nn⁻¹ (g_n − H_ns δs)`,
//!   `RSS ≈ const − 2 g̃ᵀδs + δsᵀ H̃ δs`,  `H̃ = H_ss − H_sn H_nn⁻¹ H_ns`,
//!   `g̃ = g_s − H_sn H_nn⁻¹ g_n`,
//!
//! i.e. a Gaussian pseudo-observation `s* = s + H̃⁻¹ g̃` of the screen points
//! with covariance `σ² H̃⁻¹` (σ² = RSS/(N − p), the pixel's noise). Summed
//! over pixels and fitted by the surface solver, these give exactly the
//! Gauss–Newton step of the global likelihood in the Zernike coefficients;
//! at its fixed point every pixel's `s` is the surfaces' prediction and the
//! gradient of the global likelihood vanishes. Written by hand: the blocks
//! are 2–4 wide, and the profiling is this model's algebra, not a solver
//! a crate provides.

use nalgebra::{DMatrix, DVector};

use crate::solve::spectral::model::{
    Falloff, Normal, Params, Samples, MAX_GROUPS, MAX_REFLECTIONS,
};

/// Largest number of nuisance parameters: A, B_1 … B_K, κ_1 … κ_G.
const MAX_NUISANCE: usize = 1 + MAX_REFLECTIONS + MAX_GROUPS;

/// A pixel's linearisation at its current parameters.
#[derive(Debug, Clone, Copy)]
pub struct Linear {
    /// The screen points `(u1, v1, u2, v2)` it was taken at, px (u2, v2
    /// NaN with one reflection).
    pub s0: [f64; 4],
    /// The pseudo-observation `s* = s0 + H̃⁻¹ g̃`, px.
    pub s_star: [f64; 4],
    /// Its covariance `σ² H̃⁻¹`, px² (the 2×2 block alone with one reflection).
    pub cov: [[f64; 4]; 4],
    /// `H_nn⁻¹ g_n`: the nuisance step at unchanged screen points.
    pub nuisance_step: [f64; MAX_NUISANCE],
    /// `H_nn⁻¹ H_ns`: how the nuisance step moves with the screen points.
    pub nuisance_coupling: [[f64; 4]; MAX_NUISANCE],
    /// RSS at the linearisation point, counts².
    pub rss: f64,
    /// Samples used.
    pub samples: usize,
    /// Variance of the last reflection's amplitude B_K, all parameters
    /// free, counts² (NaN with one reflection): with B_K it makes the Wald
    /// statistic that tests whether the scene has that reflection at all.
    pub last_amp_var: f64,
    /// `g̃ᵀ H̃⁻¹ g̃ / σ²`: how far the pixel's own data would move its points
    /// from the surfaces' prediction, as a χ² with 2K degrees of freedom.
    pub chi2: f64,
}

/// Indices of the nuisance (A, B_k, κ_g) and screen-point parameters of a
/// K-reflection model with G falloff groups (see [`Params`] for the order).
fn split(k: usize, groups: usize) -> (Vec<usize>, Vec<usize>) {
    let mut nuisance: Vec<usize> = (0..=k).collect();
    nuisance.extend((0..groups).map(|g| 1 + 3 * k + g));
    let screen = (1 + k..1 + 3 * k).collect();
    (nuisance, screen)
}

/// The third reflection (two internal round trips, S3) tied to the back's:
/// its amplitude `ratio · B2` and its screen point `uv` both follow from
/// the surfaces (the traced Fresnel ratio scaled by the global factor the
/// data estimate, the traced S3), so it adds no per-pixel unknown.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tie {
    /// `B3 / B2`.
    pub ratio: f64,
    /// S3, px.
    pub uv: [f64; 2],
}

/// The two-reflection parameters `p` with the tied third reflection added
/// (K = 3, `B3 = ratio · B2` at S3).
fn with_third(p: &Params, tie: &Tie) -> Params {
    let mut q = *p;
    q.k = 3;
    q.amp[2] = tie.ratio * p.amp[1];
    q.uv[2] = tie.uv;
    q
}

/// The tied model's normal equations in the two-reflection parameters of
/// `p` (A, B1, B2, u1, v1, u2, v2, κ_1 … κ_G): the three-reflection ones at
/// [`with_third`] reduced by `J₂ = J₃ T`, where T maps B2 onto B2 and
/// `ratio`·B3 and holds S3 (its columns drop out).
fn tied_normal(samples: &dyn Samples, p: &Params, tie: &Tie) -> Normal {
    let full = samples.normal(&with_third(p, tie));
    let t = tie_map(tie.ratio, p.kappa.groups);
    Normal {
        rss: full.rss,
        jtj: t.transpose() * &full.jtj * &t,
        jtr: t.transpose() * &full.jtr,
    }
}

/// T of [`tied_normal`] with G falloff groups: (10 + G) × (7 + G). Full
/// layout (K = 3): A 0, B 1–3, (u, v) 4–9, κ from 10; reduced (K = 2):
/// A 0, B 1–2, (u, v) 3–6, κ from 7.
fn tie_map(ratio: f64, groups: usize) -> DMatrix<f64> {
    let mut t = DMatrix::zeros(10 + groups, 7 + groups);
    for (full, red) in [(0, 0), (1, 1), (2, 2), (4, 3), (5, 4), (6, 5), (7, 6)] {
        t[(full, red)] = 1.0;
    }
    for g in 0..groups {
        t[(10 + g, 7 + g)] = 1.0;
    }
    t[(3, 2)] = ratio;
    t
}

/// How the tied third reflection's global factor γ (`B3 = γ ρ B2`, ρ the
/// traced Fresnel ratio) would move this pixel's fit: the score and
/// information of γ at `p` with `tie` (ratio γρ), every one of the pixel's
/// own parameters profiled out (its screen points too: holding them at
/// the surfaces' prediction would leave γ's step to the surfaces, which
/// have already bent to absorb the third path, and the alternation would
/// crawl), both divided by the pixel's σ². Summed over pixels,
/// `Σ score / Σ information` is the Gauss–Newton step of γ and
/// `1/√Σ information` its σ (conservative: what the surfaces share
/// between pixels is not counted).
pub fn third_score(samples: &dyn Samples, p: &Params, tie: &Tie, rho: f64) -> Option<[f64; 2]> {
    let full = samples.normal(&with_third(p, tie));
    let groups = p.kappa.groups;
    let (nf, nr) = (10 + groups, 7 + groups);
    let t = tie_map(tie.ratio, groups);
    // γ's column: ∂μ/∂γ = ρ B2 · (B3's column).
    let mut t_ext = DMatrix::zeros(nf, nr + 1);
    t_ext.columns_mut(0, nr).copy_from(&t);
    t_ext[(3, nr)] = rho * p.amp[1];
    let jtj = t_ext.transpose() * &full.jtj * &t_ext;
    let jtr = t_ext.transpose() * &full.jtr;
    let h_tt = jtj.view((0, 0), (nr, nr)).clone_owned();
    let h_tg = jtj.view((0, nr), (nr, 1)).clone_owned();
    let chol = h_tt.cholesky()?;
    let a = chol.solve(&h_tg);
    let g_t = jtr.rows(0, nr).clone_owned();
    let info = jtj[(nr, nr)] - (h_tg.transpose() * &a)[(0, 0)];
    let score = jtr[nr] - (a.transpose() * &g_t)[(0, 0)];
    let dof = samples.count().checked_sub(p.len()).filter(|&d| d > 0)? as f64;
    let sigma2 = full.rss / dof;
    (info > 0.0 && sigma2 > 0.0 && score.is_finite()).then_some([score / sigma2, info / sigma2])
}

/// The pixel's linearisation at `p`; `None` where its normal equations do
/// not determine the points (a singular block: no signal, or κ running off).
pub fn linearise(samples: &dyn Samples, p: &Params) -> Option<Linear> {
    linearise_tied(samples, p, None)
}

/// [`linearise`] with the tied third reflection of `tie` in the model (two
/// reflections in `p`).
pub fn linearise_tied(samples: &dyn Samples, p: &Params, tie: Option<&Tie>) -> Option<Linear> {
    let k = p.k;
    let normal = match tie {
        Some(tie) if k == 2 => tied_normal(samples, p, tie),
        _ => samples.normal(p),
    };
    let n = samples.count();
    let dof = n.checked_sub(p.len()).filter(|&d| d > 0)? as f64;
    let (ni, si) = split(k, p.kappa.groups);
    let pick = |rows: &[usize], cols: &[usize]| {
        DMatrix::from_fn(rows.len(), cols.len(), |a, b| {
            normal.jtj[(rows[a], cols[b])]
        })
    };
    let h_nn = pick(&ni, &ni);
    let h_ns = pick(&ni, &si);
    let h_ss = pick(&si, &si);
    let g_n = DVector::from_iterator(ni.len(), ni.iter().map(|&i| normal.jtr[i]));
    let g_s = DVector::from_iterator(si.len(), si.iter().map(|&i| normal.jtr[i]));
    let chol = h_nn.cholesky()?;
    let coupling = chol.solve(&h_ns);
    let step_n = chol.solve(&g_n);
    let h_red = &h_ss - h_ns.transpose() * &coupling;
    let g_red = &g_s - h_ns.transpose() * &step_n;
    let red = h_red.cholesky()?;
    let ds = red.solve(&g_red);
    let sigma2 = normal.rss / dof;
    if !(sigma2 > 0.0 && ds.iter().all(|v| v.is_finite())) {
        return None;
    }
    let inv = red.inverse();
    let last_amp_var = if k >= 2 {
        let full = normal.jtj.clone().cholesky()?.inverse();
        sigma2 * full[(k, k)]
    } else {
        f64::NAN
    };
    let mut s0 = [f64::NAN; 4];
    let mut s_star = [f64::NAN; 4];
    let mut cov = [[0.0; 4]; 4];
    for j in 0..k {
        for c in 0..2 {
            s0[2 * j + c] = p.uv[j][c];
            s_star[2 * j + c] = p.uv[j][c] + ds[2 * j + c];
        }
    }
    for (a, row) in cov.iter_mut().enumerate().take(2 * k) {
        for (b, v) in row.iter_mut().enumerate().take(2 * k) {
            *v = sigma2 * inv[(a, b)];
        }
    }
    let mut nuisance_step = [0.0; MAX_NUISANCE];
    let mut nuisance_coupling = [[0.0; 4]; MAX_NUISANCE];
    for a in 0..ni.len() {
        nuisance_step[a] = step_n[a];
        for b in 0..si.len() {
            nuisance_coupling[a][b] = coupling[(a, b)];
        }
    }
    Some(Linear {
        s0,
        s_star,
        cov,
        nuisance_step,
        nuisance_coupling,
        rss: normal.rss,
        samples: n,
        chi2: g_red.dot(&ds) / sigma2,
        last_amp_var,
    })
}

/// `p` moved to the screen points `s` (layout of [`Linear::s0`]) with the
/// nuisance that minimises the linearised RSS there:
/// `n + H_nn⁻¹ g_n − H_nn⁻¹ H_ns (s − s0)`.
pub fn moved(p: &Params, lin: &Linear, s: &[f64; 4]) -> Params {
    let k = p.k;
    let (ni, _) = split(k, p.kappa.groups);
    let mut ds = [0.0; 4];
    for (i, d) in ds.iter_mut().enumerate().take(2 * k) {
        *d = s[i] - lin.s0[i];
    }
    let mut out = *p;
    for (a, &idx) in ni.iter().enumerate() {
        let mut step = lin.nuisance_step[a];
        for (b, d) in ds.iter().enumerate().take(2 * k) {
            step -= lin.nuisance_coupling[a][b] * d;
        }
        match idx {
            0 => out.offset += step,
            i if i <= k => out.amp[i - 1] += step,
            i => out.kappa[i - (1 + 3 * k)] += step,
        }
    }
    for j in 0..k {
        out.uv[j] = [s[2 * j], s[2 * j + 1]];
    }
    out
}

/// A pixel's starting parameters: its `k` screen points at `s`, κ0, and the
/// background and amplitudes by linear least squares there.
pub fn start(samples: &dyn Samples, k: usize, s: &[f64; 4], kappa0: Falloff) -> Params {
    let mut uv = [[0.0; 2]; MAX_REFLECTIONS];
    for (j, point) in uv.iter_mut().enumerate().take(k) {
        *point = [s[2 * j], s[2 * j + 1]];
    }
    let p = Params {
        k,
        offset: 0.0,
        amp: [0.0; MAX_REFLECTIONS],
        uv,
        kappa: kappa0,
    };
    samples.linear(&p, None).0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solve::spectral::model::{Axis, Design, FrameMeta};
    use crate::solve::spectral::periodogram::SpectrumPlans;

    /// Two directions, τ 0.5…100: a design small enough for a unit test.
    /// ±45°-like axes; the second's fringe length differs from the first's
    /// unless `stretch2` is 1 (then one falloff group, else two).
    fn design(stretch2: f64) -> Design {
        let mut frames = Vec::new();
        for dir in 0..2 {
            for i in 1..=200 {
                frames.push(FrameMeta {
                    tau: 0.5 * i as f64,
                    phase_cycles: 0.0,
                    dir,
                });
            }
        }
        let axes = vec![
            Axis {
                a: 1.0 / 1000.0,
                b: 1.0 / 1000.0,
                c: 0.0,
                stretch: 1.0,
            },
            Axis {
                a: 1.0 / 1000.0,
                b: -1.0 / 1000.0,
                c: 0.0,
                stretch: stretch2,
            },
        ];
        Design::new(frames, axes, vec![45.0, -45.0])
    }

    /// Noise-free samples of `truth`: the pseudo-observation from a start
    /// off by a small fraction of a bin lands on the truth to second order
    /// in the offset, and the moved nuisance on the truth's.
    #[test]
    fn pseudo_observation_of_exact_data_is_the_truth() {
        exact_data_reaches_the_truth(1.0);
    }

    /// The same with two falloff groups whose κ differ by 1.65² (0° and 90°
    /// beside the diagonals on the paper's screen): each group's κ is
    /// profiled out on its own and recovered.
    #[test]
    fn pseudo_observation_with_two_falloff_groups_is_the_truth() {
        exact_data_reaches_the_truth(1.65);
    }

    fn exact_data_reaches_the_truth(stretch2: f64) {
        let d = design(stretch2);
        assert_eq!(d.falloff_groups(), if stretch2 == 1.0 { 1 } else { 2 });
        let truth = Params {
            k: 2,
            offset: 500.0,
            amp: [300.0, 120.0, 0.0],
            uv: [[400.0, 300.0], [403.0, 301.5], [0.0; 2]],
            kappa: d.physical_falloff(1.0 / 150.0f64.powi(2)),
        };
        let y: Vec<f64> = d
            .frames
            .iter()
            .map(|f| {
                let mut row = [0.0; crate::solve::spectral::model::MAX_PARAMS];
                crate::solve::spectral::model::eval_row(&d, f, &truth, &mut row)
            })
            .collect();
        let plans = SpectrumPlans::new(&d);
        let samples =
            crate::solve::spectral::model::SeriesSamples::new(&d, &plans, &y, truth.kappa);
        // One bin is 1000/100 = 10 px along an axis: start 0.02 bin off,
        // κ 20 % off. Each pseudo-observation is one Gauss–Newton step of
        // the pixel alone; iterated (moving the nuisance with it) it must
        // reach the truth, its fixed point, to rounding.
        let want = [400.0, 300.0, 403.0, 301.5];
        let mut s = [400.2, 299.9, 402.8, 301.7];
        let mut p = start(&samples, 2, &s, d.uniform_falloff(1.2 * truth.kappa[0]));
        let err = |s: &[f64; 4]| {
            s.iter()
                .zip(want)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max)
        };
        let mut last = err(&s);
        for it in 0..8 {
            let Some(lin) = linearise(&samples, &p) else {
                break; // exact fit: RSS 0, nothing left to estimate
            };
            p = moved(&p, &lin, &lin.s_star);
            s = lin.s_star;
            // The first step also corrects κ and the amplitudes (started
            // off): it may overshoot; from there convergence is quadratic.
            assert!(
                it == 0 || err(&s) <= last.max(1e-12),
                "{} after {last}",
                err(&s)
            );
            last = err(&s);
        }
        assert!(last < 1e-9, "{s:?}");
        assert!((p.amp[0] - 300.0).abs() < 1e-4, "{:?}", p.amp);
        assert!((p.amp[1] - 120.0).abs() < 1e-4, "{:?}", p.amp);
        for g in 0..d.falloff_groups() {
            let r = p.kappa[g] / truth.kappa[g] - 1.0;
            assert!(r.abs() < 1e-6, "{:?} {:?}", p.kappa, truth.kappa);
        }
    }
}

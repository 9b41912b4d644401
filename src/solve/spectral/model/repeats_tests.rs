//! Tests of the sums over repeated frames against the series they stand
//! for: bit for bit without repeats, to the sums' rounding with them.

use super::{RepeatSamples, Repeats};
use crate::acquire::patterns::FringeAxis;
use crate::solve::spectral::model::{
    levenberg_marquardt, normal_equations, Axis, Design, FrameMeta, Normal, Params, Samples,
    SeriesSamples,
};
use crate::solve::spectral::periodogram::SpectrumPlans;

/// Distinct frames per direction: τ = 0.4 … 120 on ±45° and 0°, a quarter
/// phase on every other τ (three falloff groups on the 1600 × 1200
/// screen).
const DISTINCT: usize = 300;

/// Frames of the distinct frames `k` of every direction shown `reps(k)`
/// times, in rounds (round r shows those with more than r repeats), so
/// that the repeats of one frame lie apart as a design's would not.
fn design_with(reps: impl Fn(usize) -> usize) -> Design {
    let dirs = [45.0, -45.0, 0.0];
    let most = (0..DISTINCT).map(&reps).max().unwrap_or(1);
    let mut frames = Vec::new();
    for r in 0..most {
        for d in 0..dirs.len() {
            for k in (0..DISTINCT).filter(|&k| r < reps(k)) {
                frames.push(FrameMeta {
                    tau: 0.4 * (k + 1) as f64,
                    phase_cycles: if k % 2 == 0 { 0.0 } else { 0.25 },
                    dir: d,
                });
            }
        }
    }
    Design::new(
        frames,
        dirs.iter()
            .map(|&a| Axis::from_fringe(&FringeAxis::new(a, 1600, 1200), 1600, 1200))
            .collect(),
        dirs.to_vec(),
    )
}

/// Two reflections at the physical falloff.
fn truth(design: &Design) -> Params {
    Params {
        k: 2,
        offset: 1800.0,
        amp: [900.0, 700.0, 0.0],
        uv: [[800.3, 600.7], [806.9, 603.1], [0.0; 2]],
        kappa: design.physical_falloff(1.3 / 150.0f64.powi(2)),
    }
}

/// Counts of the model at `p` plus a deterministic pattern of ±`noise`
/// per sample (repeats of a frame differ), rounded; every 37th sample
/// excluded (NaN), as a clipped one is.
fn series(design: &Design, p: &Params, noise: f64) -> Vec<f64> {
    let mut row = [0.0; super::MAX_PARAMS];
    design
        .frames
        .iter()
        .enumerate()
        .map(|(i, f)| {
            if i % 37 == 11 {
                return f64::NAN;
            }
            let v = super::eval_row(design, f, p, &mut row);
            let n = noise * (2.0 * ((i as f64 * 12.9898).sin() * 43758.5453).fract().abs() - 1.0);
            (v + n).round()
        })
        .collect()
}

/// Parameters away from the truth: moved points, amplitude and falloffs.
fn off(t: &Params) -> Params {
    let mut o = *t;
    o.uv[0][0] += 0.3;
    o.uv[1][1] -= 0.2;
    for g in 0..o.kappa.groups {
        o.kappa[g] *= 1.3;
    }
    o.amp[1] *= 0.8;
    o
}

fn assert_same(a: &Normal, b: &Normal) {
    assert_eq!(a.rss.to_bits(), b.rss.to_bits(), "{} vs {}", a.rss, b.rss);
    assert_eq!(a.jtj, b.jtj);
    assert_eq!(a.jtr, b.jtr);
}

/// A schedule without repeats: every sum is the series' own, in the same
/// order, each weight 1 an exact product: the same bits.
#[test]
fn without_repeats_the_sums_are_the_series_bit_for_bit() {
    let design = design_with(|_| 1);
    let plans = SpectrumPlans::new(&design);
    let t = truth(&design);
    let y = series(&design, &t, 30.0);
    let k0 = design.uniform_falloff(150.0f64.powi(-2));
    let repeats = Repeats::new(&design);
    assert_eq!(repeats.len(), design.frames.len());
    let a = SeriesSamples::new(&design, &plans, &y, k0);
    let b = RepeatSamples::new(&design, &plans, &repeats, &y, k0);
    assert_eq!(a.count(), b.count());
    let mut one = t;
    one.k = 1;
    let index: Vec<u32> = (0..design.frames.len() as u32).collect();
    let zeros = vec![0.0; index.len()];
    for p in [t, off(&t), one] {
        assert_same(&a.normal(&p), &b.normal(&p));
        assert_eq!(a.information(&p), b.information(&p));
        let all = normal_equations(&design, &index, &zeros, &p).jtj;
        assert_eq!(all, repeats.information(&design, &p));
        for dir in [None, Some(0), Some(1), Some(2)] {
            for q in [p, Params { kappa: k0, ..p }] {
                let (pa, ra) = a.linear(&q, dir);
                let (pb, rb) = b.linear(&q, dir);
                assert_eq!((pa, ra.to_bits()), (pb, rb.to_bits()), "{dir:?}");
            }
        }
    }
    for d in 0..3 {
        assert_eq!(a.peak(d), b.peak(d));
    }
}

/// Frames shown 1 to 4 times: the sums over the distinct frames are the
/// series' least squares to their rounding. Bounds: a sum of N terms
/// computed in another grouping differs by at most ~N ε Σ|terms| (ε the
/// unit roundoff; recursive summation, a few more roundings per term for
/// the weights and means: the factor 8). |JᵀJ_ab| terms sum to at most
/// √(JᵀJ_aa JᵀJ_bb) (Cauchy–Schwarz), Jᵀr's to √(JᵀJ_aa · 4 Σy²) (the
/// model within the noise of the data, |y − f| ≤ |y| + |f|), and the
/// RSS's, before its cancellation in the grouped form (W = Σy² − ȳΣy),
/// to Σy².
#[test]
fn repeated_frames_give_the_series_least_squares() {
    let design = design_with(|k| 1 + (k * 7) % 4);
    let plans = SpectrumPlans::new(&design);
    let t = truth(&design);
    let y = series(&design, &t, 30.0);
    let k0 = design.uniform_falloff(150.0f64.powi(-2));
    let repeats = Repeats::new(&design);
    assert_eq!(repeats.len(), 3 * DISTINCT);
    let a = SeriesSamples::new(&design, &plans, &y, k0);
    let b = RepeatSamples::new(&design, &plans, &repeats, &y, k0);
    assert_eq!(a.count(), b.count());
    let n = a.count() as f64;
    let yy: f64 = y.iter().filter(|v| v.is_finite()).map(|v| v * v).sum();
    let tol = 8.0 * n * f64::EPSILON;
    let index: Vec<u32> = (0..design.frames.len() as u32).collect();
    let zeros = vec![0.0; index.len()];
    let tol_all = 8.0 * index.len() as f64 * f64::EPSILON;
    let mut one = t;
    one.k = 1;
    for p in [t, off(&t), one] {
        let (sa, sb) = (a.normal(&p), b.normal(&p));
        assert!(
            (sa.rss - sb.rss).abs() <= tol * yy,
            "rss {} vs {}",
            sa.rss,
            sb.rss
        );
        let every = normal_equations(&design, &index, &zeros, &p);
        let schedule = repeats.information(&design, &p);
        let np = p.len();
        for i in 0..np {
            let ii = sa.jtj[(i, i)];
            let bound_r = tol * (ii * 4.0 * yy).sqrt();
            assert!(
                (sa.jtr[i] - sb.jtr[i]).abs() <= bound_r,
                "Jᵀr[{i}] {} vs {}",
                sa.jtr[i],
                sb.jtr[i]
            );
            for j in 0..np {
                let bound = tol * (ii * sa.jtj[(j, j)]).sqrt();
                assert!(
                    (sa.jtj[(i, j)] - sb.jtj[(i, j)]).abs() <= bound,
                    "JᵀJ[{i},{j}] {} vs {}",
                    sa.jtj[(i, j)],
                    sb.jtj[(i, j)]
                );
                // The samples' information (the used ones), and the
                // schedule's (every frame counted) against the series'
                // sum over every frame: its diagonal bounds it likewise.
                let (ia, ib) = (a.information(&p)[(i, j)], b.information(&p)[(i, j)]);
                assert!((ia - ib).abs() <= bound, "{ia} vs {ib}");
                let (fa, fb) = (every.jtj[(i, j)], schedule[(i, j)]);
                let bound_all = tol_all * (every.jtj[(i, i)] * every.jtj[(j, j)]).sqrt();
                assert!((fa - fb).abs() <= bound_all, "{fa} vs {fb}");
            }
        }
        // The linear fits: the RSS as above; background and amplitudes
        // to the sums' rounding times the Gram matrix's condition (a
        // constant and unit-envelope cosines of distinct frequencies over
        // hundreds of frames, nearly orthogonal: κ ≲ 10), relative 1e-9
        // with room to spare against 8 N ε ≈ 1e-11.
        for dir in [None, Some(0), Some(1), Some(2)] {
            let (pa, ra) = a.linear(&p, dir);
            let (pb, rb) = b.linear(&p, dir);
            assert!((ra - rb).abs() <= tol * yy, "{dir:?}: {ra} vs {rb}");
            assert!((pa.offset - pb.offset).abs() <= 1e-9 * pa.offset.abs());
            for j in 0..p.k {
                assert!((pa.amp[j] - pb.amp[j]).abs() <= 1e-9 * pa.amp[j].abs().max(1.0));
            }
        }
    }
    // The periodogram is the series' own (it windows each frame by rank).
    for d in 0..3 {
        assert_eq!(a.peak(d), b.peak(d));
    }
    // The fits from one start: each stops within ~0.03σ of the same
    // minimum (the convergence rule's χ² step, `fit::CHI2_TOL`), so within
    // 0.06σ of each other on every coordinate.
    let start = off(&t);
    let fa = levenberg_marquardt(&a, start, 50);
    let fb = levenberg_marquardt(&b, start, 50);
    assert!(fa.converged && fb.converged);
    let cov = fa.jtj.clone().try_inverse().expect("information") * fa.sigma2(a.count());
    for j in 0..2 {
        for c in 0..2 {
            let i = fa.params.u_index(j) + c;
            let sd = cov[(i, i)].sqrt();
            let d = (fa.params.uv[j][c] - fb.params.uv[j][c]).abs();
            assert!(d <= 0.06 * sd, "point {j}.{c}: {d} against σ {sd}");
            // And both near the truth (the fit works on these data): 6σ.
            assert!((fb.params.uv[j][c] - t.uv[j][c]).abs() <= 6.0 * sd);
        }
    }
}

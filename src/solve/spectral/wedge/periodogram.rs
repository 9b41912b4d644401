//! One sample pixel's periodogram per direction for the wedge search
//! (its own file: the search's grid and rules stay readable beside it).

use super::super::model::Design;
use super::{Grid, FRONT_MASK_BINS, GRID_BINS};

/// Direction `d`'s periodogram of `y` on the μ grid over `[0, 1.05]`,
/// divided by its median, the front's lobe (about its peak within the mask
/// of `mask`, the predicted front) set to the median; and that peak's
/// normalised power and μ.
pub(super) fn periodogram(
    design: &Design,
    y: &[f64],
    d: usize,
    grid: &Grid,
    mask: f64,
) -> (Vec<f64>, f64, f64) {
    let frames: Vec<(f64, f64, f64)> = design
        .frames
        .iter()
        .zip(y)
        .filter(|(f, v)| f.dir == d && v.is_finite())
        .map(|(f, &v)| (f.tau, f.phase_cycles, v))
        .collect();
    let n = (1.05 / grid.step[d]) as usize + 1;
    if frames.len() < 8 {
        return (vec![1.0; n], 1.0, mask);
    }
    let mean = frames.iter().map(|f| f.2).sum::<f64>() / frames.len() as f64;
    // A Hann window over τ: the front's sidelobes (−13 dB unwindowed) would
    // otherwise stand beside its masked lobe as tall as a weak back peak.
    let (lo_tau, hi_tau) = frames
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), f| {
            (a.min(f.0), b.max(f.0))
        });
    let span = (hi_tau - lo_tau).max(1e-12);
    let mut power = vec![0.0; n];
    // The phasor of each frame advanced by one grid step per μ: a complex
    // multiply per frame and step instead of a sine and a cosine.
    let mut re = vec![0.0; frames.len()];
    let mut im = vec![0.0; frames.len()];
    let mut rot = Vec::with_capacity(frames.len());
    for (k, &(tau, phase, v)) in frames.iter().enumerate() {
        let a = -std::f64::consts::TAU * phase;
        let win = 0.5 - 0.5 * (std::f64::consts::TAU * (tau - lo_tau) / span).cos();
        re[k] = (v - mean) * win * a.cos();
        im[k] = (v - mean) * win * a.sin();
        let r = -std::f64::consts::TAU * tau * grid.step[d];
        rot.push((r.cos(), r.sin()));
    }
    for p in power.iter_mut() {
        let (mut sr, mut si) = (0.0, 0.0);
        for k in 0..frames.len() {
            sr += re[k];
            si += im[k];
            let (c, s) = rot[k];
            let (r0, i0) = (re[k], im[k]);
            re[k] = r0 * c - i0 * s;
            im[k] = r0 * s + i0 * c;
        }
        *p = sr * sr + si * si;
    }
    let lo = (3.0 / GRID_BINS) as usize;
    let mut sorted: Vec<f64> = power.iter().skip(lo).copied().collect();
    sorted.sort_by(f64::total_cmp);
    let median = sorted
        .get(sorted.len() / 2)
        .copied()
        .unwrap_or(1.0)
        .max(1e-300);
    let half = FRONT_MASK_BINS * grid.bins[d];
    // The lobe is centred where the front's peak is, within the mask of
    // its prediction: an element or a front a little off its nominal place
    // moves the whole lobe, and its shoulder must not pass for the back.
    let mut front = (1.0f64, mask);
    for (i, p) in power.iter_mut().enumerate() {
        let mu = i as f64 * grid.step[d];
        *p /= median;
        if (mu - mask).abs() <= half && *p > front.0 {
            front = (*p, mu);
        }
    }
    for (i, p) in power.iter_mut().enumerate() {
        let mu = i as f64 * grid.step[d];
        if i < lo || (mu - front.1).abs() <= half {
            *p = 1.0;
        }
    }
    (power, front.0, front.1)
}

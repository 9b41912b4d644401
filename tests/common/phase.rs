//! A phase-shifting decode scored against the truth and the Cramér–Rao
//! bound, shared by the phase-shifting tests.

use mfd::acquire::patterns::{FringeAxis, Pattern};
use mfd::optics::station::Station;
use mfd::optics::trace::TracedView;
use mfd::sim::PhaseShiftRenderer;
use mfd::solve::spectral::bound::phase_shifting_cov;
use mfd::solve::spectral::phase::PhaseModel;
use mfd::solve::spectral::SpectralMaps;

/// The decode of the front points of `view`'s pixels.
pub struct Scored {
    /// Pixels with a front path, and those decoded.
    pub expected: usize,
    pub decoded: usize,
    /// RMS of |error| and of the bound's `sqrt(tr C)`, screen px.
    pub rms_error: f64,
    pub rms_bound: f64,
    /// RMS of error / reported σ over both coordinates of every decoded pixel.
    pub rms_z: f64,
    /// Largest |error| / σ of a coordinate.
    pub worst_z: f64,
    /// Per decoded pixel: the true point and the error, screen px.
    pub errors: Vec<([f64; 2], [f64; 2])>,
}

/// `maps` against the truth of `view`, with each pixel's bound taken at the
/// truth: its nuisance parameters fitted with `model` (the decode's own
/// response model) to `cam`'s noise-free samples of `patterns`.
pub fn score(
    view: &TracedView,
    maps: &SpectralMaps,
    model: &PhaseModel,
    cam: &PhaseShiftRenderer,
    patterns: &[Pattern],
) -> Scored {
    let clean: Vec<Vec<f64>> = patterns.iter().map(|p| cam.expected(p)).collect();
    let index: Vec<u32> = (0..patterns.len() as u32).collect();
    let ones = vec![1.0; patterns.len()];
    let (mut e2, mut c2, mut z2, mut nz, mut worst_z) = (0.0, 0.0, 0.0, 0usize, 0.0f64);
    let (mut expected, mut decoded) = (0, 0);
    let mut errors = Vec::new();
    for (q, px) in view.pixels.iter().enumerate() {
        let Ok(truth) = px.front else { continue };
        expected += 1;
        let r = &maps.pixels[q];
        if !r.s[0][0].is_finite() {
            continue;
        }
        decoded += 1;
        let y: Vec<f64> = clean.iter().map(|f| f[q]).collect();
        let start = model
            .linear_start(&index, &y, &ones, [truth.u, truth.v], 1e-4)
            .unwrap();
        let mut nuisance = model.fit(&index, &y, &ones, start, 100).params;
        nuisance.uv = [truth.u, truth.v];
        let bound = phase_shifting_cov(model, &nuisance, |mu| cam.variance(mu)).unwrap();
        let e = [r.s[0][0] - truth.u, r.s[0][1] - truth.v];
        e2 += e[0] * e[0] + e[1] * e[1];
        c2 += bound[0][0] + bound[1][1];
        for (ek, sk) in e.iter().zip(r.std[0]) {
            z2 += (ek / sk).powi(2);
            nz += 1;
            worst_z = worst_z.max((ek / sk).abs());
        }
        errors.push(([truth.u, truth.v], e));
    }
    let n = decoded.max(1) as f64;
    Scored {
        expected,
        decoded,
        rms_error: (e2 / n).sqrt(),
        rms_bound: (c2 / n).sqrt(),
        rms_z: (z2 / nz.max(1) as f64).sqrt(),
        worst_z,
        errors,
    }
}

/// The largest amplitude (screen px along the fringe direction) of the
/// error's Fourier components at the finest fringe's harmonics `m τ_f`,
/// m = 1 … 4, over both ±45° directions: where a response misfit shows.
pub fn ripple_px(station: &Station, errors: &[([f64; 2], [f64; 2])], finest_tau: f64) -> f64 {
    let n = errors.len() as f64;
    let mut worst = 0.0f64;
    for d in [45.0, -45.0] {
        let axis = FringeAxis::new(d, station.screen.width, station.screen.height);
        let (a, b) = axis.gradient();
        let norm = a.hypot(b);
        for m in 1..=4 {
            let f = m as f64 * finest_tau;
            let (mut re, mut im) = (0.0, 0.0);
            for (uv, e) in errors {
                // Error along the axis, screen px.
                let x = (a * e[0] + b * e[1]) / norm;
                let (sn, cs) = (std::f64::consts::TAU * f * axis.s(uv[0], uv[1])).sin_cos();
                re += x * cs;
                im += x * sn;
            }
            worst = worst.max(2.0 * re.hypot(im) / n);
        }
    }
    worst
}

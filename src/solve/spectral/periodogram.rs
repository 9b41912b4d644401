//! Starting values from the power spectrum: per fringe direction, the
//! windowed, zero-padded periodogram of a pixel's series over τ and its
//! strongest peak in μ ∈ (0, 1]. With the paper's geometry the two
//! reflections merge into one peak; the fit, not this, separates them.
//!
//! Three plans: an FFT on a uniform τ set; an FFT on the grid that τ sets
//! with gaps and repeats lie on (designed schedules: each frame's windowed
//! value added into its grid slot, the transform's length chosen so that
//! its frequencies are exactly the direct DFT's μ grid); the direct DFT for
//! any other τ set, and as the grid's test reference.

use std::sync::Arc;

use rustfft::num_complex::Complex;
use rustfft::{Fft, FftPlanner};

use super::model::Design;

mod aliases;
pub use aliases::{Aliases, ALIAS_SHARE, NEAR_BINS, NEAR_SHARE};

/// Zero-padding factor of the FFT (peak positions to 1/4 bin before the
/// parabolic refinement).
const PAD: usize = 4;

/// How one direction's periodogram is computed.
#[derive(Clone)]
enum Plan {
    /// τ on a uniform grid: FFT.
    Uniform {
        fft: Arc<dyn Fft<f64>>,
        n_fft: usize,
        dtau: f64,
    },
    /// τ on a grid `τ0 + kΔ` with gaps and repeats: per frame (in the
    /// direction's τ order) its slot k; an FFT of `n_fft = PAD·(K − 1)`
    /// points (K slots), whose frequency j is μ = j / (PAD · span), the
    /// direct DFT's grid, `mu_count` of them.
    Grid {
        fft: Arc<dyn Fft<f64>>,
        slot: Vec<u32>,
        mu_count: usize,
        step: f64,
        /// The grid's τ step Δ.
        dtau: f64,
    },
    /// Any other τ set: a direct DFT on a grid of μ.
    Direct { taus: Vec<f64>, mu_grid: Vec<f64> },
}

/// Largest FFT of the grid plan, in slots (2¹⁸ points: 2 MiB of complex
/// buffer); finer or longer grids take the direct DFT.
const MAX_GRID_SLOTS: usize = 1 << 16;

/// The grid `τ0 + kΔ` that every τ of `taus` (ascending, ≥ 2 distinct)
/// lies on to 1e-6 Δ: Δ the smallest gap or an integer fraction of it up to
/// 1/8; per τ its slot k. `None` when no such grid of at most
/// [`MAX_GRID_SLOTS`] slots holds them.
fn grid_slots(taus: &[f64]) -> Option<Vec<u32>> {
    let (lo, hi) = (*taus.first()?, *taus.last()?);
    let span = hi - lo;
    let gap = taus
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|&g| g > 1e-9 * span)
        .fold(f64::INFINITY, f64::min);
    if !gap.is_finite() {
        return None;
    }
    (1..=8).find_map(|j| {
        let dtau = gap / j as f64;
        let slots = (span / dtau).round();
        if slots >= MAX_GRID_SLOTS as f64 {
            return None;
        }
        let k: Vec<u32> = taus
            .iter()
            .map(|&t| ((t - lo) / dtau).round() as u32)
            .collect();
        let on_grid = taus
            .iter()
            .zip(&k)
            .all(|(&t, &k)| ((t - lo) / dtau - k as f64).abs() < 1e-6);
        on_grid.then_some(k)
    })
}

/// One direction's periodogram: the frames it takes (τ ascending), their
/// Hann window, `e^{−2πiφ}` of each frame's phase (or 1), and the plan.
#[derive(Clone)]
struct DirPlan {
    idx: Vec<u32>,
    window: Vec<f64>,
    rot: Vec<Complex<f64>>,
    plan: Plan,
    aliases: Option<Aliases>,
}

/// A direction's frames for its periodogram, and whether each must be
/// turned back by its phase. A fringe `B cos 2π(μτ + φ)` with one phase
/// throughout has its periodogram peak at μ whatever φ is; with phases
/// that vary, only the sum of `(y − ȳ) e^{−2πi(μτ + φ)}` adds up (its
/// mirror term, `e^{−2πi(μτ + 2φ)}`, spreads over μ or cancels as the
/// phases go round; with one phase it sits at −μ, outside the search).
/// So: the frames of the most common phase where they are at least half
/// of the direction's (and 8), as the plain periodogram; otherwise every
/// frame, each turned back by its phase (a phase-dithered schedule, or
/// one whose phases all differ, where one phase may hold a single frame).
fn frames_of(design: &Design, d: usize) -> (Vec<u32>, bool) {
    let all: Vec<u32> = (0..design.frames.len() as u32)
        .filter(|&i| design.frames[i as usize].dir == d)
        .collect();
    let mut phases: Vec<f64> = all
        .iter()
        .map(|&i| design.frames[i as usize].phase_cycles)
        .collect();
    phases.sort_by(f64::total_cmp);
    let mut best = (0usize, 0.0);
    let mut k = 0;
    while k < phases.len() {
        let run = phases[k..].iter().take_while(|&&p| p == phases[k]).count();
        if run > best.0 {
            best = (run, phases[k]);
        }
        k += run;
    }
    if best.0 >= 8 && 2 * best.0 >= all.len() {
        let one = all
            .into_iter()
            .filter(|&i| design.frames[i as usize].phase_cycles == best.1)
            .collect();
        (one, false)
    } else {
        (all, true)
    }
}

/// Periodogram plans for every direction of a design.
#[derive(Clone)]
pub struct SpectrumPlans {
    /// Per direction: its frames, window, phases and plan.
    dirs: Vec<DirPlan>,
    /// 1 / (τ span) per direction: one Fourier bin in μ.
    bin: Vec<f64>,
}

impl std::fmt::Debug for SpectrumPlans {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SpectrumPlans")
            .field("bin", &self.bin)
            .finish()
    }
}

impl SpectrumPlans {
    /// Plans for `design`: for each direction, the frames of its most
    /// common phase sorted by τ, or all of them turned back by their
    /// phases ([`frames_of`]).
    pub fn new(design: &Design) -> Self {
        Self::with_fft(design, true)
    }

    /// [`SpectrumPlans::new`]; with `fft` false, τ sets on a grid with gaps
    /// take the direct DFT (the grid FFT's reference).
    fn with_fft(design: &Design, fft: bool) -> Self {
        let mut planner = FftPlanner::new();
        let mut dirs = Vec::new();
        let mut bin = Vec::new();
        for d in 0..design.axes.len() {
            let (mut idx, rotate) = frames_of(design, d);
            idx.sort_by(|&a, &b| {
                design.frames[a as usize]
                    .tau
                    .total_cmp(&design.frames[b as usize].tau)
            });
            // Each sample turned back by its own phase (1 where one phase
            // is taken: the same values as without).
            let rot: Vec<Complex<f64>> = idx
                .iter()
                .map(|&i| {
                    if rotate {
                        let (s, c) = (std::f64::consts::TAU
                            * design.frames[i as usize].phase_cycles)
                            .sin_cos();
                        Complex::new(c, -s)
                    } else {
                        Complex::new(1.0, 0.0)
                    }
                })
                .collect();
            let taus: Vec<f64> = idx.iter().map(|&i| design.frames[i as usize].tau).collect();
            let n = taus.len();
            let span = (taus.last().copied().unwrap_or(1.0) - taus.first().copied().unwrap_or(0.0))
                .max(1e-9);
            bin.push(1.0 / span);
            let window: Vec<f64> = (0..n)
                .map(|k| 0.5 - 0.5 * (std::f64::consts::TAU * (k as f64 + 0.5) / n as f64).cos())
                .collect();
            let dtau = span / (n.max(2) - 1) as f64;
            let uniform = n >= 8
                && taus
                    .windows(2)
                    .all(|w| ((w[1] - w[0]) - dtau).abs() < 1e-6 * dtau);
            let step = 1.0 / (PAD as f64 * span);
            let mu_count = (1.05 / step) as usize + 1;
            let grid = (n >= 8 && !uniform && fft)
                .then(|| grid_slots(&taus))
                .flatten();
            let plan = if uniform {
                let n_fft = (PAD * n).next_power_of_two();
                Plan::Uniform {
                    fft: planner.plan_fft_forward(n_fft),
                    n_fft,
                    dtau,
                }
            } else if let Some(slot) = grid {
                let slots = slot.last().map_or(0, |&k| k as usize);
                Plan::Grid {
                    fft: planner.plan_fft_forward(PAD * slots),
                    slot,
                    mu_count,
                    step,
                    dtau: span / slots.max(1) as f64,
                }
            } else {
                let mu_grid = (0..mu_count).map(|k| k as f64 * step).collect();
                Plan::Direct { taus, mu_grid }
            };
            let phases: Vec<f64> = idx
                .iter()
                .map(|&i| design.frames[i as usize].phase_cycles)
                .collect();
            let aliases = aliases::aliases(&plan, &window, &rot, &phases, span);
            dirs.push(DirPlan {
                idx,
                window,
                rot,
                plan,
                aliases,
            });
        }
        SpectrumPlans { dirs, bin }
    }

    /// One Fourier bin in μ for direction `d`.
    pub fn bin(&self, d: usize) -> f64 {
        self.bin[d]
    }

    /// The μ that direction `d`'s periodogram cannot tell from a peak
    /// (its copies on a τ grid, [`Aliases`]); `None` for τ off any grid,
    /// whose near-repeats are weaker than the peak.
    pub fn aliases(&self, d: usize) -> Option<&Aliases> {
        self.dirs[d].aliases.as_ref()
    }

    /// Strongest peak of direction `d`'s periodogram in `μ ∈ [3 bins, 1.05]`:
    /// `(μ, peak power / median power)`. `y` is indexed by frame; excluded
    /// samples are NaN and replaced by the mean.
    pub fn peak(&self, d: usize, y: &[f64]) -> Option<(f64, f64)> {
        let (mus, power) = self.spectrum(d, y)?;
        refine_peak(&mus, &power, 3.0 * self.bin[d])
    }

    /// Direction `d`'s periodogram of `y` (indexed by frame, NaN
    /// excluded): its μ grid and power; `None` with fewer than 8 samples.
    fn spectrum(&self, d: usize, y: &[f64]) -> Option<(Vec<f64>, Vec<f64>)> {
        let DirPlan {
            idx,
            window,
            rot,
            plan,
            ..
        } = &self.dirs[d];
        let vals: Vec<f64> = idx.iter().map(|&i| y[i as usize]).collect();
        let good: Vec<f64> = vals.iter().copied().filter(|v| v.is_finite()).collect();
        if good.len() < 8 {
            return None;
        }
        let mean = good.iter().sum::<f64>() / good.len() as f64;
        let centred: Vec<Complex<f64>> = vals
            .iter()
            .zip(window)
            .zip(rot)
            .map(|((v, w), r)| {
                if v.is_finite() {
                    r * ((v - mean) * w)
                } else {
                    Complex::new(0.0, 0.0)
                }
            })
            .collect();
        let (mus, power) = match plan {
            Plan::Uniform { fft, n_fft, dtau } => {
                let mut buf = centred;
                buf.resize(*n_fft, Complex::new(0.0, 0.0));
                let mut scratch = vec![Complex::new(0.0, 0.0); fft.get_inplace_scratch_len()];
                fft.process_with_scratch(&mut buf, &mut scratch);
                let step = 1.0 / (*n_fft as f64 * dtau);
                let m = ((1.05 / step) as usize).min(n_fft / 2);
                let mus: Vec<f64> = (0..=m).map(|k| k as f64 * step).collect();
                (
                    mus,
                    buf[..=m].iter().map(|c| c.norm_sqr()).collect::<Vec<f64>>(),
                )
            }
            Plan::Grid {
                fft,
                slot,
                mu_count,
                step,
                ..
            } => {
                let n_fft = fft.len();
                let mut buf = vec![Complex::new(0.0, 0.0); n_fft];
                for (&k, &v) in slot.iter().zip(&centred) {
                    buf[k as usize] += v;
                }
                let mut scratch = vec![Complex::new(0.0, 0.0); fft.get_inplace_scratch_len()];
                fft.process_with_scratch(&mut buf, &mut scratch);
                // Frequency j is μ = j·step; past the grid's Nyquist the
                // transform repeats (period n_fft), as the DFT does.
                let mus = (0..*mu_count).map(|j| j as f64 * step).collect();
                let power = (0..*mu_count).map(|j| buf[j % n_fft].norm_sqr()).collect();
                (mus, power)
            }
            Plan::Direct { taus, mu_grid } => {
                let p = mu_grid
                    .iter()
                    .map(|&mu| {
                        let mut sum = Complex::new(0.0, 0.0);
                        for (&t, &v) in taus.iter().zip(&centred) {
                            let (s, c) = (std::f64::consts::TAU * mu * t).sin_cos();
                            sum += v * Complex::new(c, -s);
                        }
                        sum.norm_sqr()
                    })
                    .collect();
                (mu_grid.clone(), p)
            }
        };
        Some((mus, power))
    }
}

/// Largest value above `mu_min` with a parabolic refinement on log power.
pub(super) fn refine_peak(mus: &[f64], power: &[f64], mu_min: f64) -> Option<(f64, f64)> {
    let start = mus.iter().position(|&m| m >= mu_min)?;
    let (k, &pk) = power
        .iter()
        .enumerate()
        .skip(start)
        .max_by(|a, b| a.1.total_cmp(b.1))?;
    let mut sorted: Vec<f64> = power[start..].to_vec();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2].max(1e-300);
    let mut mu = mus[k];
    if k > 0 && k + 1 < power.len() {
        let (a, b, c) = (
            power[k - 1].max(1e-300).ln(),
            pk.max(1e-300).ln(),
            power[k + 1].max(1e-300).ln(),
        );
        let denom = a - 2.0 * b + c;
        if denom < 0.0 {
            mu += 0.5 * (a - c) / denom * (mus[k + 1] - mus[k]);
        }
    }
    Some((mu, pk / median))
}

#[cfg(test)]
#[path = "periodogram_tests.rs"]
mod tests;

//! A phase-shifting acquisition of a flat mirror (one reflection per
//! pixel) on a display that is not linearised ([`PhaseShiftRenderer`]),
//! and the short schedules such labs record ([`phase_shift_patterns`]).
//!
//! Per pixel seeing the mirror (the traced view's front path, Fresnel
//! weight w, fringe coordinate s), in counts before noise:
//! `I = gain · (ambient + w · L)`, `L = c_0 + Σ_n c_n M_n(τ) cos(n (2π τ s + φ))`,
//! with `c_n` the harmonics of the emitted luminance `g^γ`, `g = 0.5 + 0.5
//! cos(..)` the pattern (a DFT of the curve sampled 1024 times a period),
//! and the camera's blur as a transfer function of the spatial frequency
//! `f = n τ` (periods per screen): `M = exp(−(f/τ_max)²) · exp(−α_d f)`,
//! a Gaussian and, per direction, an exponential falloff that makes the
//! contrast fall faster than any Gaussian (defocus plus a lens's flare, as
//! real data show). Then read and shot noise (Gaussian, the Poisson
//! variance), rounding and clipping to the bit depth, seeded per frame.

use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;

use super::SimError;
use crate::acquire::patterns::{FringeAxis, Pattern};
use crate::optics::station::Screen;
use crate::optics::trace::TracedView;

/// Harmonics of `g^γ` rendered (their ratio to the first falls as
/// n^−(2γ+1): below 10⁻⁶ by n = 16 for γ ≥ 1).
const HARMONICS: usize = 16;

/// Samples of the response curve per period for its DFT.
const CURVE_SAMPLES: usize = 1024;

/// A display's emitted luminance of drive level `g ∈ [0, 1]` (1 at full
/// drive), by name (settings compare by it).
#[derive(Debug, Clone, Copy)]
pub struct Luminance {
    /// What the curve is.
    pub name: &'static str,
    /// The curve.
    pub at: fn(f64) -> f64,
}

impl PartialEq for Luminance {
    fn eq(&self, other: &Self) -> bool {
        self.name == other.name
    }
}

/// The simulated acquisition's settings.
#[derive(Debug, Clone, PartialEq)]
pub struct PhaseShiftParams {
    /// Display gamma: emitted luminance ∝ g^γ.
    pub gamma: f64,
    /// A display response that is no power law, used in place of `g^γ`.
    pub luminance: Option<Luminance>,
    /// Gaussian part of the camera blur: a fringe of τ_max periods per
    /// screen keeps 1/e of its contrast.
    pub tau_max: f64,
    /// Exponential part per direction, `(direction_deg, α)`: contrast
    /// `exp(−α f)` at f periods per screen; directions not listed have none.
    pub falloff_per_period: Vec<(f64, f64)>,
    /// Ambient light, in units of full-white screen radiance.
    pub ambient: f64,
    /// Bits per sample (8, 12 or 16).
    pub bit_depth: u32,
    /// Read noise, counts (standard deviation).
    pub read_noise_counts: f64,
    /// Full-well capacity at full scale, electrons (shot noise); `None`: none.
    pub full_well_electrons: Option<f64>,
    /// Seed of the noise.
    pub seed: u64,
}

impl Default for PhaseShiftParams {
    /// An 8-bit camera (read noise 0.5 counts, 20 000 e⁻ full well) on a
    /// gamma-2 display, 5 % ambient, blur keeping 80 % of the contrast at
    /// 64 periods along 45° and 50 % along −45°.
    fn default() -> Self {
        PhaseShiftParams {
            gamma: 2.0,
            luminance: None,
            tau_max: 200.0,
            falloff_per_period: vec![(45.0, 0.002), (-45.0, 0.009)],
            ambient: 0.05,
            bit_depth: 8,
            read_noise_counts: 0.5,
            full_well_electrons: Some(20_000.0),
            seed: 1,
        }
    }
}

/// The schedule of `directions_deg` × `taus` × `steps` equal phase steps
/// (0, 2π/steps, …), in that nesting order.
pub fn phase_shift_patterns(directions_deg: &[f64], taus: &[f64], steps: usize) -> Vec<Pattern> {
    let mut out = Vec::with_capacity(directions_deg.len() * taus.len() * steps);
    for &direction_deg in directions_deg {
        for &tau in taus {
            for k in 0..steps {
                out.push(Pattern {
                    direction_deg,
                    tau,
                    phase_rad: std::f64::consts::TAU * k as f64 / steps as f64,
                });
            }
        }
    }
    out
}

/// Renders a phase-shifting acquisition of a mirror.
#[derive(Debug)]
pub struct PhaseShiftRenderer {
    params: PhaseShiftParams,
    width: usize,
    height: usize,
    screen: [u32; 2],
    gain: f64,
    /// Lit pixels: index, (u, v), Fresnel weight.
    lit: Vec<(u32, [f64; 2], f64)>,
    /// `c_0 … c_HARMONICS` of `g^γ`.
    coeffs: Vec<f64>,
}

impl PhaseShiftRenderer {
    /// The renderer of `view`'s front reflections on `screen`; the gain puts
    /// the brightest pixel at 90 % of full scale.
    ///
    /// # Errors
    /// [`SimError::Invalid`] for out-of-range settings or a view with no
    /// pixel on the mirror.
    pub fn new(
        view: &TracedView,
        screen: &Screen,
        params: PhaseShiftParams,
    ) -> Result<Self, SimError> {
        let bad = |field, problem: String| Err(SimError::Invalid { field, problem });
        if !(params.gamma.is_finite() && params.gamma > 0.0) {
            return bad(
                "display-gamma",
                format!("expected > 0, found {}", params.gamma),
            );
        }
        if ![8, 12, 16].contains(&params.bit_depth) {
            return bad(
                "bit-depth",
                format!("expected 8, 12 or 16, found {}", params.bit_depth),
            );
        }
        if !(params.read_noise_counts >= 0.0 && params.ambient >= 0.0 && params.tau_max > 0.0) {
            return bad(
                "noise",
                "read noise and ambient must be ≥ 0 and tau-max > 0".into(),
            );
        }
        let lit: Vec<(u32, [f64; 2], f64)> = view
            .pixels
            .iter()
            .enumerate()
            .filter_map(|(i, p)| p.front.ok().map(|h| (i as u32, [h.u, h.v], h.weight)))
            .collect();
        let brightest = lit.iter().map(|l| l.2).fold(0.0, f64::max) + params.ambient;
        if lit.is_empty() || brightest <= 0.0 {
            return bad("station", "no camera pixel sees the mirror".into());
        }
        let fs = f64::from((1u32 << params.bit_depth) - 1);
        let coeffs = match params.luminance {
            Some(l) => harmonics_of(l.at),
            None => curve_harmonics(params.gamma),
        };
        Ok(PhaseShiftRenderer {
            gain: 0.9 * fs / brightest,
            width: view.width,
            height: view.height,
            screen: [screen.width, screen.height],
            lit,
            coeffs,
            params,
        })
    }

    /// Counts per unit radiance.
    pub fn gain(&self) -> f64 {
        self.gain
    }

    /// Largest count.
    pub fn full_scale(&self) -> f64 {
        f64::from((1u32 << self.params.bit_depth) - 1)
    }

    /// The variance of a sample of mean `counts` (read, shot and the
    /// rounding's 1/12), counts².
    pub fn variance(&self, counts: f64) -> f64 {
        self.drawn_variance(counts) + 1.0 / 12.0
    }

    /// The variance of the noise drawn (read and shot; the rounding adds
    /// its own), counts².
    fn drawn_variance(&self, counts: f64) -> f64 {
        let shot = self
            .params
            .full_well_electrons
            .map_or(0.0, |fw| counts.max(0.0) * self.full_scale() / fw);
        self.params.read_noise_counts.powi(2) + shot
    }

    /// Noise-free counts of every pixel for `pattern` (dark pixels: ambient).
    pub fn expected(&self, pattern: &Pattern) -> Vec<f64> {
        let axis = FringeAxis::new(pattern.direction_deg, self.screen[0], self.screen[1]);
        let alpha = self
            .params
            .falloff_per_period
            .iter()
            .find(|(d, _)| *d == pattern.direction_deg)
            .map_or(0.0, |(_, a)| *a);
        let mtf: Vec<f64> = (1..self.coeffs.len())
            .map(|n| {
                let f = n as f64 * pattern.tau;
                self.coeffs[n] * (-(f / self.params.tau_max).powi(2) - alpha * f).exp()
            })
            .collect();
        let mut out = vec![self.gain * self.params.ambient; self.width * self.height];
        for &(idx, [u, v], w) in &self.lit {
            let x = std::f64::consts::TAU * pattern.tau * axis.s(u, v) + pattern.phase_rad;
            let l: f64 = self.coeffs[0]
                + mtf
                    .iter()
                    .enumerate()
                    .map(|(k, m)| m * ((k + 1) as f64 * x).cos())
                    .sum::<f64>();
            out[idx as usize] = self.gain * (self.params.ambient + w * l);
        }
        out
    }

    /// Renders frame `index` of `pattern` into `out` (row-major counts).
    pub fn render(&self, pattern: &Pattern, index: u64, out: &mut [u16]) {
        let fs = self.full_scale();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(
            self.params.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ index,
        );
        for (o, x) in out.iter_mut().zip(self.expected(pattern)) {
            let z: f64 = StandardNormal.sample(&mut rng);
            let v = x + self.drawn_variance(x).sqrt() * z;
            *o = (v.clamp(0.0, fs) + 0.5) as u16;
        }
    }
}

/// `c_0 … c_HARMONICS` of `(0.5 + 0.5 cos x)^γ = c_0 + Σ c_n cos(n x)`.
fn curve_harmonics(gamma: f64) -> Vec<f64> {
    harmonics_of(|g| g.powf(gamma))
}

/// `c_0 … c_HARMONICS` of `L(0.5 + 0.5 cos x) = c_0 + Σ c_n cos(n x)`.
fn harmonics_of(lum: impl Fn(f64) -> f64) -> Vec<f64> {
    let m = CURVE_SAMPLES;
    let curve: Vec<f64> = (0..m)
        .map(|j| lum(0.5 + 0.5 * (std::f64::consts::TAU * j as f64 / m as f64).cos()))
        .collect();
    (0..=HARMONICS)
        .map(|n| {
            let s: f64 = curve
                .iter()
                .enumerate()
                .map(|(j, g)| g * (std::f64::consts::TAU * (n * j % m) as f64 / m as f64).cos())
                .sum();
            if n == 0 {
                s / m as f64
            } else {
                2.0 * s / m as f64
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::curve_harmonics;

    /// The harmonics rebuild the curve (γ = 2.2, any x), and γ = 2 has the
    /// closed form 3/8, 1/2, 1/8.
    #[test]
    fn harmonics_rebuild_the_response_curve() {
        let c = curve_harmonics(2.0);
        assert!((c[0] - 0.375).abs() < 1e-12 && (c[1] - 0.5).abs() < 1e-12);
        assert!((c[2] - 0.125).abs() < 1e-12 && c[3].abs() < 1e-12);
        let c = curve_harmonics(2.2);
        for x in [0.0, 0.3, 1.7, 3.0] {
            let direct = (0.5 + 0.5 * f64::cos(x)).powf(2.2);
            let series: f64 = c
                .iter()
                .enumerate()
                .map(|(n, cn)| cn * (n as f64 * x).cos())
                .sum();
            // Truncation at 16 harmonics: the tail ~ Σ n^−5.4 beyond 16.
            assert!((direct - series).abs() < 1e-5, "{x}: {direct} vs {series}");
        }
    }
}

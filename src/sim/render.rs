//! The renderer ([`Renderer`]): what the station's camera records for any
//! displayed pattern, from geometry traced once. The Camera-trait simulated
//! camera (`sim::camera`) and the fake GigE camera's feed render with it.
//!
//! Per pixel, in camera counts before noise (paper Eq. 5, 7 with the spec's
//! fringe):
//! `I = gain · (ambient + Σ_k w_k (0.5 + 0.5 e(τ) cos(2π τ s_k + φ)))`,
//! `e(τ) = exp(−(τ/τ_max)²)`, `w_k` the Fresnel weight of path k and `s_k`
//! the fringe coordinate of its screen point. Then Gaussian read noise,
//! optional shot noise (Gaussian with the Poisson variance), rounding and
//! clipping to the bit depth. Noise is seeded per frame, so a frame is the
//! same whatever order frames are rendered in.

use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;

use super::SimError;
use crate::acquire::patterns::{FringeAxis, Pattern};
use crate::kernels::cos_cycles;
use crate::optics::station::Screen;
use crate::optics::trace::TracedView;

/// Simulated camera settings.
#[derive(Debug, Clone, PartialEq)]
pub struct SimParams {
    /// Ambient light in units of full-white screen radiance (the same units
    /// as Fresnel weights).
    pub ambient: f64,
    /// Modulation falloff τ_max of `e(τ) = exp(−(τ/τ_max)²)`; infinity for none.
    pub tau_max: f64,
    /// Bits per sample: 8, 12 or 16 (stored as u8 for 8, u16 otherwise).
    pub bit_depth: u32,
    /// Counts per unit radiance; `None` puts the brightest possible pixel at
    /// 90 % of full scale.
    pub gain: Option<f64>,
    /// Read noise standard deviation as a fraction of full scale.
    pub noise_frac: f64,
    /// Full-well capacity in electrons at full scale, for shot noise; `None`
    /// for no shot noise.
    pub full_well_electrons: Option<f64>,
    /// Whether the path with two internal round trips (S3) is rendered.
    pub third_reflection: bool,
    /// Factors on the Fresnel weights of the front, back and third paths:
    /// `[1, 0, 0]` models an AR-coated back, `[1, 1, 1]` bare glass.
    pub path_scale: [f64; 3],
    /// Seed of the noise.
    pub seed: u64,
    /// What the falloff acts on.
    pub falloff: Falloff,
}

/// What the modulation falloff acts on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Falloff {
    /// `e(τ)` on every direction (paper Eq. 7; the fixtures' forward
    /// model's convention; the model fits a κ per fringe length, so it
    /// takes this and [`Falloff::ScreenPeriod`] alike).
    #[default]
    Tau,
    /// The fringe's period on the screen: `e(ℓτ)` with `ℓ = L₄₅ / L_d`
    /// (1 on the diagonals, whose τ_max it is; a plain direction's fringes
    /// are finer at equal τ), as a blur of the screen or the camera acts.
    ScreenPeriod,
}

impl Default for SimParams {
    fn default() -> Self {
        SimParams {
            ambient: 0.01,
            tau_max: 150.0,
            bit_depth: 16,
            gain: None,
            noise_frac: 0.0,
            full_well_electrons: None,
            third_reflection: false,
            path_scale: [1.0; 3],
            seed: 1,
            falloff: Falloff::Tau,
        }
    }
}

impl SimParams {
    /// Checks ranges.
    ///
    /// # Errors
    /// [`SimError::Invalid`] naming the parameter.
    pub fn validate(&self) -> Result<(), SimError> {
        let bad = |field, problem: String| Err(SimError::Invalid { field, problem });
        if ![8, 12, 16].contains(&self.bit_depth) {
            return bad(
                "bit-depth",
                format!("expected 8, 12 or 16, found {}", self.bit_depth),
            );
        }
        if !(self.ambient.is_finite() && self.ambient >= 0.0) {
            return bad("ambient", format!("expected ≥ 0, found {}", self.ambient));
        }
        if self.tau_max.is_nan() || self.tau_max <= 0.0 {
            return bad("tau-max", format!("expected > 0, found {}", self.tau_max));
        }
        if !(self.noise_frac.is_finite() && (0.0..1.0).contains(&self.noise_frac)) {
            return bad(
                "noise",
                format!("expected a fraction in [0, 1), found {}", self.noise_frac),
            );
        }
        if let Some(g) = self.gain.filter(|g| !(g.is_finite() && *g > 0.0)) {
            return bad("gain", format!("expected > 0, found {g}"));
        }
        if let Some(f) = self
            .full_well_electrons
            .filter(|f| !(f.is_finite() && *f > 0.0))
        {
            return bad("full-well", format!("expected > 0 electrons, found {f}"));
        }
        Ok(())
    }

    /// Largest count, `2^bits − 1`.
    pub fn full_scale(&self) -> f64 {
        f64::from((1u32 << self.bit_depth) - 1)
    }
}

/// Fringe coordinates of every lit pixel's paths for one direction.
#[derive(Debug)]
struct DirectionCache {
    direction_deg: f64,
    /// `s[k][q]`: fringe coordinate of path k at lit pixel q.
    s: Vec<Vec<f64>>,
}

/// Renders frames of one station and scene.
#[derive(Debug)]
pub struct Renderer {
    params: SimParams,
    width: usize,
    height: usize,
    gain: f64,
    screen_w: u32,
    screen_h: u32,
    /// Indices of pixels that see at least one path.
    lit: Vec<u32>,
    /// `(u, v)` of path k at lit pixel q (NaN-free: absent paths have amp 0 and u = v = 0).
    uv: Vec<Vec<(f64, f64)>>,
    /// `gain · w_k / 2` per path and lit pixel.
    amp: Vec<Vec<f64>>,
    /// Mean level per lit pixel, counts: `gain (ambient + Σ w_k / 2)`.
    base_lit: Vec<f64>,
    /// Level of pixels that see no path, counts: `gain · ambient`.
    dark: f64,
    cache: Option<DirectionCache>,
    /// `Σ_k amp_k cos(2π τ s_k + φ)` per lit pixel for the current pattern.
    modulation: Vec<f64>,
    signal: Vec<f64>,
    normals: Vec<f64>,
}

impl Renderer {
    /// Prepares the renderer from a traced view.
    ///
    /// # Errors
    /// [`SimError::Invalid`] for out-of-range parameters.
    pub fn new(view: &TracedView, screen: &Screen, params: SimParams) -> Result<Self, SimError> {
        params.validate()?;
        let n_paths = if params.third_reflection { 3 } else { 2 };
        let mut lit = Vec::new();
        let mut uv = vec![Vec::new(); n_paths];
        let mut weights = vec![Vec::new(); n_paths];
        let mut brightest = params.ambient;
        for (idx, p) in view.pixels.iter().enumerate() {
            let paths = [p.front, p.back, p.third];
            if paths[..n_paths].iter().all(|o| o.is_err()) {
                continue;
            }
            lit.push(idx as u32);
            let mut total = params.ambient;
            for k in 0..n_paths {
                let (u, v, w) = paths[k].map_or((0.0, 0.0, 0.0), |h| {
                    (h.u, h.v, h.weight * params.path_scale[k])
                });
                uv[k].push((u, v));
                weights[k].push(w);
                total += w;
            }
            brightest = brightest.max(total);
        }
        let gain = params.gain.unwrap_or(0.9 * params.full_scale() / brightest);
        let dark = gain * params.ambient;
        let base_lit = (0..lit.len())
            .map(|q| {
                dark + (0..n_paths)
                    .map(|k| 0.5 * gain * weights[k][q])
                    .sum::<f64>()
            })
            .collect();
        let amp = weights
            .into_iter()
            .map(|w| w.into_iter().map(|w| 0.5 * gain * w).collect())
            .collect();
        Ok(Renderer {
            modulation: vec![0.0; lit.len()],
            params,
            width: view.width,
            height: view.height,
            gain,
            screen_w: screen.width,
            screen_h: screen.height,
            lit,
            uv,
            amp,
            base_lit,
            dark,
            cache: None,
            signal: Vec::new(),
            normals: vec![0.0; view.width * view.height],
        })
    }

    /// Counts per unit radiance in use.
    pub fn gain(&self) -> f64 {
        self.gain
    }

    /// The settings.
    pub fn params(&self) -> &SimParams {
        &self.params
    }

    /// `(width, height)` of a frame.
    pub fn resolution(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Number of pixels that see the element.
    pub fn lit_pixels(&self) -> usize {
        self.lit.len()
    }

    fn direction(&mut self, direction_deg: f64) -> &DirectionCache {
        let stale = self
            .cache
            .as_ref()
            .is_none_or(|c| c.direction_deg != direction_deg);
        if stale {
            let axis = FringeAxis::new(direction_deg, self.screen_w, self.screen_h);
            let s = self
                .uv
                .iter()
                .map(|uv| uv.iter().map(|&(u, v)| axis.s(u, v)).collect())
                .collect();
            self.cache = Some(DirectionCache { direction_deg, s });
        }
        self.cache.as_ref().expect("cache filled above")
    }

    /// Fills `modulation` for `pattern`; returns the falloff `e(τ)`.
    fn modulate(&mut self, pattern: &Pattern) -> f64 {
        let stretch = match self.params.falloff {
            Falloff::Tau => 1.0,
            Falloff::ScreenPeriod => {
                FringeAxis::new(pattern.direction_deg, self.screen_w, self.screen_h)
                    .stretch_from_diagonal(self.screen_w, self.screen_h)
            }
        };
        let e = (-(stretch * pattern.tau / self.params.tau_max).powi(2)).exp();
        let phase_cycles = pattern.phase_rad / std::f64::consts::TAU;
        let tau = pattern.tau;
        self.direction(pattern.direction_deg);
        let cache = self.cache.as_ref().expect("direction cached");
        // Path by path over contiguous arrays: the loops vectorise.
        for (k, (amp, s)) in self.amp.iter().zip(&cache.s).enumerate() {
            let terms = self.modulation.iter_mut().zip(amp).zip(s);
            if k == 0 {
                terms.for_each(|((m, &a), &s)| *m = a * cos_cycles(tau * s + phase_cycles));
            } else {
                terms.for_each(|((m, &a), &s)| *m += a * cos_cycles(tau * s + phase_cycles));
            }
        }
        e
    }

    /// Noise-free expected counts (before rounding and clipping) of every
    /// pixel for `pattern`.
    pub fn expected(&mut self, pattern: &Pattern) -> &[f64] {
        let e = self.modulate(pattern);
        self.signal.clear();
        self.signal.resize(self.width * self.height, self.dark);
        for ((&idx, &m), &b) in self.lit.iter().zip(&self.modulation).zip(&self.base_lit) {
            self.signal[idx as usize] = b + e * m;
        }
        &self.signal
    }

    /// Renders one frame of `pattern` into `out` (row-major, `width·height`
    /// counts); `frame_index` seeds its noise.
    pub fn render(&mut self, pattern: &Pattern, frame_index: u64, out: &mut [u16]) {
        let fs = self.params.full_scale();
        let read_var = (self.params.noise_frac * fs).powi(2);
        // Shot noise: variance in counts = counts × (counts per electron).
        let shot = self.params.full_well_electrons.map_or(0.0, |fw| fs / fw);
        let e = self.modulate(pattern);
        let lit = self.lit.iter().zip(&self.modulation).zip(&self.base_lit);
        if read_var == 0.0 && shot == 0.0 {
            out.fill(quantise(self.dark, fs));
            for ((&idx, &m), &b) in lit {
                out[idx as usize] = quantise(b + e * m, fs);
            }
            return;
        }
        // Draw the normals first (a sequential RNG), so that the passes
        // below are branch-free and vectorise.
        let mut rng =
            Xoshiro256PlusPlus::seed_from_u64(splitmix(self.params.seed ^ splitmix(frame_index)));
        self.normals.resize(self.width * self.height, 0.0);
        for z in &mut self.normals {
            *z = StandardNormal.sample(&mut rng);
        }
        let sigma_dark = (read_var + shot * self.dark).sqrt();
        for (o, &z) in out.iter_mut().zip(&self.normals) {
            *o = quantise(self.dark + sigma_dark * z, fs);
        }
        for ((&idx, &m), &b) in lit {
            let x = b + e * m;
            let sigma = (read_var + shot * x.max(0.0)).sqrt();
            out[idx as usize] = quantise(x + sigma * self.normals[idx as usize], fs);
        }
    }
}

/// Rounds to the nearest count and clips to `[0, full_scale]`.
#[inline(always)]
fn quantise(v: f64, full_scale: f64) -> u16 {
    // After the clamp v + 0.5 ≥ 0.5, so truncation is round-half-up.
    (v.clamp(0.0, full_scale) + 0.5) as u16
}

/// SplitMix64 finaliser: decorrelates neighbouring seeds.
fn splitmix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

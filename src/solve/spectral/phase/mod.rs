//! One-reflection decoding of short phase-shifting schedules: a few fringe
//! periods τ per direction, each shown at several phase steps (e.g. τ = 1,
//! 4, 16, 64 × four steps of π/2 × two directions, 32 frames), on a display
//! whose response is not linearised.
//!
//! # When this path is taken
//! [`PhaseSchedule::detect`]: every direction of the schedule shows at most
//! [`MAX_TAUS`] distinct τ, and every τ at [`MIN_PHASES`] or more distinct
//! phases (modulo 2π; repeats allowed). The long multi-frequency schedules
//! the spectral stage was built for (hundreds of τ at one or two phases)
//! never qualify, so their results are those of the periodogram and joint
//! fit path, bit for bit. On this path the series engine is always used (a
//! few frames per pixel), one reflection is fitted (a mirror, the
//! reference flat, an AR-coated back), and the fit backend seam is not
//! used: the fits run on the CPU cores.
//!
//! # Per pixel
//! 1. Per (direction, τ) group, the least-squares cosine over its phases
//!    (all of them, whatever their values) gives the wrapped phase of τ·s
//!    and an amplitude ([`unwrap`]).
//! 2. Temporal phase unwrapping, hierarchical: every screen position the
//!    lowest τ's phase allows (one for τ = 1, ⌈τ⌉ otherwise) is carried up
//!    through the higher τ (each rounding to the fringe order its phase
//!    needs) and scored by the phase residuals of all τ; the best is kept.
//!    The runner-up's score says whether the schedule can tell them apart
//!    (periods with a common divisor cannot): a runner-up within
//!    [`AMBIGUITY_CHI2`] is reported [`UNRESOLVED`](super::PixelFlags::UNRESOLVED). No
//!    station prior is used.
//! 3. A joint least-squares fit of all frames ([`model`]): the screen point
//!    (u, v), a background per direction, an amplitude per (direction, τ)
//!    (the contrast may fall faster than any Gaussian envelope), and the
//!    display's response: emitted luminance `g^γ`, `g = 0.5 + 0.5 cos(..)`
//!    the pattern, expanded in harmonics whose camera blur is, within each
//!    (direction, τ) group, the Gaussian `exp(−κ_g (n² − 1) τ²)` relative to
//!    the first ([`Response`]; κ_g fitted where γ ≠ 1, with a weak prior
//!    `κ_g τ² ~ N(0, 3²)` that only matters where a harmonic is too weak
//!    to show its falloff). Without the response model the harmonics that
//!    the phase steps alias onto the first one (harmonic 3 onto 1 for four
//!    steps, 2 onto 1 for three) bias the phase by a ripple locked to each
//!    fringe; with γ exactly 2 and four equal steps there is no harmonic 3
//!    and the ripple vanishes either way.
//! 4. Noise: a first unweighted pass over every pixel gives the camera's
//!    noise law `var = a + b·μ` (read + quantisation, shot noise), regressed
//!    from the squared residuals of the pixels that show a fringe on their
//!    exact expectations `Σ_j (I − H)_ij² (a + b μ_j)` (H the fit's hat
//!    matrix; with 20 parameters in 32 samples the leverages are ~0.6); the
//!    second pass fits each pixel weighted by it, and the covariance of
//!    (u, v) is `(JᵀWJ)⁻¹`: the Cramér–Rao bound of this model at that
//!    noise (`bound::phase_shifting_cov` evaluates it at any parameters).
//!    Unmodelled structure (a wrong γ) is read as noise: the σ then errs
//!    large, not small. Detection uses all phases: per direction, the
//!    amplitudes' joint significance `Σ B²/σ_B²` must reach
//!    [`DETECTION_CHI2`].

pub mod curve;
pub mod model;
mod solve;
pub mod unwrap;

pub use curve::{profile_response, CurveError, ProfileResponseError, ResponseCurve};
pub use model::{PhaseFit, PhaseModel, PhaseParams};
pub use solve::NoiseLaw;
pub(super) use solve::{solve_all, PhaseSettings};

use super::model::Design;
use super::SpectralError;

/// Fewest distinct phases per τ for the phase-shifting path (a cosine's
/// offset, amplitude and phase need three samples).
pub const MIN_PHASES: usize = 3;

/// Most distinct τ per direction for the phase-shifting path.
pub const MAX_TAUS: usize = 16;

/// Per direction, the amplitudes' `Σ_τ B_τ²/σ²(B_τ)` below which the pixel
/// has no fringe signal. For noise alone it is χ² with (number of τ)
/// degrees of freedom: with four τ, P(χ²₄ > 49) ≈ 6·10⁻¹⁰, so no pixel of a
/// full sensor passes on noise.
pub const DETECTION_CHI2: f64 = 49.0;

/// Runner-up unwrapping within this χ² of the best (phase residuals at the
/// fitted noise) is an ambiguity of the schedule: 25 is a 5σ separation.
pub const AMBIGUITY_CHI2: f64 = 25.0;

/// Phases closer than this (cycles) count as one.
const PHASE_EQUAL_CYCLES: f64 = 1e-6;

/// One (direction, τ) group of frames.
#[derive(Debug, Clone, PartialEq)]
pub struct Group {
    /// Index of the direction in the design's axes.
    pub dir: usize,
    /// Fringe periods across the screen.
    pub tau: f64,
    /// Its frames, capture order.
    pub frames: Vec<u32>,
}

/// A phase-shifting schedule: the frames grouped by direction and τ.
#[derive(Debug, Clone, PartialEq)]
pub struct PhaseSchedule {
    /// The groups, by direction then τ ascending.
    pub groups: Vec<Group>,
    /// The group of every frame.
    pub group_of_frame: Vec<u32>,
    /// Number of directions.
    pub directions: usize,
}

impl PhaseSchedule {
    /// The schedule's groups when it is a phase-shifting one (the rule of
    /// the [module documentation](self)), else `None`.
    pub fn detect(design: &Design) -> Option<Self> {
        let mut groups: Vec<Group> = Vec::new();
        for (i, f) in design.frames.iter().enumerate() {
            match groups.iter_mut().find(|g| g.dir == f.dir && g.tau == f.tau) {
                Some(g) => g.frames.push(i as u32),
                None => groups.push(Group {
                    dir: f.dir,
                    tau: f.tau,
                    frames: vec![i as u32],
                }),
            }
        }
        for d in 0..design.axes.len() {
            if groups.iter().filter(|g| g.dir == d).count() > MAX_TAUS {
                return None;
            }
        }
        if groups
            .iter()
            .any(|g| distinct_phases(design, &g.frames) < MIN_PHASES)
        {
            return None;
        }
        groups.sort_by(|a, b| a.dir.cmp(&b.dir).then(a.tau.total_cmp(&b.tau)));
        let mut group_of_frame = vec![0; design.frames.len()];
        for (k, g) in groups.iter().enumerate() {
            for &i in &g.frames {
                group_of_frame[i as usize] = k as u32;
            }
        }
        Some(PhaseSchedule {
            groups,
            group_of_frame,
            directions: design.axes.len(),
        })
    }

    /// The groups of direction `d`, τ ascending (indices into `groups`).
    pub fn of_direction(&self, d: usize) -> impl Iterator<Item = usize> + '_ {
        (0..self.groups.len()).filter(move |&k| self.groups[k].dir == d)
    }
}

/// Distinct phases (modulo one cycle) among `frames`.
pub(crate) fn distinct_phases(design: &Design, frames: &[u32]) -> usize {
    let mut seen: Vec<f64> = Vec::new();
    for &i in frames {
        let p = design.frames[i as usize].phase_cycles.rem_euclid(1.0);
        let same = |q: &f64| {
            let d = (p - q).rem_euclid(1.0);
            d.min(1.0 - d) < PHASE_EQUAL_CYCLES
        };
        if !seen.iter().any(same) {
            seen.push(p);
        }
    }
    seen.len()
}

/// Samples of the response's curve per period for its harmonics (the
/// trapezoid rule on a periodic function: exact for the harmonics below
/// half of it; `g^γ` with γ not an integer has a kink of order 2γ at g = 0,
/// so the error falls as `M^−(2γ+1)`, ~10⁻¹³ at γ = 2).
const RESPONSE_SAMPLES: usize = 4096;

/// Harmonics kept: up to this many, to the last whose `c_n / c_1` exceeds
/// [`HARMONIC_FLOOR`].
const MAX_HARMONICS: usize = 12;

/// Smallest harmonic ratio kept (far below 8-bit quantisation, 1/255).
const HARMONIC_FLOOR: f64 = 1e-7;

/// The display's response, emitted luminance `L(g)` of the pattern's
/// `g = 0.5 + 0.5 cos x` (`g^γ`, or a measured curve), as harmonics:
/// `L(g) = c_0 + Σ_n c_n cos(n x)`.
#[derive(Debug, Clone, PartialEq)]
pub struct Response {
    /// γ where the response is a power law; `None` for a measured curve.
    pub gamma: Option<f64>,
    /// `c_n / c_1` for n = 1, 2, …: the first is 1.
    pub ratios: Vec<f64>,
}

impl Response {
    /// A display of gamma `gamma` (1: linear).
    ///
    /// # Errors
    /// [`SpectralError::Config`] (`display_gamma`) unless γ is finite and > 0.
    pub fn new(gamma: f64) -> Result<Self, SpectralError> {
        if !(gamma.is_finite() && gamma > 0.0) {
            return Err(SpectralError::Config {
                field: "display_gamma",
                problem: format!(
                    "expected a display gamma > 0 (the display profile's `gamma`), found {gamma}"
                ),
            });
        }
        Ok(Response {
            gamma: Some(gamma),
            ratios: harmonic_ratios(|g| g.max(0.0).powf(gamma)),
        })
    }

    /// A display of measured response `curve` (its interpolant sampled
    /// [`RESPONSE_SAMPLES`] times a period).
    pub fn from_curve(curve: &ResponseCurve) -> Self {
        Response {
            gamma: None,
            ratios: harmonic_ratios(|g| curve.at(g)),
        }
    }

    /// The response a configuration states: its measured curve where it
    /// has one, else its gamma (1: linearised).
    ///
    /// # Errors
    /// As [`Response::new`].
    pub fn of(gamma: Option<f64>, curve: Option<&ResponseCurve>) -> Result<Self, SpectralError> {
        match curve {
            Some(c) => Ok(Response::from_curve(c)),
            None => Response::new(gamma.unwrap_or(1.0)),
        }
    }

    /// Harmonics modelled (1: a pure cosine).
    pub fn harmonics(&self) -> usize {
        self.ratios.len()
    }
}

/// `c_n / c_1` of `L(0.5 + 0.5 cos x) = c_0 + Σ c_n cos(n x)`, n = 1 … up to
/// [`MAX_HARMONICS`] while above [`HARMONIC_FLOOR`] (a DFT of the curve
/// sampled [`RESPONSE_SAMPLES`] times a period).
fn harmonic_ratios(lum: impl Fn(f64) -> f64) -> Vec<f64> {
    let m = RESPONSE_SAMPLES;
    let curve: Vec<f64> = (0..m)
        .map(|j| {
            let x = std::f64::consts::TAU * j as f64 / m as f64;
            lum(0.5 + 0.5 * x.cos())
        })
        .collect();
    let coeff = |n: usize| {
        let sum: f64 = curve
            .iter()
            .enumerate()
            .map(|(j, g)| g * (std::f64::consts::TAU * (n * j) as f64 / m as f64).cos())
            .sum();
        2.0 * sum / m as f64
    };
    let c1 = coeff(1);
    let mut ratios: Vec<f64> = (1..=MAX_HARMONICS).map(|n| coeff(n) / c1).collect();
    // Up to the last harmonic above the floor: a measured curve's ratios
    // may pass through zero and rise again (a power law's fall steadily,
    // and γ = 2's vanish from n = 3 on).
    let keep = ratios
        .iter()
        .rposition(|r| r.abs() >= HARMONIC_FLOOR)
        .map_or(1, |k| k + 1);
    ratios.truncate(keep);
    ratios
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `(0.5 + 0.5 cos x)² = 3/8 + ½ cos x + ⅛ cos 2x` (closed form): the
    /// ratio of harmonic 2 is ¼ and there is no harmonic 3; a linear
    /// display has one harmonic.
    #[test]
    fn response_harmonics_match_the_closed_forms() {
        let r2 = Response::new(2.0).unwrap();
        assert_eq!(r2.harmonics(), 2);
        assert!((r2.ratios[1] - 0.25).abs() < 1e-12, "{:?}", r2.ratios);
        assert_eq!(Response::new(1.0).unwrap().harmonics(), 1);
        // γ = 3: (1 + cos)³/8 = 5/16 + 15/32 cos x + 3/16 cos 2x + 1/32 cos 3x.
        let r3 = Response::new(3.0).unwrap();
        assert!((r3.ratios[1] - 0.4).abs() < 1e-12);
        assert!((r3.ratios[2] - 1.0 / 15.0).abs() < 1e-12);
        assert!(Response::new(0.0).is_err() && Response::new(f64::NAN).is_err());
    }
}

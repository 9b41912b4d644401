//! The spectral solver: for every camera pixel, the screen points S1 (front
//! reflection) and S2 (back reflection) from the pixel's intensity over the
//! pattern schedule, with their uncertainty and quality maps.
//!
//! Per pixel ([`pixel`]): periodogram peaks per direction give the merged
//! centre; the station's geometry (a flat plate traced through the nominal
//! station) gives the expected back-minus-front offset, which seeds the two
//! screen points and later names them; Levenberg–Marquardt fits the joint
//! model of all directions ([`model`]) with one, two and optionally three
//! reflections; the Bayesian information criterion
//! `BIC = N ln(RSS/N) + p ln N` picks the model. Uncertainties are
//! `σ̂² (JᵀJ)⁻¹` with `σ̂² = RSS/(N − p)`: the Cramér–Rao bound of the fitted
//! model at the noise level the residuals show.
//!
//! The parts, in the order the data flow through them: `config`
//! (settings and errors), `prior` (the flat plate traced through the
//! nominal station: which pixels to fit, where their points should be),
//! `stream` (frames in, kept as series or reduced to [`statistics`]),
//! `batch` (the per-pixel fits and the backend seam they run behind),
//! [`periodogram`] and [`pixel`] (one pixel's starting values and fits over
//! the joint [`model`]), `scene` (the scene's number of reflections and
//! every pixel's answer under it) and `maps` (the results and their
//! files). [`bound`] is the Cramér–Rao bound of the schedule.
//!
//! Short phase-shifting schedules (a few τ, each at three or more phase
//! steps; the rule is [`phase::PhaseSchedule::detect`]'s) take another path
//! for one reflection: temporal phase unwrapping, a joint fit with an
//! amplitude per τ and the display's response, and the camera's noise law
//! pooled over the pixels ([`phase`]).

mod batch;
pub mod bound;
mod config;
mod feed;
mod maps;
pub mod model;
pub mod periodogram;
pub mod phase;
pub mod pixel;
mod prior;
mod scene;
pub mod statistics;
mod stream;
pub mod wedge;

pub use batch::{CpuFits, FitBackend, FitBatch};
pub use config::{Engine, SpectralConfig, SpectralError, SERIES_LIMIT_BYTES};
pub use feed::FeedError;
pub use maps::SpectralMaps;
pub(crate) use prior::candidates as prior_candidates;
pub use prior::nominal_plate_prior;
pub use statistics::StatisticsError;
pub use stream::{design, SpectralSolver};

use nalgebra::DMatrix;

use model::Params;

bitflags::bitflags! {
    /// Per-pixel flags (`flags.npy`, the bits as `u16`).
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Default)]
    pub struct PixelFlags: u16 {
        /// Outside the pixels the station predicts to see the element, or too few samples.
        const NO_DATA = 1;
        /// No fringe signal in at least one direction.
        const NO_SIGNAL = 2;
        /// Saturated or clipped samples were excluded from the fit.
        const SATURATED = 4;
        /// One reflection modelled (opaque element, reference flat, AR-coated back).
        const ONE_REFLECTION = 8;
        /// Three reflections modelled (second internal round trip, paper §5.1b).
        const THREE_REFLECTIONS = 16;
        /// The reflections cannot be separated with this schedule: both NaN.
        const UNRESOLVED = 32;
        /// The fitted back-minus-front offset disagrees with the geometry by more
        /// than half its size: both NaN rather than a possibly swapped answer.
        const OFFSET_MISMATCH = 64;
        /// Levenberg–Marquardt stopped at its iteration cap.
        const NOT_CONVERGED = 128;
        /// Every model needed a negative amplitude: no physical fit.
        const NEGATIVE_AMPLITUDE = 256;
        /// Statistics engine: the fit left the band of screen positions around
        /// the station's prediction that the statistics keep, or (with
        /// `NO_SIGNAL`) the band holds no signal — it may lie outside: both NaN.
        const OUT_OF_BAND = 512;
        /// The fit's residual is far above the noise of pixels as bright
        /// (a χ² test, `pipeline`'s quality pass): not reported, both NaN.
        const POOR_FIT = 1024;
        /// The fitted points lie far from where the station puts them,
        /// beyond what the surfaces and the station's tolerance allow
        /// relative to the other pixels (a wrong fringe, an alias): not
        /// reported, both NaN.
        const FAR_FROM_PRIOR = 2048;
    }
}

impl PixelFlags {
    /// Every flag with what it means in a few words: the table of
    /// `mfd reconstruct --help` and of the printed summary.
    pub const MEANINGS: [(PixelFlags, &'static str); 12] = [
        (PixelFlags::NO_DATA, "no data"),
        (PixelFlags::NO_SIGNAL, "no fringe signal"),
        (PixelFlags::SATURATED, "saturated samples excluded"),
        (PixelFlags::ONE_REFLECTION, "one reflection"),
        (PixelFlags::THREE_REFLECTIONS, "three reflections"),
        (PixelFlags::UNRESOLVED, "reflections not separable"),
        (
            PixelFlags::OFFSET_MISMATCH,
            "offset disagrees with the geometry",
        ),
        (PixelFlags::NOT_CONVERGED, "not converged"),
        (PixelFlags::NEGATIVE_AMPLITUDE, "negative amplitude"),
        (
            PixelFlags::OUT_OF_BAND,
            "outside the band the statistics engine keeps",
        ),
        (PixelFlags::POOR_FIT, "residual far above the noise"),
        (
            PixelFlags::FAR_FROM_PRIOR,
            "far from where the station puts the points",
        ),
    ];
}

/// The solver's answer for one pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelResult {
    /// `(u, v)` of the front and back reflection, NaN when not found.
    pub s: [[f64; 2]; 2],
    /// Standard deviations of those coordinates, screen px.
    pub std: [[f64; 2]; 2],
    /// Covariance of `(u1, v1, u2, v2)`, px² (NaN where a point is absent);
    /// the two points of one pixel are correlated where their spectra overlap.
    pub cov: [[f64; 4]; 4],
    /// Background A and amplitudes B1, B2, B3, counts (NaN when absent).
    pub amp: [f64; 4],
    /// Fitted τ_max.
    pub tau_max: f64,
    /// RMS of the residuals, counts.
    pub residual_rms: f64,
    /// Separation of the two reflections in Fourier bins, that of the best
    /// pair of directions (`model::Design::pair_separation`).
    pub separation_bins: f64,
    /// Number of reflections in the chosen model (0: none).
    pub model: u8,
    /// What the fit found or could not do.
    pub flags: PixelFlags,
    /// LM iterations of the chosen model.
    pub iterations: u16,
}

impl PixelResult {
    /// Nothing found.
    pub fn empty() -> Self {
        PixelResult {
            s: [[f64::NAN; 2]; 2],
            std: [[f64::NAN; 2]; 2],
            cov: [[f64::NAN; 4]; 4],
            amp: [f64::NAN; 4],
            tau_max: f64::NAN,
            residual_rms: f64::NAN,
            separation_bins: f64::NAN,
            model: 0,
            flags: PixelFlags::empty(),
            iterations: 0,
        }
    }

    /// Puts reflection `which` of `p` into slot `slot` (0 front, 1 back).
    fn set(&mut self, slot: usize, p: &Params, which: usize, cov: Option<&DMatrix<f64>>) {
        self.s[slot] = p.uv[which];
        if let Some(c) = cov {
            let u = p.u_index(which);
            self.std[slot] = [c[(u, u)].max(0.0).sqrt(), c[(u + 1, u + 1)].max(0.0).sqrt()];
            for a in 0..2 {
                for b in 0..2 {
                    self.cov[2 * slot + a][2 * slot + b] = c[(u + a, u + b)];
                }
            }
        }
    }

    /// Cross-covariance of the front (reflection `i0` of `p`) and back
    /// (`i1`) points, after both were [`PixelResult::set`].
    fn set_cross(&mut self, p: &Params, i0: usize, i1: usize, cov: Option<&DMatrix<f64>>) {
        let Some(c) = cov else { return };
        let (u0, u1) = (p.u_index(i0), p.u_index(i1));
        for a in 0..2 {
            for b in 0..2 {
                self.cov[a][2 + b] = c[(u0 + a, u1 + b)];
                self.cov[2 + b][a] = c[(u0 + a, u1 + b)];
            }
        }
    }
}

#[cfg(test)]
mod flag_tests {
    use super::PixelFlags;

    /// `flags.npy` keeps the bits it always had (other tools read them),
    /// and the table of meanings names every flag once.
    #[test]
    fn flag_bits_are_the_files_and_every_flag_has_a_meaning() {
        let bits: Vec<u16> = PixelFlags::MEANINGS.iter().map(|(f, _)| f.bits()).collect();
        assert_eq!(bits, [1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 2048]);
        let union = PixelFlags::MEANINGS
            .iter()
            .fold(PixelFlags::empty(), |acc, (f, _)| acc | *f);
        assert_eq!(union, PixelFlags::all());
    }
}

//! The outer iteration of the surface-domain estimator (see the module
//! above): predict, linearise every pixel, solve the surfaces on the
//! pseudo-observations, step with halving until the coefficients stop
//! moving on the scale of their own σ.
//! The pixels, the step, the third reflection and the iteration itself
//! are in `pixels`, `step`, `third` and `iterate`.

mod iterate;
mod pixels;
mod starts;
mod step;
mod third;

use std::time::Instant;

use crate::optics::station::Station;
use crate::solve::spectral::{PixelFlags, SpectralMaps, SpectralSolver};
use crate::solve::surfaces::{Observations, SurfaceError, SurfaceOptions, SurfaceSolution};
use iterate::fit;
use pixels::{maps_of, Pix};
pub use starts::{Starts, CLEAR_PREFERENCE, SAME_POINT_SIGMA};

/// How hard the outer iteration tries.
#[derive(Debug, Clone, PartialEq)]
pub struct DirectOptions {
    /// Outer iterations at most.
    pub max_iter: usize,
    /// Converged when no coefficient moved by more than this many of its
    /// own σ in the last step (and the term counts stayed): the answer is
    /// then within a small fraction of its uncertainty of the fixed point.
    pub step_tol_sigma: f64,
    /// Halvings of a step that raises the objective before it is taken anyway.
    pub max_halvings: usize,
}

impl Default for DirectOptions {
    fn default() -> Self {
        DirectOptions {
            max_iter: 12,
            step_tol_sigma: 0.05,
            max_halvings: 5,
        }
    }
}

/// Why the estimator could not run.
#[derive(Debug, thiserror::Error)]
pub enum DirectError {
    /// The acquisition is not one it models (e.g. a phase-shifting schedule).
    #[error("surface-domain fit: {why}")]
    NotApplicable {
        /// Why, in words.
        why: &'static str,
    },
    /// The surface solver failed on the pseudo-observations.
    #[error("surface-domain fit: {0}")]
    Surface(#[from] SurfaceError),
}

impl crate::outcome::Classify for DirectError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        match self {
            // `--estimator direct` where the data do not allow it.
            DirectError::NotApplicable { .. } => Some(Outcome::Input),
            DirectError::Surface(e) => e.outcome(),
        }
    }
}

/// One outer iteration's account.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Iteration {
    /// `Σ N_p ln RSS_p` after the step (lower is better).
    pub objective: f64,
    /// Front and back terms of the step's surface solve.
    pub terms: [usize; 2],
    /// Fraction of the surface solver's step taken (1, ½, ¼, …).
    pub step_fraction: f64,
    /// Largest coefficient change, in units of its σ.
    pub max_step_sigma: f64,
    /// Pixels in the fit.
    pub pixels: usize,
    /// Whether the clipped samples stood at their conditional means in this
    /// step (the second phase) or were left out.
    #[serde(default)]
    pub clipped_imputed: bool,
    /// The third reflection's global factor γ in this step (0: not
    /// modelled).
    #[serde(default)]
    pub third_reflection: f64,
}

/// The third reflection (two internal round trips) as the fit modelled it:
/// `B3 = factor · ρ · B2` per pixel, ρ the traced Fresnel ratio (1 for bare
/// glass), estimated from all pixels at once.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ThirdReflection {
    /// γ.
    pub factor: f64,
    /// Its σ.
    pub sigma: f64,
}

/// The estimator's answer.
#[derive(Debug, Clone)]
pub struct DirectSolution {
    /// The surfaces, their covariance (inverse global Fisher information,
    /// scaled by the fit's χ² as the surface solver does) and its figures.
    pub solution: SurfaceSolution,
    /// The pseudo-observations of the last solve (what the budget and the
    /// summary are computed on).
    pub observations: Observations,
    /// `[rows, columns, 2, 2]`: S1 and S2 the fitted surfaces predict, px
    /// (NaN where the pixel was not in the fit).
    pub predicted: Vec<f64>,
    /// `[rows, columns]`: each pixel's χ² against that prediction, its own
    /// data's pull (χ² with 2K degrees of freedom; NaN where not fitted):
    /// where the Zernike model cannot follow the element (a scratch, a
    /// bubble), it shows.
    pub chi2_map: Vec<f64>,
    /// Per iteration.
    pub iterations: Vec<Iteration>,
    /// Whether the step criterion was met within the iteration cap.
    pub converged: bool,
    /// Pixels fitted with two reflections.
    pub two_reflection_pixels: usize,
    /// Pixels with samples the camera clipped, and those samples: fitted
    /// at their conditional means (the censored likelihood, see
    /// [`crate::solve::spectral::model::censored`]).
    pub clipped: Clipped,
    /// The third reflection's factor, where the data showed it (else the
    /// model has two reflections).
    pub third_reflection: Option<ThirdReflection>,
    /// The second start's comparison, where the fit started from the
    /// per-pixel surfaces ([`Starts`]).
    pub starts: Option<Starts>,
    /// Wall time, s.
    pub seconds: f64,
}

/// The clipped samples of the fitted pixels.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Clipped {
    /// Pixels with at least one clipped sample.
    pub pixels: usize,
    /// Clipped samples over all fitted pixels.
    pub samples: usize,
}

/// Fits the surfaces to the frames `solver` holds (after its per-pixel
/// solve, whose `maps` say where there is signal and how many reflections
/// the scene has), starting from `start` (the per-pixel surfaces) or, when
/// there are none, from the flat plate the station describes. `station` is
/// in the element's frame, as the pipeline uses it.
///
/// # Errors
/// [`DirectError::NotApplicable`] for a phase-shifting schedule or when no
/// pixel can be fitted; [`DirectError::Surface`] when the surface solver
/// fails on the pseudo-observations.
pub fn solve(
    solver: &SpectralSolver,
    maps: &SpectralMaps,
    station: &Station,
    start_from: Option<&SurfaceSolution>,
    surface: &SurfaceOptions,
    opts: &DirectOptions,
) -> Result<DirectSolution, DirectError> {
    let t0 = Instant::now();
    if solver.phase_schedule().is_some() {
        return Err(DirectError::NotApplicable {
            why: "a phase-shifting schedule has no per-pixel spectral model to fit through",
        });
    }
    // An uncoated element has a back reflection; where the per-pixel scene
    // model says one reflection only because no pixel resolves two (every
    // pixel flagged unresolved: a thin plate), the global fit decides.
    let resolved_one = maps.scene_model < 2 && unresolved_share(maps) < 0.5;
    if !resolved_one {
        let two = fit_from_starts(solver, maps, station, start_from, surface, opts, true)?;
        let test = two.back_amplitude_test();
        if !test.absent() {
            return Ok(two.finish(station, t0));
        }
        log::info!(
            "surface-domain fit: no back reflection in the frames (Wald Σz² {:.0} over {:.0} \
             pixels, {:.0} expected of an uncoated back); one reflection fitted",
            test.observed,
            test.pixels,
            test.expected
        );
    }
    Ok(
        fit_from_starts(solver, maps, station, start_from, surface, opts, false)?
            .finish(station, t0),
    )
}

/// The outer iteration from `start_from` and, where that is the per-pixel
/// surfaces, again from the plate as made, one answer kept
/// ([`starts::choose`]). A second run that fails leaves the first.
fn fit_from_starts(
    solver: &SpectralSolver,
    maps: &SpectralMaps,
    station: &Station,
    start_from: Option<&SurfaceSolution>,
    surface: &SurfaceOptions,
    opts: &DirectOptions,
    two: bool,
) -> Result<Fitted, DirectError> {
    let a = fit(solver, maps, station, start_from, surface, opts, two)?;
    if start_from.is_none() {
        return Ok(a);
    }
    match fit(solver, maps, station, None, surface, opts, two) {
        Ok(b) => {
            let (mut kept, starts) = starts::choose(a, b);
            kept.starts = Some(starts);
            Ok(kept)
        }
        Err(e) => {
            log::info!(
                "surface-domain fit from the plate as made: {e}; the per-pixel start's kept"
            );
            Ok(a)
        }
    }
}

/// The state of a fit: pixels, plate, solution and iterations.
struct Fitted {
    pix: Vec<Pix>,
    obs: Observations,
    solution: SurfaceSolution,
    iterations: Vec<Iteration>,
    converged: bool,
    third: Option<ThirdReflection>,
    starts: Option<Starts>,
}

impl Fitted {
    /// The back amplitudes' Wald statistics, observed and as an uncoated
    /// back of the traced Fresnel weight would make them.
    fn back_amplitude_test(&self) -> BackTest {
        let mut t = BackTest::default();
        for p in self.pix.iter().filter(|p| p.p.k == 2) {
            let var = p.lin.last_amp_var;
            if !(var.is_finite() && var > 0.0) {
                continue;
            }
            let total = p.p.amp[0] + p.p.amp[1];
            t.observed += p.p.amp[1].powi(2) / var;
            t.expected += (total * p.back_share).powi(2) / var;
            t.pixels += 1.0;
        }
        t
    }

    fn finish(self, station: &Station, t0: Instant) -> DirectSolution {
        let (w, h) = (
            station.camera.width as usize,
            station.camera.height as usize,
        );
        let (predicted, chi2_map) = maps_of(&self.pix, w, h);
        DirectSolution {
            two_reflection_pixels: self.pix.iter().filter(|p| p.p.k == 2).count(),
            third_reflection: self.third,
            clipped: Clipped {
                pixels: self.pix.iter().filter(|p| p.clipped > 0).count(),
                samples: self.pix.iter().map(|p| p.clipped).sum(),
            },
            solution: self.solution,
            observations: self.obs,
            predicted,
            chi2_map,
            iterations: self.iterations,
            converged: self.converged,
            starts: self.starts,
            seconds: t0.elapsed().as_secs_f64(),
        }
    }
}

/// Whether the frames show a back reflection: Wald statistics summed over
/// the two-reflection pixels.
#[derive(Debug, Default, Clone, Copy)]
struct BackTest {
    /// `Σ (B2 / σ(B2))²`.
    observed: f64,
    /// The same for `B2` at the traced Fresnel share of the total amplitude.
    expected: f64,
    /// Pixels summed.
    pixels: f64,
}

impl BackTest {
    /// Without a back reflection `observed` is χ² with `pixels` degrees of
    /// freedom (mean m, standard deviation √(2m)). The back is absent when
    /// the test can tell (an uncoated back would lie 25 standard deviations
    /// out) and `observed` is within 5 of χ²'s mean; where it cannot tell
    /// (reflections so close that B2 and B1 trade off: a 1 mm plate), the
    /// physics default stands: an uncoated element has a back reflection.
    fn absent(&self) -> bool {
        let sd = (2.0 * self.pixels).sqrt();
        self.expected > self.pixels + 25.0 * sd && self.observed < self.pixels + 5.0 * sd
    }
}

/// Share of the pixels with fringes that the per-pixel stage flagged as
/// not separable.
fn unresolved_share(maps: &SpectralMaps) -> f64 {
    let lit = maps.pixels.iter().filter(|p| {
        !p.flags
            .intersects(PixelFlags::NO_DATA | PixelFlags::NO_SIGNAL)
    });
    let (n, u) = lit.fold((0usize, 0usize), |(n, u), p| {
        (
            n + 1,
            u + usize::from(p.flags.contains(PixelFlags::UNRESOLVED)),
        )
    });
    u as f64 / n.max(1) as f64
}

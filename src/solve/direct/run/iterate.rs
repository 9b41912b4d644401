//! The outer iteration itself: the start plate and pixels, then phases of
//! surface solves and steps (clipped samples left out, then imputed, then
//! the third reflection's factor) until the coefficients stop moving.

use rayon::prelude::*;

use super::pixels::{initial_pixels, pseudo_observations, Pix};
use super::step::{max_step_sigma, relinearise, step};
use super::third::{add_third_uncertainty, third_step, THIRD_ROUNDS};
use super::{DirectError, DirectOptions, Fitted, Iteration, ThirdReflection};
use crate::optics::station::Station;
use crate::optics::trace::Plate;
use crate::solve::spectral::{SpectralMaps, SpectralSolver};
use crate::solve::surfaces::solve::TermChoices;
use crate::solve::surfaces::{
    reconstruct, Observations, SurfaceError, SurfaceOptions, SurfaceSolution,
};

/// The outer iteration with two reflections (where the plate's back path
/// exists) or one everywhere.
pub(super) fn fit(
    solver: &SpectralSolver,
    maps: &SpectralMaps,
    station: &Station,
    start_from: Option<&SurfaceSolution>,
    surface: &SurfaceOptions,
    opts: &DirectOptions,
    two: bool,
) -> Result<Fitted, DirectError> {
    let mut state = State::start(solver, maps, station, start_from, surface, two)?;
    let mut converged = false;
    // Phases, each of at most `max_iter` iterations, each started from the
    // last's fixed point. First with the clipped samples left out, until
    // the surfaces describe the data; then with them at their conditional
    // means (EM on the censored likelihood, see `Pix::clipped`), which
    // needs a model near the data — from a flat start the model is far
    // from many samples and their imputations mean nothing. Then, with two
    // reflections, the third reflection's global factor γ (`B3 = γ ρ B2`,
    // ρ the traced Fresnel ratio): a score test at γ = 0; where the data
    // show the third path (|step| > 5σ: bare glass of high index) γ is
    // estimated, refitting after each of at most `THIRD_ROUNDS` steps until
    // a step is below a tenth of its σ. Where they do not (an independent
    // renderer without it, coated faces, low index: R² = 0.2 % at 1.5),
    // it is not modelled.
    let clipped = state.pix.iter().any(|x| x.clipped > 0);
    let mut phase_it = 0;
    for it in 0..(2 + THIRD_ROUNDS) * opts.max_iter {
        if phase_it == opts.max_iter {
            break;
        }
        phase_it += 1;
        let (same_terms, max_step_sigma) = state.iterate(solver, station, surface, opts, it)?;
        if !(same_terms && max_step_sigma < opts.step_tol_sigma) {
            continue;
        }
        if clipped && !state.model.impute {
            state.model.impute = true;
        } else if two && state.rounds < THIRD_ROUNDS {
            if state.third_round(solver, station) {
                converged = true;
                break;
            }
        } else {
            converged = true;
            break;
        }
        phase_it = 0;
        state.pix = state
            .pix
            .par_iter()
            .filter_map(|x| relinearise(solver, station, &state.plate, x, &state.model))
            .collect();
        state.obs = pseudo_observations(station, &state.pix);
    }
    state.finish(converged)
}

/// The outer iteration between two iterations: the plate and its pixels,
/// the surface solver's settings and last answer, and what the pixels'
/// model holds besides the surfaces.
struct State {
    plate: Plate,
    pix: Vec<Pix>,
    obs: Observations,
    solve_opts: SurfaceOptions,
    iterations: Vec<Iteration>,
    last_terms: Option<[usize; 2]>,
    /// The last term choice the criterion made (later solves hold it).
    choice: Option<TermChoices>,
    solution: Option<SurfaceSolution>,
    model: Model,
    third: Option<ThirdReflection>,
    rounds: usize,
    /// The surfaces at γ = 0, kept when the third is first modelled: with
    /// the final ones they give the surfaces' change per unit γ, through
    /// which γ's σ enters their covariance.
    without_third: Option<[Vec<f64>; 2]>,
}

impl State {
    /// The start plate and its pixels.
    fn start(
        solver: &SpectralSolver,
        maps: &SpectralMaps,
        station: &Station,
        start_from: Option<&SurfaceSolution>,
        surface: &SurfaceOptions,
        two: bool,
    ) -> Result<State, DirectError> {
        let plate = start_plate(station, start_from, surface)?;
        let pix = initial_pixels(solver, maps, station, &plate, two);
        if pix.is_empty() {
            return Err(DirectError::NotApplicable {
                why: "no pixel with fringes where the station predicts the element",
            });
        }
        // Exact weights: the fixed point is the global likelihood's only with
        // each pixel weighted by its own information (see `pixel`).
        let solve_opts = SurfaceOptions {
            covariance_smoothing_px: 0,
            ..surface.clone()
        };
        let obs = pseudo_observations(station, &pix);
        Ok(State {
            plate,
            pix,
            obs,
            solve_opts,
            iterations: Vec::new(),
            last_terms: None,
            choice: None,
            solution: None,
            model: Model::default(),
            third: None,
            rounds: 0,
            without_third: None,
        })
    }

    /// Iteration `it`: the surfaces solved on the pseudo-observations, the
    /// step towards them taken (halved as needed), the pixels relinearised.
    /// Returns whether the term counts stayed and the step's largest
    /// coefficient change in units of its σ.
    fn iterate(
        &mut self,
        solver: &SpectralSolver,
        station: &Station,
        surface: &SurfaceOptions,
        opts: &DirectOptions,
        it: usize,
    ) -> Result<(bool, f64), DirectError> {
        let sol = reconstruct(&self.obs, station, &self.solve_opts)?;
        let terms = [
            sol.front.coefficients_nm().len(),
            sol.back.coefficients_nm().len(),
        ];
        // A step below the convergence scale is taken whole: its objective
        // change is at the level of rounding in Σ N ln RSS (~1e-9 of it),
        // where halving only repeats the relinearisation.
        let halvings = if max_step_sigma(&self.plate, &sol, 1.0) < opts.step_tol_sigma {
            0
        } else {
            opts.max_halvings
        };
        let (next, step) = step(
            solver,
            station,
            &self.plate,
            &sol,
            &self.pix,
            halvings,
            &self.model,
        );
        let max_step_sigma = max_step_sigma(&self.plate, &sol, step.fraction);
        self.pix = next;
        self.plate = step.plate;
        let mut sol = sol;
        // Once the counts are held the solves no longer choose: the result
        // keeps the choice that set them, and says who fixed them.
        if sol.choice.is_some() {
            self.choice = sol.choice.clone();
        }
        sol.choice = sol.choice.or_else(|| self.choice.clone());
        sol.terms_fixed = surface.terms.is_some();
        sol.front = self.plate.front.clone();
        sol.back = self.plate.back.clone();
        self.iterations.push(Iteration {
            objective: step.objective,
            terms,
            step_fraction: step.fraction,
            max_step_sigma,
            pixels: self.pix.len(),
            clipped_imputed: self.model.impute,
            third_reflection: self.model.gamma,
        });
        log::debug!(
            "surface-domain fit, iteration {it}: {:?}",
            self.iterations.last()
        );
        let same_terms = self.last_terms == Some(terms);
        // The term choice settles first; then the counts are held, so the
        // iteration converges on one model.
        if surface.terms.is_none() && (same_terms || it >= 2) {
            self.solve_opts.terms = Some(terms[0].max(terms[1]));
        }
        self.last_terms = Some(terms);
        self.solution = Some(sol);
        self.obs = pseudo_observations(station, &self.pix);
        Ok((same_terms, max_step_sigma))
    }

    /// One step of the third reflection's factor γ at the current fixed
    /// point. Returns whether the fit has converged (no third path, or the
    /// step below its threshold).
    fn third_round(&mut self, solver: &SpectralSolver, station: &Station) -> bool {
        let Some((d, sd)) = third_step(solver, station, &self.plate, &self.pix, &self.model) else {
            return true;
        };
        log::debug!(
            "surface-domain fit: third reflection's factor {} + step {d:.4} (σ {sd:.4})",
            self.model.gamma
        );
        let settled = if self.model.gamma == 0.0 {
            d.abs() < 5.0 * sd
        } else {
            d.abs() < 0.1 * sd
        };
        if self.model.gamma != 0.0 || !settled {
            self.third = Some(ThirdReflection {
                factor: self.model.gamma + if settled { 0.0 } else { d },
                sigma: sd,
            });
        }
        if settled {
            return true;
        }
        if self.model.gamma == 0.0 {
            self.without_third = Some([
                self.plate.front.coefficients_nm().to_vec(),
                self.plate.back.coefficients_nm().to_vec(),
            ]);
        }
        self.model.gamma += d;
        self.rounds += 1;
        false
    }

    /// The fit's account at the end of the iteration.
    fn finish(self, converged: bool) -> Result<Fitted, DirectError> {
        let mut solution = self.solution.ok_or(DirectError::NotApplicable {
            why: "no iteration allowed (max_iter 0)",
        })?;
        if let (Some(t), Some(before)) = (self.third, &self.without_third) {
            add_third_uncertainty(&mut solution, before, &t);
        }
        Ok(Fitted {
            pix: self.pix,
            obs: self.obs,
            solution,
            iterations: self.iterations,
            converged,
            third: self.third,
            starts: None,
        })
    }
}

/// The start: the per-pixel surfaces, or the nominal plate (a flat front,
/// the back flat or the declared wedge's plane) with the starting term
/// count of the surface solver.
fn start_plate(
    station: &Station,
    from: Option<&SurfaceSolution>,
    surface: &SurfaceOptions,
) -> Result<Plate, SurfaceError> {
    let margin = surface.edge_margin_mm;
    if let Some(sol) = from {
        return Ok(Plate::new(
            station,
            sol.front.clone(),
            sol.back.clone(),
            margin,
        ));
    }
    let terms = surface.terms.unwrap_or(surface.max_terms).max(3);
    let (front, back) = station.element.nominal_surfaces(terms)?;
    Ok(Plate::new(station, front, back, margin))
}

/// What the pixels' model holds besides the surfaces: whether clipped
/// samples stand at their conditional means, and the third reflection's
/// global factor γ (0: not modelled).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Model {
    pub(super) impute: bool,
    pub(super) gamma: f64,
}

//! The outer iteration of the surface-domain estimator (see the module
//! above): predict, linearise every pixel, solve the surfaces on the
//! pseudo-observations, step with halving until the coefficients stop
//! moving on the scale of their own σ.

use std::time::Instant;

use nalgebra::{Unit, Vector3};
use rayon::prelude::*;

use super::pixel::{linearise_tied, moved, start, third_score, Linear, Tie};
use crate::optics::station::Station;
use crate::optics::trace::Plate;
use crate::optics::zernike::{ZernikeBasis, ZernikeSurface};
use crate::solve::spectral::model::Params;
use crate::solve::spectral::{PixelFlags, SpectralMaps, SpectralSolver};
use crate::solve::surfaces::path::{back_path, front_path};
use crate::solve::surfaces::{
    reconstruct, Observation, Observations, SurfaceError, SurfaceOptions, SurfaceSolution,
};

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

/// Adds γ's uncertainty to the surfaces' covariance: `σ_γ² d dᵀ`, with `d`
/// the surfaces' change per unit γ, from the fixed points at γ = 0
/// (`before`) and at the estimate (the solution's coefficients).
fn add_third_uncertainty(sol: &mut SurfaceSolution, before: &[Vec<f64>; 2], t: &ThirdReflection) {
    if t.factor == 0.0 {
        return;
    }
    let layout = sol.layout;
    let mut d = nalgebra::DVector::zeros(layout.columns());
    let surfaces = [sol.front.coefficients_nm(), sol.back.coefficients_nm()];
    for (side, now) in surfaces.iter().enumerate() {
        for (k, &c) in now.iter().enumerate() {
            let col = if side == 0 {
                layout.front_col(k)
            } else {
                layout.back_col(k)
            };
            if let Some(col) = col.filter(|&c| c < d.len()) {
                let was = before[side].get(k).copied().unwrap_or(0.0);
                d[col] = (c - was) / t.factor;
            }
        }
    }
    if sol.covariance.nrows() != d.len() {
        return;
    }
    sol.covariance += (t.sigma * t.sigma) * &d * d.transpose();
    for (k, s) in sol.front_std_nm.iter_mut().enumerate() {
        if let Some(col) = layout.front_col(k) {
            *s = sol.covariance[(col, col)].max(0.0).sqrt();
        }
    }
    for (k, s) in sol.back_std_nm.iter_mut().enumerate() {
        if let Some(col) = layout.back_col(k) {
            *s = sol.covariance[(col, col)].max(0.0).sqrt();
        }
    }
}

/// Steps of the third reflection's factor γ at most.
const THIRD_ROUNDS: usize = 3;

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

/// One pixel of the fit.
#[derive(Debug, Clone, Copy)]
struct Pix {
    /// Candidate index in the spectral solver.
    q: usize,
    /// Camera pixel `(column, row)`.
    cam: [u32; 2],
    /// Camera ray, element frame.
    dir: Vector3<f64>,
    /// Current parameters (K = 1 or 2 reflections).
    p: Params,
    /// Linearisation at `p`.
    lin: Linear,
    /// The back's share of the traced Fresnel weights `w_b / (w_f + w_b)`
    /// (0 with one reflection).
    back_share: f64,
    /// Samples the camera clipped (0 or saturated): these stand at their
    /// conditional means under the pixel's current model
    /// ([`crate::solve::spectral::model::censored`]), refreshed at every
    /// linearisation, so that the fit's fixed point is the censored
    /// likelihood's and no clipped trough biases the surfaces.
    clipped: usize,
}

impl Pix {
    fn objective(&self) -> f64 {
        self.lin.samples as f64 * self.lin.rss.max(f64::MIN_POSITIVE).ln()
    }

    /// The pixel's noise σ from its last linearisation, counts.
    fn sigma(&self) -> f64 {
        let dof = self.lin.samples.saturating_sub(self.p.len()).max(1);
        (self.lin.rss / dof as f64).sqrt()
    }
}

/// Candidate `q` linearised at `p`: with `imputed` = `Some(σ)` its
/// clipped samples stand at their conditional means under `p` with noise σ,
/// else they are left out.
fn linearise_at(
    solver: &SpectralSolver,
    q: usize,
    p: &Params,
    imputed: Option<f64>,
    tie: Option<&Tie>,
) -> Option<Linear> {
    let lin =
        |samples: &dyn crate::solve::spectral::model::Samples, _| linearise_tied(samples, p, tie);
    match imputed {
        None => solver.with_samples(q, lin)?,
        Some(sigma) => solver.with_samples_at(q, p, sigma, lin)?,
    }
}

/// The tied third reflection of a two-reflection pixel on `plate` with
/// global factor `gamma`: S3 and `B3/B2 = γ ρ` (ρ the traced Fresnel
/// ratio of the third path to the back's); `None` where the third path
/// does not reach the screen. Also returns ρ.
fn third_of(
    plate: &Plate,
    station: &Station,
    dir: &Vector3<f64>,
    gamma: f64,
) -> Option<(Tie, f64)> {
    let paths = plate.trace_ray(
        &station.camera.position_mm,
        &Unit::new_normalize(*dir),
        &station.screen,
    );
    let (b, t) = (paths.back.ok()?, paths.third.ok()?);
    let rho = t.weight / b.weight;
    rho.is_finite().then_some((
        Tie {
            ratio: gamma * rho,
            uv: [t.u, t.v],
        },
        rho,
    ))
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
        let two = fit(solver, maps, station, start_from, surface, opts, true)?;
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
    Ok(fit(solver, maps, station, start_from, surface, opts, false)?.finish(station, t0))
}

/// The state of a fit: pixels, plate, solution and iterations.
struct Fitted {
    pix: Vec<Pix>,
    obs: Observations,
    solution: SurfaceSolution,
    iterations: Vec<Iteration>,
    converged: bool,
    third: Option<ThirdReflection>,
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

/// The outer iteration with two reflections (where the plate's back path
/// exists) or one everywhere.
fn fit(
    solver: &SpectralSolver,
    maps: &SpectralMaps,
    station: &Station,
    start_from: Option<&SurfaceSolution>,
    surface: &SurfaceOptions,
    opts: &DirectOptions,
    two: bool,
) -> Result<Fitted, DirectError> {
    let mut plate = start_plate(station, start_from, surface)?;
    let mut pix = initial_pixels(solver, maps, station, &plate, two);
    if pix.is_empty() {
        return Err(DirectError::NotApplicable {
            why: "no pixel with fringes where the station predicts the element",
        });
    }
    // Exact weights: the fixed point is the global likelihood's only with
    // each pixel weighted by its own information (see `pixel`).
    let mut solve_opts = SurfaceOptions {
        covariance_smoothing_px: 0,
        ..surface.clone()
    };
    let mut iterations = Vec::new();
    let mut converged = false;
    let mut last_terms = None;
    let mut solution = None;
    let mut obs = pseudo_observations(station, &pix);
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
    let clipped = pix.iter().any(|x| x.clipped > 0);
    let mut model = Model::default();
    let mut third = None;
    let mut rounds = 0;
    let mut phase_it = 0;
    // The surfaces at γ = 0, kept when the third is first modelled: with
    // the final ones they give the surfaces' change per unit γ, through
    // which γ's σ enters their covariance.
    let mut without_third: Option<[Vec<f64>; 2]> = None;
    for it in 0..(2 + THIRD_ROUNDS) * opts.max_iter {
        if phase_it == opts.max_iter {
            break;
        }
        phase_it += 1;
        let sol = reconstruct(&obs, station, &solve_opts)?;
        let terms = [
            sol.front.coefficients_nm().len(),
            sol.back.coefficients_nm().len(),
        ];
        // A step below the convergence scale is taken whole: its objective
        // change is at the level of rounding in Σ N ln RSS (~1e-9 of it),
        // where halving only repeats the relinearisation.
        let halvings = if max_step_sigma(&plate, &sol, 1.0) < opts.step_tol_sigma {
            0
        } else {
            opts.max_halvings
        };
        let (next, step) = step(solver, station, &plate, &sol, &pix, halvings, &model);
        let max_step_sigma = max_step_sigma(&plate, &sol, step.fraction);
        pix = next;
        plate = step.plate;
        let mut sol = sol;
        sol.front = plate.front.clone();
        sol.back = plate.back.clone();
        iterations.push(Iteration {
            objective: step.objective,
            terms,
            step_fraction: step.fraction,
            max_step_sigma,
            pixels: pix.len(),
            clipped_imputed: model.impute,
            third_reflection: model.gamma,
        });
        log::debug!(
            "surface-domain fit, iteration {it}: {:?}",
            iterations.last()
        );
        let same_terms = last_terms == Some(terms);
        // The term choice settles first; then the counts are held, so the
        // iteration converges on one model.
        if surface.terms.is_none() && (same_terms || it >= 2) {
            solve_opts.terms = Some(terms[0].max(terms[1]));
        }
        last_terms = Some(terms);
        solution = Some(sol);
        obs = pseudo_observations(station, &pix);
        if !(same_terms && max_step_sigma < opts.step_tol_sigma) {
            continue;
        }
        if clipped && !model.impute {
            model.impute = true;
        } else if two && rounds < THIRD_ROUNDS {
            let Some((d, sd)) = third_step(solver, station, &plate, &pix, &model) else {
                converged = true;
                break;
            };
            log::debug!(
                "surface-domain fit: third reflection's factor {} + step {d:.4} (σ {sd:.4})",
                model.gamma
            );
            let settled = if model.gamma == 0.0 {
                d.abs() < 5.0 * sd
            } else {
                d.abs() < 0.1 * sd
            };
            if model.gamma != 0.0 || !settled {
                third = Some(ThirdReflection {
                    factor: model.gamma + if settled { 0.0 } else { d },
                    sigma: sd,
                });
            }
            if settled {
                converged = true;
                break;
            }
            if model.gamma == 0.0 {
                without_third = Some([
                    plate.front.coefficients_nm().to_vec(),
                    plate.back.coefficients_nm().to_vec(),
                ]);
            }
            model.gamma += d;
            rounds += 1;
        } else {
            converged = true;
            break;
        }
        phase_it = 0;
        pix = pix
            .par_iter()
            .filter_map(|x| relinearise(solver, station, &plate, x, &model))
            .collect();
        obs = pseudo_observations(station, &pix);
    }
    let mut solution = solution.ok_or(DirectError::NotApplicable {
        why: "no iteration allowed (max_iter 0)",
    })?;
    if let (Some(t), Some(before)) = (third, &without_third) {
        add_third_uncertainty(&mut solution, before, &t);
    }
    Ok(Fitted {
        pix,
        obs,
        solution,
        iterations,
        converged,
        third,
    })
}

/// The start: the per-pixel surfaces, or flat ones with the starting term
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
    let e = &station.element;
    let terms = surface.terms.unwrap_or(surface.max_terms).max(3);
    let centre = [e.aperture_center_mm.x, e.aperture_center_mm.y];
    let flat = ZernikeSurface::new(
        ZernikeBasis::new(terms, e.aperture_radius_mm, centre)?,
        vec![0.0; terms],
    )?;
    Ok(Plate::new(station, flat.clone(), flat, margin))
}

/// The pixels to fit: candidates with fringes; with `two`, two
/// reflections where the plate's back path exists, else one; rim pixels with a borrowed back offset left out.
fn initial_pixels(
    solver: &SpectralSolver,
    maps: &SpectralMaps,
    station: &Station,
    plate: &Plate,
    two: bool,
) -> Vec<Pix> {
    let kappa0 = median_kappa(maps).map_or_else(
        || solver.kappa_start(),
        |k| solver.design().uniform_falloff(k),
    );
    let cam = &station.camera;
    let w = cam.width as usize;
    let skip = PixelFlags::NO_DATA | PixelFlags::NO_SIGNAL;
    let candidates = solver.candidates();
    (0..candidates.len())
        .into_par_iter()
        .filter_map(|q| {
            let c = candidates[q] as usize;
            if maps.pixels[c].flags.intersects(skip) {
                return None;
            }
            let prior = &solver.prior().pixels[c];
            let wf = prior.front.as_ref().ok()?.weight;
            let back_share = prior
                .back
                .as_ref()
                .map_or(0.0, |b| b.weight / (wf + b.weight));
            let k = match (two, prior.back.is_ok()) {
                (true, true) => 2,
                (true, false) if solver.borrowed(q) => return None,
                _ => 1,
            };
            let ij = [(c % w) as u32, (c / w) as u32];
            let dir = cam.ray_direction(ij[0], ij[1]).into_inner();
            let s = predict(plate, station, &dir, k)?;
            let (p, clipped) = solver.with_samples(q, |samples, clipped| {
                (start(samples, k, &s, kappa0), clipped)
            })?;
            let lin = linearise_at(solver, q, &p, None, None)?;
            Some(Pix {
                q,
                cam: ij,
                dir,
                p,
                lin,
                back_share,
                clipped,
            })
        })
        .collect()
}

/// The median κ the per-pixel fits found, where they reported one.
fn median_kappa(maps: &SpectralMaps) -> Option<f64> {
    let mut k: Vec<f64> = maps
        .pixels
        .iter()
        .map(|p| p.tau_max)
        .filter(|t| t.is_finite() && *t > 0.0)
        .map(|t| t.powi(-2))
        .collect();
    if k.is_empty() {
        return None;
    }
    let mid = k.len() / 2;
    Some(*k.select_nth_unstable_by(mid, f64::total_cmp).1)
}

/// The `k` screen points `plate` predicts for the camera ray `dir`.
fn predict(plate: &Plate, station: &Station, dir: &Vector3<f64>, k: usize) -> Option<[f64; 4]> {
    let cam = &station.camera.position_mm;
    let f = front_path(plate, cam, dir, &station.screen).ok()?;
    let mut s = [f.uv[0].v, f.uv[1].v, f64::NAN, f64::NAN];
    if k == 2 {
        let b = back_path(plate, cam, dir, &station.screen).ok()?;
        s[2] = b.uv[0].v;
        s[3] = b.uv[1].v;
    }
    Some(s)
}

/// The surface solver's input: every pixel's pseudo-observation.
fn pseudo_observations(station: &Station, pix: &[Pix]) -> Observations {
    let pixels = pix
        .iter()
        .map(|x| Observation {
            pixel: x.cam,
            dir: x.dir,
            s: [
                [x.lin.s_star[0], x.lin.s_star[1]],
                [x.lin.s_star[2], x.lin.s_star[3]],
            ],
            cov: x.lin.cov,
        })
        .collect();
    Observations {
        camera: station.camera.position_mm,
        pixels,
        sigma_known: true,
        rejected: Vec::new(),
    }
}

/// What the pixels' model holds besides the surfaces: whether clipped
/// samples stand at their conditional means, and the third reflection's
/// global factor γ (0: not modelled).
#[derive(Debug, Clone, Copy, Default)]
struct Model {
    impute: bool,
    gamma: f64,
}

/// The Gauss–Newton step of the third reflection's global factor γ from
/// the pixels at `plate` under `model`, and γ's σ (the pixels' own
/// parameters profiled out, [`third_score`]); `None` where no pixel has a
/// third path.
fn third_step(
    solver: &SpectralSolver,
    station: &Station,
    plate: &Plate,
    pix: &[Pix],
    model: &Model,
) -> Option<(f64, f64)> {
    let [u, i] = pix
        .par_iter()
        .filter(|x| x.p.k == 2)
        .filter_map(|x| {
            let (tie, rho) = third_of(plate, station, &x.dir, model.gamma)?;
            let sigma = (model.impute && x.clipped > 0).then(|| x.sigma());
            let score = |samples: &dyn crate::solve::spectral::model::Samples, _| {
                third_score(samples, &x.p, &tie, rho)
            };
            match sigma {
                None => solver.with_samples(x.q, score)?,
                Some(s) => solver.with_samples_at(x.q, &x.p, s, score)?,
            }
        })
        .reduce(|| [0.0, 0.0], |a, b| [a[0] + b[0], a[1] + b[1]]);
    (i > 0.0).then(|| (u / i, i.sqrt().recip()))
}

/// The accepted step: its plate, the fraction of the solver's step, the
/// objective there.
struct Step {
    plate: Plate,
    fraction: f64,
    objective: f64,
}

/// From `plate` towards `sol`'s surfaces: the full step, halved while it
/// raises the global objective (over the pixels that can be evaluated at
/// both points). Returns the pixels at the accepted point, relinearised.
fn step(
    solver: &SpectralSolver,
    station: &Station,
    plate: &Plate,
    sol: &SurfaceSolution,
    pix: &[Pix],
    max_halvings: usize,
    model: &Model,
) -> (Vec<Pix>, Step) {
    let mut fraction = 1.0;
    loop {
        let trial = Plate {
            front: blend(&plate.front, &sol.front, fraction),
            back: blend(&plate.back, &sol.back, fraction),
            ..plate.clone()
        };
        let moved: Vec<Option<Pix>> = pix
            .par_iter()
            .map(|x| relinearise(solver, station, &trial, x, model))
            .collect();
        let (mut before, mut after) = (0.0, 0.0);
        for (old, new) in pix.iter().zip(&moved) {
            if let Some(new) = new {
                before += old.objective();
                after += new.objective();
            }
        }
        let accept = after <= before || max_halvings == 0;
        if accept || fraction < 0.5f64.powi(max_halvings as i32 - 1) {
            if !accept {
                log::warn!(
                    "surface-domain fit: the step raised the objective by {:.3e} even at \
                     {fraction}; taken",
                    after - before
                );
            }
            let next: Vec<Pix> = moved.into_iter().flatten().collect();
            let objective = next.iter().map(Pix::objective).sum();
            let step = Step {
                plate: trial,
                fraction,
                objective,
            };
            return (next, step);
        }
        fraction *= 0.5;
    }
}

/// `x` moved to the screen points `plate` predicts and linearised there;
/// `None` where a path no longer reaches the screen or the pixel's
/// normal equations are singular.
fn relinearise(
    solver: &SpectralSolver,
    station: &Station,
    plate: &Plate,
    x: &Pix,
    model: &Model,
) -> Option<Pix> {
    let s = predict(plate, station, &x.dir, x.p.k)?;
    let p = moved(&x.p, &x.lin, &s);
    let sigma = (model.impute && x.clipped > 0).then(|| x.sigma());
    let tie = (model.gamma != 0.0 && p.k == 2)
        .then(|| third_of(plate, station, &x.dir, model.gamma))
        .flatten()
        .map(|(t, _)| t);
    let lin = linearise_at(solver, x.q, &p, sigma, tie.as_ref())?;
    Some(Pix { p, lin, ..*x })
}

/// `a + fraction (b − a)` on `b`'s basis (a's coefficients padded or cut).
fn blend(a: &ZernikeSurface, b: &ZernikeSurface, fraction: f64) -> ZernikeSurface {
    let ca = a.coefficients_nm();
    let c: Vec<f64> = b
        .coefficients_nm()
        .iter()
        .enumerate()
        .map(|(k, &cb)| {
            let from = ca.get(k).copied().unwrap_or(0.0);
            from + fraction * (cb - from)
        })
        .collect();
    ZernikeSurface::new(b.basis().clone(), c).expect("same basis, same length")
}

/// Largest `|Δc| / σ` of the step `fraction` towards `sol` from `plate`.
fn max_step_sigma(plate: &Plate, sol: &SurfaceSolution, fraction: f64) -> f64 {
    let one = |old: &ZernikeSurface, new: &ZernikeSurface, std: &[f64]| {
        let co = old.coefficients_nm();
        new.coefficients_nm()
            .iter()
            .zip(std)
            .enumerate()
            .filter(|(_, (_, s))| **s > 0.0)
            .map(|(k, (c, s))| fraction * (c - co.get(k).copied().unwrap_or(0.0)).abs() / s)
            .fold(0.0, f64::max)
    };
    let f = one(&plate.front, &sol.front, &sol.front_std_nm);
    let b = if sol.back_fitted {
        one(&plate.back, &sol.back, &sol.back_std_nm)
    } else {
        0.0
    };
    f.max(b)
}

/// The predicted points and χ² of every fitted pixel, as camera maps.
fn maps_of(pix: &[Pix], w: usize, h: usize) -> (Vec<f64>, Vec<f64>) {
    let mut predicted = vec![f64::NAN; w * h * 4];
    let mut chi2 = vec![f64::NAN; w * h];
    for x in pix {
        let c = x.cam[1] as usize * w + x.cam[0] as usize;
        predicted[4 * c..4 * c + 4].copy_from_slice(&x.lin.s0);
        chi2[c] = x.lin.chi2;
    }
    (predicted, chi2)
}

//! The budget checked the hard way: stations drawn from the uncertainty's
//! covariance are the truth, the expected surfaces are traced on each, the
//! imaging noise is drawn from the scene's bound, and the points are
//! reconstructed with the *unperturbed* station and the budget's fixed
//! terms. The RMS change of each coefficient over the draws is what the
//! linear budget's total σ predicts, as far as the model is linear over the
//! station's uncertainty.

use nalgebra::{DMatrix, DVector, Matrix4};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;
use rayon::prelude::*;

use super::scene::{BudgetError, Scene, SceneOptions};
use crate::limits::{check_fits, Bytes};
use crate::optics::station::{Station, StationUncertainty};
use crate::optics::trace::{Plate, TracedView};
use crate::solve::surfaces::{reconstruct, Observations, Uncertainty};

/// One draw's errors of the front and the back coefficients, nm.
type DrawErrors = (Vec<f64>, Vec<f64>);

/// The most draws a Monte Carlo check makes. The RMS of N draws is known
/// to a relative 1σ of 1/√(2N): 0.2 % at 10⁵, finer than the three digits
/// the table prints; each draw re-traces and reconstructs (milliseconds to
/// seconds), so more would run for days and hold every draw's errors.
pub const MAX_DRAWS: usize = 100_000;

/// Memory one draw holds until the RMS is taken, bytes: its two rows of
/// errors (`terms` coefficients of each surface, 8 B each) and their
/// headers, kept for every draw ([`MonteCarlo::front_errors_nm`]).
pub fn bytes_per_draw(terms: usize) -> u64 {
    (std::mem::size_of::<Result<DrawErrors, BudgetError>>() + 2 * 8 * terms) as u64
}

/// Refuses `draws` above [`MAX_DRAWS`], or above what the machine can
/// hold for `terms` coefficients per surface, before any is drawn.
///
/// # Errors
/// [`BudgetError::Invalid`] naming `--monte-carlo`, the limit and the
/// memory the draws would need.
pub fn check_draws(draws: usize, terms: usize) -> Result<(), BudgetError> {
    let invalid = |problem: String| BudgetError::Invalid {
        input: "--monte-carlo".into(),
        problem,
    };
    let each = bytes_per_draw(terms);
    if draws == 0 || draws > MAX_DRAWS {
        let need = Bytes((draws as u64).saturating_mul(each));
        return Err(invalid(format!(
            "{draws} draws: expected 1 to {MAX_DRAWS} (the RMS of {MAX_DRAWS} is known to 0.2 %); \
             {draws} would need {need} of memory at {each} B per draw"
        )));
    }
    check_fits(
        &format!("{draws} draws at {each} B each"),
        draws as u64,
        each,
    )
    .map_err(|e| invalid(e.to_string()))
}

/// The Monte Carlo check's outcome.
#[derive(Debug, Clone, PartialEq)]
pub struct MonteCarlo {
    /// Stations drawn.
    pub draws: usize,
    /// The seed of the draws.
    pub seed: u64,
    /// RMS over the draws of each front coefficient's error against the
    /// scene's noise-free reconstruction on the true station, nm.
    pub front_rms_nm: Vec<f64>,
    /// The same for the back (empty when not reconstructed).
    pub back_rms_nm: Vec<f64>,
    /// Every draw's front errors, nm (`draws` rows).
    pub front_errors_nm: Vec<Vec<f64>>,
    /// Every draw's back errors, nm.
    pub back_errors_nm: Vec<Vec<f64>>,
}

/// A lower-triangular `L` with `L Lᵀ = covariance`; a positive
/// semi-definite covariance (a file's degenerate combination) gets the
/// rounding jitter the reader accepts.
fn cholesky(cov: &DMatrix<f64>) -> DMatrix<f64> {
    let mut a = cov.clone();
    for r in 0..a.nrows() {
        a[(r, r)] += 1e-12 * cov[(r, r)] + f64::MIN_POSITIVE;
    }
    a.cholesky()
        .map_or_else(|| DMatrix::zeros(cov.nrows(), cov.ncols()), |c| c.l())
}

/// The station the frames of draw `k` are taken on: `station` moved along
/// every degree of freedom by one draw from the covariance, each change
/// applied with `Station::perturbed` in the file's order.
pub fn drawn_station(
    station: &Station,
    uncertainty: &StationUncertainty,
    l: &DMatrix<f64>,
    rng: &mut Xoshiro256PlusPlus,
) -> Station {
    let z = DVector::<f64>::from_fn(l.ncols(), |_, _| StandardNormal.sample(rng));
    let delta = l * z;
    let mut s = station.clone();
    for (k, &dof) in uncertainty.names.iter().enumerate() {
        if delta[k] != 0.0 {
            s = s.perturbed(dof, delta[k]);
        }
    }
    s
}

/// The traced points of `view` with noise drawn from the per-pixel
/// covariance `cov` (`screen_cov.npy` layout); a reflection the scene has
/// no bound for (absent on the nominal station) is dropped.
pub fn noisy_coords(view: &TracedView, cov: &[f64], rng: &mut Xoshiro256PlusPlus) -> Vec<f64> {
    let mut coords = view.screen_coords();
    for q in 0..view.pixels.len() {
        let c = Matrix4::from_fn(|a, b| cov[16 * q + 4 * a + b]);
        let present: Vec<usize> = (0..2)
            .filter(|&k| coords[4 * q + 2 * k].is_finite() && c[(2 * k, 2 * k)].is_finite())
            .collect();
        for k in 0..2 {
            if !present.contains(&k) {
                coords[4 * q + 2 * k] = f64::NAN;
                coords[4 * q + 2 * k + 1] = f64::NAN;
            }
        }
        let idx: Vec<usize> = present.iter().flat_map(|&k| [2 * k, 2 * k + 1]).collect();
        let sub = DMatrix::from_fn(idx.len(), idx.len(), |a, b| c[(idx[a], idx[b])]);
        let l = cholesky(&sub);
        let z = DVector::<f64>::from_fn(idx.len(), |_, _| StandardNormal.sample(rng));
        let e = l * z;
        for (a, &i) in idx.iter().enumerate() {
            coords[4 * q + i] += e[a];
        }
    }
    coords
}

/// Draws `draws` stations (seeded: draw `k` uses `seed + k`), reconstructs
/// each one's noisy points with the nominal `station`, and collects the
/// coefficients' errors against `scene.solution`.
///
/// # Errors
/// [`BudgetError::Surface`] when a draw's reconstruction fails.
pub fn monte_carlo(
    station: &Station,
    uncertainty: &StationUncertainty,
    scene: &Scene,
    opts: &SceneOptions,
    draws: usize,
    seed: u64,
) -> Result<MonteCarlo, BudgetError> {
    check_draws(draws, opts.terms)?;
    let l = cholesky(&uncertainty.covariance);
    let base = &scene.solution;
    let (nf, nb) = (
        base.front.coefficients_nm().len(),
        if base.back_fitted {
            base.back.coefficients_nm().len()
        } else {
            0
        },
    );
    let sopts = opts.surface_options();
    let errors: Vec<Result<DrawErrors, BudgetError>> = (0..draws)
        .into_par_iter()
        .map(|k| {
            let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed.wrapping_add(k as u64));
            let truth = drawn_station(station, uncertainty, &l, &mut rng);
            let (front, back) = scene.surfaces.clone();
            let view = TracedView::trace(
                &truth,
                &Plate::new(&truth, front, back, opts.edge_margin_mm),
            );
            let coords = noisy_coords(&view, &scene.cov, &mut rng);
            let obs = Observations::from_maps(station, &coords, Uncertainty::Cov(&scene.cov))?;
            let sol = reconstruct(&obs, station, &sopts)?;
            let diff = |a: &[f64], b: &[f64], n: usize| -> Vec<f64> {
                (0..n)
                    .map(|i| a.get(i).copied().unwrap_or(0.0) - b.get(i).copied().unwrap_or(0.0))
                    .collect()
            };
            Ok((
                diff(
                    sol.front.coefficients_nm(),
                    base.front.coefficients_nm(),
                    nf,
                ),
                diff(sol.back.coefficients_nm(), base.back.coefficients_nm(), nb),
            ))
        })
        .collect();
    let mut front_errors_nm = Vec::with_capacity(draws);
    let mut back_errors_nm = Vec::with_capacity(draws);
    for e in errors {
        let (f, b) = e?;
        front_errors_nm.push(f);
        back_errors_nm.push(b);
    }
    let rms = |rows: &[Vec<f64>], n: usize| -> Vec<f64> {
        (0..n)
            .map(|i| {
                (rows.iter().map(|r| r[i] * r[i]).sum::<f64>() / rows.len().max(1) as f64).sqrt()
            })
            .collect()
    };
    Ok(MonteCarlo {
        draws,
        seed,
        front_rms_nm: rms(&front_errors_nm, nf),
        back_rms_nm: rms(&back_errors_nm, nb),
        front_errors_nm,
        back_errors_nm,
    })
}

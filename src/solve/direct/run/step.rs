//! One step of the outer iteration: from the current plate towards the
//! surface solver's answer, halved while it raises the global objective,
//! with every pixel moved to the new plate's points and relinearised.

use rayon::prelude::*;

use super::iterate::Model;
use super::pixels::{linearise_at, predict, Pix};
use super::third::third_of;
use crate::optics::station::Station;
use crate::optics::trace::Plate;
use crate::optics::zernike::ZernikeSurface;
use crate::solve::direct::pixel::moved;
use crate::solve::spectral::SpectralSolver;
use crate::solve::surfaces::SurfaceSolution;

/// The accepted step: its plate, the fraction of the solver's step, the
/// objective there.
pub(super) struct Step {
    pub(super) plate: Plate,
    pub(super) fraction: f64,
    pub(super) objective: f64,
}

/// From `plate` towards `sol`'s surfaces: the full step, halved while it
/// raises the global objective (over the pixels that can be evaluated at
/// both points). Returns the pixels at the accepted point, relinearised.
pub(super) fn step(
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
pub(super) fn relinearise(
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
pub(super) fn max_step_sigma(plate: &Plate, sol: &SurfaceSolution, fraction: f64) -> f64 {
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

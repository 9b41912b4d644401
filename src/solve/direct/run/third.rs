//! The third reflection (two internal round trips): its tie to the back
//! reflection per pixel, the Gauss–Newton step of its global factor γ, and
//! γ's uncertainty carried into the surfaces' covariance.

use nalgebra::{Unit, Vector3};
use rayon::prelude::*;

use super::iterate::Model;
use super::pixels::Pix;
use super::ThirdReflection;
use crate::optics::station::Station;
use crate::optics::trace::Plate;
use crate::solve::direct::pixel::{third_score, Tie};
use crate::solve::spectral::SpectralSolver;
use crate::solve::surfaces::SurfaceSolution;

/// Steps of the third reflection's factor γ at most.
pub(super) const THIRD_ROUNDS: usize = 3;

/// The tied third reflection of a two-reflection pixel on `plate` with
/// global factor `gamma`: S3 and `B3/B2 = γ ρ` (ρ the traced Fresnel
/// ratio of the third path to the back's); `None` where the third path
/// does not reach the screen. Also returns ρ.
pub(super) fn third_of(
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

/// The Gauss–Newton step of the third reflection's global factor γ from
/// the pixels at `plate` under `model`, and γ's σ (the pixels' own
/// parameters profiled out, [`third_score`]); `None` where no pixel has a
/// third path.
pub(super) fn third_step(
    solver: &SpectralSolver,
    station: &Station,
    plate: &Plate,
    pix: &[Pix],
    model: &Model,
) -> Option<(f64, f64)> {
    // Collected in pixel order and summed in it: the same sum on every run.
    let parts: Vec<[f64; 2]> = pix
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
        .collect();
    let [u, i] = parts
        .into_iter()
        .fold([0.0, 0.0], |a, b| [a[0] + b[0], a[1] + b[1]]);
    (i > 0.0).then(|| (u / i, i.sqrt().recip()))
}

/// Adds γ's uncertainty to the surfaces' covariance: `σ_γ² d dᵀ`, with `d`
/// the surfaces' change per unit γ, from the fixed points at γ = 0
/// (`before`) and at the estimate (the solution's coefficients).
pub(super) fn add_third_uncertainty(
    sol: &mut SurfaceSolution,
    before: &[Vec<f64>; 2],
    t: &ThirdReflection,
) {
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

//! What a session leaves weakly determined, and what a failed adjustment
//! did: named, with figures, rather than aborted or hidden.
//!
//! A weak direction is an eigenvector of the posterior covariance in the
//! priors' units (each parameter divided by its prior σ) whose variance the
//! data do not shrink below half the prior's: the σ along it is above
//! `1/√2` of the prior range, the same limit the hold rule puts on a single
//! parameter ([`super::adjust`]). A degenerate pair of parameters shows as
//! one such direction even when each parameter alone passes the hold rule,
//! because each borrows its σ from the other. Parameters without a prior
//! (the frame's plane) are always determined by the flat points and take
//! no part.

use nalgebra::DMatrix;
use serde::Serialize;

use super::input::CalibrationInput;
use super::params::{difference, Param, State};
use super::residuals::{raw, Blocks, Whitening};

/// A direction's σ, as a fraction of the prior range along it, above which
/// the data are said not to determine it: the hold rule's `1/√2`.
pub const WEAK_RATIO: f64 = std::f64::consts::FRAC_1_SQRT_2;

/// Components smaller than this fraction of the largest are not listed.
const SMALL_COMPONENT: f64 = 0.1;

/// One weakly determined combination of parameters.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WeakDirection {
    /// Its σ over the prior range along it (1: the data add nothing).
    pub std_over_prior: f64,
    /// The change of each parameter along the direction at 1 σ, in the
    /// parameter's own unit, largest (against its prior) first.
    pub components: Vec<(String, f64)>,
}

impl WeakDirection {
    /// `camera.z_mm +13.1, camera.focal_length_mm +0.92, …`.
    pub fn describe(&self) -> String {
        let parts: Vec<String> = self
            .components
            .iter()
            .map(|(n, v)| format!("{n} {v:+.3e}"))
            .collect();
        format!(
            "σ {:.2} of the prior range along: {}",
            self.std_over_prior,
            parts.join(", ")
        )
    }
}

/// The weak directions of `covariance` over `params` (its leading block,
/// the estimated parameters), worst first.
pub fn weak_directions(covariance: &DMatrix<f64>, params: &[Param]) -> Vec<WeakDirection> {
    let idx: Vec<(usize, f64)> = params
        .iter()
        .enumerate()
        .filter_map(|(k, p)| p.prior_std().map(|sd| (k, sd)))
        .collect();
    let n = idx.len();
    if n == 0 {
        return Vec::new();
    }
    let scaled = DMatrix::from_fn(n, n, |a, b| {
        covariance[(idx[a].0, idx[b].0)] / (idx[a].1 * idx[b].1)
    });
    let eig = scaled.symmetric_eigen();
    let mut out: Vec<WeakDirection> = (0..n)
        .filter(|&k| eig.eigenvalues[k] > WEAK_RATIO * WEAK_RATIO)
        .map(|k| {
            let s = eig.eigenvalues[k].sqrt();
            let v = eig.eigenvectors.column(k);
            let big = v.amax();
            let mut comps: Vec<(usize, f64)> = (0..n)
                .filter(|&a| v[a].abs() >= SMALL_COMPONENT * big)
                .map(|a| (a, v[a]))
                .collect();
            comps.sort_by(|x, y| y.1.abs().total_cmp(&x.1.abs()));
            // The sign of an eigenvector is arbitrary: lead with a positive one.
            let sign = comps.first().map_or(1.0, |c| c.1.signum());
            WeakDirection {
                std_over_prior: s,
                components: comps
                    .into_iter()
                    .map(|(a, c)| {
                        let (k, sd) = idx[a];
                        (params[k].name().to_string(), sign * c * s * sd)
                    })
                    .collect(),
            }
        })
        .collect();
    out.sort_by(|a, b| b.std_over_prior.total_cmp(&a.std_over_prior));
    out
}

/// What a failed adjustment did, for its error: the parameters that moved
/// most from `start` (against their prior range, or their difference step
/// where they have none) and the readings with the largest whitened
/// residuals at `end`.
pub fn failure_detail(
    input: &CalibrationInput,
    params: &[Param],
    blocks: Blocks,
    start: &State,
    end: &State,
) -> String {
    let moved = difference(start, end, params);
    let mut by: Vec<(f64, String)> = params
        .iter()
        .zip(&moved)
        .map(|(p, d)| {
            let scale = p.prior_std().unwrap_or(p.step());
            (
                (d / scale).abs(),
                match p.prior_std() {
                    Some(_) => format!("{} by {d:+.4} ({:.2} prior σ)", p.name(), d / scale),
                    None => format!("{} by {d:+.3e}", p.name()),
                },
            )
        })
        .collect();
    by.sort_by(|a, b| b.0.total_cmp(&a.0));
    let moved: Vec<String> = by.into_iter().take(4).map(|m| m.1).collect();
    let readings = worst_readings(input, end, blocks, 4);
    format!(
        "; the parameters that moved most: {}; the readings with the largest residuals: {}",
        moved.join(", "),
        if readings.is_empty() {
            "none".to_string()
        } else {
            readings.join(", ")
        }
    )
}

/// The `count` readings of `blocks` with the largest whitened residuals at
/// `state`, as `target_point[12]: 0.93 px (χ² 135)`.
pub fn worst_readings(
    input: &CalibrationInput,
    state: &State,
    blocks: Blocks,
    count: usize,
) -> Vec<String> {
    let r = raw(input, state, blocks);
    let Ok(w) = Whitening::at(input, state) else {
        return Vec::new();
    };
    let s = input.stage_std_mm;
    let mut all: Vec<(f64, String)> = Vec::new();
    let mut scalar = |entry: &str, v: &[f64]| {
        for (k, z) in v.iter().enumerate() {
            let chi = (z / s).powi(2);
            all.push((
                chi,
                format!("{entry}[{k}]: {:.1} µm (χ² {chi:.1})", z * 1e3),
            ));
        }
    };
    scalar("flat_point", &r.flat_points);
    scalar("element_point", &r.element_points);
    for (k, (v, l)) in r.targets.iter().zip(&w.targets).enumerate() {
        let chi = (l * v).norm_squared();
        all.push((
            chi,
            format!("target_point[{k}]: {:.3} px (χ² {chi:.1})", v.norm()),
        ));
    }
    for ((v, l), f) in r.flat_map.iter().zip(&w.flat_map).zip(&input.flat_screen) {
        let chi = (l * v).norm_squared();
        let [i, j] = f.pixel;
        all.push((
            chi,
            format!(
                "reference flat pixel ({i}, {j}): {:.3} screen px (χ² {chi:.1})",
                v.norm()
            ),
        ));
    }
    for (k, (v, l)) in r.screen_points.iter().zip(&w.screen_points).enumerate() {
        let chi = (l * v).norm_squared();
        all.push((
            chi,
            format!("screen_point[{k}]: {:.4} mm (χ² {chi:.1})", v.norm()),
        ));
    }
    // A residual with no model value (NaN) is the worst of all.
    all.sort_by(|a, b| {
        let key = |x: f64| if x.is_nan() { f64::INFINITY } else { x };
        key(b.0).total_cmp(&key(a.0))
    });
    all.into_iter().take(count).map(|a| a.1).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::station::Dof;

    #[test]
    fn a_pair_seen_only_through_its_sum_is_one_weak_direction() {
        // Data y = a + b with σ = 1 against priors of 10 each: the posterior
        // along a − b keeps the prior's σ (ratio 1), along a + b the data
        // shrink it to 1/√(1/100·2 + 1)·… ≈ 0.07 of the prior.
        let p = [Param::Station(Dof::CameraZ), Param::Station(Dof::ScreenZ)];
        let n = DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 1.0, 1.0])
            + DMatrix::from_diagonal_element(2, 2, 1.0 / 100.0);
        let c = n.try_inverse().unwrap();
        let w = weak_directions(&c, &p);
        assert_eq!(w.len(), 1);
        assert!((w[0].std_over_prior - 1.0).abs() < 1e-9);
        let comps = &w[0].components;
        assert_eq!(comps.len(), 2);
        // Opposite signs, each 10/√2 mm at 1 σ.
        assert!((comps[0].1 + comps[1].1).abs() < 1e-9);
        assert!((comps[0].1.abs() - 10.0 / 2f64.sqrt()).abs() < 1e-9);
    }

    #[test]
    fn well_determined_parameters_give_none() {
        let p = [Param::Station(Dof::CameraZ), Param::Station(Dof::ScreenZ)];
        let c = DMatrix::from_diagonal_element(2, 2, 0.01);
        assert!(weak_directions(&c, &p).is_empty());
    }
}

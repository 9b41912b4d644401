//! What the station's uncertainty does to the surfaces: the covariance of
//! the reported coefficients induced by a `mfd-station-uncertainty/1`,
//! beside the noise-only covariance the solver reports.
//!
//! Each degree of freedom with a σ is applied to the station by one σ
//! (`Station::perturbed`, the spec's exact change), the same observations
//! are re-solved on the changed station (the camera rays re-derived from
//! it), and the coefficients' change per σ is that degree's column of the
//! sensitivity `J`. The induced covariance is `J Σ Jᵀ` with `Σ` the
//! station's correlation (its covariance scaled to unit σ). Re-solving
//! rather than linearising the normal equations keeps the stages'
//! nonlinearity (the front's reflection points, the back's paths) exact;
//! a one-σ step is the budget's own scale, so the linear propagation it
//! feeds is tested where it is used (`tests/it/station_v2.rs`).

use nalgebra::{DMatrix, Unit};

use super::{reconstruct, Observations, SurfaceError, SurfaceOptions, SurfaceSolution};
use crate::optics::station::{Dof, Station, StationUncertainty};

/// One degree of freedom's share of the surfaces' error.
#[derive(Debug, Clone, PartialEq)]
pub struct DofShare {
    /// The degree of freedom.
    pub dof: Dof,
    /// Its 1σ, in its unit.
    pub std: f64,
    /// RMS over the aperture (Noll j ≥ 4) of the front's change per σ, nm.
    pub front_rms_nm: f64,
    /// The same for the back, nm.
    pub back_rms_nm: f64,
}

/// The station-induced covariance of both surfaces.
#[derive(Debug, Clone, PartialEq)]
pub struct StationInduced {
    /// Covariance of the front coefficients (all Noll terms of the solution), nm².
    pub front_cov_nm2: DMatrix<f64>,
    /// Covariance of the back coefficients, nm².
    pub back_cov_nm2: DMatrix<f64>,
    /// Expected RMS error over the aperture from the station alone, piston
    /// and tilt removed (√ of the trace over j ≥ 4), front, nm.
    pub front_rms_nm: f64,
    /// The same for the back, nm.
    pub back_rms_nm: f64,
    /// Each degree of freedom's share, largest first.
    pub shares: Vec<DofShare>,
}

/// The observations' camera rays re-derived from `station` (in its
/// element frame), everything measured kept.
pub fn with_station(obs: &Observations, station: &Station) -> Observations {
    let local = station.element_frame();
    let cam = &local.camera;
    let mut out = obs.clone();
    out.camera = cam.position_mm;
    for p in &mut out.pixels {
        let d: Unit<_> = cam.ray_direction(p.pixel[0], p.pixel[1]);
        p.dir = d.into_inner();
    }
    out
}

/// Each degree of freedom's change of the coefficients per σ (front,
/// back; all the base solution's terms), `None` where its σ is 0.
pub type Columns = Vec<Option<(Vec<f64>, Vec<f64>)>>;

/// Re-solves `obs` on `station` changed by one σ of every degree of
/// freedom of `uncertainty`, with the base solution's numbers of terms
/// fixed: the change of every coefficient per σ, in `uncertainty.names` order.
///
/// # Errors
/// [`SurfaceError`] when a changed station's solve fails.
pub fn station_induced_columns(
    obs: &Observations,
    station: &Station,
    uncertainty: &StationUncertainty,
    base: &SurfaceSolution,
    opts: &SurfaceOptions,
) -> Result<Columns, SurfaceError> {
    let (nf, nb) = (
        base.front.coefficients_nm().len(),
        base.back.coefficients_nm().len(),
    );
    let fixed = SurfaceOptions {
        terms: Some(nf.max(nb)),
        ..opts.clone()
    };
    let reference = reconstruct(obs, station, &fixed)?;
    let diff = |a: &[f64], b: &[f64], n: usize| -> Vec<f64> {
        (0..n)
            .map(|i| a.get(i).copied().unwrap_or(0.0) - b.get(i).copied().unwrap_or(0.0))
            .collect()
    };
    let mut out = Vec::new();
    for (k, &dof) in uncertainty.names.iter().enumerate() {
        let sigma = uncertainty.covariance[(k, k)].sqrt();
        if sigma == 0.0 {
            out.push(None);
            continue;
        }
        let changed = station.perturbed(dof, sigma);
        let sol = reconstruct(&with_station(obs, &changed), &changed, &fixed)?;
        let f = &reference.front;
        let df = diff(sol.front.coefficients_nm(), f.coefficients_nm(), nf);
        let b = &reference.back;
        let db = diff(sol.back.coefficients_nm(), b.coefficients_nm(), nb);
        out.push(Some((df, db)));
    }
    Ok(out)
}

/// The station-induced covariance from [`station_induced_columns`]: each
/// column's `J Σ Jᵀ`, and each degree of freedom's share.
///
/// # Errors
/// [`SurfaceError`] when a changed station's solve fails.
pub fn station_induced(
    obs: &Observations,
    station: &Station,
    uncertainty: &StationUncertainty,
    base: &SurfaceSolution,
    opts: &SurfaceOptions,
) -> Result<StationInduced, SurfaceError> {
    let (nf, nb) = (
        base.front.coefficients_nm().len(),
        base.back.coefficients_nm().len(),
    );
    let columns = station_induced_columns(obs, station, uncertainty, base, opts)?;
    Ok(from_columns(&columns, uncertainty, nf, nb))
}

/// The station-induced covariance of per-σ columns (front `nf`, back `nb`
/// long, in `uncertainty.names` order): `J Σ Jᵀ` with `Σ` the station's
/// correlation, and each degree of freedom's share, largest first.
pub fn from_columns(
    columns: &Columns,
    uncertainty: &StationUncertainty,
    nf: usize,
    nb: usize,
) -> StationInduced {
    let m = uncertainty.names.len();
    let mut jf = DMatrix::zeros(nf, m);
    let mut jb = DMatrix::zeros(nb, m);
    let mut shares = Vec::new();
    let sigmas: Vec<f64> = (0..m)
        .map(|k| uncertainty.covariance[(k, k)].sqrt())
        .collect();
    for (k, col) in columns.iter().enumerate() {
        let Some((df, db)) = col else { continue };
        jf.column_mut(k).copy_from_slice(df);
        jb.column_mut(k).copy_from_slice(db);
        shares.push(DofShare {
            dof: uncertainty.names[k],
            std: sigmas[k],
            front_rms_nm: rms_from(df),
            back_rms_nm: rms_from(db),
        });
    }
    // The station's correlation: its covariance with unit σ (J is per σ).
    let corr = DMatrix::from_fn(m, m, |r, c| {
        let s = sigmas[r] * sigmas[c];
        if s > 0.0 {
            uncertainty.covariance[(r, c)] / s
        } else {
            0.0
        }
    });
    let front_cov_nm2 = &jf * &corr * jf.transpose();
    let back_cov_nm2 = &jb * &corr * jb.transpose();
    shares.sort_by(|a, b| {
        (b.front_rms_nm.hypot(b.back_rms_nm)).total_cmp(&a.front_rms_nm.hypot(a.back_rms_nm))
    });
    StationInduced {
        front_rms_nm: trace_from_defocus(&front_cov_nm2),
        back_rms_nm: trace_from_defocus(&back_cov_nm2),
        front_cov_nm2,
        back_cov_nm2,
        shares,
    }
}

/// RMS over the aperture of a coefficient change, piston and tilt removed
/// (Noll-normalised terms are orthonormal: the root sum of squares from j = 4).
fn rms_from(d: &[f64]) -> f64 {
    d.iter().skip(3).fold(0.0, |s, x| s + x * x).sqrt()
}

/// √ of the covariance's trace over Noll j ≥ 4.
fn trace_from_defocus(c: &DMatrix<f64>) -> f64 {
    (3..c.nrows()).map(|k| c[(k, k)]).sum::<f64>().sqrt()
}

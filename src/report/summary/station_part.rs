//! The station's part of a summary: what the station's uncertainty adds to
//! each surface's error beside the noise (the error budget's split per
//! surface), and the degrees of freedom that contribute most.

use nalgebra::DMatrix;

use crate::optics::outline::Outline;
use serde::{Deserialize, Serialize};

use super::{Summary, UNCERTAINTY_WITH_STATION};
use crate::budget::{Budget, DofEntry};
use crate::solve::surfaces::report::{SurfaceFigures, REMOVED_TERMS};

/// What the station's uncertainty adds to each surface's error, beside the
/// noise-only figures (a station uncertainty given or found beside the
/// station file).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StationPart {
    /// How the station-induced part was computed ([`STATION_NOTE`]).
    pub note: String,
    /// The front's split.
    pub front: ErrorSplit,
    /// The back's split; `null` when it was not reconstructed.
    pub back: Option<ErrorSplit>,
    /// The degrees of freedom that contribute most, largest first (at most
    /// [`LISTED_SHARES`]).
    pub largest: Vec<Share>,
}

/// Noise-only, station-induced and total expected error of one surface.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ErrorSplit {
    /// Expected RMS error from the noise, piston and tilt removed, nm.
    pub noise_rms_nm: f64,
    /// Expected RMS error from the station's uncertainty, nm.
    pub station_rms_nm: f64,
    /// Everything together (√ of the trace over j ≥ 4 of the budget's total
    /// covariance), nm: `expected_error_rms_nm` of `surfaces.json`.
    pub total_rms_nm: f64,
    /// Per-coefficient σ from the noise alone, nm (Noll j = k + 1 at index k).
    pub noise_std_nm: Vec<f64>,
    /// Per-coefficient σ from the station alone, nm.
    pub station_std_nm: Vec<f64>,
    /// Per-coefficient σ of everything together, nm: `std_nm` of
    /// `surfaces.json`.
    pub total_std_nm: Vec<f64>,
}

/// One degree of freedom's share.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Share {
    /// Its spec name (`interchange.md`, e.g. `camera.z_mm`).
    pub name: String,
    /// Its 1σ, in the unit of its name.
    pub std: f64,
    /// The front's RMS change for one σ (j ≥ 4), nm.
    pub front_rms_nm: f64,
    /// The back's, nm (0 when the back was not reconstructed).
    pub back_rms_nm: f64,
    /// `front_rms_nm²` over the front's total expected error squared: the
    /// fraction of it this degree of freedom makes alone (correlations
    /// between degrees of freedom are in the total, not in the fractions).
    pub front_share: f64,
    /// The same for the back.
    pub back_share: f64,
}

/// Degrees of freedom listed in [`StationPart::largest`], at most.
pub const LISTED_SHARES: usize = 10;

/// How the station-induced part is computed, for the summary's reader.
pub const STATION_NOTE: &str = "the error budget's sensitivity of every coefficient to every \
degree of freedom of the station uncertainty (the same screen points re-solved on the station \
assumed otherwise), times its 1 sigma; covariance S C S^T with C the station's correlation; \
noise and station parts independent";

impl Summary {
    /// The summary with the station's part from `budget` (of the same
    /// solution) beside the noise's.
    pub fn with_budget(mut self, budget: &Budget) -> Summary {
        let over = self.over.clone();
        let over = over.as_ref();
        let front = split(&self.front, budget, false, over);
        let back = self
            .back
            .as_ref()
            .filter(|_| budget.back_fitted)
            .map(|b| split(b, budget, true, over));
        let total = |s: Option<&ErrorSplit>| s.map_or(0.0, |s| s.total_rms_nm);
        let (tf, tb) = (total(Some(&front)), total(back.as_ref()));
        let mut largest: Vec<Share> = budget
            .dofs
            .iter()
            .map(|d| {
                let f = rms_over(&d.front_contribution_nm(), over);
                let b = rms_over(&d.back_contribution_nm(), over);
                Share {
                    name: d.dof.name().into(),
                    std: d.std,
                    front_rms_nm: f,
                    back_rms_nm: b,
                    front_share: fraction(f, tf),
                    back_share: fraction(b, tb),
                }
            })
            .collect();
        largest.sort_by(|a, b| {
            (b.front_rms_nm.hypot(b.back_rms_nm)).total_cmp(&a.front_rms_nm.hypot(a.back_rms_nm))
        });
        largest.truncate(LISTED_SHARES);
        self.uncertainty_note = UNCERTAINTY_WITH_STATION.into();
        self.station = Some(StationPart {
            note: STATION_NOTE.into(),
            front,
            back,
            largest,
        });
        self
    }
}

/// One surface's split: the noise from its figures, the station's
/// `S C Sᵀ` from the budget's degrees of freedom, the total from the
/// budget's total covariance.
fn split(
    noise: &SurfaceFigures,
    budget: &Budget,
    back: bool,
    over: Option<&Outline>,
) -> ErrorSplit {
    let n = noise.std_nm.len();
    let per_sigma = |d: &DofEntry| {
        if back {
            d.back_contribution_nm()
        } else {
            d.front_contribution_nm()
        }
    };
    let s = DMatrix::from_fn(n, budget.dofs.len(), |i, k| {
        per_sigma(&budget.dofs[k]).get(i).copied().unwrap_or(0.0)
    });
    let station = &s * &budget.correlation * s.transpose();
    let total = if back {
        &budget.back_total_cov_nm2
    } else {
        &budget.front_total_cov_nm2
    };
    let diag = |c: &DMatrix<f64>| -> Vec<f64> {
        (0..n)
            .map(|k| {
                if k < c.nrows() {
                    c[(k, k)].max(0.0).sqrt()
                } else {
                    0.0
                }
            })
            .collect()
    };
    let (station_std_nm, total_std_nm) = (diag(&station), diag(total));
    // Over an outline other than the disk, through its orthonormal set.
    let expected = |c: &DMatrix<f64>, std: &[f64]| match over.map(|o| o.orthonormal(n)) {
        Some(Ok(q)) if !q.is_identity() => q.expected_rms(c, REMOVED_TERMS),
        _ => rms_from_defocus(std),
    };
    ErrorSplit {
        noise_rms_nm: noise.error_rms_nm,
        station_rms_nm: expected(&station, &station_std_nm),
        // The truncation's part is the model's, beside noise and station.
        total_rms_nm: expected(total, &total_std_nm).hypot(noise.truncation_rms_nm),
        noise_std_nm: noise.std_nm.clone(),
        station_std_nm,
        total_std_nm,
    }
}

/// The RMS over the outline (the plane removed) of the coefficient
/// shifts `v`: [`rms_from_defocus`] for the disk.
fn rms_over(v: &[f64], over: Option<&Outline>) -> f64 {
    match over.map(|o| o.orthonormal(v.len())) {
        Some(Ok(q)) if !q.is_identity() => q.rms(v, REMOVED_TERMS),
        _ => rms_from_defocus(v),
    }
}

/// Root sum of squares from Noll j = 4 (RMS-normalised terms are
/// orthonormal over the aperture: the RMS with piston and tilt removed).
fn rms_from_defocus(v: &[f64]) -> f64 {
    v.iter()
        .skip(REMOVED_TERMS)
        .map(|x| x * x)
        .sum::<f64>()
        .sqrt()
}

/// `(part / whole)²`, 0 for a zero whole.
fn fraction(part: f64, whole: f64) -> f64 {
    if whole > 0.0 {
        (part / whole).powi(2)
    } else {
        0.0
    }
}

//! The front surface from S1 alone: slopes by the exact vector law of
//! reflection at the point where each camera ray meets the current surface
//! estimate, a modal (Zernike gradient) fit, and again from the new surface
//! until the reflection points stop moving (paper Eq. 1, 9–10).

use nalgebra::{DMatrix, DVector, Point3};

use super::{Observations, SurfaceError};
use crate::optics::station::Station;
use crate::optics::trace::{intersect, Plate};
use crate::optics::zernike::{ZernikeBasis, ZernikeSurface};

/// One slope measurement: where, the two slopes, and the weight.
#[derive(Debug, Clone, Copy)]
struct Slope {
    x: f64,
    y: f64,
    sx: f64,
    sy: f64,
    w: f64,
}

/// Weighted least-squares fit of Zernike gradients (terms j ≥ 2) to the
/// slopes, by normal equations built on all cores (the modal slope problem
/// is well conditioned, κ ≈ 100 for 150 terms on a full disk, so squaring it
/// costs nothing measurable). Returns nm coefficients (piston 0), the
/// condition number of the weighted design matrix and the length of the
/// coefficients' σ vector, nm (√ of the trace of their covariance at the
/// slopes' σ).
fn fit_slopes_parallel(
    basis: &ZernikeBasis,
    pts: &[Slope],
) -> Result<(Vec<f64>, f64, f64), SurfaceError> {
    let n = basis.n_terms();
    let p = n - 1;
    if 2 * pts.len() < p {
        return Err(SurfaceError::TooFewPoints {
            stage: "front slopes",
            have: 2 * pts.len(),
            need: p,
        });
    }
    let zero = || (DMatrix::<f64>::zeros(p, p), DVector::<f64>::zeros(p));
    // Summed in chunk order (collected first): a reduction joined in the
    // order work stealing finishes would change the last bits run to run.
    let (a, b) = crate::kernels::ordered::chunk_sum(
        pts,
        crate::kernels::ordered::SUM_CHUNK,
        zero(),
        |chunk| {
            let mut cols = DMatrix::<f64>::zeros(p, 2 * chunk.len());
            let mut rhs = DVector::<f64>::zeros(2 * chunk.len());
            let (mut v, mut gx, mut gy) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
            for (k, s) in chunk.iter().enumerate() {
                // Lengths match by construction.
                let _ = basis.eval_into(s.x, s.y, &mut v, &mut gx, &mut gy);
                let r = s.w.sqrt();
                for t in 1..n {
                    // Slopes are mm/mm, coefficients nm: ∂W/∂x = Σ c ∂Z/∂x · 1e-6.
                    cols[(t - 1, 2 * k)] = gx[t] * 1e-6 * r;
                    cols[(t - 1, 2 * k + 1)] = gy[t] * 1e-6 * r;
                }
                rhs[2 * k] = s.sx * r;
                rhs[2 * k + 1] = s.sy * r;
            }
            let a = crate::kernels::gram::gram_of_columns(cols.as_slice(), p, 2 * chunk.len());
            let mut b = DVector::<f64>::zeros(p);
            b.gemv(1.0, &cols, &rhs, 0.0);
            (a, b)
        },
        |x, y| (x.0 + y.0, x.1 + y.1),
    );
    let eig = a.clone().symmetric_eigen().eigenvalues;
    let (lo, hi) = (eig.min(), eig.max());
    let condition_number = if lo > 0.0 {
        (hi / lo).sqrt()
    } else {
        f64::INFINITY
    };
    let chol = a
        .cholesky()
        .filter(|_| condition_number <= super::lm::MAX_CONDITION_NUMBER)
        .ok_or(SurfaceError::IllConditioned {
            stage: "front slopes",
            condition_number,
        })?;
    let x = chol.solve(&b);
    let sigma_nm = chol.inverse().trace().max(0.0).sqrt();
    let mut c = vec![0.0; n];
    c[1..].copy_from_slice(x.as_slice());
    Ok((c, condition_number, sigma_nm))
}

/// How the slope iteration ended.
#[derive(Debug, Clone, PartialEq)]
pub struct FrontReport {
    /// Iterations run (slope fits).
    pub iterations: usize,
    /// Length of the change of the coefficient vector in the last
    /// iteration, nm (√ of the sum of squared changes).
    pub last_change_nm: f64,
    /// Whether the change fell below [`CHANGE_TOL_NM`] (else the iteration
    /// limit stopped it).
    pub converged: bool,
    /// Length of the coefficients' σ vector at the slopes' σ, nm: what
    /// `last_change_nm` is measured against.
    pub sigma_nm: f64,
    /// Condition number of the last slope fit.
    pub condition_number: f64,
    /// Pixels whose slopes entered.
    pub points: usize,
}

/// Stop when the coefficients move less than this between iterations, nm
/// RMS: far below any measurable height (1 pm).
pub const CHANGE_TOL_NM: f64 = 1e-3;

/// The front with `terms` Noll terms from the S1 points of `obs`; piston is
/// 0 (the reference plane of the station defines it: slopes cannot).
///
/// # Errors
/// [`SurfaceError::Zernike`] when the slope fit fails (too few points,
/// ill-conditioned), [`SurfaceError::TooFewPoints`] without S1 data.
pub fn front_from_slopes(
    obs: &Observations,
    station: &Station,
    plate: &Plate,
    terms: usize,
    max_iter: usize,
) -> Result<(ZernikeSurface, FrontReport), SurfaceError> {
    let b0 = plate.front.basis();
    let basis = ZernikeBasis::new(terms, b0.radius_mm(), b0.center_mm())?;
    let mut front = ZernikeSurface::new(basis.clone(), vec![0.0; terms])?;
    let mut report = FrontReport {
        iterations: 0,
        last_change_nm: f64::INFINITY,
        converged: false,
        sigma_nm: f64::NAN,
        condition_number: f64::NAN,
        points: 0,
    };
    let pitch = station.screen.pixel_pitch_mm;
    for _ in 0..max_iter.max(1) {
        let mut pts = Vec::with_capacity(obs.pixels.len());
        for ob in obs.pixels.iter().filter(|o| o.has(0)) {
            let d = nalgebra::Unit::new_unchecked(ob.dir);
            let Ok(hit) = intersect(&obs.camera, &d, &front, 0.0) else {
                continue;
            };
            let p: Point3<f64> = hit.point;
            let s = station.screen.world_point(ob.s[0][0], ob.s[0][1]);
            let to_screen = s - p;
            let dist = to_screen.norm();
            // The reflected ray's direction: straight at the screen point, or
            // bent so that the cover glass takes it there.
            let out = match station.screen.cover_glass {
                None => to_screen / dist,
                Some(_) => match station.screen.aim(&p, ob.s[0][0], ob.s[0][1]) {
                    Some(d) => d.into_inner(),
                    None => continue,
                },
            };
            let n = (out - ob.dir).normalize();
            // A screen error δ (mm) turns the reflected ray by δ/dist and the
            // normal by half that.
            let sigma = 0.5 * (ob.sigma(0, 0) + ob.sigma(0, 1)) * pitch / (2.0 * dist);
            pts.push(Slope {
                x: p.x,
                y: p.y,
                sx: -n.x / n.z,
                sy: -n.y / n.z,
                w: 1.0 / (sigma * sigma),
            });
        }
        if pts.is_empty() {
            return Err(SurfaceError::TooFewPoints {
                stage: "front slopes",
                have: 0,
                need: terms - 1,
            });
        }
        let (coefficients, condition_number, sigma_nm) = fit_slopes_parallel(&basis, &pts)?;
        let change = coefficients
            .iter()
            .zip(front.coefficients_nm())
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt();
        front = ZernikeSurface::new(basis.clone(), coefficients)?;
        report.iterations += 1;
        report.last_change_nm = change;
        report.condition_number = condition_number;
        report.points = pts.len();
        report.sigma_nm = sigma_nm;
        if change < CHANGE_TOL_NM {
            report.converged = true;
            break;
        }
    }
    Ok((front, report))
}

//! The front surface from S1 alone: slopes by the exact vector law of
//! reflection at the point where each camera ray meets the current surface
//! estimate, a modal (Zernike gradient) fit, and again from the new surface
//! until the reflection points stop moving (paper Eq. 1, 9–10).

use nalgebra::Point3;

use super::{Observations, SurfaceError};
use crate::station::Station;
use crate::trace::{intersect, Plate};
use crate::zernike::{fit_slopes, ZernikeBasis, ZernikeSurface};

/// How the slope iteration ended.
#[derive(Debug, Clone, PartialEq)]
pub struct FrontReport {
    /// Iterations run (slope fits).
    pub iterations: usize,
    /// RMS change of the coefficients in the last iteration, nm.
    pub last_change_nm: f64,
    /// Condition number of the last slope fit.
    pub condition_number: f64,
    /// Pixels whose slopes entered.
    pub points: usize,
}

/// Stop when the coefficients move less than this between iterations, nm
/// RMS: far below any measurable height (1 pm).
const CHANGE_TOL_NM: f64 = 1e-3;

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
        condition_number: f64::NAN,
        points: 0,
    };
    let pitch = station.screen.pixel_pitch_mm;
    for _ in 0..max_iter.max(1) {
        let (mut xs, mut ys, mut sx, mut sy, mut w) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for ob in obs.pixels.iter().filter(|o| o.has(0)) {
            let d = nalgebra::Unit::new_unchecked(ob.dir);
            let Ok(hit) = intersect(&obs.camera, &d, &front, 0.0) else {
                continue;
            };
            let p: Point3<f64> = hit.point;
            let s = station.screen.world_point(ob.s[0][0], ob.s[0][1]);
            let to_screen = s - p;
            let dist = to_screen.norm();
            let n = (to_screen / dist - ob.dir).normalize();
            xs.push(p.x);
            ys.push(p.y);
            sx.push(-n.x / n.z);
            sy.push(-n.y / n.z);
            // A screen error δ (mm) turns the reflected ray by δ/dist and the
            // normal by half that.
            let sigma = 0.5 * (ob.sigma(0, 0) + ob.sigma(0, 1)) * pitch / (2.0 * dist);
            w.push(1.0 / (sigma * sigma));
        }
        if xs.is_empty() {
            return Err(SurfaceError::TooFewPoints {
                stage: "front slopes",
                have: 0,
                need: terms - 1,
            });
        }
        let fit = fit_slopes(&basis, &xs, &ys, &sx, &sy, Some(&w))?;
        let change = fit
            .coefficients_nm
            .iter()
            .zip(front.coefficients_nm())
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt();
        front = ZernikeSurface::new(basis.clone(), fit.coefficients_nm)?;
        report.iterations += 1;
        report.last_change_nm = change;
        report.condition_number = fit.condition_number;
        report.points = xs.len();
        if change < CHANGE_TOL_NM {
            break;
        }
    }
    Ok((front, report))
}

//! The session check's look at the marked screen pixels
//! (`[[screen_point]]`), before anything is solved: the marks lie on one
//! plane grid, so each reading's world position is an affine function of
//! its `(u, v)` whatever the screen's pose and pitch. Each mark is
//! predicted from the others (leave-one-out least squares) and the worst
//! is flagged when it stands beyond the stage's noise (and the PSM's focus
//! spread through the cover glass); then the check is repeated without it,
//! since one wrong reading pulls the others' fits too.

use nalgebra::{Matrix3, Unit, Vector3};

use super::check::{CheckReport, Severity};
use super::frame::WorldFrame;
use super::screen_mark::mark_focus;
use super::session::Session;
use super::spread::chi2_quantile_999;

/// An affine map from `(u, v)` to a world point has 3 × 3 parameters, so
/// three marks off one line fix it; a fourth is needed to predict a fifth
/// with any redundancy.
const MIN_MARKS: usize = 5;

/// The least-squares affine map `w = X [u, v, 1]` through `marks`, and
/// `(AᵀA)⁻¹` for the prediction's leverage; `None` for marks on one line.
fn affine(marks: &[([f64; 2], Vector3<f64>)]) -> Option<(Matrix3<f64>, Matrix3<f64>)> {
    let mut ata = Matrix3::zeros();
    let mut atw = Matrix3::zeros();
    for ([u, v], w) in marks {
        let a = Vector3::new(*u, *v, 1.0);
        ata += a * a.transpose();
        atw += a * w.transpose();
    }
    let inv = ata.try_inverse()?;
    Some(((inv * atw).transpose(), inv))
}

/// Adds a finding per wrong-looking mark.
pub(super) fn mark_findings(session: &Session, frame: &WorldFrame, report: &mut CheckReport) {
    let axis = Unit::new_normalize(frame.world_from_stage.rotation * Vector3::z());
    let screen = &session.nominal.screen;
    let s2 = session.stage_std_mm.powi(2);
    let mut marks: Vec<(usize, [f64; 2], Vector3<f64>, f64)> = session
        .screen_points
        .iter()
        .enumerate()
        .map(|(k, m)| {
            let w = frame.to_world(&m.stage_mm).coords;
            // The focus's spread along the PSM's axis on the nominal screen
            // (rank one: its trace is its variance along the axis).
            let spread = mark_focus(screen, &axis, m.screen_px.x, m.screen_px.y)
                .focus_cov_mm2
                .trace();
            (k, [m.screen_px.x, m.screen_px.y], w, spread)
        })
        .collect();
    let limit = chi2_quantile_999(3.0);
    while marks.len() >= MIN_MARKS {
        // Each mark's squared distance from the others' map, in units of
        // its variance: the reading's (isotropic stage noise, plus the
        // focus spread, taken on every axis: an upper bound) times 1 + h.
        let mut worst: Option<(usize, f64, f64)> = None;
        for j in 0..marks.len() {
            let others: Vec<([f64; 2], Vector3<f64>)> = marks
                .iter()
                .enumerate()
                .filter(|(i, _)| *i != j)
                .map(|(_, m)| (m.1, m.2))
                .collect();
            let Some((x, inv)) = affine(&others) else {
                return;
            };
            let (_, uv, w, spread) = marks[j];
            let a = Vector3::new(uv[0], uv[1], 1.0);
            let leverage = a.dot(&(inv * a));
            let r = (w - x * a).norm();
            let z2 = r * r / ((s2 + spread) * (1.0 + leverage));
            if worst.is_none_or(|(_, z, _)| z2 > z) {
                worst = Some((j, z2, r));
            }
        }
        let Some((j, z2, r)) = worst.filter(|&(_, z2, _)| z2 > limit) else {
            return;
        };
        let index = marks[j].0;
        report.push(
            Severity::Warning,
            Some(format!("screen_point[{index}]")),
            format!(
                "screen point {index}'s reading is {r:.3} mm off the plane grid the other marks \
                 follow (χ² {z2:.0} over 3 axes against the stage noise; 99.9 % of right \
                 readings stay below {limit:.1}): wrong reading or wrong mark?"
            ),
        );
        marks.remove(j);
    }
}

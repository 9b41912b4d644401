//! The check's look at the session's layout before solving: whether the
//! targets, as placed, leave a combination of the camera's parameters
//! weakly determined ([`super::weak`]) — the "dolly zoom" of a
//! narrow-field camera far from target layers close together, where the
//! camera slides along its line of sight while the focal length follows
//! and the targets' images barely change — and what would fix it.
//!
//! It asks the adjustment itself: the data's normal matrix of the
//! resection (targets alone, camera parameters) at the nominal station,
//! with every target where the nominal station projects it and its
//! centroid's σ, plus the priors; the weak directions of its inverse are
//! the ones the resection will report. The reference flat may determine
//! part of such a direction later (the check does not decode it), so the
//! finding is a warning, and the solve names what stays weak.

use nalgebra::{DMatrix, Point2, Vector3};

use super::adjust::information;
use super::check::{CheckReport, Severity};
use super::hold::select;
use super::input::{CalibrationInput, Target};
use super::params::{Param, State, WorldFrame};
use super::resect::camera_params;
use super::residuals::Blocks;
use super::session::Session;
use super::weak::weak_directions;

/// The data-alone σ along a direction, as a fraction of its prior, that a
/// layout should reach: half the prior, where the posterior σ is 0.45 of
/// it, well inside the hold rule's `1/√2` ([`super::weak::WEAK_RATIO`]).
const WANTED_DATA_RATIO: f64 = 0.5;

/// Warns when the targets leave a weak direction; `sigma_px` is a
/// centroid's σ.
pub(super) fn layout_findings(session: &Session, sigma_px: f64, report: &mut CheckReport) {
    let stage = |p: &nalgebra::Point3<f64>| Vector3::new(p.x, p.y, p.z);
    let flat: Vec<Vector3<f64>> = session.flat_points_mm.iter().map(stage).collect();
    let Some(frame) = WorldFrame::fit(&flat, session.element.center_stage_mm) else {
        return;
    };
    let cam = &session.nominal.camera;
    let targets: Vec<Target> = session
        .targets
        .iter()
        .filter_map(|t| {
            let px = cam.project(&frame.to_world(&stage(&t.stage_mm)))?;
            Some(Target {
                stage_mm: stage(&t.stage_mm),
                pixel: Point2::from(px.coords),
                pixel_cov_px2: nalgebra::Matrix2::identity() * sigma_px * sigma_px,
            })
        })
        .collect();
    if targets.len() < 6 {
        return;
    }
    let heights: Vec<f64> = targets
        .iter()
        .map(|t| frame.to_world(&t.stage_mm).z)
        .collect();
    let span = heights.iter().copied().fold(f64::NEG_INFINITY, f64::max)
        - heights.iter().copied().fold(f64::INFINITY, f64::min);
    let input = CalibrationInput {
        nominal: session.nominal.clone(),
        stage_std_mm: session.stage_std_mm,
        element_center_stage_mm: session.element.center_stage_mm,
        thickness_mm: (
            session.element.thickness_mm,
            session.element.thickness_std_mm,
        ),
        refractive_index: (
            session.element.refractive_index,
            session.element.refractive_index_std,
        ),
        flat_points_stage_mm: flat,
        element_points_stage_mm: Vec::new(),
        targets,
        flat_screen: Vec::new(),
        screen_points: Vec::new(),
    };
    let state = State {
        frame,
        station: session.nominal.clone(),
    };
    let params = camera_params(&session.nominal.camera);
    let blocks = Blocks::TARGETS;
    let Ok(n) = information(&input, &state, &params, blocks) else {
        return;
    };
    // What the resection will hold (a lens's k3 that no narrow field
    // shows) is not a finding: the same rule first, on what is left.
    let (keep, selection) = select(&n, &params);
    let distance = (cam.position_mm - frame.to_world(&input.targets[0].stage_mm)).norm();
    // A held pose or focal length is the weakest direction of all: the
    // targets know it no better than the nominal station. Not a layout
    // finding: a distortion coefficient held (a lens the field does not
    // show), or the principal point (in a narrow field it trades with a
    // turn of the camera, which takes its effect on every ray; no spread
    // of layers separates the two).
    for h in selection.held.iter().filter(|h| !is_lens_only(&h.name)) {
        let data_ratio = data_ratio(h.marginal_std / h.prior_std);
        report.push(
            Severity::Warning,
            Some("target_point".into()),
            format!(
                "the targets alone do not determine {} (σ {:.3e} with its prior range {:.3e}; the \
                 camera {distance:.0} mm from the targets): the resection will hold it at the \
                 nominal value; to determine it, take {}{}",
                h.name,
                h.marginal_std,
                h.prior_std,
                fix(span, data_ratio),
                marks(session)
            ),
        );
    }
    let params: Vec<Param> = keep.iter().map(|&i| params[i]).collect();
    let n = DMatrix::from_fn(keep.len(), keep.len(), |a, b| n[(keep[a], keep[b])]);
    let Some(cov) = posterior(&n, &params) else {
        return;
    };
    for w in weak_directions(&cov, &params) {
        let data_ratio = data_ratio(w.std_over_prior);
        report.push(
            Severity::Warning,
            Some("target_point".into()),
            format!(
                "the targets alone leave a combination of the camera's parameters weakly \
                 determined ({}; the camera {distance:.0} mm from the targets): the reference \
                 flat may fix part of it, and the solve reports what stays weak; to determine \
                 it, take {}{}",
                w.describe(),
                fix(span, data_ratio),
                marks(session)
            ),
        );
    }
}

/// The data-alone σ over the prior from the posterior's: a posterior
/// variance ratio `v = 1 / (1 + d)`, d the data's precision in prior units,
/// so the data alone give `1/√d`.
fn data_ratio(posterior_ratio: f64) -> f64 {
    let v = posterior_ratio * posterior_ratio;
    if v < 1.0 {
        1.0 / (1.0 / v - 1.0).sqrt()
    } else {
        f64::INFINITY
    }
}

/// What would determine a direction the data know to `data_ratio` of its
/// prior: along a dolly the information grows as the square of the layers'
/// spread in depth, so σ falls as 1/span.
fn fix(span: f64, data_ratio: f64) -> String {
    let needed = span * data_ratio / WANTED_DATA_RATIO;
    if needed.is_finite() {
        format!("target layers at least {needed:.0} mm apart (now {span:.0} mm) at this distance")
    } else {
        "targets at more heights, spread over more of the sensor".to_string()
    }
}

fn marks(session: &Session) -> &'static str {
    if session.screen_points.is_empty() {
        ", or marked screen pixels (`screen_point`)"
    } else {
        ""
    }
}

fn is_lens_only(name: &str) -> bool {
    [
        "camera.k1",
        "camera.k2",
        "camera.k3",
        "camera.p1",
        "camera.p2",
        "camera.cx_px",
        "camera.cy_px",
        "camera.aspect_ratio",
    ]
    .contains(&name)
}

/// `(N + P)⁻¹`, P the priors' precisions: the covariance the resection
/// would report, to first order at the nominal station.
fn posterior(n: &DMatrix<f64>, params: &[Param]) -> Option<DMatrix<f64>> {
    let mut m = n.clone();
    for (k, p) in params.iter().enumerate() {
        if let Some(sd) = p.prior_std() {
            m[(k, k)] += 1.0 / (sd * sd);
        }
    }
    m.cholesky().map(|c| c.inverse())
}

//! A check of a session in progress: everything missing or wrong before
//! anything is solved, in the operator's words — every rule of the spec
//! that fails (not only the first), the reference plane's fit against the
//! stage noise, each target's centroid, each target's spot against
//! where the nominal station puts it, and the marked screen pixels against
//! the plane grid they lie on (`check_marks.rs`).
//!
//! The nominal station is rough, so its predictions are off by a smooth
//! pattern. A target is flagged when its spot is off the central
//! projection the other targets follow — a DLT from the targets' world
//! positions to their spots, fitted robustly — by more than 5 robust σ of
//! the others' residuals (and of its own σ: centroid and stage noise): a
//! wrong reading, not a rough station.

use std::path::{Path, PathBuf};

use nalgebra::{Point2, Point3};

use super::centroid::{centroid_of_file, Centroid};
use super::dlt;
use super::frame::{ElementPose, PoseSource, WorldFrame};
use super::rules;
use super::session::{read_file, session_toml, Session, SessionError};
use super::spread::chi2_quantile_999;
use crate::acquire::acquisition::Acquisition;

/// How much a finding matters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Severity {
    /// The session cannot be solved until this is fixed.
    Error,
    /// Solvable, but probably wrong or weak.
    Warning,
    /// For information.
    Note,
}

/// One thing the check found.
#[derive(Debug, Clone, PartialEq)]
pub struct Finding {
    /// How much it matters.
    pub severity: Severity,
    /// The entry it is about (`target_point[7]`), if any.
    pub entry: Option<String>,
    /// What, in the operator's words, with what to do.
    pub message: String,
}

/// What the check found of one target.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetCheck {
    /// `target_point[index]`.
    pub index: usize,
    /// Its centroid, px (pixel-centre convention), where one was found.
    pub found_px: Option<Point2<f64>>,
    /// Where the nominal station puts it, px.
    pub predicted_px: Option<Point2<f64>>,
    /// Its distance from the smooth pattern of the others, px.
    pub off_pattern_px: Option<f64>,
}

/// The check's result.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckReport {
    /// The session file checked.
    pub path: PathBuf,
    /// Findings, errors first.
    pub findings: Vec<Finding>,
    /// Per target, in file order.
    pub targets: Vec<TargetCheck>,
}

impl CheckReport {
    /// Whether nothing stops solving.
    pub fn ready(&self) -> bool {
        !self.findings.iter().any(|f| f.severity == Severity::Error)
    }

    /// Number of findings of `severity`.
    pub fn count(&self, severity: Severity) -> usize {
        self.findings
            .iter()
            .filter(|f| f.severity == severity)
            .count()
    }

    pub(super) fn push(&mut self, severity: Severity, entry: Option<String>, message: String) {
        self.findings.push(Finding {
            severity,
            entry,
            message,
        });
    }
}

/// Checks the session at `path` (its `session.toml` or folder).
pub fn check(path: &Path) -> CheckReport {
    let path = session_toml(path);
    let mut report = CheckReport {
        path: path.clone(),
        findings: Vec::new(),
        targets: Vec::new(),
    };
    let file = match read_file(&path) {
        Ok(f) => f,
        Err(e) => {
            report.push(Severity::Error, None, e.to_string());
            return report;
        }
    };
    let (nominal, problems) = rules::validate(&file, &path);
    // What can be judged with the rest unfinished: with the nominal
    // station and readings that are all numbers, the frame, the pose and
    // the targets are checked too.
    let judgeable = problems.iter().all(|p| {
        matches!(
            p,
            SessionError::MissingFile { .. }
                | SessionError::TooFew { .. }
                | SessionError::Coplanar { .. }
        )
    });
    for p in &problems {
        report.push(
            Severity::Error,
            p.entry().map(str::to_string),
            operator_words(p, &path),
        );
    }
    if file.element_point.is_empty() {
        report.push(
            Severity::Note,
            Some("element_point".into()),
            "no element points: the element is taken to stand on the reference plane".into(),
        );
    }
    if let (Some(nominal), true) = (nominal, judgeable) {
        let session = Session::build(path.clone(), file, nominal);
        check_loaded(&session, &mut report);
    }
    report.findings.sort_by_key(|f| f.severity);
    report
}

/// The error's text without the file and entry the finding already names.
fn operator_words(e: &super::SessionError, path: &Path) -> String {
    let text = e.to_string();
    let text = text
        .strip_prefix(&format!("{}: ", path.display()))
        .unwrap_or(&text);
    match e.entry() {
        Some(entry) => text
            .strip_prefix(&format!("`{entry}`: "))
            .unwrap_or(text)
            .to_string(),
        None => text.to_string(),
    }
}

fn check_loaded(session: &Session, report: &mut CheckReport) {
    let frame = match WorldFrame::of_session(session) {
        Ok(f) => f,
        Err(e) => {
            // Too few flat points are already reported by the rules.
            if session.flat_points_mm.len() >= 3 {
                report.push(Severity::Error, Some("flat_point".into()), e.to_string());
            }
            return;
        }
    };
    plane_findings(session, &frame, report);
    if let Ok(pose) = ElementPose::of_session(session) {
        pose_findings(&pose, report);
    }
    // A missing acquisition is already reported by the rules.
    let flat = &session.reference_flat;
    if let Some(e) = flat
        .is_file()
        .then(|| Acquisition::open(flat).err())
        .flatten()
    {
        report.push(
            Severity::Error,
            Some("reference_flat.acquisition".into()),
            format!("{e}; record it again with `mfd measure --no-reconstruct`"),
        );
    }
    target_findings(session, &frame, report);
    super::check_marks::mark_findings(session, &frame, report);
}

fn plane_findings(session: &Session, frame: &WorldFrame, report: &mut CheckReport) {
    let p = &frame.plane;
    let std_um = session.stage_std_mm * 1e3;
    let tilt_deg = p.normal.z.clamp(-1.0, 1.0).acos().to_degrees();
    report.push(
        Severity::Note,
        Some("flat_point".into()),
        format!(
            "reference plane: {} points, {:.2} µm RMS off the plane (stage σ {std_um} µm), \
             {tilt_deg:.3}° from the stage's xy plane",
            p.residuals_um.len(),
            p.rms_um()
        ),
    );
    if p.dof > 0 && p.chi2 > chi2_quantile_999(p.dof as f64) {
        let (worst, r) = p
            .residuals_um
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
            .map_or((0, 0.0), |(k, r)| (k, *r));
        report.push(
            Severity::Warning,
            Some(format!("flat_point[{worst}]")),
            format!(
                "the flat points are {:.2} µm RMS off their plane, more than the stage noise \
                 ({std_um} µm) allows; flat point {worst} is {r:.1} µm off: wrong reading, or \
                 the flat moved?",
                p.rms_um()
            ),
        );
    }
}

fn pose_findings(pose: &ElementPose, report: &mut CheckReport) {
    let s = pose.std();
    if let PoseSource::ElementPoints(n) = pose.source {
        report.push(
            Severity::Note,
            Some("element_point".into()),
            format!(
                "element: {n} points, {:.4} ± {:.4} mm above the reference plane, tilted \
                 rx {:.4} ± {:.4}°, ry {:.4} ± {:.4}°",
                pose.offset_mm.z, s[0], pose.tilt_deg[0], s[1], pose.tilt_deg[1], s[2]
            ),
        );
    }
}

/// Each target's centroid, its prediction, and the ones off the pattern.
fn target_findings(session: &Session, frame: &WorldFrame, report: &mut CheckReport) {
    let cam = &session.nominal.camera;
    let size = (cam.width, cam.height);
    let mut pairs = Vec::new();
    let mut sigmas = Vec::new();
    for t in &session.targets {
        let entry = t.entry();
        let found: Option<(Point2<f64>, Option<Centroid>)> = match &t.observation {
            super::TargetObservation::Centroid(px) => Some((*px, None)),
            // A missing frame is already reported by the rules.
            super::TargetObservation::Image(file) if !file.is_file() => None,
            super::TargetObservation::Image(file) => {
                match centroid_of_file(file, &entry, Some(size)) {
                    Ok(c) => Some((c.position_px, Some(c))),
                    Err(e) => {
                        let text = e.to_string();
                        let text = text.strip_prefix(&format!("`{entry}`: ")).unwrap_or(&text);
                        report.push(Severity::Error, Some(entry.clone()), text.to_string());
                        None
                    }
                }
            }
        };
        if let Some((_, c)) = &found {
            sigmas.push(
                c.as_ref()
                    .map_or(super::from_session::GIVEN_CENTROID_STD_PX, |c| {
                        c.std_px()[0].max(c.std_px()[1])
                    }),
            );
        }
        if let Some((_, Some(c))) = &found {
            if c.saturated_px > 0 {
                report.push(
                    Severity::Warning,
                    Some(entry.clone()),
                    format!(
                        "target {}'s spot has {} saturated pixels: lower the exposure",
                        t.index, c.saturated_px
                    ),
                );
            }
        }
        let predicted = cam.project(&frame.to_world(&t.stage_mm));
        let (w, h) = (f64::from(cam.width), f64::from(cam.height));
        if let Some(p) = predicted.filter(|p| !(0.0..w).contains(&p.x) || !(0.0..h).contains(&p.y))
        {
            report.push(
                Severity::Warning,
                Some(entry.clone()),
                format!(
                    "the nominal station puts target {} at ({:.0}, {:.0}) px, off its {}x{} sensor: \
                     wrong reading, or move it into the view",
                    t.index, p.x, p.y, cam.width, cam.height
                ),
            );
        }
        if predicted.is_none() {
            report.push(
                Severity::Warning,
                Some(entry.clone()),
                format!("target {} lies behind the nominal camera: wrong reading or wrong nominal station?", t.index),
            );
        }
        let world_mm = frame.to_world(&t.stage_mm);
        if let (Some((f, c)), Some(p)) = (&found, predicted) {
            // The spot's σ: its centroid's, and the stage noise seen from
            // the camera (focal length in px over the distance).
            let centroid = c.as_ref().map_or(0.0, |c| c.std_px()[0].max(c.std_px()[1]));
            let stage = session.stage_std_mm * cam.focal_px() / (world_mm - cam.position_mm).norm();
            pairs.push(Pair {
                slot: report.targets.len(),
                world_mm,
                predicted_px: p,
                found_px: *f,
                sigma_px: centroid.hypot(stage),
            });
        }
        report.targets.push(TargetCheck {
            index: t.index,
            found_px: found.map(|(f, _)| f),
            predicted_px: predicted,
            off_pattern_px: None,
        });
    }
    flag_off_pattern(&pairs, report);
    coverage(report, size);
    // The layout's weak directions with the centroids' median σ (a given
    // centroid's σ where no image gave one).
    sigmas.sort_by(f64::total_cmp);
    let sigma = sigmas
        .get(sigmas.len() / 2)
        .copied()
        .unwrap_or(super::from_session::GIVEN_CENTROID_STD_PX);
    super::check_layout::layout_findings(session, sigma, report);
}

/// A target for the pattern test: its slot in the report, world position,
/// nominal prediction, centroid and that centroid's σ (px).
struct Pair {
    slot: usize,
    world_mm: Point3<f64>,
    predicted_px: Point2<f64>,
    found_px: Point2<f64>,
    sigma_px: f64,
}

/// Fits a projection matrix (DLT) from the targets' world positions to
/// their spots, robustly, and flags the targets far off it: a central
/// projection explains every right reading up to distortion and noise.
fn flag_off_pattern(pairs: &[Pair], report: &mut CheckReport) {
    // 11 parameters: 7 or more targets leave residuals to judge.
    if pairs.len() < 7 {
        return;
    }
    let mut keep = vec![true; pairs.len()];
    let mut residuals = vec![0.0; pairs.len()];
    let mut scale = 0.0;
    let limit = |scale: f64, p: &Pair| 5.0 * scale.max(p.sigma_px);
    for _ in 0..3 {
        let (w, f): (Vec<_>, Vec<_>) = pairs
            .iter()
            .zip(&keep)
            .filter(|(_, k)| **k)
            .map(|(p, _)| (p.world_mm, p.found_px))
            .unzip();
        let Some(m) = dlt::dlt(&w, &f) else { return };
        for (k, p) in pairs.iter().enumerate() {
            residuals[k] =
                dlt::project(&m, &p.world_mm).map_or(f64::INFINITY, |q| (q - p.found_px).norm());
        }
        let mut kept: Vec<f64> = residuals
            .iter()
            .zip(&keep)
            .filter(|(_, k)| **k)
            .map(|(r, _)| *r)
            .collect();
        kept.sort_by(f64::total_cmp);
        // The median length of a 2-D Gaussian residual is 1.1774 σ.
        scale = kept[kept.len() / 2] / 1.1774;
        for (k, p) in pairs.iter().enumerate() {
            keep[k] = residuals[k] <= limit(scale, p);
        }
    }
    for (k, p) in pairs.iter().enumerate() {
        report.targets[p.slot].off_pattern_px = Some(residuals[k]);
        if residuals[k] > limit(scale, p) {
            let index = report.targets[p.slot].index;
            report.push(
                Severity::Warning,
                Some(format!("target_point[{index}]")),
                format!(
                    "target {index}'s spot is {:.0} px from where the nominal station puts it, \
                     {:.1} px off the projection the other targets follow (they agree to \
                     {:.2} px): wrong reading?",
                    (p.predicted_px - p.found_px).norm(),
                    residuals[k],
                    scale.max(p.sigma_px)
                ),
            );
        }
    }
}

/// Warns when the found spots cover less than half the sensor along an axis.
fn coverage(report: &mut CheckReport, size: (u32, u32)) {
    let found: Vec<Point2<f64>> = report.targets.iter().filter_map(|t| t.found_px).collect();
    if found.len() < 2 {
        return;
    }
    for (axis, name, extent) in [(0, "width", size.0), (1, "height", size.1)] {
        let lo = found.iter().map(|p| p[axis]).fold(f64::INFINITY, f64::min);
        let hi = found
            .iter()
            .map(|p| p[axis])
            .fold(f64::NEG_INFINITY, f64::max);
        let fraction = (hi - lo) / f64::from(extent);
        // The distortion is fitted over the sensor: spots over half of it
        // or less leave its outer part to extrapolation.
        if fraction < 0.5 {
            report.push(
                Severity::Warning,
                Some("target_point".into()),
                format!(
                    "the spots cover {:.0} % of the sensor's {name}: add targets nearer its edges \
                     (`mfd calibrate targets`)",
                    100.0 * fraction
                ),
            );
        }
    }
}

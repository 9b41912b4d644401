//! The calibration's single entry point, [`calibrate`]: the world frame's
//! plane from the flat points (linear), the camera by resection, the screen
//! from the flat's fringe map and the marked screen pixels, then one joint adjustment of everything
//! against all the data; and what it writes ([`Calibration::write`]):
//! `station.toml` (`mfd-station/2`), `station_uncertainty.toml`
//! (`mfd-station-uncertainty/1`) and `report.json`.

use std::path::Path;

use nalgebra::{DMatrix, Matrix2, Point2, Vector3};

use super::adjust::adjust;
use super::error::CalibrationError;
use super::input::CalibrationInput;
use super::params::{Param, State, WorldFrame, STATION_DOFS};
use super::report::{Estimate, Report, StepReport};
use super::resect::resect;
use super::residuals::{flat_reflection_uv, Blocks};
use crate::optics::station::{Dof, Pose, Station, StationUncertainty};

/// The fewest flat points that define a plane.
pub const MIN_FLAT_POINTS: usize = 3;

/// The calibrated station, its uncertainty and the report.
#[derive(Debug, Clone)]
pub struct Calibration {
    /// The calibrated station (`mfd-station/2`), world frame of the session.
    pub station: Station,
    /// The world frame in the stage frame.
    pub frame: WorldFrame,
    /// Every parameter of the joint adjustment (the plane's and the
    /// station's, estimated first, then held), by name.
    pub names: Vec<String>,
    /// Their covariance (held ones with their prior σ and its effect on the
    /// estimated ones).
    pub covariance: DMatrix<f64>,
    /// 1 σ of what the session gave: the thickness and the index.
    pub given_std: Vec<(Dof, f64)>,
    /// The report.
    pub report: Report,
}

/// The element's pose from the element points: the plane through them in
/// the world frame (its height at the pivot and its tilts); identity
/// without points.
fn element_start(input: &CalibrationInput, frame: &WorldFrame, station: &Station) -> Pose {
    let pts: Vec<Vector3<f64>> = input
        .element_points_stage_mm
        .iter()
        .map(|p| frame.to_world(p).coords)
        .collect();
    let c = station.element.aperture_center_mm;
    match WorldFrame::fit(&pts, [c.x, c.y]) {
        Some(plane) if pts.len() >= MIN_FLAT_POINTS => {
            let [z, sx, sy] = plane.plane;
            Pose {
                offset_mm: Vector3::new(0.0, 0.0, z),
                tilt_deg: [sy.atan().to_degrees(), (-sx).atan().to_degrees()],
            }
        }
        _ => Pose::default(),
    }
}

fn check_points(input: &CalibrationInput) -> Result<WorldFrame, CalibrationError> {
    let n = input.flat_points_stage_mm.len();
    if n < MIN_FLAT_POINTS {
        return Err(CalibrationError::TooFew {
            entry: "flat_point",
            found: n,
            needed: MIN_FLAT_POINTS,
        });
    }
    let m = input.element_points_stage_mm.len();
    if m > 0 && m < MIN_FLAT_POINTS {
        return Err(CalibrationError::TooFew {
            entry: "element_point",
            found: m,
            needed: MIN_FLAT_POINTS,
        });
    }
    let line = CalibrationError::Degenerate {
        entry: "flat_point",
        problem: "lie on one line: add a point off that line".into(),
    };
    // Across a line of points the plane's tilt is known to σ_stage over
    // their spread: ten readings' σ of spread leaves it at 0.1 rad, no plane.
    if smallest_spread_xy(&input.flat_points_stage_mm) < 10.0 * input.stage_std_mm {
        return Err(line);
    }
    WorldFrame::fit(&input.flat_points_stage_mm, input.element_center_stage_mm).ok_or(line)
}

/// The smallest principal standard deviation of the points' x, y, mm.
fn smallest_spread_xy(points: &[Vector3<f64>]) -> f64 {
    let n = points.len() as f64;
    let mean = points
        .iter()
        .fold(nalgebra::Vector2::zeros(), |a, p| a + p.xy())
        / n;
    let cov = points.iter().fold(nalgebra::Matrix2::zeros(), |a, p| {
        let d = p.xy() - mean;
        a + d * d.transpose()
    }) / n;
    cov.symmetric_eigenvalues().min().max(0.0).sqrt()
}

/// Calibrates a station from a session's numbers.
///
/// # Errors
/// [`CalibrationError`] naming the session entry that is missing or
/// degenerate, or the step that did not converge.
pub fn calibrate(input: &CalibrationInput) -> Result<Calibration, CalibrationError> {
    let frame = check_points(input)?;
    let mut station = input.nominal.clone();
    station.element.thickness_mm = input.thickness_mm.0;
    station.element.refractive_index = input.refractive_index.0;
    station.element.pose = element_start(input, &frame, &station);
    let start = State { frame, station };
    let camera = resect(input, &start)?;
    let screen_blocks = Blocks {
        flat_points: false,
        element_points: false,
        targets: false,
        flat_map: true,
        screen_points: true,
    };
    let mut screen_params: Vec<Param> = dofs_of("screen.");
    if input.nominal.screen.cover_glass.is_some() {
        screen_params.push(Param::CoverGlassThickness);
    }
    let screen = adjust(
        input,
        camera.state.clone(),
        &start,
        &screen_params,
        screen_blocks,
        "screen",
    )?;
    let mut all = vec![Param::PlaneHeight, Param::PlaneSlopeX, Param::PlaneSlopeY];
    all.extend(STATION_DOFS.iter().map(|d| Param::Station(d.dof)));
    if input.nominal.screen.cover_glass.is_some() {
        all.push(Param::CoverGlassThickness);
    }
    if input.nominal.camera.aspect_ratio.is_some() {
        all.push(Param::AspectRatio);
    }
    let joint = adjust(
        input,
        screen.state.clone(),
        &start,
        &all,
        Blocks::ALL,
        "joint",
    )?;
    let steps = vec![
        StepReport::new("resection", input, &camera, Blocks::TARGETS),
        StepReport::new("screen", input, &screen, screen_blocks),
        StepReport::new("joint", input, &joint, Blocks::ALL),
    ];
    let mut report = Report::new(input, steps);
    for (k, p) in joint.params.iter().enumerate() {
        let value = match p {
            Param::CoverGlassThickness => joint
                .state
                .station
                .screen
                .cover_glass
                .map(|g| g.thickness_mm),
            Param::AspectRatio => joint.state.station.camera.aspect_ratio,
            _ => None,
        };
        if let Some(value) = value {
            report.beside_the_uncertainty_file.push(Estimate {
                name: p.name(),
                value,
                std: joint.covariance[(k, k)].max(0.0).sqrt(),
            });
        }
    }
    // Validated as a loaded file is, and as a reader will see it (axes
    // normalised).
    let station = Station::from_file(
        &joint.state.station.to_file(),
        Path::new("<calibrated station>"),
    )
    .map_err(|source| CalibrationError::InvalidResult { source })?;
    Ok(Calibration {
        station,
        frame: joint.state.frame,
        names: joint.params.iter().map(|p| p.name().to_string()).collect(),
        covariance: joint.covariance.clone(),
        given_std: vec![
            (Dof::Thickness, input.thickness_mm.1),
            (Dof::RefractiveIndex, input.refractive_index.1),
        ],
        report,
    })
}

fn dofs_of(prefix: &str) -> Vec<Param> {
    STATION_DOFS
        .iter()
        .filter(|d| d.dof.name().starts_with(prefix))
        .map(|d| Param::Station(d.dof))
        .collect()
}

impl Calibration {
    /// The covariance over the station's degrees of freedom alone (the
    /// plane's and the cover glass's marginalised out), with their names.
    pub fn station_covariance(&self) -> (Vec<String>, DMatrix<f64>) {
        let keep: Vec<usize> = (0..self.names.len())
            .filter(|&i| Dof::parse(&self.names[i]).is_some())
            .collect();
        let m = DMatrix::from_fn(keep.len(), keep.len(), |i, j| {
            self.covariance[(keep[i], keep[j])]
        });
        (keep.iter().map(|&i| self.names[i].clone()).collect(), m)
    }

    /// The calibrated station's screen point for the flat reflection of
    /// camera pixel `(i, j)` (a flat mirror at the reference plane) and its
    /// covariance, screen px², from the calibration's covariance through
    /// central differences. `None` where the ray does not reach the screen.
    pub fn flat_screen_point(&self, i: u32, j: u32) -> Option<(Point2<f64>, Matrix2<f64>)> {
        let state = State {
            frame: self.frame,
            station: self.station.clone(),
        };
        let uv = flat_reflection_uv(&self.station, i, j)?;
        let params: Vec<Param> = self
            .names
            .iter()
            .filter_map(|n| Param::from_name(n))
            .collect();
        let mut jac = nalgebra::DMatrix::zeros(2, params.len());
        for (k, p) in params.iter().enumerate() {
            let h = p.step();
            let a = flat_reflection_uv(&state.perturbed(*p, h).station, i, j)?;
            let b = flat_reflection_uv(&state.perturbed(*p, -h).station, i, j)?;
            jac.set_column(k, &((a - b) / (2.0 * h)));
        }
        let c = &jac * &self.covariance * jac.transpose();
        Some((uv, Matrix2::new(c[(0, 0)], c[(0, 1)], c[(1, 0)], c[(1, 1)])))
    }

    /// Writes `station.toml`, `station_uncertainty.toml` and `report.json`
    /// into `dir` (created if missing).
    ///
    /// # Errors
    /// [`CalibrationError::Io`] naming the file.
    pub fn write(&self, dir: &Path) -> Result<(), CalibrationError> {
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| CalibrationError::Io { path, source }
        };
        std::fs::create_dir_all(dir).map_err(io(dir))?;
        let station = dir.join("station.toml");
        std::fs::write(&station, self.station.to_toml_string()).map_err(io(&station))?;
        let unc = dir.join("station_uncertainty.toml");
        let text = self.uncertainty_comments() + &self.uncertainty("station.toml").to_toml_string();
        std::fs::write(&unc, text).map_err(io(&unc))?;
        let report = dir.join("report.json");
        std::fs::write(&report, self.report.to_json()).map_err(io(&report))?;
        Ok(())
    }

    /// Comment lines for the head of `station_uncertainty.toml`: the
    /// combinations the session left weakly determined (the format has no
    /// field for them, and a reader must not meet one it does not know; a
    /// TOML comment is for the reader's human). Their σ is in the
    /// covariance below as it is.
    pub fn uncertainty_comments(&self) -> String {
        let weak = self.report.steps.last().map_or(&[][..], |s| &s.weak[..]);
        if weak.is_empty() {
            return "# The session determined every estimated combination of the station's \
                    degrees of freedom\n# better than its prior range.\n"
                .into();
        }
        let mut s = format!(
            "# {} combination(s) the session left weakly determined (σ near the prior range;\n\
             # the covariance below carries it; 1 σ change of each parameter along it):\n",
            weak.len()
        );
        for w in weak {
            s += &format!("#   {}\n", w.describe());
        }
        s
    }

    /// The station's uncertainty (`mfd-station-uncertainty/1`, for the
    /// station file `station_file`): the full covariance of the station's
    /// degrees of freedom (estimated and held), then the thickness and index
    /// as given, uncorrelated (`[std]`).
    pub fn uncertainty(&self, station_file: &str) -> StationUncertainty {
        let (names, m) = self.station_covariance();
        let mut dofs: Vec<Dof> = names.iter().filter_map(|n| Dof::parse(n)).collect();
        let k = dofs.len();
        dofs.extend(self.given_std.iter().map(|(d, _)| *d));
        let mut covariance = DMatrix::zeros(dofs.len(), dofs.len());
        for r in 0..k {
            for c in 0..k {
                covariance[(r, c)] = 0.5 * (m[(r, c)] + m[(c, r)]);
            }
        }
        for (i, (_, s)) in self.given_std.iter().enumerate() {
            covariance[(k + i, k + i)] = s * s;
        }
        StationUncertainty {
            station: station_file.into(),
            names: dofs,
            covariance,
            correlated: k,
        }
    }
}

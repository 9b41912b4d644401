//! A calibration session, loaded and validated: [`Session::load`] reads
//! `session.toml` (`mfd-calibration/1`), resolves its paths against the
//! file's folder, loads the nominal station, and checks every rule of the
//! spec (`calibration.md`) with errors ([`SessionError`]) that name the
//! file, the entry (`target_point[7]`, `flat_point[2].stage_mm`), what was
//! found, what was expected and what to do.
//!
//! All readings stay in the stage frame (mm); [`crate::calibrate::frame`]
//! turns them into the world frame the session defines.

use std::path::{Path, PathBuf};

use nalgebra::{Matrix2, Point2, Point3};

use super::centroid::{centroid_of_file, CentroidError};
use super::rules;
use super::session_file::{SessionElement, SessionFile};
use crate::optics::station::{Station, StationError};

/// What is wrong with a session. Every variant names `path` (the
/// `session.toml`) and, where there is one, the entry.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// Not valid TOML for `mfd-calibration/1` (unknown or missing field, wrong type).
    #[error("{path}: not a valid mfd-calibration/1 session: {source}")]
    Parse {
        /// The session file.
        path: PathBuf,
        /// The TOML error, which names the field and line.
        #[source]
        source: Box<toml::de::Error>,
    },
    /// The nominal station could not be loaded.
    #[error("{path}: `nominal_station` = {station}: {source}")]
    Nominal {
        /// The session file.
        path: PathBuf,
        /// The nominal station's file, resolved.
        station: PathBuf,
        /// Why it was refused.
        #[source]
        source: Box<StationError>,
    },
    /// Fewer entries of a kind than the spec asks for.
    #[error("{path}: `{entry}`: {count} given, {needed}: {todo}")]
    TooFew {
        /// The session file.
        path: PathBuf,
        /// The entry kind, e.g. `flat_point`.
        entry: &'static str,
        /// How many there are.
        count: usize,
        /// What the spec asks for, e.g. "at least 3".
        needed: &'static str,
        /// What to do.
        todo: &'static str,
    },
    /// Points that must span a plane lie on one line, within the stage noise.
    #[error(
        "{path}: `{entry}`: the {count} points lie on one line: {off_line_um:.2} µm RMS \
         off their best line, where the stage noise alone ({stage_std_um} µm) allows \
         that; {todo}"
    )]
    Collinear {
        /// The session file.
        path: PathBuf,
        /// The entry kind.
        entry: &'static str,
        /// How many points.
        count: usize,
        /// Their RMS distance from the best line, µm.
        off_line_um: f64,
        /// The session's stage noise, µm.
        stage_std_um: f64,
        /// What to do.
        todo: &'static str,
    },
    /// Points that must span a volume lie in one plane, within the stage noise.
    #[error(
        "{path}: `{entry}`: the {count} points lie in one plane: {off_plane_um:.2} µm RMS \
         off their best plane, where the stage noise alone ({stage_std_um} µm) allows \
         that; {todo}"
    )]
    Coplanar {
        /// The session file.
        path: PathBuf,
        /// The entry kind.
        entry: &'static str,
        /// How many points.
        count: usize,
        /// Their RMS distance from the best plane, µm.
        off_plane_um: f64,
        /// The session's stage noise, µm.
        stage_std_um: f64,
        /// What to do.
        todo: &'static str,
    },
    /// A value the session cannot have.
    #[error("{path}: `{entry}`: found {found}, expected {expected}; {todo}")]
    Invalid {
        /// The session file.
        path: PathBuf,
        /// The entry and field, e.g. `target_point[3].image`.
        entry: String,
        /// What was found.
        found: String,
        /// What was expected.
        expected: String,
        /// What to do.
        todo: String,
    },
    /// A stage reading that looks written in the wrong unit.
    #[error("{path}: `{entry}`: {found}; readings must be in mm: {todo}")]
    Units {
        /// The session file.
        path: PathBuf,
        /// The entry, e.g. `flat_point[2].stage_mm`.
        entry: String,
        /// What was found and against what scale it was judged.
        found: String,
        /// What to do (e.g. divide by 1000).
        todo: String,
    },
    /// A file the session names does not exist.
    #[error("{path}: `{entry}`: {file} does not exist; {todo}")]
    MissingFile {
        /// The session file.
        path: PathBuf,
        /// The entry and field, e.g. `reference_flat.acquisition`.
        entry: String,
        /// The missing file, resolved.
        file: PathBuf,
        /// What to do.
        todo: String,
    },
}

impl crate::outcome::Classify for SessionError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        Some(Outcome::Input)
    }
}

impl SessionError {
    /// The entry the error is about (`target_point[7]`, `stage_std_um`), or
    /// `None` for errors of the whole file.
    pub fn entry(&self) -> Option<&str> {
        match self {
            SessionError::Io { .. } | SessionError::Parse { .. } => None,
            SessionError::Nominal { .. } => Some("nominal_station"),
            SessionError::TooFew { entry, .. }
            | SessionError::Collinear { entry, .. }
            | SessionError::Coplanar { entry, .. } => Some(entry),
            SessionError::Invalid { entry, .. }
            | SessionError::Units { entry, .. }
            | SessionError::MissingFile { entry, .. } => Some(entry),
        }
    }
}

/// How the camera saw one target.
#[derive(Debug, Clone, PartialEq)]
pub enum TargetObservation {
    /// A camera frame (path resolved against the session folder); the
    /// centroid is found by [`crate::calibrate::centroid`].
    Image(PathBuf),
    /// The centroid as given, pixel-centre convention, px.
    Centroid(Point2<f64>),
}

/// One `[[target_point]]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Target {
    /// Its index in the file (`target_point[index]`).
    pub index: usize,
    /// The PSM's focus, stage frame, mm.
    pub stage_mm: Point3<f64>,
    /// The camera frame or the centroid.
    pub observation: TargetObservation,
}

impl Target {
    /// The entry's name, `target_point[index]`.
    pub fn entry(&self) -> String {
        format!("target_point[{}]", self.index)
    }
}

/// A target with its centroid ([`Session::centroids`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ObservedTarget {
    /// `target_point[index]`.
    pub index: usize,
    /// The PSM's focus, stage frame, mm.
    pub stage_mm: Point3<f64>,
    /// The centroid, pixel-centre convention, px.
    pub position_px: Point2<f64>,
    /// Its covariance from the frame's noise, px²; `None` for a centroid
    /// given as `image_px`.
    pub covariance_px2: Option<Matrix2<f64>>,
}

/// One `[[screen_point]]`.
#[derive(Debug, Clone, PartialEq)]
pub struct ScreenMark {
    /// The PSM's focus on the mark, stage frame, mm.
    pub stage_mm: Point3<f64>,
    /// The mark's screen coordinate `(u, v)`, spec convention, screen px.
    pub screen_px: Point2<f64>,
}

/// A validated session: everything the spec requires holds.
#[derive(Debug, Clone, PartialEq)]
pub struct Session {
    /// The `session.toml` it was read from.
    pub path: PathBuf,
    /// The file as read.
    pub file: SessionFile,
    /// The nominal station's file, resolved.
    pub nominal_path: PathBuf,
    /// The nominal station (a starting point; see [`Session::starting_station`]).
    pub nominal: Station,
    /// 1 σ of one stage reading, each axis, mm.
    pub stage_std_mm: f64,
    /// The element's measured values.
    pub element: SessionElement,
    /// The reference flat's surface points, stage frame, mm (≥ 3, not on one line).
    pub flat_points_mm: Vec<Point3<f64>>,
    /// The element's front points, stage frame, mm (none, or ≥ 3 not on one line).
    pub element_points_mm: Vec<Point3<f64>>,
    /// The targets (≥ 6, not in one plane).
    pub targets: Vec<Target>,
    /// The marked screen pixels.
    pub screen_points: Vec<ScreenMark>,
    /// The reference flat's `acquisition.toml`, resolved.
    pub reference_flat: PathBuf,
    /// Its certified flatness, nm PV.
    pub flat_pv_nm: f64,
}

impl Session {
    /// Reads and validates a session: `path` is its `session.toml` or the
    /// folder holding one.
    ///
    /// # Errors
    /// The first [`SessionError`] of the session (the order of the spec:
    /// file, scalars, entries, files, units, counts, geometry);
    /// [`crate::calibrate::check`] lists all of them.
    pub fn load(path: &Path) -> Result<Session, SessionError> {
        let path = session_toml(path);
        let file = read_file(&path)?;
        let (nominal, problems) = rules::validate(&file, &path);
        match (nominal, problems.into_iter().next()) {
            (Some(nominal), None) => Ok(Session::build(path, file, nominal)),
            (_, Some(first)) => Err(first),
            // validate() reports a station it could not load as a problem;
            // this arm only keeps the match total.
            (None, None) => Err(SessionError::Invalid {
                path: path.clone(),
                entry: "nominal_station".into(),
                found: file.nominal_station.clone(),
                expected: "a loadable station".into(),
                todo: "check the nominal station file".into(),
            }),
        }
    }

    /// The session as the file says, without checking its rules (the
    /// check judges an unfinished one with it).
    pub(super) fn build(path: PathBuf, file: SessionFile, nominal: Station) -> Session {
        let dir = folder_of(&path);
        let pt = |p: [f64; 3]| Point3::from(p);
        let targets = file
            .target_point
            .iter()
            .enumerate()
            .map(|(index, t)| Target {
                index,
                stage_mm: pt(t.stage_mm),
                observation: match (&t.image, t.image_px) {
                    (Some(image), _) => TargetObservation::Image(dir.join(image)),
                    (None, Some(px)) => TargetObservation::Centroid(Point2::from(px)),
                    // validate() rejects a target with neither.
                    (None, None) => TargetObservation::Centroid(Point2::new(f64::NAN, f64::NAN)),
                },
            })
            .collect();
        Session {
            nominal_path: dir.join(&file.nominal_station),
            nominal,
            stage_std_mm: file.stage_std_um * 1e-3,
            element: file.element.clone(),
            flat_points_mm: file.flat_point.iter().map(|p| pt(p.stage_mm)).collect(),
            element_points_mm: file.element_point.iter().map(|p| pt(p.stage_mm)).collect(),
            targets,
            screen_points: file
                .screen_point
                .iter()
                .map(|s| ScreenMark {
                    stage_mm: pt(s.stage_mm),
                    screen_px: Point2::from(s.screen_px),
                })
                .collect(),
            reference_flat: dir.join(&file.reference_flat.acquisition),
            flat_pv_nm: file.reference_flat.flat_pv_nm,
            path,
            file,
        }
    }

    /// Every target's centroid, px (pixel-centre convention), in file
    /// order: found in its frame (with its covariance, px²) or as given
    /// (`image_px`, whose σ the session does not state: `None`).
    ///
    /// # Errors
    /// The first frame without a usable spot, naming its entry and file
    /// (wrong size for the nominal camera, no spot, two spots, on the edge).
    pub fn centroids(&self) -> Result<Vec<ObservedTarget>, CentroidError> {
        let size = (self.nominal.camera.width, self.nominal.camera.height);
        self.targets
            .iter()
            .map(|t| {
                let (position_px, covariance_px2) = match &t.observation {
                    TargetObservation::Centroid(px) => (*px, None),
                    TargetObservation::Image(file) => {
                        let c = centroid_of_file(file, &t.entry(), Some(size))?;
                        (c.position_px, Some(c.covariance_px2))
                    }
                };
                Ok(ObservedTarget {
                    index: t.index,
                    stage_mm: t.stage_mm,
                    position_px,
                    covariance_px2,
                })
            })
            .collect()
    }

    /// The folder of `session.toml`, against which its paths resolve.
    pub fn dir(&self) -> PathBuf {
        folder_of(&self.path)
    }

    /// The nominal station with the session's measured thickness and
    /// refractive index in place of its own (the spec: they replace the
    /// nominal station's; everything else is a starting value).
    pub fn starting_station(&self) -> Station {
        let mut station = self.nominal.clone();
        station.element.thickness_mm = self.element.thickness_mm;
        station.element.refractive_index = self.element.refractive_index;
        station
    }
}

/// `path` itself when it names a file, else `path/session.toml`.
pub fn session_toml(path: &Path) -> PathBuf {
    if path.is_dir() {
        path.join("session.toml")
    } else {
        path.to_path_buf()
    }
}

/// The folder a session file's paths resolve against.
pub(crate) fn folder_of(path: &Path) -> PathBuf {
    path.parent()
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
}

/// Reads and parses `session.toml`, refusing an entry that repeats
/// another (`duplicates.rs`), without validating the rest.
///
/// # Errors
/// [`SessionError::Io`] or [`SessionError::Parse`]; [`SessionError::Invalid`]
/// naming both entries of a repeat.
pub fn read_file(path: &Path) -> Result<SessionFile, SessionError> {
    let text = std::fs::read_to_string(path).map_err(|source| SessionError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let file = toml::from_str(&text).map_err(|source| SessionError::Parse {
        path: path.to_path_buf(),
        source: Box::new(source),
    })?;
    match super::duplicates::first_duplicate(&file, path) {
        Some(e) => Err(e),
        None => Ok(file),
    }
}

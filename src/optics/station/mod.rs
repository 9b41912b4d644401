//! The station: camera, fringe screen and element, validated.
//!
//! [`Station::load`] reads `station.toml` (spec `mfd-station/1` and `/2`)
//! and rejects impossible geometry with a [`StationError`] that names the
//! file and field. Version 2 adds the lens's [`Distortion`], the screen's
//! [`CoverGlass`] and the element's [`Pose`]; without them a station is
//! exactly version 1 (and is written as version 1). All lengths are
//! millimetres in the world frame (see [`crate::conventions`]).

mod aspect_check;
mod build;
mod camera;
mod cover_glass;
mod distortion;
mod dof;
mod file;
pub mod outline_check;
mod pose;
mod uncertainty;
mod validate;
mod wedge;

use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Point2, Point3, Rotation3, Unit, Vector3};

pub use aspect_check::ASPECT_RANGE;
pub use build::{bench_station, CameraProfile, DisplayProfile, SymmetricLayout};
pub use cover_glass::CoverGlass;
pub use distortion::Distortion;
pub use dof::Dof;
pub use file::{
    CameraFile, CoverGlassFile, DistortionFile, ElementFile, OutlineFile, ScreenFile, StationFile,
    STATION_FORMAT, STATION_FORMAT_V2, STATION_FORMAT_V3,
};
pub use pose::Pose;
pub use uncertainty::{StationUncertainty, UncertaintyError, UNCERTAINTY_FORMAT};
pub use wedge::{Wedge, MAX_WEDGE_ARCMIN};

/// What went wrong reading or checking a station.
#[derive(Debug, thiserror::Error)]
pub enum StationError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The station file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The file is not valid TOML for `mfd-station/1` or `/2` (unknown or
    /// missing field, wrong type).
    #[error("{path}: not a valid mfd-station/1 or /2 file: {source}")]
    Parse {
        /// The station file.
        path: PathBuf,
        /// The TOML error, which names the field.
        #[source]
        source: toml::de::Error,
    },
    /// A field holds a value the station cannot have.
    #[error("{path}: field `{field}`: {problem}")]
    Invalid {
        /// The station file (or `<memory>`).
        path: PathBuf,
        /// Dotted field name, e.g. `camera.rotation`.
        field: &'static str,
        /// What is wrong and what was expected.
        problem: String,
    },
}

impl crate::outcome::Classify for StationError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        Some(Outcome::Input)
    }
}

/// A central-projection camera: a pinhole, with the lens's distortion
/// where the station gives one.
#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    /// Projection centre C, world frame, mm.
    pub position_mm: Point3<f64>,
    /// Rotation taking camera-frame vectors to the world frame.
    pub world_from_camera: Rotation3<f64>,
    /// Focal length, mm.
    pub focal_length_mm: f64,
    /// Pixel pitch, mm.
    pub pixel_pitch_mm: f64,
    /// Sensor width in pixels (columns).
    pub width: u32,
    /// Sensor height in pixels (rows).
    pub height: u32,
    /// Principal point `(cx, cy)` in pixels.
    pub principal_point_px: Point2<f64>,
    /// The lens's distortion (station v2); `None` is the ideal pinhole.
    pub distortion: Option<Distortion>,
    /// `fy / fx`, the focal length in rows over that in columns (proposal
    /// `mfd-station/3`, `docs/proposals/aspect.md`), as a calibration by
    /// OpenCV or OpenCSP gives it; `None`: square pixels, not declared
    /// (versions 1 and 2), which projects exactly as `Some(1.0)`.
    pub aspect_ratio: Option<f64>,
}

/// The fringe screen: a plane of square pixels.
#[derive(Debug, Clone, PartialEq)]
pub struct Screen {
    /// Width in screen pixels.
    pub width: u32,
    /// Height in screen pixels.
    pub height: u32,
    /// Pixel pitch, mm.
    pub pixel_pitch_mm: f64,
    /// World position of `(u, v) = (0, 0)`, mm.
    pub origin_mm: Point3<f64>,
    /// Direction of increasing u, world frame.
    pub u_axis: Unit<Vector3<f64>>,
    /// Direction of increasing v, world frame.
    pub v_axis: Unit<Vector3<f64>>,
    /// The glass in front of the pixels (station v2); `None`: bare pixels.
    pub cover_glass: Option<CoverGlass>,
}

impl Screen {
    /// World point of continuous screen coordinate `(u, v)`.
    pub fn world_point(&self, u: f64, v: f64) -> Point3<f64> {
        self.origin_mm + self.pixel_pitch_mm * (u * self.u_axis.as_ref() + v * self.v_axis.as_ref())
    }

    /// Unit normal `u × v` of the screen plane.
    pub fn normal(&self) -> Unit<Vector3<f64>> {
        Unit::new_normalize(self.u_axis.cross(&self.v_axis))
    }

    /// Screen coordinates `(u, v)` of a world point (projected onto the plane).
    pub fn coordinates(&self, p: &Point3<f64>) -> (f64, f64) {
        let d = p - self.origin_mm;
        (
            d.dot(&self.u_axis) / self.pixel_pitch_mm,
            d.dot(&self.v_axis) / self.pixel_pitch_mm,
        )
    }

    /// Whether `(u, v)` lies on the screen, `[0, width] × [0, height]`.
    pub fn contains(&self, u: f64, v: f64) -> bool {
        (0.0..=f64::from(self.width)).contains(&u) && (0.0..=f64::from(self.height)).contains(&v)
    }

    /// World point of the screen's centre.
    pub fn centre(&self) -> Point3<f64> {
        self.world_point(f64::from(self.width) / 2.0, f64::from(self.height) / 2.0)
    }

    /// The screen's unit normal on the side of `p` (the viewer's side).
    pub fn normal_towards(&self, p: &Point3<f64>) -> Unit<Vector3<f64>> {
        let n = self.normal();
        if (p - self.origin_mm).dot(&n) >= 0.0 {
            n
        } else {
            -n
        }
    }

    /// The direction in air from `from` of the ray that lands at screen
    /// coordinate `(u, v)`: straight at its world point for bare pixels,
    /// bent by the cover glass otherwise. `None` when `from` is not in
    /// front of the glass.
    pub fn aim(&self, from: &Point3<f64>, u: f64, v: f64) -> Option<Unit<Vector3<f64>>> {
        let target = self.world_point(u, v);
        match &self.cover_glass {
            None => Some(Unit::new_normalize(target - from)),
            Some(g) => g.aim(&self.origin_mm, &self.normal_towards(from), from, &target),
        }
    }
}

/// The transparent plate under test (nominal geometry; the surfaces' shapes
/// are Zernike expansions kept elsewhere).
#[derive(Debug, Clone, PartialEq)]
pub struct Element {
    /// Refractive index (air is 1).
    pub refractive_index: f64,
    /// Nominal thickness, mm: the back surface is `z = -thickness_mm + W2`.
    pub thickness_mm: f64,
    /// Radius of the reported aperture, mm.
    pub aperture_radius_mm: f64,
    /// Centre of the reported aperture `(x, y)`, mm.
    pub aperture_center_mm: Point2<f64>,
    /// Where the element's own frame sits (station v2); identity: on the reference plane.
    pub pose: Pose,
    /// The wedge the plate was made with (station v2); none: parallel faces.
    pub wedge: Wedge,
    /// The reported region's shape (proposal station v3); the disk unless
    /// given. Its Zernike disk is the aperture's, which contains it.
    pub outline: crate::optics::outline::Shape,
}

impl Element {
    /// The pose's pivot `c = (aperture_center_mm, 0)`.
    pub fn pivot(&self) -> Point3<f64> {
        Point3::new(self.aperture_center_mm.x, self.aperture_center_mm.y, 0.0)
    }

    /// The reported region in place: the shape about the aperture centre
    /// in the aperture's Zernike disk.
    pub fn outline(&self) -> crate::optics::outline::Outline {
        crate::optics::outline::Outline::new(
            self.outline.clone(),
            self.centre(),
            self.aperture_radius_mm,
        )
    }

    /// The aperture centre `[x, y]`, mm: the Zernike centre of both faces.
    pub fn centre(&self) -> [f64; 2] {
        [self.aperture_center_mm.x, self.aperture_center_mm.y]
    }

    /// The nominal front and back with `terms` Noll terms each on the
    /// aperture: a flat front and the wedge's plane as the back (flat for a
    /// parallel plate). Every stage that starts from the plate as made
    /// starts here.
    ///
    /// # Errors
    /// [`crate::optics::zernike::ZernikeError`] for an aperture that makes
    /// no basis.
    pub fn nominal_surfaces(
        &self,
        terms: usize,
    ) -> Result<
        (
            crate::optics::zernike::ZernikeSurface,
            crate::optics::zernike::ZernikeSurface,
        ),
        crate::optics::zernike::ZernikeError,
    > {
        use crate::optics::zernike::{ZernikeBasis, ZernikeSurface};
        let terms = if self.wedge.is_none() {
            terms.max(1)
        } else {
            terms.max(3)
        };
        let basis = ZernikeBasis::new(terms, self.aperture_radius_mm, self.centre())?;
        let back = self
            .wedge
            .back_coefficients_nm(terms, self.aperture_radius_mm);
        Ok((
            ZernikeSurface::new(basis.clone(), vec![0.0; terms])?,
            ZernikeSurface::new(basis, back)?,
        ))
    }
}

/// A validated station.
#[derive(Debug, Clone, PartialEq)]
pub struct Station {
    /// The camera.
    pub camera: Camera,
    /// The screen.
    pub screen: Screen,
    /// The element.
    pub element: Element,
}

impl Station {
    /// Reads and validates a `station.toml`.
    ///
    /// # Errors
    /// [`StationError`] naming the file and, for bad values, the field.
    pub fn load(path: &Path) -> Result<Self, StationError> {
        Ok(Self::load_with_bytes(path)?.0)
    }

    /// Reads and validates a `station.toml`, and gives back the bytes it was
    /// parsed from: for a record of the file (its digest) that is certainly
    /// of the station used, the file read once.
    ///
    /// # Errors
    /// [`StationError`] naming the file and, for bad values, the field; a
    /// file that is not UTF-8 is an [`StationError::Io`] of kind
    /// `InvalidData`, as `read_to_string` reports it.
    pub fn load_with_bytes(path: &Path) -> Result<(Self, Vec<u8>), StationError> {
        let io = |source| StationError::Io {
            path: path.to_path_buf(),
            source,
        };
        let bytes = std::fs::read(path).map_err(io)?;
        let text = std::str::from_utf8(&bytes)
            .map_err(|e| io(std::io::Error::new(std::io::ErrorKind::InvalidData, e)))?;
        let station = Self::from_toml_str(text, path)?;
        Ok((station, bytes))
    }

    /// Parses and validates station TOML; `path` is only used in errors.
    ///
    /// # Errors
    /// [`StationError::Parse`] or [`StationError::Invalid`].
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Self, StationError> {
        let file: StationFile = toml::from_str(text).map_err(|source| StationError::Parse {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_file(&file, path)
    }

    /// The same station in the element's own frame (its pose the
    /// identity): the frame every stage traces, fits and reports in. A
    /// station whose element stands on the reference plane comes back
    /// unchanged, bit for bit.
    pub fn element_frame(&self) -> Station {
        let pose = self.element.pose;
        if pose.is_identity() {
            return self.clone();
        }
        let c = self.element.pivot();
        let back = pose.rotation().inverse();
        let mut s = self.clone();
        s.camera.position_mm = pose.to_element(&c, &self.camera.position_mm);
        s.camera.world_from_camera = back * self.camera.world_from_camera;
        s.screen.origin_mm = pose.to_element(&c, &self.screen.origin_mm);
        s.screen.u_axis = Unit::new_normalize(back * self.screen.u_axis.into_inner());
        s.screen.v_axis = Unit::new_normalize(back * self.screen.v_axis.into_inner());
        s.element.pose = Pose::default();
        s
    }

    /// Whether a field of the proposals is in use (the element's outline,
    /// the camera's aspect ratio; the writer then writes `mfd-station/3`).
    pub fn needs_version_3(&self) -> bool {
        !self.element.outline.is_circle() || self.camera.aspect_ratio.is_some()
    }

    /// Whether any version-2 field is in use (the writer then writes
    /// `mfd-station/2`).
    pub fn needs_version_2(&self) -> bool {
        self.camera.distortion.is_some()
            || self.screen.cover_glass.is_some()
            || !self.element.pose.is_identity()
            || !self.element.wedge.is_none()
    }

    /// Validates the on-disk form.
    ///
    /// # Errors
    /// [`StationError::Invalid`] naming the first bad field.
    pub fn from_file(file: &StationFile, path: &Path) -> Result<Self, StationError> {
        validate::station(file, path)
    }

    /// The on-disk form of this station.
    pub fn to_file(&self) -> StationFile {
        let r: &Matrix3<f64> = self.camera.world_from_camera.matrix();
        let c = &self.camera;
        let v2 = self.needs_version_2();
        let pose = &self.element.pose;
        StationFile {
            format: if self.needs_version_3() {
                STATION_FORMAT_V3
            } else if v2 {
                STATION_FORMAT_V2
            } else {
                STATION_FORMAT
            }
            .to_string(),
            camera: CameraFile {
                position_mm: c.position_mm.coords.into(),
                rotation: [0, 1, 2].map(|row| [r[(row, 0)], r[(row, 1)], r[(row, 2)]]),
                focal_length_mm: c.focal_length_mm,
                pixel_pitch_um: c.pixel_pitch_mm * 1000.0,
                resolution: [c.width, c.height],
                principal_point_px: Some([c.principal_point_px.x, c.principal_point_px.y]),
                aspect_ratio: c.aspect_ratio,
                distortion: c.distortion.map(|d| DistortionFile {
                    model: file::BROWN_CONRADY.to_string(),
                    k: Some(d.k),
                    p: Some(d.p),
                }),
            },
            screen: ScreenFile {
                resolution: [self.screen.width, self.screen.height],
                pixel_pitch_mm: self.screen.pixel_pitch_mm,
                origin_mm: self.screen.origin_mm.coords.into(),
                u_axis: self.screen.u_axis.into_inner().into(),
                v_axis: self.screen.v_axis.into_inner().into(),
                cover_glass: self.screen.cover_glass.map(|g| CoverGlassFile {
                    thickness_mm: g.thickness_mm,
                    refractive_index: g.refractive_index,
                }),
            },
            element: ElementFile {
                refractive_index: self.element.refractive_index,
                thickness_mm: self.element.thickness_mm,
                aperture_radius_mm: self.element.aperture_radius_mm,
                aperture_center_mm: Some([
                    self.element.aperture_center_mm.x,
                    self.element.aperture_center_mm.y,
                ]),
                offset_mm: (!pose.is_identity()).then(|| pose.offset_mm.into()),
                tilt_deg: (!pose.is_identity()).then_some(pose.tilt_deg),
                wedge_arcmin: (!self.element.wedge.is_none()).then_some(self.element.wedge.arcmin),
                wedge_azimuth_deg: (!self.element.wedge.is_none())
                    .then_some(self.element.wedge.azimuth_deg),
                outline: outline_check::to_file(&self.element.outline),
            },
        }
    }

    /// TOML text of this station (`mfd-station/1`, or `/2` when a version-2 field is used).
    pub fn to_toml_string(&self) -> String {
        // Serialising plain structs of numbers and strings cannot fail.
        toml::to_string(&self.to_file()).unwrap_or_default()
    }

    /// Writes this station as `station.toml`.
    ///
    /// # Errors
    /// [`StationError::Io`] when the file cannot be written.
    pub fn save(&self, path: &Path) -> Result<(), StationError> {
        std::fs::write(path, self.to_toml_string()).map_err(|source| StationError::Io {
            path: path.to_path_buf(),
            source,
        })
    }
}

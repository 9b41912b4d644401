//! `surfaces.json`: front and back Zernike coefficients, as
//! `mfd-surfaces/1` (coefficients only) or `mfd-surfaces/2` (beside each
//! surface's coefficients their 1σ, the expected RMS error over the
//! aperture, and why a surface was not reconstructed). The reader takes
//! both versions, strictly: a field the file's version does not allow, a
//! `std_nm` of another length than `coefficients_nm`, a negative σ are
//! errors naming the file and the field. `interchange.md` is the spec.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Deserializer, Serialize};

use crate::optics::outline::{Outline, Shape};
use crate::optics::station::{OutlineFile, Station};
use crate::optics::zernike::{ZernikeBasis, ZernikeError, ZernikeSurface};

mod validate;
use validate::{check_zernike, entry};

/// The tests (`surfaces_file_tests.rs`) check the term limit by name.
#[cfg(test)]
use crate::optics::zernike::MAX_TERMS;

/// The format tag of a version-1 surfaces file (coefficients only).
pub const SURFACES_FORMAT: &str = "mfd-surfaces/1";
/// The format tag of a version-2 surfaces file (with uncertainties).
pub const SURFACES_FORMAT_V2: &str = "mfd-surfaces/2";

mod outline;
pub use outline::{ORTHONORMAL_NAME, SURFACES_FORMAT_V3};

/// What went wrong with a surfaces file.
#[derive(Debug, thiserror::Error)]
pub enum SurfacesFileError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// Not valid JSON for `mfd-surfaces/1` or `/2`.
    #[error("{path}: not a valid mfd-surfaces/1 or mfd-surfaces/2 file: {source}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The JSON error (names the field and line).
        #[source]
        source: serde_json::Error,
    },
    /// A field holds an impossible value, or one the file's version does
    /// not allow.
    #[error("{path}: field `{field}`: {problem}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The field, e.g. `front.coefficients_nm[3]`.
        field: String,
        /// What is wrong and what was expected.
        problem: String,
    },
}

impl crate::outcome::Classify for SurfacesFileError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        Some(Outcome::Input)
    }
}

/// The `zernike` block.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ZernikeSpec {
    /// Must be `noll`.
    pub ordering: String,
    /// Must be `rms`.
    pub normalization: String,
    /// Normalisation radius, mm.
    pub radius_mm: f64,
    /// Centre `[x, y]`, mm.
    pub center_mm: [f64; 2],
}

impl ZernikeSpec {
    /// The block describing `basis` (Noll order, RMS normalisation).
    pub fn of(basis: &ZernikeBasis) -> Self {
        ZernikeSpec {
            ordering: "noll".into(),
            normalization: "rms".into(),
            radius_mm: basis.radius_mm(),
            center_mm: basis.center_mm(),
        }
    }
}

/// One reconstructed surface's coefficients, and (version 2) how well they
/// are known.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceCoefficients {
    /// `coefficients_nm[k]` is Noll j = k + 1, nm.
    pub coefficients_nm: Vec<f64>,
    /// Version 2: `std_nm[k]` is the 1σ of `coefficients_nm[k]`, nm,
    /// everything known included (noise, and the station's uncertainty
    /// where one was given); `None` when not known (always in version 1).
    pub std_nm: Option<Vec<f64>>,
    /// Version 2: the expected RMS over the aperture of the reported minus
    /// the true surface, piston and tilt removed, nm (version 3: over the
    /// outline, its best-fit plane removed).
    pub expected_error_rms_nm: Option<f64>,
    /// Version 3 (proposal): the 1σ of the coefficients in the polynomials
    /// orthonormal over the outline, nm (the coefficients themselves
    /// follow from `coefficients_nm` and the outline and are written, and
    /// checked, from them).
    pub orthonormal_std_nm: Option<Vec<f64>>,
}

/// One surface of the file.
#[derive(Debug, Clone, PartialEq)]
pub enum SurfaceEntry {
    /// The surface was reconstructed.
    Reconstructed(SurfaceCoefficients),
    /// It was not: `null` in the file when `because` is `None`; in version
    /// 2 `{"coefficients_nm": null, "not_reconstructed_because": because}`.
    NotReconstructed {
        /// Why, in words an operator understands.
        because: Option<String>,
    },
}

impl SurfaceEntry {
    /// The coefficients of a reconstructed surface.
    pub fn coefficients(&self) -> Option<&SurfaceCoefficients> {
        match self {
            SurfaceEntry::Reconstructed(c) => Some(c),
            SurfaceEntry::NotReconstructed { .. } => None,
        }
    }

    /// Whether the surface is absent.
    pub fn is_none(&self) -> bool {
        self.coefficients().is_none()
    }
}

/// The whole file, either version.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfacesFile {
    /// [`SURFACES_FORMAT`], [`SURFACES_FORMAT_V2`] or the proposal
    /// [`SURFACES_FORMAT_V3`].
    pub format: String,
    /// Basis definition.
    pub zernike: ZernikeSpec,
    /// Version 3: the element's outline (centred on `zernike.center_mm`,
    /// inside the Zernike disk); `None` in versions 1 and 2 (the disk).
    pub outline: Option<Shape>,
    /// Front surface.
    pub front: SurfaceEntry,
    /// Back surface.
    pub back: SurfaceEntry,
}

/// One surface as it stands in the JSON (both versions' fields; which are
/// allowed is checked after parsing, so that the error names the version).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSurface {
    /// Absent (outer `None`) is an error; `null` is a surface not
    /// reconstructed (version 2).
    #[serde(default, deserialize_with = "present")]
    coefficients_nm: Option<Option<Vec<f64>>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    std_nm: Option<Vec<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    expected_error_rms_nm: Option<f64>,
    #[serde(
        default,
        deserialize_with = "present",
        skip_serializing_if = "Option::is_none"
    )]
    not_reconstructed_because: Option<Option<String>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    orthonormal_coefficients_nm: Option<Vec<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    orthonormal_std_nm: Option<Vec<f64>>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    format: String,
    zernike: ZernikeSpec,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    outline: Option<OutlineFile>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    orthonormal: Option<String>,
    front: Option<RawSurface>,
    back: Option<RawSurface>,
}

/// A field that is there, `null` or not: `Some(None)` for `null`.
fn present<'de, D: Deserializer<'de>, T: Deserialize<'de>>(
    d: D,
) -> Result<Option<Option<T>>, D::Error> {
    Option::<T>::deserialize(d).map(Some)
}

/// What a field of `path` holds that it may not.
fn invalid(path: &Path, field: &str, problem: String) -> SurfacesFileError {
    SurfacesFileError::Invalid {
        path: path.to_path_buf(),
        field: field.to_string(),
        problem,
    }
}

impl SurfacesFile {
    /// Reads and validates a surfaces file of either version.
    ///
    /// # Errors
    /// [`SurfacesFileError`] naming the file and field.
    pub fn load(path: &Path) -> Result<Self, SurfacesFileError> {
        let text = std::fs::read_to_string(path).map_err(|source| SurfacesFileError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_json_str(&text, path)
    }

    /// Parses and validates; `path` is only used in errors.
    ///
    /// # Errors
    /// [`SurfacesFileError::Parse`] or [`SurfacesFileError::Invalid`].
    pub fn from_json_str(text: &str, path: &Path) -> Result<Self, SurfacesFileError> {
        let raw: RawFile =
            serde_json::from_str(text).map_err(|source| SurfacesFileError::Parse {
                path: path.to_path_buf(),
                source,
            })?;
        let v2 = match raw.format.as_str() {
            SURFACES_FORMAT => false,
            SURFACES_FORMAT_V2 | SURFACES_FORMAT_V3 => true,
            other => {
                return Err(invalid(
                    path,
                    "format",
                    format!(
                        "expected \"{SURFACES_FORMAT}\", \"{SURFACES_FORMAT_V2}\" or the proposal \
                     \"{SURFACES_FORMAT_V3}\", found \"{other}\""
                    ),
                ))
            }
        };
        check_zernike(&raw.zernike, path)?;
        let shape = outline::check_file(&raw, path)?;
        let file = SurfacesFile {
            front: entry(raw.front.clone(), "front", v2, path)?,
            back: entry(raw.back.clone(), "back", v2, path)?,
            format: raw.format.clone(),
            zernike: raw.zernike.clone(),
            outline: shape,
        };
        outline::check_surfaces(&raw, &file, path)?;
        Ok(file)
    }

    /// The file's JSON text (pretty, with a final newline), after the
    /// checks the reader applies: what is written reads back.
    ///
    /// # Errors
    /// [`SurfacesFileError::Invalid`] for what the reader would reject
    /// (`path` names the file in it).
    pub fn to_json_string(&self, path: &Path) -> Result<String, SurfacesFileError> {
        let v2 = self.format == SURFACES_FORMAT_V2;
        let v2 = v2 || self.format == SURFACES_FORMAT_V3;
        let mut raw = RawFile {
            format: self.format.clone(),
            zernike: self.zernike.clone(),
            outline: None,
            orthonormal: None,
            front: raw_entry(&self.front, v2),
            back: raw_entry(&self.back, v2),
        };
        outline::fill_raw(self, &mut raw, path)?;
        // Plain numbers, strings and arrays: serialising cannot fail.
        let text = serde_json::to_string_pretty(&raw).unwrap_or_default() + "\n";
        Self::from_json_str(&text, path)?;
        Ok(text)
    }

    /// Writes the file as pretty JSON.
    ///
    /// # Errors
    /// [`SurfacesFileError::Invalid`] for a file the reader would reject,
    /// [`SurfacesFileError::Io`].
    pub fn save(&self, path: &Path) -> Result<(), SurfacesFileError> {
        let text = self.to_json_string(path)?;
        std::fs::write(path, text).map_err(|source| SurfacesFileError::Io {
            path: path.to_path_buf(),
            source,
        })
    }

    /// The version-1 file describing two surfaces (on the front's basis
    /// disk): coefficients only, as a simulation's truth is written.
    pub fn from_surfaces(front: &ZernikeSurface, back: &ZernikeSurface) -> Self {
        let plain = |s: &ZernikeSurface| {
            SurfaceEntry::Reconstructed(SurfaceCoefficients {
                coefficients_nm: s.coefficients_nm().to_vec(),
                std_nm: None,
                expected_error_rms_nm: None,
                orthonormal_std_nm: None,
            })
        };
        SurfacesFile {
            format: SURFACES_FORMAT.to_string(),
            zernike: ZernikeSpec::of(front.basis()),
            outline: None,
            front: plain(front),
            back: plain(back),
        }
    }

    /// A version-2 file on `zernike`'s basis.
    pub fn v2(zernike: ZernikeSpec, front: SurfaceEntry, back: SurfaceEntry) -> Self {
        SurfacesFile {
            format: SURFACES_FORMAT_V2.to_string(),
            zernike,
            outline: None,
            front,
            back,
        }
    }

    /// A version-2 file, or for an outline other than the disk the
    /// proposal's version 3 with it.
    pub fn with_outline(
        zernike: ZernikeSpec,
        shape: &Shape,
        front: SurfaceEntry,
        back: SurfaceEntry,
    ) -> Self {
        let mut f = Self::v2(zernike, front, back);
        if !shape.is_circle() {
            f.format = SURFACES_FORMAT_V3.to_string();
            f.outline = Some(shape.clone());
        }
        f
    }

    /// The outline the file's figures are over: the Zernike disk unless
    /// version 3 gives one.
    pub fn outline_in_place(&self) -> Outline {
        Outline::new(
            self.outline.clone().unwrap_or_default(),
            self.zernike.center_mm,
            self.zernike.radius_mm,
        )
    }

    /// Front coefficients, if present.
    pub fn front_coefficients(&self) -> Option<&Vec<f64>> {
        self.front.coefficients().map(|s| &s.coefficients_nm)
    }

    /// Back coefficients, if present.
    pub fn back_coefficients(&self) -> Option<&Vec<f64>> {
        self.back.coefficients().map(|s| &s.coefficients_nm)
    }
}

/// The JSON form of one surface: `null`, the object of a reconstructed
/// surface (version 2 with `"not_reconstructed_because": null`), or
/// version 2's object of a surface not reconstructed.
fn raw_entry(e: &SurfaceEntry, v2: bool) -> Option<RawSurface> {
    match e {
        SurfaceEntry::NotReconstructed { because: None } => None,
        SurfaceEntry::NotReconstructed { because: Some(b) } => Some(RawSurface {
            coefficients_nm: Some(None),
            std_nm: None,
            expected_error_rms_nm: None,
            not_reconstructed_because: Some(Some(b.clone())),
            orthonormal_coefficients_nm: None,
            orthonormal_std_nm: None,
        }),
        SurfaceEntry::Reconstructed(c) => Some(RawSurface {
            coefficients_nm: Some(Some(c.coefficients_nm.clone())),
            std_nm: c.std_nm.clone(),
            expected_error_rms_nm: c.expected_error_rms_nm,
            not_reconstructed_because: v2.then_some(None),
            orthonormal_coefficients_nm: None,
            orthonormal_std_nm: c.orthonormal_std_nm.clone(),
        }),
    }
}

/// The surface of `coefficients` on the file's basis disk; flat for `None`.
///
/// # Errors
/// [`ZernikeError`] for an invalid radius or coefficients.
pub fn to_surface(
    file: &SurfacesFile,
    coefficients: Option<&Vec<f64>>,
) -> Result<ZernikeSurface, ZernikeError> {
    let z = &file.zernike;
    match coefficients {
        Some(c) => ZernikeSurface::new(
            ZernikeBasis::new(c.len(), z.radius_mm, z.center_mm)?,
            c.clone(),
        ),
        None => ZernikeSurface::flat(z.radius_mm, z.center_mm),
    }
}

/// Why [`surfaces_or_flat`] gave no surfaces.
#[derive(Debug, thiserror::Error)]
pub enum SurfacesOrFlatError {
    /// The file could not be read or is not valid.
    #[error(transparent)]
    File(#[from] SurfacesFileError),
    /// A surface of the file could not be built.
    #[error("{path}: building the Zernike surface")]
    Build {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: ZernikeError,
    },
    /// The flat surfaces over the station's aperture could not be built.
    #[error("flat surfaces over the station's aperture")]
    Flat(#[source] ZernikeError),
}

impl crate::outcome::Classify for SurfacesOrFlatError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        match self {
            SurfacesOrFlatError::File(e) => e.outcome(),
            // The file's `zernike` block, or the station's aperture.
            SurfacesOrFlatError::Build { .. } | SurfacesOrFlatError::Flat(_) => {
                Some(Outcome::Input)
            }
        }
    }
}

/// Front and back surfaces from a `surfaces.json` (`mfd-surfaces/1` or
/// `/2`; a `null` surface is flat), or the nominal plate over the station's
/// aperture when none is given (a flat front; the back flat, or the plane
/// of the wedge the station declares): the expected surfaces of a simulation, a
/// trace or a budget.
///
/// # Errors
/// [`SurfacesOrFlatError`]: the file, one of its surfaces, or the flat.
pub fn surfaces_or_flat(
    path: Option<&Path>,
    station: &Station,
) -> Result<(ZernikeSurface, ZernikeSurface), SurfacesOrFlatError> {
    let Some(path) = path else {
        return station
            .element
            .nominal_surfaces(1)
            .map_err(SurfacesOrFlatError::Flat);
    };
    let file = SurfacesFile::load(path)?;
    let make = |coefficients: Option<&Vec<f64>>| {
        to_surface(&file, coefficients).map_err(|source| SurfacesOrFlatError::Build {
            path: path.to_path_buf(),
            source,
        })
    };
    Ok((
        make(file.front_coefficients())?,
        make(file.back_coefficients())?,
    ))
}

#[cfg(test)]
#[path = "surfaces_file_tests.rs"]
mod tests;

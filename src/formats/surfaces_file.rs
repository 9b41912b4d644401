//! `surfaces.json` (`mfd-surfaces/1`): front and back Zernike coefficients.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::optics::zernike::{ZernikeBasis, ZernikeError, ZernikeSurface};

/// The format tag of a surfaces file.
pub const SURFACES_FORMAT: &str = "mfd-surfaces/1";

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
    /// Not valid JSON for `mfd-surfaces/1`.
    #[error("{path}: not a valid mfd-surfaces/1 file: {source}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The JSON error (names the field and line).
        #[source]
        source: serde_json::Error,
    },
    /// A field holds an impossible value.
    #[error("{path}: field `{field}`: {problem}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The field, e.g. `front.coefficients_nm[3]`.
        field: String,
        /// What is wrong.
        problem: String,
    },
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

/// One surface's coefficients.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SurfaceCoefficients {
    /// `coefficients_nm[k]` is Noll j = k + 1, nm.
    pub coefficients_nm: Vec<f64>,
}

/// The whole file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SurfacesFile {
    /// Must be [`SURFACES_FORMAT`].
    pub format: String,
    /// Basis definition.
    pub zernike: ZernikeSpec,
    /// Front surface, or `null` when not reconstructed.
    pub front: Option<SurfaceCoefficients>,
    /// Back surface, or `null` when not reconstructed.
    pub back: Option<SurfaceCoefficients>,
}

impl SurfacesFile {
    /// Reads and validates a surfaces file.
    ///
    /// # Errors
    /// [`SurfacesFileError`] naming the file and field.
    pub fn load(path: &Path) -> Result<Self, SurfacesFileError> {
        let text = std::fs::read_to_string(path).map_err(|source| SurfacesFileError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let file: SurfacesFile =
            serde_json::from_str(&text).map_err(|source| SurfacesFileError::Parse {
                path: path.to_path_buf(),
                source,
            })?;
        file.validate(path)?;
        Ok(file)
    }

    fn validate(&self, path: &Path) -> Result<(), SurfacesFileError> {
        let bad = |field: &str, problem: String| {
            Err(SurfacesFileError::Invalid {
                path: path.to_path_buf(),
                field: field.to_string(),
                problem,
            })
        };
        if self.format != SURFACES_FORMAT {
            return bad(
                "format",
                format!("expected \"{SURFACES_FORMAT}\", found \"{}\"", self.format),
            );
        }
        let z = &self.zernike;
        if z.ordering != "noll" {
            return bad(
                "zernike.ordering",
                format!("expected \"noll\", found \"{}\"", z.ordering),
            );
        }
        if z.normalization != "rms" {
            return bad(
                "zernike.normalization",
                format!("expected \"rms\", found \"{}\"", z.normalization),
            );
        }
        if !(z.radius_mm.is_finite() && z.radius_mm > 0.0) {
            return bad(
                "zernike.radius_mm",
                format!("expected a finite radius > 0, found {}", z.radius_mm),
            );
        }
        if !z.center_mm.iter().all(|c| c.is_finite()) {
            return bad(
                "zernike.center_mm",
                format!("expected finite numbers, found {:?}", z.center_mm),
            );
        }
        for (name, s) in [("front", &self.front), ("back", &self.back)] {
            let Some(s) = s else { continue };
            if s.coefficients_nm.is_empty() {
                return bad(
                    &format!("{name}.coefficients_nm"),
                    "expected at least one coefficient".into(),
                );
            }
            if let Some((k, c)) = s
                .coefficients_nm
                .iter()
                .enumerate()
                .find(|(_, c)| !c.is_finite())
            {
                return bad(
                    &format!("{name}.coefficients_nm[{k}]"),
                    format!("expected a finite number, found {c}"),
                );
            }
        }
        Ok(())
    }

    /// Writes the file as pretty JSON.
    ///
    /// # Errors
    /// [`SurfacesFileError::Io`].
    pub fn save(&self, path: &Path) -> Result<(), SurfacesFileError> {
        let text = serde_json::to_string_pretty(self).unwrap_or_default();
        std::fs::write(path, text + "\n").map_err(|source| SurfacesFileError::Io {
            path: path.to_path_buf(),
            source,
        })
    }

    /// The file describing two surfaces (on the front's basis disk).
    pub fn from_surfaces(front: &ZernikeSurface, back: &ZernikeSurface) -> Self {
        let b = front.basis();
        SurfacesFile {
            format: SURFACES_FORMAT.to_string(),
            zernike: ZernikeSpec {
                ordering: "noll".into(),
                normalization: "rms".into(),
                radius_mm: b.radius_mm(),
                center_mm: b.center_mm(),
            },
            front: Some(SurfaceCoefficients {
                coefficients_nm: front.coefficients_nm().to_vec(),
            }),
            back: Some(SurfaceCoefficients {
                coefficients_nm: back.coefficients_nm().to_vec(),
            }),
        }
    }

    /// Front coefficients, if present.
    pub fn front_coefficients(&self) -> Option<&Vec<f64>> {
        self.front.as_ref().map(|s| &s.coefficients_nm)
    }

    /// Back coefficients, if present.
    pub fn back_coefficients(&self) -> Option<&Vec<f64>> {
        self.back.as_ref().map(|s| &s.coefficients_nm)
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

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"{"format": "mfd-surfaces/1",
        "zernike": {"ordering": "noll", "normalization": "rms", "radius_mm": 25.5, "center_mm": [0.0, 0.0]},
        "front": {"coefficients_nm": [0.0, 12.5, -3.1, 40.2]}, "back": null}"#;

    fn load_text(text: &str) -> Result<SurfacesFile, SurfacesFileError> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("surfaces.json");
        std::fs::write(&p, text).unwrap();
        SurfacesFile::load(&p)
    }

    #[test]
    fn spec_example_loads_and_round_trips() {
        let f = load_text(GOOD).unwrap();
        assert_eq!(f.front_coefficients().unwrap().len(), 4);
        assert!(f.back.is_none());
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("s.json");
        f.save(&p).unwrap();
        assert_eq!(SurfacesFile::load(&p).unwrap(), f);
    }

    #[test]
    fn bad_files_name_the_field() {
        let err = load_text(&GOOD.replace("\"noll\"", "\"ansi\""))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("zernike.ordering") && err.contains("ansi"),
            "{err}"
        );
        let err = load_text(&GOOD.replace("\"back\": null", "\"back\": null, \"extra\": 1"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("extra"), "{err}");
        let err = load_text(&GOOD.replace("25.5", "-1"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("zernike.radius_mm"), "{err}");
    }
}

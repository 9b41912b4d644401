//! `mfd-station-uncertainty/1` (`interchange.md`): how well each degree of
//! freedom of a station is known, as 1σ values (`[std]`) and/or a
//! covariance over named degrees of freedom (`[covariance]`); where both
//! give a name, the covariance holds. Reader (strict, errors naming the
//! file and field) and writer.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use super::Dof;

/// The format tag.
pub const UNCERTAINTY_FORMAT: &str = "mfd-station-uncertainty/1";

/// What went wrong reading or writing a station uncertainty.
#[derive(Debug, thiserror::Error)]
pub enum UncertaintyError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// Not valid TOML of this format (the TOML error names the field).
    #[error("{path}: not a valid {UNCERTAINTY_FORMAT} file: {source}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The TOML error.
        #[source]
        source: toml::de::Error,
    },
    /// A field holds what the format does not allow.
    #[error("{path}: field `{field}`: {problem}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The field, e.g. `covariance.matrix` or `std."camera.z_mm"`.
        field: String,
        /// What is wrong and what was expected.
        problem: String,
    },
}

impl crate::outcome::Classify for UncertaintyError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        Some(Outcome::Input)
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct UncertaintyFile {
    format: String,
    station: String,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    std: BTreeMap<String, f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    covariance: Option<CovarianceFile>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct CovarianceFile {
    names: Vec<String>,
    matrix: Vec<Vec<f64>>,
}

/// The uncertainty of a station: the covariance over the degrees of
/// freedom named, every other one exact.
#[derive(Debug, Clone, PartialEq)]
pub struct StationUncertainty {
    /// The station file these are the uncertainties of, as written in the file.
    pub station: String,
    /// The degrees of freedom with a known uncertainty, in the file's order
    /// (covariance names first, then `[std]` names).
    pub names: Vec<Dof>,
    /// Their covariance (units: the names' units squared).
    pub covariance: DMatrix<f64>,
    /// How many leading `names` came from `[covariance]` (the rest from
    /// `[std]`, uncorrelated); the writer keeps the split.
    pub correlated: usize,
}

/// Relative tolerance of the covariance's symmetry: files are written with
/// ~16 digits, a hand-typed matrix with fewer; 1e-9 accepts both.
const SYMMETRY_TOL: f64 = 1e-9;

/// The largest 1σ a degree of freedom may have, and its unit: beyond it
/// the quantity is not uncertain but unknown, and a linearised budget about
/// the nominal station means nothing (a camera 1 m off, a screen turned by
/// 90°). Lengths 1000 mm (the size of a whole station), angles 90°, the
/// principal point a sensor's largest side (65 536 px), dimensionless
/// quantities (distortion coefficients, the refractive index) 1.
fn largest_std(d: Dof) -> (f64, &'static str) {
    let name = d.name();
    if name.ends_with("_mm") {
        (1000.0, "mm")
    } else if name.ends_with("_deg") {
        (90.0, "°")
    } else if name.ends_with("_px") {
        (65_536.0, "px")
    } else {
        (1.0, "(dimensionless)")
    }
}

impl StationUncertainty {
    /// Reads and validates a file.
    ///
    /// # Errors
    /// [`UncertaintyError`] naming the file and field.
    pub fn load(path: &Path) -> Result<Self, UncertaintyError> {
        let text = std::fs::read_to_string(path).map_err(|source| UncertaintyError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_toml_str(&text, path)
    }

    /// Parses and validates; `path` is only used in errors.
    ///
    /// # Errors
    /// [`UncertaintyError::Parse`] or [`UncertaintyError::Invalid`].
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Self, UncertaintyError> {
        let file: UncertaintyFile =
            toml::from_str(text).map_err(|source| UncertaintyError::Parse {
                path: path.to_path_buf(),
                source,
            })?;
        let fail = |field: String, problem: String| UncertaintyError::Invalid {
            path: path.to_path_buf(),
            field,
            problem,
        };
        if file.format != UNCERTAINTY_FORMAT {
            return Err(fail(
                "format".into(),
                format!(
                    "expected \"{UNCERTAINTY_FORMAT}\", found \"{}\"",
                    file.format
                ),
            ));
        }
        let dof = |name: &str, field: String| {
            Dof::parse(name).ok_or_else(|| {
                fail(
                    field,
                    format!(
                        "`{name}` is not a degree of freedom of the spec's table (e.g. \
                         \"camera.z_mm\", \"screen.rz_deg\", \"element.thickness_mm\")"
                    ),
                )
            })
        };
        let mut names = Vec::new();
        let mut values: Vec<Vec<f64>> = Vec::new();
        if let Some(c) = &file.covariance {
            for (k, n) in c.names.iter().enumerate() {
                let d = dof(n, format!("covariance.names[{k}]"))?;
                if names.contains(&d) {
                    return Err(fail(
                        format!("covariance.names[{k}]"),
                        format!("`{n}` twice"),
                    ));
                }
                names.push(d);
            }
            check_matrix(&c.matrix, names.len())
                .map_err(|p| fail("covariance.matrix".into(), p))?;
            for (k, &d) in names.iter().enumerate() {
                let (max, unit) = largest_std(d);
                let std = c.matrix[k][k].sqrt();
                if std > max {
                    return Err(fail(
                        format!("covariance.matrix[{k}][{k}]"),
                        format!(
                            "1σ of {} = {std}: above the {max} {unit} that is still an uncertainty",
                            d.name()
                        ),
                    ));
                }
            }
            values = c.matrix.clone();
        }
        let correlated = names.len();
        for (n, &s) in &file.std {
            let field = format!("std.\"{n}\"");
            let d = dof(n, field.clone())?;
            if !(s.is_finite() && s >= 0.0) {
                return Err(fail(field, format!("expected a finite 1σ ≥ 0, found {s}")));
            }
            let (max, unit) = largest_std(d);
            if s > max {
                return Err(fail(
                    field,
                    format!("1σ = {s}: above the {max} {unit} that is still an uncertainty"),
                ));
            }
            if !names.contains(&d) {
                names.push(d);
                values.push(vec![s * s]);
            }
        }
        let m = names.len();
        let mut covariance = DMatrix::zeros(m, m);
        for r in 0..m {
            if r < correlated {
                for c in 0..correlated {
                    covariance[(r, c)] = 0.5 * (values[r][c] + values[c][r]);
                }
            } else {
                covariance[(r, r)] = values[r][0];
            }
        }
        Ok(StationUncertainty {
            station: file.station,
            names,
            covariance,
            correlated,
        })
    }

    /// The 1σ of `dof`, 0 when it is exact.
    pub fn std_of(&self, dof: Dof) -> f64 {
        self.names
            .iter()
            .position(|&d| d == dof)
            .map_or(0.0, |k| self.covariance[(k, k)].sqrt())
    }

    /// TOML text: `[covariance]` for the first `correlated` names, `[std]`
    /// for the rest.
    pub fn to_toml_string(&self) -> String {
        let k = self.correlated;
        let file = UncertaintyFile {
            format: UNCERTAINTY_FORMAT.into(),
            station: self.station.clone(),
            std: self.names[k..]
                .iter()
                .enumerate()
                .map(|(i, d)| (d.name().to_string(), self.covariance[(k + i, k + i)].sqrt()))
                .collect(),
            covariance: (k > 0).then(|| CovarianceFile {
                names: self.names[..k]
                    .iter()
                    .map(|d| d.name().to_string())
                    .collect(),
                matrix: (0..k)
                    .map(|r| (0..k).map(|c| self.covariance[(r, c)]).collect())
                    .collect(),
            }),
        };
        // Plain strings, numbers and arrays: serialising cannot fail.
        toml::to_string(&file).unwrap_or_default()
    }

    /// Writes the file.
    ///
    /// # Errors
    /// [`UncertaintyError::Io`].
    pub fn save(&self, path: &Path) -> Result<(), UncertaintyError> {
        std::fs::write(path, self.to_toml_string()).map_err(|source| UncertaintyError::Io {
            path: path.to_path_buf(),
            source,
        })
    }
}

/// Square, the names' size, finite, symmetric, with a non-negative
/// diagonal and positive semi-definite (Cholesky of the matrix plus a
/// relative 1e-12 of its diagonal, the rounding a writer leaves).
fn check_matrix(m: &[Vec<f64>], n: usize) -> Result<(), String> {
    if m.len() != n || m.iter().any(|r| r.len() != n) {
        return Err(format!(
            "expected a {n}×{n} matrix (one row and column per name)"
        ));
    }
    let a = DMatrix::from_fn(n, n, |r, c| m[r][c]);
    if a.iter().any(|v| !v.is_finite()) {
        return Err("expected finite numbers".into());
    }
    for r in 0..n {
        if a[(r, r)] < 0.0 {
            return Err(format!("diagonal element {r} is negative ({})", a[(r, r)]));
        }
        for c in 0..r {
            let scale = (a[(r, r)] * a[(c, c)]).sqrt().max(f64::MIN_POSITIVE);
            if (a[(r, c)] - a[(c, r)]).abs() > SYMMETRY_TOL * scale {
                return Err(format!("not symmetric at [{r}][{c}]"));
            }
        }
    }
    let mut jittered = a.clone();
    for r in 0..n {
        jittered[(r, r)] += 1e-12 * a[(r, r)] + f64::MIN_POSITIVE;
    }
    if jittered.cholesky().is_none() {
        return Err("not positive semi-definite: no covariance can be".into());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const SPEC: &str = r#"
format = "mfd-station-uncertainty/1"
station = "station.toml"

[std]
"camera.z_mm" = 0.5
"screen.rz_deg" = 0.01
"element.thickness_mm" = 0.002

[covariance]
names = ["camera.x_mm", "camera.z_mm"]
matrix = [[0.04, 0.01], [0.01, 0.25]]
"#;

    /// Issue 19: a 1σ of 1e200 mm was read (and squared to inf in the
    /// covariance); one above what is still an uncertainty is refused.
    #[test]
    fn a_std_beyond_any_uncertainty_is_refused() {
        let text = SPEC.replace("\"camera.z_mm\" = 0.5", "\"camera.z_mm\" = 1e200");
        let err = StationUncertainty::from_toml_str(&text, Path::new("u.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("camera.z_mm") && err.contains("1000 mm"),
            "{err}"
        );
        let text = SPEC.replace("\"screen.rz_deg\" = 0.01", "\"screen.rz_deg\" = 120.0");
        let err = StationUncertainty::from_toml_str(&text, Path::new("u.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("screen.rz_deg") && err.contains("90"), "{err}");
        let text = SPEC.replace("[0.01, 0.25]]", "[0.01, 4e6]]");
        let err = StationUncertainty::from_toml_str(&text, Path::new("u.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("covariance.matrix[1][1]"), "{err}");
    }

    #[test]
    fn the_specs_example_reads_and_the_covariance_holds() {
        let u = StationUncertainty::from_toml_str(SPEC, Path::new("u.toml")).unwrap();
        assert_eq!(u.names.len(), 4);
        // camera.z_mm is in both: the covariance's 0.25 holds, not 0.5².
        assert_eq!(u.std_of(Dof::CameraZ), 0.5);
        assert_eq!(u.covariance[(0, 1)], 0.01);
        assert_eq!(u.std_of(Dof::ScreenRz), 0.01);
        assert_eq!(u.std_of(Dof::K1), 0.0);
        let again = StationUncertainty::from_toml_str(&u.to_toml_string(), Path::new("v")).unwrap();
        assert_eq!(again, u);
    }

    #[test]
    fn bad_files_name_the_field() {
        let cases = [
            (
                SPEC.replace("camera.z_mm\" = 0.5", "camera.zz\" = 0.5"),
                "std.\"camera.zz\"",
            ),
            (
                SPEC.replace("\"screen.rz_deg\" = 0.01", "\"screen.rz_deg\" = -0.01"),
                "screen.rz_deg",
            ),
            (
                SPEC.replace("[0.01, 0.25]]", "[0.02, 0.25]]"),
                "covariance.matrix",
            ),
            (
                SPEC.replace("[0.01, 0.25]]", "[0.01, 0.001]]"),
                "covariance.matrix",
            ),
            (
                SPEC.replace("[0.01, 0.25]]", "[0.01, 0.25], [0.0, 0.0]]"),
                "covariance.matrix",
            ),
            (SPEC.replace("/1\"", "/2\""), "format"),
        ];
        for (text, field) in cases {
            let err = StationUncertainty::from_toml_str(&text, Path::new("u.toml"))
                .unwrap_err()
                .to_string();
            assert!(
                err.contains("u.toml") && err.contains(field),
                "{field}: {err}"
            );
        }
    }
}

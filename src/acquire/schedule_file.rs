//! The schedule file, `mfd-schedule/1` (`interchange.md`, "Schedule"): the
//! patterns of an acquisition before it is taken, in display order. Its
//! serde types, the one strict reader and the one writer; `mfd plan` writes
//! it, `mfd budget`, `mfd plan`, `mfd simulate` and `mfd measure` read it.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::acquire::acquisition::FrameInfo;
use crate::acquire::patterns::{first_beyond_screen, Pattern, MAX_FRAMES};

/// The format tag of a schedule file.
pub const SCHEDULE_FORMAT: &str = "mfd-schedule/1";

/// What went wrong reading or writing a schedule file.
#[derive(Debug, thiserror::Error)]
pub enum ScheduleFileError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// Not TOML of the format's shape (the TOML error names the field).
    #[error("{path}: not a valid {SCHEDULE_FORMAT} file: {source}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The TOML error.
        #[source]
        source: Box<toml::de::Error>,
    },
    /// A field holds what the spec does not allow.
    #[error("{path}: {field}: {problem}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The field, e.g. `frame[3].tau`.
        field: String,
        /// What is wrong and what was expected.
        problem: String,
    },
}

impl crate::outcome::Classify for ScheduleFileError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        Some(Outcome::Input)
    }
}

/// The file as serde sees it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScheduleFile {
    /// Must be [`SCHEDULE_FORMAT`].
    pub format: String,
    /// One entry per frame, in display order.
    pub frame: Vec<ScheduleFrame>,
}

/// One `[[frame]]` table.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScheduleFrame {
    /// Fringe direction, degrees.
    pub direction_deg: f64,
    /// Fringe periods across the screen, > 0.
    pub tau: f64,
    /// Phase offset, radians (optional in the file; default 0).
    #[serde(default)]
    pub phase_rad: f64,
}

impl ScheduleFile {
    /// The file of `frames`, in their order.
    pub fn from_frames(frames: &[FrameInfo]) -> Self {
        ScheduleFile {
            format: SCHEDULE_FORMAT.to_string(),
            frame: frames
                .iter()
                .map(|f| ScheduleFrame {
                    direction_deg: f.direction_deg,
                    tau: f.tau,
                    phase_rad: f.phase_rad,
                })
                .collect(),
        }
    }

    /// The frames, indexed in display order.
    pub fn frames(&self) -> Vec<FrameInfo> {
        self.frame
            .iter()
            .enumerate()
            .map(|(index, f)| FrameInfo {
                index,
                direction_deg: f.direction_deg,
                tau: f.tau,
                phase_rad: f.phase_rad,
            })
            .collect()
    }

    /// The patterns, in display order.
    pub fn patterns(&self) -> Vec<Pattern> {
        self.frame
            .iter()
            .map(|f| Pattern {
                direction_deg: f.direction_deg,
                tau: f.tau,
                phase_rad: f.phase_rad,
            })
            .collect()
    }

    /// Checks what the spec requires beyond the TOML shape: the format tag,
    /// at least one frame, finite directions and phases, finite τ > 0.
    ///
    /// # Errors
    /// [`ScheduleFileError::Invalid`] naming `path` and the field.
    pub fn validate(&self, path: &Path) -> Result<(), ScheduleFileError> {
        let bad = |field: String, problem: String| ScheduleFileError::Invalid {
            path: path.to_path_buf(),
            field,
            problem,
        };
        if self.format != SCHEDULE_FORMAT {
            return Err(bad(
                "format".into(),
                format!("expected \"{SCHEDULE_FORMAT}\", found \"{}\"", self.format),
            ));
        }
        if self.frame.is_empty() {
            return Err(bad(
                "frame".into(),
                "no [[frame]] table: a schedule needs frames".into(),
            ));
        }
        if self.frame.len() > MAX_FRAMES {
            return Err(bad(
                "frame".into(),
                format!(
                    "{} [[frame]] tables: above the {MAX_FRAMES} frames a schedule may have",
                    self.frame.len()
                ),
            ));
        }
        for (index, f) in self.frame.iter().enumerate() {
            for (name, v, ok) in [
                (
                    "direction_deg",
                    f.direction_deg,
                    f.direction_deg.is_finite(),
                ),
                ("tau", f.tau, f.tau.is_finite() && f.tau > 0.0),
                ("phase_rad", f.phase_rad, f.phase_rad.is_finite()),
            ] {
                if !ok {
                    let want = if name == "tau" {
                        "a finite τ > 0"
                    } else {
                        "a finite number"
                    };
                    return Err(bad(
                        format!("frame[{index}].{name}"),
                        format!("expected {want}, found {v}"),
                    ));
                }
            }
        }
        Ok(())
    }
}

impl ScheduleFile {
    /// Checks that a `width × height` screen can show every frame's τ
    /// (the display's Nyquist limit, [`crate::acquire::patterns::FringeAxis::max_tau`]).
    ///
    /// # Errors
    /// [`ScheduleFileError::Invalid`] naming `path`, `frame[k].tau` and the limit.
    pub fn check_against_screen(
        &self,
        path: &Path,
        width: u32,
        height: u32,
    ) -> Result<(), ScheduleFileError> {
        let frames = self.frame.iter().map(|f| (f.direction_deg, f.tau));
        match first_beyond_screen(frames, width, height) {
            None => Ok(()),
            Some((index, problem)) => Err(ScheduleFileError::Invalid {
                path: path.to_path_buf(),
                field: format!("frame[{index}].tau"),
                problem,
            }),
        }
    }
}

/// Reads an `mfd-schedule/1` file: its frames in display order.
///
/// # Errors
/// [`ScheduleFileError`] naming the file and the field (`frame[k].tau`, ...).
pub fn load(path: &Path) -> Result<ScheduleFile, ScheduleFileError> {
    let text = std::fs::read_to_string(path).map_err(|source| ScheduleFileError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let file: ScheduleFile = toml::from_str(&text).map_err(|source| ScheduleFileError::Parse {
        path: path.to_path_buf(),
        source: Box::new(source),
    })?;
    file.validate(path)?;
    Ok(file)
}

/// Writes `frames` as an `mfd-schedule/1` file (the one writer), with a
/// comment line on top (`#`-prefixed by this function).
///
/// # Errors
/// [`ScheduleFileError::Invalid`] for frames the reader would reject (so
/// no file is written that cannot be read back), [`ScheduleFileError::Io`].
pub fn write(path: &Path, frames: &[FrameInfo], comment: &str) -> Result<(), ScheduleFileError> {
    let file = ScheduleFile::from_frames(frames);
    file.validate(path)?;
    let body = toml::to_string(&file).map_err(|e| ScheduleFileError::Invalid {
        path: path.to_path_buf(),
        field: "frame".into(),
        problem: format!("cannot be written as TOML: {e}"),
    })?;
    let mut text = String::new();
    for line in comment.lines() {
        text.push_str("# ");
        text.push_str(line);
        text.push('\n');
    }
    text.push_str(&body);
    std::fs::write(path, text).map_err(|source| ScheduleFileError::Io {
        path: path.to_path_buf(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frames() -> Vec<FrameInfo> {
        [(45.0, 0.5, 0.0), (-45.0, 97.3, 1.234_567_890_123)]
            .iter()
            .enumerate()
            .map(|(index, &(d, t, p))| FrameInfo {
                index,
                direction_deg: d,
                tau: t,
                phase_rad: p,
            })
            .collect()
    }

    #[test]
    fn writer_and_reader_round_trip_exactly() {
        let dir = std::env::temp_dir().join(format!("mfd-schedule-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("s.toml");
        write(&path, &frames(), "a test\nof two lines").unwrap();
        let back = load(&path).unwrap().frames();
        // Floats are written in their shortest round-trip form: bit-exact.
        assert_eq!(back, frames());
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn tau_beyond_the_screen_names_the_frame() {
        let file = ScheduleFile::from_frames(&frames());
        let path = Path::new("s.toml");
        assert!(file.check_against_screen(path, 1600, 1200).is_ok());
        // Frame 1 is τ = 97.3 at −45°: a 100×100 screen shows τ ≤ 100·√2/2 = 70.7.
        let err = file.check_against_screen(path, 100, 100).unwrap_err();
        let err = err.to_string();
        assert!(
            err.contains("frame[1].tau") && err.contains("70.71"),
            "{err}"
        );
    }

    #[test]
    fn more_frames_than_a_schedule_may_have_are_refused() {
        let one = frames()[0];
        let many = vec![one; MAX_FRAMES + 1];
        let err = ScheduleFile::from_frames(&many)
            .validate(Path::new("s.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("100000"), "{err}");
    }

    #[test]
    fn writer_refuses_what_the_reader_rejects() {
        let mut f = frames();
        f[1].tau = 0.0;
        let path = Path::new("/nonexistent/never-written.toml");
        let err = write(path, &f, "").unwrap_err().to_string();
        assert!(err.contains("frame[1].tau"), "{err}");
    }
}

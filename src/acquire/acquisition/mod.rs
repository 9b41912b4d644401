//! Acquisition folders (`mfd-acquisition/1`): the manifest, the one reader
//! the solvers and tools use, and the one writer, in two modes: a whole
//! acquisition (the simulator) and a crash-safe append (the recorder).
//! Frames are read one at a time, never all at once.

mod append;
mod manifest;
mod range;
mod same;
mod writer;

use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

pub use manifest::{FrameEntry, ManifestFile, ACQUISITION_FORMAT};
pub use range::check_against_station;
pub use same::file_identity;
pub use writer::{AcquisitionWriter, FrameImage, FrameLayout};

use crate::acquire::patterns::MAX_FRAMES;
use crate::formats::image_io::{self, GrayHeader, ImageError};
use crate::formats::npy::{NpyError, NpyStackReader};

/// File name of the manifest inside an acquisition folder.
pub const MANIFEST: &str = "acquisition.toml";

/// What went wrong with an acquisition.
#[derive(Debug, thiserror::Error)]
pub enum AcquisitionError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The manifest is not valid TOML for `mfd-acquisition/1`.
    #[error("{path}: not a valid mfd-acquisition/1 manifest: {source}")]
    Parse {
        /// The manifest.
        path: PathBuf,
        /// The TOML error, which names the field.
        #[source]
        source: toml::de::Error,
    },
    /// A manifest field holds an impossible value.
    #[error("{path}: field `{field}`: {problem}")]
    Invalid {
        /// The manifest.
        path: PathBuf,
        /// Field, e.g. `frame[17].tau`.
        field: String,
        /// What is wrong.
        problem: String,
    },
    /// One frame cannot be used.
    #[error("frame {frame} ({path}): {problem}")]
    Frame {
        /// Frame index in capture order.
        frame: usize,
        /// Its file.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// The frame stack is unreadable or does not match the manifest.
    #[error(transparent)]
    Stack(#[from] NpyError),
    /// A frame image is unreadable.
    #[error("frame {frame}: {source}")]
    Image {
        /// Frame index.
        frame: usize,
        /// The image error, naming the file.
        #[source]
        source: ImageError,
    },
    /// The manifest could not be serialised (a value TOML cannot hold).
    #[error("{path}: cannot write the manifest: {source}")]
    Serialize {
        /// The manifest.
        path: PathBuf,
        /// The TOML error, which names the value.
        #[source]
        source: toml::ser::Error,
    },
    /// The writer would replace an existing acquisition.
    #[error("{path}: an acquisition is already there (pass --overwrite to replace it)")]
    Exists {
        /// The existing manifest.
        path: PathBuf,
    },
}

impl crate::outcome::Classify for AcquisitionError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        // A file that cannot be written, or an I/O fault on one that is
        // there, is not the input's fault: the cause decides (no class).
        match self {
            AcquisitionError::Io { source, .. } => crate::outcome::io_outcome(source),
            AcquisitionError::Serialize { .. } => None,
            AcquisitionError::Stack(e) => e.outcome(),
            _ => Some(Outcome::Input),
        }
    }
}

/// One frame's pattern.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameInfo {
    /// Index in capture order.
    pub index: usize,
    /// Fringe direction, degrees.
    pub direction_deg: f64,
    /// Fringe periods across the screen.
    pub tau: f64,
    /// Phase offset, radians.
    pub phase_rad: f64,
}

impl FrameInfo {
    /// The frames of `patterns` shown in that order.
    pub fn from_patterns(patterns: &[crate::acquire::patterns::Pattern]) -> Vec<FrameInfo> {
        patterns
            .iter()
            .enumerate()
            .map(|(index, p)| FrameInfo {
                index,
                direction_deg: p.direction_deg,
                tau: p.tau,
                phase_rad: p.phase_rad,
            })
            .collect()
    }
}

#[derive(Debug)]
enum Source {
    Stack(Mutex<NpyStackReader>),
    Files(Vec<PathBuf>),
}

/// An opened acquisition folder.
#[derive(Debug)]
pub struct Acquisition {
    manifest_path: PathBuf,
    station_path: PathBuf,
    frames: Vec<FrameInfo>,
    source: Source,
    resolution: Option<(u32, u32)>,
    /// Frame 0's size and bit depth, once a frame file was read.
    first: OnceLock<GrayHeader>,
}

impl Acquisition {
    /// Opens `dir/acquisition.toml` (or a manifest path) and checks it
    /// against the spec and the stack.
    ///
    /// # Errors
    /// [`AcquisitionError`] naming the file, field or frame.
    pub fn open(dir_or_manifest: &Path) -> Result<Self, AcquisitionError> {
        let manifest_path = if dir_or_manifest.is_dir() {
            dir_or_manifest.join(MANIFEST)
        } else {
            dir_or_manifest.to_path_buf()
        };
        let text =
            std::fs::read_to_string(&manifest_path).map_err(|source| AcquisitionError::Io {
                path: manifest_path.clone(),
                source,
            })?;
        let file: ManifestFile =
            toml::from_str(&text).map_err(|source| AcquisitionError::Parse {
                path: manifest_path.clone(),
                source,
            })?;
        Self::from_manifest(file, manifest_path)
    }

    fn from_manifest(file: ManifestFile, manifest_path: PathBuf) -> Result<Self, AcquisitionError> {
        let invalid = |field: String, problem: String| AcquisitionError::Invalid {
            path: manifest_path.clone(),
            field,
            problem,
        };
        if file.format != ACQUISITION_FORMAT {
            return Err(invalid(
                "format".into(),
                format!(
                    "expected \"{ACQUISITION_FORMAT}\", found \"{}\"",
                    file.format
                ),
            ));
        }
        if file.frames.is_empty() {
            return Err(invalid("frame".into(), "no [[frame]] tables".into()));
        }
        if file.frames.len() > MAX_FRAMES {
            return Err(invalid(
                "frame".into(),
                format!(
                    "{} [[frame]] tables: above the {MAX_FRAMES} frames an acquisition may have",
                    file.frames.len()
                ),
            ));
        }
        let dir = manifest_path
            .parent()
            .unwrap_or(Path::new("."))
            .to_path_buf();
        let mut frames = Vec::with_capacity(file.frames.len());
        let mut files = Vec::new();
        let mut names = Vec::new();
        for (index, f) in file.frames.iter().enumerate() {
            let (info, name) = frame_entry(index, f, file.stack.is_some())
                .map_err(|(field, problem)| invalid(field, problem))?;
            files.extend(name.map(|n| dir.join(n)));
            names.extend(name);
            frames.push(info);
        }
        same::check_distinct(&manifest_path, &files, &names)?;
        let source = match &file.stack {
            Some(name) => {
                let reader = NpyStackReader::open(&dir.join(name))?;
                if reader.frames() != frames.len() {
                    return Err(invalid(
                        "stack".into(),
                        format!(
                            "{name} holds {} frames, the manifest lists {}",
                            reader.frames(),
                            frames.len()
                        ),
                    ));
                }
                Source::Stack(Mutex::new(reader))
            }
            None => Source::Files(files),
        };
        Ok(Acquisition {
            station_path: dir.join(&file.station),
            manifest_path,
            frames,
            source,
            resolution: None,
            first: OnceLock::new(),
        })
    }

    /// The manifest's path.
    pub fn manifest_path(&self) -> &Path {
        &self.manifest_path
    }

    /// The station file the manifest names (not parsed here).
    pub fn station_path(&self) -> &Path {
        &self.station_path
    }

    /// Frames in capture order.
    pub fn frames(&self) -> &[FrameInfo] {
        &self.frames
    }

    /// Frames present in full on disk: all of them, unless a stack was cut short.
    pub fn complete_frames(&self) -> usize {
        match &self.source {
            Source::Stack(r) => r.lock().map_or(0, |r| r.complete_frames()),
            Source::Files(f) => f.iter().take_while(|p| p.is_file()).count(),
        }
    }

    /// Requires every frame to be `width × height` (the camera's resolution):
    /// checked now for a stack, on each read for files.
    ///
    /// # Errors
    /// [`AcquisitionError::Invalid`] when the stack's frame shape differs.
    pub fn check_resolution(&mut self, width: u32, height: u32) -> Result<(), AcquisitionError> {
        if let Source::Stack(r) = &self.source {
            let shape = r.lock().map(|r| r.frame_shape()).unwrap_or((0, 0));
            if shape != (height as usize, width as usize) {
                return Err(AcquisitionError::Invalid {
                    path: self.manifest_path.clone(),
                    field: "stack".into(),
                    problem: format!(
                        "frames are {}x{} (columns x rows), the camera is {width}x{height}",
                        shape.1, shape.0
                    ),
                });
            }
        }
        self.resolution = Some((width, height));
        Ok(())
    }

    /// Reads frame `index` (capture order) into `out`, row-major counts.
    ///
    /// # Errors
    /// [`AcquisitionError`] naming the frame and its file.
    pub fn read_frame(&self, index: usize, out: &mut Vec<u16>) -> Result<(), AcquisitionError> {
        match &self.source {
            Source::Stack(r) => {
                let mut r = r.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
                r.read_frame(index, out)?;
                Ok(())
            }
            Source::Files(files) => {
                let path = files.get(index).ok_or_else(|| AcquisitionError::Frame {
                    frame: index,
                    path: self.manifest_path.clone(),
                    problem: format!("no such frame (the manifest lists {})", files.len()),
                })?;
                let img = image_io::read_gray(path).map_err(|source| AcquisitionError::Image {
                    frame: index,
                    source,
                })?;
                same::check_like_first(&self.first, files, index, img.header())?;
                if let Some((w, h)) = self.resolution.filter(|&r| r != (img.width, img.height)) {
                    return Err(AcquisitionError::Frame {
                        frame: index,
                        path: path.clone(),
                        problem: format!("{}x{} pixels, expected {w}x{h}", img.width, img.height),
                    });
                }
                *out = img.data;
                Ok(())
            }
        }
    }
}

/// One `[[frame]]` table checked: τ > 0 and finite angles, and a `file`
/// exactly when there is no `stack`. Returns the frame and its file; the
/// error is the field (`frame[i].tau`, ...) and what is wrong with it.
fn frame_entry(
    index: usize,
    f: &FrameEntry,
    stack: bool,
) -> Result<(FrameInfo, Option<&str>), (String, String)> {
    let bad = |field: &str, problem: String| Err((format!("frame[{index}].{field}"), problem));
    if !(f.tau.is_finite() && f.tau > 0.0) {
        return bad("tau", format!("expected τ > 0, found {}", f.tau));
    }
    if !f.direction_deg.is_finite() {
        return bad("direction_deg", "expected a finite angle".into());
    }
    let phase_rad = f.phase_rad.unwrap_or(0.0);
    if !phase_rad.is_finite() {
        return bad("phase_rad", "expected a finite phase".into());
    }
    let name = match (stack, &f.file) {
        (true, Some(_)) => {
            return bad(
                "file",
                "a frame file is given although `stack` holds all frames".into(),
            )
        }
        (false, None) => {
            return bad(
                "file",
                "missing: without `stack` every frame needs a file".into(),
            )
        }
        (false, Some(name)) => Some(name.as_str()),
        (true, None) => None,
    };
    let info = FrameInfo {
        index,
        direction_deg: f.direction_deg,
        tau: f.tau,
        phase_rad,
    };
    Ok((info, name))
}

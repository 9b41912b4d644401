//! The recorder: writes the spec's acquisition folder (`mfd-acquisition/1`)
//! as frames arrive, so that a crash at any moment leaves a readable
//! partial acquisition.
//!
//! Layout: one PNG per frame (`frames/NNNNNN.png`, 8-bit for 8-bit cameras,
//! 16-bit otherwise, raw counts) and no `stack`, because a stack's header
//! fixes the frame count up front. Each frame is written to a temporary
//! name and renamed; only then is its `[[frame]]` table appended to
//! `acquisition.toml` in one `write`. The manifest therefore never lists a
//! frame that is not complete on disk, and every prefix of it is valid TOML
//! of the spec.

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use super::sinks::{FrameSink, SinkError};
use crate::acquire::acquisition::{AcquisitionError, ManifestFile, ACQUISITION_FORMAT, MANIFEST};
use crate::acquire::camera::Frame;
use crate::acquire::patterns::Pattern;
use crate::formats::image_io;
use crate::optics::station::Station;

/// Name of the station copy beside the manifest.
pub const STATION_FILE: &str = "station.toml";

/// Writes frames into an acquisition folder.
#[derive(Debug)]
pub struct Recorder {
    dir: PathBuf,
    manifest: File,
    patterns: Vec<Pattern>,
    next: usize,
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> AcquisitionError + '_ {
    move |source| AcquisitionError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn frame_file(index: usize) -> String {
    format!("frames/{index:06}.png")
}

/// One `[[frame]]` table; `{:?}` prints the shortest text that reads back
/// to the same `f64`, which is also valid TOML for finite values.
fn entry(p: &Pattern, index: usize) -> String {
    format!(
        "\n[[frame]]\ndirection_deg = {:?}\ntau = {:?}\nphase_rad = {:?}\nfile = \"{}\"\n",
        p.direction_deg,
        p.tau,
        p.phase_rad,
        frame_file(index)
    )
}

impl Recorder {
    /// Starts a new acquisition in `dir` for `patterns`: copies the station,
    /// writes a manifest with no frames yet.
    ///
    /// # Errors
    /// [`AcquisitionError::Exists`] when `dir` holds an acquisition and
    /// `overwrite` is false; I/O errors naming the path.
    pub fn create(
        dir: &Path,
        station: &Station,
        patterns: &[Pattern],
        overwrite: bool,
    ) -> Result<Self, AcquisitionError> {
        let manifest_path = dir.join(MANIFEST);
        if manifest_path.exists() && !overwrite {
            return Err(AcquisitionError::Exists {
                path: manifest_path,
            });
        }
        let frames = dir.join("frames");
        if frames.is_dir() {
            std::fs::remove_dir_all(&frames).map_err(io(&frames))?;
        }
        std::fs::create_dir_all(&frames).map_err(io(&frames))?;
        replace(&dir.join(STATION_FILE), &station.to_toml_string())?;
        let header = format!(
            "# written by mfd {} (mfd measure), frames appended as they are recorded\n\
             format = \"{ACQUISITION_FORMAT}\"\nstation = \"{STATION_FILE}\"\n",
            env!("CARGO_PKG_VERSION")
        );
        replace(&manifest_path, &header)?;
        Self::append_to(dir, patterns, 0)
    }

    /// Reopens the acquisition in `dir` to continue `patterns`: the frames
    /// its manifest lists must be the schedule's first ones and be on disk;
    /// recording continues after them.
    ///
    /// # Errors
    /// [`AcquisitionError::Invalid`] when the recorded frames are not a
    /// prefix of `patterns`; I/O and parse errors.
    pub fn resume(dir: &Path, patterns: &[Pattern]) -> Result<Self, AcquisitionError> {
        let path = dir.join(MANIFEST);
        let text = std::fs::read_to_string(&path).map_err(io(&path))?;
        let file: ManifestFile =
            toml::from_str(&text).map_err(|source| AcquisitionError::Parse {
                path: path.clone(),
                source,
            })?;
        let invalid = |field: String, problem: String| AcquisitionError::Invalid {
            path: path.clone(),
            field,
            problem,
        };
        if file.stack.is_some() || file.frames.len() > patterns.len() {
            return Err(invalid(
                "frame".into(),
                "not a recording of this schedule (a stack, or more frames than patterns)".into(),
            ));
        }
        for (i, (f, p)) in file.frames.iter().zip(patterns).enumerate() {
            let same = f.direction_deg == p.direction_deg
                && f.tau == p.tau
                && f.phase_rad.unwrap_or(0.0) == p.phase_rad
                && f.file.as_deref() == Some(frame_file(i).as_str());
            if !same || !dir.join(frame_file(i)).is_file() {
                return Err(invalid(
                    format!("frame[{i}]"),
                    format!(
                        "differs from pattern {i} of the schedule ({p:?}) or its file is missing"
                    ),
                ));
            }
        }
        Self::append_to(dir, patterns, file.frames.len())
    }

    fn append_to(dir: &Path, patterns: &[Pattern], next: usize) -> Result<Self, AcquisitionError> {
        let path = dir.join(MANIFEST);
        let manifest = OpenOptions::new()
            .append(true)
            .open(&path)
            .map_err(io(&path))?;
        Ok(Recorder {
            dir: dir.to_path_buf(),
            manifest,
            patterns: patterns.to_vec(),
            next,
        })
    }

    /// Frames recorded (listed in the manifest) so far.
    pub fn recorded(&self) -> usize {
        self.next
    }

    /// The acquisition folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Writes frame `index`, which must be the next one.
    ///
    /// # Errors
    /// [`AcquisitionError`] naming the frame and file.
    pub fn write(&mut self, index: usize, frame: &Frame) -> Result<(), AcquisitionError> {
        let name = frame_file(index);
        let bad = |problem: String| AcquisitionError::Frame {
            frame: index,
            path: PathBuf::from(frame_file(index)),
            problem,
        };
        if index != self.next || index >= self.patterns.len() {
            return Err(bad(format!(
                "recorded out of order (next is {} of {})",
                self.next,
                self.patterns.len()
            )));
        }
        let depth = if frame.bit_depth <= 8 { 8 } else { 16 };
        let part = self.dir.join(format!("{name}.part"));
        image_io::write_png(&part, frame.width, frame.height, depth, &frame.data).map_err(
            |source| AcquisitionError::Image {
                frame: index,
                source,
            },
        )?;
        let path = self.dir.join(&name);
        std::fs::rename(&part, &path).map_err(io(&path))?;
        let text = entry(&self.patterns[index], index);
        let manifest = self.dir.join(MANIFEST);
        self.manifest
            .write_all(text.as_bytes())
            .map_err(io(&manifest))?;
        self.next += 1;
        Ok(())
    }
}

/// Writes `text` to `path` atomically (temporary file and rename).
fn replace(path: &Path, text: &str) -> Result<(), AcquisitionError> {
    let tmp = path.with_extension("toml.tmp");
    std::fs::write(&tmp, text).map_err(io(&tmp))?;
    std::fs::rename(&tmp, path).map_err(io(path))
}

impl FrameSink for Recorder {
    fn name(&self) -> &'static str {
        "recorder"
    }

    fn accept(&mut self, index: usize, frame: &Frame) -> Result<(), SinkError> {
        Ok(self.write(index, frame)?)
    }

    fn finish(&mut self) -> Result<(), SinkError> {
        let path = self.dir.join(MANIFEST);
        self.manifest.sync_all().map_err(io(&path))?;
        Ok(())
    }
}

//! The recorder: the consumer that writes the spec's acquisition folder
//! (`mfd-acquisition/1`) as frames arrive, through the acquisition writer's
//! crash-safe append mode ([`AcquisitionWriter::append`]), so that a crash
//! at any moment leaves a readable partial acquisition and `--resume`
//! continues it.
//!
//! Layout: one PNG per frame (`frames/NNNNNN.png`, 8-bit for 8-bit cameras,
//! 16-bit otherwise, raw counts), no `stack`, and a copy of the station as
//! `station.toml` beside the manifest.

use std::path::Path;

use super::sinks::{FrameSink, SinkError};
use crate::acquire::acquisition::{AcquisitionError, AcquisitionWriter, FrameImage, FrameInfo};
use crate::acquire::camera::Frame;
use crate::acquire::patterns::Pattern;
use crate::optics::station::Station;

/// Name of the station copy beside the manifest.
pub const STATION_FILE: &str = "station.toml";

/// Writes frames into an acquisition folder.
#[derive(Debug)]
pub struct Recorder {
    writer: AcquisitionWriter,
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
        let schedule = FrameInfo::from_patterns(patterns);
        let station_copy = (STATION_FILE, station.to_toml_string());
        let writer = AcquisitionWriter::append(dir, station_copy, &schedule, overwrite)?;
        Ok(Recorder { writer })
    }

    /// Reopens the acquisition in `dir` to continue `patterns`: the frames
    /// its manifest lists must be the schedule's first ones and be on disk;
    /// recording continues after them.
    ///
    /// # Errors
    /// [`AcquisitionError::Invalid`] when the recorded frames are not a
    /// prefix of `patterns`; I/O and parse errors.
    pub fn resume(dir: &Path, patterns: &[Pattern]) -> Result<Self, AcquisitionError> {
        let schedule = FrameInfo::from_patterns(patterns);
        Ok(Recorder {
            writer: AcquisitionWriter::resume(dir, &schedule)?,
        })
    }

    /// Frames recorded (listed in the manifest) so far.
    pub fn recorded(&self) -> usize {
        self.writer.written()
    }

    /// The acquisition folder.
    pub fn dir(&self) -> &Path {
        self.writer.dir()
    }

    /// Writes frame `index`, which must be the next one.
    ///
    /// # Errors
    /// [`AcquisitionError`] naming the frame and file.
    pub fn write(&mut self, index: usize, frame: &Frame) -> Result<(), AcquisitionError> {
        let image = FrameImage {
            width: frame.width,
            height: frame.height,
            bit_depth: frame.bit_depth,
            data: &frame.data,
        };
        self.writer.write_frame(index, &image)
    }
}

impl FrameSink for Recorder {
    fn name(&self) -> &'static str {
        "recorder"
    }

    fn accept(&mut self, index: usize, frame: &Frame) -> Result<(), SinkError> {
        Ok(self.write(index, frame)?)
    }

    fn finish(&mut self) -> Result<(), SinkError> {
        Ok(self.writer.sync()?)
    }
}

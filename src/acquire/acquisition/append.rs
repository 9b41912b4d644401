//! The writer's crash-safe append mode: starting an acquisition that grows
//! frame by frame, and resuming one that stopped.

use std::fs::OpenOptions;
use std::path::Path;

use super::manifest::{self, ManifestFile, ACQUISITION_FORMAT};
use super::writer::{frame_file, io, prepare_dir, replace, AcquisitionWriter, Mode, Prepare};
use super::{AcquisitionError, FrameInfo, MANIFEST};
use crate::formats::image_io;

impl AcquisitionWriter {
    /// Append mode: starts a new acquisition in `dir` for the schedule
    /// `schedule` (capture order). `station` is the station file's name
    /// (relative to `dir`) and text: it is written (atomically) first, then
    /// a manifest that lists no frames yet. Frames are one PNG each;
    /// [`AcquisitionWriter::write_frame`] adds them.
    ///
    /// # Errors
    /// [`AcquisitionError::Exists`] when `dir` holds an acquisition and
    /// `overwrite` is false (nothing is written then); I/O errors naming the
    /// path.
    pub fn append(
        dir: &Path,
        station: (&str, String),
        schedule: &[FrameInfo],
        overwrite: bool,
    ) -> Result<Self, AcquisitionError> {
        let (station_file, station_text) = station;
        let how = Prepare {
            overwrite,
            always_clear_frames: true,
            png: true,
        };
        prepare_dir(dir, &how)?;
        replace(&dir.join(station_file), &station_text)?;
        let path = dir.join(MANIFEST);
        let head = ManifestFile {
            format: ACQUISITION_FORMAT.to_string(),
            station: station_file.to_string(),
            stack: None,
            frames: Vec::new(),
        };
        let note = format!(
            "written by mfd {}, frames appended as they are recorded",
            env!("CARGO_PKG_VERSION")
        );
        replace(&path, &manifest::head_text(&head, &note, &path)?)?;
        Self::open_append(dir, schedule, 0)
    }

    /// Append mode, continuing the acquisition in `dir`: the frames its
    /// manifest lists must be the first ones of `schedule` and be on disk;
    /// writing continues after them.
    ///
    /// # Errors
    /// [`AcquisitionError::Invalid`] when the recorded frames are not a
    /// prefix of `schedule`; I/O and parse errors.
    pub fn resume(dir: &Path, schedule: &[FrameInfo]) -> Result<Self, AcquisitionError> {
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
        if file.stack.is_some() || file.frames.len() > schedule.len() {
            return Err(invalid(
                "frame".into(),
                "not a recording of this schedule (a stack, or more frames than patterns)".into(),
            ));
        }
        for (i, (f, p)) in file.frames.iter().zip(schedule).enumerate() {
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
        let mut writer = Self::open_append(dir, schedule, file.frames.len())?;
        if !file.frames.is_empty() {
            // The frames still to come must match those on disk: frame 0's
            // header fixes the size and bit depth (the reader holds the
            // recorded ones to it).
            let first = dir.join(frame_file(0));
            let header = image_io::read_gray_header(&first)
                .map_err(|source| AcquisitionError::Image { frame: 0, source })?;
            writer.resolution = Some((header.width, header.height));
            writer.stored_bits = Some(header.bit_depth);
        }
        Ok(writer)
    }

    fn open_append(
        dir: &Path,
        schedule: &[FrameInfo],
        next: usize,
    ) -> Result<Self, AcquisitionError> {
        let path = dir.join(MANIFEST);
        let manifest = OpenOptions::new()
            .append(true)
            .open(&path)
            .map_err(io(&path))?;
        Ok(AcquisitionWriter {
            dir: dir.to_path_buf(),
            mode: Mode::Append { manifest },
            frames: schedule.to_vec(),
            resolution: None,
            stored_bits: None,
            next,
        })
    }
}

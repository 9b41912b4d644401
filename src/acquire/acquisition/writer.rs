//! The one writer of acquisition folders, in two modes.
//!
//! - **Whole acquisition** ([`AcquisitionWriter::create`], the simulator):
//!   the manifest lists every frame up front (written atomically), then the
//!   frames follow in capture order, into a `frames.npy` stack or one PNG
//!   per frame.
//! - **Crash-safe append** ([`AcquisitionWriter::append`] and
//!   [`AcquisitionWriter::resume`], the recorder): one PNG per frame and no
//!   `stack` (a stack's header fixes the frame count up front). Each frame
//!   is written to a temporary name and renamed; only then is its
//!   `[[frame]]` table appended to the manifest in one `write`. The manifest
//!   therefore never lists a frame that is not complete on disk, and every
//!   prefix of it is valid TOML of the spec.
//!
//! Both modes write the manifest's text the same way, from its serde types
//! (see `manifest`): a whole acquisition's manifest is the same text an
//! append of the same frames leaves behind.

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

use super::manifest::{self, FrameEntry, ManifestFile, ACQUISITION_FORMAT};
use super::{AcquisitionError, FrameInfo, MANIFEST};
use crate::formats::image_io;
use crate::formats::npy::{NpyStackWriter, StackDtype};

/// How frames are stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameLayout {
    /// One `frames.npy` stack `[frames, rows, columns]`.
    Stack {
        /// Element type.
        dtype: StackDtype,
    },
    /// One grayscale PNG per frame, `frames/NNNNNN.png`.
    Png {
        /// 8 or 16.
        bit_depth: u8,
    },
}

/// One frame as the writer takes it: row-major raw counts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameImage<'a> {
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Significant bits per sample. The append mode stores 8-bit PNGs for
    /// up to 8 bits, 16-bit ones otherwise; a whole acquisition stores what
    /// its [`FrameLayout`] says.
    pub bit_depth: u8,
    /// `width · height` counts.
    pub data: &'a [u16],
}

#[derive(Debug)]
pub(super) enum Mode {
    /// Whole acquisition into a stack.
    Stack(NpyStackWriter),
    /// Whole acquisition as PNG files of this bit depth.
    Png { bit_depth: u8 },
    /// Crash-safe append: PNG files, each frame's table appended to the
    /// manifest once its file is complete.
    Append { manifest: File },
}

/// An acquisition being written.
#[derive(Debug)]
pub struct AcquisitionWriter {
    pub(super) dir: PathBuf,
    pub(super) mode: Mode,
    /// Frames the manifest lists (whole) or the schedule (append).
    pub(super) frames: Vec<FrameInfo>,
    /// Frame size `(width, height)`: given for a whole acquisition, set by
    /// the first frame written when appending.
    pub(super) resolution: Option<(u32, u32)>,
    /// When appending: the bits per sample of the frames already on disk
    /// (8 or 16), set by the first one; a resumed recording must go on at
    /// that depth, or its frames would mix two scales.
    pub(super) stored_bits: Option<u8>,
    pub(super) next: usize,
}

pub(super) fn io(path: &Path) -> impl FnOnce(std::io::Error) -> AcquisitionError + '_ {
    move |source| AcquisitionError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// File name of frame `index`'s PNG, relative to the manifest.
pub(super) fn frame_file(index: usize) -> String {
    format!("frames/{index:06}.png")
}

/// The `[[frame]]` entry of `frame`; `png` when it is stored in its own file.
pub(super) fn entry(frame: &FrameInfo, png: bool) -> FrameEntry {
    FrameEntry {
        direction_deg: frame.direction_deg,
        tau: frame.tau,
        phase_rad: Some(frame.phase_rad),
        file: png.then(|| frame_file(frame.index)),
    }
}

/// Writes `text` to `path` atomically (temporary file and rename).
///
/// # Errors
/// [`AcquisitionError::Io`] naming the file.
pub(super) fn replace(path: &Path, text: &str) -> Result<(), AcquisitionError> {
    let mut name = path.as_os_str().to_owned();
    name.push(".tmp");
    let tmp = PathBuf::from(name);
    std::fs::write(&tmp, text).map_err(io(&tmp))?;
    std::fs::rename(&tmp, path).map_err(io(path))
}

/// How [`prepare_dir`] treats the folder.
pub(super) struct Prepare {
    /// Whether an existing acquisition may be replaced.
    pub overwrite: bool,
    /// Whether a `frames/` folder already there is removed even when no
    /// acquisition is replaced (the append mode always starts it afresh).
    pub always_clear_frames: bool,
    /// Whether the frames are PNG files (an empty `frames/` is made).
    pub png: bool,
}

/// Refuses to replace an acquisition unless `overwrite`; creates `dir`,
/// removes the frames of a replaced acquisition and makes `frames/`.
pub(super) fn prepare_dir(dir: &Path, how: &Prepare) -> Result<(), AcquisitionError> {
    let manifest_path = dir.join(MANIFEST);
    if manifest_path.exists() && !how.overwrite {
        return Err(AcquisitionError::Exists {
            path: manifest_path,
        });
    }
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let stale = dir.join("frames");
    if (how.overwrite || how.always_clear_frames) && stale.is_dir() {
        std::fs::remove_dir_all(&stale).map_err(io(&stale))?;
    }
    if how.png {
        std::fs::create_dir_all(&stale).map_err(io(&stale))?;
    }
    Ok(())
}

impl AcquisitionWriter {
    /// Whole-acquisition mode: creates `dir` and its manifest listing
    /// `frames`, the station file name relative to `dir`, and prepares the
    /// frame sink for `width × height` frames.
    ///
    /// # Errors
    /// [`AcquisitionError::Exists`] when `dir` already holds an acquisition
    /// and `overwrite` is false; I/O errors naming the path.
    pub fn create(
        dir: &Path,
        station_file: &str,
        layout: FrameLayout,
        frames: &[FrameInfo],
        width: u32,
        height: u32,
        overwrite: bool,
    ) -> Result<Self, AcquisitionError> {
        let png = matches!(layout, FrameLayout::Png { .. });
        let how = Prepare {
            overwrite,
            always_clear_frames: false,
            png,
        };
        prepare_dir(dir, &how)?;
        let manifest_path = dir.join(MANIFEST);
        let head = ManifestFile {
            format: ACQUISITION_FORMAT.to_string(),
            station: station_file.to_string(),
            stack: (!png).then(|| "frames.npy".to_string()),
            frames: Vec::new(),
        };
        let note = format!("written by mfd {}", env!("CARGO_PKG_VERSION"));
        let mut text = manifest::head_text(&head, &note, &manifest_path)?;
        for f in frames {
            text += &manifest::frame_text(&entry(f, png), &manifest_path)?;
        }
        replace(&manifest_path, &text)?;
        let mode = match layout {
            FrameLayout::Stack { dtype } => Mode::Stack(NpyStackWriter::create(
                &dir.join("frames.npy"),
                dtype,
                frames.len(),
                height as usize,
                width as usize,
            )?),
            FrameLayout::Png { bit_depth } => Mode::Png { bit_depth },
        };
        Ok(AcquisitionWriter {
            dir: dir.to_path_buf(),
            mode,
            frames: frames.to_vec(),
            resolution: Some((width, height)),
            stored_bits: None,
            next: 0,
        })
    }

    /// The acquisition folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Frames written so far (in append mode: listed in the manifest,
    /// resumed ones included).
    pub fn written(&self) -> usize {
        self.next
    }

    /// Writes frame `index`, which must be the next one in capture order
    /// (when appending, its table goes into the manifest once its file is
    /// complete).
    ///
    /// # Errors
    /// Out-of-order index, wrong size, or an I/O error, naming the frame.
    pub fn write_frame(
        &mut self,
        index: usize,
        frame: &FrameImage<'_>,
    ) -> Result<(), AcquisitionError> {
        self.check(index, frame)?;
        match &mut self.mode {
            Mode::Stack(w) => w.append(frame.data)?,
            Mode::Png { bit_depth } => write_png(&self.dir, index, *bit_depth, frame)?,
            Mode::Append { manifest } => {
                let depth = stored_depth(frame.bit_depth);
                write_png(&self.dir, index, depth, frame)?;
                let path = self.dir.join(MANIFEST);
                let text = manifest::frame_text(&entry(&self.frames[index], true), &path)?;
                manifest.write_all(text.as_bytes()).map_err(io(&path))?;
            }
        }
        self.resolution = Some((frame.width, frame.height));
        if let Mode::Append { .. } = self.mode {
            self.stored_bits = Some(stored_depth(frame.bit_depth));
        }
        self.next += 1;
        Ok(())
    }

    fn check(&self, index: usize, frame: &FrameImage<'_>) -> Result<(), AcquisitionError> {
        let bad = |problem: String| AcquisitionError::Frame {
            frame: index,
            path: PathBuf::from(frame_file(index)),
            problem,
        };
        if index != self.next || index >= self.frames.len() {
            return Err(bad(format!(
                "written out of order (next is {} of {})",
                self.next,
                self.frames.len()
            )));
        }
        let (w, h) = self.resolution.unwrap_or((frame.width, frame.height));
        if (frame.width, frame.height) != (w, h) {
            return Err(bad(format!(
                "{}x{} pixels, expected {w}x{h}",
                frame.width, frame.height
            )));
        }
        let depth = stored_depth(frame.bit_depth);
        if let Some(held) = self.stored_bits.filter(|&b| b != depth) {
            return Err(bad(format!(
                "{depth}-bit, but the frames recorded before it (from {}) are {held}-bit: \
                 a recording keeps one bit depth",
                frame_file(0)
            )));
        }
        let expected = w as usize * h as usize;
        if frame.data.len() != expected {
            return Err(bad(format!(
                "{} pixels, expected {expected}",
                frame.data.len()
            )));
        }
        Ok(())
    }

    /// Flushes what was written to the disk (the manifest when appending,
    /// the stack's buffer), keeping the writer open.
    ///
    /// # Errors
    /// An I/O error naming the file.
    pub fn sync(&mut self) -> Result<(), AcquisitionError> {
        match &mut self.mode {
            Mode::Stack(w) => w.flush()?,
            Mode::Png { .. } => {}
            Mode::Append { manifest } => {
                let path = self.dir.join(MANIFEST);
                manifest.sync_all().map_err(io(&path))?;
            }
        }
        Ok(())
    }

    /// Flushes and, for a whole acquisition, checks that every listed frame
    /// was written (an appended acquisition may stop anywhere).
    ///
    /// # Errors
    /// Missing frames or an I/O error.
    pub fn finish(mut self) -> Result<(), AcquisitionError> {
        if let Mode::Append { .. } = self.mode {
            return self.sync();
        }
        match self.mode {
            Mode::Stack(w) => w.finish()?,
            Mode::Png { .. } if self.next != self.frames.len() => {
                return Err(AcquisitionError::Frame {
                    frame: self.next,
                    path: PathBuf::from(frame_file(self.next)),
                    problem: format!(
                        "never written ({} of {} frames done)",
                        self.next,
                        self.frames.len()
                    ),
                })
            }
            Mode::Png { .. } | Mode::Append { .. } => {}
        }
        Ok(())
    }
}

/// The PNG depth the append mode stores `bit_depth` significant bits at.
pub(super) fn stored_depth(bit_depth: u8) -> u8 {
    if bit_depth <= 8 {
        8
    } else {
        16
    }
}

/// Writes frame `index` as `frames/NNNNNN.png` under a temporary name, then
/// renames it: the file is either absent or complete.
fn write_png(
    dir: &Path,
    index: usize,
    bit_depth: u8,
    frame: &FrameImage<'_>,
) -> Result<(), AcquisitionError> {
    let path = dir.join(frame_file(index));
    let part = dir.join(format!("{}.part", frame_file(index)));
    image_io::write_png(&part, frame.width, frame.height, bit_depth, frame.data).map_err(
        |source| AcquisitionError::Image {
            frame: index,
            source,
        },
    )?;
    std::fs::rename(&part, &path).map_err(io(&path))
}

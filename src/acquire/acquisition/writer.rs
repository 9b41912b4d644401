//! Writes acquisition folders: manifest first (atomically), then frames in
//! capture order as they come.

use std::path::{Path, PathBuf};

use super::manifest::{FrameEntry, ManifestFile, ACQUISITION_FORMAT};
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

#[derive(Debug)]
enum Sink {
    Stack(NpyStackWriter),
    Png { dir: PathBuf, bit_depth: u8 },
}

/// An acquisition being written.
#[derive(Debug)]
pub struct AcquisitionWriter {
    sink: Sink,
    width: u32,
    height: u32,
    frames: usize,
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

impl AcquisitionWriter {
    /// Creates `dir` and its manifest listing `frames`, the station file
    /// name relative to `dir`, and prepares the frame sink.
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
        let manifest_path = dir.join(MANIFEST);
        if manifest_path.exists() && !overwrite {
            return Err(AcquisitionError::Exists {
                path: manifest_path,
            });
        }
        std::fs::create_dir_all(dir).map_err(io(dir))?;
        let stale = dir.join("frames");
        if overwrite && stale.is_dir() {
            std::fs::remove_dir_all(&stale).map_err(io(&stale))?;
        }
        let stack = matches!(layout, FrameLayout::Stack { .. });
        let manifest = ManifestFile {
            format: ACQUISITION_FORMAT.to_string(),
            station: station_file.to_string(),
            stack: stack.then(|| "frames.npy".to_string()),
            frames: frames
                .iter()
                .map(|f| FrameEntry {
                    direction_deg: f.direction_deg,
                    tau: f.tau,
                    phase_rad: Some(f.phase_rad),
                    file: (!stack).then(|| frame_file(f.index)),
                })
                .collect(),
        };
        let text = format!(
            "# written by mfd {}\n{}",
            env!("CARGO_PKG_VERSION"),
            toml::to_string(&manifest).unwrap_or_default()
        );
        let tmp = dir.join(format!("{MANIFEST}.tmp"));
        std::fs::write(&tmp, text).map_err(io(&tmp))?;
        std::fs::rename(&tmp, &manifest_path).map_err(io(&manifest_path))?;
        let sink = match layout {
            FrameLayout::Stack { dtype } => Sink::Stack(NpyStackWriter::create(
                &dir.join("frames.npy"),
                dtype,
                frames.len(),
                height as usize,
                width as usize,
            )?),
            FrameLayout::Png { bit_depth } => {
                let fdir = dir.join("frames");
                std::fs::create_dir_all(&fdir).map_err(io(&fdir))?;
                Sink::Png {
                    dir: dir.to_path_buf(),
                    bit_depth,
                }
            }
        };
        Ok(AcquisitionWriter {
            sink,
            width,
            height,
            frames: frames.len(),
            next: 0,
        })
    }

    /// Writes frame `index`, which must be the next one in capture order.
    ///
    /// # Errors
    /// Out-of-order index, wrong size, or an I/O error, naming the frame.
    pub fn write_frame(&mut self, index: usize, frame: &[u16]) -> Result<(), AcquisitionError> {
        let expected = self.width as usize * self.height as usize;
        let bad = |problem: String| AcquisitionError::Frame {
            frame: index,
            path: PathBuf::from(frame_file(index)),
            problem,
        };
        if index != self.next || index >= self.frames {
            return Err(bad(format!(
                "written out of order (next is {} of {})",
                self.next, self.frames
            )));
        }
        if frame.len() != expected {
            return Err(bad(format!("{} pixels, expected {expected}", frame.len())));
        }
        match &mut self.sink {
            Sink::Stack(w) => w.append(frame)?,
            Sink::Png { dir, bit_depth } => {
                image_io::write_png(
                    &dir.join(frame_file(index)),
                    self.width,
                    self.height,
                    *bit_depth,
                    frame,
                )
                .map_err(|source| AcquisitionError::Image {
                    frame: index,
                    source,
                })?;
            }
        }
        self.next += 1;
        Ok(())
    }

    /// Flushes and checks that every listed frame was written.
    ///
    /// # Errors
    /// Missing frames or an I/O error.
    pub fn finish(self) -> Result<(), AcquisitionError> {
        match self.sink {
            Sink::Stack(w) => w.finish()?,
            Sink::Png { .. } if self.next != self.frames => {
                return Err(AcquisitionError::Frame {
                    frame: self.next,
                    path: PathBuf::from(frame_file(self.next)),
                    problem: format!(
                        "never written ({} of {} frames done)",
                        self.next, self.frames
                    ),
                })
            }
            Sink::Png { .. } => {}
        }
        Ok(())
    }
}

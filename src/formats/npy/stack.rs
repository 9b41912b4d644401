//! Frame stacks `[frames, rows, columns]`, written and read one frame at a time.

use std::fs::File;
use std::io::{BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use super::{checked_len, header_bytes, io_err, open_header, NpyError, StackDtype};

/// Writes a `[frames, rows, columns]` stack one frame at a time.
#[derive(Debug)]
pub struct NpyStackWriter {
    path: PathBuf,
    out: BufWriter<File>,
    dtype: StackDtype,
    frames: usize,
    pixels: usize,
    written: usize,
}

impl NpyStackWriter {
    /// Creates the file and writes the header for `frames` frames.
    ///
    /// # Errors
    /// [`NpyError::Io`] when the file cannot be created.
    pub fn create(
        path: &Path,
        dtype: StackDtype,
        frames: usize,
        rows: usize,
        cols: usize,
    ) -> Result<Self, NpyError> {
        let mut out = BufWriter::with_capacity(1 << 20, File::create(path).map_err(io_err(path))?);
        out.write_all(&header_bytes(dtype.descr(), &[frames, rows, cols]))
            .map_err(io_err(path))?;
        Ok(NpyStackWriter {
            path: path.to_path_buf(),
            out,
            dtype,
            frames,
            pixels: rows * cols,
            written: 0,
        })
    }

    /// Appends the next frame (values above 255 are an error for a u8 stack).
    ///
    /// # Errors
    /// Wrong frame size, too many frames, a u8 overflow, or an I/O failure.
    pub fn append(&mut self, frame: &[u16]) -> Result<(), NpyError> {
        let unexpected = |expected: String, found: String| NpyError::Unexpected {
            path: self.path.clone(),
            expected,
            found,
        };
        if frame.len() != self.pixels {
            return Err(unexpected(
                format!("{} pixels per frame", self.pixels),
                format!("{}", frame.len()),
            ));
        }
        if self.written == self.frames {
            return Err(unexpected(
                format!("{} frames", self.frames),
                "one more".into(),
            ));
        }
        let bytes: Vec<u8> = match self.dtype {
            StackDtype::U16 => frame.iter().flat_map(|v| v.to_le_bytes()).collect(),
            StackDtype::U8 => {
                if let Some(v) = frame.iter().find(|&&v| v > 255) {
                    return Err(unexpected("8-bit values".into(), format!("{v}")));
                }
                frame.iter().map(|&v| v as u8).collect()
            }
        };
        self.out.write_all(&bytes).map_err(io_err(&self.path))?;
        self.written += 1;
        Ok(())
    }

    /// Flushes the data written so far to the OS (a crash keeps it readable).
    ///
    /// # Errors
    /// [`NpyError::Io`].
    pub fn flush(&mut self) -> Result<(), NpyError> {
        self.out.flush().map_err(io_err(&self.path))
    }

    /// Flushes and checks that every announced frame was written.
    ///
    /// # Errors
    /// [`NpyError::Truncated`] when frames are missing; [`NpyError::Io`].
    pub fn finish(mut self) -> Result<(), NpyError> {
        self.flush()?;
        if self.written != self.frames {
            return Err(NpyError::Truncated {
                path: self.path,
                complete: self.written,
                expected: self.frames,
            });
        }
        Ok(())
    }
}

/// Reads frames of a `[frames, rows, columns]` uint8/uint16 stack by seeking.
#[derive(Debug)]
pub struct NpyStackReader {
    path: PathBuf,
    file: File,
    dtype: StackDtype,
    frames: usize,
    rows: usize,
    cols: usize,
    data_offset: u64,
    complete: usize,
}

impl NpyStackReader {
    /// Opens a stack and checks its dtype and shape.
    ///
    /// # Errors
    /// [`NpyError`] for a non-3-D array or another dtype.
    pub fn open(path: &Path) -> Result<Self, NpyError> {
        let (_, h) = open_header(path)?;
        let dtype = match h.descr.as_str() {
            "|u1" | "<u1" | "u1" => StackDtype::U8,
            "<u2" => StackDtype::U16,
            other => {
                return Err(NpyError::Unexpected {
                    path: path.to_path_buf(),
                    expected: "a uint8 or little-endian uint16 stack".into(),
                    found: format!("dtype {other}"),
                })
            }
        };
        let [frames, rows, cols] = h.shape[..] else {
            return Err(NpyError::Unexpected {
                path: path.to_path_buf(),
                expected: "shape [frames, rows, columns]".into(),
                found: format!("shape {:?}", h.shape),
            });
        };
        let file = File::open(path).map_err(io_err(path))?;
        let len = file.metadata().map_err(io_err(path))?.len();
        checked_len(path, &[frames, rows, cols, dtype.size()])?;
        // A stack of 0 frames passes the line above with any frame size.
        let frame_len = checked_len(path, &[rows, cols, dtype.size()])?;
        if rows == 0 || cols == 0 {
            return Err(NpyError::Unexpected {
                path: path.to_path_buf(),
                expected: "frames of at least one row and one column".into(),
                found: format!("shape {:?}", h.shape),
            });
        }
        let frame_bytes = frame_len as u64;
        let complete = len
            .saturating_sub(h.data_offset)
            .checked_div(frame_bytes)
            .map_or(frames, |c| c.min(frames as u64) as usize);
        Ok(NpyStackReader {
            path: path.to_path_buf(),
            file,
            dtype,
            frames,
            rows,
            cols,
            data_offset: h.data_offset,
            complete,
        })
    }

    /// Frames announced by the header.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Frames present in full in the file (fewer than [`Self::frames`] when truncated).
    pub fn complete_frames(&self) -> usize {
        self.complete
    }

    /// `(rows, columns)` of a frame.
    pub fn frame_shape(&self) -> (usize, usize) {
        (self.rows, self.cols)
    }

    /// Element type.
    pub fn dtype(&self) -> StackDtype {
        self.dtype
    }

    /// Reads frame `index` into `out` (u8 widened to u16).
    ///
    /// # Errors
    /// [`NpyError::NoSuchFrame`], [`NpyError::Truncated`] naming the frame count, or I/O.
    pub fn read_frame(&mut self, index: usize, out: &mut Vec<u16>) -> Result<(), NpyError> {
        if index >= self.frames {
            return Err(NpyError::NoSuchFrame {
                path: self.path.clone(),
                frame: index,
                frames: self.frames,
            });
        }
        if index >= self.complete {
            return Err(NpyError::Truncated {
                path: self.path.clone(),
                complete: self.complete,
                expected: self.frames,
            });
        }
        let n = self.rows * self.cols;
        let size = self.dtype.size();
        let mut bytes = vec![0u8; n * size];
        self.file
            .seek(SeekFrom::Start(
                self.data_offset + (index * n * size) as u64,
            ))
            .map_err(io_err(&self.path))?;
        self.file
            .read_exact(&mut bytes)
            .map_err(io_err(&self.path))?;
        out.clear();
        match self.dtype {
            StackDtype::U8 => out.extend(bytes.iter().map(|&b| u16::from(b))),
            StackDtype::U16 => out.extend(
                bytes
                    .chunks_exact(2)
                    .map(|c| u16::from_le_bytes([c[0], c[1]])),
            ),
        }
        Ok(())
    }
}

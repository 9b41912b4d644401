//! What keeps frames from mixing silently into one result: every frame file
//! has the first frame's size and bit depth, and no file is named twice.
//! An 8-bit frame among 16-bit ones reads as a frame 256 times darker, and
//! a file named twice counts one capture as two; both moved results well
//! past their stated error without any other sign (issue 37).

use std::collections::HashMap;
use std::path::{Component, Path, PathBuf};
use std::sync::OnceLock;

use super::AcquisitionError;
use crate::formats::image_io::{self, GrayHeader};

/// Checks frame `index`'s header against frame 0's, which `first` caches
/// (read from frame 0's file when another frame is read first).
///
/// # Errors
/// [`AcquisitionError::Frame`] naming this frame, its file, frame 0's file
/// and both sizes and bit depths; [`AcquisitionError::Image`] when frame 0's
/// header cannot be read.
pub(super) fn check_like_first(
    first: &OnceLock<GrayHeader>,
    files: &[PathBuf],
    index: usize,
    header: GrayHeader,
) -> Result<(), AcquisitionError> {
    let reference = match (index, first.get()) {
        (0, _) => *first.get_or_init(|| header),
        (_, Some(h)) => *h,
        (_, None) => {
            let h = image_io::read_gray_header(&files[0])
                .map_err(|source| AcquisitionError::Image { frame: 0, source })?;
            *first.get_or_init(|| h)
        }
    };
    if header == reference {
        return Ok(());
    }
    Err(AcquisitionError::Frame {
        frame: index,
        path: files[index].clone(),
        problem: format!(
            "{header}, but frame 0 ({}) is {reference}: every frame of an acquisition has \
             the same size and bit depth",
            files[0].display()
        ),
    })
}

/// The path a file is known by, to tell two names of one file: the
/// canonical path where the file exists (links and `..` resolved),
/// otherwise the path with `.` and `name/..` removed.
pub fn file_identity(path: &Path) -> PathBuf {
    if let Ok(canonical) = path.canonicalize() {
        return canonical;
    }
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir
                if matches!(out.components().next_back(), Some(Component::Normal(_))) =>
            {
                out.pop();
            }
            other => out.push(other),
        }
    }
    out
}

/// Refuses two `[[frame]]` tables that name one file. `files[i]` is frame
/// `i`'s path (the manifest's folder joined to its `file`), `names[i]` the
/// name as written.
///
/// # Errors
/// [`AcquisitionError::Invalid`] naming both tables and the file.
pub(super) fn check_distinct(
    manifest: &Path,
    files: &[PathBuf],
    names: &[&str],
) -> Result<(), AcquisitionError> {
    let mut seen: HashMap<PathBuf, usize> = HashMap::with_capacity(files.len());
    for (i, path) in files.iter().enumerate() {
        if let Some(j) = seen.insert(file_identity(path), i) {
            return Err(AcquisitionError::Invalid {
                path: manifest.to_path_buf(),
                field: format!("frame[{i}].file"),
                problem: format!(
                    "\"{}\" is the file of frame[{j}] (\"{}\") too: each frame is its own \
                     capture, so a file may be named once (repeat the pattern with a new \
                     file to capture it twice)",
                    names[i], names[j]
                ),
            });
        }
    }
    Ok(())
}

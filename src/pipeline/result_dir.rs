//! Result folders that never mix runs. A reconstruction is written into a
//! fresh folder beside the target (`.NAME.partial-PID`) and renamed into
//! place only when it is complete, so a later reader finds the previous
//! complete result or the new one, never a mix; a run that fails keeps what
//! it made in `NAME.failed` with the error, and leaves `NAME` as it was.
//! Every result names the inputs it was made from (`inputs.json`, and the
//! same in `summary.json`), with SHA-256 digests of their bytes.
//!
//! A folder that is not an mfd result (it holds none of [`RESULT_MARKERS`])
//! is never replaced: the user may have pointed `--out` at the wrong place.

use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

use super::PipelineError;
pub use crate::report::records::{InputFile, Inputs};

/// The file every result folder holds: the inputs it was made from.
pub const INPUTS_FILE: &str = "inputs.json";

/// Files of which one marks a folder as an mfd result (this version's
/// `inputs.json`, or an earlier version's maps or summary).
pub const RESULT_MARKERS: [&str; 4] = [
    INPUTS_FILE,
    "screen_coords.npy",
    "summary.json",
    "surfaces.json",
];

impl InputFile {
    /// `path` with the digest of its bytes.
    ///
    /// # Errors
    /// [`PipelineError::Io`] when the file cannot be read.
    pub fn of(path: &Path) -> Result<InputFile, PipelineError> {
        Ok(InputFile {
            path: path.display().to_string(),
            sha256: sha256_file(path)?,
        })
    }
}

/// SHA-256 of a file's bytes, lower-case hex, read in blocks.
///
/// # Errors
/// [`PipelineError::Io`] naming the file.
pub fn sha256_file(path: &Path) -> Result<String, PipelineError> {
    use std::io::Read;
    let io = |source| PipelineError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut file = std::fs::File::open(path).map_err(io)?;
    let mut hasher = Sha256::new();
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = file.read(&mut buf).map_err(io)?;
        if n == 0 {
            break;
        }
        hasher.update(&buf[..n]);
    }
    Ok(hasher
        .finalize()
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect())
}

/// A result being written: the staging folder beside the target.
#[derive(Debug)]
pub struct Staged {
    target: PathBuf,
    staging: PathBuf,
}

/// Why a result folder could not be prepared or put in place.
fn io(path: &Path) -> impl FnOnce(std::io::Error) -> PipelineError + '_ {
    move |source| PipelineError::Io {
        path: path.to_path_buf(),
        source,
    }
}

impl Staged {
    /// Prepares a fresh staging folder for a result that will replace
    /// `target` (which need not exist). Left-over staging folders of
    /// earlier, killed runs are removed.
    ///
    /// # Errors
    /// [`PipelineError::Output`] when `target` is a file, or a non-empty
    /// folder that is not an mfd result; [`PipelineError::Io`] when the
    /// staging folder cannot be made.
    pub fn begin(target: &Path) -> Result<Staged, PipelineError> {
        let name = target
            .file_name()
            .ok_or_else(|| PipelineError::Output {
                path: target.to_path_buf(),
                problem: "not a folder name".into(),
            })?
            .to_string_lossy()
            .into_owned();
        if target.exists() {
            if !target.is_dir() {
                return Err(PipelineError::Output {
                    path: target.to_path_buf(),
                    problem: "is a file, not a result folder".into(),
                });
            }
            let empty = std::fs::read_dir(target)
                .map_err(io(target))?
                .next()
                .is_none();
            let ours = RESULT_MARKERS.iter().any(|m| target.join(m).exists());
            if !empty && !ours {
                return Err(PipelineError::Output {
                    path: target.to_path_buf(),
                    problem: format!(
                        "holds files but is not an mfd result folder (none of {}); \
                         a result replaces its folder whole, so give a new or empty --out",
                        RESULT_MARKERS.join(", ")
                    ),
                });
            }
        }
        let parent = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        std::fs::create_dir_all(&parent).map_err(io(&parent))?;
        let prefix = format!(".{name}.partial-");
        if let Ok(entries) = std::fs::read_dir(&parent) {
            for e in entries.flatten() {
                if e.file_name().to_string_lossy().starts_with(&prefix) {
                    let _ = std::fs::remove_dir_all(e.path());
                }
            }
        }
        let staging = parent.join(format!("{prefix}{}", std::process::id()));
        std::fs::create_dir(&staging).map_err(io(&staging))?;
        Ok(Staged {
            target: target.to_path_buf(),
            staging,
        })
    }

    /// The folder to write the result into.
    pub fn path(&self) -> &Path {
        &self.staging
    }

    /// Puts the complete result in place of the target: the old result is
    /// moved aside, the new one renamed in, the old one removed.
    ///
    /// # Errors
    /// [`PipelineError::Io`] when a rename fails (the old result is then
    /// put back where it can be).
    pub fn commit(self) -> Result<PathBuf, PipelineError> {
        let aside = self.sibling("old");
        let had_old = self.target.exists();
        if had_old {
            let _ = std::fs::remove_dir_all(&aside);
            std::fs::rename(&self.target, &aside).map_err(io(&self.target))?;
        }
        if let Err(e) = std::fs::rename(&self.staging, &self.target) {
            if had_old {
                let _ = std::fs::rename(&aside, &self.target);
            }
            return Err(io(&self.target)(e));
        }
        if had_old {
            let _ = std::fs::remove_dir_all(&aside);
        }
        // A failed run's leftovers no longer describe the target.
        let _ = std::fs::remove_dir_all(failed_path(&self.target));
        Ok(self.target)
    }

    /// Keeps what a failed run made in `TARGET.failed` (replacing an
    /// earlier one), with `error.txt` saying why, and leaves the target
    /// untouched. Returns where it was kept.
    ///
    /// # Errors
    /// [`PipelineError::Io`] when the folder cannot be renamed.
    pub fn fail(self, error: &str) -> Result<PathBuf, PipelineError> {
        let kept = failed_path(&self.target);
        let _ = std::fs::write(self.staging.join("error.txt"), format!("{error}\n"));
        let _ = std::fs::remove_dir_all(&kept);
        std::fs::rename(&self.staging, &kept).map_err(io(&kept))?;
        Ok(kept)
    }

    fn sibling(&self, what: &str) -> PathBuf {
        let name = self
            .target
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        self.staging
            .with_file_name(format!(".{name}.{what}-{}", std::process::id()))
    }
}

/// Where a failed run's partial result is kept: `TARGET.failed`.
pub fn failed_path(target: &Path) -> PathBuf {
    let mut name = target.file_name().unwrap_or_default().to_os_string();
    name.push(".failed");
    target.with_file_name(name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_committed_result_replaces_the_old_one_whole() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("R");
        std::fs::create_dir(&target).unwrap();
        std::fs::write(target.join("summary.json"), "old").unwrap();
        std::fs::write(target.join("front.png"), "old").unwrap();
        let staged = Staged::begin(&target).unwrap();
        std::fs::write(staged.path().join("summary.json"), "new").unwrap();
        staged.commit().unwrap();
        assert_eq!(
            std::fs::read_to_string(target.join("summary.json")).unwrap(),
            "new"
        );
        assert!(
            !target.join("front.png").exists(),
            "nothing of the old run is left"
        );
        let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().flatten().collect();
        assert_eq!(left.len(), 1, "no staging or old folder is left beside it");
    }

    #[test]
    fn a_failed_run_leaves_the_old_result_and_keeps_its_own_aside() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("R");
        std::fs::create_dir(&target).unwrap();
        std::fs::write(target.join("summary.json"), "old").unwrap();
        let staged = Staged::begin(&target).unwrap();
        std::fs::write(staged.path().join("screen_coords.npy"), "new").unwrap();
        let kept = staged.fail("surface stage: nothing").unwrap();
        assert_eq!(
            std::fs::read_to_string(target.join("summary.json")).unwrap(),
            "old"
        );
        assert!(!target.join("screen_coords.npy").exists());
        assert!(kept.join("screen_coords.npy").exists());
        assert!(std::fs::read_to_string(kept.join("error.txt"))
            .unwrap()
            .contains("nothing"));
    }

    #[test]
    fn a_folder_that_is_not_a_result_is_never_replaced() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("thesis.tex"), "precious").unwrap();
        let err = Staged::begin(dir.path()).unwrap_err().to_string();
        assert!(err.contains("not an mfd result folder"), "{err}");
        assert!(dir.path().join("thesis.tex").exists());
        // An empty folder and a missing one are fine.
        let empty = dir.path().join("empty");
        std::fs::create_dir(&empty).unwrap();
        Staged::begin(&empty).unwrap().commit().unwrap();
        Staged::begin(&dir.path().join("new/deep"))
            .unwrap()
            .commit()
            .unwrap();
        assert!(dir.path().join("new/deep").is_dir());
    }

    #[test]
    fn digests_are_those_of_the_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x");
        std::fs::write(&p, "abc").unwrap();
        // FIPS 180-2's test vector for "abc".
        assert_eq!(
            sha256_file(&p).unwrap(),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }
}

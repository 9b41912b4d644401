//! The on-disk form of `acquisition.toml` (`mfd-acquisition/1`): its serde
//! types, and the text the writer puts on disk, made from them by serde
//! only (the head, then one `[[frame]]` table per frame).

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::AcquisitionError;

/// The format tag every acquisition manifest carries.
pub const ACQUISITION_FORMAT: &str = "mfd-acquisition/1";

/// Top level of `acquisition.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ManifestFile {
    /// Must be [`ACQUISITION_FORMAT`].
    pub format: String,
    /// Station file, relative to the manifest.
    pub station: String,
    /// NumPy stack `[frames, rows, columns]` of all frames, relative to the manifest.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stack: Option<String>,
    /// One entry per captured frame, in capture order.
    #[serde(rename = "frame", default, skip_serializing_if = "Vec::is_empty")]
    pub frames: Vec<FrameEntry>,
}

/// One `[[frame]]` table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrameEntry {
    /// Fringe direction, degrees.
    pub direction_deg: f64,
    /// Fringe periods across the screen.
    pub tau: f64,
    /// Phase offset, radians (default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub phase_rad: Option<f64>,
    /// Image file of this frame, relative to the manifest (when there is no stack).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub file: Option<String>,
}

/// One `[[frame]]` table on its own, for appending to a manifest.
#[derive(Serialize)]
struct FrameTable<'a> {
    frame: &'a [FrameEntry],
}

fn serialize_error(path: &Path) -> impl FnOnce(toml::ser::Error) -> AcquisitionError + '_ {
    move |source| AcquisitionError::Serialize {
        path: path.to_path_buf(),
        source,
    }
}

/// The manifest's head: a `# note` comment line, then `format`, `station`
/// and `stack` (the frames of `head`, if any, are left out).
///
/// # Errors
/// [`AcquisitionError::Serialize`] naming `path`, the manifest.
pub(super) fn head_text(
    head: &ManifestFile,
    note: &str,
    path: &Path,
) -> Result<String, AcquisitionError> {
    let head = ManifestFile {
        frames: Vec::new(),
        ..head.clone()
    };
    let body = toml::to_string(&head).map_err(serialize_error(path))?;
    Ok(format!("# {note}\n{body}"))
}

/// One frame's `[[frame]]` table, preceded by a blank line: appended to a
/// manifest's text it keeps it valid TOML of the spec. Values are written
/// by serde (`f64` in the shortest form that reads back to the same bits).
///
/// # Errors
/// [`AcquisitionError::Serialize`] naming `path`, the manifest.
pub(super) fn frame_text(entry: &FrameEntry, path: &Path) -> Result<String, AcquisitionError> {
    let table = toml::to_string(&FrameTable {
        frame: std::slice::from_ref(entry),
    })
    .map_err(serialize_error(path))?;
    Ok(format!("\n{table}"))
}

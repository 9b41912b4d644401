//! The on-disk form of `acquisition.toml` (`mfd-acquisition/1`).

use serde::{Deserialize, Serialize};

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
    #[serde(rename = "frame", default)]
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

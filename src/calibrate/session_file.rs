//! The on-disk form of a calibration session's `session.toml`
//! (`mfd-calibration/1`, spec `calibration.md`), exactly as the spec writes
//! it. Only this module knows the TOML field names; loading and validating a
//! session (errors naming the file and entry) build on these types.

use serde::{Deserialize, Serialize};

/// The format tag every session file carries.
pub const SESSION_FORMAT: &str = "mfd-calibration/1";

/// Top level of `session.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SessionFile {
    /// Must be [`SESSION_FORMAT`].
    pub format: String,
    /// `mfd-station/1` or `/2` of what is known before calibrating, relative
    /// to `session.toml`.
    pub nominal_station: String,
    /// 1 σ of one stage reading, each axis, µm.
    pub stage_std_um: f64,
    /// The element: where it stands on the stage, its measured thickness and index.
    pub element: SessionElement,
    /// The PSM focused on the reference flat's surface; at least 3, not on one line.
    #[serde(default)]
    pub flat_point: Vec<StagePoint>,
    /// The PSM focused on the element's front; none, or at least 3.
    #[serde(default)]
    pub element_point: Vec<StagePoint>,
    /// A point target at the PSM's focus seen by the camera; at least 6, not coplanar.
    #[serde(default)]
    pub target_point: Vec<TargetPoint>,
    /// The PSM focused on a marked screen pixel (optional).
    #[serde(default)]
    pub screen_point: Vec<ScreenPoint>,
    /// The reference flat's acquisition.
    pub reference_flat: ReferenceFlat,
}

/// `[element]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SessionElement {
    /// Stage x, y of the element's centre, mm (defines the world origin).
    #[serde(deserialize_with = "crate::conventions::exact::array")]
    pub center_stage_mm: [f64; 2],
    /// Measured thickness, mm.
    pub thickness_mm: f64,
    /// Its 1 σ, mm.
    pub thickness_std_mm: f64,
    /// Measured refractive index.
    pub refractive_index: f64,
    /// Its 1 σ.
    pub refractive_index_std: f64,
}

/// `[[flat_point]]` or `[[element_point]]`: one stage reading.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StagePoint {
    /// Stage x, y, z of the PSM's focus, mm.
    #[serde(deserialize_with = "crate::conventions::exact::array")]
    pub stage_mm: [f64; 3],
}

/// `[[target_point]]`: a target at the PSM's focus and where the camera sees it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TargetPoint {
    /// Stage x, y, z of the target, mm.
    #[serde(deserialize_with = "crate::conventions::exact::array")]
    pub stage_mm: [f64; 3],
    /// A camera frame of the target, relative to `session.toml` (one of
    /// `image` and `image_px`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub image: Option<String>,
    /// The centroid itself, pixel-centre convention (one of `image` and `image_px`).
    #[serde(
        default,
        deserialize_with = "crate::conventions::exact::option_array",
        skip_serializing_if = "Option::is_none"
    )]
    pub image_px: Option<[f64; 2]>,
}

/// `[[screen_point]]`: the PSM focused on a marked screen pixel.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScreenPoint {
    /// Stage x, y, z, mm.
    #[serde(deserialize_with = "crate::conventions::exact::array")]
    pub stage_mm: [f64; 3],
    /// `(u, v)` of the mark, spec convention.
    #[serde(deserialize_with = "crate::conventions::exact::array")]
    pub screen_px: [f64; 2],
}

/// `[reference_flat]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReferenceFlat {
    /// An acquisition folder's `acquisition.toml`, relative to `session.toml`.
    pub acquisition: String,
    /// Its certified flatness, nm PV (reported, not modelled).
    pub flat_pv_nm: f64,
}

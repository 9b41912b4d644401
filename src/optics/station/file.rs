//! The on-disk form of `station.toml` (`mfd-station/1` and `/2`), exactly
//! as the interchange spec writes it. Only this module knows the TOML field names;
//! [`super::Station`] is the validated, typed model built from it.

use serde::{Deserialize, Serialize};

/// The format tag of a version-1 station file.
pub const STATION_FORMAT: &str = "mfd-station/1";
/// The format tag of a version-2 station file (distortion, cover glass, pose).
pub const STATION_FORMAT_V2: &str = "mfd-station/2";
/// The format tag of a station file using the proposals
/// `docs/proposals/outline.md` (the element's outline) and
/// `docs/proposals/aspect.md` (the camera's aspect ratio); not yet part of
/// the interchange spec, written only when one of them is used.
pub const STATION_FORMAT_V3: &str = "mfd-station/3";
/// The one distortion model version 2 names.
pub const BROWN_CONRADY: &str = "brown-conrady";

/// Top level of `station.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StationFile {
    /// [`STATION_FORMAT`] or [`STATION_FORMAT_V2`].
    pub format: String,
    /// The pinhole camera.
    pub camera: CameraFile,
    /// The fringe screen.
    pub screen: ScreenFile,
    /// The element under test.
    pub element: ElementFile,
}

/// `[camera]`: an ideal pinhole camera.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraFile {
    /// Projection centre C in the world frame, mm.
    #[serde(deserialize_with = "crate::conventions::exact::array")]
    pub position_mm: [f64; 3],
    /// Camera-to-world rotation, row-major; columns are the camera's x (column
    /// i), y (row j) and optical axes in world coordinates.
    #[serde(deserialize_with = "crate::conventions::exact::matrix3")]
    pub rotation: [[f64; 3]; 3],
    /// Focal length, mm.
    pub focal_length_mm: f64,
    /// Pixel pitch, µm.
    pub pixel_pitch_um: f64,
    /// `[width, height]` in pixels.
    #[serde(deserialize_with = "crate::conventions::exact::array")]
    pub resolution: [u32; 2],
    /// Principal point `[cx, cy]` in pixels; default `[width/2, height/2]`.
    #[serde(
        default,
        deserialize_with = "crate::conventions::exact::option_array",
        skip_serializing_if = "Option::is_none"
    )]
    pub principal_point_px: Option<[f64; 2]>,
    /// `fy / fx` (proposal `mfd-station/3`, `docs/proposals/aspect.md`);
    /// absent: square pixels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub aspect_ratio: Option<f64>,
    /// `[camera.distortion]` (version 2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distortion: Option<DistortionFile>,
}

/// `[camera.distortion]`: the lens in OpenCV's Brown–Conrady model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DistortionFile {
    /// Must be [`BROWN_CONRADY`].
    pub model: String,
    /// Radial k1, k2, k3; absent: zero.
    #[serde(
        default,
        deserialize_with = "crate::conventions::exact::option_array",
        skip_serializing_if = "Option::is_none"
    )]
    pub k: Option<[f64; 3]>,
    /// Tangential p1, p2; absent: zero.
    #[serde(
        default,
        deserialize_with = "crate::conventions::exact::option_array",
        skip_serializing_if = "Option::is_none"
    )]
    pub p: Option<[f64; 2]>,
}

/// `[screen.cover_glass]`: the slab in front of the pixels.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CoverGlassFile {
    /// Thickness, mm.
    pub thickness_mm: f64,
    /// Refractive index.
    pub refractive_index: f64,
}

/// `[screen]`: the display that shows the fringes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScreenFile {
    /// `[width, height]` in screen pixels.
    #[serde(deserialize_with = "crate::conventions::exact::array")]
    pub resolution: [u32; 2],
    /// Screen pixel pitch, mm.
    pub pixel_pitch_mm: f64,
    /// World position of `(u, v) = (0, 0)`, mm.
    #[serde(deserialize_with = "crate::conventions::exact::array")]
    pub origin_mm: [f64; 3],
    /// Unit vector of increasing u, world frame.
    #[serde(deserialize_with = "crate::conventions::exact::array")]
    pub u_axis: [f64; 3],
    /// Unit vector of increasing v, world frame.
    #[serde(deserialize_with = "crate::conventions::exact::array")]
    pub v_axis: [f64; 3],
    /// `[screen.cover_glass]` (version 2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cover_glass: Option<CoverGlassFile>,
}

/// `[element]`: the transparent plate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ElementFile {
    /// Refractive index of the plate (the surrounding air is 1).
    pub refractive_index: f64,
    /// Nominal thickness, mm.
    pub thickness_mm: f64,
    /// Radius of the region whose surfaces are reported, mm.
    pub aperture_radius_mm: f64,
    /// Centre of that region `[x, y]`, mm; default `[0, 0]`.
    #[serde(
        default,
        deserialize_with = "crate::conventions::exact::option_array",
        skip_serializing_if = "Option::is_none"
    )]
    pub aperture_center_mm: Option<[f64; 2]>,
    /// Where the element's frame sits, world frame, mm (version 2).
    #[serde(
        default,
        deserialize_with = "crate::conventions::exact::option_array",
        skip_serializing_if = "Option::is_none"
    )]
    pub offset_mm: Option<[f64; 3]>,
    /// Rotation about world x, then world y, degrees (version 2).
    #[serde(
        default,
        deserialize_with = "crate::conventions::exact::option_array",
        skip_serializing_if = "Option::is_none"
    )]
    pub tilt_deg: Option<[f64; 2]>,
    /// The nominal wedge between the faces, arcmin (version 2; default 0, at most 120).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wedge_arcmin: Option<f64>,
    /// The direction in the element's frame along which the plate thins,
    /// degrees (version 2; default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wedge_azimuth_deg: Option<f64>,
    /// `[element.outline]` (version 3, a proposal): the reported region
    /// when it is not the aperture disk.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub outline: Option<OutlineFile>,
}

/// `[element.outline]` (proposal `mfd-station/3`): a rectangle or a polygon.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutlineFile {
    /// `"rectangle"` or `"polygon"`.
    pub shape: String,
    /// Rectangle: side lengths along the element's x and y before the
    /// rotation, mm.
    #[serde(
        default,
        deserialize_with = "crate::conventions::exact::option_array",
        skip_serializing_if = "Option::is_none"
    )]
    pub sides_mm: Option<[f64; 2]>,
    /// Rectangle: rotation about the aperture centre, degrees from +x
    /// towards +y; default 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotation_deg: Option<f64>,
    /// Polygon: the vertices `[x, y]` in the element's frame, mm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vertices_mm: Option<Vec<[f64; 2]>>,
}

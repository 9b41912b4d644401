//! The on-disk form of `station.toml` (`mfd-station/1`), exactly as the
//! interchange spec writes it. Only this module knows the TOML field names;
//! [`super::Station`] is the validated, typed model built from it.

use serde::{Deserialize, Serialize};

/// The format tag every station file carries.
pub const STATION_FORMAT: &str = "mfd-station/1";

/// Top level of `station.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StationFile {
    /// Must be [`STATION_FORMAT`].
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
    pub position_mm: [f64; 3],
    /// Camera-to-world rotation, row-major; columns are the camera's x (column
    /// i), y (row j) and optical axes in world coordinates.
    pub rotation: [[f64; 3]; 3],
    /// Focal length, mm.
    pub focal_length_mm: f64,
    /// Pixel pitch, µm.
    pub pixel_pitch_um: f64,
    /// `[width, height]` in pixels.
    pub resolution: [u32; 2],
    /// Principal point `[cx, cy]` in pixels; default `[width/2, height/2]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub principal_point_px: Option<[f64; 2]>,
}

/// `[screen]`: the display that shows the fringes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScreenFile {
    /// `[width, height]` in screen pixels.
    pub resolution: [u32; 2],
    /// Screen pixel pitch, mm.
    pub pixel_pitch_mm: f64,
    /// World position of `(u, v) = (0, 0)`, mm.
    pub origin_mm: [f64; 3],
    /// Unit vector of increasing u, world frame.
    pub u_axis: [f64; 3],
    /// Unit vector of increasing v, world frame.
    pub v_axis: [f64; 3],
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
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub aperture_center_mm: Option<[f64; 2]>,
}

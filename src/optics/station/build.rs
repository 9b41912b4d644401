//! Hardware profiles (`hw/`) and the symmetric layout of the paper's station,
//! from which a `station.toml` can be built.

use std::path::Path;

use nalgebra::{Matrix3, Point2, Point3, Rotation3, Unit, Vector3};
use serde::{Deserialize, Serialize};

use super::{Camera, CoverGlassFile, DistortionFile, Element, Screen, Station, StationError};

/// Format tag of a camera profile.
pub const CAMERA_PROFILE_FORMAT: &str = "mfd-camera-profile/1";
/// Format tag of a display profile.
pub const DISPLAY_PROFILE_FORMAT: &str = "mfd-display-profile/1";

/// A camera model's fixed properties (`hw/camera/*.toml`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraProfile {
    /// Must be `mfd-camera-profile/1`.
    pub format: String,
    /// Vendor and model.
    pub model: String,
    /// Sensor `[width, height]` in pixels.
    #[serde(deserialize_with = "crate::conventions::exact::array")]
    pub resolution: [u32; 2],
    /// Pixel pitch, µm.
    pub pixel_pitch_um: f64,
    /// Native ADC bit depth.
    pub bit_depth: u32,
    /// `[distortion]`: the mounted lens's distortion, as in `mfd-station/2`'s
    /// `[camera.distortion]` (optional; a station built from the profile
    /// then is version 2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distortion: Option<DistortionFile>,
}

/// A display model's fixed properties (`hw/display/*.toml`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DisplayProfile {
    /// Must be `mfd-display-profile/1`.
    pub format: String,
    /// Vendor and model.
    pub model: String,
    /// Panel `[width, height]` in pixels.
    #[serde(deserialize_with = "crate::conventions::exact::array")]
    pub resolution: [u32; 2],
    /// Pixel pitch, mm.
    pub pixel_pitch_mm: f64,
    /// Panel diagonal, inches (documentation; the pitch is what is used).
    pub diagonal_in: f64,
    /// Display gamma: emitted luminance ∝ (level / max)^gamma.
    pub gamma: f64,
    /// Time for the LCD to settle after a new frame is presented, ms.
    pub settle_ms: f64,
    /// `[cover_glass]`: the glass in front of the pixels, as in
    /// `mfd-station/2`'s `[screen.cover_glass]` (optional).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cover_glass: Option<CoverGlassFile>,
    /// `response = [[level, luminance], …]`: the measured response
    /// (optional), two values a row; the phase-shifting decode models it in
    /// place of `gamma` (`crate::solve::spectral::phase::ResponseCurve`
    /// checks it monotone).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub response: Option<Vec<Vec<f64>>>,
}

fn load_profile<T: serde::de::DeserializeOwned>(
    path: &Path,
    format: &str,
    read_format: impl Fn(&T) -> &str,
) -> Result<T, StationError> {
    let text = std::fs::read_to_string(path).map_err(|source| StationError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let profile: T = toml::from_str(&text).map_err(|source| StationError::Parse {
        path: path.to_path_buf(),
        source,
    })?;
    if read_format(&profile) != format {
        return Err(StationError::Invalid {
            path: path.to_path_buf(),
            field: "format",
            problem: format!("expected \"{format}\", found \"{}\"", read_format(&profile)),
        });
    }
    Ok(profile)
}

impl CameraProfile {
    /// Reads a camera profile.
    ///
    /// # Errors
    /// [`StationError`] naming the file and field.
    pub fn load(path: &Path) -> Result<Self, StationError> {
        let p: Self = load_profile(path, CAMERA_PROFILE_FORMAT, |p: &Self| &p.format)?;
        let bad = |field, problem| Err(profile_error(path, field, problem));
        if !(p.pixel_pitch_um.is_finite() && p.pixel_pitch_um > 0.0) {
            return bad(
                "pixel_pitch_um",
                format!("expected > 0 µm, found {}", p.pixel_pitch_um),
            );
        }
        // Camera ADCs give 8 to 16 bits; frames are stored as u8 or u16.
        if !(8..=16).contains(&p.bit_depth) {
            return bad(
                "bit_depth",
                format!("expected 8 to 16 bits, found {}", p.bit_depth),
            );
        }
        Ok(p)
    }
}

fn profile_error(path: &Path, field: &'static str, problem: String) -> StationError {
    StationError::Invalid {
        path: path.to_path_buf(),
        field,
        problem,
    }
}

impl DisplayProfile {
    /// Reads a display profile.
    ///
    /// # Errors
    /// [`StationError`] naming the file and field.
    pub fn load(path: &Path) -> Result<Self, StationError> {
        let p: Self = load_profile(path, DISPLAY_PROFILE_FORMAT, |p: &Self| &p.format)?;
        let bad = |field, problem| Err(profile_error(path, field, problem));
        for (field, v) in [
            ("pixel_pitch_mm", p.pixel_pitch_mm),
            ("diagonal_in", p.diagonal_in),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return bad(field, format!("expected a finite value > 0, found {v}"));
            }
        }
        // Displays are made to γ ≈ 1.8–2.6; 0.5 to 5 takes any panel,
        // linearised (1) or not, and refuses what is no gamma at all.
        if !(0.5..=5.0).contains(&p.gamma) {
            return bad("gamma", format!("expected 0.5 to 5, found {}", p.gamma));
        }
        if let Some(rows) = &p.response {
            if let Some((k, r)) = rows.iter().enumerate().find(|(_, r)| r.len() != 2) {
                return bad(
                    "response",
                    format!(
                        "row {k}: expected [level, luminance], found {} values",
                        r.len()
                    ),
                );
            }
        }
        // An LCD settles in a few to ~100 ms; 10 s is no display's.
        if !(0.0..=10_000.0).contains(&p.settle_ms) {
            return bad(
                "settle_ms",
                format!("expected 0 to 10000 ms, found {}", p.settle_ms),
            );
        }
        Ok(p)
    }
}

/// The paper's layout (§3, Fig. 7a): camera and screen at the same height
/// above the element, the camera's axis tilted from −z by `tilt_deg` in the
/// x–z plane and aimed at the element's centre, the screen parallel to the
/// element and centred on the specular reflection of the camera's axis, with
/// u along +x and v along −y.
#[derive(Debug, Clone, PartialEq)]
pub struct SymmetricLayout {
    /// Height of the camera's projection centre above the element, mm.
    pub camera_height_mm: f64,
    /// Height of the screen plane above the element, mm.
    pub screen_height_mm: f64,
    /// Angle between the camera's axis and −z, degrees.
    pub tilt_deg: f64,
    /// Lens focal length, mm.
    pub focal_length_mm: f64,
    /// The element.
    pub element: Element,
}

/// The 48 × 48 bench station: a small camera (10 µm pixels, f = 6 mm)
/// that sees the whole Ø 51 mm element from the paper's 825 mm, so every
/// pixel samples the aperture; the paper's 1600 × 1200 LCD; a plate of
/// `thickness_mm` and `index`, camera and screen tilted by `tilt_deg`.
/// What `mfd bench thickness|extremes`, `mfd tradeoff` and the tests run.
///
/// # Errors
/// As [`SymmetricLayout::build`].
pub fn bench_station(
    thickness_mm: f64,
    index: f64,
    tilt_deg: f64,
) -> Result<Station, StationError> {
    let camera = CameraProfile {
        format: "mfd-camera-profile/1".into(),
        model: "bench 48x48".into(),
        resolution: [48, 48],
        pixel_pitch_um: 10.0,
        bit_depth: 16,
        distortion: None,
    };
    let display = DisplayProfile::paper_lcd();
    let element = Element {
        refractive_index: index,
        thickness_mm,
        ..SymmetricLayout::paper_element()
    };
    let layout = SymmetricLayout {
        camera_height_mm: 825.0,
        screen_height_mm: 825.0,
        tilt_deg,
        focal_length_mm: 6.0,
        element,
    };
    layout.build(&camera, &display)
}

impl DisplayProfile {
    /// The paper's LCD: 1600 × 1200 pixels of 0.27 mm (21.3 in), gamma 2.2,
    /// 30 ms to settle, no cover glass, no measured response.
    pub fn paper_lcd() -> DisplayProfile {
        DisplayProfile {
            format: "mfd-display-profile/1".into(),
            model: "paper LCD".into(),
            resolution: [1600, 1200],
            pixel_pitch_mm: 0.27,
            diagonal_in: 21.3,
            gamma: 2.2,
            settle_ms: 30.0,
            cover_glass: None,
            response: None,
        }
    }
}

impl SymmetricLayout {
    /// The paper's simulated element: n = 1.5, 10 mm thick, Ø 51 mm.
    pub fn paper_element() -> Element {
        Element {
            refractive_index: 1.5,
            thickness_mm: 10.0,
            aperture_radius_mm: 25.5,
            aperture_center_mm: Point2::origin(),
            pose: super::Pose::default(),
            wedge: super::Wedge::NONE,
            outline: crate::optics::outline::Shape::Circle,
        }
    }

    /// Builds the station from the two profiles.
    ///
    /// # Errors
    /// [`StationError::Invalid`] when the result is not a possible station
    /// (checked exactly as a loaded file is).
    pub fn build(
        &self,
        camera: &CameraProfile,
        display: &DisplayProfile,
    ) -> Result<Station, StationError> {
        let t = self.tilt_deg.to_radians();
        let x_cam = Vector3::new(0.0, -1.0, 0.0);
        let axis = Vector3::new(t.sin(), 0.0, -t.cos());
        let y_cam = axis.cross(&x_cam);
        // `+ 0.0` turns the −0.0 of the cross product into 0.0 for tidy files.
        let m = Matrix3::from_columns(&[x_cam, y_cam, axis]).map(|v| v + 0.0);
        let [w, h] = camera.resolution;
        let cam = Camera {
            position_mm: Point3::new(-self.camera_height_mm * t.tan(), 0.0, self.camera_height_mm),
            world_from_camera: Rotation3::from_matrix_unchecked(m),
            focal_length_mm: self.focal_length_mm,
            pixel_pitch_mm: camera.pixel_pitch_um * 1e-3,
            width: w,
            height: h,
            principal_point_px: Point2::new(f64::from(w) / 2.0, f64::from(h) / 2.0),
            distortion: None,
            aspect_ratio: None,
        };
        let [sw, sh] = display.resolution;
        let p = display.pixel_pitch_mm;
        let centre = Point3::new(self.screen_height_mm * t.tan(), 0.0, self.screen_height_mm);
        let u_axis = Unit::new_normalize(Vector3::x());
        let v_axis = Unit::new_normalize(Vector3::new(0.0, -1.0, 0.0));
        let origin = centre
            - (f64::from(sw) * p / 2.0) * u_axis.as_ref()
            - (f64::from(sh) * p / 2.0) * v_axis.as_ref();
        let station = Station {
            camera: cam,
            screen: Screen {
                width: sw,
                height: sh,
                pixel_pitch_mm: p,
                origin_mm: origin,
                u_axis,
                v_axis,
                cover_glass: None,
            },
            element: self.element.clone(),
        };
        // Round-trip through the file form so a built station passes the very
        // checks a loaded one does; the profiles' version-2 tables go in
        // there, so they are validated exactly as a file's are.
        let mut file = station.to_file();
        if camera.distortion.is_some() || display.cover_glass.is_some() {
            file.format = super::STATION_FORMAT_V2.to_string();
            file.camera.distortion = camera.distortion.clone();
            file.screen.cover_glass = display.cover_glass.clone();
        }
        Station::from_file(&file, Path::new("<built station>"))
    }
}

//! Checks that turn a parsed [`StationFile`] into a [`Station`] or name the
//! first impossible field.

use std::path::Path;

use nalgebra::{Matrix3, Point2, Point3, Rotation3, Unit, Vector3};

use super::file::BROWN_CONRADY;
use super::{
    Camera, CoverGlass, Distortion, Element, ElementFile, Pose, Screen, Station, StationError,
    StationFile, Wedge, MAX_WEDGE_ARCMIN, STATION_FORMAT, STATION_FORMAT_V2, STATION_FORMAT_V3,
};

/// Tolerance on orthonormality of the rotation and of the screen axes.
/// Station files are written with ~16 significant digits by programs, but a
/// person typing `0.7071068` leaves errors of ~1e-7; 1e-6 accepts both and
/// still rejects any real mistake (a wrong sign or swapped column is O(1)).
const ORTHO_TOL: f64 = 1e-6;

/// The largest sensor or screen a station may have, checked before
/// anything of that size is allocated.
struct ResolutionLimit {
    /// Longest side, px.
    side_px: u32,
    /// Width × height.
    pixels: u64,
    /// What has it, for the message.
    what: &'static str,
}

/// The camera. Every stage holds a few values per camera pixel: the tracer
/// three paths of 32 B each (96 B), the spectral maps and `screen_coords`
/// at least 64 B more. At 2^26 = 67 Mpx that is over 10 GB, about what a
/// workstation gives one process, and above the machine-vision sensors a
/// station uses (up to 65 Mpx); a side of 65 536 px is 4 times the longest
/// of them. Beyond either a resolution is a typing error, and a 4e9-pixel
/// sensor panicked in the tracer.
const SENSOR_LIMIT: ResolutionLimit = ResolutionLimit {
    side_px: 65_536,
    pixels: 1 << 26,
    what: "a sensor",
};

/// The screen: a side of 16 384 px is twice an 8K display's 7 680, and the
/// largest texture a graphics adapter commonly takes; its pixel count
/// follows from the side. The screen's extent also bounds τ (the display's
/// Nyquist limit), and with it the spectral stage's frequency grid.
const SCREEN_LIMIT: ResolutionLimit = ResolutionLimit {
    side_px: 16_384,
    pixels: 16_384 * 16_384,
    what: "a screen",
};

struct Check<'a> {
    path: &'a Path,
}

impl Check<'_> {
    fn fail<T>(&self, field: &'static str, problem: String) -> Result<T, StationError> {
        Err(StationError::Invalid {
            path: self.path.to_path_buf(),
            field,
            problem,
        })
    }

    fn finite(&self, field: &'static str, values: &[f64]) -> Result<(), StationError> {
        if values.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            self.fail(field, format!("expected finite numbers, found {values:?}"))
        }
    }

    fn positive(&self, field: &'static str, value: f64) -> Result<(), StationError> {
        if value.is_finite() && value > 0.0 {
            Ok(())
        } else {
            self.fail(field, format!("expected a finite value > 0, found {value}"))
        }
    }

    fn resolution(
        &self,
        field: &'static str,
        r: [u32; 2],
        limit: &ResolutionLimit,
    ) -> Result<(), StationError> {
        if r[0] == 0 || r[1] == 0 {
            return self.fail(field, format!("expected [width, height] > 0, found {r:?}"));
        }
        if let Some(side) = r.iter().find(|&&s| s > limit.side_px) {
            return self.fail(
                field,
                format!(
                    "{side} px: above the {} px {} can have (found {r:?})",
                    limit.side_px, limit.what
                ),
            );
        }
        let pixels = u64::from(r[0]) * u64::from(r[1]);
        if pixels > limit.pixels {
            return self.fail(
                field,
                format!(
                    "{r:?} is {pixels} pixels: above the {} pixels {} can have",
                    limit.pixels, limit.what
                ),
            );
        }
        Ok(())
    }

    fn unit(&self, field: &'static str, v: [f64; 3]) -> Result<Unit<Vector3<f64>>, StationError> {
        self.finite(field, &v)?;
        let v = Vector3::from(v);
        if (v.norm() - 1.0).abs() > ORTHO_TOL {
            return self.fail(
                field,
                format!("expected a unit vector, found length {:.9}", v.norm()),
            );
        }
        Ok(Unit::new_normalize(v))
    }
}

pub(super) fn station(file: &StationFile, path: &Path) -> Result<Station, StationError> {
    let check = Check { path };
    if ![STATION_FORMAT, STATION_FORMAT_V2, STATION_FORMAT_V3].contains(&file.format.as_str()) {
        return check.fail(
            "format",
            format!(
                "expected \"{STATION_FORMAT}\", \"{STATION_FORMAT_V2}\" or the proposal \
                 \"{STATION_FORMAT_V3}\", found \"{}\"",
                file.format
            ),
        );
    }
    if file.format == STATION_FORMAT {
        version_1_only(&check, file)?;
    }
    let mut camera = camera(&check, file)?;
    camera.aspect_ratio =
        super::aspect_check::checked(path, &file.format, file.camera.aspect_ratio)?;
    camera.distortion = distortion(&check, file, &camera)?;
    let screen = screen(&check, file)?;
    let element = element(&check, file)?;
    geometry(&check, &camera, &screen)?;
    let station = Station {
        camera,
        screen,
        element,
    };
    if !station.element.pose.is_identity() {
        let local = station.element_frame();
        if geometry(&check, &local.camera, &local.screen).is_err() {
            return check.fail(
                "element.tilt_deg",
                format!(
                    "the element's pose (offset {:?} mm, tilt {:?}°) turns its front away \
                     from the camera or the screen: both must stay on the front's side, \
                     looking down at it",
                    station.element.pose.offset_mm.as_slice(),
                    station.element.pose.tilt_deg
                ),
            );
        }
    }
    Ok(station)
}

/// A version-1 file must not use version-2 fields.
fn version_1_only(check: &Check, file: &StationFile) -> Result<(), StationError> {
    let used = [
        ("camera.distortion", file.camera.distortion.is_some()),
        ("screen.cover_glass", file.screen.cover_glass.is_some()),
        ("element.offset_mm", file.element.offset_mm.is_some()),
        ("element.tilt_deg", file.element.tilt_deg.is_some()),
        ("element.wedge_arcmin", file.element.wedge_arcmin.is_some()),
        (
            "element.wedge_azimuth_deg",
            file.element.wedge_azimuth_deg.is_some(),
        ),
    ];
    match used.iter().find(|(_, u)| *u) {
        Some((field, _)) => check.fail(
            field,
            format!(
                "a version-2 field in a \"{STATION_FORMAT}\" file: write \
                 format = \"{STATION_FORMAT_V2}\" to use it"
            ),
        ),
        None => Ok(()),
    }
}

/// Round-trip points per sensor side when checking the distortion's inverse.
const INVERSE_GRID: u32 = 17;

fn distortion(
    check: &Check,
    file: &StationFile,
    camera: &Camera,
) -> Result<Option<Distortion>, StationError> {
    let Some(d) = &file.camera.distortion else {
        return Ok(None);
    };
    if d.model != BROWN_CONRADY {
        return check.fail(
            "camera.distortion.model",
            format!("expected \"{BROWN_CONRADY}\", found \"{}\"", d.model),
        );
    }
    let k = d.k.unwrap_or([0.0; 3]);
    let p = d.p.unwrap_or([0.0; 2]);
    check.finite("camera.distortion.k", &k)?;
    check.finite("camera.distortion.p", &p)?;
    let dist = Distortion { k, p };
    if dist.is_zero() {
        return Ok(None);
    }
    let [fx, fy] = camera.focal_px_xy();
    let (w, h) = (f64::from(camera.width), f64::from(camera.height));
    let c = camera.principal_point_px;
    let rd_max = [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h)]
        .iter()
        .map(|&(x, y)| ((x - c.x) / fx).hypot((y - c.y) / fy))
        .fold(0.0, f64::max);
    if let Some(problem) = dist.not_monotone_below(rd_max) {
        return check.fail("camera.distortion.k", problem);
    }
    // The spec's condition is on the radial part; the tangential terms can
    // still fold the map. Newton from every point of a grid over the whole
    // sensor (edges included) must converge and distort back to it.
    for a in 0..=INVERSE_GRID {
        for b in 0..=INVERSE_GRID {
            let xd = (w * f64::from(a) / f64::from(INVERSE_GRID) - c.x) / fx;
            let yd = (h * f64::from(b) / f64::from(INVERSE_GRID) - c.y) / fy;
            let ok = dist.undistort(xd, yd).is_some_and(|(x, y)| {
                let j = dist.jacobian(x, y);
                j[0][0] * j[1][1] - j[0][1] * j[1][0] > 0.0
            });
            if !ok {
                return check.fail(
                    "camera.distortion",
                    format!(
                        "the distortion's inverse is not unique over the sensor: at pixel \
                         ({:.0}, {:.0}) Newton finds no ideal point with a non-folding map",
                        xd * fx + c.x,
                        yd * fy + c.y
                    ),
                );
            }
        }
    }
    Ok(Some(dist))
}

/// The widest angle from the optical axis, degrees, at which a station's
/// camera may see the corner of its sensor. The station's camera is a
/// central projection (with a small distortion): a rectilinear lens. At
/// 80° the image of a ray is already 5.7 focal lengths off axis
/// (tan 80°); the widest rectilinear lenses made stay below that, and a
/// wider view is a fisheye, whose mapping the model does not describe.
pub const MAX_HALF_FIELD_DEG: f64 = 80.0;

/// The focal length against the sensor it images: the half diagonal must
/// be seen within [`MAX_HALF_FIELD_DEG`] of the axis. A focal length far
/// too short (a unit slip: 1e-9 mm) is named here, before the distortion's
/// checks see its consequences.
fn field_of_view(check: &Check, c: &super::file::CameraFile) -> Result<(), StationError> {
    let [w, h] = c.resolution.map(f64::from);
    let half_diagonal_mm = 0.5 * w.hypot(h) * c.pixel_pitch_um * 1e-3;
    let half_field_deg = half_diagonal_mm.atan2(c.focal_length_mm).to_degrees();
    if half_field_deg <= MAX_HALF_FIELD_DEG {
        return Ok(());
    }
    let shortest = half_diagonal_mm / MAX_HALF_FIELD_DEG.to_radians().tan();
    check.fail(
        "camera.focal_length_mm",
        format!(
            "{:?} mm: the sensor's corner ({half_diagonal_mm:.2} mm from its centre) would be \
             {half_field_deg:.1}° off the axis, beyond the {MAX_HALF_FIELD_DEG}° a \
             rectilinear lens images; with this sensor the focal length must be at least \
             {shortest:.2} mm (is it in mm?)",
            c.focal_length_mm
        ),
    )
}

fn camera(check: &Check, file: &StationFile) -> Result<Camera, StationError> {
    let c = &file.camera;
    check.finite("camera.position_mm", &c.position_mm)?;
    check.finite("camera.rotation", c.rotation.as_flattened())?;
    let m = Matrix3::from_fn(|r, col| c.rotation[r][col]);
    let ortho_err = (m.transpose() * m - Matrix3::identity()).abs().max();
    if ortho_err > ORTHO_TOL {
        return check.fail(
            "camera.rotation",
            format!("expected an orthonormal matrix, |RᵀR − I| reaches {ortho_err:.3e}"),
        );
    }
    if m.determinant() < 0.0 {
        return check.fail(
            "camera.rotation",
            "determinant is −1: a reflection, not a rotation (columns must be right-handed)".into(),
        );
    }
    check.positive("camera.focal_length_mm", c.focal_length_mm)?;
    check.positive("camera.pixel_pitch_um", c.pixel_pitch_um)?;
    check.resolution("camera.resolution", c.resolution, &SENSOR_LIMIT)?;
    field_of_view(check, c)?;
    let [w, h] = c.resolution;
    let pp = c
        .principal_point_px
        .unwrap_or([f64::from(w) / 2.0, f64::from(h) / 2.0]);
    check.finite("camera.principal_point_px", &pp)?;
    Ok(Camera {
        position_mm: Point3::from(c.position_mm),
        world_from_camera: Rotation3::from_matrix_unchecked(m),
        focal_length_mm: c.focal_length_mm,
        pixel_pitch_mm: c.pixel_pitch_um * 1e-3,
        width: w,
        height: h,
        principal_point_px: Point2::from(pp),
        distortion: None,
        aspect_ratio: None,
    })
}

fn screen(check: &Check, file: &StationFile) -> Result<Screen, StationError> {
    let s = &file.screen;
    check.resolution("screen.resolution", s.resolution, &SCREEN_LIMIT)?;
    check.positive("screen.pixel_pitch_mm", s.pixel_pitch_mm)?;
    check.finite("screen.origin_mm", &s.origin_mm)?;
    let u_axis = check.unit("screen.u_axis", s.u_axis)?;
    let v_axis = check.unit("screen.v_axis", s.v_axis)?;
    let dot = u_axis.dot(&v_axis);
    if dot.abs() > ORTHO_TOL {
        return check.fail(
            "screen.v_axis",
            format!("expected perpendicular to screen.u_axis, u·v = {dot:.3e}"),
        );
    }
    let cover_glass = match &s.cover_glass {
        None => None,
        Some(g) => {
            check.positive("screen.cover_glass.thickness_mm", g.thickness_mm)?;
            if !(g.refractive_index.is_finite() && g.refractive_index > 1.0) {
                return check.fail(
                    "screen.cover_glass.refractive_index",
                    format!(
                        "expected a finite index > 1 (glass in air), found {}",
                        g.refractive_index
                    ),
                );
            }
            Some(CoverGlass {
                thickness_mm: g.thickness_mm,
                refractive_index: g.refractive_index,
            })
        }
    };
    Ok(Screen {
        width: s.resolution[0],
        height: s.resolution[1],
        pixel_pitch_mm: s.pixel_pitch_mm,
        origin_mm: Point3::from(s.origin_mm),
        u_axis,
        v_axis,
        cover_glass,
    })
}

fn element(check: &Check, file: &StationFile) -> Result<Element, StationError> {
    let e = &file.element;
    if !(e.refractive_index.is_finite() && e.refractive_index > 1.0) {
        return check.fail(
            "element.refractive_index",
            format!(
                "expected a finite index > 1 (the element sits in air), found {}",
                e.refractive_index
            ),
        );
    }
    check.positive("element.thickness_mm", e.thickness_mm)?;
    check.positive("element.aperture_radius_mm", e.aperture_radius_mm)?;
    let centre = e.aperture_center_mm.unwrap_or([0.0, 0.0]);
    check.finite("element.aperture_center_mm", &centre)?;
    let offset = e.offset_mm.unwrap_or([0.0; 3]);
    let tilt = e.tilt_deg.unwrap_or([0.0; 2]);
    check.finite("element.offset_mm", &offset)?;
    check.finite("element.tilt_deg", &tilt)?;
    if let Some(t) = tilt.iter().find(|t| t.abs() >= 90.0) {
        return check.fail(
            "element.tilt_deg",
            format!("expected tilts within ±90° (degrees, not radians?), found {t}"),
        );
    }
    let wedge = wedge(check, e)?;
    let outline = super::outline_check::shape(check.path, &file.format, e, centre)?;
    Ok(Element {
        refractive_index: e.refractive_index,
        thickness_mm: e.thickness_mm,
        aperture_radius_mm: e.aperture_radius_mm,
        aperture_center_mm: Point2::from(centre),
        pose: Pose {
            offset_mm: Vector3::from(offset),
            tilt_deg: tilt,
        },
        wedge,
        outline,
    })
}

/// `wedge_arcmin` in `[0, 120]` (the spec's limit), `wedge_azimuth_deg` finite.
fn wedge(check: &Check, e: &ElementFile) -> Result<Wedge, StationError> {
    let arcmin = e.wedge_arcmin.unwrap_or(0.0);
    let azimuth_deg = e.wedge_azimuth_deg.unwrap_or(0.0);
    if !(arcmin.is_finite() && (0.0..=MAX_WEDGE_ARCMIN).contains(&arcmin)) {
        return check.fail(
            "element.wedge_arcmin",
            format!(
                "expected a wedge of 0 to {MAX_WEDGE_ARCMIN} arcmin (minutes of arc, not \
                 degrees or radians; its direction is wedge_azimuth_deg), found {arcmin}"
            ),
        );
    }
    check.finite("element.wedge_azimuth_deg", &[azimuth_deg])?;
    Ok(Wedge {
        arcmin,
        azimuth_deg,
    })
}

/// The camera and screen must both be above the element (z > 0), the camera
/// must look down at it, and the camera's principal ray, reflected by the
/// reference plane z = 0, must reach the screen plane going forward; a screen
/// behind the camera or below the element cannot show the camera anything.
fn geometry(check: &Check, camera: &Camera, screen: &Screen) -> Result<(), StationError> {
    if camera.position_mm.z <= 0.0 {
        return check.fail(
            "camera.position_mm",
            format!(
                "the camera must be above the element (z > 0, +z points from the element \
                 towards the camera), found z = {}",
                camera.position_mm.z
            ),
        );
    }
    let axis = camera.axis();
    if axis.z >= 0.0 {
        return check.fail(
            "camera.rotation",
            format!(
                "the optical axis (third column) must point down at the element (z < 0), \
                 found {:?}",
                axis.as_ref()
            ),
        );
    }
    let corners = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)].map(|(a, b)| {
        screen.world_point(a * f64::from(screen.width), b * f64::from(screen.height))
    });
    if let Some(low) = corners.iter().find(|p| p.z <= 0.0) {
        return check.fail(
            "screen.origin_mm",
            format!(
                "the screen must be above the element (z > 0); a corner lies at z = {}",
                low.z
            ),
        );
    }
    let t_plane = -camera.position_mm.z / axis.z;
    let hit = camera.position_mm + t_plane * axis.as_ref();
    let reflected = Vector3::new(axis.x, axis.y, -axis.z);
    let n = screen.normal();
    let denom = reflected.dot(&n);
    let t_screen = (screen.origin_mm - hit).dot(&n) / denom;
    if denom.abs() < 1e-12 || t_screen <= 0.0 {
        return check.fail(
            "screen.origin_mm",
            "the screen is behind the camera: the principal ray reflected by the element \
             never reaches the screen plane"
                .into(),
        );
    }
    Ok(())
}

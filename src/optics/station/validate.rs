//! Checks that turn a parsed [`StationFile`] into a [`Station`] or name the
//! first impossible field.

use std::path::Path;

use nalgebra::{Matrix3, Point2, Point3, Rotation3, Unit, Vector3};

use super::{Camera, Element, Screen, Station, StationError, StationFile, STATION_FORMAT};

/// Tolerance on orthonormality of the rotation and of the screen axes.
/// Station files are written with ~16 significant digits by programs, but a
/// person typing `0.7071068` leaves errors of ~1e-7; 1e-6 accepts both and
/// still rejects any real mistake (a wrong sign or swapped column is O(1)).
const ORTHO_TOL: f64 = 1e-6;

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

    fn resolution(&self, field: &'static str, r: [u32; 2]) -> Result<(), StationError> {
        if r[0] == 0 || r[1] == 0 {
            return self.fail(field, format!("expected [width, height] > 0, found {r:?}"));
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
    if file.format != STATION_FORMAT {
        return check.fail(
            "format",
            format!("expected \"{STATION_FORMAT}\", found \"{}\"", file.format),
        );
    }
    let camera = camera(&check, file)?;
    let screen = screen(&check, file)?;
    let element = element(&check, file)?;
    geometry(&check, &camera, &screen)?;
    Ok(Station {
        camera,
        screen,
        element,
    })
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
    check.resolution("camera.resolution", c.resolution)?;
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
    })
}

fn screen(check: &Check, file: &StationFile) -> Result<Screen, StationError> {
    let s = &file.screen;
    check.resolution("screen.resolution", s.resolution)?;
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
    Ok(Screen {
        width: s.resolution[0],
        height: s.resolution[1],
        pixel_pitch_mm: s.pixel_pitch_mm,
        origin_mm: Point3::from(s.origin_mm),
        u_axis,
        v_axis,
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
    Ok(Element {
        refractive_index: e.refractive_index,
        thickness_mm: e.thickness_mm,
        aperture_radius_mm: e.aperture_radius_mm,
        aperture_center_mm: Point2::from(centre),
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

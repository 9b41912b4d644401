//! The element's pose (station v2): where the element's own frame sits in
//! the world. A point `p'` of the element's frame is at world position
//! `p = c + R (p' − c) + offset`, with `c = (aperture_center_mm, 0)` and
//! `R = R_y(ry) R_x(rx)`.
//!
//! Every stage works in the element's frame: [`super::Station::element_frame`]
//! re-expresses the camera and the screen there, so the plate is traced,
//! fitted and reported exactly as on a version-1 station, and the back's
//! piston is the thickness along the element's own normal.

use nalgebra::{Point3, Rotation3, Vector3};

/// Offset and tilts of the element's frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Translation of the element's frame, world frame, mm.
    pub offset_mm: Vector3<f64>,
    /// Rotation about world x, then world y, degrees.
    pub tilt_deg: [f64; 2],
}

impl Default for Pose {
    fn default() -> Self {
        Pose {
            offset_mm: Vector3::zeros(),
            tilt_deg: [0.0; 2],
        }
    }
}

impl Pose {
    /// Whether this is the version-1 pose (the element exactly at the reference plane).
    pub fn is_identity(&self) -> bool {
        self.offset_mm == Vector3::zeros() && self.tilt_deg == [0.0; 2]
    }

    /// `R = R_y(ry) R_x(rx)`, element frame to world.
    pub fn rotation(&self) -> Rotation3<f64> {
        let [rx, ry] = self.tilt_deg.map(f64::to_radians);
        Rotation3::from_axis_angle(&Vector3::y_axis(), ry)
            * Rotation3::from_axis_angle(&Vector3::x_axis(), rx)
    }

    /// World position of the element-frame point `p`, pivot `c`.
    pub fn to_world(&self, c: &Point3<f64>, p: &Point3<f64>) -> Point3<f64> {
        c + self.rotation() * (p - c) + self.offset_mm
    }

    /// Element-frame position of the world point `p`, pivot `c`.
    pub fn to_element(&self, c: &Point3<f64>, p: &Point3<f64>) -> Point3<f64> {
        c + self.rotation().inverse() * (p - self.offset_mm - c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_is_about_x_then_y() {
        let pose = Pose {
            offset_mm: Vector3::zeros(),
            tilt_deg: [90.0, 90.0],
        };
        // R_x(90°) takes y to z; R_y(90°) then takes z to x.
        let v = pose.rotation() * Vector3::y();
        assert!((v - Vector3::x()).norm() < 1e-15);
    }

    #[test]
    fn to_element_inverts_to_world() {
        let pose = Pose {
            offset_mm: Vector3::new(0.1, -0.2, 0.012),
            tilt_deg: [0.8, -0.1],
        };
        let c = Point3::new(1.0, 2.0, 0.0);
        let p = Point3::new(-30.0, 12.0, 825.0);
        let back = pose.to_element(&c, &pose.to_world(&c, &p));
        assert!((back - p).norm() < 1e-12);
        // The pivot moves only by the offset.
        assert!((pose.to_world(&c, &c) - c - pose.offset_mm).norm() < 1e-15);
    }
}

//! The camera's projection: a pixel's ray and a point's pixel, through
//! the distortion and both focal lengths (`interchange.md`'s formulas, and
//! `docs/proposals/aspect.md`'s fx ≠ fy).

use nalgebra::{Point2, Point3, Unit, Vector3};

use super::Camera;

impl Camera {
    /// Unit direction, world frame, of the ray through the centre of pixel
    /// (column `i`, row `j`), per the spec.
    pub fn ray_direction(&self, i: u32, j: u32) -> Unit<Vector3<f64>> {
        if self.distortion.is_some() {
            return self.ray_through(f64::from(i) + 0.5, f64::from(j) + 0.5);
        }
        let p = self.pixel_pitch_mm;
        let v_cam = Vector3::new(
            (f64::from(i) + 0.5 - self.principal_point_px.x) * p,
            (f64::from(j) + 0.5 - self.principal_point_px.y) * p / self.aspect(),
            self.focal_length_mm,
        );
        Unit::new_normalize(self.world_from_camera * v_cam)
    }

    /// Unit direction, world frame, of the ray that lands at the continuous
    /// pixel position `(x_px, y_px)` (pixel-centre convention: the centre of
    /// pixel `(i, j)` is `(i + 0.5, j + 0.5)`), through the distortion's
    /// inverse. Validation guarantees the inverse over the sensor; outside
    /// it, where Newton may not converge, the direction is NaN.
    pub fn ray_through(&self, x_px: f64, y_px: f64) -> Unit<Vector3<f64>> {
        let [fx, fy] = self.focal_px_xy();
        let xd = (x_px - self.principal_point_px.x) / fx;
        let yd = (y_px - self.principal_point_px.y) / fy;
        let (x, y) = match &self.distortion {
            None => (xd, yd),
            Some(d) => d.undistort(xd, yd).unwrap_or((f64::NAN, f64::NAN)),
        };
        Unit::new_unchecked((self.world_from_camera * Vector3::new(x, y, 1.0)).normalize())
    }

    /// The continuous pixel position where the world point `p` is imaged,
    /// or `None` when it lies behind the camera.
    pub fn project(&self, p: &Point3<f64>) -> Option<Point2<f64>> {
        let q = self.world_from_camera.inverse() * (p - self.position_mm);
        if q.z <= 0.0 {
            return None;
        }
        let (x, y) = (q.x / q.z, q.y / q.z);
        let (xd, yd) = match &self.distortion {
            None => (x, y),
            Some(d) => d.distort(x, y),
        };
        let [fx, fy] = self.focal_px_xy();
        Some(Point2::new(
            self.principal_point_px.x + fx * xd,
            self.principal_point_px.y + fy * yd,
        ))
    }

    /// `F = focal_length_mm / pixel pitch`: the focal length in pixels
    /// along the columns (OpenCV's `fx`).
    pub fn focal_px(&self) -> f64 {
        self.focal_length_mm / self.pixel_pitch_mm
    }

    /// `fy / fx`: the declared aspect ratio, 1 for square pixels.
    pub fn aspect(&self) -> f64 {
        self.aspect_ratio.unwrap_or(1.0)
    }

    /// `[fx, fy]`, the focal lengths in pixels along the columns and the
    /// rows: `fy = aspect · fx`.
    pub fn focal_px_xy(&self) -> [f64; 2] {
        let fx = self.focal_px();
        [fx, fx * self.aspect()]
    }

    /// The optical axis, world frame.
    pub fn axis(&self) -> Unit<Vector3<f64>> {
        Unit::new_normalize(self.world_from_camera * Vector3::z())
    }

    /// Number of pixels.
    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }
}

//! The soak generator's own optics, written from `interchange.md` alone
//! (station v1 and v2): the pinhole with Brown–Conrady distortion in the
//! pixel-centre convention, the distortion's inverse by Newton, the flat
//! mirror at the world's `z = 0`, and the screen's cover glass (a slab on
//! the viewer's side of the pixel plane, refraction at its outer face).
//! Nothing here calls mfd's optics: these are the second implementation
//! the calibration is checked against.

use nalgebra::{Matrix2, Matrix3, Point2, Point3, Vector2, Vector3};

/// A camera as `interchange.md` describes it.
#[derive(Debug, Clone, PartialEq)]
pub struct Cam {
    /// Projection centre C, world, mm.
    pub centre: Point3<f64>,
    /// Camera-to-world rotation: columns are the camera's x (increasing
    /// column), y (increasing row) and optical axis, world frame.
    pub rotation: Matrix3<f64>,
    /// Focal length, mm.
    pub focal_mm: f64,
    /// Pixel pitch, µm.
    pub pitch_um: f64,
    /// `[width, height]`, pixels.
    pub resolution: [u32; 2],
    /// Principal point `(cx, cy)`, continuous pixel position.
    pub principal_px: [f64; 2],
    /// Radial `k1, k2, k3` and tangential `p1, p2`; all zero: a pinhole.
    pub k: [f64; 3],
    /// See [`Cam::k`].
    pub p: [f64; 2],
    /// `fy / fx` (`docs/proposals/aspect.md`); `None`: square pixels.
    pub aspect: Option<f64>,
}

impl Cam {
    /// `F = focal_length_mm / (pixel_pitch_um / 1000)`, px: `fx`, and
    /// `fy = aspect · F` (`docs/proposals/aspect.md`).
    pub fn focal_px(&self) -> [f64; 2] {
        let f = self.focal_mm / (self.pitch_um / 1000.0);
        [f, f * self.aspect.unwrap_or(1.0)]
    }

    /// The spec's distortion of normalised coordinates `(x', y')`.
    pub fn distort(&self, x: f64, y: f64) -> Vector2<f64> {
        let [k1, k2, k3] = self.k;
        let [p1, p2] = self.p;
        let r2 = x * x + y * y;
        let radial = 1.0 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2;
        Vector2::new(
            x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
        )
    }

    /// `∂(x'', y'') / ∂(x', y')`, differentiated by hand from
    /// [`Cam::distort`].
    fn distort_jacobian(&self, x: f64, y: f64) -> Matrix2<f64> {
        let [k1, k2, k3] = self.k;
        let [p1, p2] = self.p;
        let r2 = x * x + y * y;
        let radial = 1.0 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2;
        // d radial / d(r²)
        let dr = k1 + 2.0 * k2 * r2 + 3.0 * k3 * r2 * r2;
        Matrix2::new(
            radial + x * dr * 2.0 * x + 2.0 * p1 * y + p2 * 6.0 * x,
            x * dr * 2.0 * y + 2.0 * p1 * x + p2 * 2.0 * y,
            y * dr * 2.0 * x + p1 * 2.0 * x + 2.0 * p2 * y,
            radial + y * dr * 2.0 * y + p1 * 6.0 * y + 2.0 * p2 * x,
        )
    }

    /// The continuous pixel position of world point `p` (`None` behind
    /// the camera).
    pub fn project(&self, p: &Point3<f64>) -> Option<Point2<f64>> {
        let q = self.rotation.transpose() * (p - self.centre);
        if q.z <= 0.0 {
            return None;
        }
        let d = self.distort(q.x / q.z, q.y / q.z);
        let [fx, fy] = self.focal_px();
        Some(Point2::new(
            self.principal_px[0] + fx * d.x,
            self.principal_px[1] + fy * d.y,
        ))
    }

    /// The normalised `(x', y')` whose distortion lands at continuous pixel
    /// position `px`: Newton from the distorted point, to 1e-15 (the
    /// generator only draws distortions whose radial factor increases over
    /// the sensor, so the root is unique there). `None` if it does not
    /// converge.
    pub fn undistort(&self, px: Point2<f64>) -> Option<Vector2<f64>> {
        let [fx, fy] = self.focal_px();
        let target = Vector2::new(
            (px.x - self.principal_px[0]) / fx,
            (px.y - self.principal_px[1]) / fy,
        );
        let mut x = target;
        for _ in 0..50 {
            let r = self.distort(x.x, x.y) - target;
            if r.norm() < 1e-15 {
                return Some(x);
            }
            x -= self.distort_jacobian(x.x, x.y).try_inverse()? * r;
        }
        None
    }

    /// Unit direction, world, of the ray landing at continuous pixel `px`.
    pub fn ray(&self, px: Point2<f64>) -> Option<Vector3<f64>> {
        let n = self.undistort(px)?;
        Some((self.rotation * Vector3::new(n.x, n.y, 1.0)).normalize())
    }
}

/// A screen as `interchange.md` describes it (u, v axes orthonormal here).
#[derive(Debug, Clone, PartialEq)]
pub struct Scr {
    /// World position of `(u, v) = (0, 0)`, mm.
    pub origin: Point3<f64>,
    /// Unit vector of increasing u, world.
    pub u: Vector3<f64>,
    /// Unit vector of increasing v, world.
    pub v: Vector3<f64>,
    /// Screen pixel pitch, mm.
    pub pitch_mm: f64,
    /// `[width, height]`, screen pixels.
    pub resolution: [u32; 2],
    /// Cover glass `(thickness mm, index)`, if any.
    pub glass: Option<(f64, f64)>,
}

impl Scr {
    /// World point of screen coordinate `(u, v)`.
    pub fn world(&self, u: f64, v: f64) -> Point3<f64> {
        self.origin + self.pitch_mm * (u * self.u + v * self.v)
    }

    /// Screen coordinate of a world point of the pixel plane.
    pub fn coords(&self, p: &Point3<f64>) -> Point2<f64> {
        let d = p - self.origin;
        Point2::new(d.dot(&self.u), d.dot(&self.v)) / self.pitch_mm
    }

    /// Where a ray from `from` along unit `dir` lands on the pixel plane:
    /// straight on bare pixels; through the slab otherwise, refracted at
    /// the slab's outer face (the plane `thickness` in front of the pixel
    /// plane, on the side the ray comes from) by Snell's law, then straight
    /// to the pixel plane. `None` if the ray runs away from the screen.
    pub fn land(&self, from: &Point3<f64>, dir: &Vector3<f64>) -> Option<Point3<f64>> {
        let n0 = self.u.cross(&self.v);
        // The normal on the viewer's side: the side `from` is on.
        let n = if (from - self.origin).dot(&n0) >= 0.0 {
            n0
        } else {
            -n0
        };
        let (face, d) = match self.glass {
            None => (self.origin, *dir),
            Some((t, index)) => {
                let face = self.origin + t * n;
                let a = hit_plane(from, dir, &face, &n)?;
                // Snell in vector form from air (1) into the glass (index):
                // the tangential part scales by 1/index, the normal part
                // makes the direction a unit vector again.
                let cos_i = -dir.dot(&n);
                let tangential = (dir + cos_i * n) / index;
                let cos_t = (1.0 - tangential.norm_squared()).sqrt();
                let inside = tangential - cos_t * n;
                let p = hit_plane(&a, &inside, &self.origin, &n)?;
                return Some(p);
            }
        };
        hit_plane(from, &d, &face, &n)
    }
}

/// Where the ray `from + s dir` (`s > 0`) meets the plane through `on`
/// with normal `n`.
fn hit_plane(
    from: &Point3<f64>,
    dir: &Vector3<f64>,
    on: &Point3<f64>,
    n: &Vector3<f64>,
) -> Option<Point3<f64>> {
    let s = (on - from).dot(n) / dir.dot(n);
    (s.is_finite() && s > 0.0).then(|| from + s * dir)
}

/// The screen coordinate that camera pixel position `px` sees in a flat
/// mirror at the world's `z = 0`, and where its ray meets the mirror
/// (world, mm). `None` where the ray misses the mirror or the screen.
pub fn flat_uv(cam: &Cam, scr: &Scr, px: Point2<f64>) -> Option<(Point2<f64>, Point3<f64>)> {
    let d = cam.ray(px)?;
    if d.z >= 0.0 {
        return None;
    }
    let hit = cam.centre + (-cam.centre.z / d.z) * d;
    let r = Vector3::new(d.x, d.y, -d.z);
    let landing = scr.land(&hit, &r)?;
    Some((scr.coords(&landing), hit))
}

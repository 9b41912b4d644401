//! The element's light paths for one camera ray (paper Fig. 3 and §5.1b):
//! front reflection (S1), one internal back reflection (S2), and the path
//! with a second internal round trip (S3).

use nalgebra::Point3;

use super::intersect::{intersect, IntersectFailure, SurfaceHit};
use super::Plate;
use crate::optics::refraction::{reflect, reflectance, refract, Dir, Refraction};
use crate::optics::station::Screen;

/// Why a path yields no screen point. Every pixel's path ends in a hit or in
/// exactly one of these; nothing is dropped silently or propagated as NaN.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Miss {
    /// The camera ray does not meet the element's front within its edge.
    ElementMissed,
    /// The path meets a surface beyond the element's edge (`surface` 0 front,
    /// 1 back) and would leave through the rim.
    LeavesEdge {
        /// 0 front, 1 back.
        surface: u8,
    },
    /// Total internal reflection where the path should leave the element.
    TotalInternalReflection,
    /// Newton did not converge on a surface.
    NoConvergence,
    /// The outgoing ray never reaches the screen plane.
    ScreenMissed,
    /// The ray reaches the screen plane outside the displayed area.
    OffScreen,
}

impl Miss {
    /// A small stable code for status maps (0 is reserved for "hit").
    pub fn code(self) -> u8 {
        match self {
            Miss::ElementMissed => 1,
            Miss::LeavesEdge { .. } => 2,
            Miss::TotalInternalReflection => 3,
            Miss::NoConvergence => 4,
            Miss::ScreenMissed => 5,
            Miss::OffScreen => 6,
        }
    }
}

impl From<IntersectFailure> for Miss {
    fn from(f: IntersectFailure) -> Self {
        match f {
            IntersectFailure::NoCrossing => Miss::ElementMissed,
            IntersectFailure::NoConvergence => Miss::NoConvergence,
        }
    }
}

/// Where a path lands on the screen and how much light it carries.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScreenHit {
    /// Continuous screen coordinate u, screen pixels.
    pub u: f64,
    /// Continuous screen coordinate v, screen pixels.
    pub v: f64,
    /// Unpolarised Fresnel weight of the path: the fraction of screen
    /// radiance that reaches the camera along it.
    pub weight: f64,
}

/// Outcome of one path.
pub type PathOutcome = Result<ScreenHit, Miss>;

/// The three paths of one camera ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelPaths {
    /// Front reflection, S1.
    pub front: PathOutcome,
    /// One internal reflection off the back, S2.
    pub back: PathOutcome,
    /// Two internal round trips, S3.
    pub third: PathOutcome,
}

/// Intersects the screen plane (through the cover glass where the station
/// has one) and converts to `(u, v)`.
pub fn to_screen(screen: &Screen, from: &Point3<f64>, d: &Dir) -> Result<(f64, f64), Miss> {
    let landing = match &screen.cover_glass {
        None => bare_landing(screen, from, d)?,
        Some(glass) => glass
            .land(&screen.origin_mm, &screen.normal_towards(from), from, d)
            .ok_or(Miss::ScreenMissed)?,
    };
    let (u, v) = screen.coordinates(&landing);
    if screen.contains(u, v) {
        Ok((u, v))
    } else {
        Err(Miss::OffScreen)
    }
}

fn bare_landing(screen: &Screen, from: &Point3<f64>, d: &Dir) -> Result<Point3<f64>, Miss> {
    let n = screen.normal();
    let denom = d.dot(&n);
    if denom.abs() < 1e-12 {
        return Err(Miss::ScreenMissed);
    }
    let s = (screen.origin_mm - from).dot(&n) / denom;
    if s <= 0.0 {
        return Err(Miss::ScreenMissed);
    }
    Ok(from + s * d.as_ref())
}

impl Plate {
    fn hit(&self, from: &Point3<f64>, d: &Dir, back: bool) -> Result<SurfaceHit, Miss> {
        let (surface, z0, code) = if back {
            (&self.back, -self.thickness_mm, 1)
        } else {
            (&self.front, 0.0, 0)
        };
        let hit = intersect(from, d, surface, z0)?;
        if self.outside_edge(&hit.point) {
            return Err(Miss::LeavesEdge { surface: code });
        }
        Ok(hit)
    }

    fn outside_edge(&self, p: &Point3<f64>) -> bool {
        self.outside_edge_xy(p.x, p.y)
    }

    /// Traces all three paths of the ray from `camera` along `d`.
    pub fn trace_ray(&self, camera: &Point3<f64>, d: &Dir, screen: &Screen) -> PixelPaths {
        let none = PixelPaths {
            front: Err(Miss::ElementMissed),
            back: Err(Miss::ElementMissed),
            third: Err(Miss::ElementMissed),
        };
        // Cheap rejection on the reference plane: the surfaces are within
        // micrometres of it, so a ray missing the rim by 1 mm there misses it.
        if d.z >= 0.0 {
            return none;
        }
        let on_plane = camera + (-camera.z / d.z) * d.as_ref();
        if self.outline.outside_by_mm(on_plane.x, on_plane.y) > self.edge_margin_mm + 1.0 {
            return none;
        }
        let m1 = match self.hit(camera, d, false) {
            Ok(h) => h,
            Err(Miss::LeavesEdge { .. }) => return none,
            Err(e) => {
                return PixelPaths {
                    front: Err(e),
                    back: Err(e),
                    third: Err(e),
                }
            }
        };
        let n = self.refractive_index;
        let cos1 = -d.dot(&m1.normal);
        let r1 = reflectance(cos1, 1.0, n);
        let front = to_screen(screen, &m1.point, &reflect(d, &m1.normal)).map(|(u, v)| ScreenHit {
            u,
            v,
            weight: r1,
        });
        let (back, third) = self.internal(&m1, d, 1.0 - r1, screen);
        PixelPaths { front, back, third }
    }

    /// The paths that enter the element at `m1`: one and two internal round trips.
    fn internal(
        &self,
        m1: &SurfaceHit,
        d: &Dir,
        t_in: f64,
        screen: &Screen,
    ) -> (PathOutcome, PathOutcome) {
        let n = self.refractive_index;
        let Refraction::Transmitted { direction: t1, .. } = refract(d, &m1.normal, 1.0, n) else {
            // Impossible from air into n > 1; kept total rather than panicking.
            return (Err(Miss::NoConvergence), Err(Miss::NoConvergence));
        };
        let round_trip = |from: &Point3<f64>, dir: &Dir| -> Result<(SurfaceHit, Dir, f64), Miss> {
            let mb = self.hit(from, dir, true)?;
            let rb = reflectance(dir.dot(&mb.normal).abs(), n, 1.0);
            let up = reflect(dir, &mb.normal);
            let mf = self.hit(&mb.point, &up, false)?;
            Ok((mf, up, rb))
        };
        let leave = |mf: &SurfaceHit, up: &Dir, weight: f64| -> PathOutcome {
            match refract(up, &mf.normal, n, 1.0) {
                Refraction::Transmitted {
                    direction,
                    cos_incidence,
                    ..
                } => {
                    let t_out = 1.0 - reflectance(cos_incidence, n, 1.0);
                    let (u, v) = to_screen(screen, &mf.point, &direction)?;
                    Ok(ScreenHit {
                        u,
                        v,
                        weight: weight * t_out,
                    })
                }
                Refraction::TotalInternalReflection { .. } => Err(Miss::TotalInternalReflection),
            }
        };
        let (m3, up, rb2) = match round_trip(&m1.point, &t1) {
            Ok(x) => x,
            Err(e) => return (Err(e), Err(e)),
        };
        let back = leave(&m3, &up, t_in * rb2);
        // Second round trip: reflect internally at the front instead of leaving.
        let rf3 = reflectance(up.dot(&m3.normal).abs(), n, 1.0);
        let down = reflect(&up, &m3.normal);
        let third = round_trip(&m3.point, &down)
            .and_then(|(m5, up5, rb4)| leave(&m5, &up5, t_in * rb2 * rf3 * rb4));
        (back, third)
    }
}

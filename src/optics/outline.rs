//! The element's outline: the region over which its surfaces are reported.
//!
//! A station v1/v2 element is a disk (`aperture_radius_mm` about
//! `aperture_center_mm`). The proposal `docs/proposals/outline.md`
//! (station `mfd-station/3`) adds rectangles (sides, rotation, centred on
//! the aperture centre) and simple polygons (vertices in the element's
//! frame). The surfaces keep the Zernike basis on the disk that
//! circumscribes the outline (`aperture_radius_mm`, which must contain it);
//! every figure is taken over the outline itself, through the polynomials
//! orthonormal over it ([`orthonormal`]), and the tracer's rim follows the
//! outline ([`Outline::outside_by_mm`]).

mod geometry;
pub mod orthonormal;
pub mod quadrature;

pub use orthonormal::{Orthonormal, OutlineError};

/// The shape of the outline (the centre and the circumscribing radius are
/// the element's aperture centre and radius).
#[derive(Debug, Clone, PartialEq, Default)]
pub enum Shape {
    /// The aperture disk (station v1 and v2).
    #[default]
    Circle,
    /// A rectangle centred on the aperture centre.
    Rectangle {
        /// Side lengths `[a, b]`, mm: along x and y before the rotation.
        sides_mm: [f64; 2],
        /// Rotation about the centre, degrees from +x towards +y.
        rotation_deg: f64,
    },
    /// A simple polygon, vertices in the element's frame, mm (either
    /// orientation; closed implicitly).
    Polygon {
        /// The vertices, at least three.
        vertices_mm: Vec<[f64; 2]>,
    },
}

impl Shape {
    /// Whether this is the disk of station v1 and v2.
    pub fn is_circle(&self) -> bool {
        matches!(self, Shape::Circle)
    }

    /// The shape in words, for outputs.
    pub fn describe(&self) -> String {
        match self {
            Shape::Circle => "circle".into(),
            Shape::Rectangle {
                sides_mm: [a, b],
                rotation_deg,
            } => format!("rectangle {a} × {b} mm rotated {rotation_deg}°"),
            Shape::Polygon { vertices_mm } => format!("polygon of {} vertices", vertices_mm.len()),
        }
    }
}

/// An outline in place: its shape, the aperture centre and the
/// circumscribing radius (the Zernike disk).
#[derive(Debug, Clone, PartialEq)]
pub struct Outline {
    /// The shape.
    pub shape: Shape,
    /// The aperture centre `[x, y]`, mm (the rectangle's centre).
    pub centre_mm: [f64; 2],
    /// The Zernike disk's radius, mm (the whole disk for a circle).
    pub radius_mm: f64,
    /// The polygon's vertices, mm (`None` for the disk), kept for the
    /// tracer's inner loop.
    polygon: Option<Vec<[f64; 2]>>,
}

impl Outline {
    /// `shape` about `centre_mm` in the Zernike disk of `radius_mm`.
    pub fn new(shape: Shape, centre_mm: [f64; 2], radius_mm: f64) -> Self {
        let polygon = corners(&shape, centre_mm);
        Outline {
            shape,
            centre_mm,
            radius_mm,
            polygon,
        }
    }

    /// The disk of `radius_mm` about `centre_mm`.
    pub fn circle(centre_mm: [f64; 2], radius_mm: f64) -> Self {
        Self::new(Shape::Circle, centre_mm, radius_mm)
    }

    /// The polygon's vertices (a rectangle's four corners,
    /// counter-clockwise); `None` for the disk.
    pub fn vertices(&self) -> Option<&[[f64; 2]]> {
        self.polygon.as_deref()
    }

    /// Whether `(x, y)` (mm, element frame) lies in the outline (its
    /// boundary included).
    pub fn contains(&self, x: f64, y: f64) -> bool {
        self.outside_by_mm(x, y) <= 0.0
    }

    /// How far `(x, y)` lies outside the outline, mm (≤ 0 inside; for a
    /// polygon, 0 anywhere inside): the tracer's rim is where this exceeds
    /// the edge margin.
    pub fn outside_by_mm(&self, x: f64, y: f64) -> f64 {
        let [cx, cy] = self.centre_mm;
        match self.vertices() {
            None => (x - cx).hypot(y - cy) - self.radius_mm,
            Some(v) => geometry::outside_by(v, x, y),
        }
    }

    /// The largest distance of the outline from the centre, mm: the least
    /// Zernike radius that contains it.
    pub fn circumradius_mm(&self) -> f64 {
        let [cx, cy] = self.centre_mm;
        match self.vertices() {
            None => self.radius_mm,
            Some(v) => v
                .iter()
                .map(|p| (p[0] - cx).hypot(p[1] - cy))
                .fold(0.0, f64::max),
        }
    }

    /// The area, mm².
    pub fn area_mm2(&self) -> f64 {
        match self.vertices() {
            None => std::f64::consts::PI * self.radius_mm.powi(2),
            Some(v) => geometry::signed_area(v).abs(),
        }
    }

    /// The fraction of the Zernike disk the outline fills.
    pub fn fill_of_disk(&self) -> f64 {
        self.area_mm2() / (std::f64::consts::PI * self.radius_mm.powi(2))
    }

    /// The polynomials orthonormal over this outline built from `terms`
    /// Noll terms on its disk (see [`Orthonormal`]).
    ///
    /// # Errors
    /// [`OutlineError`] where the Gram matrix is not positive definite
    /// (an outline too thin for that many terms) or the basis is invalid.
    pub fn orthonormal(&self, terms: usize) -> Result<Orthonormal, OutlineError> {
        Orthonormal::new(self, terms)
    }

    /// The most terms up to `max` the outline supports: `max` itself, or
    /// the full radial orders below the first term that is dependent over
    /// it (at least the plane, 3 terms).
    ///
    /// # Errors
    /// [`OutlineError`] when not even the plane is independent over it.
    pub fn supported_terms(&self, max: usize) -> Result<usize, OutlineError> {
        let mut t = max;
        loop {
            match self.orthonormal(t) {
                Ok(_) => return Ok(t),
                // Near the edge of f64 the first dependent term moves with
                // the quadrature's size: try again with the orders below it.
                Err(OutlineError::TooNarrow { term, .. }) if term > 3 && t > 3 => {
                    t = (1..)
                        .map(crate::optics::zernike::terms_up_to_order)
                        .take_while(|&n| n < term.min(t))
                        .last()
                        .unwrap_or(3)
                        .max(3);
                }
                Err(e) => return Err(e),
            }
        }
    }
}

/// The corners of a rectangle (counter-clockwise) or a polygon's vertices.
fn corners(shape: &Shape, [cx, cy]: [f64; 2]) -> Option<Vec<[f64; 2]>> {
    match shape {
        Shape::Circle => None,
        Shape::Rectangle {
            sides_mm: [a, b],
            rotation_deg,
        } => {
            let (s, c) = rotation_deg.to_radians().sin_cos();
            let corner = |x: f64, y: f64| [cx + c * x - s * y, cy + s * x + c * y];
            let (h, k) = (a / 2.0, b / 2.0);
            Some(vec![
                corner(-h, -k),
                corner(h, -k),
                corner(h, k),
                corner(-h, k),
            ])
        }
        Shape::Polygon { vertices_mm } => Some(vertices_mm.clone()),
    }
}

/// Checks a polygon: at least three finite vertices, a non-zero area, and
/// no two edges crossing. `Err` says what is wrong.
pub fn check_polygon(vertices: &[[f64; 2]]) -> Result<(), String> {
    geometry::check(vertices)
}

#[cfg(test)]
mod tests;

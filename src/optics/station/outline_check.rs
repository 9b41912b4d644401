//! `[element.outline]` (proposal `mfd-station/3`, `docs/proposals/outline.md`)
//! read and checked, and written back.

use std::path::Path;

use super::file::{ElementFile, OutlineFile, STATION_FORMAT_V3};
use super::StationError;
use crate::optics::outline::{check_polygon, Outline, Shape};

fn fail<T>(path: &Path, field: &'static str, problem: String) -> Result<T, StationError> {
    Err(StationError::Invalid {
        path: path.to_path_buf(),
        field,
        problem,
    })
}

/// The element's shape from its file (`Circle` without a table), checked:
/// a rectangle's sides positive and finite and its rotation finite, a
/// polygon simple, the fields of the other shape absent, and the aperture
/// disk (`aperture_radius_mm` about `aperture_center_mm`, the Zernike
/// disk) containing the whole outline. `format` must be version 3 when a
/// table is given.
pub(super) fn shape(
    path: &Path,
    format: &str,
    e: &ElementFile,
    centre: [f64; 2],
) -> Result<Shape, StationError> {
    let Some(o) = &e.outline else {
        return Ok(Shape::Circle);
    };
    if format != STATION_FORMAT_V3 {
        return fail(
            path,
            "element.outline",
            format!(
                "an outline is a field of the proposal \"{STATION_FORMAT_V3}\" \
                 (docs/proposals/outline.md), not of \"{format}\": write format = \
                 \"{STATION_FORMAT_V3}\" to use it"
            ),
        );
    }
    let shape = match shape_of(o) {
        Ok(s) => s,
        Err((field, problem)) => {
            return fail(path, element_field(field), problem);
        }
    };
    let outline = Outline::new(shape.clone(), centre, e.aperture_radius_mm);
    let needed = outline.circumradius_mm();
    if needed > e.aperture_radius_mm * (1.0 + 1e-9) {
        return fail(
            path,
            "element.aperture_radius_mm",
            format!(
                "the outline reaches {needed} mm from aperture_center_mm, beyond the \
                 aperture disk of {} mm: with an outline, aperture_radius_mm is the \
                 Zernike disk and must contain it (set it to {needed} or more)",
                e.aperture_radius_mm
            ),
        );
    }
    Ok(shape)
}

/// The station's name of an outline field.
fn element_field(field: &'static str) -> &'static str {
    match field {
        "shape" => "element.outline.shape",
        "sides_mm" => "element.outline.sides_mm",
        "rotation_deg" => "element.outline.rotation_deg",
        _ => "element.outline.vertices_mm",
    }
}

/// The shape an outline table describes, checked; `Err((field, problem))`
/// names the table's field (`shape`, `sides_mm`, `rotation_deg`,
/// `vertices_mm`). Used by the station and by `surfaces.json` version 3.
pub fn shape_of(o: &OutlineFile) -> Result<Shape, (&'static str, String)> {
    match o.shape.as_str() {
        "rectangle" => rectangle(o),
        "polygon" => polygon(o),
        other => Err((
            "shape",
            format!("expected \"rectangle\" or \"polygon\", found \"{other}\""),
        )),
    }
}

fn rectangle(o: &OutlineFile) -> Result<Shape, (&'static str, String)> {
    if o.vertices_mm.is_some() {
        return Err((
            "vertices_mm",
            "a rectangle has sides_mm and rotation_deg, not vertices (use shape = \
             \"polygon\" for those)"
                .into(),
        ));
    }
    let Some(sides) = o.sides_mm else {
        return Err(("sides_mm", "a rectangle needs sides_mm = [a, b], mm".into()));
    };
    if !sides.iter().all(|s| s.is_finite() && *s > 0.0) {
        return Err((
            "sides_mm",
            format!("expected two finite sides > 0, mm, found {sides:?}"),
        ));
    }
    let rotation_deg = o.rotation_deg.unwrap_or(0.0);
    if !rotation_deg.is_finite() {
        return Err((
            "rotation_deg",
            format!("expected a finite angle in degrees, found {rotation_deg}"),
        ));
    }
    Ok(Shape::Rectangle {
        sides_mm: sides,
        rotation_deg,
    })
}

fn polygon(o: &OutlineFile) -> Result<Shape, (&'static str, String)> {
    if o.sides_mm.is_some() || o.rotation_deg.is_some() {
        let field = if o.sides_mm.is_some() {
            "sides_mm"
        } else {
            "rotation_deg"
        };
        return Err((
            field,
            "a polygon has vertices_mm only (use shape = \"rectangle\" for sides and a \
             rotation)"
                .into(),
        ));
    }
    let Some(v) = &o.vertices_mm else {
        return Err((
            "vertices_mm",
            "a polygon needs vertices_mm = [[x, y], ...], mm, element frame".into(),
        ));
    };
    if let Err(problem) = check_polygon(v) {
        return Err(("vertices_mm", problem));
    }
    Ok(Shape::Polygon {
        vertices_mm: v.clone(),
    })
}

/// The table of `shape` (none for the disk).
pub fn to_file(shape: &Shape) -> Option<OutlineFile> {
    match shape {
        Shape::Circle => None,
        Shape::Rectangle {
            sides_mm,
            rotation_deg,
        } => Some(OutlineFile {
            shape: "rectangle".into(),
            sides_mm: Some(*sides_mm),
            rotation_deg: Some(*rotation_deg),
            vertices_mm: None,
        }),
        Shape::Polygon { vertices_mm } => Some(OutlineFile {
            shape: "polygon".into(),
            sides_mm: None,
            rotation_deg: None,
            vertices_mm: Some(vertices_mm.clone()),
        }),
    }
}

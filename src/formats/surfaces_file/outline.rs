//! The proposal `mfd-surfaces/3` (`docs/proposals/outline.md`): version 2
//! plus the element's outline and, per surface, its coefficients in the
//! polynomials orthonormal over that outline. The orthonormal
//! coefficients follow from `coefficients_nm` and the outline, so the
//! writer computes them and the reader checks them against its own.

use std::path::Path;

use super::{invalid, RawFile, RawSurface, SurfaceEntry, SurfacesFile, SurfacesFileError};
use crate::optics::outline::{Outline, Shape};
use crate::optics::station::outline_check::{shape_of, to_file};

/// The format tag of the proposal (an outline other than the disk).
pub const SURFACES_FORMAT_V3: &str = "mfd-surfaces/3";

/// The name of the orthonormal set in `"orthonormal"`.
pub const ORTHONORMAL_NAME: &str = "zernike-gram-schmidt-over-outline";

/// The largest difference between a file's orthonormal coefficient and the
/// reader's, relative to the surface's largest coefficient (two exact
/// quadratures differ by rounding, ~1e-13; a wrong set by O(1)).
const AGREEMENT: f64 = 1e-6;

/// The outline of a version-3 file, checked; none in versions 1 and 2,
/// whose files may hold none of version 3's fields.
pub(super) fn check_file(raw: &RawFile, path: &Path) -> Result<Option<Shape>, SurfacesFileError> {
    let surfaces = [("front", &raw.front), ("back", &raw.back)];
    if raw.format != SURFACES_FORMAT_V3 {
        let not_here = |f: String| {
            invalid(
                path,
                &f,
                format!(
                    "not a field of {} (it is one of the proposal {SURFACES_FORMAT_V3}: \
                     write that format)",
                    raw.format
                ),
            )
        };
        if raw.outline.is_some() {
            return Err(not_here("outline".into()));
        }
        if raw.orthonormal.is_some() {
            return Err(not_here("orthonormal".into()));
        }
        for (name, s) in surfaces {
            if let Some(s) = s {
                if s.orthonormal_coefficients_nm.is_some() {
                    return Err(not_here(format!("{name}.orthonormal_coefficients_nm")));
                }
                if s.orthonormal_std_nm.is_some() {
                    return Err(not_here(format!("{name}.orthonormal_std_nm")));
                }
            }
        }
        return Ok(None);
    }
    let Some(o) = &raw.outline else {
        return Err(invalid(
            path,
            "outline",
            format!("missing: a {SURFACES_FORMAT_V3} file gives the element's outline"),
        ));
    };
    if raw.orthonormal.as_deref() != Some(ORTHONORMAL_NAME) {
        return Err(invalid(
            path,
            "orthonormal",
            format!(
                "expected \"{ORTHONORMAL_NAME}\", found {:?}",
                raw.orthonormal
            ),
        ));
    }
    let shape = shape_of(o).map_err(|(f, p)| invalid(path, &format!("outline.{f}"), p))?;
    let outline = Outline::new(shape.clone(), raw.zernike.center_mm, raw.zernike.radius_mm);
    let reach = outline.circumradius_mm();
    if reach > raw.zernike.radius_mm * (1.0 + 1e-9) {
        return Err(invalid(
            path,
            "outline",
            format!(
                "reaches {reach} mm from zernike.center_mm, beyond the Zernike disk of {} mm",
                raw.zernike.radius_mm
            ),
        ));
    }
    Ok(Some(shape))
}

/// Each reconstructed surface of a version-3 file: its orthonormal
/// coefficients given, as many as `coefficients_nm`, and equal to the
/// reader's; their σ, where given, as many, finite and ≥ 0.
pub(super) fn check_surfaces(
    raw: &RawFile,
    file: &SurfacesFile,
    path: &Path,
) -> Result<(), SurfacesFileError> {
    if file.outline.is_none() {
        return Ok(());
    }
    let outline = file.outline_in_place();
    for (name, s, e) in [
        ("front", &raw.front, &file.front),
        ("back", &raw.back, &file.back),
    ] {
        let (Some(s), Some(c)) = (s, e.coefficients()) else {
            continue;
        };
        let field = |f: &str| format!("{name}.{f}");
        let n = c.coefficients_nm.len();
        let Some(given) = &s.orthonormal_coefficients_nm else {
            return Err(invalid(
                path,
                &field("orthonormal_coefficients_nm"),
                "missing: each reconstructed surface gives its orthonormal coefficients".into(),
            ));
        };
        if given.len() != n {
            return Err(invalid(
                path,
                &field("orthonormal_coefficients_nm"),
                format!("{} values for {n} coefficients_nm", given.len()),
            ));
        }
        let q = outline
            .orthonormal(n)
            .map_err(|e| invalid(path, "outline", e.to_string()))?;
        let ours = q.coefficients(&c.coefficients_nm);
        let scale = ours.iter().fold(1.0f64, |m, a| m.max(a.abs()));
        // NaN disagrees too.
        let agrees = |k: usize| (given[k] - ours[k]).abs() <= AGREEMENT * scale;
        if let Some(k) = (0..n).find(|&k| !agrees(k)) {
            return Err(invalid(
                path,
                &format!("{name}.orthonormal_coefficients_nm[{k}]"),
                format!(
                    "{} where coefficients_nm over this outline give {}: not the set \
                     \"{ORTHONORMAL_NAME}\" of this outline",
                    given[k], ours[k]
                ),
            ));
        }
        if let Some(std) = &s.orthonormal_std_nm {
            if std.len() != n {
                return Err(invalid(
                    path,
                    &field("orthonormal_std_nm"),
                    format!("{} values for {n} coefficients_nm", std.len()),
                ));
            }
            if let Some(k) = std.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
                return Err(invalid(
                    path,
                    &format!("{name}.orthonormal_std_nm[{k}]"),
                    format!("expected a finite σ ≥ 0, found {}", std[k]),
                ));
            }
        }
    }
    Ok(())
}

/// Version 3's fields of `raw` from `file` (nothing for other versions).
pub(super) fn fill_raw(
    file: &SurfacesFile,
    raw: &mut RawFile,
    path: &Path,
) -> Result<(), SurfacesFileError> {
    let Some(shape) = &file.outline else {
        return Ok(());
    };
    raw.outline = to_file(shape);
    raw.orthonormal = Some(ORTHONORMAL_NAME.into());
    let outline = file.outline_in_place();
    let fill = |r: &mut Option<RawSurface>, e: &SurfaceEntry| -> Result<(), SurfacesFileError> {
        if let (Some(r), Some(c)) = (r.as_mut(), e.coefficients()) {
            let q = outline
                .orthonormal(c.coefficients_nm.len())
                .map_err(|e| invalid(path, "outline", e.to_string()))?;
            r.orthonormal_coefficients_nm = Some(q.coefficients(&c.coefficients_nm));
        }
        Ok(())
    };
    fill(&mut raw.front, &file.front)?;
    fill(&mut raw.back, &file.back)
}

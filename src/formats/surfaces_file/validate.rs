//! The reader's checks of `surfaces.json`: the `zernike` block, each
//! surface against its version's rules, and the numbers of a reconstructed
//! surface; every failure names the file and the field.

use std::path::Path;

use super::{
    invalid, RawSurface, SurfaceCoefficients, SurfaceEntry, SurfacesFileError, ZernikeSpec,
    SURFACES_FORMAT, SURFACES_FORMAT_V2,
};
use crate::optics::zernike::{MAX_RADIAL_ORDER, MAX_TERMS};

/// The `zernike` block: Noll order, RMS normalisation, a finite radius
/// > 0 and a finite centre.
pub(super) fn check_zernike(z: &ZernikeSpec, path: &Path) -> Result<(), SurfacesFileError> {
    if z.ordering != "noll" {
        let problem = format!("expected \"noll\", found \"{}\"", z.ordering);
        return Err(invalid(path, "zernike.ordering", problem));
    }
    if z.normalization != "rms" {
        let problem = format!("expected \"rms\", found \"{}\"", z.normalization);
        return Err(invalid(path, "zernike.normalization", problem));
    }
    if !(z.radius_mm.is_finite() && z.radius_mm > 0.0) {
        let problem = format!("expected a finite radius > 0, found {}", z.radius_mm);
        return Err(invalid(path, "zernike.radius_mm", problem));
    }
    if !z.center_mm.iter().all(|c| c.is_finite()) {
        let problem = format!("expected finite numbers, found {:?}", z.center_mm);
        return Err(invalid(path, "zernike.center_mm", problem));
    }
    Ok(())
}

/// One surface of the JSON checked against its version's rules.
pub(super) fn entry(
    raw: Option<RawSurface>,
    name: &str,
    v2: bool,
    path: &Path,
) -> Result<SurfaceEntry, SurfacesFileError> {
    let Some(raw) = raw else {
        return Ok(SurfaceEntry::NotReconstructed { because: None });
    };
    let field = |f: &str| format!("{name}.{f}");
    if !v2 {
        no_v2_fields(&raw, name, path)?;
    }
    let because = raw.not_reconstructed_because.flatten();
    match raw.coefficients_nm {
        None => Err(invalid(
            path,
            &field("coefficients_nm"),
            "missing: a surface is `null` or has `coefficients_nm`".into(),
        )),
        Some(None) if !v2 => Err(invalid(
            path,
            &field("coefficients_nm"),
            format!("null: in {SURFACES_FORMAT} a surface not reconstructed is `null` as a whole"),
        )),
        Some(None) => not_reconstructed(
            because,
            raw.std_nm.is_some(),
            raw.expected_error_rms_nm.is_some(),
            name,
            path,
        ),
        Some(Some(coefficients_nm)) => {
            if let Some(b) = because {
                let problem = format!("\"{b}\" given for a surface that has coefficients");
                return Err(invalid(path, &field("not_reconstructed_because"), problem));
            }
            let c = SurfaceCoefficients {
                coefficients_nm,
                std_nm: raw.std_nm,
                expected_error_rms_nm: raw.expected_error_rms_nm,
                orthonormal_std_nm: raw.orthonormal_std_nm,
            };
            check_numbers(&c, name, path)?;
            Ok(SurfaceEntry::Reconstructed(c))
        }
    }
}

/// A version-1 surface holds none of version 2's fields.
fn no_v2_fields(raw: &RawSurface, name: &str, path: &Path) -> Result<(), SurfacesFileError> {
    let only_v2 = |f: &str| {
        invalid(
            path,
            &format!("{name}.{f}"),
            format!("not a field of {SURFACES_FORMAT} (it is one of {SURFACES_FORMAT_V2}: write that format)"),
        )
    };
    if raw.std_nm.is_some() {
        return Err(only_v2("std_nm"));
    }
    if raw.expected_error_rms_nm.is_some() {
        return Err(only_v2("expected_error_rms_nm"));
    }
    if raw.not_reconstructed_because.is_some() {
        return Err(only_v2("not_reconstructed_because"));
    }
    Ok(())
}

/// A version-2 surface with `"coefficients_nm": null`: it says why (not
/// blank), and gives no σ or expected error.
fn not_reconstructed(
    because: Option<String>,
    has_std: bool,
    has_expected: bool,
    name: &str,
    path: &Path,
) -> Result<SurfaceEntry, SurfacesFileError> {
    let field = |f: &str| format!("{name}.{f}");
    let Some(because) = because.filter(|b| !b.trim().is_empty()) else {
        let problem = "null without `not_reconstructed_because`: say why the surface \
                       was not reconstructed";
        return Err(invalid(
            path,
            &field("not_reconstructed_because"),
            problem.into(),
        ));
    };
    for (f, set) in [("std_nm", has_std), ("expected_error_rms_nm", has_expected)] {
        if set {
            let problem = "given for a surface that was not reconstructed".into();
            return Err(invalid(path, &field(f), problem));
        }
    }
    Ok(SurfaceEntry::NotReconstructed {
        because: Some(because),
    })
}

/// Coefficients finite and at least one; σ finite, ≥ 0 and one per
/// coefficient; the expected error finite and ≥ 0.
fn check_numbers(
    c: &SurfaceCoefficients,
    name: &str,
    path: &Path,
) -> Result<(), SurfacesFileError> {
    let n = c.coefficients_nm.len();
    if n == 0 || n > MAX_TERMS {
        let field = format!("{name}.coefficients_nm");
        return Err(invalid(
            path,
            &field,
            format!(
                "{n} coefficients: expected 1 to {MAX_TERMS} (every Noll term up to radial \
                 order {MAX_RADIAL_ORDER})"
            ),
        ));
    }
    if let Some((k, v)) = c
        .coefficients_nm
        .iter()
        .enumerate()
        .find(|(_, v)| !v.is_finite())
    {
        let field = format!("{name}.coefficients_nm[{k}]");
        return Err(invalid(
            path,
            &field,
            format!("expected a finite number, found {v}"),
        ));
    }
    if let Some(std) = &c.std_nm {
        if std.len() != n {
            let field = format!("{name}.std_nm");
            let problem = format!(
                "{} entries where `coefficients_nm` has {n}: one σ per coefficient",
                std.len()
            );
            return Err(invalid(path, &field, problem));
        }
        if let Some((k, s)) = std
            .iter()
            .enumerate()
            .find(|(_, s)| !(s.is_finite() && **s >= 0.0))
        {
            let field = format!("{name}.std_nm[{k}]");
            return Err(invalid(
                path,
                &field,
                format!("expected a finite σ ≥ 0, found {s}"),
            ));
        }
    }
    if let Some(e) = c.expected_error_rms_nm {
        if !(e.is_finite() && e >= 0.0) {
            let field = format!("{name}.expected_error_rms_nm");
            return Err(invalid(
                path,
                &field,
                format!("expected a finite RMS ≥ 0, found {e}"),
            ));
        }
    }
    Ok(())
}

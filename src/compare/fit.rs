//! The comparison itself: the map's points on the measured aperture, the
//! same Zernike terms fitted to them, the difference point by point with
//! piston and tilt removed, and both coefficient sets term by term with
//! mfd's σ.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::register::{best_turn, place, Registration, RegistrationOptions};
use super::{CompareError, InterferometerMap};
use crate::formats::surfaces_file::SurfacesFile;
use crate::optics::zernike::{fit_heights, ZernikeBasis, ZernikeSurface};
use crate::solve::surfaces::report::REMOVED_TERMS;

/// The `format` of the comparison's JSON.
pub const COMPARISON_FORMAT: &str = "mfd-comparison/1";

/// The least share of the aperture's area the map must cover: below half,
/// the terms fitted over the part that is there no longer describe the
/// aperture the coefficients are defined on.
pub const MIN_COVERAGE: f64 = 0.5;

/// Side of the square world grid of the comparison's pictures.
pub const MAP_GRID: usize = 201;

/// One Zernike term in both.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TermComparison {
    /// Noll index.
    pub noll: usize,
    /// mfd's coefficient, nm.
    pub mfd_nm: f64,
    /// Its 1σ, nm, when `surfaces.json` gives one.
    pub mfd_std_nm: Option<f64>,
    /// The interferometer map's coefficient, nm.
    pub interferometer_nm: f64,
    /// mfd − interferometer, nm.
    pub difference_nm: f64,
    /// The difference over mfd's σ (`None` for piston and tilt, which are
    /// alignment).
    pub difference_over_sigma: Option<f64>,
}

/// The pictures' grids: `n × n` over the aperture's bounding square, row
/// 0 at `+y`, NaN outside the aperture or where the map has no data;
/// piston and tilt removed.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ComparisonMaps {
    /// Side of the grid.
    pub n: usize,
    /// `[x_min, x_max, y_min, y_max]`, mm.
    pub extent_mm: [f64; 4],
    /// mfd's surface, nm.
    pub mfd_nm: Vec<f64>,
    /// The interferometer's map, nm (nearest map pixel).
    pub interferometer_nm: Vec<f64>,
    /// mfd − interferometer, nm.
    pub difference_nm: Vec<f64>,
}

/// A comparison of one mfd surface with an interferometer map.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Comparison {
    /// [`COMPARISON_FORMAT`].
    pub format: String,
    /// The map's file.
    pub interferometer: String,
    /// Which reader read it.
    pub interferometer_format: String,
    /// The instrument's wavelength, nm, when the file says it.
    pub wavelength_nm: Option<f64>,
    /// The surfaces file.
    pub surfaces: String,
    /// `front` or `back`.
    pub surface: String,
    /// Where the map lies on the aperture.
    pub registration: Registration,
    /// The aperture radius the terms are defined on, mm.
    pub aperture_radius_mm: f64,
    /// Map pixels on the aperture.
    pub points: usize,
    /// Their share of the aperture's area.
    pub coverage: f64,
    /// Every term, Noll j = 1 … n.
    pub terms: Vec<TermComparison>,
    /// RMS of mfd − interferometer over the map's pixels on the aperture,
    /// piston and tilt removed, nm.
    pub difference_rms_nm: f64,
    /// The same from the coefficients: √Σ_{j≥4} (difference)², nm (leaves
    /// out the map's content beyond the fitted terms).
    pub difference_coefficients_rms_nm: f64,
    /// mfd's expected RMS error (piston and tilt removed), nm, when known:
    /// the difference expected if the interferometer were exact.
    pub mfd_expected_error_rms_nm: Option<f64>,
    /// RMS of the map beyond the fitted terms (its fit residual), nm.
    pub interferometer_beyond_terms_rms_nm: f64,
    /// The pictures' grids (not in the JSON).
    #[serde(skip)]
    pub maps: ComparisonMaps,
}

/// Compares `surface` (`front` or `back`) of `surfaces` (read from
/// `surfaces_path`) with `map`.
///
/// # Errors
/// [`CompareError::NoSurface`] when that surface is absent;
/// [`CompareError::Coverage`] when the map covers less than
/// [`MIN_COVERAGE`] of the aperture; [`CompareError::Fit`] when the fit fails.
pub fn compare(
    map: &InterferometerMap,
    surfaces: &SurfacesFile,
    surfaces_path: &Path,
    surface: &str,
    options: &RegistrationOptions,
) -> Result<Comparison, CompareError> {
    let entry = if surface == "back" {
        &surfaces.back
    } else {
        &surfaces.front
    };
    let Some(ours) = entry.coefficients() else {
        return Err(CompareError::NoSurface {
            path: surfaces_path.to_path_buf(),
            surface: surface.into(),
        });
    };
    let z = &surfaces.zernike;
    let fit_err = |source| CompareError::Fit {
        path: map.path.clone(),
        source,
    };
    let basis =
        ZernikeBasis::new(ours.coefficients_nm.len(), z.radius_mm, z.center_mm).map_err(fit_err)?;
    let mut reg = place(map, options, z.radius_mm, z.center_mm)?;
    let (offsets, heights) = on_aperture(map, &reg, z.radius_mm);
    let coverage =
        offsets.len() as f64 * reg.pixel_mm.powi(2) / (std::f64::consts::PI * z.radius_mm.powi(2));
    if coverage < MIN_COVERAGE || offsets.len() < basis.n_terms() {
        return Err(CompareError::Coverage {
            path: map.path.clone(),
            points: offsets.len(),
            fraction: coverage,
        });
    }
    let fit_at = |reg: &Registration| {
        let (xs, ys): (Vec<f64>, Vec<f64>) =
            offsets.iter().map(|o| reg.world_of_offset(*o)).unzip();
        let h_mm: Vec<f64> = heights.iter().map(|h| h * 1e-6).collect();
        fit_heights(&basis, &xs, &ys, &h_mm, None).map(|f| (f, xs, ys))
    };
    if options.rotation_deg.is_none() || options.flip.is_none() {
        let (plain, _, _) = fit_at(&reg).map_err(fit_err)?;
        let (theta, flip) = best_turn(
            &plain.coefficients_nm,
            &ours.coefficients_nm,
            ours.std_nm.as_deref(),
            options.rotation_deg,
            options.flip,
        );
        reg.rotation_deg = theta;
        reg.flip = flip;
        for (given, name) in [
            (options.rotation_deg.is_some(), "rotation_deg"),
            (options.flip.is_some(), "flip"),
        ] {
            if !given {
                reg.fitted.push(name.into());
            }
        }
    } else {
        reg.rotation_deg = options.rotation_deg.unwrap_or(0.0);
        reg.flip = options.flip.unwrap_or(false);
    }
    let (fit, xs, ys) = fit_at(&reg).map_err(fit_err)?;
    let mfd = ZernikeSurface::new(basis.clone(), ours.coefficients_nm.clone()).map_err(fit_err)?;
    let theirs =
        ZernikeSurface::new(basis.clone(), fit.coefficients_nm.clone()).map_err(fit_err)?;
    let diff: Vec<f64> = (0..xs.len())
        .map(|i| mfd.height_mm(xs[i], ys[i]) * 1e6 - heights[i])
        .collect();
    let (diff_rms, diff_tilt) =
        without_tilt(&xs, &ys, &diff, z.radius_mm, z.center_mm).map_err(fit_err)?;
    let beyond = rms((0..xs.len()).map(|i| heights[i] - theirs.height_mm(xs[i], ys[i]) * 1e6));
    let terms = term_rows(
        &ours.coefficients_nm,
        ours.std_nm.as_deref(),
        &fit.coefficients_nm,
    );
    let coeff_rms = terms
        .iter()
        .skip(REMOVED_TERMS)
        .map(|t| t.difference_nm.powi(2))
        .sum::<f64>()
        .sqrt();
    let maps = grids(map, &reg, &mfd, &theirs, &diff_tilt);
    Ok(Comparison {
        format: COMPARISON_FORMAT.into(),
        interferometer: map.path.display().to_string(),
        interferometer_format: map.format.into(),
        wavelength_nm: map.wavelength_nm,
        surfaces: surfaces_path.display().to_string(),
        surface: surface.into(),
        registration: reg,
        aperture_radius_mm: z.radius_mm,
        points: xs.len(),
        coverage,
        terms,
        difference_rms_nm: diff_rms,
        difference_coefficients_rms_nm: coeff_rms,
        mfd_expected_error_rms_nm: ours.expected_error_rms_nm,
        interferometer_beyond_terms_rms_nm: beyond,
        maps,
    })
}

/// Offsets (mm, before flip and rotation) and heights (nm) of the map's
/// valid pixels within `radius_mm` of the aperture centre.
fn on_aperture(
    map: &InterferometerMap,
    reg: &Registration,
    radius_mm: f64,
) -> (Vec<(f64, f64)>, Vec<f64>) {
    let mut offsets = Vec::new();
    let mut heights = Vec::new();
    for (k, h) in map.heights_nm.iter().enumerate() {
        if !h.is_finite() {
            continue;
        }
        let o = reg.offset_mm(k % map.width, k / map.width);
        if o.0.hypot(o.1) <= radius_mm {
            offsets.push(o);
            heights.push(*h);
        }
    }
    (offsets, heights)
}

fn rms(values: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v * v, n + 1));
    if n == 0 {
        f64::NAN
    } else {
        (s / n as f64).sqrt()
    }
}

/// RMS of `values` (nm) at `(xs, ys)` after removing their least-squares
/// piston and tilt, and that piston and tilt as a surface.
fn without_tilt(
    xs: &[f64],
    ys: &[f64],
    values: &[f64],
    radius_mm: f64,
    center_mm: [f64; 2],
) -> Result<(f64, ZernikeSurface), crate::optics::zernike::ZernikeError> {
    let basis = ZernikeBasis::new(REMOVED_TERMS, radius_mm, center_mm)?;
    let mm: Vec<f64> = values.iter().map(|v| v * 1e-6).collect();
    let fit = fit_heights(&basis, xs, ys, &mm, None)?;
    let tilt = ZernikeSurface::new(basis, fit.coefficients_nm)?;
    let r = rms((0..xs.len()).map(|i| values[i] - tilt.height_mm(xs[i], ys[i]) * 1e6));
    Ok((r, tilt))
}

fn term_rows(ours: &[f64], std: Option<&[f64]>, theirs: &[f64]) -> Vec<TermComparison> {
    (0..ours.len())
        .map(|k| {
            let s = std.and_then(|s| s.get(k)).copied();
            let d = ours[k] - theirs[k];
            TermComparison {
                noll: k + 1,
                mfd_nm: ours[k],
                mfd_std_nm: s,
                interferometer_nm: theirs[k],
                difference_nm: d,
                // Piston and tilt are the instruments' alignment, not the
                // surface: their difference is shown, never weighed.
                difference_over_sigma: s.filter(|s| *s > 0.0 && k >= REMOVED_TERMS).map(|s| d / s),
            }
        })
        .collect()
}

/// The pictures' grids (see [`ComparisonMaps`]).
fn grids(
    map: &InterferometerMap,
    reg: &Registration,
    mfd: &ZernikeSurface,
    theirs: &ZernikeSurface,
    diff_tilt: &ZernikeSurface,
) -> ComparisonMaps {
    let (r, [cx, cy]) = (mfd.basis().radius_mm(), mfd.basis().center_mm());
    let n = MAP_GRID;
    let step = 2.0 * r / n as f64;
    let tilt_of = |s: &ZernikeSurface, x: f64, y: f64| {
        let c = s.coefficients_nm();
        let b = s.basis();
        let mut v = vec![0.0; b.n_terms()];
        let _ = b.eval_values_into(x, y, &mut v);
        (0..REMOVED_TERMS.min(c.len()))
            .map(|k| c[k] * v[k])
            .sum::<f64>()
    };
    let mut out = ComparisonMaps {
        n,
        extent_mm: [cx - r, cx + r, cy - r, cy + r],
        ..ComparisonMaps::default()
    };
    for row in 0..n {
        let y = cy + r - (row as f64 + 0.5) * step;
        for col in 0..n {
            let x = cx - r + (col as f64 + 0.5) * step;
            let (mut a, mut b, mut d) = (f64::NAN, f64::NAN, f64::NAN);
            if (x - cx).hypot(y - cy) <= r {
                let ours = mfd.height_mm(x, y) * 1e6;
                a = ours - tilt_of(mfd, x, y);
                let (c, rr) = reg.map_px(x, y);
                let (c, rr) = (c.floor(), rr.floor());
                if c >= 0.0 && rr >= 0.0 && (c as usize) < map.width && (rr as usize) < map.height {
                    let h = map.heights_nm[rr as usize * map.width + c as usize];
                    if h.is_finite() {
                        b = h - tilt_of(theirs, x, y);
                        d = ours - h - diff_tilt.height_mm(x, y) * 1e6;
                    }
                }
            }
            out.mfd_nm.push(a);
            out.interferometer_nm.push(b);
            out.difference_nm.push(d);
        }
    }
    out
}

impl Comparison {
    /// The comparison in sentences, for the terminal and the report.
    pub fn describe(&self) -> Vec<String> {
        let r = &self.registration;
        let mut lines = vec![
            format!(
                "{} ({}) against the {} surface of {}",
                self.interferometer, self.interferometer_format, self.surface, self.surfaces
            ),
            format!(
                "registration: aperture centre at map pixel ({:.2}, {:.2}), pixel {:.5} mm, \
                 rotation {:.2}°, {}; fitted: {}",
                r.center_px[0],
                r.center_px[1],
                r.pixel_mm,
                r.rotation_deg,
                if r.flip { "flipped" } else { "not flipped" },
                if r.fitted.is_empty() {
                    "nothing".to_string()
                } else {
                    r.fitted.join(", ")
                }
            ),
            format!(
                "{} map pixels on the aperture of radius {} mm ({:.1} % of its area); the map \
                 beyond the {} fitted terms: {:.3} nm RMS",
                self.points,
                self.aperture_radius_mm,
                100.0 * self.coverage,
                self.terms.len(),
                self.interferometer_beyond_terms_rms_nm
            ),
        ];
        let expected = self.mfd_expected_error_rms_nm.map_or(String::new(), |e| {
            format!("; mfd's expected error {e:.3} nm RMS")
        });
        lines.push(format!(
            "difference mfd − interferometer: {:.3} nm RMS over the map's pixels, {:.3} nm RMS \
             from the coefficients (piston and tilt removed){expected}",
            self.difference_rms_nm, self.difference_coefficients_rms_nm
        ));
        lines
    }

    /// The table's rows: Noll j, mfd, σ, interferometer, difference, /σ.
    pub fn table_rows(&self) -> Vec<Vec<String>> {
        let opt = |v: Option<f64>, p: usize| v.map_or("–".to_string(), |x| format!("{x:.p$}"));
        self.terms
            .iter()
            .map(|t| {
                vec![
                    t.noll.to_string(),
                    format!("{:.3}", t.mfd_nm),
                    opt(t.mfd_std_nm, 3),
                    format!("{:.3}", t.interferometer_nm),
                    format!("{:.3}", t.difference_nm),
                    opt(t.difference_over_sigma, 2),
                ]
            })
            .collect()
    }
}

//! A display's measured response curve: emitted luminance at a table of
//! drive levels (a display profile's `response = [[level, luminance], …]`),
//! checked monotone and interpolated by the monotone cubic of Fritsch and
//! Carlson (1980).
//!
//! Why that interpolant: a display's response is smooth, and a table has
//! 9–33 rows. Piecewise-linear interpolation puts a kink at every row,
//! whose error `h² L''/8` between rows (3e-4 of full scale at 17 rows on a
//! γ 2.2 curve) goes into every harmonic the decode models; a free cubic
//! spline is smoother but may overshoot and fall between the rows of a
//! noisy measurement, which no display does. Fritsch–Carlson is C¹, never
//! leaves the rows' monotone order, and is third order on smooth data.

use std::path::{Path, PathBuf};

use crate::optics::station::{DisplayProfile, StationError};

/// Why a display profile's response could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ProfileResponseError {
    /// The profile itself (names the file and field).
    #[error(transparent)]
    Profile(#[from] StationError),
    /// Its `response` table.
    #[error("{}: `response` {source}", path.display())]
    Curve {
        /// The profile.
        path: PathBuf,
        /// The row at fault.
        #[source]
        source: CurveError,
    },
}

impl crate::outcome::Classify for ProfileResponseError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        match self {
            ProfileResponseError::Profile(e) => e.outcome(),
            ProfileResponseError::Curve { .. } => Some(Outcome::Input),
        }
    }
}

/// A display profile (`hw/display/*.toml`) and its measured response,
/// where it has one.
///
/// # Errors
/// [`ProfileResponseError`] naming the file, and the row of a table that
/// is not monotone.
pub fn profile_response(
    path: &Path,
) -> Result<(DisplayProfile, Option<ResponseCurve>), ProfileResponseError> {
    let profile = DisplayProfile::load(path)?;
    let curve = match &profile.response {
        None => None,
        Some(rows) => {
            let rows: Vec<[f64; 2]> = rows.iter().map(|r| [r[0], r[1]]).collect();
            let curve =
                ResponseCurve::new(&rows).map_err(|source| ProfileResponseError::Curve {
                    path: path.to_path_buf(),
                    source,
                })?;
            Some(curve)
        }
    };
    Ok((profile, curve))
}

/// Why a response table was refused: the row (0-based) and the problem,
/// in the operator's words.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("row {row}: {problem}")]
pub struct CurveError {
    /// The table's row, 0-based.
    pub row: usize,
    /// What is wrong and what to do.
    pub problem: String,
}

impl crate::outcome::Classify for CurveError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        // A row of a display profile's `response` table.
        Some(Outcome::Input)
    }
}

/// A validated response: levels normalised to `[0, 1]` (the last row is
/// full drive), luminance normalised to the last row's, and the
/// interpolant's tangents.
#[derive(Debug, Clone, PartialEq)]
pub struct ResponseCurve {
    /// Drive level, fraction of full scale, strictly increasing from 0 to 1.
    pub level: Vec<f64>,
    /// Luminance, fraction of full drive's, non-decreasing.
    pub luminance: Vec<f64>,
    /// Fritsch–Carlson tangents `dL/dlevel` at the rows.
    tangent: Vec<f64>,
}

/// The fewest rows: black, one level between, full drive.
pub const MIN_ROWS: usize = 3;

impl ResponseCurve {
    /// A curve from `[level, luminance]` rows: levels in any unit (drive
    /// counts, or a fraction), strictly increasing from 0 to full drive;
    /// luminance in any unit (cd/m²), finite, ≥ 0, non-decreasing, the last
    /// above the first. Only the curve's shape matters.
    ///
    /// # Errors
    /// [`CurveError`] naming the first row at fault.
    pub fn new(rows: &[[f64; 2]]) -> Result<Self, CurveError> {
        let bad = |row, problem: String| Err(CurveError { row, problem });
        if rows.len() < MIN_ROWS {
            return bad(
                rows.len(),
                format!(
                    "{} rows, at least {MIN_ROWS} needed: measure black, full drive and levels \
                     between (17 or more for a decode at its bound)",
                    rows.len()
                ),
            );
        }
        for (k, [l, y]) in rows.iter().enumerate() {
            if !(l.is_finite() && y.is_finite() && *l >= 0.0 && *y >= 0.0) {
                return bad(
                    k,
                    format!("[{l}, {y}]: expected a finite level and luminance, both ≥ 0"),
                );
            }
        }
        if rows[0][0] != 0.0 {
            return bad(
                0,
                format!(
                    "the first level is {}: the table starts at black (level 0), which the \
                     fringes' dark half shows",
                    rows[0][0]
                ),
            );
        }
        for k in 1..rows.len() {
            let ([l0, y0], [l1, y1]) = (rows[k - 1], rows[k]);
            if l1 <= l0 {
                return bad(
                    k,
                    format!(
                        "level {l1} after {l0}: list the levels in increasing order, once each"
                    ),
                );
            }
            if y1 < y0 {
                return bad(
                    k,
                    format!(
                        "luminance {y1} at level {l1} is below {y0} at level {l0}: a display's \
                         luminance does not fall as its level rises; measure the row again"
                    ),
                );
            }
        }
        let last = rows.len() - 1;
        let (full_level, full) = (rows[last][0], rows[last][1]);
        if full <= rows[0][1] {
            return bad(
                last,
                format!(
                    "full drive's luminance {full} is not above black's {}: no fringe could show",
                    rows[0][1]
                ),
            );
        }
        let level: Vec<f64> = rows.iter().map(|r| r[0] / full_level).collect();
        let luminance: Vec<f64> = rows.iter().map(|r| r[1] / full).collect();
        let tangent = fritsch_carlson(&level, &luminance);
        Ok(ResponseCurve {
            level,
            luminance,
            tangent,
        })
    }

    /// Luminance at drive level `g` (fraction of full scale, clamped to
    /// `[0, 1]`), fraction of full drive's.
    pub fn at(&self, g: f64) -> f64 {
        let g = g.clamp(0.0, 1.0);
        let k = self
            .level
            .partition_point(|&l| l <= g)
            .clamp(1, self.level.len() - 1)
            - 1;
        let (x0, x1) = (self.level[k], self.level[k + 1]);
        let h = x1 - x0;
        let t = (g - x0) / h;
        let (t2, t3) = (t * t, t * t * t);
        let (y0, y1) = (self.luminance[k], self.luminance[k + 1]);
        let (m0, m1) = (self.tangent[k], self.tangent[k + 1]);
        (2.0 * t3 - 3.0 * t2 + 1.0) * y0
            + (t3 - 2.0 * t2 + t) * h * m0
            + (-2.0 * t3 + 3.0 * t2) * y1
            + (t3 - t2) * h * m1
    }
}

/// Tangents of the monotone cubic Hermite interpolant (Fritsch & Carlson,
/// SIAM J. Numer. Anal. 17 (1980) 238): three-point estimates (the mean
/// of the secants inside, the one-sided three-point formula at the ends,
/// kept of the end secant's sign), zero on a flat segment, scaled into the
/// circle of radius 3 where they would let the cubic overshoot. The ends
/// matter: the end secant as tangent is first order only, and on γ 2.2 at
/// 17 rows leaves 7.6e-4 of full scale in the last interval, where the
/// three-point formula leaves 2.6e-5.
fn fritsch_carlson(x: &[f64], y: &[f64]) -> Vec<f64> {
    let n = x.len();
    let h: Vec<f64> = (0..n - 1).map(|k| x[k + 1] - x[k]).collect();
    let secant: Vec<f64> = (0..n - 1).map(|k| (y[k + 1] - y[k]) / h[k]).collect();
    let end = |h0: f64, h1: f64, d0: f64, d1: f64| {
        let e = ((2.0 * h0 + h1) * d0 - h0 * d1) / (h0 + h1);
        if e * d0 <= 0.0 {
            0.0
        } else if d0 * d1 < 0.0 && e.abs() > 3.0 * d0.abs() {
            3.0 * d0
        } else {
            e
        }
    };
    let mut m = vec![0.0; n];
    m[0] = end(h[0], h[1], secant[0], secant[1]);
    m[n - 1] = end(h[n - 2], h[n - 3], secant[n - 2], secant[n - 3]);
    for k in 1..n - 1 {
        m[k] = if secant[k - 1] * secant[k] <= 0.0 {
            0.0
        } else {
            0.5 * (secant[k - 1] + secant[k])
        };
    }
    for k in 0..n - 1 {
        let d = secant[k];
        if d == 0.0 {
            m[k] = 0.0;
            m[k + 1] = 0.0;
            continue;
        }
        let (a, b) = (m[k] / d, m[k + 1] / d);
        let r = a.hypot(b);
        if r > 3.0 {
            m[k] = 3.0 * a / r * d;
            m[k + 1] = 3.0 * b / r * d;
        }
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(f: impl Fn(f64) -> f64, rows: usize) -> Vec<[f64; 2]> {
        (0..rows)
            .map(|k| {
                let g = k as f64 / (rows - 1) as f64;
                [255.0 * g, 180.0 * f(g)]
            })
            .collect()
    }

    #[test]
    fn the_interpolant_passes_the_rows_and_follows_a_smooth_curve() {
        let f = |g: f64| g.powf(2.2);
        let c = ResponseCurve::new(&table(f, 17)).unwrap();
        for (l, y) in c.level.iter().zip(&c.luminance) {
            assert!((c.at(*l) - y).abs() < 1e-15);
        }
        // Between rows (h = 1/16): piecewise linear errs by up to
        // h² max L''/8 = 2.2 · 1.2 / (8 · 256) = 1.3e-3 (at g = 1); the
        // reason for a cubic is to do an order better, so a tenth of that
        // is the bound (its third-order error is ~3e-5 here).
        let worst = (0..=1000)
            .map(|k| k as f64 / 1000.0)
            .map(|g| (c.at(g) - f(g)).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1.3e-4, "{worst}");
    }

    #[test]
    fn the_interpolant_is_monotone_on_a_table_with_a_plateau() {
        // A curve that rises steeply, then is flat: a free cubic would
        // overshoot the plateau; Fritsch–Carlson never does.
        let rows = [[0.0, 0.0], [0.2, 0.0], [0.4, 0.9], [0.6, 1.0], [1.0, 1.0]];
        let c = ResponseCurve::new(&rows).unwrap();
        let mut prev = 0.0;
        for k in 0..=1000 {
            let y = c.at(k as f64 / 1000.0);
            assert!(y >= prev - 1e-15 && y <= 1.0 + 1e-15, "{k}: {y}");
            prev = y;
        }
    }

    #[test]
    fn bad_tables_name_the_row() {
        let e = ResponseCurve::new(&[[0.0, 0.1], [128.0, 30.0], [100.0, 40.0], [255.0, 90.0]])
            .unwrap_err();
        assert_eq!(e.row, 2);
        assert!(e.problem.contains("increasing order"), "{e}");
        let e = ResponseCurve::new(&[[0.0, 0.1], [128.0, 30.0], [200.0, 29.0], [255.0, 90.0]])
            .unwrap_err();
        assert_eq!(e.row, 2);
        assert!(e.problem.contains("does not fall"), "{e}");
        let e = ResponseCurve::new(&[[10.0, 0.1], [128.0, 30.0], [255.0, 90.0]]).unwrap_err();
        assert_eq!(e.row, 0);
        let e = ResponseCurve::new(&[[0.0, 0.1], [255.0, 90.0]]).unwrap_err();
        assert!(e.problem.contains("at least 3"), "{e}");
        let e = ResponseCurve::new(&[[0.0, 5.0], [128.0, 5.0], [255.0, 5.0]]).unwrap_err();
        assert_eq!(e.row, 2);
        let e = ResponseCurve::new(&[[0.0, 0.0], [128.0, f64::NAN], [255.0, 5.0]]).unwrap_err();
        assert_eq!(e.row, 1);
    }
}

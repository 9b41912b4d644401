//! The measurements the surface solvers fit: per camera pixel, the screen
//! points S1 and S2 with their covariance.

use nalgebra::{Point3, Vector3};

use super::SurfaceError;
use crate::optics::station::Station;

/// One camera pixel's measurement.
#[derive(Debug, Clone, Copy)]
pub struct Observation {
    /// Camera pixel `(column, row)`.
    pub pixel: [u32; 2],
    /// The camera ray's unit direction, world frame.
    pub dir: Vector3<f64>,
    /// Measured `(u, v)` of the front (0) and back (1) reflection, screen px;
    /// NaN where that reflection was not found.
    pub s: [[f64; 2]; 2],
    /// Covariance of `(u1, v1, u2, v2)`, px² (the spectral solver's: the
    /// two points of one pixel are correlated where their spectra overlap).
    pub cov: [[f64; 4]; 4],
}

impl Observation {
    /// Whether reflection `k` (0 front, 1 back) was measured.
    pub fn has(&self, k: usize) -> bool {
        self.s[k][0].is_finite() && self.s[k][1].is_finite()
    }

    /// Standard deviation of coordinate `c` (0 u, 1 v) of reflection `k`, px.
    pub fn sigma(&self, k: usize, c: usize) -> f64 {
        self.cov[2 * k + c][2 * k + c].sqrt()
    }
}

/// How the uncertainty of the screen points is given.
#[derive(Debug, Clone, Copy)]
pub enum Uncertainty<'a> {
    /// Unknown: 1 px everywhere; the residuals set the covariance's scale.
    Unknown,
    /// `[rows, columns, 2, 2]` standard deviations (`screen_std.npy`).
    Std(&'a [f64]),
    /// `[rows, columns, 4, 4]` covariance of `(u1, v1, u2, v2)` (`screen_cov.npy`).
    Cov(&'a [f64]),
}

/// All pixels' measurements, from `screen_coords.npy` and `screen_std.npy`.
#[derive(Debug, Clone)]
pub struct Observations {
    /// Camera position, world frame, mm.
    pub camera: Point3<f64>,
    /// Pixels carrying at least one reflection.
    pub pixels: Vec<Observation>,
    /// Whether the σ came from the data (else 1 px everywhere, and the
    /// residuals set the scale of the covariance).
    pub sigma_known: bool,
    /// Pixels `(column, row)` left out as outliers by the surface stage.
    pub rejected: Vec<[u32; 2]>,
}

impl Observations {
    /// Builds the observations from arrays in the spec's layout
    /// `[rows, columns, 2, 2]` (`std` the same shape, optional).
    ///
    /// # Errors
    /// [`SurfaceError::Input`] when a length disagrees with the camera.
    pub fn from_maps(
        station: &Station,
        coords: &[f64],
        unc: Uncertainty,
    ) -> Result<Self, SurfaceError> {
        // Rays in the element's own frame (station v2's pose).
        let station = &station.element_frame();
        let cam = &station.camera;
        let n = cam.pixel_count() * 4;
        let (unc_name, unc_len, unc_want, tail) = match unc {
            Uncertainty::Unknown => ("", None, 0, ""),
            Uncertainty::Std(s) => ("screen_std", Some(s.len()), n, "2×2"),
            Uncertainty::Cov(s) => ("screen_cov", Some(s.len()), 4 * n, "4×4"),
        };
        let checks = [
            ("screen_coords", Some(coords.len()), n, "2×2"),
            (unc_name, unc_len, unc_want, tail),
        ];
        for (what, len, want, tail) in checks {
            if let Some(len) = len.filter(|&l| l != want) {
                return Err(SurfaceError::Input {
                    what,
                    problem: format!(
                        "{len} values, expected {want} = {}×{}×{tail} for the station's camera",
                        cam.height, cam.width
                    ),
                });
            }
        }
        let mut pixels = Vec::new();
        for j in 0..cam.height {
            for i in 0..cam.width {
                let base = 4 * (j as usize * cam.width as usize + i as usize);
                let s = [
                    [coords[base], coords[base + 1]],
                    [coords[base + 2], coords[base + 3]],
                ];
                let ob = observation(cam.ray_direction(i, j).into_inner(), [i, j], s, unc, base);
                if ob.has(0) || ob.has(1) {
                    pixels.push(ob);
                }
            }
        }
        Ok(Observations {
            camera: cam.position_mm,
            pixels,
            sigma_known: !matches!(unc, Uncertainty::Unknown),
            rejected: Vec::new(),
        })
    }

    /// The same observations with every pixel's covariance replaced by the
    /// mean over the `(2 half + 1)²` neighbourhood of pixels that carry the
    /// same reflections.
    ///
    /// Why: the spectral solver's covariance is the bound at the *fitted*
    /// points, so it depends on that pixel's own error (a pair fitted
    /// farther apart looks better resolved and gets more weight). Weighting
    /// by it biases the least-squares surfaces coherently along the
    /// front–back offset: on 8 simulated 48×48 acquisitions (10 mm, 2 %
    /// noise) the front error was 26.5 nm RMS against a bound of 13.3 nm;
    /// with the 5×5 mean, 13.3 nm. The covariance varies slowly over the
    /// element, so the mean loses nothing of the weighting's purpose.
    pub fn smoothed_covariance(&self, half: u32) -> Observations {
        let mut grid = std::collections::HashMap::with_capacity(self.pixels.len());
        for (k, p) in self.pixels.iter().enumerate() {
            grid.insert(p.pixel, k);
        }
        let h = i64::from(half);
        let pixels = self
            .pixels
            .iter()
            .map(|p| {
                let pattern = [p.has(0), p.has(1)];
                let mut acc = [[0.0; 4]; 4];
                let mut n = 0.0;
                for dj in -h..=h {
                    for di in -h..=h {
                        let (i, j) = (i64::from(p.pixel[0]) + di, i64::from(p.pixel[1]) + dj);
                        let (Ok(i), Ok(j)) = (u32::try_from(i), u32::try_from(j)) else {
                            continue;
                        };
                        let Some(&k) = grid.get(&[i, j]) else {
                            continue;
                        };
                        let q = &self.pixels[k];
                        if [q.has(0), q.has(1)] != pattern {
                            continue;
                        }
                        for (a, row) in acc.iter_mut().enumerate() {
                            for (b, x) in row.iter_mut().enumerate() {
                                *x += q.cov[a][b];
                            }
                        }
                        n += 1.0;
                    }
                }
                let mut out = *p;
                out.cov = acc.map(|row| row.map(|x| x / n));
                out
            })
            .collect();
        Observations {
            camera: self.camera,
            pixels,
            sigma_known: self.sigma_known,
            rejected: self.rejected.clone(),
        }
    }

    /// Number of measured reflections `k` (0 front, 1 back).
    pub fn count(&self, k: usize) -> usize {
        self.pixels.iter().filter(|p| p.has(k)).count()
    }
}

/// One pixel's observation; a reflection whose σ is missing or not
/// positive is dropped, and covariance entries that are NaN (an absent
/// partner reflection) are neutral.
fn observation(
    dir: Vector3<f64>,
    pixel: [u32; 2],
    s: [[f64; 2]; 2],
    unc: Uncertainty,
    base: usize,
) -> Observation {
    let mut ob = Observation {
        pixel,
        dir,
        s,
        cov: diagonal([1.0; 4]),
    };
    match unc {
        Uncertainty::Unknown => {}
        Uncertainty::Std(sd) => {
            ob.cov = diagonal(std::array::from_fn(|a| sd[base + a] * sd[base + a]));
        }
        Uncertainty::Cov(c) => {
            let b = 4 * base;
            ob.cov = std::array::from_fn(|a| std::array::from_fn(|k| c[b + 4 * a + k]));
        }
    }
    for k in 0..2 {
        let ok = (0..2).all(|c| ob.cov[2 * k + c][2 * k + c] > 0.0);
        if !ok {
            ob.s[k] = [f64::NAN; 2];
        }
    }
    for a in 0..4 {
        for b in 0..4 {
            if !ob.cov[a][b].is_finite() {
                ob.cov[a][b] = if a == b { 1.0 } else { 0.0 };
            }
        }
    }
    ob
}

pub(crate) fn diagonal(d: [f64; 4]) -> [[f64; 4]; 4] {
    std::array::from_fn(|a| std::array::from_fn(|b| if a == b { d[a] } else { 0.0 }))
}

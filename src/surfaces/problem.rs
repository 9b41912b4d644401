//! The inverse problem's data and its normal equations: the measured screen
//! points of every pixel, which Zernike terms are free, and the weighted
//! Gauss–Newton system `JᵀJ δ = −Jᵀr` built from one dual trace per path.

use nalgebra::{DMatrix, DVector, Point3, Vector3};
use rayon::prelude::*;

use super::path::{back_path, front_path, DualPath, SLOT_BACK, SLOT_FRONT_IN, SLOT_FRONT_OUT};
use super::SurfaceError;
use crate::station::Station;
use crate::trace::Plate;
use crate::zernike::ZernikeBasis;

/// Millimetres per nanometre: coefficients are nm, the tracer works in mm.
const MM_PER_NM: f64 = 1e-6;

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
    /// Standard deviations of those coordinates, screen px.
    pub sigma: [[f64; 2]; 2],
}

impl Observation {
    /// Whether reflection `k` (0 front, 1 back) was measured.
    pub fn has(&self, k: usize) -> bool {
        self.s[k][0].is_finite() && self.s[k][1].is_finite()
    }
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
        std: Option<&[f64]>,
    ) -> Result<Self, SurfaceError> {
        let cam = &station.camera;
        let n = cam.pixel_count() * 4;
        for (what, len) in [
            ("screen_coords", Some(coords.len())),
            ("screen_std", std.map(<[f64]>::len)),
        ] {
            if let Some(len) = len.filter(|&l| l != n) {
                return Err(SurfaceError::Input {
                    what,
                    problem: format!(
                        "{len} values, expected {n} = {}×{}×2×2 for the station's camera",
                        cam.height, cam.width
                    ),
                });
            }
        }
        let mut pixels = Vec::new();
        for j in 0..cam.height {
            for i in 0..cam.width {
                let base = 4 * (j as usize * cam.width as usize + i as usize);
                let mut ob = Observation {
                    pixel: [i, j],
                    dir: cam.ray_direction(i, j).into_inner(),
                    s: [
                        [coords[base], coords[base + 1]],
                        [coords[base + 2], coords[base + 3]],
                    ],
                    sigma: [[1.0; 2]; 2],
                };
                if let Some(sd) = std {
                    ob.sigma = [[sd[base], sd[base + 1]], [sd[base + 2], sd[base + 3]]];
                }
                for k in 0..2 {
                    let ok = ob.sigma[k].iter().all(|s| s.is_finite() && *s > 0.0);
                    if !ok {
                        ob.s[k] = [f64::NAN; 2];
                    }
                }
                if ob.has(0) || ob.has(1) {
                    pixels.push(ob);
                }
            }
        }
        Ok(Observations {
            camera: cam.position_mm,
            pixels,
            sigma_known: std.is_some(),
        })
    }

    /// Number of measured reflections `k` (0 front, 1 back).
    pub fn count(&self, k: usize) -> usize {
        self.pixels.iter().filter(|p| p.has(k)).count()
    }
}

/// Which coefficients are unknowns and which data enter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Layout {
    /// Terms of the front surface (Noll 1..=n).
    pub front_terms: usize,
    /// Terms of the back surface.
    pub back_terms: usize,
    /// Front coefficients j ≥ 2 are unknowns (piston is the reference plane's).
    pub fit_front: bool,
    /// Back coefficients are unknowns.
    pub fit_back: bool,
    /// The back's piston (its departure from the nominal thickness) is an unknown.
    pub back_piston: bool,
    /// S1 residuals enter.
    pub use_s1: bool,
    /// S2 residuals enter.
    pub use_s2: bool,
}

impl Layout {
    fn front_cols(&self) -> usize {
        if self.fit_front {
            self.front_terms - 1
        } else {
            0
        }
    }

    fn back_first(&self) -> usize {
        usize::from(!self.back_piston)
    }

    /// Number of unknowns.
    pub fn columns(&self) -> usize {
        self.front_cols()
            + if self.fit_back {
                self.back_terms - self.back_first()
            } else {
                0
            }
    }

    /// Column of front coefficient index `k` (Noll k + 1), if free.
    pub fn front_col(&self, k: usize) -> Option<usize> {
        (self.fit_front && k >= 1 && k < self.front_terms).then(|| k - 1)
    }

    /// Column of back coefficient index `k`, if free.
    pub fn back_col(&self, k: usize) -> Option<usize> {
        (self.fit_back && k >= self.back_first() && k < self.back_terms)
            .then(|| self.front_cols() + k - self.back_first())
    }
}

/// The Gauss–Newton system at one point.
#[derive(Debug, Clone)]
pub struct Normal {
    /// `JᵀJ` of the σ-weighted residuals (coefficients in nm).
    pub a: DMatrix<f64>,
    /// `Jᵀr`.
    pub b: DVector<f64>,
    /// `rᵀr` (χ² when σ is known).
    pub chi2: f64,
    /// Residual components that entered (two per path).
    pub n_resid: usize,
    /// Measured paths the model could not trace (front, back), e.g. a
    /// back reflection the current surfaces send through the rim.
    pub failed: [usize; 2],
}

impl Normal {
    fn zeros(p: usize) -> Self {
        Normal {
            a: DMatrix::zeros(p, p),
            b: DVector::zeros(p),
            chi2: 0.0,
            n_resid: 0,
            failed: [0; 2],
        }
    }

    fn merge(mut self, o: Normal) -> Self {
        self.a += o.a;
        self.b += o.b;
        self.chi2 += o.chi2;
        self.n_resid += o.n_resid;
        self.failed[0] += o.failed[0];
        self.failed[1] += o.failed[1];
        self
    }
}

/// Basis values and gradients at one point, per surface.
struct BasisAt {
    v: Vec<f64>,
    dx: Vec<f64>,
    dy: Vec<f64>,
}

impl BasisAt {
    fn new(n: usize) -> Self {
        BasisAt {
            v: vec![0.0; n],
            dx: vec![0.0; n],
            dy: vec![0.0; n],
        }
    }

    fn eval(&mut self, basis: &ZernikeBasis, xy: [f64; 2]) {
        // Lengths match by construction.
        let _ = basis.eval_into(xy[0], xy[1], &mut self.v, &mut self.dx, &mut self.dy);
    }
}

/// Adds slot `slot`'s contribution of path `p` (component `c`) to `row`.
#[allow(clippy::too_many_arguments)]
fn add_slot(
    row: &mut [f64],
    p: &DualPath,
    c: usize,
    slot: usize,
    at: &BasisAt,
    col: impl Fn(usize) -> Option<usize>,
    inv_sigma: f64,
) {
    let g = &p.uv[c].g;
    let (gh, gx, gy) = (g[slot], g[slot + 1], g[slot + 2]);
    let k = MM_PER_NM * inv_sigma;
    for (t, ((v, dx), dy)) in at.v.iter().zip(&at.dx).zip(&at.dy).enumerate() {
        if let Some(col) = col(t) {
            row[col] += (gh * v + gx * dx + gy * dy) * k;
        }
    }
}

/// Builds the normal equations (and χ²) of `layout` at the surfaces of
/// `plate`, on all cores. With `jacobian` false only χ² is computed.
pub fn accumulate(
    obs: &Observations,
    station: &Station,
    plate: &Plate,
    layout: &Layout,
    jacobian: bool,
) -> Normal {
    let p = if jacobian { layout.columns() } else { 0 };
    obs.pixels
        .par_chunks(128)
        .map(|chunk| accumulate_chunk(chunk, obs, station, plate, layout, p))
        .reduce(|| Normal::zeros(p), Normal::merge)
}

fn accumulate_chunk(
    chunk: &[Observation],
    obs: &Observations,
    station: &Station,
    plate: &Plate,
    layout: &Layout,
    p: usize,
) -> Normal {
    let mut out = Normal::zeros(p);
    let mut rows = DMatrix::<f64>::zeros(4 * chunk.len(), p);
    let mut res = DVector::<f64>::zeros(4 * chunk.len());
    let (mut f_in, mut f_out) = (
        BasisAt::new(layout.front_terms),
        BasisAt::new(layout.front_terms),
    );
    let mut bk = BasisAt::new(layout.back_terms);
    let mut r = 0;
    let mut row = vec![0.0; p];
    for ob in chunk {
        for k in 0..2 {
            if !ob.has(k) || !(if k == 0 { layout.use_s1 } else { layout.use_s2 }) {
                continue;
            }
            let traced = if k == 0 {
                front_path(plate, &obs.camera, &ob.dir, &station.screen)
            } else {
                back_path(plate, &obs.camera, &ob.dir, &station.screen)
            };
            let Ok(path) = traced else {
                out.failed[k] += 1;
                continue;
            };
            if p > 0 {
                f_in.eval(plate.front.basis(), path.hits[0]);
                if k == 1 {
                    bk.eval(plate.back.basis(), path.hits[1]);
                    f_out.eval(plate.front.basis(), path.hits[2]);
                }
            }
            for c in 0..2 {
                let inv_s = 1.0 / ob.sigma[k][c];
                res[r] = (path.uv[c].v - ob.s[k][c]) * inv_s;
                if p > 0 {
                    row.iter_mut().for_each(|x| *x = 0.0);
                    add_slot(
                        &mut row,
                        &path,
                        c,
                        SLOT_FRONT_IN,
                        &f_in,
                        |t| layout.front_col(t),
                        inv_s,
                    );
                    if k == 1 {
                        add_slot(
                            &mut row,
                            &path,
                            c,
                            SLOT_BACK,
                            &bk,
                            |t| layout.back_col(t),
                            inv_s,
                        );
                        add_slot(
                            &mut row,
                            &path,
                            c,
                            SLOT_FRONT_OUT,
                            &f_out,
                            |t| layout.front_col(t),
                            inv_s,
                        );
                    }
                    rows.row_mut(r).copy_from_slice(&row);
                }
                r += 1;
            }
        }
    }
    let used = res.rows(0, r);
    out.chi2 = used.norm_squared();
    out.n_resid = r;
    if p > 0 && r > 0 {
        let j = rows.rows(0, r);
        out.a.gemm_tr(1.0, &j, &j, 0.0);
        out.b.gemv_tr(1.0, &j, &used, 0.0);
    }
    out
}

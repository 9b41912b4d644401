//! The σ of the non-linear figures: their spread over coefficient vectors
//! drawn from the joint covariance of front and back.

use nalgebra::{DMatrix, DVector};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;

use super::{difference, face_rms, wedge_of, FigureInput, Grid, DRAWS, DRAWS_SEED};

/// Draws evaluated per batch of PV grids (bounds the memory of one batch).
const BATCH: usize = 50;

/// The spread (1σ) of each non-linear figure.
pub(super) struct Spread {
    /// Per face: irregularity PV, RMSt, RMSi, RMSa.
    pub face: [[f64; 4]; 2],
    /// Wedge, azimuth, thickness variation PV and RMS.
    pub plate: [f64; 4],
}

/// A square root `L` of the covariance (`L Lᵀ = C`), from its eigenvectors
/// with negative eigenvalues (rounding) set to zero: fixed coefficients
/// have zero rows and columns, which a Cholesky factor would refuse.
pub(super) fn square_root(c: &DMatrix<f64>) -> DMatrix<f64> {
    let sym = (c + c.transpose()) * 0.5;
    let eig = sym.symmetric_eigen();
    let mut l = eig.eigenvectors;
    for (k, &v) in eig.eigenvalues.iter().enumerate() {
        let s = v.max(0.0).sqrt();
        l.column_mut(k).scale_mut(s);
    }
    l
}

/// The spread of every non-linear figure of `input` over [`DRAWS`] draws.
pub(super) fn spread(input: &FigureInput<'_>, grid: &Grid) -> Spread {
    let (nf, nb) = (input.front_nm.len(), input.back_nm.len());
    let n = input.covariance_nm2.nrows().min(nf + nb);
    let l = square_root(&input.covariance_nm2.view((0, 0), (n, n)).into_owned());
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(DRAWS_SEED);
    let t = grid.terms();
    // Per draw: the front, the back and W1 − W2 as columns.
    let mut faces = [Vec::new(), Vec::new()];
    let mut plate = Vec::new();
    let mut done = 0;
    while done < DRAWS {
        let m = BATCH.min(DRAWS - done);
        let mut cols = [
            DMatrix::zeros(t, m),
            DMatrix::zeros(t, m),
            DMatrix::zeros(t, m),
        ];
        for d in 0..m {
            let z: DVector<f64> = DVector::from_fn(n, |_, _| StandardNormal.sample(&mut rng));
            let delta = &l * z;
            let at = |k: usize| delta.get(k).copied().unwrap_or(0.0);
            let f: Vec<f64> = (0..nf).map(|k| input.front_nm[k] + at(k)).collect();
            let b: Vec<f64> = (0..nb).map(|k| input.back_nm[k] + at(nf + k)).collect();
            let diff = difference(&f, &b);
            for (col, v) in cols.iter_mut().zip([&f, &b, &diff]) {
                for (k, x) in v.iter().enumerate().take(t) {
                    col[(k, d)] = *x;
                }
            }
            let (w, az) = wedge_of(&diff, input);
            let rms = diff.iter().skip(3).fold(0.0, |s, x| s + x * x).sqrt();
            plate.push([w, az, 0.0, rms]);
            for (k, v) in [&f, &b].into_iter().enumerate() {
                let [rt, ri, ra] = face_rms(v);
                faces[k].push([0.0, rt, ri, ra]);
            }
        }
        let first = plate.len() - m;
        for (k, v) in grid.pv_columns(&cols[0], 4).into_iter().enumerate() {
            faces[0][first + k][0] = v;
        }
        for (k, v) in grid.pv_columns(&cols[1], 4).into_iter().enumerate() {
            faces[1][first + k][0] = v;
        }
        for (k, v) in grid.pv_columns(&cols[2], 3).into_iter().enumerate() {
            plate[first + k][2] = v;
        }
        done += m;
    }
    let (_, azimuth) = wedge_of(&difference(input.front_nm, input.back_nm), input);
    Spread {
        face: [columns_std(&faces[0], None), columns_std(&faces[1], None)],
        plate: columns_std(&plate, Some((1, azimuth))),
    }
}

/// The sample standard deviation of each column of `rows`; the column of
/// `angle` (index, the estimate in degrees) is taken as the difference from
/// the estimate wrapped to ±180°.
fn columns_std(rows: &[[f64; 4]], angle: Option<(usize, f64)>) -> [f64; 4] {
    let mut out = [0.0; 4];
    if rows.len() < 2 {
        return out;
    }
    for (k, o) in out.iter_mut().enumerate() {
        let v: Vec<f64> = rows
            .iter()
            .map(|r| match angle {
                Some((i, est)) if i == k => (r[k] - est + 180.0).rem_euclid(360.0) - 180.0,
                _ => r[k],
            })
            .collect();
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (v.len() - 1) as f64;
        *o = var.sqrt();
    }
    out
}

//! Least-squares fits: round trips, weights, agreement with a dense solve,
//! and rank-deficient or malformed input.

use super::test_util::Rng;
use super::*;
use nalgebra::{DMatrix, DVector};

const RADIUS: f64 = 12.0;
const CENTER: [f64; 2] = [2.0, -3.0];

/// Random coefficients in [-100, 100) nm.
fn random_coefficients(rng: &mut Rng, n: usize) -> Vec<f64> {
    (0..n).map(|_| rng.range(-100.0, 100.0)).collect()
}

/// `count` points uniform on a disk 2 % larger than the aperture (rays land
/// slightly outside it).
fn random_points(rng: &mut Rng, count: usize) -> (Vec<f64>, Vec<f64>) {
    (0..count)
        .map(|_| rng.in_disk(1.02 * RADIUS, CENTER))
        .unzip()
}

/// Largest coefficient error relative to the largest coefficient.
fn relative_error(got: &[f64], want: &[f64]) -> f64 {
    let scale = want.iter().fold(0.0_f64, |a, b| a.max(b.abs()));
    got.iter()
        .zip(want)
        .map(|(g, w)| (g - w).abs())
        .fold(0.0, f64::max)
        / scale
}

#[test]
fn heights_round_trip_231_terms() {
    let mut rng = Rng::new(11);
    let basis = ZernikeBasis::new(231, RADIUS, CENTER).unwrap();
    let c = random_coefficients(&mut rng, 231);
    let surf = ZernikeSurface::new(basis.clone(), c.clone()).unwrap();
    let (xs, ys) = random_points(&mut rng, 1500); // > 5 blocks of 256 rows
    let h: Vec<f64> = xs
        .iter()
        .zip(&ys)
        .map(|(&x, &y)| surf.height_mm(x, y))
        .collect();
    let fit = fit_heights(&basis, &xs, &ys, &h, None).unwrap();
    assert_eq!(fit.n_points, 1500);
    // Householder QR is backward stable: the coefficient error is about
    // cond x eps x (data scale). With cond < 1e4 (asserted) that is < 1e-11
    // relative; 1e-9 leaves margin for the data's own rounding (heights are
    // sums of 231 terms, each rounded).
    assert!(fit.condition_number < 1e4, "cond {}", fit.condition_number);
    assert!(relative_error(&fit.coefficients_nm, &c) < 1e-9);
    // Exact data: the residual is rounding only, ~eps x |W| ~ 1e-16 x 1e-3 mm.
    assert!(fit.residual_rms < 1e-15, "rms {}", fit.residual_rms);
}

#[test]
fn slopes_round_trip_excludes_piston() {
    let mut rng = Rng::new(12);
    let basis = ZernikeBasis::new(231, RADIUS, CENTER).unwrap();
    let c = random_coefficients(&mut rng, 231);
    let surf = ZernikeSurface::new(basis.clone(), c.clone()).unwrap();
    let (xs, ys) = random_points(&mut rng, 1000); // 2000 equations, 230 unknowns
    let (gx, gy): (Vec<f64>, Vec<f64>) = xs
        .iter()
        .zip(&ys)
        .map(|(&x, &y)| {
            let (_, gx, gy) = surf.height_and_gradient(x, y);
            (gx, gy)
        })
        .unzip();
    let fit = fit_slopes(&basis, &xs, &ys, &gx, &gy, None).unwrap();
    assert_eq!(fit.coefficients_nm.len(), 231);
    assert_eq!(fit.coefficients_nm[0], 0.0); // piston is not observable
                                             // Gradients of order-20 terms are ~n^2 larger than tilts, so the design
                                             // is less well conditioned than for heights (cond < 1e5, asserted); the
                                             // backward-stable bound cond x eps is still < 1e-10 relative.
    assert!(fit.condition_number < 1e5, "cond {}", fit.condition_number);
    assert!(relative_error(&fit.coefficients_nm[1..], &c[1..]) < 1e-9);
    assert!(fit.residual_rms < 1e-15, "rms {}", fit.residual_rms);
}

#[test]
fn zero_weights_drop_corrupted_points() {
    let mut rng = Rng::new(13);
    let basis = ZernikeBasis::new(36, RADIUS, CENTER).unwrap();
    let c = random_coefficients(&mut rng, 36);
    let surf = ZernikeSurface::new(basis.clone(), c.clone()).unwrap();
    let (xs, ys) = random_points(&mut rng, 600);
    let mut h: Vec<f64> = xs
        .iter()
        .zip(&ys)
        .map(|(&x, &y)| surf.height_mm(x, y))
        .collect();
    let mut w = vec![1.0; 600];
    for i in (0..600).step_by(3) {
        h[i] += 1.0; // a 1 mm outlier...
        w[i] = 0.0; // ...that must not count
    }
    let fit = fit_heights(&basis, &xs, &ys, &h, Some(&w)).unwrap();
    assert_eq!(fit.n_points, 400);
    // Same argument as the unweighted round trip (cond is small for 36 terms).
    assert!(relative_error(&fit.coefficients_nm, &c) < 1e-9);
}

#[test]
fn integer_weights_equal_duplicated_points() {
    // sum w r^2 with w in {1, 2, 3} is the plain sum over points repeated w
    // times: both fits solve the same least-squares problem.
    let mut rng = Rng::new(14);
    let basis = ZernikeBasis::new(28, RADIUS, CENTER).unwrap();
    let (xs, ys) = random_points(&mut rng, 500);
    let noisy: Vec<f64> = (0..500).map(|_| rng.range(-1e-4, 1e-4)).collect();
    let w: Vec<f64> = (0..500).map(|i| f64::from(1 + (i % 3) as u32)).collect();
    let (mut dx, mut dy, mut dh) = (vec![], vec![], vec![]);
    for i in 0..500 {
        for _ in 0..w[i] as usize {
            dx.push(xs[i]);
            dy.push(ys[i]);
            dh.push(noisy[i]);
        }
    }
    let weighted = fit_heights(&basis, &xs, &ys, &noisy, Some(&w)).unwrap();
    let repeated = fit_heights(&basis, &dx, &dy, &dh, None).unwrap();
    // Two different row orders / scalings of a problem with cond < 1e3: the
    // solutions agree to ~cond x eps relative to the solution norm.
    assert!(relative_error(&weighted.coefficients_nm, &repeated.coefficients_nm) < 1e-11);
    let d = (weighted.residual_rms - repeated.residual_rms).abs();
    assert!(
        d <= 1e-12 * repeated.residual_rms,
        "{weighted:?} vs {repeated:?}"
    );

    let (gx, gy) = (noisy.clone(), noisy.iter().map(|v| -v).collect::<Vec<_>>());
    let rep = |v: &[f64]| {
        (0..500)
            .flat_map(|i| vec![v[i]; w[i] as usize])
            .collect::<Vec<_>>()
    };
    let weighted = fit_slopes(&basis, &xs, &ys, &gx, &gy, Some(&w)).unwrap();
    let repeated = fit_slopes(&basis, &dx, &dy, &rep(&gx), &rep(&gy), None).unwrap();
    assert!(relative_error(&weighted.coefficients_nm, &repeated.coefficients_nm) < 1e-11);
}

#[test]
fn matches_a_dense_solve_on_noisy_data() {
    let mut rng = Rng::new(15);
    let basis = ZernikeBasis::new(45, RADIUS, CENTER).unwrap();
    let (xs, ys) = random_points(&mut rng, 700);
    let h: Vec<f64> = (0..700).map(|_| rng.range(-1e-3, 1e-3)).collect();
    let fit = fit_heights(&basis, &xs, &ys, &h, None).unwrap();
    let mut a = DMatrix::zeros(700, 45);
    let mut row = vec![0.0; 45];
    for i in 0..700 {
        basis.eval_values_into(xs[i], ys[i], &mut row).unwrap();
        a.row_mut(i).copy_from_slice(&row);
    }
    let b = DVector::from_iterator(700, h.iter().map(|v| v * 1e6));
    let dense = a.clone().svd(true, true).solve(&b, 1e-14).unwrap();
    // Two backward-stable solvers of a problem with cond < 1e3: agreement to
    // ~cond x eps relative.
    assert!(relative_error(&fit.coefficients_nm, dense.as_slice()) < 1e-11);
    let r = &a * &dense - &b;
    let rms = r.norm() / 700f64.sqrt() * 1e-6;
    assert!(
        (fit.residual_rms - rms).abs() <= 1e-12 * rms,
        "{} vs {rms}",
        fit.residual_rms
    );
}

#[test]
fn too_few_points_is_an_error() {
    use ZernikeError::TooFewPoints;
    let basis = ZernikeBasis::new(15, RADIUS, CENTER).unwrap();
    let (xs, ys) = random_points(&mut Rng::new(16), 10);
    let h = vec![0.0; 10];
    let want = TooFewPoints {
        points: 10,
        equations: 10,
        unknowns: 15,
    };
    assert_eq!(fit_heights(&basis, &xs, &ys, &h, None), Err(want));
    // Slopes: two equations per point, piston not among the unknowns.
    let got = fit_slopes(&basis, &xs[..6], &ys[..6], &h[..6], &h[..6], None);
    assert_eq!(
        got,
        Err(TooFewPoints {
            points: 6,
            equations: 12,
            unknowns: 14
        })
    );
    let zero = vec![0.0; 10];
    let want = TooFewPoints {
        points: 0,
        equations: 0,
        unknowns: 15,
    };
    assert_eq!(fit_heights(&basis, &xs, &ys, &h, Some(&zero)), Err(want));
}

/// Assert that `got` is `IllConditioned` with a (non-NaN) condition number
/// above the limit.
fn assert_ill_conditioned(got: Result<ZernikeFit, ZernikeError>) {
    match got {
        Err(ZernikeError::IllConditioned {
            condition_number: k,
        }) => {
            assert!(k > MAX_CONDITION_NUMBER, "{k}")
        }
        other => panic!("expected IllConditioned, got {other:?}"),
    }
}

#[test]
fn degenerate_sampling_is_ill_conditioned() {
    let basis = ZernikeBasis::new(15, RADIUS, CENTER).unwrap();
    // 200 points on the line y = CENTER.y: every sine term vanishes there
    // (exactly singular: condition number +inf).
    let xs: Vec<f64> = (0..200)
        .map(|i| CENTER[0] + f64::from(i) * 0.1 - 10.0)
        .collect();
    let ys = vec![CENTER[1]; 200];
    let h = vec![1e-3; 200];
    assert_ill_conditioned(fit_heights(&basis, &xs, &ys, &h, None));
    assert_ill_conditioned(fit_slopes(&basis, &xs, &ys, &h, &h, None));
    // 200 points within 1e-4 radii of one spot: the terms are numerically
    // dependent there (condition number ~1e13 for slopes, +inf for heights
    // where a singular value of the factor comes out exactly 0).
    let mut rng = Rng::new(17);
    let (xs, ys): (Vec<f64>, Vec<f64>) = (0..200)
        .map(|_| rng.in_disk(1e-4 * RADIUS, [5.0, 1.0]))
        .unzip();
    assert_ill_conditioned(fit_heights(&basis, &xs, &ys, &h, None));
    assert_ill_conditioned(fit_slopes(&basis, &xs, &ys, &h, &h, None));
}

#[test]
fn malformed_input_is_an_error() {
    use ZernikeError::*;
    let basis = ZernikeBasis::new(3, RADIUS, CENTER).unwrap();
    let (xs, ys) = (vec![0.0, 1.0, 2.0, 3.0], vec![0.0, 1.0, -1.0, 2.0]);
    let h = vec![0.0; 4];
    let want = LengthMismatch {
        what: "ys_mm",
        expected: 4,
        actual: 3,
    };
    assert_eq!(fit_heights(&basis, &xs, &ys[..3], &h, None), Err(want));
    let want = LengthMismatch {
        what: "weights",
        expected: 4,
        actual: 5,
    };
    assert_eq!(
        fit_heights(&basis, &xs, &ys, &h, Some(&[1.0; 5])),
        Err(want)
    );
    let bad = vec![0.0, f64::NAN, 0.0, 0.0];
    let want = NonFinite {
        what: "heights_mm",
        index: 1,
    };
    assert_eq!(fit_heights(&basis, &xs, &ys, &bad, None), Err(want));
    let want = NonFinite {
        what: "dzdy",
        index: 1,
    };
    assert_eq!(fit_slopes(&basis, &xs, &ys, &h, &bad, None), Err(want));
    let want = InvalidWeight {
        index: 1,
        weight: -1.0,
    };
    assert_eq!(
        fit_heights(&basis, &xs, &ys, &h, Some(&[1.0, -1.0, 1.0, 1.0])),
        Err(want)
    );
    // Weights are divided by their maximum: neither huge nor subnormal
    // weights overflow.
    for w in [1e300, 5e-324] {
        assert!(fit_heights(&basis, &xs, &ys, &h, Some(&[w; 4])).is_ok());
    }
}

#[test]
fn piston_only_slope_fit_is_trivial() {
    // One term: nothing is observable from slopes; the fit is the zero surface.
    let basis = ZernikeBasis::new(1, RADIUS, CENTER).unwrap();
    let fit = fit_slopes(&basis, &[0.0], &[0.0], &[3e-3], &[4e-3], None).unwrap();
    assert_eq!(fit.coefficients_nm, vec![0.0]);
    assert_eq!(fit.condition_number, 1.0);
    // rms of (3e-3, 4e-3) = sqrt(12.5e-6); rounding only.
    assert!((fit.residual_rms - 12.5e-6f64.sqrt()).abs() < 1e-15);
}

//! Tests of the Zernike module against closed forms, the factorial formula,
//! quadrature orthonormality and finite differences.

use super::*;
use proptest::prelude::*;

/// Explicit factorial sum for R_n^m — the slow reference (accurate to ~1e-13
/// for n ≤ 10, where its alternating terms stay below ~1e4).
fn radial_factorial(n: u32, m: u32, rho: f64) -> f64 {
    let fact = |k: u32| (1..=k).map(f64::from).product::<f64>();
    (0..=(n - m) / 2)
        .map(|s| {
            let sign = if s % 2 == 0 { 1.0 } else { -1.0 };
            sign * fact(n - s) / (fact(s) * fact((n + m) / 2 - s) * fact((n - m) / 2 - s))
                * rho.powi((n - 2 * s) as i32)
        })
        .sum()
}

fn zernike_reference(j: usize, rho: f64, theta: f64) -> f64 {
    let (n, m) = noll_to_nm(j).unwrap();
    let am = m.unsigned_abs();
    let r = radial_factorial(n, am, rho);
    match m {
        0 => f64::from(n + 1).sqrt() * r,
        m if m > 0 => (2.0 * f64::from(n + 1)).sqrt() * r * (f64::from(am) * theta).cos(),
        _ => (2.0 * f64::from(n + 1)).sqrt() * r * (f64::from(am) * theta).sin(),
    }
}

fn values(basis: &ZernikeBasis, x: f64, y: f64) -> Vec<f64> {
    let mut v = vec![0.0; basis.n_terms()];
    basis.eval_values_into(x, y, &mut v);
    v
}

#[test]
fn noll_table_matches_the_literature() {
    // Noll (1976), Table 1.
    let expect = [
        (1, 0, 0),
        (2, 1, 1),
        (3, 1, -1),
        (4, 2, 0),
        (5, 2, -2),
        (6, 2, 2),
        (7, 3, -1),
        (8, 3, 1),
        (9, 3, -3),
        (10, 3, 3),
        (11, 4, 0),
        (12, 4, 2),
        (13, 4, -2),
        (22, 6, 0),
        (37, 8, 0),
    ];
    for (j, n, m) in expect {
        assert_eq!(noll_to_nm(j).unwrap(), (n, m), "j = {j}");
        assert_eq!(nm_to_noll(n, m).unwrap(), j);
    }
    assert!(noll_to_nm(0).is_err());
    assert!(nm_to_noll(3, 2).is_err());
    assert_eq!(terms_up_to_order(20), 231);
}

#[test]
fn agrees_with_factorial_formula_to_order_10() {
    let basis = ZernikeBasis::new(terms_up_to_order(10), 1.0, [0.0, 0.0]).unwrap();
    for k in 0..200 {
        let rho = k as f64 / 199.0 * 1.1;
        let theta = 0.37 * k as f64;
        let v = values(&basis, rho * theta.cos(), rho * theta.sin());
        for (i, &got) in v.iter().enumerate() {
            let want = zernike_reference(i + 1, rho, theta);
            // Both sides are O(1) sums of O(1e3) terms at most: 1e-11 is
            // ~1e4 ulps of headroom for the factorial sum's cancellation.
            assert!(
                (got - want).abs() < 1e-11,
                "j = {} rho = {rho}: {got} vs {want}",
                i + 1
            );
        }
    }
}

#[test]
fn closed_forms_of_low_terms() {
    let basis = ZernikeBasis::new(11, 2.0, [0.5, -0.25]).unwrap();
    let (rho, th): (f64, f64) = (0.63, 1.1);
    let (x, y) = (0.5 + 2.0 * rho * th.cos(), -0.25 + 2.0 * rho * th.sin());
    let v = values(&basis, x, y);
    let s = |v: f64| v.sqrt();
    let want = [
        (2, 2.0 * rho * th.cos()),
        (4, s(3.0) * (2.0 * rho * rho - 1.0)),
        (5, s(6.0) * rho * rho * (2.0 * th).sin()),
        (7, s(8.0) * (3.0 * rho.powi(3) - 2.0 * rho) * th.sin()),
        (11, s(5.0) * (6.0 * rho.powi(4) - 6.0 * rho * rho + 1.0)),
    ];
    for (j, w) in want {
        // A few ulps of rounding on O(1) values.
        assert!((v[j - 1] - w).abs() < 1e-13, "Z{j}: {} vs {w}", v[j - 1]);
    }
}

/// Gauss–Legendre nodes and weights on [0, 1] by Newton on P_n.
fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    (1..=n)
        .map(|i| {
            let mut x = (std::f64::consts::PI * (i as f64 - 0.25) / (n as f64 + 0.5)).cos();
            let mut dp = 0.0;
            for _ in 0..100 {
                let (mut p0, mut p1) = (1.0, x);
                for k in 2..=n {
                    let kf = k as f64;
                    let p2 = ((2.0 * kf - 1.0) * x * p1 - (kf - 1.0) * p0) / kf;
                    p0 = p1;
                    p1 = p2;
                }
                dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
                let dx = p1 / dp;
                x -= dx;
                if dx.abs() < 1e-16 {
                    break;
                }
            }
            ((1.0 + x) / 2.0, 1.0 / ((1.0 - x * x) * dp * dp))
        })
        .collect()
}

#[test]
fn orthonormal_on_the_unit_disk_to_order_20() {
    // (1/π)∫∫ Z_i Z_j ρ dρ dθ = δ_ij. In t = ρ², ρ dρ = dt/2 and the radial
    // product is a polynomial of degree ≤ 20 in t: 24 Gauss nodes are exact.
    // The angular product is a trig polynomial of degree ≤ 40: the trapezoid
    // rule with 48 nodes is exact. What is left is rounding, ~1e-13.
    let basis = ZernikeBasis::new(231, 1.0, [0.0, 0.0]).unwrap();
    let radial = gauss_legendre(24);
    let n_theta = 48;
    let mut gram = vec![0.0; 231 * 231];
    for &(t, wt) in &radial {
        let rho = t.sqrt();
        for a in 0..n_theta {
            let th = std::f64::consts::TAU * a as f64 / n_theta as f64;
            let v = values(&basis, rho * th.cos(), rho * th.sin());
            let w = wt * 0.5 * std::f64::consts::TAU / n_theta as f64 / std::f64::consts::PI;
            for i in 0..231 {
                for j in i..231 {
                    gram[i * 231 + j] += w * v[i] * v[j];
                }
            }
        }
    }
    for i in 0..231 {
        for j in i..231 {
            let want = if i == j { 1.0 } else { 0.0 };
            assert!(
                (gram[i * 231 + j] - want).abs() < 1e-11,
                "<Z{},Z{}> = {}",
                i + 1,
                j + 1,
                gram[i * 231 + j]
            );
        }
    }
}

#[test]
fn radial_polynomials_are_one_at_the_edge_to_order_40() {
    let basis = ZernikeBasis::new(terms_up_to_order(40), 1.0, [0.0, 0.0]).unwrap();
    let v = values(&basis, 1.0, 0.0);
    for (k, &val) in v.iter().enumerate() {
        let (n, m) = noll_to_nm(k + 1).unwrap();
        let norm = if m == 0 {
            f64::from(n + 1).sqrt()
        } else {
            (2.0 * f64::from(n + 1)).sqrt()
        };
        // At θ = 0 the sin terms vanish and cos terms are N · R(1) = N.
        let want = if m < 0 { 0.0 } else { norm };
        // The recurrence accumulates ~n ulps per step: 1e-11 at n = 40.
        assert!((val - want).abs() < 1e-11, "j = {}: {val} vs {want}", k + 1);
    }
}

#[test]
fn gradients_match_finite_differences() {
    let basis = ZernikeBasis::new(231, 25.5, [1.0, -2.0]).unwrap();
    let n = basis.n_terms();
    let (mut v, mut gx, mut gy) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    // Points: the centre (ρ = 0), inside, on and outside the edge (ρ = 1.3).
    for (x, y) in [
        (1.0, -2.0),
        (10.0, 5.0),
        (1.0 + 25.5, -2.0),
        (1.0 - 20.0, -2.0 + 24.0),
    ] {
        basis.eval_into(x, y, &mut v, &mut gx, &mut gy);
        let h = 1e-4; // mm; central difference error h²/6 · f''' ~ 1e-8 · |f'''|
        let (p, m) = (values(&basis, x + h, y), values(&basis, x - h, y));
        let (py, my) = (values(&basis, x, y + h), values(&basis, x, y - h));
        for k in 0..n {
            let fdx = (p[k] - m[k]) / (2.0 * h);
            let fdy = (py[k] - my[k]) / (2.0 * h);
            // Terms up to ρ^20 · sqrt(42) at ρ = 1.3 reach ~1e3, their third
            // derivatives (per mm) ~1e3 · 20³ / 25.5³ ≈ 5e2: truncation 1e-6;
            // rounding eps · 1e3 / h = 2e-9. Scale by the value's size.
            let tol = 1e-6 * (1.0 + v[k].abs());
            assert!(
                (gx[k] - fdx).abs() < tol,
                "j = {} d/dx at ({x},{y}): {} vs {fdx}",
                k + 1,
                gx[k]
            );
            assert!(
                (gy[k] - fdy).abs() < tol,
                "j = {} d/dy at ({x},{y}): {} vs {fdy}",
                k + 1,
                gy[k]
            );
        }
    }
}

/// A small deterministic generator for test data.
fn xorshift(state: &mut u64) -> f64 {
    *state ^= *state << 13;
    *state ^= *state >> 7;
    *state ^= *state << 17;
    (*state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
}

fn disk_points(n: usize, radius: f64, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let mut s = seed;
    let (mut xs, mut ys) = (Vec::new(), Vec::new());
    while xs.len() < n {
        let (x, y) = (xorshift(&mut s), xorshift(&mut s));
        if x * x + y * y <= 1.0 {
            xs.push(x * radius);
            ys.push(y * radius);
        }
    }
    (xs, ys)
}

#[test]
fn height_and_slope_fits_recover_coefficients() {
    let basis = ZernikeBasis::new(66, 25.5, [0.0, 0.0]).unwrap();
    let mut s = 5;
    let truth: Vec<f64> = (0..66).map(|_| 50.0 * xorshift(&mut s)).collect();
    let surf = ZernikeSurface::new(basis.clone(), truth.clone()).unwrap();
    let (xs, ys) = disk_points(10_000, 25.5, 9);
    let mut h = Vec::new();
    let (mut sx, mut sy) = (Vec::new(), Vec::new());
    for (&x, &y) in xs.iter().zip(&ys) {
        let (w, wx, wy) = surf.height_and_gradient(x, y);
        h.push(w);
        sx.push(wx);
        sy.push(wy);
    }
    let fit = fit_heights(&basis, &xs, &ys, &h, None).unwrap();
    // Exact data: the error is rounding amplified by the condition number
    // (reported, ~2): far below 1e-9 nm on 50 nm coefficients.
    for (a, b) in fit.coefficients_nm.iter().zip(&truth) {
        assert!((a - b).abs() < 1e-9, "{a} vs {b}");
    }
    assert!(fit.condition_number < 10.0, "cond {}", fit.condition_number);
    let weights: Vec<f64> = (0..xs.len()).map(|k| 1.0 + (k % 3) as f64).collect();
    let fit = fit_slopes(&basis, &xs, &ys, &sx, &sy, Some(&weights)).unwrap();
    assert_eq!(
        fit.coefficients_nm[0], 0.0,
        "piston is not observable from slopes"
    );
    for (a, b) in fit.coefficients_nm.iter().zip(&truth).skip(1) {
        assert!((a - b).abs() < 1e-8, "{a} vs {b}");
    }
}

#[test]
fn degenerate_fits_are_errors_not_nan() {
    let basis = ZernikeBasis::new(10, 1.0, [0.0, 0.0]).unwrap();
    let err = fit_heights(&basis, &[0.1, 0.2], &[0.0, 0.1], &[1.0, 2.0], None).unwrap_err();
    assert!(matches!(err, ZernikeError::TooFewPoints { .. }));
    // Twenty points on one line cannot separate x- from y-dependence.
    let xs: Vec<f64> = (0..20).map(|k| k as f64 / 20.0).collect();
    let ys = vec![0.0; 20];
    let err = fit_heights(&basis, &xs, &ys, &[0.0; 20], None).unwrap_err();
    assert!(
        matches!(err, ZernikeError::IllConditioned { .. }),
        "{err:?}"
    );
    assert!(ZernikeBasis::new(3, 0.0, [0.0, 0.0]).is_err());
    let b = ZernikeBasis::new(3, 1.0, [0.0, 0.0]).unwrap();
    assert!(ZernikeSurface::new(b.clone(), vec![0.0; 2]).is_err());
    assert!(ZernikeSurface::new(b, vec![0.0, f64::NAN, 0.0]).is_err());
}

proptest! {
    #[test]
    fn noll_round_trip(j in 1usize..=1000) {
        let (n, m) = noll_to_nm(j).unwrap();
        prop_assert_eq!(nm_to_noll(n, m).unwrap(), j);
    }

    #[test]
    fn evaluation_is_finite_within_twice_the_radius(x in -2.0f64..2.0, y in -2.0f64..2.0) {
        let basis = ZernikeBasis::new(231, 1.0, [0.0, 0.0]).unwrap();
        let n = basis.n_terms();
        let (mut v, mut gx, mut gy) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        basis.eval_into(x, y, &mut v, &mut gx, &mut gy);
        prop_assert!(v.iter().chain(&gx).chain(&gy).all(|a| a.is_finite()));
    }
}

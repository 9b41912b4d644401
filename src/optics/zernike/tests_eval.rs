//! Indices, radial polynomials, closed forms and orthonormality.

use super::test_util::{gauss_legendre_01, radial_factorial};
use super::*;
use proptest::prelude::*;
use std::f64::consts::PI;

const EPS: f64 = f64::EPSILON;

#[test]
fn noll_table_matches_the_spec() {
    let expected = [
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
        (14, 4, 4),
        (15, 4, -4),
        (22, 6, 0),
        (230, 20, 20),
        (231, 20, -20),
    ];
    for (j, n, m) in expected {
        assert_eq!(noll_to_nm(j), Ok((n, m)), "j = {j}");
        assert_eq!(nm_to_noll(n, m), Ok(j), "(n, m) = ({n}, {m})");
    }
    assert_eq!(terms_up_to_order(0), 1);
    assert_eq!(terms_up_to_order(4), 15);
    assert_eq!(terms_up_to_order(20), 231);
    assert_eq!(terms_up_to_order(u32::MAX), (1usize << 63) + (1 << 31)); // 2^32 (2^32 + 1) / 2
}

#[test]
fn invalid_indices_are_errors() {
    assert_eq!(noll_to_nm(0), Err(ZernikeError::InvalidIndex { j: 0 }));
    assert!(noll_to_nm(usize::MAX).is_err()); // order does not fit an i32
    assert_eq!(
        nm_to_noll(3, 0),
        Err(ZernikeError::InvalidOrder { n: 3, m: 0 })
    );
    assert_eq!(
        nm_to_noll(2, 4),
        Err(ZernikeError::InvalidOrder { n: 2, m: 4 })
    );
    assert_eq!(
        nm_to_noll(2, -3),
        Err(ZernikeError::InvalidOrder { n: 2, m: -3 })
    );
    assert!(nm_to_noll(u32::MAX, 1).is_err());
    assert!(radial_polynomial(5, 2, 0.5).is_err());
    assert!(radial_polynomial(MAX_RADIAL_ORDER + 2, 0, 0.5).is_err());
}

proptest! {
    #[test]
    fn noll_round_trip(j in 1usize..=1000) {
        let (n, m) = noll_to_nm(j).unwrap();
        prop_assert!(m.unsigned_abs() <= n && (n - m.unsigned_abs()) % 2 == 0);
        // m != 0: even j is the cosine (m > 0), odd j the sine (m < 0).
        prop_assert!(m == 0 || (j % 2 == 0) == (m > 0));
        prop_assert_eq!(nm_to_noll(n, m), Ok(j));
    }

    #[test]
    fn evaluation_is_finite_within_two_radii(
        fx in -2.0f64..=2.0, fy in -2.0f64..=2.0,
        radius in 0.5f64..100.0, cx in -50.0f64..50.0, cy in -50.0f64..50.0,
    ) {
        let basis = ZernikeBasis::new(231, radius, [cx, cy]).unwrap();
        let (x, y) = (cx + fx * radius, cy + fy * radius);
        let (mut v, mut gx, mut gy) = (vec![0.0; 231], vec![0.0; 231], vec![0.0; 231]);
        basis.eval_into(x, y, &mut v, &mut gx, &mut gy).unwrap();
        prop_assert!(v.iter().chain(&gx).chain(&gy).all(|z| z.is_finite()));
        let surf = ZernikeSurface::new(basis, vec![100.0; 231]).unwrap();
        let (h, hx, hy) = surf.height_and_gradient(x, y);
        prop_assert!(h.is_finite() && hx.is_finite() && hy.is_finite());
    }
}

#[test]
fn radial_matches_factorial_formula_to_order_10() {
    for n in 0..=10u32 {
        for m in (n % 2..=n).step_by(2) {
            for i in 0..=130 {
                let rho = f64::from(i) / 100.0; // 0 ..= 1.3, also outside the disk
                let (reference, abs_sum) = radial_factorial(n, m, rho);
                let got = radial_polynomial(n, m, rho).unwrap();
                // Both are sums/recurrences of <= 6 terms: each is within a few
                // eps x (sum of |terms|) of the true value. 16 eps x that scale
                // covers both with margin and is ~1e-13 at worst here.
                let tol = 16.0 * EPS * abs_sum.max(1.0);
                assert!(
                    (got - reference).abs() <= tol,
                    "R_{n}^{m}({rho}) {got} vs {reference}"
                );
            }
        }
    }
}

/// `R_n^m(a/4)` exactly: integer coefficients, t = a^2/16 on a common
/// denominator 16^k in i128, one rounding to f64 (then exact power-of-two
/// scaling and rho^m by powi, a few more ulps).
fn radial_exact(n: u32, m: u32, a: u32) -> f64 {
    let binom =
        |n: u32, k: u32| (0..k).fold(1i128, |c, i| c * i128::from(n - i) / i128::from(i + 1));
    let k = (n - m) / 2;
    let p = i128::from(a * a);
    let mut sum = 0i128;
    for s in 0..=k {
        let c = binom(n - s, s) * binom(n - 2 * s, k - s);
        let term = c
            .checked_mul(p.pow(k - s))
            .and_then(|t| t.checked_mul(16i128.pow(s)));
        let term = term.expect("reference overflow: choose smaller a");
        sum += if s % 2 == 0 { term } else { -term };
    }
    let rho = f64::from(a) / 4.0;
    (sum as f64) * 2f64.powi(-4 * k as i32) * rho.powi(m as i32)
}

#[test]
fn radial_is_exact_at_high_order() {
    for (n, a_max) in [(20u32, 6u32), (30, 6), (40, 4)] {
        for m in (n % 2..=n).step_by(2) {
            for a in 0..=a_max {
                let exact = radial_exact(n, m, a);
                let got = radial_polynomial(n, m, f64::from(a) / 4.0).unwrap();
                // The reference has a few ulps of error (one rounding, then powi);
                // the recurrence loses about an ulp per step relative to |R|
                // (k <= 20 steps), i.e. ~5e-15 relative. 1e-13 relative, plus
                // 1e-13 absolute near roots where |R| is small but the steps'
                // values are O(1), leaves ~10x margin over the observed 1e-14.
                let tol = 1e-13 * exact.abs() + 1e-13;
                assert!(
                    (got - exact).abs() <= tol,
                    "R_{n}^{m}({a}/4) = {got} vs {exact}"
                );
            }
        }
    }
}

#[test]
fn radial_is_one_at_the_edge_and_bounded_inside() {
    for n in 0..=MAX_RADIAL_ORDER {
        for m in (n % 2..=n).step_by(2) {
            // Exact value 1; each of <= 50 recurrence steps adds ~1 ulp relative.
            let r1 = radial_polynomial(n, m, 1.0).unwrap();
            assert!((r1 - 1.0).abs() <= 1e-12, "R_{n}^{m}(1) = {r1}");
            if n <= 40 {
                for i in 0..=200 {
                    let r = radial_polynomial(n, m, f64::from(i) / 200.0).unwrap();
                    // |R| <= 1 on [0, 1] exactly; allow the same rounding margin.
                    assert!(r.abs() <= 1.0 + 1e-12, "|R_{n}^{m}| = {r}");
                }
            }
        }
    }
}

/// `Z_j` at the world point of normalised polar coordinates (rho, theta).
fn z_at(basis: &ZernikeBasis, rho: f64, theta: f64) -> Vec<f64> {
    let [cx, cy] = basis.center_mm();
    let r = basis.radius_mm();
    let mut v = vec![0.0; basis.n_terms()];
    let (x, y) = (cx + r * rho * theta.cos(), cy + r * rho * theta.sin());
    basis.eval_values_into(x, y, &mut v).unwrap();
    v
}

#[test]
fn closed_forms() {
    let basis = ZernikeBasis::new(11, 12.5, [3.0, -7.0]).unwrap();
    for i in 0..=26 {
        for l in 0..16 {
            let rho = f64::from(i) * 0.05; // up to 1.3, outside the disk too
            let th = f64::from(l) * 0.4;
            let z = z_at(&basis, rho, th);
            let r2 = rho * rho;
            let expect = [
                (2, 2.0 * rho * th.cos()),
                (4, 3f64.sqrt() * (2.0 * r2 - 1.0)),
                (5, 6f64.sqrt() * r2 * (2.0 * th).sin()),
                (7, 8f64.sqrt() * (3.0 * r2 * rho - 2.0 * rho) * th.sin()),
                (11, 5f64.sqrt() * (6.0 * r2 * r2 - 6.0 * r2 + 1.0)),
            ];
            for (j, e) in expect {
                // rho, theta go through the mm frame and back (a few ulps of
                // 1.3 each) and both sides have ~10 roundings of O(10) terms.
                assert!(
                    (z[j - 1] - e).abs() <= 1e-13,
                    "Z{j}({rho}, {th}) {} vs {e}",
                    z[j - 1]
                );
            }
        }
    }
}

#[test]
fn orthonormal_on_the_unit_disk_to_order_20() {
    let basis = ZernikeBasis::new(231, 1.0, [0.0, 0.0]).unwrap();
    // (1/pi) int int Z_i Z_j rho drho dtheta with t = rho^2 (rho drho = dt/2).
    // Same-|m| products are polynomials of degree <= 20 in t: 16 Gauss-Legendre
    // nodes are exact to degree 31. The angular factor is a trig polynomial of
    // degree <= 40: the trapezoid rule with 48 > 40 nodes is exact for it (and
    // gives exactly 0 for different |m|, whatever the radial factor).
    let nodes = gauss_legendre_01(16);
    let n_theta = 48;
    let mut gram = vec![0.0; 231 * 231];
    for &(t, wt) in &nodes {
        for l in 0..n_theta {
            let th = 2.0 * PI * f64::from(l) / f64::from(n_theta);
            let z = z_at(&basis, t.sqrt(), th);
            let w = wt / f64::from(n_theta); // (1/pi)(1/2) wt (2 pi / n_theta)
            for i in 0..231 {
                for j in 0..231 {
                    gram[i * 231 + j] += w * z[i] * z[j];
                }
            }
        }
    }
    for i in 0..231 {
        for j in 0..231 {
            let want = if i == j { 1.0 } else { 0.0 };
            // 768 products of values <= ~6.5 summed with positive weights, and
            // nodes/weights accurate to a few ulps: the rounding is ~1e-14
            // (observed 7e-15); 1e-13 keeps a 10x margin.
            let g = gram[i * 231 + j];
            assert!((g - want).abs() <= 1e-13, "<Z{}, Z{}> = {g}", i + 1, j + 1);
        }
    }
}

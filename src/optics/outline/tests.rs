//! The outline against closed forms: Gauss–Legendre exactness, polygon
//! areas and moments, Mahajan & Dai's square polynomials, and the
//! orthonormality of the set over a non-convex polygon checked by an
//! independent midpoint sum.

use super::geometry::{check, triangles};
use super::quadrature::{gauss_legendre_01, polygon_rule};
use super::{Outline, Shape};
use crate::optics::zernike::ZernikeBasis;

#[test]
fn gauss_legendre_is_exact_to_degree_2n_minus_1() {
    for n in [1, 2, 5, 11, 21] {
        let rule = gauss_legendre_01(n);
        for k in 0..2 * n {
            let got: f64 = rule.iter().map(|(x, w)| w * x.powi(k as i32)).sum();
            let want = 1.0 / (k as f64 + 1.0);
            assert!((got - want).abs() < 1e-13, "n {n}, x^{k}: {got} vs {want}");
        }
    }
}

#[test]
fn polygon_rules_integrate_moments_exactly() {
    // An L shape (non-convex) of area 3: [0,2]×[0,1] ∪ [0,1]×[1,2].
    let l = [
        [0.0, 0.0],
        [2.0, 0.0],
        [2.0, 1.0],
        [1.0, 1.0],
        [1.0, 2.0],
        [0.0, 2.0],
    ];
    assert_eq!(triangles(&l).len(), 4);
    let rule = polygon_rule(&l, 6);
    let area: f64 = rule.iter().map(|r| r.1).sum();
    assert!((area - 3.0).abs() < 1e-13, "{area}");
    // ∫ x³ y² over the L: [0,2]×[0,1] gives 4·(1/3), [0,1]×[1,2] gives (1/4)·(7/3).
    let m: f64 = rule
        .iter()
        .map(|(p, w)| w * p[0].powi(3) * p[1].powi(2))
        .sum();
    let want = 4.0 / 3.0 + 7.0 / 12.0;
    assert!((m - want).abs() < 1e-12, "{m} vs {want}");
}

#[test]
fn polygons_that_are_not_simple_are_refused() {
    assert!(check(&[[0.0, 0.0], [1.0, 0.0]]).is_err());
    let bow = [[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]];
    assert!(check(&bow).unwrap_err().contains("cross"));
    let flat = [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]];
    assert!(check(&flat).is_err());
    assert!(check(&[[0.0, 0.0], [1.0, 0.0], [f64::NAN, 1.0]]).is_err());
}

/// The square inscribed in the unit disk (half-side 1/√2): Mahajan & Dai's
/// R2 = √6 x, R4 = √(5/2) (3ρ² − 1), so Z2 = 2x is (2/√6) R2 and
/// Z4 = √3 (2ρ² − 1) = −1/√3 R1 + 2√6/(3√5) R4.
#[test]
fn the_square_gives_mahajan_and_dais_polynomials() {
    let r = 10.0;
    let side = r * 2f64.sqrt();
    let sq = Outline::new(
        Shape::Rectangle {
            sides_mm: [side, side],
            rotation_deg: 0.0,
        },
        [0.0, 0.0],
        r,
    );
    assert!((sq.circumradius_mm() - r).abs() < 1e-12);
    assert!((sq.fill_of_disk() - 2.0 / std::f64::consts::PI).abs() < 1e-12);
    let q = sq.orthonormal(11).unwrap();
    let mut e2 = vec![0.0; 11];
    e2[1] = 1.0;
    let a = q.coefficients(&e2);
    assert!((a[1] - 2.0 / 6f64.sqrt()).abs() < 1e-12, "{a:?}");
    assert!(a.iter().enumerate().all(|(k, v)| k == 1 || v.abs() < 1e-12));
    let mut e4 = vec![0.0; 11];
    e4[3] = 1.0;
    let a = q.coefficients(&e4);
    assert!((a[0] + 1.0 / 3f64.sqrt()).abs() < 1e-12, "{a:?}");
    assert!(
        (a[3] - 2.0 * 6f64.sqrt() / (3.0 * 5f64.sqrt())).abs() < 1e-12,
        "{a:?}"
    );
    // The plane removed: only piston and tilts change.
    let c: Vec<f64> = (0..11).map(|k| (k as f64 + 1.0).sin()).collect();
    let w = q.without_first(&c, 3);
    assert_eq!(&w[3..], &c[3..]);
    let aw = q.coefficients(&w);
    assert!(aw[..3].iter().all(|v| v.abs() < 1e-12), "{aw:?}");
}

/// Over a rotated, off-centre pentagon (non-convex), the set is
/// orthonormal by a midpoint sum that shares nothing with the quadrature
/// (its error is O(h²) ≈ 1e-4 at 800 × 800 cells for these degrees).
#[test]
fn the_set_is_orthonormal_over_a_non_convex_polygon() {
    let v = vec![
        [-8.0, -6.0],
        [9.0, -7.0],
        [3.0, 0.0],
        [8.0, 7.0],
        [-7.0, 8.0],
    ];
    let o = Outline::new(Shape::Polygon { vertices_mm: v }, [0.5, 0.2], 12.5);
    assert!(o.circumradius_mm() <= 12.5);
    let terms = 15;
    let q = o.orthonormal(terms).unwrap();
    let basis = ZernikeBasis::new(terms, 12.5, [0.5, 0.2]).unwrap();
    let n = 800;
    let (lo, step) = (-12.5, 25.0 / n as f64);
    let mut g = nalgebra::DMatrix::<f64>::zeros(terms, terms);
    let mut z = vec![0.0; terms];
    let mut count = 0.0;
    for i in 0..n {
        for j in 0..n {
            let (x, y) = (lo + (i as f64 + 0.5) * step, lo + (j as f64 + 0.5) * step);
            if o.contains(x, y) {
                basis.eval_values_into(x, y, &mut z).unwrap();
                let a = nalgebra::DVector::from_column_slice(&z);
                g += &a * a.transpose();
                count += 1.0;
            }
        }
    }
    g /= count;
    // Q = L⁻¹ Z, so ⟨Q Qᵀ⟩ = L⁻¹ G L⁻ᵀ with L = (Lᵀ)ᵀ.
    let lt = q.matrix();
    let l_inv = lt.transpose().try_inverse().unwrap();
    let qq = &l_inv * g * l_inv.transpose();
    let off = (&qq - nalgebra::DMatrix::<f64>::identity(terms, terms))
        .abs()
        .max();
    assert!(off < 2e-3, "⟨Q Qᵀ⟩ departs from I by {off}");
}

#[test]
fn a_sliver_too_narrow_for_the_terms_is_named() {
    let o = Outline::new(
        Shape::Rectangle {
            sides_mm: [20.0, 0.02],
            rotation_deg: 30.0,
        },
        [0.0, 0.0],
        10.0,
    );
    let e = o.orthonormal(66).unwrap_err().to_string();
    assert!(e.contains("too narrow") && e.contains("66"), "{e}");
    assert!(o.orthonormal(3).is_ok());
    // The choice stops at the full orders it supports.
    let most = o.supported_terms(66).unwrap();
    assert!(
        (3..66).contains(&most) && o.orthonormal(most).is_ok(),
        "{most}"
    );
    assert!(crate::optics::zernike::terms_up_to_order(1) <= most);
}

#[test]
fn the_disk_is_its_own_set_and_the_rim_follows_the_outline() {
    let d = Outline::circle([1.0, 2.0], 5.0);
    assert!(d.orthonormal(10).unwrap().is_identity());
    assert!(d.contains(5.9, 2.0) && !d.contains(6.1, 2.0));
    let r = Outline::new(
        Shape::Rectangle {
            sides_mm: [4.0, 2.0],
            rotation_deg: 90.0,
        },
        [0.0, 0.0],
        3.0,
    );
    // Rotated by 90°: 2 mm along x, 4 mm along y.
    assert!(r.contains(0.9, 1.9) && !r.contains(1.1, 0.0));
    assert!((r.outside_by_mm(3.0, 0.0) - 2.0).abs() < 1e-12);
}

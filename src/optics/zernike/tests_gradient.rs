//! Gradients against central finite differences, and the surface against the
//! basis it is built on.

use super::test_util::Rng;
use super::*;

const EPS: f64 = f64::EPSILON;

/// The test points, normalised polar (rho, theta): the centre, the rim and
/// rho = 1.3 outside the disk, plus a few interior points.
fn probe_points() -> Vec<(f64, f64)> {
    let mut pts = vec![(0.0, 0.0)];
    for l in 0..7 {
        let th = 0.3 + 0.9 * f64::from(l);
        pts.extend([(1.0, th), (1.3, th), (0.37, th), (1e-6, th)]);
    }
    pts
}

/// Values of all terms at (x, y) mm.
fn values(basis: &ZernikeBasis, x: f64, y: f64) -> Vec<f64> {
    let mut v = vec![0.0; basis.n_terms()];
    basis.eval_values_into(x, y, &mut v).unwrap();
    v
}

/// Central difference of all terms along unit direction `dir` with step h (mm),
/// and a third-derivative estimate `|f'''|` from a 4-point stencil with step
/// `big` (mm), the larger of two such estimates at `big` and `2 big`.
fn differences(basis: &ZernikeBasis, p: [f64; 2], dir: [f64; 2], h: f64, big: f64) -> Diff {
    let at = |s: f64| values(basis, p[0] + s * dir[0], p[1] + s * dir[1]);
    let (fp, fm) = (at(h), at(-h));
    let third = |hh: f64| {
        let (a, b, c, d) = (at(2.0 * hh), at(hh), at(-hh), at(-2.0 * hh));
        (0..a.len())
            .map(|i| ((a[i] - 2.0 * b[i] + 2.0 * c[i] - d[i]) / (2.0 * hh.powi(3))).abs())
            .collect::<Vec<_>>()
    };
    let (t1, t2) = (third(big), third(2.0 * big));
    Diff {
        fd: (0..fp.len()).map(|i| (fp[i] - fm[i]) / (2.0 * h)).collect(),
        scale: (0..fp.len())
            .map(|i| fp[i].abs().max(fm[i].abs()).max(1.0))
            .collect(),
        third: (0..fp.len()).map(|i| t1[i].max(t2[i])).collect(),
    }
}

struct Diff {
    fd: Vec<f64>,
    scale: Vec<f64>,
    third: Vec<f64>,
}

#[test]
fn gradients_match_central_differences() {
    let radius = 7.5;
    let basis = ZernikeBasis::new(231, radius, [1.0, -2.0]).unwrap();
    let n = basis.n_terms();
    // Step 1e-5 of the radius: truncation h^2 |f'''| / 6 stays ~1e-10 |f'''| (mm),
    // rounding stays eps |f| / h ~ 1e-11 |f| x (order) per mm.
    let h = 1e-5 * radius;
    let big = 1e-2 * radius;
    let (mut v, mut gx, mut gy) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    for (rho, th) in probe_points() {
        let p = [
            1.0 + radius * rho * th.cos(),
            -2.0 + radius * rho * th.sin(),
        ];
        basis
            .eval_into(p[0], p[1], &mut v, &mut gx, &mut gy)
            .unwrap();
        for (dir, analytic) in [([1.0, 0.0], &gx), ([0.0, 1.0], &gy)] {
            let d = differences(&basis, p, dir, h, big);
            for k in 0..n {
                let order = f64::from(noll_to_nm(k + 1).unwrap().0);
                // Truncation h^2 f'''/6 (f''' estimated, x4 for the estimate's
                // own O(big^2) error) plus rounding: each value carries
                // <= (order + 2) eps |f| from the recurrence, so the difference
                // quotient carries (order + 2) eps |f| / h; x +- h and the
                // normalisation (x - c) / radius are rounded to eps of the
                // coordinates' size, moving f by |grad| eps (|p| + |c| + r rho),
                // i.e. that / h in the quotient; the analytic side carries
                // (order + 2) eps of its own magnitude.
                let trunc = 4.0 * h * h / 6.0 * d.third[k];
                let coords = p[0].abs() + p[1].abs() + 3.0 + radius * rho;
                let grad = gx[k].abs() + gy[k].abs();
                let round = (order + 2.0) * EPS * (d.scale[k] / h + analytic[k].abs())
                    + EPS * coords * grad / h;
                let err = (d.fd[k] - analytic[k]).abs();
                assert!(
                    err <= trunc + round,
                    "dZ{}/d{dir:?} at rho {rho}, theta {th}: fd {} vs {} (tol {})",
                    k + 1,
                    d.fd[k],
                    analytic[k],
                    trunc + round
                );
            }
        }
    }
}

#[test]
fn surface_matches_the_basis_sum() {
    let mut rng = Rng::new(7);
    // Dense and sparse (70 % zeros: whole azimuthal columns and column tails
    // drop out of the folded table) coefficient sets, full and partial orders.
    for (n_terms, zero_prob) in [
        (1, 0.0),
        (5, 0.0),
        (37, 0.0),
        (231, 0.0),
        (37, 0.7),
        (231, 0.7),
    ] {
        let basis = ZernikeBasis::new(n_terms, 20.0, [-4.0, 6.0]).unwrap();
        let mut draw = || {
            if rng.uniform() < zero_prob {
                0.0
            } else {
                rng.range(-500.0, 500.0)
            }
        };
        let c: Vec<f64> = (0..n_terms).map(|_| draw()).collect();
        let surf = ZernikeSurface::new(basis.clone(), c.clone()).unwrap();
        let (mut v, mut gx, mut gy) = (vec![0.0; n_terms], vec![0.0; n_terms], vec![0.0; n_terms]);
        for i in 0..200 {
            // The exact centre first (w = 0: only m <= 1 contributes), then
            // random points out to rho = 1.3.
            let (x, y) = if i == 0 {
                (-4.0, 6.0)
            } else {
                rng.in_disk(1.3 * 20.0, [-4.0, 6.0])
            };
            basis.eval_into(x, y, &mut v, &mut gx, &mut gy).unwrap();
            let dot = |a: &[f64]| a.iter().zip(&c).map(|(a, c)| a * c * 1e-6).sum::<f64>();
            let abs = |a: &[f64]| {
                a.iter()
                    .zip(&c)
                    .map(|(a, c)| (a * c * 1e-6).abs())
                    .sum::<f64>()
            };
            let (h, hx, hy) = surf.height_and_gradient(x, y);
            // Same recurrence, different summation order: the difference is
            // rounding, a few tens of eps of the sum of |c_j Z_j|.
            for (got, want, scale) in [(h, dot(&v), abs(&v)), (hx, dot(&gx), abs(&gx))] {
                assert!((got - want).abs() <= 64.0 * EPS * scale, "{got} vs {want}");
            }
            assert!((hy - dot(&gy)).abs() <= 64.0 * EPS * abs(&gy), "{hy}");
            assert!((surf.height_mm(x, y) - h).abs() <= 64.0 * EPS * abs(&v));
        }
    }
}

#[test]
fn sparse_and_flat_surfaces() {
    let basis = ZernikeBasis::new(231, 10.0, [0.0, 0.0]).unwrap();
    let mut c = vec![0.0; 231];
    c[230] = 50.0; // only Z231 = sqrt(42) R_20^20 sin(20 theta) = sqrt(42) Im((X+iY)^20)
    let surf = ZernikeSurface::new(basis, c).unwrap();
    assert!(!surf.is_flat());
    let (x, y) = (6.0, 7.0);
    let w = nalgebra::Complex::new(0.6, 0.7).powu(20);
    let expect = 50.0 * 42f64.sqrt() * w.im * 1e-6;
    // powu and the recurrence differ by a few ulps of |w|^20 ~ 2e-1.
    assert!((surf.height_mm(x, y) - expect).abs() <= 1e-12 * expect.abs().max(1e-9));

    let flat = ZernikeSurface::flat(25.0, [1.0, 2.0]).unwrap();
    assert!(flat.is_flat());
    assert_eq!(flat.n_terms(), 1);
    assert_eq!(flat.height_and_gradient(3.0, -40.0), (0.0, 0.0, 0.0));
    assert_eq!(flat.height_mm(1e3, 1e3), 0.0);
}

#[test]
fn invalid_basis_parameters_are_errors() {
    use ZernikeError::*;
    let c = [0.0, 0.0];
    for n_terms in [0, MAX_TERMS + 1] {
        let want = Err(InvalidTermCount {
            n_terms,
            max: MAX_TERMS,
        });
        assert_eq!(ZernikeBasis::new(n_terms, 1.0, c), want);
    }
    assert!(ZernikeBasis::new(MAX_TERMS, 1.0, c).is_ok());
    for radius_mm in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let got = ZernikeBasis::new(3, radius_mm, c);
        assert!(
            matches!(got, Err(InvalidRadius { .. })),
            "{radius_mm}: {got:?}"
        );
        assert!(matches!(
            ZernikeSurface::flat(radius_mm, c),
            Err(InvalidRadius { .. })
        ));
    }
    let center_mm = [f64::NAN, 0.0];
    let got = ZernikeBasis::new(3, 1.0, center_mm);
    assert!(matches!(got, Err(InvalidCenter { .. })), "{got:?}");
}

#[test]
fn wrong_lengths_and_non_finite_coefficients_are_errors() {
    use ZernikeError::*;
    let basis = ZernikeBasis::new(3, 1.0, [0.0, 0.0]).unwrap();
    let (mut a, mut b, mut d) = (vec![0.0; 3], vec![0.0; 2], vec![0.0; 3]);
    let want = LengthMismatch {
        what: "d_dx",
        expected: 3,
        actual: 2,
    };
    assert_eq!(basis.eval_into(0.1, 0.2, &mut a, &mut b, &mut d), Err(want));
    assert!(basis.eval_values_into(0.0, 0.0, &mut b).is_err());
    let want = LengthMismatch {
        what: "coefficients_nm",
        expected: 3,
        actual: 4,
    };
    assert_eq!(ZernikeSurface::new(basis.clone(), vec![1.0; 4]), Err(want));
    let want = NonFinite {
        what: "coefficients_nm",
        index: 1,
    };
    assert_eq!(
        ZernikeSurface::new(basis, vec![1.0, f64::NAN, 0.0]),
        Err(want)
    );
}

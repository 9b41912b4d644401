//! Tests of the design's direction geometry.

use super::*;

fn design(dirs: &[f64]) -> Design {
    Design::of_directions(dirs, 1600, 1200)
}

#[test]
fn pair_separation_takes_the_best_non_parallel_pair() {
    // Reflections 10 px apart along v: 0° sees nothing, 90° all of it
    // (10/1200 of s), each diagonal √½ of it (10·√½/1979.9).
    let d = [0.0, 10.0];
    let along = |x: &Design| -> Vec<f64> {
        x.axes
            .iter()
            .map(|a| (a.a * d[0] + a.b * d[1]).abs())
            .collect()
    };
    let diag = 10.0 * std::f64::consts::FRAC_1_SQRT_2 / 1979.898987322333;
    let two = design(&[45.0, -45.0]);
    let s = two.pair_separation(&along(&two)).unwrap();
    assert!((s - diag).abs() < 1e-12, "{s} {diag}");
    // With the plain ones: the pair (90°, a diagonal), the diagonal's.
    let four = design(&[45.0, -45.0, 0.0, 90.0]);
    let s = four.pair_separation(&along(&four)).unwrap();
    assert!((s - diag).abs() < 1e-12, "{s} {diag}");
    // 0° and 90° alone: the pair's smaller, 0.
    let plain = design(&[0.0, 90.0]);
    assert_eq!(plain.pair_separation(&along(&plain)), Some(0.0));
    // Parallel directions have no pair: the smallest.
    let par = design(&[90.0, 270.0]);
    let s = par.pair_separation(&along(&par)).unwrap();
    assert!((s - 10.0 / 1200.0).abs() < 1e-12, "{s}");
    assert_eq!(design(&[]).pair_separation(&[]), None);
}

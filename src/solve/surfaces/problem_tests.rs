//! Tests of the normal equations.

use super::*;
use crate::optics::trace::{Plate, DEFAULT_EDGE_MARGIN_MM};
use crate::optics::zernike::RandomSurfaceSpec;
use crate::optics::zernike::ZernikeSurface;
use crate::solve::surfaces::observe::diagonal;

fn station() -> Station {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("calib/paper-sim.toml");
    Station::load(&p).unwrap()
}

fn with_coeff(s: &ZernikeSurface, k: usize, delta: f64) -> ZernikeSurface {
    let mut c = s.coefficients_nm().to_vec();
    c[k] += delta;
    ZernikeSurface::new(s.basis().clone(), c).unwrap()
}

/// Every Jacobian entry of S2 (and S1) against central differences over
/// the coefficient itself. The curvature term is in (its forward-difference
/// error is ~1e-3 of a term that is itself ~1e-3 of the slope term), so the
/// analytic entries are exact to ~1e-6 relative at worst; the difference
/// quotient over ±1 nm has round-off ~1e-13 px against entries ~1e-3 px/nm.
/// Bound: 1e-7 of the largest entry (measured: passes at 1e-8).
/// (About 85 lines: one scenario, every Jacobian block compared in turn.)
#[test]
fn jacobian_matches_finite_differences() {
    let st = station();
    let e = &st.element;
    let (f, b) = RandomSurfaceSpec {
        n_terms: 15,
        ..Default::default()
    }
    .draw_pair(e.aperture_radius_mm, [0.0, 0.0], 3)
    .unwrap();
    let plate = Plate::new(&st, f.clone(), b.clone(), DEFAULT_EDGE_MARGIN_MM);
    let cam = &st.camera;
    let layout = Layout {
        front_terms: 15,
        back_terms: 15,
        fit_front: true,
        fit_back: true,
        back_piston: true,
        use_s1: true,
        use_s2: true,
    };
    let mut checked = 0;
    for (i, j) in [(640, 470), (600, 500), (690, 440)] {
        let d = cam.ray_direction(i, j);
        let paths = plate.trace_ray(&cam.position_mm, &d, &st.screen);
        let (Ok(s1), Ok(s2)) = (paths.front, paths.back) else {
            continue;
        };
        for (refl, comp) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
            let mut s = [[s1.u, s1.v], [s2.u, s2.v]];
            let mut other = [[f64::NAN; 2]; 2];
            s[refl][comp] -= 1.0; // residual +1 on this component
            other[refl] = s[refl];
            let ob = Observation {
                pixel: [i, j],
                dir: d.into_inner(),
                s: other,
                cov: diagonal([1.0; 4]),
            };
            let obs = Observations {
                camera: cam.position_mm,
                pixels: vec![ob],
                sigma_known: true,
                rejected: Vec::new(),
            };
            let n = accumulate(&obs, &st, &plate, &layout, true);
            for k in 0..15 {
                for back in [false, true] {
                    let Some(col) = (if back {
                        layout.back_col(k)
                    } else {
                        layout.front_col(k)
                    }) else {
                        continue;
                    };
                    let h = 1.0;
                    let coord = |delta: f64| {
                        let mut p = plate.clone();
                        if back {
                            p.back = with_coeff(&b, k, delta)
                        } else {
                            p.front = with_coeff(&f, k, delta)
                        }
                        let t = p.trace_ray(&cam.position_mm, &d, &st.screen);
                        let hit = if refl == 0 { t.front } else { t.back }.unwrap();
                        if comp == 0 {
                            hit.u
                        } else {
                            hit.v
                        }
                    };
                    let fd = (coord(h) - coord(-h)) / (2.0 * h);
                    let jac = n.b[col];
                    let scale = n.b.amax();
                    assert!(
                        (jac - fd).abs() <= 1e-7 * scale,
                        "pixel ({i},{j}) refl {refl} comp {comp} {} k {k}: {jac} vs {fd}",
                        if back { "back" } else { "front" }
                    );
                    checked += 1;
                }
            }
        }
    }
    assert!(checked > 100, "{checked}");
}

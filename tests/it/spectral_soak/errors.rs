//! The soak's errors over reported σ: their RMS, the far ones, and a
//! listing of the pixels that hold them.

use crate::common::spectral::Run;

/// Errors over reported σ beyond which a coordinate counts as far (a
/// Gaussian's |z| exceeds 5 once in 1.7 million).
pub const FAR_Z: f64 = 5.0;

/// RMS of error over reported σ, both coordinates of both reflections
/// found, and how many.
pub fn error_over_sigma(r: &Run) -> (f64, usize) {
    let z2 = z_squares(r);
    let n = z2.len();
    ((z2.iter().sum::<f64>() / n.max(1) as f64).sqrt(), n)
}

/// Coordinates beyond [`FAR_Z`], and the RMS error over σ of the rest.
pub fn tail(r: &Run) -> (usize, f64) {
    let z2 = z_squares(r);
    let all = z2.len();
    let near: Vec<f64> = z2.into_iter().filter(|&z| z <= FAR_Z * FAR_Z).collect();
    let far = all - near.len();
    (
        far,
        (near.iter().sum::<f64>() / near.len().max(1) as f64).sqrt(),
    )
}

/// Prints every pixel with a coordinate beyond [`FAR_Z`] σ of the truth:
/// its errors over σ, points, σ, truth, amplitudes, flags.
pub fn dump_far(r: &Run, engine: &str) {
    for (q, px) in r.view.pixels.iter().enumerate() {
        let p = &r.maps.pixels[q];
        let truth = [px.front, px.back].map(|t| t.ok().map(|t| [t.u, t.v]));
        let mut z = [0.0f64; 4];
        for k in 0..2 {
            if let (Some(t), false) = (truth[k], p.s[k][0].is_nan()) {
                z[2 * k] = (p.s[k][0] - t[0]) / p.std[k][0];
                z[2 * k + 1] = (p.s[k][1] - t[1]) / p.std[k][1];
            }
        }
        if z.iter().any(|z| z.abs() > FAR_Z) {
            eprintln!(
                "{engine} pixel {q}: error/σ {z:.1?}, points {:.2?} ± {:.3?}, truth {truth:.2?}, \
                 amplitudes {:.0?}, {:.2} bins apart, flags {:?}",
                p.s, p.std, p.amp, p.separation_bins, p.flags
            );
        }
    }
}

/// Squared errors over reported σ, both coordinates of both reflections.
fn z_squares(r: &Run) -> Vec<f64> {
    let mut z2 = Vec::new();
    for (q, px) in r.view.pixels.iter().enumerate() {
        let p = &r.maps.pixels[q];
        for (k, truth) in [px.front, px.back].into_iter().enumerate() {
            if let (Ok(t), false) = (truth, p.s[k][0].is_nan()) {
                z2.push(((p.s[k][0] - t.u) / p.std[k][0]).powi(2));
                z2.push(((p.s[k][1] - t.v) / p.std[k][1]).powi(2));
            }
        }
    }
    z2
}

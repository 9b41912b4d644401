//! Renders the report pictures from synthetic data, to look at them:
//! `cargo run --example plot_demo [OUT_DIR]` (default `/tmp/plot-demo`).

use std::path::PathBuf;

use mfd::plot::{coefficient_chart_png, height_map_png};

/// A 120×100 map: a circular aperture (NaN outside) holding astigmatism,
/// coma and a ripple, in nm.
fn surface(w: usize, h: usize) -> Vec<f64> {
    let r0 = 0.48 * w.min(h) as f64;
    (0..w * h)
        .map(|i| {
            let x = ((i % w) as f64 - 0.5 * w as f64) / r0;
            let y = (0.5 * h as f64 - (i / w) as f64) / r0;
            let r2 = x * x + y * y;
            if r2 > 1.0 {
                return f64::NAN;
            }
            let astig = 18.0 * (x * x - y * y);
            let coma = 9.0 * (3.0 * r2 - 2.0) * y;
            astig + coma + 2.5 * (9.0 * x).sin()
        })
        .collect()
}

/// `n` coefficients decaying with j, with uncertainties.
fn coefficients(n: usize) -> (Vec<f64>, Vec<f64>) {
    let v = (0..n)
        .map(|k| 60.0 * ((k as f64 * 1.7).sin()) / (1.0 + 0.15 * k as f64))
        .collect();
    let s = (0..n)
        .map(|k| {
            if k % 7 == 3 {
                f64::NAN
            } else {
                1.0 + 0.02 * k as f64
            }
        })
        .collect();
    (v, s)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = PathBuf::from(std::env::args().nth(1).unwrap_or("/tmp/plot-demo".into()));
    std::fs::create_dir_all(&dir)?;
    let (w, h) = (120, 100);
    let title = "Front surface, piston and tilt removed, RMS 12.3 nm, PV 45.6 nm";
    height_map_png(
        &dir.join("height_map.png"),
        &surface(w, h),
        w,
        h,
        title,
        "nm",
    )?;
    let small = surface(24, 24).iter().map(|v| v * 1e-3).collect::<Vec<_>>();
    height_map_png(
        &dir.join("height_map_small.png"),
        &small,
        24,
        24,
        "Back",
        "nm",
    )?;
    height_map_png(
        &dir.join("height_map_empty.png"),
        &[f64::NAN; 4],
        2,
        2,
        "Empty",
        "nm",
    )?;
    for n in [12, 33, 231] {
        let (v, s) = coefficients(n);
        let t = format!("Front surface, {n} Zernike terms (Noll 4..{})", n + 3);
        coefficient_chart_png(&dir.join(format!("chart_{n}.png")), &v, &s, 4, &t)?;
    }
    println!("pictures in {}", dir.display());
    Ok(())
}

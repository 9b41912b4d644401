//! Renders the report pictures from synthetic data, to look at them:
//! `cargo run --example plot_demo [OUT_DIR]` (default `/tmp/plot-demo`).

use std::path::PathBuf;

use mfd::plot::{coefficient_chart_png, height_map_png, line_plot_png, Panel, Series};

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

/// A convergence study: RMS error (nm) and compute time (s) against frames
/// per direction, with a NaN (a failed run) in one series.
fn convergence(dir: &std::path::Path) -> Result<(), mfd::plot::PlotError> {
    let frames = [4.0, 8.0, 16.0, 32.0, 64.0, 128.0, 256.0];
    let curve = |a: f64, floor: f64| -> Vec<(f64, f64)> {
        frames
            .iter()
            .map(|&n| (n, (a * a / n + floor * floor).sqrt()))
            .collect()
    };
    let spectral = curve(40.0, 0.8);
    let mut phase_step = curve(90.0, 2.5);
    phase_step[3].1 = f64::NAN;
    let bound = curve(25.0, 0.0);
    let time =
        |a: f64, b: f64| -> Vec<(f64, f64)> { frames.iter().map(|&n| (n, a + b * n)).collect() };
    let (t_spectral, t_phase) = (time(0.4, 0.021), time(0.1, 0.012));
    let rms = [
        Series {
            label: "spectral",
            points: &spectral,
        },
        Series {
            label: "phase-step",
            points: &phase_step,
        },
        Series {
            label: "Cramer-Rao bound",
            points: &bound,
        },
    ];
    let secs = [
        Series {
            label: "spectral",
            points: &t_spectral,
        },
        Series {
            label: "phase-step",
            points: &t_phase,
        },
    ];
    let panels = [
        Panel {
            title: "Convergence",
            x_label: "frames per direction",
            y_label: "RMS surface error (nm)",
            log_x: true,
            log_y: true,
            series: &rms,
        },
        Panel {
            title: "Cost",
            x_label: "frames per direction",
            y_label: "compute time (s)",
            log_x: false,
            log_y: false,
            series: &secs,
        },
    ];
    line_plot_png(&dir.join("lines.png"), &panels)
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
    convergence(&dir)?;
    println!("pictures in {}", dir.display());
    Ok(())
}

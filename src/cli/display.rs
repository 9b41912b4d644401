//! `mfd display`: list the monitors, show one pattern fullscreen (for
//! alignment), or render one offscreen into a PNG (for checking).

use std::path::PathBuf;
use std::time::Instant;
#[cfg(feature = "display")]
use std::time::{Duration, SystemTime, UNIX_EPOCH};

#[cfg(feature = "display")]
use anyhow::Context;
use clap::Args;

#[cfg(feature = "display")]
use mfd::acquire::display::Shown;
use mfd::acquire::display::{Dither, OffscreenDisplay, PatternDisplay};
use mfd::acquire::patterns::Pattern;
use mfd::optics::station::DisplayProfile;

/// Arguments of `mfd display`.
#[derive(Args)]
pub struct DisplayArgs {
    /// List the monitors (index, name, resolution, position, refresh rate).
    #[arg(long, conflicts_with_all = ["pattern", "offscreen"])]
    list: bool,
    /// The pattern `direction_deg,tau[,phase_rad]`, e.g. `45,37.5` or `0,10,1.5708`.
    #[arg(long, value_parser = parse_pattern, allow_hyphen_values = true)]
    pattern: Option<Pattern>,
    /// Monitor to cover (index from `--list`).
    #[arg(long, default_value_t = 0)]
    monitor: usize,
    /// Display profile: gamma, settle time, resolution.
    #[arg(long, default_value = "hw/display/mtiph-e2m21gm.toml")]
    profile: PathBuf,
    /// Accept a monitor whose resolution differs from the profile's.
    #[arg(long)]
    any_resolution: bool,
    /// Exact levels (round to nearest) instead of 8×8 Bayer dithering.
    #[arg(long)]
    no_dither: bool,
    /// Render offscreen at the profile's resolution instead of in a window.
    #[arg(long, requires = "png")]
    offscreen: bool,
    /// Where to write the offscreen render: 8-bit grayscale PNG.
    #[arg(long, requires = "offscreen")]
    png: Option<PathBuf>,
    /// Close the window after this many seconds instead of at a key press.
    #[arg(long, value_parser = super::check::non_negative)]
    hold_s: Option<f64>,
}

/// Parses `direction_deg,tau[,phase_rad]`.
fn parse_pattern(text: &str) -> Result<Pattern, String> {
    let bad = || {
        format!("`{text}`: expected direction_deg,tau[,phase_rad] with finite values and tau > 0")
    };
    let parts: Vec<f64> = text
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| bad())?;
    let (direction_deg, tau, phase_rad) = match parts[..] {
        [d, t] => (d, t, 0.0),
        [d, t, p] => (d, t, p),
        _ => return Err(bad()),
    };
    if !(direction_deg.is_finite() && tau.is_finite() && tau > 0.0 && phase_rad.is_finite()) {
        return Err(bad());
    }
    Ok(Pattern {
        direction_deg,
        tau,
        phase_rad,
    })
}

/// Runs `mfd display`.
pub fn run(args: &DisplayArgs) -> anyhow::Result<()> {
    if args.list {
        return list();
    }
    let Some(pattern) = args.pattern else {
        return Err(super::exit::usage(anyhow::anyhow!("give --list, or --pattern direction_deg,tau[,phase_rad] (with --offscreen --png FILE to render offscreen)")));
    };
    let profile = DisplayProfile::load(&args.profile)?;
    let dither = if args.no_dither {
        Dither::None
    } else {
        Dither::Bayer8
    };
    if args.offscreen {
        offscreen(args, &profile, &pattern, dither)
    } else {
        window(args, &profile, pattern, dither)
    }
}

/// Renders offscreen, writes the PNG and prints timings as one JSON line.
fn offscreen(
    args: &DisplayArgs,
    profile: &DisplayProfile,
    pattern: &Pattern,
    dither: Dither,
) -> anyhow::Result<()> {
    let png = args
        .png
        .as_ref()
        .ok_or_else(|| super::exit::usage(anyhow::anyhow!("--offscreen needs --png FILE")))?;
    let mut display = OffscreenDisplay::from_profile(profile, dither)?;
    // The first draw includes the shader's compilation by the driver.
    let t0 = Instant::now();
    display.draw(0, pattern)?;
    let first_ms = t0.elapsed().as_secs_f64() * 1e3;
    let t1 = Instant::now();
    display.draw(0, pattern)?;
    let render_ms = t1.elapsed().as_secs_f64() * 1e3;
    let t2 = Instant::now();
    let frame = display.read_frame()?;
    let readback_ms = t2.elapsed().as_secs_f64() * 1e3;
    let (w, h) = display.resolution();
    let data: Vec<u16> = frame.iter().map(|&v| u16::from(v)).collect();
    mfd::formats::image_io::write_png(png, w, h, 8, &data)?;
    let line = serde_json::json!({
        "event": "offscreen",
        "adapter": display.adapter(),
        "width": w,
        "height": h,
        "first_render_ms": first_ms,
        "render_ms": render_ms,
        "readback_ms": readback_ms,
        "png": png,
    });
    println!("{line}");
    Ok(())
}

#[cfg(feature = "display")]
/// The instant `at` as seconds since the Unix epoch (wall clock), so that
/// another process can compare its own times with it.
fn unix_seconds(at: Instant) -> f64 {
    let now_wall = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap_or_default()
        .as_secs_f64();
    let now = Instant::now();
    now_wall - now.saturating_duration_since(at).as_secs_f64()
        + at.saturating_duration_since(now).as_secs_f64()
}

#[cfg(feature = "display")]
/// One JSON line for a shown pattern.
fn shown_line(monitor: usize, (w, h): (u32, u32), asked: Instant, shown: &Shown) -> String {
    serde_json::json!({
        "event": "shown",
        "monitor": monitor,
        "width": w,
        "height": h,
        "show_ms": shown.presented.duration_since(asked).as_secs_f64() * 1e3,
        "settle_ms": shown.settled.duration_since(shown.presented).as_secs_f64() * 1e3,
        "presented_unix_s": unix_seconds(shown.presented),
        "settled_unix_s": unix_seconds(shown.settled),
    })
    .to_string()
}

#[cfg(feature = "display")]
fn list() -> anyhow::Result<()> {
    for monitor in mfd::acquire::display::window::list_monitors()? {
        println!("{monitor}");
    }
    Ok(())
}

#[cfg(not(feature = "display"))]
fn list() -> anyhow::Result<()> {
    Err(not_built().into())
}

#[cfg(not(feature = "display"))]
fn not_built() -> mfd::acquire::display::DisplayError {
    mfd::acquire::display::DisplayError::NotBuilt {
        backend: "window".into(),
        feature: "display",
    }
}

#[cfg(not(feature = "display"))]
fn window(_: &DisplayArgs, _: &DisplayProfile, _: Pattern, _: Dither) -> anyhow::Result<()> {
    Err(not_built().into())
}

/// Shows the pattern fullscreen until a key is pressed (or `--hold-s`).
#[cfg(feature = "display")]
fn window(
    args: &DisplayArgs,
    profile: &DisplayProfile,
    pattern: Pattern,
    dither: Dither,
) -> anyhow::Result<()> {
    use mfd::acquire::display::window::{run_fullscreen, WindowConfig};

    let mut config = WindowConfig::from_profile(profile, args.monitor, dither)?;
    if args.any_resolution {
        config.expect_resolution = None;
    }
    let hold = match args.hold_s {
        Some(s) => Some(
            Duration::try_from_secs_f64(s)
                .with_context(|| format!("--hold-s {s}: expected ≥ 0"))?,
        ),
        None => None,
    };
    let monitor = args.monitor;
    run_fullscreen(config, move |display| -> anyhow::Result<()> {
        let asked = Instant::now();
        let shown = display.show(0, &pattern)?;
        println!(
            "{}",
            shown_line(monitor, display.resolution(), asked, &shown)
        );
        match hold {
            Some(hold) => std::thread::sleep(hold),
            None => {
                eprintln!("showing {pattern:?}; press a key in the window to close");
                display.wait_key()?;
            }
        }
        Ok(())
    })?
}

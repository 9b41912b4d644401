//! The fullscreen fringe window in a real X server: starts `Xvfb` on a free
//! display with one 1600×1200 screen, runs `mfd display --pattern …` there,
//! screenshots the root window (`xwd | convert`) and compares it with the
//! CPU definition of the pattern within one level. Also measures how long
//! after `presented` the pattern is in the X framebuffer (printed; Xvfb's
//! frame pacing is not judged). Needs `Xvfb`, `xwd`, ImageMagick's
//! `/usr/bin/convert` and a Vulkan driver (apt `xvfb x11-apps imagemagick
//! mesa-vulkan-drivers`, installed by `scripts/install-deps.sh`): without
//! them the test fails saying so.
#![cfg(feature = "display")]

use crate::common;

use std::io::{BufRead, BufReader};
use std::os::unix::fs::PermissionsExt;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use mfd::acquire::display::levels::reference_frame;
use mfd::acquire::display::{Dither, Shading};
use mfd::acquire::patterns::Pattern;
use mfd::optics::station::DisplayProfile;

const PROFILE: &str = "hw/display/mtiph-e2m21gm.toml";

/// An X server this test started; killed (by its own pid) when dropped.
struct Xvfb {
    child: Child,
    display: String,
}

impl Drop for Xvfb {
    fn drop(&mut self) {
        if let Err(e) = self.child.kill() {
            eprintln!("stopping Xvfb {}: {e}", self.display);
        }
        let _ = self.child.wait();
    }
}

fn require_tool(path: &str) {
    let found = if path.starts_with('/') {
        Path::new(path).exists()
    } else {
        Command::new("sh")
            .args(["-c", &format!("command -v {path}")])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    assert!(
        found,
        "`{path}` not found: this test needs apt packages xvfb x11-apps imagemagick \
         mesa-vulkan-drivers (scripts/install-deps.sh installs them)"
    );
}

/// Starts Xvfb on a display number it picks itself (`-displayfd`).
fn start_xvfb() -> Xvfb {
    require_tool("Xvfb");
    let mut child = Command::new("Xvfb")
        .args([
            "-displayfd",
            "1",
            "-screen",
            "0",
            "1600x1200x24",
            "-nolisten",
            "tcp",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("cannot start Xvfb");
    let mut line = String::new();
    let stdout = child.stdout.take().expect("Xvfb stdout");
    BufReader::new(stdout)
        .read_line(&mut line)
        .expect("reading Xvfb's display number");
    let number: u32 = line
        .trim()
        .parse()
        .unwrap_or_else(|_| panic!("Xvfb gave no display number (got {line:?})"));
    Xvfb {
        child,
        display: format!(":{number}"),
    }
}

/// A private 0700 `XDG_RUNTIME_DIR` (Mesa complains without one).
fn runtime_dir() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o700)).unwrap();
    dir
}

fn mfd(display: &str, runtime: &Path, args: &[&str]) -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_mfd"));
    cmd.args(args)
        .env("DISPLAY", display)
        .env("XDG_RUNTIME_DIR", runtime)
        .env_remove("WAYLAND_DISPLAY")
        .current_dir(env!("CARGO_MANIFEST_DIR"));
    cmd
}

/// The red channel of a screenshot of the whole root window, row-major.
fn screenshot(display: &str, png: &Path) -> (u32, u32, Vec<u8>) {
    require_tool("xwd");
    require_tool("/usr/bin/convert");
    let script = format!(
        "xwd -root -silent -display {display} | /usr/bin/convert xwd:- {}",
        png.display()
    );
    let status = Command::new("sh").args(["-c", &script]).status().unwrap();
    assert!(status.success(), "screenshot failed: {script}");
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(png).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let channels = info.color_type.samples();
    assert_eq!(
        info.bit_depth,
        png::BitDepth::Eight,
        "{:?}",
        info.color_type
    );
    let red = buf[..info.buffer_size()]
        .chunks_exact(channels)
        .map(|px| {
            if channels >= 3 {
                assert!(px[0] == px[1] && px[1] == px[2], "not gray: {px:?}");
            }
            px[0]
        })
        .collect();
    (info.width, info.height, red)
}

/// Largest level difference between a screenshot and the expected frame.
fn worst_difference(got: &[u8], want: &[u8]) -> i32 {
    got.iter()
        .zip(want)
        .map(|(&a, &b)| (i32::from(a) - i32::from(b)).abs())
        .max()
        .unwrap_or(i32::MAX)
}

fn unix_now() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_secs_f64()
}

#[test]
fn window_shows_the_pattern_on_the_whole_monitor() {
    let xvfb = start_xvfb();
    let runtime = runtime_dir();
    let shots = tempfile::tempdir().unwrap();

    let list = mfd(&xvfb.display, runtime.path(), &["display", "--list"])
        .output()
        .unwrap();
    let listed = String::from_utf8_lossy(&list.stdout);
    println!("mfd display --list:\n{listed}");
    assert!(
        list.status.success(),
        "{}",
        String::from_utf8_lossy(&list.stderr)
    );
    assert!(listed.contains("1600x1200 at (0, 0)"), "{listed}");

    let pattern = Pattern {
        direction_deg: 45.0,
        tau: 37.5,
        phase_rad: 0.7,
    };
    let profile = DisplayProfile::load(&common::repo(PROFILE)).unwrap();
    let shading = Shading::from_profile(&profile, Dither::None).unwrap();
    let expected = reference_frame(&pattern, 1600, 1200, &shading);

    let mut child = mfd(
        &xvfb.display,
        runtime.path(),
        &[
            "display",
            "--pattern",
            "45,37.5,0.7",
            "--no-dither",
            "--hold-s",
            "8",
            "--profile",
            PROFILE,
        ],
    )
    .stdout(Stdio::piped())
    .spawn()
    .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    assert!(
        !line.is_empty(),
        "mfd display printed nothing (see its stderr above)"
    );
    let shown: serde_json::Value = serde_json::from_str(&line).unwrap();
    let presented = shown["presented_unix_s"].as_f64().unwrap();
    let settled = shown["settled_unix_s"].as_f64().unwrap();
    assert_eq!(
        (shown["width"].as_u64(), shown["height"].as_u64()),
        (Some(1600), Some(1200))
    );

    // How soon after `presented` is the pattern in the X framebuffer? The
    // first screenshot starting after the line arrived gives an upper bound.
    let started = unix_now();
    let (w, h, first) = screenshot(&xvfb.display, &shots.path().join("first.png"));
    assert_eq!((w, h), (1600, 1200));
    let first_worst = worst_difference(&first, &expected);

    // After `settled` the screen must show the pattern: within one level.
    let wait = settled - unix_now();
    if wait > 0.0 {
        std::thread::sleep(Duration::from_secs_f64(wait));
    }
    let (_, _, shot) = screenshot(&xvfb.display, &shots.path().join("settled.png"));
    let worst = worst_difference(&shot, &expected);

    println!(
        "Xvfb: show (draw + present) {:.1} ms; screenshot started {:.1} ms after presented \
         {} the pattern (max diff {first_worst}); profile settle {:.1} ms; after settle max diff {worst}",
        shown["show_ms"].as_f64().unwrap_or(f64::NAN),
        (started - presented) * 1e3,
        if first_worst <= 1 { "already showed" } else { "did not yet show" },
        (settled - presented) * 1e3,
    );
    assert!(
        worst <= 1,
        "screenshot after settle differs by up to {worst} levels"
    );

    let deadline = Instant::now() + Duration::from_secs(30);
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if Instant::now() > deadline {
            child.kill().unwrap();
            panic!("mfd display did not close after --hold-s");
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    assert!(status.success(), "mfd display failed: {status}");
}

#[test]
fn a_missing_monitor_is_an_error_naming_it() {
    let xvfb = start_xvfb();
    let runtime = runtime_dir();
    let out = mfd(
        &xvfb.display,
        runtime.path(),
        &[
            "display",
            "--pattern",
            "0,10",
            "--monitor",
            "3",
            "--hold-s",
            "0",
        ],
    )
    .output()
    .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("monitor 3") && err.contains("no such monitor"),
        "{err}"
    );
}

/// A whole `mfd measure` with the schedule on the (virtual) monitor: the
/// window's event loop owns the main thread, the sequencer runs on its
/// worker; every pattern is recorded and the acquisition reads back.
#[test]
fn measure_shows_the_schedule_on_a_monitor() {
    let xvfb = start_xvfb();
    let runtime = runtime_dir();
    let out_dir = tempfile::tempdir().unwrap();
    let station = common::public_small().join("station.toml");
    let out = mfd(
        &xvfb.display,
        runtime.path(),
        &[
            "measure",
            "--station",
            station.to_str().unwrap(),
            "--camera",
            "sim",
            "--display",
            "0",
            "--tau-stop",
            "4",
            "--no-reconstruct",
            "--out",
            out_dir.path().to_str().unwrap(),
        ],
    )
    .output()
    .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "{text}");
    // τ 0.2 … 4 step 0.2 on ±45°: 40 patterns.
    let acq =
        mfd::acquire::acquisition::Acquisition::open(&out_dir.path().join("acquisition")).unwrap();
    assert_eq!(acq.complete_frames(), 40, "{text}");
}

//! The element soak of issue 36: stations and plates drawn at random over
//! what a lab brings (thickness 1–30 mm, index 1.45–2.3, wedge 0–60 arcmin
//! at any azimuth, declared or not, element tilt up to 2°, lens distortion,
//! a cover glass, surfaces 10 nm to 1 µm RMS, camera and screen heights,
//! tilts and lenses, noise 2–5 %, the falloff on τ or on the screen
//! period), each run through the whole chain at a modest size (the paper's
//! field of view on a 162 × 121 sensor, 400 frames), and judged:
//!
//! - surfaces reported: each surface's actual error over the error it
//!   reports (Noll 4+ RMS) within [`PER_DRAW`]; over all draws the RMS of
//!   those ratios within [`OVERALL`];
//! - surfaces withheld, or the chain refused: a reason in words (a wedge
//!   the station cannot show, a wedge seen but not declared, a plate the
//!   schedule cannot resolve); counted, and bounded ([`MAX_REFUSED`]).
//!
//! - `MFD_WEDGE_SOAK_DRAWS=n`: draw `n` (default 100, ~3 minutes on 2 cores
//!   in the test profile); `MFD_WEDGE_SOAK_SEED=s`: seed `s` alone;
//!   `MFD_WEDGE_SOAK_FAILURES=path`: where failing seeds are appended
//!   (default `target/wedge-soak-failures.txt`); with one seed,
//!   `MFD_SOAK_NOISE_STUDY=k`: that draw under `k` noise realisations,
//!   its bias and scatter against its report ([`noise_study`]), not judged.

use std::io::Write;
use std::path::{Path, PathBuf};

use mfd::acquire::patterns::Schedule;
use mfd::optics::station::{
    CameraProfile, CoverGlassFile, DisplayProfile, DistortionFile, Station, SymmetricLayout, Wedge,
};
use mfd::sim::Falloff;
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

use super::chain::{noise_study, run_scored, Scene};

/// One draw's actual error over its reported error, per reported surface:
/// the RMS of ~33 unit z-scores lies within 0.6–1.4 at 4σ; the band is
/// wider for what a 400-frame acquisition's few pixels leave (a thin or
/// steep plate keeps a few hundred pixels and a dozen terms).
const PER_DRAW: std::ops::RangeInclusive<f64> = 0.4..=2.0;

/// The RMS over all draws of error over reported (the honesty
/// band).
const OVERALL: std::ops::RangeInclusive<f64> = 0.6..=1.6;

/// At most this share of draws may end refused or with both surfaces
/// withheld (thin plates on a schedule not designed for them, wedges off
/// the screen).
const MAX_REFUSED: f64 = 0.35;

const FIRST_SEED: u64 = 36_000;

// Seed 36071 (a 1.05 mm plate, 7 arcmin declared, tilted 1.6°) was a
// confident wrong answer: the surface-domain fit from the per-pixel
// surfaces converged to a second maximum, 3.1× and 2.7× the reported
// error; the fit is now also run from the plate as made and the more
// likely answer kept (`solve::direct::Starts`). It is among the default
// draws and asserted like any other.

/// Every drawn parameter of one element and station.
#[derive(Debug, Clone)]
pub struct Draw {
    pub seed: u64,
    pub thickness_mm: f64,
    pub index: f64,
    pub wedge: Wedge,
    pub declared: bool,
    pub element_tilt_deg: [f64; 2],
    pub k1: Option<f64>,
    pub cover_glass_mm: Option<f64>,
    pub surface_rms_nm: f64,
    pub height_mm: [f64; 2],
    pub camera_tilt_deg: f64,
    pub focal_length_mm: f64,
    pub noise: f64,
    pub falloff: Falloff,
}

impl Draw {
    pub fn new(seed: u64) -> Self {
        let mut r = Xoshiro256PlusPlus::seed_from_u64(seed);
        let log_uniform = |r: &mut Xoshiro256PlusPlus, lo: f64, hi: f64| {
            (lo.ln() + r.random::<f64>() * (hi.ln() - lo.ln())).exp()
        };
        let thickness_mm = log_uniform(&mut r, 1.0, 30.0);
        let index = r.random_range(1.45..2.3);
        // A quarter parallel, the rest 0–60 arcmin at any azimuth.
        let wedge = if r.random::<f64>() < 0.25 {
            Wedge::NONE
        } else {
            Wedge {
                arcmin: r.random_range(0.0..60.0),
                azimuth_deg: r.random_range(0.0..360.0),
            }
        };
        let declared = r.random::<f64>() < 0.75;
        let tilt_r = 2.0 * r.random::<f64>().sqrt();
        let tilt_a = r.random_range(0.0..std::f64::consts::TAU);
        Draw {
            seed,
            thickness_mm,
            index,
            wedge,
            declared,
            element_tilt_deg: [tilt_r * tilt_a.cos(), tilt_r * tilt_a.sin()],
            k1: (r.random::<f64>() < 0.5).then(|| r.random_range(-0.12..0.08)),
            cover_glass_mm: (r.random::<f64>() < 0.5).then(|| r.random_range(1.0..2.0)),
            surface_rms_nm: log_uniform(&mut r, 10.0, 1000.0),
            height_mm: [r.random_range(650.0..950.0), r.random_range(650.0..950.0)],
            camera_tilt_deg: r.random_range(10.0..20.0),
            focal_length_mm: r.random_range(14.0..20.0),
            noise: r.random_range(0.02..0.05),
            falloff: if r.random::<bool>() {
                Falloff::Tau
            } else {
                Falloff::ScreenPeriod
            },
        }
    }

    /// The true station; `None` where the drawn geometry is not a station
    /// (counted apart: it is the draw, not mfd, that is impossible).
    pub fn station(&self) -> Option<Station> {
        let camera = CameraProfile {
            format: "mfd-camera-profile/1".into(),
            model: "binned".into(),
            resolution: [162, 121],
            pixel_pitch_um: 30.0,
            bit_depth: 12,
            distortion: self.k1.map(|k1| DistortionFile {
                model: "brown-conrady".into(),
                k: Some([k1, 0.0, 0.0]),
                p: Some([0.0, 0.0]),
            }),
        };
        let display = DisplayProfile {
            cover_glass: self.cover_glass_mm.map(|t| CoverGlassFile {
                thickness_mm: t,
                refractive_index: 1.52,
            }),
            ..DisplayProfile::paper_lcd()
        };
        let mut element = SymmetricLayout::paper_element();
        element.thickness_mm = self.thickness_mm;
        element.refractive_index = self.index;
        let mut s = SymmetricLayout {
            camera_height_mm: self.height_mm[0],
            screen_height_mm: self.height_mm[1],
            tilt_deg: self.camera_tilt_deg,
            focal_length_mm: self.focal_length_mm,
            element,
        }
        .build(&camera, &display)
        .ok()?;
        s.element.pose.tilt_deg = self.element_tilt_deg;
        s.element.wedge = self.wedge;
        Station::from_file(&s.to_file(), std::path::Path::new("<draw>")).ok()
    }
}

/// `name`'s value as a whole number, if set (the soaks' knobs).
pub fn env_u64(name: &str) -> Option<u64> {
    std::env::var(name).ok().map(|v| {
        v.trim()
            .parse()
            .unwrap_or_else(|_| panic!("{name}={v}: expected a whole number"))
    })
}

/// Prints a failing seed and appends it with its draw to `path` (the
/// soaks' failure files).
pub fn save_failure_to(path: &Path, seed: u64, draw: &dyn std::fmt::Debug, why: &str) {
    eprintln!("seed {seed} FAILED: {why}\n  {draw:?}");
    if let Some(dir) = path.parent() {
        let _ = std::fs::create_dir_all(dir);
    }
    if let Ok(mut f) = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
    {
        let _ = writeln!(f, "seed {seed} failed: {why}\n  {draw:?}");
    }
}

fn save_failure(draw: &Draw, why: &str) {
    let path = std::env::var_os("MFD_WEDGE_SOAK_FAILURES").map_or_else(
        || PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/wedge-soak-failures.txt"),
        PathBuf::from,
    );
    save_failure_to(&path, draw.seed, draw, why);
}

#[test]
fn random_plates_are_measured_honestly_or_refused_in_words() {
    let seeds: Vec<u64> = match env_u64("MFD_WEDGE_SOAK_SEED") {
        Some(s) => vec![s],
        None => (FIRST_SEED..FIRST_SEED + env_u64("MFD_WEDGE_SOAK_DRAWS").unwrap_or(100)).collect(),
    };
    let schedule = Schedule {
        tau_start: 0.5,
        tau_stop: 100.0,
        tau_step: 0.5,
        ..Schedule::default()
    };
    let (mut ratios, mut failed, mut refused, mut impossible) = (Vec::new(), Vec::new(), 0, 0);
    let mut worst: (f64, u64) = (1.0, 0);
    for &seed in &seeds {
        let draw = Draw::new(seed);
        eprintln!("seed {seed}: {draw:?}");
        let Some(truth) = draw.station() else {
            impossible += 1;
            continue;
        };
        let scene = Scene {
            declared: if draw.declared {
                draw.wedge
            } else {
                Wedge::NONE
            },
            truth,
            seed,
            noise: draw.noise,
            patterns: schedule.patterns(),
            surface_rms_nm: draw.surface_rms_nm,
            falloff: draw.falloff,
        };
        if let Some(k) = env_u64("MFD_SOAK_NOISE_STUDY") {
            noise_study(&scene, k);
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let outcome = std::panic::catch_unwind(|| run_scored(&scene, dir.path(), false));
        match outcome {
            Err(_) => {
                save_failure(&draw, "panicked");
                failed.push(seed);
            }
            Ok(Err(msg)) => {
                eprintln!("seed {seed}: refused: {msg}");
                if msg.trim().is_empty() {
                    save_failure(&draw, "refused without a reason");
                    failed.push(seed);
                }
                refused += 1;
            }
            Ok(Ok(o)) => {
                eprintln!(
                    "seed {seed}: error {:.2?} nm, reported {:.2?}, withheld {:?}; {}",
                    o.error,
                    o.reported,
                    o.withheld,
                    o.wedge_note.as_deref().unwrap_or("")
                );
                let mut any = false;
                for k in 0..2 {
                    if o.withheld[k].is_some() {
                        continue;
                    }
                    any = true;
                    let ratio = o.error[k] / o.reported[k];
                    ratios.push(ratio);
                    if (ratio - 1.0).abs() > (worst.0 - 1.0).abs() {
                        worst = (ratio, seed);
                    }
                    if !PER_DRAW.contains(&ratio) {
                        let face = ["front", "back"][k];
                        save_failure(&draw, &format!("{face}: error over reported {ratio:.2}"));
                        failed.push(seed);
                    }
                }
                if !any {
                    refused += 1;
                }
            }
        }
    }
    let rms = (ratios.iter().map(|r| r * r).sum::<f64>() / ratios.len().max(1) as f64).sqrt();
    let ran = seeds.len() - impossible;
    println!(
        "wedge-soak-figures: {{\"draws\": {}, \"not_a_station\": {impossible}, \"surfaces_judged\": {}, \
         \"rms_error_over_reported\": {rms:.3}, \"worst\": {:.3}, \"worst_seed\": {}, \
         \"refused_or_withheld\": {refused}, \"failed\": {failed:?}}}",
        seeds.len(),
        ratios.len(),
        worst.0,
        worst.1
    );
    assert!(failed.is_empty(), "failing seeds: {failed:?}");
    if seeds.len() > 1 {
        assert!(OVERALL.contains(&rms), "RMS error over reported {rms:.3}");
        assert!(
            refused as f64 <= MAX_REFUSED * ran as f64,
            "{refused} of {ran} draws refused or withheld"
        );
    }
}

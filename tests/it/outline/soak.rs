//! The outline soak: elements of random outline (rectangles 35–70 mm of
//! any aspect up to 2.5 and rotation, star-shaped polygons of 3–8 vertices
//! 18–35 mm from the centre,
//! convex or not, off-centre), thickness, index, surfaces and noise, each
//! run through the whole chain on the paper's field of view at a modest
//! size (162 × 121 pixels, 400 frames), and judged: each reported
//! surface's actual error over the outline against the error it reports
//! over the outline within [`PER_DRAW`], their RMS over all draws within
//! [`OVERALL`]; a refusal must say why. The disk soak is the wedge soak.
//!
//! `MFD_OUTLINE_SOAK_DRAWS=n` (default 16, ~1 minute on 2 cores in the
//! test profile), `MFD_OUTLINE_SOAK_SEED=s` (with `MFD_SOAK_NOISE_STUDY=k`:
//! that draw under `k` noise realisations, not judged); failing seeds are
//! appended to `target/outline-soak-failures.txt`.

use std::path::{Path, PathBuf};

use mfd::acquire::patterns::Schedule;
use mfd::optics::outline::Shape;
use mfd::optics::station::{Station, Wedge};
use mfd::sim::Falloff;
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

use crate::wedge::chain::{binned_paper_station, noise_study, run_scored, Scene};
use crate::wedge::soak::{env_u64, save_failure_to};

/// As the wedge soak's: the RMS of ~33 unit z-scores within 0.6–1.4 at
/// 4σ, wider for the few pixels and terms a small outline keeps.
const PER_DRAW: std::ops::RangeInclusive<f64> = 0.4..=2.0;

/// The RMS over all draws of error over reported.
const OVERALL: std::ops::RangeInclusive<f64> = 0.6..=1.6;

const FIRST_SEED: u64 = 40_000;

// Seed 40011 (a 59.9 × 25.1 mm rectangle, 8.1 mm, n 1.49) was a confident
// wrong answer: the surface-domain fit from the per-pixel surfaces chose 36
// terms and a maximum less likely than the plate as made's (its back 2.07×
// its report; on other noise draws up to 8×). The fit now keeps the more
// likely of the two starts (`solve::direct::Starts`); the seed is among the
// default draws and asserted.

/// One draw.
#[derive(Debug, Clone)]
struct Draw {
    seed: u64,
    shape: Shape,
    centre: [f64; 2],
    thickness_mm: f64,
    index: f64,
    surface_rms_nm: f64,
    noise: f64,
}

impl Draw {
    fn new(seed: u64) -> Self {
        let mut r = Xoshiro256PlusPlus::seed_from_u64(seed);
        let shape = if r.random_bool(0.5) {
            let a = r.random_range(35.0..70.0);
            let aspect: f64 = r.random_range(1.0..2.5);
            Shape::Rectangle {
                sides_mm: [a, a / aspect],
                rotation_deg: r.random_range(-180.0..180.0),
            }
        } else {
            // Star-shaped about the centre: sorted angles, radii 18–35 mm.
            let n = r.random_range(3..=8);
            let mut angles: Vec<f64> = (0..n)
                .map(|_| r.random_range(0.0..std::f64::consts::TAU))
                .collect();
            angles.sort_by(f64::total_cmp);
            let vertices_mm = angles
                .iter()
                .map(|t| {
                    let rho = r.random_range(18.0..35.0);
                    [rho * t.cos(), rho * t.sin()]
                })
                .collect();
            Shape::Polygon { vertices_mm }
        };
        Draw {
            seed,
            shape,
            centre: [r.random_range(-3.0..3.0), r.random_range(-3.0..3.0)],
            thickness_mm: r.random_range(4.0..20.0),
            index: r.random_range(1.45..2.0),
            surface_rms_nm: 10f64.powf(r.random_range(1.3..2.3)),
            noise: r.random_range(0.02..0.05),
        }
    }

    /// The station, through its file (`None`: an outline the station
    /// refuses, e.g. a degenerate polygon, which is counted, not run).
    fn station(&self) -> Option<Station> {
        let mut s = binned_paper_station(self.thickness_mm, self.index);
        s.element.aperture_center_mm = self.centre.into();
        // Polygon vertices are drawn about the origin; the aperture centre
        // moves the rectangle only, as the spec places it.
        if let Shape::Polygon { vertices_mm } = &self.shape {
            let v = vertices_mm
                .iter()
                .map(|p| [p[0] + self.centre[0], p[1] + self.centre[1]])
                .collect();
            s.element.outline = Shape::Polygon { vertices_mm: v };
        } else {
            s.element.outline = self.shape.clone();
        }
        s.element.aperture_radius_mm = s.element.outline().circumradius_mm();
        Station::from_file(&s.to_file(), Path::new("<draw>")).ok()
    }
}

fn save_failure(draw: &Draw, why: &str) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/outline-soak-failures.txt");
    save_failure_to(&path, draw.seed, draw, why);
}

#[test]
fn random_outlines_are_measured_honestly_or_refused_in_words() {
    let seeds: Vec<u64> = match env_u64("MFD_OUTLINE_SOAK_SEED") {
        Some(s) => vec![s],
        None => {
            (FIRST_SEED..FIRST_SEED + env_u64("MFD_OUTLINE_SOAK_DRAWS").unwrap_or(16)).collect()
        }
    };
    let schedule = Schedule {
        tau_start: 0.5,
        tau_stop: 100.0,
        tau_step: 0.5,
        ..Schedule::default()
    };
    let (mut ratios, mut failed, mut refused, mut impossible) = (Vec::new(), Vec::new(), 0, 0);
    for &seed in &seeds {
        let draw = Draw::new(seed);
        eprintln!("seed {seed}: {draw:?}");
        let Some(truth) = draw.station() else {
            impossible += 1;
            continue;
        };
        let scene = Scene {
            truth,
            declared: Wedge::NONE,
            seed,
            noise: draw.noise,
            patterns: schedule.patterns(),
            surface_rms_nm: draw.surface_rms_nm,
            falloff: Falloff::Tau,
        };
        if let Some(k) = env_u64("MFD_SOAK_NOISE_STUDY") {
            noise_study(&scene, k);
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        match std::panic::catch_unwind(|| run_scored(&scene, dir.path(), false)) {
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
                    "seed {seed}: error {:.2?} nm, reported {:.2?}, withheld {:?}",
                    o.error, o.reported, o.withheld
                );
                for k in 0..2 {
                    if o.withheld[k].is_some() {
                        continue;
                    }
                    let ratio = o.error[k] / o.reported[k];
                    ratios.push(ratio);
                    if !PER_DRAW.contains(&ratio) {
                        let face = ["front", "back"][k];
                        save_failure(&draw, &format!("{face}: error over reported {ratio:.2}"));
                        failed.push(seed);
                    }
                }
            }
        }
    }
    let rms = (ratios.iter().map(|r| r * r).sum::<f64>() / ratios.len().max(1) as f64).sqrt();
    eprintln!(
        "outline soak: {} draws, {} surfaces judged, RMS error/reported {rms:.3}, {refused} \
         refused, {impossible} outlines the station refused, failing {failed:?}",
        seeds.len(),
        ratios.len()
    );
    assert!(failed.is_empty(), "failing seeds: {failed:?}");
    if seeds.len() > 1 {
        // A soak that judges nothing tests nothing: at least a third of the
        // 2 × draws surfaces must be reported (the rest withheld in words,
        // as small outlines on this 1.6 mm-per-pixel sensor often are).
        assert!(
            3 * ratios.len() >= 2 * seeds.len(),
            "too few surfaces judged: {} of {}",
            ratios.len(),
            2 * seeds.len()
        );
        assert!(
            OVERALL.contains(&rms),
            "RMS of error over reported {rms:.3}"
        );
    }
}

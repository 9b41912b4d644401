//! The spectral stage's soak over schedules (issue 39: "the statistics
//! engine for any schedule mfd accepts"): random schedules (two to four
//! directions at any angle, unequal τ spans and frame counts, grids with
//! gaps, irregular τ, repeats, phase shifts, shuffled or reversed order)
//! on random plates (3–30 mm, n 1.45–2.3), noise 1–8 %, 8-, 12- and
//! 16-bit cameras,
//! either falloff, each acquisition fitted by both engines. Each draw must
//! give, from the statistics, the series' answers: the same flags and the
//! same points to 0.05 σ (the derivation is
//! `spectral_engines::the_statistics_give_the_series_answers`'); and where
//! the series finds points, the errors over their reported σ are unit
//! within their sampling scatter.
//!
//! - `MFD_SPECTRAL_SOAK=n`: draw `n` schedules (default: the first 8 and
//!   [`FIXED_SEEDS`], about 16 s on 2 cores in the test profile).
//! - `MFD_SPECTRAL_SOAK_SEED=s`: run seed `s` alone.
//! - `MFD_SPECTRAL_SOAK_DUMP=1`: print every pixel with a point beyond
//!   5 σ of the truth.
//! - Failing seeds, with their draw, are appended to
//!   `target/spectral-soak-failures.txt` under the crate.

use std::io::Write;

use mfd::acquire::patterns::{FringeAxis, Pattern};
use mfd::sim::SimParams;
use mfd::solve::spectral::{Engine, PixelFlags, SpectralMaps};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

use crate::common::env_u64;
use crate::common::spectral::*;
use errors::{dump_far, error_over_sigma, tail, FAR_Z};

mod errors;

/// Seeds of the default run start here.
const FIRST_SEED: u64 = 39_000;

/// Draws beyond the default run's first eight that failed and were fixed,
/// run by default too (each about a second): 39032 and 39039, phases
/// alternating on τ grids, whose periodogram copies at `±μ + 1/(2Δ)` the
/// search did not know (`periodogram::Aliases`); 39049, four directions
/// with gapped grids, whose pair start sat on the window's sidelobe
/// (`Aliases::near`); 39058, a gapped grid where the statistics held the
/// peak against one sinusoid's residual (the pair's second reflection in
/// it) and a 0.9-bin pair was judged on the one-reflection fit's beat-made
/// falloff (`pixel::BEAT_KAPPA`).
const FIXED_SEEDS: [u64; 4] = [39_032, 39_039, 39_049, 39_058];

/// The statistics' points against the series': the two engines' least
/// squares agree to the node tolerance, so they part only where a stopping
/// test is borderline, within ~√1e-3 σ of the minimum each (0.05 σ with
/// margin; `spectral_engines`).
const SAME_POINT_SIGMAS: f64 = 0.05;

/// Of the pixels whose points the series reports, those the statistics may
/// not: 1 in 200 (`spectral_engines`: a detection or resolution test near
/// its threshold, which the engines make on different spectra — the
/// whole one and the band's). Pixels whose points only the statistics
/// report (its band keeps the search near the station's prediction) are
/// counted and printed, not failed: the issue asks the statistics for the
/// series' answers, and their errors are held to their σ below.
const LOST_FRACTION: f64 = 0.005;

/// One random acquisition.
#[derive(Debug, Clone)]
struct Draw {
    seed: u64,
    thickness_mm: f64,
    index: f64,
    noise: f64,
    bit_depth: u32,
    screen_period_falloff: bool,
    /// Per direction: angle, τ from, τ to, frames, τ layout.
    directions: Vec<(f64, f64, f64, usize, Layout)>,
    phases: Phases,
    order: Order,
}

#[derive(Debug, Clone, Copy)]
enum Layout {
    Grid,
    /// A grid with a band of its τ left out.
    Gap,
    /// τ drawn uniformly over the span.
    Irregular,
    /// Every τ of a grid shown twice.
    Repeats,
}

#[derive(Debug, Clone, Copy)]
enum Phases {
    Zero,
    /// 0 and π/2 alternately.
    Alternate,
    /// Uniform on [0, 2π) per frame.
    Random,
}

#[derive(Debug, Clone, Copy)]
enum Order {
    /// Direction after direction, τ rising.
    Blocks,
    /// Direction after direction, τ falling.
    Falling,
    /// Every frame in random order.
    Shuffled,
}

/// Directions that see the pair apart: the station's back-minus-front
/// offset lies along the screen's u, so a direction within 60° of 90°
/// projects it to under half (90° itself cannot tell the two points' v
/// apart, `spectral_sim`); each draw has at least two non-parallel
/// directions within 60° of u, and any others.
const ANGLES: [f64; 8] = [45.0, -45.0, 0.0, 30.0, -30.0, 60.0, -60.0, 90.0];

fn draw(seed: u64) -> Draw {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let st = station(10.0);
    let (w, h) = (st.screen.width, st.screen.height);
    let n_dirs = rng.random_range(2..=4);
    let mut angles: Vec<f64> = Vec::new();
    while angles.len() < n_dirs {
        let a = ANGLES[rng.random_range(0..ANGLES.len())];
        let resolving = angles
            .iter()
            .filter(|x| x.to_radians().cos().abs() >= 0.5)
            .count();
        // The first two resolve the pair.
        if angles.contains(&a) || (resolving < 2 && a.to_radians().cos().abs() < 0.5) {
            continue;
        }
        angles.push(a);
    }
    let layouts = [
        Layout::Grid,
        Layout::Gap,
        Layout::Irregular,
        Layout::Repeats,
    ];
    let directions = angles
        .into_iter()
        .map(|a| {
            let max = FringeAxis::new(a, w, h).max_tau().min(200.0);
            let from = rng.random_range(0.2..3.0);
            let to = max * rng.random_range(0.5..1.0);
            let frames = rng.random_range(150..=700);
            (a, from, to, frames, layouts[rng.random_range(0..4)])
        })
        .collect();
    Draw {
        seed,
        thickness_mm: rng.random_range(3.0..30.0),
        index: rng.random_range(1.45..2.3),
        noise: rng.random_range(0.01..0.08),
        bit_depth: [8, 12, 16][rng.random_range(0..3)],
        screen_period_falloff: rng.random_bool(0.5),
        directions,
        phases: [Phases::Zero, Phases::Alternate, Phases::Random][rng.random_range(0..3)],
        order: [Order::Blocks, Order::Falling, Order::Shuffled][rng.random_range(0..3)],
    }
}

/// The draw's frames in display order.
fn patterns(d: &Draw) -> Vec<Pattern> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(d.seed ^ 0x39);
    let mut blocks: Vec<Vec<Pattern>> = Vec::new();
    for &(direction_deg, from, to, frames, layout) in &d.directions {
        let grid = |n: usize| -> Vec<f64> {
            (0..n)
                .map(|k| from + (to - from) * k as f64 / (n - 1) as f64)
                .collect()
        };
        let mut taus: Vec<f64> = match layout {
            Layout::Grid => grid(frames),
            Layout::Gap => {
                // A fifth to a third of the span missing, away from its ends.
                let g0 = from + (to - from) * rng.random_range(0.2..0.5);
                let g1 = g0 + (to - from) * rng.random_range(0.2..0.33);
                let all = grid(frames);
                all.into_iter().filter(|&t| t < g0 || t > g1).collect()
            }
            Layout::Irregular => (0..frames).map(|_| rng.random_range(from..=to)).collect(),
            Layout::Repeats => grid(frames / 2).into_iter().flat_map(|t| [t, t]).collect(),
        };
        taus.sort_by(f64::total_cmp);
        if matches!(d.order, Order::Falling) {
            taus.reverse();
        }
        let block = taus
            .into_iter()
            .enumerate()
            .map(|(k, tau)| Pattern {
                direction_deg,
                tau,
                phase_rad: match d.phases {
                    Phases::Zero => 0.0,
                    Phases::Alternate => {
                        if k % 2 == 0 {
                            0.0
                        } else {
                            std::f64::consts::FRAC_PI_2
                        }
                    }
                    Phases::Random => rng.random_range(0.0..std::f64::consts::TAU),
                },
            })
            .collect();
        blocks.push(block);
    }
    let mut all: Vec<Pattern> = blocks.into_iter().flatten().collect();
    if matches!(d.order, Order::Shuffled) {
        all.shuffle(&mut rng);
    }
    all
}

/// What one draw gave.
#[derive(Debug)]
struct Judged {
    /// Points compared, worst difference over σ, pixels with other flags.
    compared: usize,
    worst: f64,
    differ: usize,
    pixels: usize,
    /// Pixels with points from the series alone, and the statistics alone.
    lost: usize,
    gained: usize,
    /// Found / expected, per reflection, series then statistics.
    found: [[(usize, usize); 2]; 2],
    /// Series, statistics: RMS error over σ and coordinates.
    z: [(f64, usize); 2],
    /// Series, statistics: coordinates beyond [`FAR_Z`] σ, and the RMS of
    /// those within (tells a few far points from σ too small everywhere).
    tails: [(usize, f64); 2],
    /// Flags set on one engine's pixel and not the other's, with counts.
    flag_diffs: Vec<(u32, usize)>,
    problems: Vec<String>,
}

fn judge(d: &Draw) -> Judged {
    let mut st = station(d.thickness_mm);
    st.element.refractive_index = d.index;
    let params = SimParams {
        noise_frac: d.noise,
        bit_depth: d.bit_depth,
        seed: d.seed,
        falloff: if d.screen_period_falloff {
            mfd::sim::Falloff::ScreenPeriod
        } else {
            mfd::sim::Falloff::Tau
        },
        ..SimParams::default()
    };
    let pats = patterns(d);
    let series = run_patterns(&st, params.clone(), &pats, config(Engine::Series));
    let stats = run_patterns(&st, params, &pats, config(Engine::Statistics));
    let Agreement {
        compared,
        worst,
        differ,
        lost,
        gained,
        flag_diffs,
    } = agreement(&series.maps, &stats.maps);
    let found = [score(&series), score(&stats)].map(|s| s.map(|(_, _, _, n, m)| (n, m)));
    let z = [error_over_sigma(&series), error_over_sigma(&stats)];
    let tails = [tail(&series), tail(&stats)];
    if std::env::var_os("MFD_SPECTRAL_SOAK_DUMP").is_some() {
        let mut hist = std::collections::BTreeMap::new();
        for p in &series.maps.pixels {
            *hist.entry(p.flags.bits()).or_insert(0usize) += 1;
        }
        eprintln!("{d:?}\nseries flags (bits: pixels): {hist:?}");
        dump_far(&series, "series");
        dump_far(&stats, "statistics");
    }
    let pixels = series.maps.pixels.len();
    let mut problems = Vec::new();
    if worst > SAME_POINT_SIGMAS {
        problems.push(format!(
            "a statistics point {worst:.3} σ from the series' (≤ {SAME_POINT_SIGMAS})"
        ));
    }
    let reported = series
        .maps
        .pixels
        .iter()
        .filter(|p| p.s[0][0].is_finite() || p.s[1][0].is_finite())
        .count();
    if lost as f64 > LOST_FRACTION * reported as f64 {
        problems.push(format!(
            "{lost} of the series' {reported} pixels with points have none from the statistics"
        ));
    }
    // Unit RMS of error / σ within 5 of its sampling σ, 1/√(2N) for N
    // independent coordinates (z² is χ²(1): its mean has σ √(2/N)).
    for (name, (rms, n)) in ["series", "statistics"].into_iter().zip(z) {
        let band = 5.0 / (2.0 * n as f64).sqrt();
        if n >= 200 && (rms - 1.0).abs() > band {
            problems.push(format!(
                "{name}: RMS error / σ {rms:.3} over {n} coordinates (1 ± {band:.3})"
            ));
        }
    }
    Judged {
        compared,
        worst,
        differ,
        pixels,
        lost,
        gained,
        found,
        z,
        tails,
        flag_diffs,
        problems,
    }
}

/// The two engines' maps side by side.
struct Agreement {
    /// Points both report, and their worst difference over the series' σ.
    compared: usize,
    worst: f64,
    /// Pixels whose flags differ (where no signal is found the statistics
    /// add "maybe outside the band" by design), and which flags, how often.
    differ: usize,
    flag_diffs: Vec<(u32, usize)>,
    /// Pixels with points from the series alone, and the statistics alone.
    lost: usize,
    gained: usize,
}

fn agreement(a: &SpectralMaps, b: &SpectralMaps) -> Agreement {
    let mut out = Agreement {
        compared: 0,
        worst: 0.0,
        differ: 0,
        flag_diffs: Vec::new(),
        lost: 0,
        gained: 0,
    };
    let mut bits = [0usize; 16];
    for (p, q) in a.pixels.iter().zip(&b.pixels) {
        let qf = if q.flags.intersects(PixelFlags::NO_SIGNAL) {
            q.flags & !PixelFlags::OUT_OF_BAND
        } else {
            q.flags
        };
        // A pixel clipped on more than a quarter of its samples is given up
        // by the statistics (no data: its sums are not kept) where the
        // series fits what is left; where that finds no fringe either,
        // neither reports a point.
        let given_up = PixelFlags::NO_DATA | PixelFlags::SATURATED;
        let qf = if qf == given_up && p.flags.contains(PixelFlags::SATURATED) && p.s[0][0].is_nan()
        {
            p.flags
        } else {
            qf
        };
        if p.flags != qf {
            out.differ += 1;
            let x = (p.flags ^ qf).bits();
            for (b, n) in bits.iter_mut().enumerate() {
                *n += usize::from(x >> b & 1 == 1);
            }
        }
        let has =
            |m: &mfd::solve::spectral::PixelResult| m.s[0][0].is_finite() || m.s[1][0].is_finite();
        match (has(p), has(q)) {
            (true, false) => out.lost += 1,
            (false, true) => out.gained += 1,
            _ => {}
        }
        for k in 0..2 {
            if p.s[k][0].is_finite() && q.s[k][0].is_finite() {
                let sd = p.std[k][0].hypot(p.std[k][1]);
                let d = (p.s[k][0] - q.s[k][0]).hypot(p.s[k][1] - q.s[k][1]);
                out.worst = out.worst.max(d / sd);
                out.compared += 1;
            }
        }
    }
    out.flag_diffs = (0..16)
        .filter(|&b| bits[b] > 0)
        .map(|b| (1u32 << b, bits[b]))
        .collect();
    out
}

#[test]
fn random_schedules_give_the_series_answers_from_the_statistics() {
    let seeds: Vec<u64> = match env_u64("MFD_SPECTRAL_SOAK_SEED") {
        Some(s) => vec![s],
        None => match env_u64("MFD_SPECTRAL_SOAK") {
            Some(n) => (FIRST_SEED..FIRST_SEED + n).collect(),
            None => (FIRST_SEED..FIRST_SEED + 8).chain(FIXED_SEEDS).collect(),
        },
    };
    let mut failed = Vec::new();
    let (mut compared, mut worst, mut lost, mut gained) = (0, 0.0f64, 0, 0);
    for &seed in &seeds {
        let d = draw(seed);
        let t = std::time::Instant::now();
        // A solver that errs or panics on the draw is a failure with the
        // draw saved, like any other.
        let j = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| judge(&d)))
            .unwrap_or_else(|e| {
                let why = e
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default();
                Judged {
                    compared: 0,
                    worst: 0.0,
                    differ: 0,
                    pixels: 0,
                    lost: 0,
                    gained: 0,
                    found: [[(0, 0); 2]; 2],
                    z: [(f64::NAN, 0); 2],
                    tails: [(0, f64::NAN); 2],
                    flag_diffs: Vec::new(),
                    problems: vec![format!("panicked: {why}")],
                }
            });
        compared += j.compared;
        worst = worst.max(j.worst);
        lost += j.lost;
        gained += j.gained;
        eprintln!(
            "seed {seed}: {} frames, {} directions; {} points compared, worst {:.2e} σ, \
             {} of {} pixels flagged otherwise, with points from the series alone {}, \
             the statistics alone {}; found S1 {:?} / {:?}, S2 {:?} / {:?} \
             (series / statistics); error/σ {:.3} over {} / {:.3} over {} (beyond {FAR_Z} σ {} / {}, \
             the rest {:.3} / {:.3}); flags differing {:?}; {:.1} s",
            patterns(&d).len(),
            d.directions.len(),
            j.compared,
            j.worst,
            j.differ,
            j.pixels,
            j.lost,
            j.gained,
            j.found[0][0],
            j.found[1][0],
            j.found[0][1],
            j.found[1][1],
            j.z[0].0,
            j.z[0].1,
            j.z[1].0,
            j.z[1].1,
            j.tails[0].0,
            j.tails[1].0,
            j.tails[0].1,
            j.tails[1].1,
            j.flag_diffs,
            t.elapsed().as_secs_f64()
        );
        if !j.problems.is_empty() {
            let text = format!("seed {seed} failed: {}\n  {d:?}\n", j.problems.join("; "));
            eprint!("{text}");
            let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("target/spectral-soak-failures.txt");
            if let Some(dir) = path.parent() {
                let _ = std::fs::create_dir_all(dir);
            }
            if let Ok(mut f) = std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(&path)
            {
                let _ = f.write_all(text.as_bytes());
            }
            failed.push(seed);
        }
    }
    eprintln!(
        "spectral-soak-figures: {{\"draws\": {}, \"failed\": {}, \"points_compared\": {compared}, \
         \"worst_sigma\": {worst:.3e}, \"series_alone\": {lost}, \"statistics_alone\": {gained}}}",
        seeds.len(),
        failed.len()
    );
    assert!(failed.is_empty(), "failing seeds: {failed:?}");
}

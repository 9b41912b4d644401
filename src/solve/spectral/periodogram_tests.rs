//! The grid FFT against the direct DFT it replaces (the reference, as
//! RustFFT keeps a naive DFT for its own tests).

use super::{Plan, SpectrumPlans};
use crate::solve::spectral::model::{Axis, Design, FrameMeta};

/// A designed schedule's shape on two directions: τ on the 0.5 grid with
/// gaps (a band of τ left out), repeats (every third τ of the dense part
/// taken twice, every 7th three times), unequal spans and frame counts,
/// and on direction 1 two τ of every three on the grid, a gap, and a
/// second phase (the periodogram takes the first).
fn gapped_design() -> Design {
    let mut frames = Vec::new();
    let mut push = |tau: f64, dir: usize, phase_cycles: f64| {
        frames.push(FrameMeta {
            tau,
            phase_cycles,
            dir,
        });
    };
    for k in 1..=300u32 {
        let tau = 0.5 * k as f64;
        if (60.0..90.0).contains(&tau) {
            continue;
        }
        let copies = if k % 7 == 0 {
            3
        } else if k % 3 == 0 && tau < 40.0 {
            2
        } else {
            1
        };
        for _ in 0..copies {
            push(tau, 0, 0.0);
        }
    }
    for k in (3..=250u32).filter(|k| k % 3 != 0 && !(101..121).contains(k)) {
        push(0.5 * k as f64, 1, 0.0);
        if k % 5 == 0 {
            push(0.5 * k as f64, 1, 0.25);
        }
    }
    let axes = vec![
        Axis {
            a: 0.7,
            b: 0.7,
            c: 0.0,
            stretch: 1.0,
        },
        Axis {
            a: 1.0,
            b: 0.0,
            c: 0.0,
            stretch: 1.24,
        },
    ];
    Design::new(frames, axes, vec![45.0, 0.0])
}

/// Counts of a fringe at μ = 0.37 (direction 0) and 0.61 (direction 1;
/// both under the 0.5 grid's Nyquist μ of 1)
/// with a falloff, plus deterministic pseudo-random noise; frame 5 excluded
/// (NaN), as clipped samples are.
fn counts(design: &Design) -> Vec<f64> {
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut noise = || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let mut y: Vec<f64> = design
        .frames
        .iter()
        .map(|f| {
            let mu = [0.37, 0.61][f.dir];
            let x = std::f64::consts::TAU * (mu * f.tau + f.phase_cycles);
            1000.0 + 400.0 * (-(f.tau / 150.0).powi(2)).exp() * x.cos() + 80.0 * noise()
        })
        .collect();
    y[5] = f64::NAN;
    y
}

#[test]
fn the_grid_fft_is_the_direct_dft_on_gapped_repeated_taus() {
    let design = gapped_design();
    let fft = SpectrumPlans::with_fft(&design, true);
    let direct = SpectrumPlans::with_fft(&design, false);
    let y = counts(&design);
    for d in 0..2 {
        assert!(
            matches!(fft.dirs[d].plan, Plan::Grid { .. }),
            "direction {d}"
        );
        assert!(
            matches!(direct.dirs[d].plan, Plan::Direct { .. }),
            "direction {d}"
        );
        let (mu_a, pa) = fft.spectrum(d, &y).unwrap();
        let (mu_b, pb) = direct.spectrum(d, &y).unwrap();
        assert_eq!(mu_a, mu_b, "direction {d}: the same μ grid");
        // Both sum the same ~300 terms of size ~400 counts; the direct
        // DFT's sine–cosines of arguments up to 2π·1.05·150 ≈ 10³ rad carry
        // ~1e-13 relative error each: 1e-9 of the largest power is far
        // above rounding and far below any difference of method.
        let top = pb.iter().copied().fold(0.0, f64::max);
        for (j, (a, b)) in pa.iter().zip(&pb).enumerate() {
            assert!(
                (a - b).abs() <= 1e-9 * top,
                "direction {d}, μ {}: {a} vs {b}",
                mu_a[j]
            );
        }
        let (ma, ra) = fft.peak(d, &y).unwrap();
        let (mb, rb) = direct.peak(d, &y).unwrap();
        assert!((ma - mb).abs() <= 1e-9, "direction {d}: {ma} vs {mb}");
        assert!((ra - rb).abs() <= 1e-9 * rb, "direction {d}: {ra} vs {rb}");
        // And the peak is the fringe's, within a quarter bin.
        let mu = [0.37, 0.61][d];
        assert!((ma - mu).abs() < 0.25 * fft.bin(d), "direction {d}: {ma}");
    }
}

/// The 0° fringes' axis on a unit screen.
const U_AXIS: Axis = Axis {
    a: 1.0,
    b: 0.0,
    c: 0.0,
    stretch: 1.0,
};

#[test]
fn taus_off_any_grid_take_the_direct_dft() {
    let frames = (1..=64)
        .map(|k| FrameMeta {
            tau: (k as f64).powf(1.3),
            phase_cycles: 0.0,
            dir: 0,
        })
        .collect();
    let design = Design::new(frames, vec![U_AXIS], vec![0.0]);
    let plans = SpectrumPlans::new(&design);
    assert!(matches!(plans.dirs[0].plan, Plan::Direct { .. }));
}

/// A phase-dithered schedule: every frame at its own phase (the most
/// common one holds a single frame). Each sample is turned back by its
/// phase: the grid FFT is still the direct DFT, and the peak is the
/// fringe's (with one phase's frames alone there would be one sample).
#[test]
fn every_frame_at_its_own_phase_is_turned_back_by_it() {
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut uniform = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let frames: Vec<FrameMeta> = (1..=300u32)
        .filter(|k| !(120..150).contains(k))
        .map(|k| FrameMeta {
            tau: 0.5 * k as f64,
            phase_cycles: uniform(),
            dir: 0,
        })
        .collect();
    let design = Design::new(frames, vec![U_AXIS], vec![0.0]);
    let fft = SpectrumPlans::with_fft(&design, true);
    let direct = SpectrumPlans::with_fft(&design, false);
    assert!(matches!(fft.dirs[0].plan, Plan::Grid { .. }));
    assert_eq!(
        fft.dirs[0].idx.len(),
        design.frames.len(),
        "every frame taken"
    );
    let y: Vec<f64> = design
        .frames
        .iter()
        .map(|f| {
            let x = std::f64::consts::TAU * (0.37 * f.tau + f.phase_cycles);
            1000.0 + 400.0 * (-(f.tau / 150.0).powi(2)).exp() * x.cos() + 80.0 * (uniform() - 0.5)
        })
        .collect();
    let (_, pa) = fft.spectrum(0, &y).unwrap();
    let (_, pb) = direct.spectrum(0, &y).unwrap();
    // As in the gapped test: 1e-9 of the largest power.
    let top = pb.iter().copied().fold(0.0, f64::max);
    for (a, b) in pa.iter().zip(&pb) {
        assert!((a - b).abs() <= 1e-9 * top, "{a} vs {b}");
    }
    let (mu, ratio) = fft.peak(0, &y).unwrap();
    assert!((mu - 0.37).abs() < 0.25 * fft.bin(0), "{mu}");
    // The mirror term spreads over μ like noise of the fringe's own
    // power: the peak still stands far above the median.
    assert!(ratio > 100.0, "{ratio}");
    assert!(
        (fft.bin(0) - 1.0 / 149.5).abs() < 1e-12,
        "the bin is the whole span's"
    );
}

/// A coarse grid (Δ = 0.8) whose frames alternate between phases 0 and
/// ¼ cycle, with a gap of 31 grid points (odd: the alternation flips
/// after it). The periodogram takes the phase-0 frames: every other grid
/// point before the gap, the other ones after, so it repeats nearly at
/// `1/(2Δ)` as well as at `1/Δ`. Every strong local maximum of a noise-free
/// fringe's periodogram must be one of the copies [`super::Aliases`] lists,
/// and every copy listed must be strong there.
#[test]
fn the_copies_listed_are_the_periodograms_strong_maxima() {
    let dtau = 0.8;
    let frames: Vec<FrameMeta> = (0..240u32)
        .filter(|k| !(90..121).contains(k))
        .enumerate()
        .map(|(n, k)| FrameMeta {
            tau: 1.0 + dtau * f64::from(k),
            phase_cycles: if n % 2 == 0 { 0.0 } else { 0.25 },
            dir: 0,
        })
        .collect();
    let design = Design::new(frames, vec![U_AXIS], vec![0.0]);
    let plans = SpectrumPlans::new(&design);
    let aliases = plans.aliases(0).expect("τ on a grid").clone();
    assert!((aliases.period - 1.0 / dtau).abs() < 1e-9);
    let bin = plans.bin(0);
    for mu in [0.11, 0.23, 0.47] {
        let y: Vec<f64> = design
            .frames
            .iter()
            .map(|f| 1000.0 + 400.0 * (std::f64::consts::TAU * (mu * f.tau + f.phase_cycles)).cos())
            .collect();
        let (mus, power) = plans.spectrum(0, &y).unwrap();
        let top = power.iter().copied().fold(0.0, f64::max);
        let listed = aliases.of(mu, 0.0, 1.05);
        // The copy the old rule (±μ + k/Δ) missed: half a period away.
        // The frames before the gap and after it add there with opposite
        // signs, so it is split into two lobes about a bin either side.
        let half = 0.5 / dtau;
        assert!(
            [half - mu, half + mu]
                .iter()
                .filter(|c| (0.0..=1.05).contains(*c))
                .all(|c| listed.iter().any(|&m| (m - c).abs() < 2.0 * bin)),
            "μ {mu}: no copy at 1/(2Δ) ± μ in {listed:?}"
        );
        // Strong maxima (a quarter of the peak's power: the listing's
        // ALIAS_SHARE in amplitude, less the other term's interference)
        // are listed, to a bin.
        for j in 1..power.len() - 1 {
            let strong =
                power[j] >= 0.3 * top && power[j] >= power[j - 1] && power[j] > power[j + 1];
            if strong && mus[j] > 3.0 * bin {
                assert!(
                    listed.iter().any(|&m| (m - mus[j]).abs() < bin),
                    "μ {mu}: a maximum at {} ({:.2} of the peak) is not listed in {listed:?}",
                    mus[j],
                    power[j] / top
                );
            }
        }
        // And each listed copy on the search's range is strong there.
        for &m in listed.iter().filter(|&&m| m > 3.0 * bin && m < 1.0) {
            let near = mus
                .iter()
                .zip(&power)
                .filter(|(x, _)| (*x - m).abs() < bin)
                .map(|(_, p)| *p)
                .fold(0.0, f64::max);
            assert!(
                near >= 0.15 * top,
                "μ {mu}: listed copy {m} holds {:.3} of the peak",
                near / top
            );
        }
    }
}

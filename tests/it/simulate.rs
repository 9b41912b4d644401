//! The simulated camera end to end: frames written by `simulate` and read
//! back by the acquisition reader are cosines at exactly the traced screen
//! points, deterministic, and agree with the independent fixture's frames.

use crate::common;

use mfd::acquire::acquisition::{Acquisition, FrameLayout};
use mfd::acquire::patterns::{FringeAxis, Schedule};
use mfd::formats::npy::StackDtype;
use mfd::formats::surfaces_file::{self, SurfacesFile};
use mfd::optics::station::Station;
use mfd::optics::trace::{Plate, TracedView};
use mfd::sim::{simulate, RandomSurfaceSpec, Renderer, SimParams, Simulation};
use nalgebra::{DMatrix, DVector};

fn fixture_station() -> Station {
    Station::load(&common::public_small().join("station.toml")).unwrap()
}

fn random_plate(station: &Station, seed: u64) -> (Plate, SurfacesFile) {
    let (front, back) = RandomSurfaceSpec::default()
        .draw_pair(station.element.aperture_radius_mm, [0.0, 0.0], seed)
        .unwrap();
    let file = SurfacesFile::from_surfaces(&front, &back);
    (Plate::new(station, front, back, 3.0), file)
}

/// Gauss–Newton fit of `A + e(τ) (B1 cos 2πμ1τ + B2 cos 2πμ2τ)` started at
/// the truth; returns the fitted (μ1, μ2).
fn fit_two_cosines(taus: &[f64], y: &[f64], tau_max: f64, mut mu: [f64; 2]) -> [f64; 2] {
    for _ in 0..20 {
        let n = taus.len();
        // Linear part at the current μ.
        let basis = DMatrix::from_fn(n, 3, |r, c| {
            let e = (-(taus[r] / tau_max).powi(2)).exp();
            match c {
                0 => 1.0,
                k => e * (std::f64::consts::TAU * mu[k - 1] * taus[r]).cos(),
            }
        });
        let lin = basis
            .clone()
            .svd(true, true)
            .solve(&DVector::from_column_slice(y), 1e-14)
            .unwrap();
        let resid = DVector::from_column_slice(y) - &basis * &lin;
        let jac = DMatrix::from_fn(n, 5, |r, c| {
            let e = (-(taus[r] / tau_max).powi(2)).exp();
            let w = std::f64::consts::TAU * taus[r];
            match c {
                0..=2 => basis[(r, c)],
                k => -lin[k - 2] * e * w * (w * mu[k - 3]).sin(),
            }
        });
        let step = jac.svd(true, true).solve(&resid, 1e-14).unwrap();
        mu[0] += step[3];
        mu[1] += step[4];
        if step[3].abs().max(step[4].abs()) < 1e-13 {
            break;
        }
    }
    mu
}

#[test]
fn frames_are_cosines_at_the_traced_points() {
    let station = fixture_station();
    let (plate, truth) = random_plate(&station, 11);
    let schedule = Schedule {
        tau_start: 0.5,
        tau_stop: 200.0,
        tau_step: 0.5,
        ..Schedule::default()
    };
    let patterns = schedule.patterns();
    let params = SimParams {
        bit_depth: 16,
        tau_max: 150.0,
        ..SimParams::default()
    };
    let dir = tempfile::tempdir().unwrap();
    let sim = Simulation {
        station: &station,
        plate: &plate,
        truth: &truth,
        patterns: &patterns,
        params: params.clone(),
        layout: FrameLayout::Stack {
            dtype: StackDtype::U16,
        },
        overwrite: false,
    };
    simulate(&sim, dir.path()).unwrap();

    let acq = Acquisition::open(dir.path()).unwrap();
    let (w, h) = (
        station.camera.width as usize,
        station.camera.height as usize,
    );
    let mut frames = Vec::new();
    let mut buf = Vec::new();
    for f in acq.frames() {
        acq.read_frame(f.index, &mut buf).unwrap();
        frames.push(buf.clone());
    }
    let view = TracedView::trace(&station, &plate);
    let taus = schedule.taus();
    let mut worst_px: f64 = 0.0;
    let mut fitted = 0;
    for (d, &direction) in schedule.directions_deg.iter().enumerate() {
        let axis = FringeAxis::new(direction, station.screen.width, station.screen.height);
        for (q, p) in view.pixels.iter().enumerate() {
            let (Ok(s1), Ok(s2)) = (p.front, p.back) else {
                continue;
            };
            let truth_mu = [axis.s(s1.u, s1.v), axis.s(s2.u, s2.v)];
            let y: Vec<f64> = (0..taus.len())
                .map(|t| f64::from(frames[d * taus.len() + t][q]))
                .collect();
            let mu = fit_two_cosines(&taus, &y, params.tau_max, truth_mu);
            for k in 0..2 {
                worst_px = worst_px.max((mu[k] - truth_mu[k]).abs() * axis.length_px);
            }
            fitted += 1;
        }
    }
    let _ = (w, h);
    // The bound: no offset above 0.01 screen px. 16-bit rounding
    // alone (σ = 0.29 counts on ~10^4-count fringes) moves μ by ~1e-5 px.
    eprintln!("fit of simulated frames at the truth: worst offset {worst_px:.3e} px over {fitted} pixel-directions");
    assert!(worst_px < 0.01, "worst offset {worst_px} px");
    assert!(fitted > 2000, "fitted {fitted} pixel-directions");
}

#[test]
fn the_screen_period_falloff_is_the_diagonals_on_a_finer_fringe() {
    // Noise-free, the difference of a pattern and its π-shifted twin is
    // 2 a e cos(…): its ratio between the two falloffs is e(ℓτ)/e(τ),
    // ℓ = L₄₅/L_d from the spec's screen lengths, at every pixel.
    use mfd::acquire::patterns::Pattern;
    use mfd::sim::Falloff;
    let station = fixture_station();
    let (plate, _) = random_plate(&station, 3);
    let view = TracedView::trace(&station, &plate);
    let (w, h) = (station.screen.width, station.screen.height);
    let l45 = FringeAxis::new(45.0, w, h).length_px;
    let n = station.camera.pixel_count();
    let diff = |falloff: Falloff, direction_deg: f64, tau: f64| -> Vec<f64> {
        let params = SimParams {
            falloff,
            ..SimParams::default()
        };
        let mut cam = Renderer::new(&view, &station.screen, params).unwrap();
        let (mut a, mut b) = (vec![0u16; n], vec![0u16; n]);
        let p = |phase_rad| Pattern {
            direction_deg,
            tau,
            phase_rad,
        };
        cam.render(&p(0.0), 0, &mut a);
        cam.render(&p(std::f64::consts::PI), 1, &mut b);
        a.iter()
            .zip(&b)
            .map(|(&x, &y)| f64::from(x) - f64::from(y))
            .collect()
    };
    let tau = 100.0;
    for direction_deg in [45.0, -45.0, 0.0, 90.0] {
        let l = l45 / FringeAxis::new(direction_deg, w, h).length_px;
        let want = (-((l * tau / 150.0).powi(2) - (tau / 150.0).powi(2))).exp();
        let (t, sp) = (
            diff(Falloff::Tau, direction_deg, tau),
            diff(Falloff::ScreenPeriod, direction_deg, tau),
        );
        let mut used = 0;
        for (x, y) in t.iter().zip(&sp) {
            // Counts are rounded: ±1 on each of two frames, so ±2 on a
            // difference of at least 2000 is 1e-3 of it; the ratio's
            // error is then at most 2e-3 (both differences rounded).
            if x.abs() >= 2000.0 {
                used += 1;
                assert!(
                    (y / x - want).abs() <= 2e-3 + 2.0 * want / x.abs(),
                    "{direction_deg}°: {y} / {x} against {want}"
                );
            }
        }
        assert!(used > 100, "{direction_deg}°: {used} pixels compared");
        if direction_deg.abs() == 45.0 {
            assert_eq!(want, 1.0);
        } else {
            // A plain direction's L is shorter than the diagonals' on any
            // screen: the effect is there, well beyond the 2e-3 above.
            assert!(want < 0.95, "{direction_deg}°: {want}");
        }
    }
}

#[test]
fn rendering_is_seeded_and_order_independent() {
    let station = fixture_station();
    let (plate, _) = random_plate(&station, 3);
    let view = TracedView::trace(&station, &plate);
    let params = SimParams {
        noise_frac: 0.05,
        full_well_electrons: Some(20_000.0),
        seed: 9,
        ..SimParams::default()
    };
    let pats = Schedule::default().patterns();
    let mut a = Renderer::new(&view, &station.screen, params.clone()).unwrap();
    let mut b = Renderer::new(&view, &station.screen, params).unwrap();
    let n = station.camera.pixel_count();
    let (mut fa, mut fb, mut other) = (vec![0u16; n], vec![0u16; n], vec![0u16; n]);
    a.render(&pats[5], 5, &mut fa);
    b.render(&pats[1500], 1500, &mut other);
    b.render(&pats[5], 5, &mut fb);
    assert_eq!(
        fa, fb,
        "frame 5 must not depend on what was rendered before"
    );
    a.render(&pats[5], 6, &mut other);
    assert_ne!(fa, other, "another frame index draws other noise");
}

#[test]
fn agrees_with_the_independent_fixture_frames() {
    // Render the fixture's scene with its own camera constants (scene.json:
    // gain 677610.446…, ambient 0.01, τ_max 150) and no noise. The fixture's
    // frames carry Gaussian noise of σ = 1310.7 counts, so the residual RMS
    // over all 921 600 samples must be σ: its sampling spread is
    // σ/√(2N) = 0.07 %, and a model error of 190 counts (0.7 % of the mean
    // level) would already lift it by 1 %.
    let dir = common::public_small();
    let station = fixture_station();
    let truth = SurfacesFile::load(&dir.join("truth/truth_surfaces.json")).unwrap();
    let front = surfaces_file::to_surface(&truth, truth.front_coefficients()).unwrap();
    let back = surfaces_file::to_surface(&truth, truth.back_coefficients()).unwrap();
    let plate = Plate::new(&station, front, back, 3.0);
    let view = TracedView::trace(&station, &plate);
    let params = SimParams {
        gain: Some(677_610.446_152_014_3),
        noise_frac: 0.0,
        ..SimParams::default()
    };
    let mut cam = Renderer::new(&view, &station.screen, params).unwrap();
    let acq = Acquisition::open(&dir).unwrap();
    let mut theirs = Vec::new();
    let (mut sum2, mut sum, mut n) = (0.0, 0.0, 0usize);
    for f in acq.frames() {
        acq.read_frame(f.index, &mut theirs).unwrap();
        let pattern = mfd::acquire::patterns::Pattern {
            direction_deg: f.direction_deg,
            tau: f.tau,
            phase_rad: f.phase_rad,
        };
        let ours = cam.expected(&pattern);
        for (&a, &b) in ours.iter().zip(&theirs) {
            let r = f64::from(b) - a;
            sum += r;
            sum2 += r * r;
            n += 1;
        }
    }
    let rms = (sum2 / n as f64).sqrt();
    let mean = sum / n as f64;
    eprintln!("fixture frames − ours: RMS {rms:.2} counts (fixture σ 1310.7), mean {mean:.3} over {n} samples");
    assert!(
        (rms / 1310.7 - 1.0).abs() < 0.01,
        "residual RMS {rms} counts"
    );
    // Mean of N noise samples: σ/√N = 1.4 counts; 10 counts is 7 σ.
    assert!(mean.abs() < 10.0, "residual mean {mean} counts");
}

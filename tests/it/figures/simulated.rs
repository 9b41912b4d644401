//! The figures of whole simulated measurements against the truth's: the
//! issue's criterion, every figure within 4σ and the RMS of all the
//! z-scores between 0.3 and 2, on parallel plates (the fixture's 10 mm,
//! n = 1.5), thick silica ones (20 mm, n = 1.4496) and plates with a
//! 1-arcmin wedge in the back's tilt terms (the station assuming none).

use crate::common;

use mfd::acquire::acquisition::FrameInfo;
use mfd::acquire::patterns::Schedule;
use mfd::optics::station::Station;
use mfd::optics::trace::{Plate, TracedView};
use mfd::optics::zernike::ZernikeSurface;
use mfd::report::figures::joint::of_solution;
use mfd::report::figures::{of_truth, table};
use mfd::sim::{RandomSurfaceSpec, Renderer, SimParams};
use mfd::solve::spectral::{SpectralConfig, SpectralSolver};
use mfd::solve::surfaces::{reconstruct, Observations, SurfaceOptions, Uncertainty};

/// One simulated measurement (2 % noise, 200 frames, 36 terms) of random
/// surfaces on `station`: each figure's score against the truth's.
fn scores(station: &Station, seed: u64, wedge_arcmin: f64) -> Vec<table::Score> {
    let r = station.element.aperture_radius_mm;
    let (front, back) = RandomSurfaceSpec::default()
        .draw_pair(r, [0.0, 0.0], seed)
        .unwrap();
    // A wedge thinning along 30° in the back's tilt terms, as the spec
    // reports one (`interchange.md`, "Wedge"); the station assumes none.
    let back = {
        let (w, phi) = ((wedge_arcmin / 60.0).to_radians(), 30f64.to_radians());
        let mut c = back.coefficients_nm().to_vec();
        c[1] += w.tan() * r * phi.cos() / 2.0 * 1e6;
        c[2] += w.tan() * r * phi.sin() / 2.0 * 1e6;
        ZernikeSurface::new(back.basis().clone(), c).unwrap()
    };
    let view = TracedView::trace(
        station,
        &Plate::new(station, front.clone(), back.clone(), 3.0),
    );
    let schedule = Schedule {
        tau_start: 0.5,
        tau_stop: 100.0,
        tau_step: 0.5,
        ..Schedule::default()
    };
    let params = SimParams {
        noise_frac: 0.02,
        seed: seed + 100,
        ..SimParams::default()
    };
    let patterns = schedule.patterns();
    let mut cam = Renderer::new(&view, &station.screen, params).unwrap();
    let frames = FrameInfo::from_patterns(&patterns);
    let mut solver = SpectralSolver::new(station, &frames, SpectralConfig::default()).unwrap();
    let mut buf = vec![0u16; station.camera.pixel_count()];
    for (k, p) in patterns.iter().enumerate() {
        cam.render(p, k as u64, &mut buf);
        solver.push_frame(k, &buf).unwrap();
    }
    let maps = solver.solve().unwrap();
    let (coords, cov) = (maps.screen_coords(), maps.screen_cov());
    let obs = Observations::from_maps(station, &coords, Uncertainty::Cov(&cov)).unwrap();
    let opts = SurfaceOptions {
        terms: Some(36),
        ..SurfaceOptions::default()
    };
    let sol = reconstruct(&obs, station, &opts).unwrap();
    let ours = of_solution(&sol, None, station, 1053.0, &[None, None]).unwrap();
    let n = station.element.refractive_index;
    let truth = of_truth(
        front.coefficients_nm(),
        back.coefficients_nm(),
        r,
        n,
        1053.0,
    )
    .unwrap();
    table::scores(&ours, &truth)
}

#[test]
fn simulated_plates_give_every_figure_within_4_sigma() {
    let parallel = Station::load(&common::public_small().join("station.toml")).unwrap();
    let mut silica = parallel.clone();
    silica.element.thickness_mm = 20.0;
    silica.element.refractive_index = 1.4496;
    let mut all = Vec::new();
    for (name, station, seed, wedge) in [
        ("parallel", &parallel, 21, 0.0),
        ("parallel", &parallel, 23, 0.0),
        ("silica", &silica, 25, 0.0),
        ("silica", &silica, 27, 0.0),
        ("wedge 1'", &parallel, 29, 1.0),
        ("wedge 1'", &silica, 31, 1.0),
    ] {
        for s in scores(station, seed, wedge) {
            println!(
                "{name} {seed} {:<40} {:>12.4} truth {:>12.4} σ {:>9.4} z {:>6.2}",
                s.key, s.value, s.truth, s.std, s.z
            );
            all.push(s);
        }
    }
    // 17 figures with a σ per measurement: 5 per face, 7 of the plate.
    assert_eq!(all.len(), 6 * 17, "{all:?}");
    let zs: Vec<f64> = all.iter().map(|s| s.z).collect();
    let rms = (zs.iter().map(|z| z * z).sum::<f64>() / zs.len() as f64).sqrt();
    println!("RMS of {} z-scores {rms:.3}", zs.len());
    for s in &all {
        assert!(s.z.abs() < 4.0, "{s:?}");
    }
    assert!((0.3..=2.0).contains(&rms), "RMS z {rms}");
}

//! The spectral solver on the independent fixture `public-small` (τ stops at
//! 100: the two reflections are ~half a Fourier bin apart; its own
//! Cramér–Rao bound is ~0.3 px), judged against that bound.

use crate::common;

use mfd::acquire::acquisition::Acquisition;
use mfd::formats::npy;
use mfd::optics::station::Station;
use mfd::solve::spectral::{Engine, SpectralConfig, SpectralSolver};

#[test]
fn fixture_screen_points_within_the_bound_series() {
    fixture_screen_points_within_the_bound(Engine::Series);
}

#[test]
fn fixture_screen_points_within_the_bound_statistics() {
    fixture_screen_points_within_the_bound(Engine::Statistics);
}

fn fixture_screen_points_within_the_bound(engine: Engine) {
    let dir = common::public_small();
    let station = Station::load(&dir.join("station.toml")).unwrap();
    let acq = Acquisition::open(&dir).unwrap();
    let config = SpectralConfig {
        engine,
        ..SpectralConfig::default()
    };
    let mut solver = SpectralSolver::new(&station, acq.frames(), config).unwrap();
    let mut buf = Vec::new();
    for f in acq.frames() {
        acq.read_frame(f.index, &mut buf).unwrap();
        solver.push_frame(f.index, &buf).unwrap();
    }
    let maps = solver.solve().unwrap();
    let (_, truth) = npy::read_f64(&dir.join("truth/truth_screen_coords.npy")).unwrap();
    let (_, crb) = npy::read_f64(&dir.join("truth/crb_screen_std.npy")).unwrap();
    let (_, mask) = npy::read_bool(&dir.join("truth/aperture_mask.npy")).unwrap();
    let ours = maps.screen_coords();
    let mut stats = [[0.0f64; 3]; 2]; // per reflection: Σ err², Σ crb², count
    let mut missing = [0usize; 2];
    let mut flags_hist = std::collections::BTreeMap::new();
    for p in 0..48 * 48 {
        if !mask[p] {
            continue;
        }
        *flags_hist.entry(maps.pixels[p].flags).or_insert(0) += 1;
        for k in 0..2 {
            let (tu, tv) = (truth[p * 4 + 2 * k], truth[p * 4 + 2 * k + 1]);
            let (u, v) = (ours[p * 4 + 2 * k], ours[p * 4 + 2 * k + 1]);
            if tu.is_nan() {
                continue;
            }
            if u.is_nan() {
                missing[k] += 1;
                continue;
            }
            stats[k][0] += (u - tu).powi(2) + (v - tv).powi(2);
            stats[k][1] += crb[p * 2 + k].powi(2);
            stats[k][2] += 1.0;
        }
    }
    for (k, s) in stats.iter().enumerate() {
        let rms = (s[0] / s[2]).sqrt();
        let bound = (s[1] / s[2]).sqrt();
        eprintln!(
            "{engine:?} S{}: RMS error {rms:.4} px, CRB {bound:.4} px, ratio {:.3}, n = {}, missing {}",
            k + 1,
            rms / bound,
            s[2],
            missing[k]
        );
        // The criteria against the fixture's own bound: within 1.5×
        // of it, and ≥ 99 % of the aperture's points found.
        assert!(rms <= 1.5 * bound, "S{}: {rms} vs {bound}", k + 1);
        assert!(
            missing[k] as f64 <= 0.01 * (s[2] + missing[k] as f64),
            "S{}: {} missing of {}",
            k + 1,
            missing[k],
            s[2] + missing[k] as f64
        );
    }
    eprintln!("flags {flags_hist:?}");
}

#[test]
fn our_bound_against_the_fixture_bound() {
    use mfd::formats::surfaces_file::{self, SurfacesFile};
    use mfd::optics::trace::{Plate, TracedView};
    use mfd::solve::spectral::model::{normal_equations, Params};
    let dir = common::public_small();
    let station = Station::load(&dir.join("station.toml")).unwrap();
    let acq = Acquisition::open(&dir).unwrap();
    let truth = SurfacesFile::load(&dir.join("truth/truth_surfaces.json")).unwrap();
    let front = surfaces_file::to_surface(&truth, truth.front_coefficients()).unwrap();
    let back = surfaces_file::to_surface(&truth, truth.back_coefficients()).unwrap();
    let view = TracedView::trace(&station, &Plate::new(&station, front, back, 3.0));
    let solver = SpectralSolver::new(&station, acq.frames(), SpectralConfig::default()).unwrap();
    let design = solver.design().clone();
    let (_, crb) = npy::read_f64(&dir.join("truth/crb_screen_std.npy")).unwrap();
    let (gain, sigma, amb) = (677_610.446_152_014_3, 1310.7, 0.01);
    let index: Vec<u32> = (0..design.frames.len() as u32).collect();
    let y = vec![0.0; index.len()];
    let mut ratios = Vec::new();
    for (p, px) in view.pixels.iter().enumerate() {
        let (Ok(f), Ok(b)) = (px.front, px.back) else {
            continue;
        };
        let params = Params {
            k: 2,
            offset: gain * (amb + 0.5 * (f.weight + b.weight)),
            amp: [0.5 * gain * f.weight, 0.5 * gain * b.weight, 0.0],
            uv: [[f.u, f.v], [b.u, b.v], [0.0, 0.0]],
            kappa: design.uniform_falloff(150f64.powi(-2)),
        };
        let ne = normal_equations(&design, &index, &y, &params);
        let cov = ne.jtj.try_inverse().unwrap() * sigma * sigma;
        let s1 = (cov[(3, 3)] + cov[(4, 4)]).sqrt();
        ratios.push(s1 / crb[p * 2]);
    }
    ratios.sort_by(f64::total_cmp);
    // Our bound is that of the joint model (A, B, τ_max shared by the two
    // directions), the fixture's of a model with more unknowns: ours must
    // not exceed it, beyond the 5 % its own numerics allow.
    assert!(ratios[ratios.len() / 2] < 1.0);
    eprintln!(
        "our joint-model bound / fixture bound, S1: median {:.3}, min {:.3}, max {:.3}",
        ratios[ratios.len() / 2],
        ratios[0],
        ratios[ratios.len() - 1]
    );
}

//! Helpers of the spectral tests (`tests/it/spectral_sim.rs`,
//! `tests/it/spectral_engines.rs`): simulated acquisitions of the bench
//! station streamed through the solver, and their scores against the truth.

use mfd::acquire::acquisition::FrameInfo;
use mfd::acquire::patterns::Schedule;
use mfd::optics::station::Station;
use mfd::optics::trace::{Plate, TracedView};
use mfd::sim::{RandomSurfaceSpec, Renderer, SimParams};
use mfd::solve::spectral::model::{normal_equations, Params};
use mfd::solve::spectral::{Engine, SpectralConfig, SpectralMaps, SpectralSolver};

pub struct Run {
    pub view: TracedView,
    pub maps: SpectralMaps,
    pub crb: Vec<[f64; 2]>,
}

/// The fixture's 48×48 station with another plate; random 60 nm surfaces.
pub fn station(thickness_mm: f64) -> Station {
    let mut s = Station::load(&super::public_small().join("station.toml")).unwrap();
    s.element.thickness_mm = thickness_mm;
    s
}

pub fn run(station: &Station, params: SimParams, schedule: &Schedule, engine: Engine) -> Run {
    run_with(station, params, schedule, config(engine))
}

pub fn config(engine: Engine) -> SpectralConfig {
    SpectralConfig {
        engine,
        ..SpectralConfig::default()
    }
}

pub fn run_with(
    station: &Station,
    params: SimParams,
    schedule: &Schedule,
    config: SpectralConfig,
) -> Run {
    run_patterns(station, params, &schedule.patterns(), config)
}

pub fn run_patterns(
    station: &Station,
    params: SimParams,
    patterns: &[mfd::acquire::patterns::Pattern],
    config: SpectralConfig,
) -> Run {
    let (front, back) = RandomSurfaceSpec::default()
        .draw_pair(25.5, [0.0, 0.0], 21)
        .unwrap();
    let view = TracedView::trace(station, &Plate::new(station, front, back, 3.0));
    let (mut solver, cam) = fed_solver(station, &view, params.clone(), patterns, config);
    let frames: Vec<_> = FrameInfo::from_patterns(patterns);
    let maps = solver.solve().unwrap();
    // The bound of the same joint model at the truth (A, B from the Fresnel
    // weights and gain, κ = 1/τ_max², σ the read noise).
    let sigma = (params.noise_frac * params.full_scale()).max(1e-9);
    let index: Vec<u32> = (0..frames.len() as u32).collect();
    let zeros = vec![0.0; frames.len()];
    let g = cam.gain();
    let crb = view
        .pixels
        .iter()
        .map(|px| {
            let (Ok(f), Ok(b)) = (px.front, px.back) else {
                return [f64::NAN; 2];
            };
            let (wf, wb) = (
                f.weight * params.path_scale[0],
                b.weight * params.path_scale[1],
            );
            if wb == 0.0 {
                return [f64::NAN; 2]; // one reflection: no two-reflection bound
            }
            let p = Params {
                k: 2,
                offset: g * (params.ambient + 0.5 * (wf + wb)),
                amp: [0.5 * g * wf, 0.5 * g * wb, 0.0],
                uv: [[f.u, f.v], [b.u, b.v], [0.0; 2]],
                kappa: match params.falloff {
                    mfd::sim::Falloff::Tau => {
                        solver.design().uniform_falloff(params.tau_max.powi(-2))
                    }
                    mfd::sim::Falloff::ScreenPeriod => {
                        solver.design().physical_falloff(params.tau_max.powi(-2))
                    }
                },
            };
            let cov = normal_equations(solver.design(), &index, &zeros, &p)
                .jtj
                .try_inverse()
                .unwrap()
                * sigma
                * sigma;
            [
                (cov[(3, 3)] + cov[(4, 4)]).sqrt(),
                (cov[(5, 5)] + cov[(6, 6)]).sqrt(),
            ]
        })
        .collect();
    Run { view, maps, crb }
}

/// A solver that has taken every frame the simulated camera renders of `view`.
pub fn fed_solver(
    station: &Station,
    view: &TracedView,
    params: SimParams,
    patterns: &[mfd::acquire::patterns::Pattern],
    config: SpectralConfig,
) -> (SpectralSolver, Renderer) {
    let mut cam = Renderer::new(view, &station.screen, params).unwrap();
    let frames: Vec<_> = FrameInfo::from_patterns(patterns);
    let mut solver = SpectralSolver::new(station, &frames, config).unwrap();
    let mut buf = vec![0u16; station.camera.pixel_count()];
    for (k, p) in patterns.iter().enumerate() {
        cam.render(p, k as u64, &mut buf);
        solver.push_frame(k, &buf).unwrap();
    }
    (solver, cam)
}

/// Per reflection: (RMS error, RMS bound, worst error, found, expected).
pub fn score(r: &Run) -> [(f64, f64, f64, usize, usize); 2] {
    let mut out = [(0.0, 0.0, 0.0, 0, 0); 2];
    for (q, px) in r.view.pixels.iter().enumerate() {
        let (Ok(f), Ok(b)) = (px.front, px.back) else {
            continue;
        };
        for (k, t) in [f, b].iter().enumerate() {
            let s = r.maps.pixels[q].s[k];
            out[k].4 += 1;
            if s[0].is_nan() {
                continue;
            }
            let e2 = (s[0] - t.u).powi(2) + (s[1] - t.v).powi(2);
            out[k].0 += e2;
            out[k].1 += r.crb[q][k].powi(2);
            out[k].2 = f64::max(out[k].2, e2.sqrt());
            out[k].3 += 1;
        }
    }
    out.map(|(e, c, w, n, m)| ((e / n as f64).sqrt(), (c / n as f64).sqrt(), w, n, m))
}

pub fn paper_schedule() -> Schedule {
    Schedule::default()
}

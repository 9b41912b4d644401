//! The whole chain on wedged windows: simulated frames written as an
//! acquisition, `pipeline::reconstruct` (the wedge search, the spectral
//! stage, the surfaces), each surface's error against its Cramér–Rao
//! bound and against the error it reports.
//!
//! The station is the paper's geometry (825 mm, 15°, f = 16 mm, the
//! 1600 × 1200 LCD) with the sensor binned 8 × 8 (162 × 121 pixels of
//! 30 µm): the same field of view and the same screen points at 1/64 of the
//! pixels, so a 2000-frame acquisition is 78 MB and seconds to solve.

use mfd::acquire::acquisition::{Acquisition, FrameInfo, FrameLayout};
use mfd::acquire::patterns::{Pattern, Schedule};
use mfd::formats::surfaces_file::SurfacesFile;
use mfd::optics::station::{CameraProfile, DisplayProfile, Station, SymmetricLayout, Wedge};
use mfd::optics::trace::{Plate, TracedView, DEFAULT_EDGE_MARGIN_MM};
use mfd::optics::zernike::ZernikeSurface;
use mfd::pipeline::{self, Input, Options, PipelineError};
use mfd::report::metrics::rms_difference_nm;
use mfd::sim::{RandomSurfaceSpec, Renderer, SimParams, Simulation};
use mfd::solve::spectral::bound::truth_cov_map;
use mfd::solve::surfaces::report::{figures, REMOVED_TERMS};
use mfd::solve::surfaces::{reconstruct, Observations, SurfaceOptions, Uncertainty};

/// The paper's station, sensor binned 8 × 8, with `thickness_mm` and `index`.
pub fn binned_paper_station(thickness_mm: f64, index: f64) -> Station {
    let camera = CameraProfile {
        format: "mfd-camera-profile/1".into(),
        model: "paper camera, 8x8 binned".into(),
        resolution: [162, 121],
        pixel_pitch_um: 30.0,
        bit_depth: 12,
        distortion: None,
    };
    let mut element = SymmetricLayout::paper_element();
    element.thickness_mm = thickness_mm;
    element.refractive_index = index;
    SymmetricLayout {
        camera_height_mm: 825.0,
        screen_height_mm: 825.0,
        tilt_deg: 15.0,
        focal_length_mm: 16.0,
        element,
    }
    .build(&camera, &DisplayProfile::paper_lcd())
    .unwrap()
}

/// One scene: the station (its element's wedge the truth), what the
/// station file declares, the surfaces' seed, the noise and schedule.
pub struct Scene {
    pub truth: Station,
    pub declared: Wedge,
    pub seed: u64,
    pub noise: f64,
    pub patterns: Vec<Pattern>,
    /// RMS of each face's drawn departure (Noll 4–36), nm.
    pub surface_rms_nm: f64,
    /// What the blur acts on.
    pub falloff: mfd::sim::Falloff,
}

impl Scene {
    /// The paper's schedule (±45°, τ 0.2–200 by 0.2: 2000 frames) at 5 %
    /// noise, 60 nm surfaces.
    pub fn paper(truth: Station, declared: Wedge, seed: u64) -> Self {
        Scene {
            truth,
            declared,
            seed,
            noise: 0.05,
            patterns: Schedule::default().patterns(),
            surface_rms_nm: 60.0,
            falloff: mfd::sim::Falloff::Tau,
        }
    }
}

/// What a scene gave.
#[derive(Debug)]
pub struct Outcome {
    /// Per surface: RMS error of Noll 4+ (nm), the bound (`None` unless
    /// asked), the reported.
    pub error: [f64; 2],
    pub bound: Option<[f64; 2]>,
    pub reported: [f64; 2],
    /// RMS over Noll 4+ of (error / reported σ) per coefficient.
    pub z_rms: [f64; 2],
    /// The wedge search's line, where it ran.
    pub wedge_note: Option<String>,
    /// Whether the stages started from a wedge found in the frames.
    pub used_found: bool,
    /// Why a surface was withheld, where it was.
    pub withheld: [Option<String>; 2],
}

/// What [`run_solved`] gives beside the scores: the solution and the truth.
pub struct Solved {
    pub solution: mfd::solve::surfaces::SurfaceSolution,
    pub truth: [ZernikeSurface; 2],
}

/// Renders the scene into `dir`, reconstructs it on the declared station,
/// and scores it (with the bound when `with_bound`); `Err` with the
/// message where the pipeline or its surface stage refused.
pub fn run_scored(
    scene: &Scene,
    dir: &std::path::Path,
    with_bound: bool,
) -> Result<Outcome, String> {
    run_solved(scene, dir, with_bound).map(|(o, _)| o)
}

/// [`run_scored`], with the solution and the truth.
pub fn run_solved(
    scene: &Scene,
    dir: &std::path::Path,
    with_bound: bool,
) -> Result<(Outcome, Solved), String> {
    run_solved_on(scene, &declared_of(scene), dir, with_bound)
}

/// The station file the scene declares: the truth with its declared wedge.
fn declared_of(scene: &Scene) -> Station {
    let mut declared = scene.truth.clone();
    declared.element.wedge = scene.declared;
    declared
}

/// [`run_solved`] reconstructing on `declared` (the station file as given,
/// where it differs from the truth by more than the wedge).
pub fn run_solved_on(
    scene: &Scene,
    declared: &Station,
    dir: &std::path::Path,
    with_bound: bool,
) -> Result<(Outcome, Solved), String> {
    run_solved_full(scene, declared, dir, with_bound, scene.seed + 1000)
}

/// [`run_solved`] with the noise drawn from `noise_seed` (the surfaces
/// still from the scene's seed): the same element and station under
/// another noise realisation.
pub fn run_solved_with_noise(
    scene: &Scene,
    dir: &std::path::Path,
    with_bound: bool,
    noise_seed: u64,
) -> Result<(Outcome, Solved), String> {
    run_solved_full(scene, &declared_of(scene), dir, with_bound, noise_seed)
}

/// Renders the scene with the noise of `noise_seed` and reconstructs it
/// on `declared`.
fn run_solved_full(
    scene: &Scene,
    declared: &Station,
    dir: &std::path::Path,
    with_bound: bool,
    noise_seed: u64,
) -> Result<(Outcome, Solved), String> {
    let st = &scene.truth;
    let e = &st.element;
    let spec = RandomSurfaceSpec {
        rms_nm: scene.surface_rms_nm,
        ..RandomSurfaceSpec::default()
    };
    let (front, back) = spec
        .draw_pair(e.aperture_radius_mm, e.centre(), scene.seed)
        .unwrap();
    let back = e.wedge.added_to(&back).unwrap();
    let plate = Plate::new(st, front.clone(), back.clone(), DEFAULT_EDGE_MARGIN_MM);
    let params = SimParams {
        noise_frac: scene.noise,
        bit_depth: 12,
        seed: noise_seed,
        falloff: scene.falloff,
        ..SimParams::default()
    };
    let truth_file = SurfacesFile::from_surfaces(&front, &back);
    let acq_dir = dir.join("acquisition");
    mfd::sim::simulate(
        &Simulation {
            station: st,
            plate: &plate,
            truth: &truth_file,
            patterns: &scene.patterns,
            params: params.clone(),
            layout: FrameLayout::Stack {
                dtype: mfd::formats::npy::StackDtype::U16,
            },
            overwrite: true,
        },
        &acq_dir,
    )
    .unwrap();
    let mut acq = Acquisition::open(&acq_dir).unwrap();
    let options = Options {
        surfaces: Some(SurfaceOptions::default()),
        // For a failing seed's diagnosis: the declared wedge alone.
        skip_wedge_search: std::env::var_os("MFD_WEDGE_KEEP_DECLARED").is_some(),
        ..Options::default()
    };
    let rec = pipeline::reconstruct(
        Input::Acquisition(&mut acq),
        declared,
        &options,
        &mut |_, _| {},
    )
    .map_err(|e: PipelineError| e.to_string())?;
    // The result folder as `mfd reconstruct` writes it (its files are checked
    // where a test needs them).
    rec.write(&dir.join("result"))
        .map_err(|e| format!("writing the result: {e}"))?;
    let spectral = rec.spectral.as_ref().unwrap();
    let wedge_note = spectral.wedge.map(|w| w.describe());
    let used_found = spectral.wedge.is_some_and(|w| w.used_found);
    let stage = match rec.surfaces {
        Some(Ok(s)) => s,
        Some(Err(e)) => return Err(format!("surface stage: {e}")),
        None => unreachable!(),
    };
    let sol = &stage.solution;
    let bound = with_bound.then(|| bound(st, &plate, &scene.patterns, &params));
    let z = |fit: &ZernikeSurface, truth: &ZernikeSurface, std: &[f64]| {
        let (c, t) = (fit.coefficients_nm(), truth.coefficients_nm());
        let n = c.len().min(t.len());
        let zs: Vec<f64> = (REMOVED_TERMS..n).map(|k| (c[k] - t[k]) / std[k]).collect();
        (zs.iter().map(|z| z * z).sum::<f64>() / zs.len() as f64).sqrt()
    };
    let outcome = Outcome {
        // Over the element's outline (for the disk, the Noll 4+ RMS).
        error: [
            over_outline(st, sol.front.coefficients_nm(), front.coefficients_nm()),
            over_outline(st, sol.back.coefficients_nm(), back.coefficients_nm()),
        ],
        bound,
        reported: [
            figures(sol, false).error_rms_nm,
            figures(sol, true).error_rms_nm,
        ],
        z_rms: [
            z(&sol.front, &front, &sol.front_std_nm),
            z(&sol.back, &back, &sol.back_std_nm),
        ],
        wedge_note,
        used_found,
        // A back the solver did not fit (its σ zero) is not reported.
        withheld: [
            stage.withheld[0].clone(),
            stage.withheld[1]
                .clone()
                .or_else(|| (!sol.back_fitted).then(|| "back not fitted".to_string())),
        ],
    };
    Ok((
        outcome,
        Solved {
            solution: stage.solution.clone(),
            truth: [front, back],
        },
    ))
}

/// The RMS over `st`'s outline of `fit − truth`, the plane removed, nm
/// ([`rms_difference_nm`] for the disk).
pub fn over_outline(st: &Station, fit: &[f64], truth: &[f64]) -> f64 {
    let n = fit.len().max(truth.len());
    let d: Vec<f64> = (0..n)
        .map(|k| fit.get(k).copied().unwrap_or(0.0) - truth.get(k).copied().unwrap_or(0.0))
        .collect();
    match st.element.outline().orthonormal(n) {
        Ok(q) if !q.is_identity() => q.rms(&d, REMOVED_TERMS),
        _ => rms_difference_nm(fit, truth),
    }
}

/// [`run_scored`] with the bound.
pub fn run(scene: &Scene, dir: &std::path::Path) -> Result<Outcome, String> {
    run_scored(scene, dir, true)
}

/// The Cramér–Rao bound of each surface (Noll 4+ RMS, nm): the spectral
/// bound at the true points as every pixel's covariance, through the exact
/// optics at the true plate, 36 terms.
fn bound(st: &Station, plate: &Plate, patterns: &[Pattern], params: &SimParams) -> [f64; 2] {
    let view = TracedView::trace(st, plate);
    let cam = Renderer::new(&view, &st.screen, params.clone()).unwrap();
    let design = mfd::solve::spectral::design(st, &FrameInfo::from_patterns(patterns)).unwrap();
    let sigma = params.noise_frac * params.full_scale();
    let crb = truth_cov_map(
        &design,
        &view,
        cam.gain(),
        params.ambient,
        params.tau_max.powi(-2),
        sigma,
    );
    let obs = Observations::from_maps(st, &view.screen_coords(), Uncertainty::Cov(&crb)).unwrap();
    let at_truth = SurfaceOptions {
        terms: Some(36),
        covariance_smoothing_px: 0,
        ..SurfaceOptions::default()
    };
    let sol = reconstruct(&obs, st, &at_truth).unwrap();
    [
        figures(&sol, false).error_rms_nm,
        figures(&sol, true).error_rms_nm,
    ]
}

fn wedged(arcmin: f64, azimuth_deg: f64) -> Wedge {
    Wedge {
        arcmin,
        azimuth_deg,
    }
}

fn check(name: &str, o: &Outcome) {
    eprintln!("{name}: {o:?}");
    for k in 0..2 {
        let face = ["front", "back"][k];
        let bound = o.bound.expect("scored with the bound")[k];
        let (ratio, honest) = (o.error[k] / bound, o.error[k] / o.reported[k]);
        // The criteria: within 1.5× the bound, and the actual error
        // over the reported one 0.6–1.6 (one realisation of ~33 terms: the
        // RMS of 33 unit normals lies within 0.76–1.24 at 2σ).
        assert!(ratio <= 1.5, "{name} {face}: {ratio:.2}× the bound");
        assert!(
            (0.6..=1.6).contains(&honest),
            "{name} {face}: error over reported {honest:.2}"
        );
        // Per coefficient too (the issue saw z-scores of RMS 1.85 where the
        // surface's error was twice its report).
        assert!(
            (0.6..=1.6).contains(&o.z_rms[k]),
            "{name} {face}: coefficient z-scores of RMS {:.2}",
            o.z_rms[k]
        );
    }
}

#[test]
fn a_declared_one_arcmin_wedge_is_measured_at_the_bound_and_honestly() {
    let dir = tempfile::tempdir().unwrap();
    let mut st = binned_paper_station(10.0, 1.5);
    st.element.wedge = wedged(1.0, 0.0);
    let o = run(&Scene::paper(st.clone(), st.element.wedge, 11), dir.path()).unwrap();
    check("1 arcmin, declared", &o);
}

#[test]
fn a_declared_thirty_arcmin_wedge_is_measured_at_the_bound_and_honestly() {
    let dir = tempfile::tempdir().unwrap();
    let mut st = binned_paper_station(10.0, 1.5);
    st.element.wedge = wedged(30.0, 0.0);
    let o = run(&Scene::paper(st.clone(), st.element.wedge, 12), dir.path()).unwrap();
    check("30 arcmin, declared", &o);
    assert!(
        !o.used_found,
        "the declared wedge is where the frames show it: {:?}",
        o.wedge_note
    );
}

#[test]
fn an_undeclared_thirty_arcmin_wedge_is_found_and_measured_or_named() {
    let dir = tempfile::tempdir().unwrap();
    let mut st = binned_paper_station(10.0, 1.5);
    st.element.wedge = wedged(30.0, 0.0);
    match run(&Scene::paper(st, Wedge::NONE, 13), dir.path()) {
        Ok(o) => {
            check("30 arcmin, undeclared", &o);
            assert!(o.used_found, "{:?}", o.wedge_note);
            let note = o.wedge_note.unwrap();
            assert!(note.contains("element.wedge_arcmin"), "{note}");
        }
        Err(msg) => {
            assert!(
                msg.contains("wedge") && msg.contains("element.wedge_arcmin"),
                "{msg}"
            );
        }
    }
}

/// The same draw under `realisations` noise seeds (the soaks' knob for a
/// seed whose error exceeds its report): per surface, the reported error,
/// the mean fit's error (a bias shows here and does not shrink with more
/// realisations) and the fits' scatter about their mean (what the reported
/// error should match if the fit is unbiased), each over the outline.
/// Printed, one line per realisation and one per surface.
pub fn noise_study(scene: &Scene, realisations: u64) {
    let mut fits: [Vec<Vec<f64>>; 2] = [Vec::new(), Vec::new()];
    let mut reported: [Vec<f64>; 2] = [Vec::new(), Vec::new()];
    let mut stds: [Vec<f64>; 2] = [Vec::new(), Vec::new()];
    let mut truth: Option<[ZernikeSurface; 2]> = None;
    for r in 0..realisations {
        let dir = tempfile::tempdir().unwrap();
        match run_solved_with_noise(scene, dir.path(), false, scene.seed + 1000 + 7919 * r) {
            Err(msg) => eprintln!("noise study {r}: refused: {msg}"),
            Ok((o, s)) => {
                eprintln!(
                    "noise study {r}: error {:.2?} nm, reported {:.2?}, z_rms {:.2?}, withheld {:?}",
                    o.error, o.reported, o.z_rms, o.withheld
                );
                for k in 0..2 {
                    let surf = if k == 0 {
                        &s.solution.front
                    } else {
                        &s.solution.back
                    };
                    let std = if k == 0 {
                        &s.solution.front_std_nm
                    } else {
                        &s.solution.back_std_nm
                    };
                    stds[k] = std.clone();
                    fits[k].push(surf.coefficients_nm().to_vec());
                    reported[k].push(o.reported[k]);
                }
                truth = Some(s.truth);
            }
        }
    }
    let Some(truth) = truth else { return };
    let st = &scene.truth;
    for k in 0..2 {
        let n = fits[k].iter().map(Vec::len).max().unwrap_or(0);
        let m = fits[k].len() as f64;
        let mean: Vec<f64> = (0..n)
            .map(|j| {
                fits[k]
                    .iter()
                    .map(|c| c.get(j).copied().unwrap_or(0.0))
                    .sum::<f64>()
                    / m
            })
            .collect();
        let bias = over_outline(st, &mean, truth[k].coefficients_nm());
        let scatter = (fits[k]
            .iter()
            .map(|c| over_outline(st, c, &mean).powi(2))
            .sum::<f64>()
            / (m - 1.0).max(1.0))
        .sqrt();
        let rep = reported[k].iter().sum::<f64>() / m;
        // Per coefficient (Noll 4+): the mean fit's bias and the scatter,
        // each over the last realisation's reported σ.
        let t = truth[k].coefficients_nm();
        let per: Vec<String> = (REMOVED_TERMS..n.min(stds[k].len()))
            .map(|j| {
                let sd = (fits[k]
                    .iter()
                    .map(|c| (c.get(j).copied().unwrap_or(0.0) - mean[j]).powi(2))
                    .sum::<f64>()
                    / (m - 1.0).max(1.0))
                .sqrt();
                let b = mean[j] - t.get(j).copied().unwrap_or(0.0);
                format!(
                    "Z{}: bias {:.1}σ sd {:.2}σ",
                    j + 1,
                    b / stds[k][j],
                    sd / stds[k][j]
                )
            })
            .collect();
        eprintln!(
            "noise study {} per term: {}",
            ["front", "back"][k],
            per.join("; ")
        );
        eprintln!(
            "noise study {}: {m} realisations, reported {rep:.2} nm, mean fit's error {bias:.2} \
             nm, scatter about the mean {scatter:.2} nm",
            ["front", "back"][k]
        );
    }
}

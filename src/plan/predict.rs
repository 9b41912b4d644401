//! The prediction of one schedule before any frame is taken: the flat
//! plate traced through the station, every pixel's Cramér–Rao bound of its
//! screen points under the schedule ([`crate::budget::scene::bound_map`],
//! the simulator's radiometry), the noise-free reconstruction whose
//! covariance is the bound of the Zernike coefficients (the surface
//! solver's own normal equations), which estimator `auto` will use
//! ([`bound_kind`]), whether it will measure (per-pixel: the stage finds
//! and separates the two reflections; surface-domain: the fit converges
//! from the flat plate, [`super::converge`]), and the acquisition time.

use serde::Serialize;

use crate::acquire::acquisition::FrameInfo;
use crate::budget::scene::{self, auto_stride, bound_map, SceneOptions};
use crate::optics::station::Station;
use crate::optics::trace::{Miss, Plate, TracedView, DEFAULT_EDGE_MARGIN_MM};
use crate::optics::zernike::ZernikeSurface;
use crate::solve::spectral::bound::truth_cov_map;
use crate::solve::spectral::model::Design;
use crate::solve::spectral::pixel::RESOLVE_SIGMAS;
use crate::solve::surfaces::{reconstruct, Observations, Uncertainty};

use super::ambiguity::{self, Ambiguity};
use super::converge::{self, Convergence};
use super::stage::{self, StageCheck};
use super::{invalid, PlanError, PlanOptions};

/// Fraction of the pixels with both reflections that must be separable
/// for the schedule to measure the back: nine in ten (the surface solver
/// fits the back from the pixels it is given; a tenth lost at the rim
/// costs little, most of them lost leave the back to the front's slopes).
pub const SEPARABLE_FRACTION: f64 = 0.9;

/// Which Cramér–Rao bound a prediction is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum BoundKind {
    /// The spectral stage's per-pixel bound of the screen points,
    /// propagated through the surface solver: what the two-stage estimator
    /// can reach. Needs the reflections separable per pixel.
    PerPixel,
    /// The surface-domain fit's global bound ([`crate::solve::direct`]):
    /// every pixel's full 4×4 bound of `(u1, v1, u2, v2)` (all its
    /// parameters free, however close the reflections) through the surface
    /// solver's normal equations, as `budget::scene` and `mfd bench thin`
    /// compute it. Used where the reflections are closer than
    /// `--estimator auto`'s rule ([`crate::solve::direct::surface_domain_preferred`]),
    /// i.e. where `auto` will fit the surfaces to the frames.
    SurfaceDomain,
}

/// Which bound a schedule of `design` is predicted with on the traced
/// flat plate `view`, and the median front–back separation in Fourier
/// bins it is decided on: `auto`'s own rule on the stage's candidate
/// pixels, so that the plan and the reconstruction choose alike.
pub fn bound_kind(design: &Design, view: &TracedView, opts: &PlanOptions) -> (BoundKind, f64) {
    let candidates =
        crate::solve::spectral::prior_candidates(view, i64::from(opts.spectral.margin_px));
    let bins = crate::solve::direct::median_separation_bins_of(
        design,
        view,
        candidates.iter().map(|&c| c as usize),
    );
    let kind = if crate::solve::direct::surface_domain_preferred(bins) {
        BoundKind::SurfaceDomain
    } else {
        BoundKind::PerPixel
    };
    (kind, bins)
}

/// The bound of one surface.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SurfacePrediction {
    /// 1σ per Noll term (index k is term j = k + 1), nm; 0 where fixed.
    pub std_nm: Vec<f64>,
    /// Expected RMS error over the aperture, piston and tilts removed: the
    /// root of the summed variances of terms j ≥ 4, nm.
    pub rms_nm: f64,
}

impl SurfacePrediction {
    /// Relative standard deviation of the achieved RMS error over `seeds`
    /// noise draws, if the errors are the bound's: the squared RMS is
    /// `S = Σ e_j²` (j ≥ 4) with `e_j ~ N(0, σ_j²)` independent, so
    /// `Var S = 2 Σ σ_j⁴` and, to first order, `sd(√S)/√S = ½ sd(S)/S =
    /// √(2 Σ σ⁴) / (2 Σ σ²)`; the RMS over m seeds has `Var` over m. It is
    /// `1/√(2 n_eff m)` with `n_eff = (Σσ²)²/Σσ⁴` the effective number of
    /// terms: equal σ over 33 terms give 12 % for one seed, a bound
    /// dominated by a few low-order terms much more.
    pub fn rms_relative_spread(&self, seeds: usize) -> f64 {
        let (s2, s4) = self
            .std_nm
            .iter()
            .skip(3)
            .fold((0.0, 0.0), |(a, b), s| (a + s * s, b + s.powi(4)));
        (2.0 * s4).sqrt() / (2.0 * s2) / (seeds.max(1) as f64).sqrt()
    }
}

/// Whether the per-pixel stage can tell the two reflections apart.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Separation {
    /// Sample pixels with both reflections.
    pub pixels: usize,
    /// Their median front–back distance on the screen, px.
    pub median_separation_px: f64,
    /// Fraction of them whose separation exceeds [`RESOLVE_SIGMAS`] times
    /// its bound (the spectral stage's own test for reporting both points).
    pub separable_fraction: f64,
    /// At least [`SEPARABLE_FRACTION`] of them are separable (true when no
    /// pixel has two reflections: there is nothing to separate).
    pub separable: bool,
}

/// The prediction of one schedule.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Prediction {
    /// Frames.
    pub frames: usize,
    /// Times the screen changes pattern (repeats excluded).
    pub patterns_shown: usize,
    /// Acquisition time, s.
    pub seconds: f64,
    /// The bound used.
    pub bound: BoundKind,
    /// Median front–back separation over the pixels, Fourier bins of the
    /// schedule's τ span (NaN with one reflection): what decides `bound`.
    pub separation_bins: f64,
    /// The front surface.
    pub front: SurfacePrediction,
    /// The back surface; `None` when it is not measured (AR-coated, or the
    /// reflections not separable: see `not_measured_because`).
    pub back: Option<SurfacePrediction>,
    /// Why the back is not measured, in an operator's words.
    pub back_not_measured_because: Option<String>,
    /// Separability of the two reflections.
    pub separation: Separation,
    /// Ambiguity of the start (diagnostic: the information-weighted
    /// ambiguity function and the noise-free periodogram start).
    pub ambiguity: Ambiguity,
    /// The spectral stage run on sample pixels at the planned noise
    /// ([`stage::stage_check`]): whether it finds the true points.
    pub stage: StageCheck,
    /// The surface-domain fit's convergence from the flat plate
    /// ([`converge::convergence`]): the measurability rule where the bound
    /// is [`BoundKind::SurfaceDomain`], a diagnostic elsewhere.
    pub convergence: Convergence,
    /// Why the estimator will not measure this schedule, in an operator's
    /// words; `None` when it will (the per-pixel route:
    /// [`StageCheck::measurable`]; the surface-domain fit:
    /// [`Convergence::converges`] and signal detected on the stage's
    /// sample pixels).
    pub not_measurable_because: Option<String>,
    /// The block size the bound was evaluated on, camera px.
    pub bound_stride_px: usize,
}

/// The traced flat plate with the back's weight scaled (0: the back path
/// removed, an AR-coated back).
pub fn traced_view(station: &Station, back_scale: f64) -> Result<TracedView, PlanError> {
    let e = &station.element;
    let flat = ZernikeSurface::flat(
        e.aperture_radius_mm,
        [e.aperture_center_mm.x, e.aperture_center_mm.y],
    )
    .map_err(scene::BudgetError::from)?;
    let plate = Plate::new(station, flat.clone(), flat, DEFAULT_EDGE_MARGIN_MM);
    let mut view = TracedView::trace(station, &plate);
    for p in &mut view.pixels {
        if back_scale == 0.0 {
            p.back = Err(Miss::ElementMissed);
        } else if let Ok(h) = &mut p.back {
            h.weight *= back_scale;
        }
        p.third = Err(Miss::ElementMissed);
    }
    Ok(view)
}

/// Up to `n` lit pixels spread evenly over the view (every k-th), those
/// with both reflections when `both`.
pub fn sample_pixels(view: &TracedView, n: usize, both: bool) -> Vec<usize> {
    let lit: Vec<usize> = (0..view.pixels.len())
        .filter(|&q| {
            let p = &view.pixels[q];
            if both {
                p.front.is_ok() && p.back.is_ok_and(|h| h.weight > 0.0)
            } else {
                p.front.is_ok() || p.back.is_ok_and(|h| h.weight > 0.0)
            }
        })
        .collect();
    let step = lit.len().div_ceil(n.max(1)).max(1);
    lit.into_iter().step_by(step).collect()
}

/// Up to `n` pixels spread evenly over the sensor whose reflections in
/// the expected plate `bent` are those of the flat prediction `flat` (no
/// path appears or leaves at the rim between them), with both reflections
/// when `both`: the pixels the stage is run on.
pub fn stage_pixels(flat: &TracedView, bent: &TracedView, n: usize, both: bool) -> Vec<usize> {
    let same = |q: usize| {
        let (a, b) = (&flat.pixels[q], &bent.pixels[q]);
        a.front.is_ok() == b.front.is_ok() && a.back.is_ok() == b.back.is_ok()
    };
    let lit: Vec<usize> = (0..flat.pixels.len())
        .filter(|&q| {
            let p = &flat.pixels[q];
            let ok = if both {
                p.front.is_ok() && p.back.is_ok_and(|h| h.weight > 0.0)
            } else {
                p.front.is_ok()
            };
            ok && same(q)
        })
        .collect();
    let step = lit.len().div_ceil(n.max(1)).max(1);
    lit.into_iter().step_by(step).collect()
}

/// The stage run on `n` sample pixels of `frames`' design (see
/// [`stage::stage_check`]): the prior is the station's flat plate with
/// both paths (what the stage holds, AR-coated or not), the truth the
/// expected plate.
pub fn run_stage(
    station: &Station,
    design: &Design,
    view: &TracedView,
    bent: &TracedView,
    n: usize,
    opts: &PlanOptions,
) -> Result<StageCheck, PlanError> {
    let full;
    let prior = if opts.back_scale == 1.0 {
        view
    } else {
        full = traced_view(station, 1.0)?;
        &full
    };
    let both = opts.back_scale > 0.0;
    let pixels = stage_pixels(view, bent, n, both);
    let gain = opts.radiometry.gain(view);
    Ok(stage::stage_check(
        design, prior, bent, &pixels, gain, opts, STAGE_SEED,
    ))
}

/// The noise draws of the stage's check: fixed, so that a plan is the
/// same every time it is made.
pub const STAGE_SEED: u64 = 0x005e_ed17;

/// Sample pixels the surface-domain fit's iteration is run on
/// ([`converge::pixels_converge`]).
pub const CONVERGENCE_PIXELS: usize = 64;

/// Sample pixels the stage is run on by [`predict`].
pub const STAGE_PIXELS: usize = 64;

/// The bound's covariance of one pixel (`screen_cov.npy` layout, 16 values).
pub fn pixel_cov(
    design: &Design,
    view: &TracedView,
    q: usize,
    gain: f64,
    opts: &PlanOptions,
) -> Vec<f64> {
    let r = &opts.radiometry;
    let one = TracedView {
        width: 1,
        height: 1,
        pixels: vec![view.pixels[q]],
    };
    truth_cov_map(
        design,
        &one,
        gain,
        r.ambient,
        r.tau_max.powi(-2),
        r.sigma_counts(),
    )
}

/// Separability on the sample pixels `both` (pixels with two reflections).
pub fn separation(
    design: &Design,
    view: &TracedView,
    both: &[usize],
    gain: f64,
    opts: &PlanOptions,
) -> Separation {
    let mut seps = Vec::new();
    let mut good = 0usize;
    for &q in both {
        let p = &view.pixels[q];
        let (Ok(f), Ok(b)) = (p.front, p.back) else {
            continue;
        };
        let d = [b.u - f.u, b.v - f.v];
        let dist = d[0].hypot(d[1]);
        seps.push(dist);
        let c = pixel_cov(design, view, q, gain, opts);
        // Var of the separation along d: Var(Δ) with Δ = (u2 − u1, v2 − v1).
        let at = |a: usize, b: usize| c[4 * a + b];
        let mut var = 0.0;
        for (a, wa) in [(0, -d[0]), (1, -d[1]), (2, d[0]), (3, d[1])] {
            for (b, wb) in [(0, -d[0]), (1, -d[1]), (2, d[0]), (3, d[1])] {
                var += wa * wb * at(a, b);
            }
        }
        let sd = (var / (dist * dist).max(1e-300)).sqrt();
        if sd.is_finite() && RESOLVE_SIGMAS * sd < dist {
            good += 1;
        }
    }
    seps.sort_by(f64::total_cmp);
    let n = seps.len();
    let frac = if n == 0 { 1.0 } else { good as f64 / n as f64 };
    Separation {
        pixels: n,
        median_separation_px: seps.get(n / 2).copied().unwrap_or(f64::NAN),
        separable_fraction: frac,
        separable: frac >= SEPARABLE_FRACTION,
    }
}

/// The prediction of `frames` (display order) on `station`.
///
/// # Errors
/// [`PlanError`] for out-of-range options, parallel directions, or a
/// reconstruction the surface solver cannot make (too few pixels).
pub fn predict(
    station: &Station,
    frames: &[FrameInfo],
    opts: &PlanOptions,
) -> Result<Prediction, PlanError> {
    opts.validate()?;
    if frames.is_empty() {
        return Err(invalid("the schedule", "no frames"));
    }
    let design = scene::design(station, frames)?;
    let view = traced_view(station, opts.back_scale)?;
    let gain = opts.radiometry.gain(&view);
    let both = sample_pixels(&view, 400, true);
    let separation = separation(&design, &view, &both, gain, opts);
    let bent = ambiguity::expected_view(station, opts)?;
    let spread = ambiguity::spread_between(&view, &bent, opts);
    let stage = run_stage(station, &design, &view, &bent, STAGE_PIXELS, opts)?;
    let (bound, separation_bins) = bound_kind(&design, &view, opts);
    let kappa = opts.radiometry.tau_max.powi(-2);
    let both_sample = sample_pixels(&view, CONVERGENCE_PIXELS, true);
    let convergence = converge::convergence(
        station,
        frames,
        &converge::Scene {
            design: &design,
            flat: &view,
            bent: &bent,
            pixels: &both_sample,
            gain,
            radiometry: &opts.radiometry,
        },
        spread,
    );
    let not_measurable_because = match bound {
        BoundKind::PerPixel => (!stage.measurable).then(|| {
            format!(
                "the spectral stage ({} engine), run on {} sample pixels at this noise, found the true points on {:.0} % of them (needs {:.0} %; no signal detected on {:.0} %): give more frames or spread τ wider",
                stage.engine,
                stage.pixels,
                100.0 * stage.found_fraction,
                100.0 * stage::STAGE_FRACTION,
                100.0 * stage.no_signal_fraction
            )
        }),
        BoundKind::SurfaceDomain => surface_domain_unmeasurable(&convergence, &stage),
    };
    let sample = sample_pixels(&view, 200, false);
    let ambiguity = ambiguity::ambiguity(station, frames, &design, (&view, &sample), spread, kappa);
    let stride = opts.bound_stride_px.unwrap_or_else(|| auto_stride(&view));
    let mut cov = bound_map(&design, &view, gain, &opts.radiometry, stride);
    let mut coords = view.screen_coords();
    let back_off = if opts.back_scale == 0.0 {
        Some("the back is AR-coated: one reflection".to_string())
    } else if bound == BoundKind::PerPixel && !separation.separable {
        Some(format!(
            "this schedule separates the two reflections on {:.0} % of the pixels (needs {:.0} %): add frames at larger τ or spread τ wider",
            100.0 * separation.separable_fraction,
            100.0 * SEPARABLE_FRACTION
        ))
    } else {
        None
    };
    if back_off.is_some() {
        // The two-stage estimator reports no back point where it cannot
        // separate them: predict the front from the front points alone,
        // with the bound of the two-reflection fit.
        for q in 0..view.pixels.len() {
            coords[4 * q + 2] = f64::NAN;
            coords[4 * q + 3] = f64::NAN;
            for a in 0..4 {
                for b in 0..4 {
                    if a >= 2 || b >= 2 {
                        cov[16 * q + 4 * a + b] = f64::NAN;
                    }
                }
            }
        }
    }
    let observations = Observations::from_maps(station, &coords, Uncertainty::Cov(&cov))?;
    let scene_opts = SceneOptions {
        radiometry: opts.radiometry.clone(),
        terms: opts.terms,
        ..SceneOptions::default()
    };
    let sol = reconstruct(&observations, station, &scene_opts.surface_options())?;
    let surface = |std: &[f64]| SurfacePrediction {
        std_nm: std.to_vec(),
        rms_nm: std.iter().skip(3).map(|s| s * s).sum::<f64>().sqrt(),
    };
    let back = (sol.back_fitted && back_off.is_none()).then(|| surface(&sol.back_std_nm));
    let front = surface(&sol.front_std_nm);
    // `mfd reconstruct` withholds a surface whose expected error is at
    // least its fitted RMS (`pipeline::withheld`): a bound at the expected
    // departure or above resolves nothing.
    let not_measurable_because = not_measurable_because.or_else(|| {
        (front.rms_nm >= opts.surface_nm).then(|| {
            format!(
                "the predicted front error, {:.0} nm RMS, is at least the expected departure of the surface ({:.0} nm RMS, --surface-nm): the reconstruction would be withheld; give more frames or spread τ wider",
                front.rms_nm, opts.surface_nm
            )
        })
    });
    Ok(Prediction {
        frames: frames.len(),
        patterns_shown: super::timing::switches(frames),
        seconds: opts.timing.seconds(frames),
        bound,
        separation_bins,
        front,
        back,
        back_not_measured_because: back_off,
        separation,
        ambiguity,
        stage,
        convergence,
        not_measurable_because,
        bound_stride_px: stride,
    })
}

/// Why the surface-domain fit will not measure a schedule: its start
/// outside the basin the fit converges from, or the stage detecting no
/// signal on more than a tenth of the sample pixels (the fit leaves out
/// the pixels the stage found no fringes on); `None` when it will.
pub fn surface_domain_unmeasurable(c: &Convergence, stage: &StageCheck) -> Option<String> {
    if !c.converges {
        let worst = c
            .directions
            .iter()
            .map(|d| d.basin_px)
            .fold(f64::INFINITY, f64::min);
        return Some(format!(
            "the reflections are too close to separate pixel by pixel, and the surface-domain fit started from the flat plate does not reach the truth from the prior's spread of {:.1} px (one reflection: from {worst:.1} px; both, noise-free: on {:.0} % of the sample pixels, needs {:.0} %): add frames at low τ, or start from a closer prior",
            c.prior_spread_px,
            100.0 * c.pixel_fraction,
            100.0 * converge::PIXEL_FRACTION
        ));
    }
    (stage.no_signal_fraction > 1.0 - stage::STAGE_FRACTION).then(|| {
        format!(
            "the spectral stage detected no fringes on {:.0} % of {} sample pixels at this noise (the surface-domain fit leaves those out; at most {:.0} %): give more frames",
            100.0 * stage.no_signal_fraction,
            stage.pixels,
            100.0 * (1.0 - stage::STAGE_FRACTION)
        )
    })
}

impl Prediction {
    /// The prediction as the JSON `mfd plan --json` writes: `frames`,
    /// `seconds`, `predicted.front_rms_nm`, `predicted.back_rms_nm` (null
    /// when not measured), and the rest.
    pub fn json(&self) -> serde_json::Value {
        serde_json::json!({
            "frames": self.frames,
            "seconds": self.seconds,
            "patterns_shown": self.patterns_shown,
            "predicted": {
                "bound": self.bound,
                "separation_bins": self.separation_bins,
                "front_rms_nm": self.front.rms_nm,
                "back_rms_nm": self.back.as_ref().map(|b| b.rms_nm),
                "front_std_nm": self.front.std_nm,
                "back_std_nm": self.back.as_ref().map(|b| &b.std_nm),
                "back_not_measured_because": self.back_not_measured_because,
            },
            "separation": self.separation,
            "ambiguity": self.ambiguity,
            "measurable": self.not_measurable_because.is_none(),
            "not_measurable_because": self.not_measurable_because,
            "stage": self.stage,
            "convergence": self.convergence,
            "bound_stride_px": self.bound_stride_px,
        })
    }
}

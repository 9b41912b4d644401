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
use crate::optics::trace::TracedView;
use crate::solve::spectral::model::Design;
use crate::solve::surfaces::{reconstruct, Observations, Uncertainty};

use super::ambiguity::{self, Ambiguity};
use super::converge::{self, Convergence};
use super::stage::StageCheck;
use super::{invalid, PlanError, PlanOptions};

mod pixels;
mod reasons;
mod separation;

pub use pixels::{run_stage, sample_pixels, stage_pixels, traced_view};
pub use reasons::surface_domain_unmeasurable;
pub use separation::{pixel_cov, separation, Separation, SEPARABLE_FRACTION};

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
    ///
    /// [`stage::stage_check`]: super::stage::stage_check
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
    let stage = run_stage(station, &design, &view, &bent, STAGE_PIXELS, opts, true)?;
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
        BoundKind::PerPixel => reasons::stage_unmeasurable(&stage),
        BoundKind::SurfaceDomain => surface_domain_unmeasurable(&convergence, &stage),
    };
    let sample = sample_pixels(&view, 200, false);
    let ambiguity = ambiguity::ambiguity(station, frames, &design, (&view, &sample), spread, kappa);
    let back_off = reasons::back_not_measured(opts, bound, &separation);
    let (front, back, stride) =
        surface_bounds(station, &design, &view, gain, opts, back_off.is_none())?;
    // `mfd reconstruct` withholds a surface whose expected error is at
    // least its fitted RMS (`pipeline::withheld`): a bound at the expected
    // departure or above resolves nothing.
    let not_measurable_because =
        not_measurable_because.or_else(|| reasons::front_withheld(&front, opts));
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

/// The noise draws of the stage's check: fixed, so that a plan is the
/// same every time it is made.
pub const STAGE_SEED: u64 = 0x005e_ed17;

/// Sample pixels the surface-domain fit's iteration is run on
/// ([`converge::pixels_converge`]).
pub const CONVERGENCE_PIXELS: usize = 64;

/// Sample pixels the stage is run on by [`predict`].
pub const STAGE_PIXELS: usize = 64;

/// The bound of both surfaces through the surface solver's normal
/// equations: every pixel's bound on the block grid (the stride used is
/// returned), the back's points left out unless `with_back`; the back's
/// bound only where it is fitted and `with_back`.
fn surface_bounds(
    station: &Station,
    design: &Design,
    view: &TracedView,
    gain: f64,
    opts: &PlanOptions,
    with_back: bool,
) -> Result<(SurfacePrediction, Option<SurfacePrediction>, usize), PlanError> {
    let stride = opts.bound_stride_px.unwrap_or_else(|| auto_stride(view));
    let mut cov = bound_map(design, view, gain, &opts.radiometry, stride);
    let mut coords = view.screen_coords();
    if !with_back {
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
        rms_nm: std.iter().skip(3).fold(0.0, |a, s| a + s * s).sqrt(),
    };
    let back = (sol.back_fitted && with_back).then(|| surface(&sol.back_std_nm));
    let front = surface(&sol.front_std_nm);
    Ok((front, back, stride))
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

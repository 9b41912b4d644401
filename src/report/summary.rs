//! `summary.json` (`mfd-summary/1`): the figures of a surface solution for
//! scripts and for the operator's report — pixels used, outliers, both
//! surfaces' figures and coefficients with σ, the term choice, every stage's
//! iterations and χ², the fit's χ²/dof and condition number; what the σ
//! include (the noise alone, or the station's geometry too), and where a
//! station uncertainty was used, the error budget's breakdown per surface
//! (noise, station, total) with the degrees of freedom that contribute
//! most. Every sentence in it comes from the library constant of the rule
//! it describes.

use serde::{Deserialize, Serialize};

use crate::budget::refine::Refined;

use crate::solve::surfaces::convergence::{self, Convergence};
use crate::solve::surfaces::report::{figures, SurfaceFigures, FIGURES_NOTE};
use crate::solve::surfaces::select::{TermChoice, CRITERION};
use crate::solve::surfaces::solve::{Stage, TermChoices, OUTLIER_RULE};
use crate::solve::surfaces::{Observations, SurfaceSolution};

mod station_part;
pub use station_part::{ErrorSplit, Share, StationPart, LISTED_SHARES, STATION_NOTE};

/// The `format` value of a summary.
pub const SUMMARY_FORMAT: &str = "mfd-summary/1";

/// Outliers kept in the summary's list, at most (the count is exact).
const LISTED_OUTLIERS: usize = 1000;

/// The figures of one surface reconstruction (`summary.json`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Summary {
    /// Always [`SUMMARY_FORMAT`].
    pub format: String,
    /// The outline every figure is over (not written: the figures say it
    /// in words, `front.outline`).
    #[serde(skip)]
    pub over: Option<crate::optics::outline::Outline>,
    /// Pixels with a measured S1 and S2.
    pub pixels: PixelCounts,
    /// Whether the screen points' σ came from the data (the spectral stage)
    /// rather than from the residuals.
    pub sigma_from_data: bool,
    /// Pixels left out as outliers.
    pub outliers: Outliers,
    /// What the figures leave out ([`FIGURES_NOTE`]).
    pub figures_note: String,
    /// The front's figures.
    pub front: SurfaceFigures,
    /// The back's figures; `null` when it was not reconstructed.
    pub back: Option<SurfaceFigures>,
    /// How the number of Zernike terms was chosen.
    pub terms: Terms,
    /// Every stage that ran, in order.
    pub stages: Vec<StageSummary>,
    /// How every stage ended: converged, or stopped by its iteration limit
    /// with its last step against its σ, and whether that flags the result
    /// (`mfd` then exits 5 unless `--accept-unconverged`); absent in
    /// summaries written before it.
    #[serde(default)]
    pub convergence: Vec<Convergence>,
    /// Final χ² of the joint fit.
    pub chi2: f64,
    /// Residual components of the final fit.
    pub residuals: usize,
    /// χ²/(N − p).
    pub reduced_chi2: f64,
    /// Factor applied to (JᵀJ)⁻¹ for the covariance.
    pub covariance_scale: f64,
    /// Condition number of the weighted Jacobian.
    #[serde(with = "nullable")]
    pub condition_number: f64,
    /// Wall time of the surface stage, s.
    pub seconds: f64,
    /// What the reported σ include ([`UNCERTAINTY_NOISE_ONLY`] or
    /// [`UNCERTAINTY_WITH_STATION`]).
    #[serde(default)]
    pub uncertainty_note: String,
    /// The station's uncertainty beside the noise, when one was given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub station: Option<StationPart>,
    /// Degrees of freedom estimated with the surfaces (`--refine`), when
    /// asked for; the figures above are those on the refined station.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub refined: Vec<RefinedSummary>,
    /// Which estimator made the surfaces: "per-pixel" (screen points per
    /// pixel, then the surfaces) or "surface-domain" (fitted to the frames).
    #[serde(default = "per_pixel")]
    pub estimator: String,
    /// The surface-domain fit's account, when it made the surfaces.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub direct: Option<DirectSummary>,
    /// Why the front and back are reported as not reconstructed, where
    /// they are (`surfaces.json`'s `not_reconstructed_because`).
    #[serde(default)]
    pub withheld: [Option<String>; 2],
    /// What the result was made from (paths and SHA-256 digests).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inputs: Option<crate::report::records::Inputs>,
    /// The spectral stage's points checked against the station.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub consistency: Option<crate::report::records::Consistency>,
    /// The figures an optician reads, per face and of the plate, each with
    /// its σ (`report::figures`); absent in summaries written before them.
    #[serde(default)]
    pub figures: Option<crate::report::figures::Figures>,
}

fn per_pixel() -> String {
    "per-pixel".into()
}

/// The surface-domain fit (`solve::direct`) in `summary.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct DirectSummary {
    /// What it is, in words.
    pub note: String,
    /// Whether its step criterion was met.
    pub converged: bool,
    /// Pixels fitted with two reflections.
    pub two_reflection_pixels: usize,
    /// Pixels with clipped samples (0 or saturated) and those samples, which
    /// the fit took as censored (at their conditional means) rather than
    /// leaving them out.
    #[serde(default)]
    pub clipped: crate::solve::direct::Clipped,
    /// The third reflection (two internal round trips) where the frames
    /// showed it: `B3 = factor · ρ · B2`, ρ the traced Fresnel ratio (1 for
    /// bare glass), with its σ; absent where it was not modelled.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub third_reflection: Option<crate::solve::direct::ThirdReflection>,
    /// The fit run again from the plate as made, where it started from the
    /// per-pixel surfaces: the two answers compared, the one kept.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub starts: Option<crate::solve::direct::Starts>,
    /// Wall time, s.
    pub seconds: f64,
    /// Per outer iteration: objective, terms, step fraction, step in σ.
    pub iterations: Vec<crate::solve::direct::Iteration>,
    /// The per-pixel route's failure, where it measured nothing.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub per_pixel_failed: Option<String>,
}

/// One degree of freedom estimated jointly with the surfaces.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RefinedSummary {
    /// Its spec name.
    pub name: String,
    /// The estimate's change from the station file, in its unit.
    pub change: f64,
    /// Its 1σ before the data (the uncertainty file's).
    pub prior_std: f64,
    /// Its 1σ with the data.
    pub posterior_std: f64,
}

/// What the reported σ include when a station uncertainty was used.
pub const UNCERTAINTY_WITH_STATION: &str = "sigma and expected errors include the imaging noise \
and the station's geometry uncertainty (the station part below)";

/// What the reported σ include when no station uncertainty was given or
/// found: the noise alone.
pub const UNCERTAINTY_NOISE_ONLY: &str = "sigma and expected errors are the imaging noise alone: \
the station's geometry was taken as exact (no station uncertainty was given or found beside the \
station file); a real station's geometry error is not included";

/// What the surface-domain fit is, for `summary.json`.
pub const DIRECT_NOTE: &str = "surfaces fitted to the frames: every pixel's exact likelihood at \
the screen points the surfaces predict, its background, amplitudes and falloff profiled out; \
sigma from the global Fisher information; samples the camera clipped (0 or saturated) are \
taken as censored, at their conditional means under the fitted model, once the surfaces \
describe the data (iterations with clipped_imputed). `pixels` counts the pixels fitted; \
direct_screen_coords.npy holds the predicted points, direct_chi2.npy each pixel's pull";

/// Pixels that entered the surface stage.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
pub struct PixelCounts {
    /// With a front point S1.
    pub s1: usize,
    /// With a back point S2.
    pub s2: usize,
}

/// The outlier rule and what it left out.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Outliers {
    /// The rule in words ([`OUTLIER_RULE`]).
    pub rule: String,
    /// Pixels left out.
    pub count: usize,
    /// The first of them as `[column, row]` (at most 1000).
    pub pixels_col_row: Vec<[u32; 2]>,
}

/// The term choice: the criterion, and per surface the chosen count with
/// every candidate's value (absent when the caller fixed the count).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Terms {
    /// The criterion in words ([`CRITERION`]), or that the count was fixed.
    pub criterion: String,
    /// The front's choice.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub front: Option<Choice>,
    /// The back's choice.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub back: Option<Choice>,
}

/// One surface's term choice.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Choice {
    /// Chosen number of terms.
    pub terms: usize,
    /// `[terms, BIC]` of every candidate.
    pub candidates: Vec<(usize, f64)>,
}

/// One stage of the surface solvers.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StageSummary {
    /// The stage's name ("front slopes", "back", "joint", ...).
    pub name: String,
    /// Wall time, s.
    pub seconds: f64,
    /// The stage's own figures, beside `name` and `seconds` in the JSON.
    #[serde(flatten)]
    pub detail: StageDetail,
}

/// A stage's own figures: which kind of stage it was decides the fields.
/// (Untagged: the JSON has the fields side by side with `name`, as readers
/// of `mfd-summary/1` expect.)
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(untagged)]
pub enum StageDetail {
    /// The front's slope iteration.
    Slopes(SlopeStage),
    /// A Levenberg–Marquardt stage.
    LeastSquares(LeastSquaresStage),
    /// A stage that reports its time only.
    Timed {},
}

/// Figures of the front's slope iteration.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SlopeStage {
    /// Slope fits run.
    pub iterations: usize,
    /// RMS change of the coefficients in the last iteration, nm.
    pub last_change_nm: f64,
    /// Condition number of the last slope fit.
    #[serde(with = "nullable")]
    pub condition_number: f64,
    /// Pixels whose slopes entered.
    pub points: usize,
}

/// Figures of a Levenberg–Marquardt stage.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LeastSquaresStage {
    /// Normal-equation builds.
    pub iterations: usize,
    /// χ² at the start.
    pub chi2_start: f64,
    /// χ² at the end.
    pub chi2: f64,
    /// Residual components at the end.
    pub residuals: usize,
    /// Whether the step tolerance was reached.
    pub converged: bool,
    /// Why it stopped, in words.
    pub reason: String,
    /// Measured paths the final surfaces could not trace (front, back).
    pub paths_lost: [usize; 2],
}

impl Summary {
    /// The summary of `sol`, solved from `obs` in `seconds`.
    pub fn new(obs: &Observations, sol: &SurfaceSolution, seconds: f64) -> Summary {
        Summary {
            format: SUMMARY_FORMAT.into(),
            over: Some(sol.outline.clone()),
            pixels: PixelCounts {
                s1: obs.count(0),
                s2: obs.count(1),
            },
            sigma_from_data: obs.sigma_known,
            outliers: Outliers {
                rule: OUTLIER_RULE.into(),
                count: sol.rejected.len(),
                pixels_col_row: sol.rejected.iter().take(LISTED_OUTLIERS).copied().collect(),
            },
            figures_note: FIGURES_NOTE.into(),
            front: figures(sol, false),
            back: sol.back_fitted.then(|| figures(sol, true)),
            terms: terms(sol.choice.as_ref(), sol.terms_fixed),
            stages: sol.stages.iter().map(stage).collect(),
            convergence: convergence::of_stages(&sol.stages),
            chi2: sol.chi2,
            residuals: sol.n_resid,
            reduced_chi2: sol.reduced_chi2,
            covariance_scale: sol.covariance_scale,
            condition_number: sol.condition_number,
            seconds,
            uncertainty_note: UNCERTAINTY_NOISE_ONLY.into(),
            station: None,
            refined: Vec::new(),
            estimator: per_pixel(),
            direct: None,
            withheld: [None, None],
            inputs: None,
            consistency: None,
            figures: None,
        }
    }

    /// The summary of a solution the surface-domain fit made.
    pub fn with_direct(mut self, d: &crate::solve::direct::DirectReport) -> Summary {
        self.estimator = "surface-domain".into();
        self.convergence.push(direct_convergence(d));
        self.direct = Some(DirectSummary {
            note: DIRECT_NOTE.into(),
            converged: d.converged,
            two_reflection_pixels: d.two_reflection_pixels,
            clipped: d.clipped,
            third_reflection: d.third_reflection,
            starts: d.starts.clone(),
            seconds: d.seconds,
            iterations: d.iterations.clone(),
            per_pixel_failed: d.per_pixel_failed.clone(),
        });
        self
    }

    /// The summary with the estimates of a refinement.
    pub fn with_refined(mut self, refined: &Refined) -> Summary {
        self.refined = refined
            .estimates
            .iter()
            .map(|e| RefinedSummary {
                name: e.dof.name().into(),
                change: e.change,
                prior_std: e.prior_std,
                posterior_std: e.posterior_std,
            })
            .collect();
        self
    }

    /// Per-coefficient 1σ of everything known, and the expected RMS error
    /// (j ≥ 4), of the front (`back` false) or back: the station's part's
    /// totals where there is one, else the noise's.
    pub fn reported(&self, back: bool) -> Option<(&[f64], f64)> {
        let station = self.station.as_ref();
        let split = if back {
            station.and_then(|s| s.back.as_ref())
        } else {
            station.map(|s| &s.front)
        };
        let noise = if back {
            self.back.as_ref()
        } else {
            Some(&self.front)
        }?;
        Some(match split {
            Some(s) => (&s.total_std_nm[..], s.total_rms_nm),
            None => (&noise.std_nm[..], noise.error_rms_nm),
        })
    }

    /// Whether a stage's ending flags the result ([`Convergence::flags_result`]).
    pub fn unconverged(&self) -> bool {
        convergence::flagged(&self.convergence)
    }
}

/// What the summary says when the caller did not fix the count but the
/// criterion could not be evaluated (the normal equations at the fit not
/// positive definite): every surface kept the largest model.
pub const CHOICE_FAILED: &str = "not chosen: the criterion could not be evaluated at the fit \
     (singular normal equations); the largest model (--max-terms) was kept";

fn terms(choice: Option<&TermChoices>, fixed: bool) -> Terms {
    let one = |c: &TermChoice| Choice {
        terms: c.terms,
        candidates: c.candidates.clone(),
    };
    match choice {
        Some(c) => Terms {
            criterion: CRITERION.into(),
            front: Some(one(&c.front)),
            back: c.back.as_ref().map(one),
        },
        None => Terms {
            criterion: if fixed {
                "fixed by --terms".into()
            } else {
                CHOICE_FAILED.into()
            },
            front: None,
            back: None,
        },
    }
}

/// The surface-domain fit's ending: converged when its largest step fell
/// below the tolerance in σ, else stopped by its iteration limit, with the
/// last step in σ of the coefficient (its own account, `max_step_sigma`).
/// It does not flag the result: where it did not converge both surfaces
/// are withheld as not reconstructed, with the reason
/// (`pipeline::estimator::withheld`), so no unconverged figure is reported.
fn direct_convergence(d: &crate::solve::direct::DirectReport) -> Convergence {
    let last = d.iterations.last().map(|i| i.max_step_sigma);
    let stopped_by = if d.converged {
        "largest step below its tolerance in sigma".to_string()
    } else {
        format!(
            "iteration limit ({} iterations; the surfaces are withheld as not reconstructed)",
            d.iterations.len()
        )
    };
    let mut c = Convergence::new("surface-domain fit", stopped_by, d.converged, None, false);
    c.step_in_sigma = last.filter(|r| r.is_finite());
    c.flags_result = false;
    c
}

fn stage(s: &Stage) -> StageSummary {
    StageSummary {
        name: s.name.into(),
        seconds: s.seconds,
        detail: match (&s.front, &s.lm) {
            (Some(f), _) => StageDetail::Slopes(SlopeStage {
                iterations: f.iterations,
                last_change_nm: f.last_change_nm,
                condition_number: f.condition_number,
                points: f.points,
            }),
            (None, Some(l)) => StageDetail::LeastSquares(LeastSquaresStage {
                iterations: l.iterations,
                chi2_start: l.chi2_start,
                chi2: l.chi2,
                residuals: l.n_resid,
                converged: l.converged,
                reason: l.reason.clone(),
                paths_lost: l.failed,
            }),
            (None, None) => StageDetail::Timed {},
        },
    }
}

/// A float that JSON writes as `null` when it is not finite (a condition
/// number of a singular system) and reads back as NaN.
mod nullable {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(x: &f64, s: S) -> Result<S::Ok, S::Error> {
        if x.is_finite() {
            s.serialize_f64(*x)
        } else {
            s.serialize_none()
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
    }
}

//! Designing a schedule: the frames (directions, τ values, repeats) that
//! minimise the predicted error for a budget of frames, of seconds, or the
//! frames for a target error.
//!
//! **Method.** An approximate (continuous) optimal design over a candidate
//! grid, then rounded to frames. The candidates are every τ of a grid
//! (0.5 steps up to twice τ_max, beyond which a frame carries less than
//! e⁻⁸ of its information) on each fringe direction, phase 0. A design is
//! a weight per candidate; its Fisher information at sample pixel p is
//! `F_p(w) = N/σ² Σ_c w_c J_pc J_pcᵀ`, `J_pc` the gradient of the per-pixel
//! model (all its parameters: background, amplitudes, screen points,
//! falloff) at the traced flat plate. The criterion is A-optimality of the
//! screen points, `Φ(w) = Σ_p tr(K F_p(w)⁻¹ Kᵀ)` (K picks every present
//! reflection's u and v): the summed Cramér–Rao variances the surface
//! solver's least squares averages into the Zernike coefficients.
//!
//! Why this method: `F_p` is linear in the weights and Φ convex, so the
//! multiplicative algorithm `w_c ← w_c (d_c / Φ)^½`, `d_c = −∂Φ/∂w_c`
//! (Silvey, Titterington & Torsney; Yu 2010 shows it monotone for
//! A-optimality with the power ½) converges to the global optimum from any
//! start with every weight positive, needs no step size, and its
//! general-equivalence bound `Φ* ≥ 2Φ(w) − max_c d_c` certifies how far a
//! design is from the best over these candidates: the Fisher-information
//! limit reported as `efficiency`. Fedorov exchange works on exact designs
//! but needs N steps; an integer program is far too large (≈1200 candidates
//! × 2000 frames); crates for optimal design (none in Rust's ecosystem)
//! would not know this model. Phases are not designed: at one τ the
//! information of a phase-stepped frame differs from a repeat's only by
//! where the pixel sits on the fringe, which averages over the pixels, and
//! a repeat costs no settle time.
//!
//! **Directions.** The candidates may span the plain directions (0°,
//! 90°) beside the diagonals (`--design-directions`). Where the two
//! reflections lie apart along one screen axis (the plane of incidence)
//! the diagonals each see √½ of their separation and the plain direction
//! across it all of it, so the plain directions pay where the reflections
//! are close (docs/figures.md, "Planned schedules"). Their fringes run a
//! shorter length L across the screen, and a blur (the camera's, the
//! screen's) acts on the fringe's period in screen pixels, L/τ: at equal
//! τ they fall off sooner. The model fits one falloff κ per fringe length
//! ([`Design::falloff_group`]), so it holds whether a scene's falloff
//! acts on τ (this renderer's default, the fixtures' forward model) or on
//! the screen period (`mfd simulate --falloff screen-period`); the
//! candidates are weighed, and the prediction made, with the physical one
//! ([`Design::physical_falloff`]), the smaller modulation of the two, so
//! that the geometry, not a renderer's convention, decides their share.
//!
//! **Constraints.** The optimum concentrates the frames near the τ of most
//! information, which can leave the spectral stage's start on a wrong
//! fringe or the reflections unseparated. The design used is the mixture
//! `(1 − α) w* + α u` with the uniform weights `u` (the paper's kind of
//! schedule) and the smallest α (bisection) for which the rounded schedule
//! is measured by the spectral stage itself ([`super::stage`]: its search
//! and fit run on sample pixels at the planned noise find the true points,
//! so an alias outside the range the stage searches costs nothing) and is
//! separable by the stage's 5σ rule. Where the reflections are closer than
//! `--estimator auto`'s rule (a thin plate: the surface-domain fit, not the
//! stage, makes the surfaces) the constraint is instead that fit's
//! convergence from the flat plate ([`super::converge`]: every start
//! within the prior's spread inside the basin of its Gauss–Newton
//! iteration) and the stage's fringe detection on at least nine in ten of
//! the sample pixels (the fit takes only the pixels the stage detected
//! fringes on). The A-optimum alone of a 3 mm plate (τ ≈ 90–115 and
//! 225–250) meets the first and fails the second: the periodogram found
//! no fringes on 92 % of the sample pixels, and the fit on the rest missed
//! its prediction fourfold.
//!
//! [`Design::falloff_group`]: crate::solve::spectral::model::Design::falloff_group
//! [`Design::physical_falloff`]: crate::solve::spectral::model::Design::physical_falloff

use crate::acquire::acquisition::FrameInfo;
use crate::acquire::patterns::MAX_FRAMES;
use crate::limits::{check_fits, Bytes};
use crate::optics::station::Station;
use crate::optics::trace::TracedView;

use super::ambiguity;
use super::predict::{traced_view, Prediction};
use super::{invalid, PlanError, PlanOptions, Timing};

mod constrain;
mod problem;

use constrain::design_frames;
use problem::{problem, Problem};

/// What a design is for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Budget {
    /// Exactly this many frames.
    Frames(usize),
    /// At most this many seconds of acquisition.
    Seconds(f64),
    /// The fewest frames whose predicted RMS error of both surfaces is at
    /// most this, nm.
    TargetNm(f64),
}

/// How a design is searched.
#[derive(Debug, Clone)]
pub struct DesignOptions {
    /// The scene and timing.
    pub plan: PlanOptions,
    /// Fringe directions the design may use, degrees; the design weighs
    /// each. Default: ±45°, 0° and 90° (the module's "Directions").
    pub directions_deg: Vec<f64>,
    /// Grid step of the candidate τ values.
    pub tau_step: f64,
    /// Largest candidate τ; `None`: 2 τ_max.
    pub tau_hi: Option<f64>,
    /// Sample pixels the criterion sums over.
    pub pixels: usize,
    /// Multiplicative iterations.
    pub iterations: usize,
}

impl Default for DesignOptions {
    fn default() -> Self {
        DesignOptions {
            plan: PlanOptions::default(),
            directions_deg: vec![45.0, -45.0, 0.0, 90.0],
            tau_step: 0.5,
            tau_hi: None,
            pixels: 48,
            iterations: 400,
        }
    }
}

/// A designed schedule.
#[derive(Debug, Clone)]
pub struct Designed {
    /// The frames, display order (per direction, τ ascending, repeats
    /// together).
    pub frames: Vec<FrameInfo>,
    /// Its prediction.
    pub prediction: Prediction,
    /// Share α of the start component (uniform over τ ≤
    /// [`Self::start_tau_max`]) mixed in for the constraints.
    pub uniform_share: f64,
    /// Largest τ of the start component.
    pub start_tau_max: f64,
    /// The rounded design's criterion over the Fisher-information limit
    /// (the equivalence-theorem lower bound of the best continuous design
    /// of these candidates at the same frames): ≤ 1, 1 is the limit.
    pub efficiency: f64,
    /// The criterion Φ of the design and the limit, px² (summed variances
    /// of the sample pixels' screen points).
    pub criterion_px2: [f64; 2],
}

/// The schedule for `budget` on `station`.
///
/// # Errors
/// [`PlanError`] for a budget too small to design (fewer than 8 frames per
/// direction), a target no affordable schedule reaches, or a failed
/// prediction.
pub fn design(
    station: &Station,
    budget: Budget,
    opts: &DesignOptions,
) -> Result<Designed, PlanError> {
    opts.plan.validate()?;
    budget_frames(budget, &opts.plan.timing)?;
    if opts.directions_deg.len() < 2 {
        return Err(invalid(
            "--directions",
            "two non-parallel directions are needed",
        ));
    }
    let (prob, _) = problem(station, opts)?;
    let opt = prob.optimum(opts.iterations)?;
    let flat = traced_view(station, opts.plan.back_scale)?;
    let bent = ambiguity::expected_view(station, &opts.plan)?;
    let spread_px = ambiguity::spread_between(&flat, &bent, &opts.plan);
    let search = Search {
        station,
        opts,
        prob: &prob,
        opt: &opt,
        views: &Views {
            flat,
            bent,
            spread_px,
        },
        min_frames: 8 * opts.directions_deg.len(),
    };
    match budget {
        Budget::Frames(n) => {
            if n < search.min_frames {
                return Err(invalid(
                    "--frames",
                    format!("expected at least {} frames, found {n}", search.min_frames),
                ));
            }
            search.frames(n)
        }
        Budget::Seconds(t) => search.within_seconds(t),
        Budget::TargetNm(x) => search.reaching(x),
    }
}

/// Memory a design holds per frame of its schedule, bytes: the schedule,
/// its rounded weights and the spectral stage's series of the sample
/// pixels. Measured: `mfd plan` of 10 000 and 100 000 frames on the
/// public-small station peaked at 23.8 and 54.0 MB, 343 B per frame; three
/// times that, as a design holds a schedule and its candidate at once.
pub const BYTES_PER_FRAME: u64 = 1024;

/// The frames `budget` asks for, refused before anything is designed when
/// above [`MAX_FRAMES`] (a budget of seconds counts its frames at the
/// camera's frame time, the fewest seconds any frame takes) or above what
/// the machine can hold at [`BYTES_PER_FRAME`]. `None` for a target error
/// (its frames are found by the search, which stops at [`MAX_FRAMES`]).
///
/// # Errors
/// [`PlanError::Invalid`] naming `--frames` or `--time-s`, the limit and
/// the memory the design would need.
pub fn budget_frames(budget: Budget, timing: &Timing) -> Result<Option<usize>, PlanError> {
    let (option, frames, asked) = match budget {
        Budget::Frames(n) => ("--frames", n as f64, format!("{n} frames")),
        Budget::Seconds(t) => (
            "--time-s",
            t / timing.frame_s(),
            format!(
                "{t} s, at least {:.0} frames at {:.4} s per frame,",
                t / timing.frame_s(),
                timing.frame_s()
            ),
        ),
        Budget::TargetNm(_) => return Ok(None),
    };
    let need = Bytes((frames * BYTES_PER_FRAME as f64).min(u64::MAX as f64) as u64);
    if frames.is_nan() || frames > MAX_FRAMES as f64 {
        let most = match budget {
            Budget::Seconds(_) => {
                format!(" (at most {:.0} s)", MAX_FRAMES as f64 * timing.frame_s())
            }
            _ => String::new(),
        };
        return Err(invalid(
            option,
            format!(
                "{asked} is above the {MAX_FRAMES} frames a schedule may have{most}; its design \
                 would need {need} of memory"
            ),
        ));
    }
    let n = frames as usize;
    check_fits(&asked, n as u64, BYTES_PER_FRAME).map_err(|e| invalid(option, e.to_string()))?;
    Ok(Some(n))
}

/// The traced plates the constraints are checked on, traced once per design.
struct Views {
    /// The flat plate with the back scaled (the prediction).
    flat: TracedView,
    /// The expected plate ([`ambiguity::expected_view`]): the truth the
    /// stage is run on.
    bent: TracedView,
    /// How far the true points may lie from the flat plate's, px
    /// ([`ambiguity::spread_between`]): the start the surface-domain fit
    /// must converge from.
    spread_px: f64,
}

/// What every design of one [`design`] call shares: the candidates, their
/// optimum and the traced plates.
struct Search<'a> {
    station: &'a Station,
    opts: &'a DesignOptions,
    prob: &'a Problem,
    opt: &'a (Vec<f64>, f64),
    views: &'a Views,
    /// The fewest frames designed: 8 per direction.
    min_frames: usize,
}

impl Search<'_> {
    /// The constrained design of exactly `n` frames.
    fn frames(&self, n: usize) -> Result<Designed, PlanError> {
        design_frames(self.station, n, self.opts, self.prob, self.opt, self.views)
    }

    /// The design of at most `t` seconds of acquisition.
    fn within_seconds(&self, t: f64) -> Result<Designed, PlanError> {
        let opts = self.opts;
        let t_min = opts
            .plan
            .timing
            .seconds(&vec![self.prob.candidates[0]; self.min_frames]);
        if !(t.is_finite() && t > t_min) {
            return Err(invalid(
                "--time-s",
                format!("expected more than {t_min:.2} s, found {t}"),
            ));
        }
        let mut n = ((t / opts.plan.timing.frame_s()) as usize).max(self.min_frames);
        for _ in 0..8 {
            let d = self.frames(n)?;
            if d.prediction.seconds <= t {
                return Ok(d);
            }
            n = ((n as f64 * t / d.prediction.seconds * 0.99) as usize).max(self.min_frames);
        }
        Err(invalid(
            "--time-s",
            format!("no schedule found within {t} s"),
        ))
    }

    /// The fewest frames whose predicted RMS error of both surfaces is at
    /// most `x` nm.
    fn reaching(&self, x: f64) -> Result<Designed, PlanError> {
        if !(x.is_finite() && x > 0.0) {
            return Err(invalid(
                "--target-nm",
                format!("expected a target > 0 nm, found {x}"),
            ));
        }
        let worst = |d: &Designed| {
            d.prediction
                .back
                .as_ref()
                .map_or(d.prediction.front.rms_nm, |b| {
                    b.rms_nm.max(d.prediction.front.rms_nm)
                })
        };
        let mut n = 1000;
        for _ in 0..8 {
            let d = self.frames(n)?;
            let r = worst(&d);
            if r <= x && d.prediction.back.is_some() == (self.opts.plan.back_scale > 0.0) {
                // Shrink while the 1/√N law says a smaller one would do.
                let smaller = ((n as f64) * (r / x).powi(2)).ceil() as usize;
                if smaller + n / 50 >= n || smaller < self.min_frames {
                    return Ok(d);
                }
                let d2 = self.frames(smaller)?;
                return Ok(if worst(&d2) <= x { d2 } else { d });
            }
            // The 1/√N law's frames for x nm; refused at once when they
            // lie beyond the largest schedule by more than the law's own
            // error over such a step (the design's shape changes with N:
            // the 5 % the search grows by, doubled), else tried up to it.
            let law = (n as f64) * (r / x).powi(2);
            if law > 1.1 * MAX_FRAMES as f64 || (n == MAX_FRAMES && r > x) {
                return Err(invalid(
                    "--target-nm",
                    format!(
                        "{x} nm: {r:.3e} nm at {n} frames, so about {law:.3e} frames by the \
                         1/√N law, above the {MAX_FRAMES} frames a schedule may have"
                    ),
                ));
            }
            let grow = (law * 1.05).ceil() as usize;
            n = grow.max(n + n / 10).min(MAX_FRAMES);
        }
        Err(invalid(
            "--target-nm",
            format!("no schedule up to {MAX_FRAMES} frames reaches {x} nm"),
        ))
    }
}

#[cfg(test)]
#[path = "design_tests.rs"]
mod tests;

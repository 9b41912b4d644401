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

use crate::acquire::acquisition::FrameInfo;
use crate::budget::scene;
use crate::optics::station::Station;
use crate::solve::spectral::model::{normal_equations, Design};

use super::ambiguity;
use super::converge;
use super::predict::{
    bound_kind, predict, run_stage, sample_pixels, separation, traced_view, BoundKind, Prediction,
};
use super::{invalid, PlanError, PlanOptions};
use crate::optics::trace::TracedView;

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

/// The per-pixel gradients of every candidate at the sample pixels.
struct Problem {
    /// Candidate frames (direction-major, τ ascending).
    candidates: Vec<FrameInfo>,
    /// Per sample pixel: the parameter count and the indices of u, v.
    pixels: Vec<(usize, Vec<usize>)>,
    /// Per sample pixel, per candidate, the gradient (length of the pixel's
    /// parameters), scaled by 1/σ.
    grads: Vec<Vec<Vec<f64>>>,
}

fn candidates(opts: &DesignOptions) -> Result<Vec<FrameInfo>, PlanError> {
    let tau_max = opts.plan.radiometry.tau_max;
    let hi = opts.tau_hi.unwrap_or(2.0 * tau_max);
    if !(opts.tau_step.is_finite() && opts.tau_step > 0.0 && hi > 2.0 * opts.tau_step) {
        return Err(invalid(
            "--tau-step",
            format!(
                "expected a step > 0 well below the largest τ {hi}, found {}",
                opts.tau_step
            ),
        ));
    }
    let n = (hi / opts.tau_step).floor() as usize;
    let mut out = Vec::new();
    for &d in &opts.directions_deg {
        for k in 1..=n {
            out.push(FrameInfo {
                index: out.len(),
                direction_deg: d,
                tau: k as f64 * opts.tau_step,
                phase_rad: 0.0,
            });
        }
    }
    Ok(out)
}

fn problem(station: &Station, opts: &DesignOptions) -> Result<(Problem, Design), PlanError> {
    let candidates = candidates(opts)?;
    let design = scene::design(station, &candidates)?;
    let view = traced_view(station, opts.plan.back_scale)?;
    let r = &opts.plan.radiometry;
    let gain = r.gain(&view);
    let sigma = r.sigma_counts();
    let mut pixels = Vec::new();
    let mut grads = Vec::new();
    for q in sample_pixels(&view, opts.pixels, false) {
        // The truth with the physical falloff (a blur on the screen
        // period, [`Design::physical_falloff`]); the fit's κ per falloff
        // group is among the parameters, as in reconstruction.
        let p = super::stage::truth_params(&design, &view.pixels[q], gain, r);
        let k = p.k;
        // The model's gradient row has ∂/∂A = 1 first, so a one-frame JᵀJ's
        // first column is the row itself.
        let g: Vec<Vec<f64>> = (0..candidates.len() as u32)
            .map(|c| {
                let m = normal_equations(&design, &[c], &[0.0], &p).jtj;
                (0..p.len()).map(|a| m[(a, 0)] / sigma).collect()
            })
            .collect();
        let uv: Vec<usize> = (0..k)
            .flat_map(|j| [p.u_index(j), p.u_index(j) + 1])
            .collect();
        pixels.push((p.len(), uv));
        grads.push(g);
    }
    Ok((
        Problem {
            candidates,
            pixels,
            grads,
        },
        design,
    ))
}

impl Problem {
    /// Φ(w) and d_c for one frame in total (`Σ w = 1`); `None` when some
    /// pixel's information is singular.
    fn criterion(&self, w: &[f64]) -> Option<(f64, Vec<f64>)> {
        let mut phi = 0.0;
        let mut d = vec![0.0; w.len()];
        for ((n, uv), g) in self.pixels.iter().zip(&self.grads) {
            let mut f = nalgebra::DMatrix::<f64>::zeros(*n, *n);
            for (gc, &wc) in g.iter().zip(w) {
                if wc > 0.0 {
                    let v = nalgebra::DVector::from_column_slice(gc);
                    f += wc * &v * v.transpose();
                }
            }
            let inv = f.cholesky()?.inverse();
            phi += uv.iter().map(|&a| inv[(a, a)]).sum::<f64>();
            // d_c = Σ_a (F⁻¹ J_c)_a² over the picked a.
            let rows: Vec<nalgebra::DVector<f64>> =
                uv.iter().map(|&a| inv.row(a).transpose()).collect();
            for (gc, dc) in g.iter().zip(d.iter_mut()) {
                for r in &rows {
                    let z: f64 = r.iter().zip(gc).map(|(x, y)| x * y).sum();
                    *dc += z * z;
                }
            }
        }
        Some((phi, d))
    }

    /// The continuous A-optimal weights and the equivalence bound of their Φ.
    fn optimum(&self, iterations: usize) -> Result<(Vec<f64>, f64), PlanError> {
        let n = self.candidates.len();
        let mut w = vec![1.0 / n as f64; n];
        let singular = || {
            invalid("the design", "the information of the candidate frames is singular at a sample pixel: check the station and the τ grid")
        };
        let mut lower = 0.0;
        for it in 0..iterations {
            let (phi, d) = self.criterion(&w).ok_or_else(singular)?;
            let dmax = d.iter().copied().fold(0.0, f64::max);
            lower = (2.0 * phi - dmax).max(lower);
            if dmax <= 1.001 * phi {
                log::debug!("design: converged after {it} iterations");
                break;
            }
            let mut sum = 0.0;
            for (wc, dc) in w.iter_mut().zip(&d) {
                *wc *= (dc / phi).sqrt();
                sum += *wc;
            }
            w.iter_mut().for_each(|x| *x /= sum);
        }
        Ok((w, lower))
    }
}

/// Frames for weights `w` over the candidates: cumulative (systematic)
/// rounding, `n_c = ⌊N W_c + ½⌋ − ⌊N W_{c−1} + ½⌋` with `W` the running
/// sum, which keeps every stretch of τ at its share of the frames even
/// where single weights are below 1/N; repeats of a candidate follow one
/// another.
fn round(candidates: &[FrameInfo], w: &[f64], n: usize) -> Vec<FrameInfo> {
    let total: f64 = w.iter().sum();
    let mut cum = 0.0;
    let mut prev = 0usize;
    let mut out = Vec::with_capacity(n);
    for (c, &wc) in candidates.iter().zip(w) {
        cum += wc / total;
        let upto = ((n as f64 * cum + 0.5).floor() as usize).min(n);
        for _ in prev..upto {
            out.push(FrameInfo {
                index: out.len(),
                ..*c
            });
        }
        prev = upto.max(prev);
    }
    out
}

/// The weights of a rounded schedule over the candidates (Σ = 1).
fn weights_of(candidates: &[FrameInfo], frames: &[FrameInfo]) -> Vec<f64> {
    let mut w = vec![0.0; candidates.len()];
    for f in frames {
        if let Some(c) = candidates
            .iter()
            .position(|c| c.direction_deg == f.direction_deg && c.tau == f.tau)
        {
            w[c] += 1.0 / frames.len() as f64;
        }
    }
    w
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

/// Largest τ of the start component tried, in units of τ_max (the whole
/// grid, 2 τ_max, last).
const START_LADDERS: [f64; 4] = [0.5, 0.75, 1.0, 2.0];

/// The start component's share is searched on a grid of 1/`GRID`, then
/// by `BISECTIONS` halvings below the first admissible one: to 1/32.
const GRID: usize = 8;
const BISECTIONS: usize = 2;

/// Whether a rounded schedule meets the constraints: the spectral stage,
/// run on sample pixels at the planned noise, finds the true points
/// ([`super::stage`]; this is the start's ambiguity as the stage meets it,
/// within the range it searches), and the reflections are separable by
/// the stage's 5σ rule; where the bound is the surface-domain fit's, that
/// the fit converges from the flat plate ([`super::converge`]).
fn admissible(
    station: &Station,
    frames: &[FrameInfo],
    opts: &DesignOptions,
    views: &Views,
) -> Result<bool, PlanError> {
    if opts
        .directions_deg
        .iter()
        .any(|&d| frames.iter().filter(|f| f.direction_deg == d).count() < 2)
    {
        return Ok(false);
    }
    let design = scene::design(station, frames)?;
    let stage = run_stage(
        station,
        &design,
        &views.flat,
        &views.bent,
        super::predict::STAGE_PIXELS,
        &opts.plan,
    )?;
    if bound_kind(&design, &views.flat, &opts.plan).0 == BoundKind::SurfaceDomain {
        // `auto` will fit the surfaces to the frames: what must hold is
        // that fit's convergence from the flat plate, on the pixels it
        // takes (those the stage detected fringes on); per-pixel
        // separability is not needed.
        let both = sample_pixels(&views.flat, super::predict::CONVERGENCE_PIXELS, true);
        let c = converge::convergence(
            station,
            frames,
            &converge::Scene {
                design: &design,
                flat: &views.flat,
                bent: &views.bent,
                pixels: &both,
                gain: opts.plan.radiometry.gain(&views.flat),
                radiometry: &opts.plan.radiometry,
            },
            views.spread_px,
        );
        let why = super::predict::surface_domain_unmeasurable(&c, &stage);
        log::debug!(
            "design candidate of {} frames: surface-domain basin {:?} px against the prior's {:.1} px, pixels {:.2}, no signal on {:.2}: {why:?}",
            frames.len(),
            c.directions.iter().map(|d| d.basin_px).collect::<Vec<_>>(),
            views.spread_px,
            c.pixel_fraction,
            stage.no_signal_fraction,
        );
        return Ok(why.is_none());
    }
    let gain = opts.plan.radiometry.gain(&views.flat);
    let both = sample_pixels(&views.flat, 64, true);
    let sep = stage
        .measurable
        .then(|| separation(&design, &views.flat, &both, gain, &opts.plan));
    log::debug!(
        "design candidate of {} frames: stage ({}) found {:.2}, no signal {:.2}; separable {:?}",
        frames.len(),
        stage.engine,
        stage.found_fraction,
        stage.no_signal_fraction,
        sep.as_ref().map(|s| s.separable_fraction)
    );
    Ok(sep.is_some_and(|s| s.separable))
}

/// The constrained design of exactly `n` frames.
fn design_frames(
    station: &Station,
    n: usize,
    opts: &DesignOptions,
    prob: &Problem,
    opt: &(Vec<f64>, f64),
    views: &Views,
) -> Result<Designed, PlanError> {
    let (w_star, lower) = opt;
    let tau_max = opts.plan.radiometry.tau_max;
    let top = prob.candidates.iter().map(|c| c.tau).fold(0.0, f64::max);
    // The start component: uniform over the candidates up to τ_u. Over the
    // whole grid (up to 2 τ_max) a third of it sits where a frame carries
    // less than e⁻⁸·⁸ of the information at τ_max/√2; the stage's start
    // needs the low and middle τ (the periodogram's main lobe and a ladder
    // the fit cannot skip a fringe on), so shorter ladders are tried too.
    let mut best: Option<(f64, f64, f64, Vec<FrameInfo>)> = None;
    for frac in START_LADDERS {
        let tau_u = (frac * tau_max).min(top);
        let inside = prob.candidates.iter().filter(|c| c.tau <= tau_u).count();
        if inside < 8 * opts.directions_deg.len() {
            continue;
        }
        let mix = |alpha: f64| -> Vec<f64> {
            w_star
                .iter()
                .zip(&prob.candidates)
                .map(|(&w, c)| {
                    let u = if c.tau <= tau_u {
                        1.0 / inside as f64
                    } else {
                        0.0
                    };
                    (1.0 - alpha) * w + alpha * u
                })
                .collect()
        };
        let at = |alpha: f64| {
            log::debug!("design of {n} frames: trying share {alpha} of uniform τ ≤ {tau_u}");
            round(&prob.candidates, &mix(alpha), n)
        };
        // The smallest admissible share on a grid of 1/8 (admissibility
        // need not be monotone in α: a short ladder alone separates
        // nothing, mixed with w* it may), then bisection below it.
        let mut first = None;
        for k in 0..=GRID {
            let alpha = k as f64 / GRID as f64;
            if admissible(station, &at(alpha), opts, views)? {
                first = Some(alpha);
                break;
            }
        }
        let Some(mut hi) = first else {
            continue;
        };
        let mut lo = (hi - 1.0 / GRID as f64).max(0.0);
        if hi > 0.0 {
            for _ in 0..BISECTIONS {
                let mid = 0.5 * (lo + hi);
                if admissible(station, &at(mid), opts, views)? {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
        }
        let frames = at(hi);
        let Some((phi, _)) = prob.criterion(&weights_of(&prob.candidates, &frames)) else {
            continue;
        };
        log::debug!("design of {n} frames: τ_u {tau_u}: share {hi}, criterion {phi}");
        if best.as_ref().is_none_or(|b| phi < b.0) {
            best = Some((phi, hi, tau_u, frames));
        }
    }
    let (phi, hi, tau_u, frames) = match best {
        Some(b) => b,
        None => {
            // Nothing the stage measures: the uniform design of the whole
            // grid, predicted (and flagged) as it is.
            let m = prob.candidates.len();
            let frames = round(&prob.candidates, &vec![1.0 / m as f64; m], n);
            let (phi, _) = prob
                .criterion(&weights_of(&prob.candidates, &frames))
                .ok_or_else(|| {
                    invalid(
                        "the design",
                        format!("{n} frames leave a sample pixel's information singular: give more frames"),
                    )
                })?;
            log::warn!("design of {n} frames: no schedule tried is measured by the spectral stage and separable at this budget");
            (phi, 1.0, top, frames)
        }
    };
    let prediction = predict(station, &frames, &opts.plan)?;
    Ok(Designed {
        frames,
        prediction,
        uniform_share: hi,
        start_tau_max: tau_u,
        efficiency: (lower / phi).min(1.0),
        criterion_px2: [phi / n as f64, lower / n as f64],
    })
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
    let views = Views {
        flat,
        bent,
        spread_px,
    };
    let min_frames = 8 * opts.directions_deg.len();
    let worst = |d: &Designed| {
        d.prediction
            .back
            .as_ref()
            .map_or(d.prediction.front.rms_nm, |b| {
                b.rms_nm.max(d.prediction.front.rms_nm)
            })
    };
    match budget {
        Budget::Frames(n) => {
            if n < min_frames {
                return Err(invalid(
                    "--frames",
                    format!("expected at least {min_frames} frames, found {n}"),
                ));
            }
            design_frames(station, n, opts, &prob, &opt, &views)
        }
        Budget::Seconds(t) => {
            let t_min = opts
                .plan
                .timing
                .seconds(&vec![prob.candidates[0]; min_frames]);
            if !(t.is_finite() && t > t_min) {
                return Err(invalid(
                    "--time-s",
                    format!("expected more than {t_min:.2} s, found {t}"),
                ));
            }
            let mut n = ((t / opts.plan.timing.frame_s()) as usize).max(min_frames);
            for _ in 0..8 {
                let d = design_frames(station, n, opts, &prob, &opt, &views)?;
                if d.prediction.seconds <= t {
                    return Ok(d);
                }
                n = ((n as f64 * t / d.prediction.seconds * 0.99) as usize).max(min_frames);
            }
            Err(invalid(
                "--time-s",
                format!("no schedule found within {t} s"),
            ))
        }
        Budget::TargetNm(x) => {
            if !(x.is_finite() && x > 0.0) {
                return Err(invalid(
                    "--target-nm",
                    format!("expected a target > 0 nm, found {x}"),
                ));
            }
            let mut n = 1000;
            for _ in 0..8 {
                let d = design_frames(station, n, opts, &prob, &opt, &views)?;
                let r = worst(&d);
                if r <= x && d.prediction.back.is_some() == (opts.plan.back_scale > 0.0) {
                    // Shrink while the 1/√N law says a smaller one would do.
                    let smaller = ((n as f64) * (r / x).powi(2)).ceil() as usize;
                    if smaller + n / 50 >= n || smaller < min_frames {
                        return Ok(d);
                    }
                    let d2 = design_frames(station, smaller, opts, &prob, &opt, &views)?;
                    return Ok(if worst(&d2) <= x { d2 } else { d });
                }
                let grow = ((n as f64) * (r / x).powi(2) * 1.05).ceil() as usize;
                n = grow.max(n + n / 10).min(200_000);
            }
            Err(invalid(
                "--target-nm",
                format!("no schedule up to 200000 frames reaches {x} nm"),
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cumulative_rounding_keeps_the_count_and_the_shares() {
        let c: Vec<FrameInfo> = (0..10)
            .map(|k| FrameInfo {
                index: k,
                direction_deg: 45.0,
                tau: 1.0 + k as f64,
                phase_rad: 0.0,
            })
            .collect();
        let mut w = vec![0.01; 10];
        w[3] = 0.91;
        let f = round(&c, &w, 100);
        assert_eq!(f.len(), 100);
        // Share 0.91 of 100 frames: 91 repeats, within one of rounding.
        let at3 = f.iter().filter(|x| x.tau == 4.0).count();
        assert!((90..=92).contains(&at3), "{at3}");
        // Repeats of one pattern follow one another.
        assert_eq!(super::super::timing::switches(&f), 10);
    }
}

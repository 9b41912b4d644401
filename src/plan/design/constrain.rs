//! The constraints a design must meet (the spectral stage measures it and
//! separates the reflections, or the surface-domain fit converges) and the
//! search for the smallest share of the start component that meets them.

use crate::acquire::acquisition::FrameInfo;
use crate::budget::scene;
use crate::optics::station::Station;
use crate::solve::spectral::model::Design;

use super::super::converge;
use super::super::predict::{bound_kind, predict, run_stage, sample_pixels, separation, BoundKind};
use super::super::stage::StageCheck;
use super::super::{invalid, PlanError};
use super::problem::{round, weights_of, Problem};
use super::{DesignOptions, Designed, Views};

/// Largest τ of the start component tried, in units of τ_max (the whole
/// grid, 2 τ_max, last).
const START_LADDERS: [f64; 4] = [0.5, 0.75, 1.0, 2.0];

/// The start component's share is searched on a grid of 1/`GRID`, then
/// by `BISECTIONS` halvings below the first admissible one: to 1/32.
const GRID: usize = 8;
const BISECTIONS: usize = 2;

/// Whether a rounded schedule meets the constraints: the spectral stage,
/// run on sample pixels at the planned noise, finds the true points
/// ([`super::super::stage`]; this is the start's ambiguity as the stage meets it,
/// within the range it searches), and the reflections are separable by
/// the stage's 5σ rule; where the bound is the surface-domain fit's, that
/// the fit converges from the flat plate ([`super::super::converge`]).
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
        super::super::predict::STAGE_PIXELS,
        &opts.plan,
        false,
    )?;
    if bound_kind(&design, &views.flat, &opts.plan).0 == BoundKind::SurfaceDomain {
        return Ok(surface_domain_admissible(
            station, frames, opts, views, &design, &stage,
        ));
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

/// Whether the surface-domain fit measures a rounded schedule of `design`:
/// it converges from the flat plate, and the stage's run `stage` detected
/// fringes on enough of its sample pixels.
fn surface_domain_admissible(
    station: &Station,
    frames: &[FrameInfo],
    opts: &DesignOptions,
    views: &Views,
    design: &Design,
    stage: &StageCheck,
) -> bool {
    // `auto` will fit the surfaces to the frames: what must hold is
    // that fit's convergence from the flat plate, on the pixels it
    // takes (those the stage detected fringes on); per-pixel
    // separability is not needed.
    let both = sample_pixels(&views.flat, super::super::predict::CONVERGENCE_PIXELS, true);
    let c = converge::convergence(
        station,
        frames,
        &converge::Scene {
            design,
            flat: &views.flat,
            bent: &views.bent,
            pixels: &both,
            gain: opts.plan.radiometry.gain(&views.flat),
            radiometry: &opts.plan.radiometry,
        },
        views.spread_px,
    );
    let why = super::super::predict::surface_domain_unmeasurable(&c, stage);
    log::debug!(
        "design candidate of {} frames: surface-domain basin {:?} px against the prior's {:.1} px, pixels {:.2}, no signal on {:.2}: {why:?}",
        frames.len(),
        c.directions.iter().map(|d| d.basin_px).collect::<Vec<_>>(),
        views.spread_px,
        c.pixel_fraction,
        stage.no_signal_fraction,
    );
    why.is_none()
}

/// One constrained design of the search: its criterion Φ, the start
/// component's share α and largest τ, and the rounded frames.
type Constrained = (f64, f64, f64, Vec<FrameInfo>);

/// The constrained design of exactly `n` frames.
pub(super) fn design_frames(
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
    let mut best: Option<Constrained> = None;
    let mut seen = Seen::default();
    for frac in START_LADDERS {
        let tau_u = (frac * tau_max).min(top);
        let Some(c) = with_start(station, n, opts, prob, w_star, tau_u, views, &mut seen)? else {
            continue;
        };
        if best.as_ref().is_none_or(|b| c.0 < b.0) {
            best = Some(c);
        }
    }
    let (phi, hi, tau_u, frames) = match best {
        Some(b) => b,
        None => uniform_fallback(prob, n, top)?,
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

/// Schedules already judged in one [`design_frames`] call, with the
/// verdict: every ladder's share 0 is the same rounded A-optimum, and a
/// share may round to a schedule another share or ladder gave. The
/// judgement is a function of the frames alone (its noise seed included),
/// so it is looked up, not run again.
#[derive(Default)]
struct Seen(Vec<(Vec<FrameInfo>, bool)>);

impl Seen {
    fn admissible(
        &mut self,
        station: &Station,
        frames: Vec<FrameInfo>,
        opts: &DesignOptions,
        views: &Views,
    ) -> Result<bool, PlanError> {
        if let Some((_, ok)) = self.0.iter().find(|(f, _)| *f == frames) {
            return Ok(*ok);
        }
        let ok = admissible(station, &frames, opts, views)?;
        self.0.push((frames, ok));
        Ok(ok)
    }
}

/// The A-optimum `w_star` mixed with the start component uniform over the
/// candidates up to `tau_u`, at the smallest share that makes the rounded
/// schedule of `n` frames admissible; `None` where the ladder is too short
/// (fewer than 8 candidates per direction), no share is admissible, or the
/// frames leave a sample pixel's information singular.
#[allow(clippy::too_many_arguments)]
fn with_start(
    station: &Station,
    n: usize,
    opts: &DesignOptions,
    prob: &Problem,
    w_star: &[f64],
    tau_u: f64,
    views: &Views,
    seen: &mut Seen,
) -> Result<Option<Constrained>, PlanError> {
    let inside = prob.candidates.iter().filter(|c| c.tau <= tau_u).count();
    if inside < 8 * opts.directions_deg.len() {
        return Ok(None);
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
    let Some(hi) = smallest_share(|alpha| seen.admissible(station, at(alpha), opts, views))? else {
        return Ok(None);
    };
    let frames = at(hi);
    let Some((phi, _)) = prob.criterion(&weights_of(&prob.candidates, &frames)) else {
        return Ok(None);
    };
    log::debug!("design of {n} frames: τ_u {tau_u}: share {hi}, criterion {phi}");
    Ok(Some((phi, hi, tau_u, frames)))
}

/// The smallest share α that `admits`: the first on a grid of 1/[`GRID`]
/// (admissibility need not be monotone in α: a short ladder alone
/// separates nothing, mixed with w* it may), then [`BISECTIONS`] halvings
/// below it; `None` where no share of the grid is admitted.
fn smallest_share(
    mut admits: impl FnMut(f64) -> Result<bool, PlanError>,
) -> Result<Option<f64>, PlanError> {
    let mut first = None;
    for k in 0..=GRID {
        let alpha = k as f64 / GRID as f64;
        if admits(alpha)? {
            first = Some(alpha);
            break;
        }
    }
    let Some(mut hi) = first else {
        return Ok(None);
    };
    let mut lo = (hi - 1.0 / GRID as f64).max(0.0);
    if hi > 0.0 {
        for _ in 0..BISECTIONS {
            let mid = 0.5 * (lo + hi);
            if admits(mid)? {
                hi = mid;
            } else {
                lo = mid;
            }
        }
    }
    Ok(Some(hi))
}

/// Where no schedule tried is admissible: nothing the stage measures, so
/// the uniform design of the whole grid (up to `top`), predicted (and
/// flagged) as it is.
fn uniform_fallback(prob: &Problem, n: usize, top: f64) -> Result<Constrained, PlanError> {
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
    Ok((phi, 1.0, top, frames))
}

//! Why a schedule will not measure, in an operator's words: the spectral
//! stage missing the true points, the surface-domain fit not converging,
//! the reflections not separable, a bound no smaller than the surface.

use super::super::converge::{self, Convergence};
use super::super::stage::{self, StageCheck};

use super::super::PlanOptions;
use super::{BoundKind, Separation, SurfacePrediction, SEPARABLE_FRACTION};

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

/// Why the per-pixel route will not measure a schedule: the stage did not
/// find the true points on enough of its sample pixels; `None` when it will.
pub(super) fn stage_unmeasurable(stage: &StageCheck) -> Option<String> {
    (!stage.measurable).then(|| {
        format!(
            "the spectral stage ({} engine), run on {} sample pixels at this noise, found the true points on {:.0} % of them (needs {:.0} %; no signal detected on {:.0} %): give more frames or spread τ wider",
            stage.engine,
            stage.pixels,
            100.0 * stage.found_fraction,
            100.0 * stage::STAGE_FRACTION,
            100.0 * stage.no_signal_fraction
        )
    })
}

/// Why the back is not measured: AR-coated, or (per-pixel bound) the
/// reflections not separable on enough pixels; `None` when it is.
pub(super) fn back_not_measured(
    opts: &PlanOptions,
    bound: BoundKind,
    separation: &Separation,
) -> Option<String> {
    if opts.back_scale == 0.0 {
        Some("the back is AR-coated: one reflection".to_string())
    } else if bound == BoundKind::PerPixel && !separation.separable {
        Some(format!(
            "this schedule separates the two reflections on {:.0} % of the pixels (needs {:.0} %): add frames at larger τ or spread τ wider",
            100.0 * separation.separable_fraction,
            100.0 * SEPARABLE_FRACTION
        ))
    } else {
        None
    }
}

/// Why the reconstruction would be withheld: the predicted front error at
/// least the expected departure of the surface (`--surface-nm`); `None`
/// when it is below.
pub(super) fn front_withheld(front: &SurfacePrediction, opts: &PlanOptions) -> Option<String> {
    (front.rms_nm >= opts.surface_nm).then(|| {
        format!(
            "the predicted front error, {:.0} nm RMS, is at least the expected departure of the surface ({:.0} nm RMS, --surface-nm): the reconstruction would be withheld; give more frames or spread τ wider",
            front.rms_nm, opts.surface_nm
        )
    })
}

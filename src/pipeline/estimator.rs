//! Which estimator makes the surfaces from the frames, and what the result
//! withholds: the per-pixel route (screen points per pixel, then the
//! surfaces fitted to them) or the surface-domain fit to the frames
//! themselves ([`crate::solve::direct`]), started from the per-pixel
//! surfaces where those exist.

use serde::{Deserialize, Serialize};

use crate::optics::station::Station;
use crate::report::summary::Summary;
use crate::solve::direct::{self, DirectOptions, DirectReport};
use crate::solve::spectral::{SpectralMaps, SpectralSolver};
use crate::solve::surfaces::{
    reconstruct as solve_surfaces, Observations, SurfaceError, SurfaceOptions, SurfaceSolution,
    Uncertainty,
};

/// Which estimator makes the surfaces when the frames are at hand.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Estimator {
    /// The surface-domain fit where the reflections are closer than
    /// [`direct::DIRECT_BELOW_BINS`] (median over the pixels) or the per-pixel route
    /// measures nothing, started from the per-pixel surfaces where those
    /// exist; the per-pixel route elsewhere, and where the schedule is one
    /// the surface-domain fit does not model (phase shifting).
    #[default]
    Auto,
    /// Screen points per pixel, then the surfaces fitted to them.
    PerPixel,
    /// The surface-domain fit; an error where it cannot run.
    Direct,
}

/// The surfaces from the spectral stage's `solver` and `maps` with the
/// chosen estimator: the observations the solution was fitted to (screen
/// points, or the surface-domain fit's pseudo-observations), the solution,
/// and the surface-domain fit's account when it ran.
///
/// # Errors
/// The per-pixel route's [`SurfaceError`] where it is the estimator (or
/// the fallback) and fails; the surface-domain fit's where it is asked for.
pub fn surfaces_from_frames(
    solver: &SpectralSolver,
    maps: &SpectralMaps,
    station: &Station,
    opts: &SurfaceOptions,
    estimator: Estimator,
) -> Result<(Observations, SurfaceSolution, Option<DirectReport>), SurfaceError> {
    let cov = maps.screen_cov();
    let obs = Observations::from_maps(station, &maps.screen_coords(), Uncertainty::Cov(&cov))?;
    let per_pixel = solve_surfaces(&obs, station, opts);
    let close = direct::surface_domain_preferred(direct::median_separation_bins(solver));
    let wanted = match estimator {
        Estimator::PerPixel => false,
        Estimator::Direct => true,
        Estimator::Auto => close || per_pixel.is_err(),
    };
    if !wanted {
        return per_pixel.map(|s| (obs, s, None));
    }
    let fit = direct::solve(
        solver,
        maps,
        station,
        per_pixel.as_ref().ok(),
        opts,
        &DirectOptions::default(),
    );
    match fit {
        Ok(d) => {
            let report = DirectReport {
                iterations: d.iterations,
                converged: d.converged,
                two_reflection_pixels: d.two_reflection_pixels,
                clipped: d.clipped,
                third_reflection: d.third_reflection,
                starts: d.starts,
                seconds: d.seconds,
                width: station.camera.width as usize,
                predicted: d.predicted,
                chi2_map: d.chi2_map,
                per_pixel_failed: per_pixel.as_ref().err().map(|e| e.to_string()),
            };
            Ok((d.observations, d.solution, Some(report)))
        }
        Err(e) if estimator == Estimator::Auto && per_pixel.is_ok() => {
            log::warn!("{e}; the per-pixel result is reported");
            per_pixel.map(|s| (obs, s, None))
        }
        Err(direct::DirectError::Surface(e)) => Err(e),
        Err(e @ direct::DirectError::NotApplicable { .. }) => match per_pixel {
            Ok(s) if estimator == Estimator::Auto => Ok((obs, s, None)),
            Ok(_) => Err(SurfaceError::Input {
                what: "--estimator direct",
                problem: e.to_string(),
            }),
            Err(p) => Err(p),
        },
    }
}

/// A surface is withheld (`mfd-surfaces/2`'s `not_reconstructed_because`)
/// when its expected RMS error is at least its own fitted RMS (both piston
/// and tilt removed): the map would then be mostly noise, the surface
/// flatter than the acquisition resolves. Also where it exceeds the
/// caller's limit, and both surfaces where the surface-domain fit did not
/// converge (its last step still moved the coefficients by more than the
/// tolerance in σ: the answer is not the likelihood's maximum). Returns the
/// reason per surface (front, back).
pub fn withheld(
    summary: &Summary,
    direct: Option<&DirectReport>,
    limit_nm: Option<f64>,
) -> [Option<String>; 2] {
    if let Some(d) = direct.filter(|d| !d.converged) {
        let step = d.iterations.last().map_or(f64::NAN, |i| i.max_step_sigma);
        let why = format!(
            "the surface-domain fit did not converge in {} iterations (its last step moved a \
             coefficient by {step:.2} of its σ): the two reflections are too close for this \
             schedule to separate. `mfd plan` on this station predicts whether the fit \
             converges on a schedule before it is measured (on sample pixels, so a schedule it \
             designed can still fall short), and where it does not, names what to add: frames \
             at low τ, or a closer prior",
            d.iterations.len()
        );
        let back = summary.back.is_some().then(|| why.clone());
        return [Some(why), back];
    }
    if let Some(why) = direct.and_then(|d| d.starts.as_ref()?.withheld_because()) {
        let back = summary.back.is_some().then(|| why.clone());
        return [Some(why), back];
    }
    let one = |back: bool| {
        let figures = if back {
            summary.back.as_ref()?
        } else {
            &summary.front
        };
        let (_, expected) = summary.reported(back)?;
        let name = if back { "back" } else { "front" };
        let what = format!(
            "the {name}'s expected error, {expected:.1} nm RMS (piston and tilt removed), is"
        );
        if let Some(limit) = limit_nm.filter(|&l| expected > l) {
            return Some(format!(
                "{what} above the limit of {limit:.1} nm asked for; `mfd plan --target-nm \
                 {limit:.1}` designs a schedule predicted to reach it, or says that none up to \
                 its frame limit does"
            ));
        }
        // With no term beyond tilt (the criterion kept the plane, or
        // `--terms 3`) the fitted RMS is 0 and says nothing: what the face's
        // figure may be is the dropped terms' estimate, `expected` (its
        // `truncation_rms_nm`). Whether "flat within that" is an answer is
        // the caller's to say: with `--max-expected-nm` holding it, the
        // plane is reported (a flat window measured to what was asked);
        // without, it is withheld naming that estimate. (Reported always,
        // the estimate overstates small outlines' error 4–10×: the outline
        // soak's planes, 12.9 nm against 124.7 reported.)
        if figures.terms <= crate::solve::surfaces::report::REMOVED_TERMS {
            if limit_nm.is_some() {
                return None;
            }
            return Some(format!(
                "the criterion kept no term beyond tilt: the {name} shows no figure this \
                 acquisition resolves, and the dropped terms' estimate puts it at up to \
                 {expected:.1} nm RMS (piston and tilt removed); give `--max-expected-nm` at or \
                 above that to have the plane reported, flat within it, or `mfd plan \
                 --target-nm` designs a schedule that resolves less"
            ));
        }
        (expected > 0.0 && expected >= figures.rms_nm).then(|| {
            format!(
                "{what} as large as the fitted surface itself ({:.1} nm RMS): this acquisition \
                 does not resolve it (the two reflections too close for the schedule's τ \
                 range, or too little signal); `mfd plan --target-nm {:.1}` designs a schedule \
                 whose predicted error is below the surface's size, or says that none up to \
                 its frame limit reaches it",
                figures.rms_nm,
                figures.rms_nm / 2.0
            )
        })
    };
    [one(false), one(true)]
}

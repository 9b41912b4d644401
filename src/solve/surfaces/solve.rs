//! The surface pipeline: front by slopes, back by inverse ray tracing, both
//! jointly, term selection, covariance.

use std::time::Instant;

use nalgebra::{DMatrix, DVector};

use super::front::{front_from_slopes, FrontReport};
use super::lm::{levenberg_marquardt, LmOptions, LmReport};
use super::outliers::{outliers, without};
pub use super::outliers::{OUTLIER_CHI2, OUTLIER_RULE};
use super::problem::{Layout, Normal, Observations};
use super::select::{self, choose_terms, TermChoice};
use super::SurfaceError;
use crate::optics::station::Station;
use crate::optics::trace::Plate;
use crate::optics::zernike::{ZernikeBasis, ZernikeSurface};

/// What to solve for and how hard to try.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceOptions {
    /// Fixed number of terms per surface; `None` chooses by BIC up to `max_terms`.
    pub terms: Option<usize>,
    /// Largest model considered when choosing.
    pub max_terms: usize,
    /// Levenberg–Marquardt stopping rules (back and joint stages).
    pub lm: LmOptions,
    /// Iterations of the front's reflection-point correction.
    pub front_iter: usize,
    /// The back's piston (thickness departure) is an unknown.
    pub back_piston: bool,
    /// Refine front and back jointly on S1 and S2.
    pub joint: bool,
    /// The element's rim beyond the aperture, mm.
    pub edge_margin_mm: f64,
    /// Weight by the covariance averaged over a `(2k + 1)²` pixel
    /// neighbourhood (see [`Observations::smoothed_covariance`]); 0: as given.
    pub covariance_smoothing_px: u32,
}

impl Default for SurfaceOptions {
    fn default() -> Self {
        SurfaceOptions {
            terms: None,
            max_terms: 66,
            lm: LmOptions::default(),
            front_iter: 20,
            back_piston: false,
            joint: true,
            edge_margin_mm: crate::optics::trace::DEFAULT_EDGE_MARGIN_MM,
            covariance_smoothing_px: 2,
        }
    }
}

impl SurfaceOptions {
    /// `obs` as the solve weights them: the covariance smoothed over
    /// [`SurfaceOptions::covariance_smoothing_px`] when the σ are known.
    pub fn weighted<'a>(&self, obs: &'a Observations) -> std::borrow::Cow<'a, Observations> {
        if self.covariance_smoothing_px > 0 && obs.sigma_known {
            std::borrow::Cow::Owned(obs.smoothed_covariance(self.covariance_smoothing_px))
        } else {
            std::borrow::Cow::Borrowed(obs)
        }
    }
}

/// One stage's account.
#[derive(Debug, Clone, PartialEq)]
pub struct Stage {
    /// "front slopes", "back", "joint", "joint (chosen terms)".
    pub name: &'static str,
    /// Wall time, s.
    pub seconds: f64,
    /// The slope iteration's report (front stage).
    pub front: Option<FrontReport>,
    /// The LM report (other stages).
    pub lm: Option<LmReport>,
}

/// The reconstructed surfaces with their uncertainty.
#[derive(Debug, Clone)]
pub struct SurfaceSolution {
    /// The element's outline: every figure is taken over it.
    pub outline: crate::optics::outline::Outline,
    /// Front surface (piston 0: the reference plane).
    pub front: ZernikeSurface,
    /// Back surface (departure from `z = −thickness`); flat and not
    /// reconstructed unless `back_fitted`.
    pub back: ZernikeSurface,
    /// Whether the back was reconstructed (some back reflection was measured).
    pub back_fitted: bool,
    /// Pixels `(column, row)` left out as outliers (χ² > [`OUTLIER_CHI2`]).
    pub rejected: Vec<[u32; 2]>,
    /// σ of every front coefficient, nm (0 for the fixed piston).
    pub front_std_nm: Vec<f64>,
    /// σ of every back coefficient, nm (0 where fixed).
    pub back_std_nm: Vec<f64>,
    /// Covariance of the free coefficients, nm², in `layout`'s column order.
    pub covariance: DMatrix<f64>,
    /// The final unknowns.
    pub layout: Layout,
    /// Stages run, in order.
    pub stages: Vec<Stage>,
    /// The term choice (front, and the back where it was fitted) when not
    /// fixed by the caller.
    pub choice: Option<TermChoices>,
    /// Whether the caller fixed the term count ([`SurfaceOptions::terms`]).
    pub terms_fixed: bool,
    /// Final χ², residual components, and χ²/(N − p).
    pub chi2: f64,
    /// Residual components of the final fit.
    pub n_resid: usize,
    /// χ²/(N − p); ≈ 1 when the σ are right and the model suffices.
    pub reduced_chi2: f64,
    /// Factor applied to (JᵀJ)⁻¹: max(1, χ²_red) with known σ, χ²_red otherwise.
    pub covariance_scale: f64,
    /// Condition number of the weighted Jacobian (√ of that of JᵀJ).
    pub condition_number: f64,
}

/// `opts` with `max_terms` lowered to the full radial orders the element's
/// outline supports (a narrow outline makes high orders dependent over it:
/// `optics::outline::orthonormal`).
///
/// # Errors
/// [`SurfaceError::Input`] naming `element.outline` when fixed `terms` or
/// even the plane are beyond it.
fn outline_terms(station: &Station, opts: &SurfaceOptions) -> Result<SurfaceOptions, SurfaceError> {
    let outline = station.element.outline();
    let refuse = |e: crate::optics::outline::OutlineError| SurfaceError::Input {
        what: "element.outline",
        problem: e.to_string(),
    };
    match opts.terms {
        Some(t) => outline
            .orthonormal(t.max(3))
            .map(|_| opts.clone())
            .map_err(refuse),
        None => {
            let most = outline
                .supported_terms(opts.max_terms.max(3))
                .map_err(refuse)?;
            Ok(SurfaceOptions {
                max_terms: most,
                ..opts.clone()
            })
        }
    }
}

/// Runs every stage on `obs`: the front from its slopes, the back on S2,
/// the joint fit, outliers out and refit, the term choice and its refit.
/// (About 80 lines: the sequence of stages, each one call, reads best
/// top to bottom in one place.)
///
/// # Errors
/// [`SurfaceError`] when a stage cannot proceed (no data, ill-conditioned).
pub fn reconstruct(
    obs: &Observations,
    station: &Station,
    opts: &SurfaceOptions,
) -> Result<SurfaceSolution, SurfaceError> {
    // Everything is fitted in the element's own frame (station v2's pose);
    // `obs` were built in it by `Observations::from_maps`.
    let station = &station.element_frame();
    // An outline too narrow for the terms asked: the choice stops at the
    // orders it supports; terms fixed by the user are refused, named.
    let opts = &outline_terms(station, opts)?;
    let weighted = opts.weighted(obs);
    let obs = &*weighted;
    let (terms, mut plate, mut stages) = front_stage(obs, station, opts)?;
    let mut layout = Layout {
        front_terms: terms,
        back_terms: terms,
        fit_front: false,
        fit_back: true,
        back_piston: opts.back_piston,
        use_s1: false,
        use_s2: true,
    };
    if obs.count(1) > 0 {
        if opts.terms.is_none() {
            determined_layout(obs, station, &mut plate, &mut layout)?;
        }
        lm_stage(obs, station, &mut plate, &layout, "back", opts, &mut stages)?;
    }
    layout.fit_front = true;
    layout.use_s1 = true;
    layout.fit_back = obs.count(1) > 0;
    if opts.terms.is_none() {
        determined_layout(obs, station, &mut plate, &mut layout)?;
    }
    let mut normal = if opts.joint || opts.terms.is_none() {
        lm_stage(
            obs,
            station,
            &mut plate,
            &layout,
            "joint",
            opts,
            &mut stages,
        )?
    } else {
        super::problem::accumulate(obs, station, &plate, &layout, true)
    };
    let kept;
    let rejected = outliers(obs, station, &plate, &layout);
    let obs = if rejected.is_empty() {
        obs
    } else {
        kept = without(obs, &rejected);
        normal = lm_stage(
            &kept,
            station,
            &mut plate,
            &layout,
            "joint (outliers out)",
            opts,
            &mut stages,
        )?;
        &kept
    };
    let mut choice = None;
    if opts.terms.is_none() {
        let chosen = refit_chosen_terms(
            obs,
            station,
            &mut plate,
            &mut layout,
            &normal,
            opts,
            &mut stages,
        )?;
        if let Some((terms, refitted)) = chosen {
            normal = refitted.unwrap_or(normal);
            choice = Some(terms);
        }
    }
    let mut sol = finish(plate, layout, normal, stages, choice, obs.sigma_known)?;
    sol.rejected = obs.rejected.clone();
    sol.terms_fixed = opts.terms.is_some();
    Ok(sol)
}

/// The first stage: the front from the S1 slopes with the starting term
/// count, on the nominal plate (its back flat, or the declared wedge's plane). Returns the term count, the plate
/// and the stage's record.
fn front_stage(
    obs: &Observations,
    station: &Station,
    opts: &SurfaceOptions,
) -> Result<(usize, Plate, Vec<Stage>), SurfaceError> {
    let terms = opts.terms.unwrap_or(opts.max_terms).max(3);
    // The plate as made: a flat front and the declared wedge's back plane.
    let (front, back) = station.element.nominal_surfaces(terms)?;
    let mut plate = Plate::new(station, front, back, opts.edge_margin_mm);
    let mut stages = Vec::new();

    let t = Instant::now();
    let (front, rep) = front_from_slopes(obs, station, &plate, terms, opts.front_iter)?;
    if !rep.converged {
        log::warn!(
            "front slopes: stopped by its iteration limit {}, last change {:.4} nm against a σ \
             of {:.4} nm",
            rep.iterations,
            rep.last_change_nm,
            rep.sigma_nm
        );
    }
    plate.front = front;
    stages.push(Stage {
        name: "front slopes",
        seconds: t.elapsed().as_secs_f64(),
        front: Some(rep),
        lm: None,
    });

    Ok((terms, plate, stages))
}

/// The term choice on the joint fit's normal equations (`normal`): the
/// front's, and the back's where it was fitted (a one-surface element, a
/// mirror or an AR-coated back, has the front's alone); where it differs
/// from the fitted counts, the surfaces are truncated to it and fitted
/// again ("joint (chosen terms)"). Returns the choice and, when refitted,
/// the new normal equations; `None` when no choice was possible.
fn refit_chosen_terms(
    obs: &Observations,
    station: &Station,
    plate: &mut Plate,
    layout: &mut Layout,
    normal: &Normal,
    opts: &SurfaceOptions,
    stages: &mut Vec<Stage>,
) -> Result<Option<ChosenTerms>, SurfaceError> {
    let x = free_values(plate, layout);
    let Some(f) = choose_terms(normal, layout, &x, false, obs.sigma_known) else {
        return Ok(None);
    };
    let b = if layout.fit_back {
        match choose_terms(normal, layout, &x, true, obs.sigma_known) {
            Some(b) => Some(b),
            None => return Ok(None),
        }
    } else {
        None
    };
    let (mut f, mut b) = (f, b);
    select::dropped(
        plate,
        layout,
        normal,
        station,
        obs.sigma_known,
        &mut f,
        b.as_mut(),
    );
    // Without a fitted back the back stays the nominal one, carried with
    // the front's count.
    let back_terms = b.as_ref().map_or(f.terms, |b| b.terms);
    let mut refitted = None;
    if f.terms != layout.front_terms || back_terms != layout.back_terms {
        plate.front = truncate(&plate.front, f.terms)?;
        plate.back = truncate(&plate.back, back_terms)?;
        layout.front_terms = f.terms;
        layout.back_terms = back_terms;
        let stage = "joint (chosen terms)";
        refitted = Some(lm_stage(obs, station, plate, layout, stage, opts, stages)?);
    }
    Ok(Some((TermChoices { front: f, back: b }, refitted)))
}

/// The term counts chosen by the criterion.
#[derive(Debug, Clone, PartialEq)]
pub struct TermChoices {
    /// The front's.
    pub front: TermChoice,
    /// The back's; `None` where no back reflection was measured (the back
    /// is not fitted).
    pub back: Option<TermChoice>,
}

/// The terms chosen, and the normal equations of the refit when the choice
/// changed the model.
type ChosenTerms = (TermChoices, Option<Normal>);

/// When the term count is the data's to choose: shrink the model (the
/// back first, by full Noll orders, then the front) until its Jacobian at
/// the current surfaces is conditioned below
/// [`super::lm::MAX_CONDITION_NUMBER`]. The back is seen only where the
/// refracted rays land, which a thick plate at oblique incidence shrinks.
fn determined_layout(
    obs: &Observations,
    station: &Station,
    plate: &mut Plate,
    layout: &mut Layout,
) -> Result<(), SurfaceError> {
    loop {
        let n = super::problem::accumulate(obs, station, plate, layout, true);
        if super::lm::condition_number(&n) <= super::lm::MAX_CONDITION_NUMBER {
            return Ok(());
        }
        let smaller = |t: usize| super::select::candidates(t).into_iter().rev().nth(1);
        if let Some(t) = smaller(layout.back_terms).filter(|_| layout.fit_back) {
            layout.back_terms = t;
            plate.back = truncate(&plate.back, t)?;
        } else if let Some(t) = smaller(layout.front_terms).filter(|_| layout.fit_front) {
            layout.front_terms = t;
            plate.front = truncate(&plate.front, t)?;
        } else {
            return Ok(()); // the stage itself reports the condition number
        }
    }
}

fn lm_stage(
    obs: &Observations,
    station: &Station,
    plate: &mut Plate,
    layout: &Layout,
    name: &'static str,
    opts: &SurfaceOptions,
    stages: &mut Vec<Stage>,
) -> Result<Normal, SurfaceError> {
    let t = Instant::now();
    let (rep, normal) = levenberg_marquardt(obs, station, plate, layout, name, &opts.lm)?;
    if !rep.converged {
        let step = rep.last_step.map_or_else(
            || "not measured".into(),
            |s| format!("{:.4} nm = {:.3} σ", s.step_nm, s.in_sigma()),
        );
        log::warn!("{name}: stopped by {}, last step {step}", rep.reason);
    }
    stages.push(Stage {
        name,
        seconds: t.elapsed().as_secs_f64(),
        front: None,
        lm: Some(rep),
    });
    Ok(normal)
}

/// The free coefficients in column order.
fn free_values(plate: &Plate, layout: &Layout) -> DVector<f64> {
    let mut x = DVector::zeros(layout.columns());
    for (k, c) in plate.front.coefficients_nm().iter().enumerate() {
        if let Some(col) = layout.front_col(k) {
            x[col] = *c;
        }
    }
    for (k, c) in plate.back.coefficients_nm().iter().enumerate() {
        if let Some(col) = layout.back_col(k) {
            x[col] = *c;
        }
    }
    x
}

fn truncate(s: &ZernikeSurface, terms: usize) -> Result<ZernikeSurface, SurfaceError> {
    let b = s.basis();
    let mut c = s.coefficients_nm().to_vec();
    c.resize(terms, 0.0);
    Ok(ZernikeSurface::new(
        ZernikeBasis::new(terms, b.radius_mm(), b.center_mm())?,
        c,
    )?)
}

fn finish(
    plate: Plate,
    layout: Layout,
    normal: Normal,
    stages: Vec<Stage>,
    choice: Option<TermChoices>,
    sigma_known: bool,
) -> Result<SurfaceSolution, SurfaceError> {
    let p = layout.columns();
    let eig = normal.a.clone().symmetric_eigen().eigenvalues;
    let (lo, hi) = (eig.min(), eig.max());
    let condition_number = if lo > 0.0 {
        (hi / lo).sqrt()
    } else {
        f64::INFINITY
    };
    let inv =
        normal
            .a
            .clone()
            .cholesky()
            .map(|c| c.inverse())
            .ok_or(SurfaceError::IllConditioned {
                stage: "covariance",
                condition_number,
            })?;
    let dof = normal.n_resid.saturating_sub(p).max(1) as f64;
    let reduced_chi2 = normal.chi2 / dof;
    let covariance_scale = if sigma_known {
        reduced_chi2.max(1.0)
    } else {
        reduced_chi2
    };
    let covariance = inv * covariance_scale;
    let std_of = |n: usize, col: &dyn Fn(usize) -> Option<usize>| -> Vec<f64> {
        (0..n)
            .map(|k| col(k).map_or(0.0, |c| covariance[(c, c)].sqrt()))
            .collect()
    };
    let front_std_nm = std_of(layout.front_terms, &|k| layout.front_col(k));
    let back_std_nm = std_of(layout.back_terms, &|k| layout.back_col(k));
    Ok(SurfaceSolution {
        outline: plate.outline.clone(),
        front: plate.front,
        back: plate.back,
        back_fitted: layout.fit_back,
        rejected: Vec::new(),
        front_std_nm,
        back_std_nm,
        covariance,
        layout,
        stages,
        choice,
        terms_fixed: false,
        chi2: normal.chi2,
        n_resid: normal.n_resid,
        reduced_chi2,
        covariance_scale,
        condition_number,
    })
}

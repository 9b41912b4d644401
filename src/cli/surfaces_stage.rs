//! The surface stage's options and printed summary (`mfd reconstruct`,
//! `mfd measure`); the stage itself is the library's pipeline.

use clap::Args;

use mfd::solve::surfaces::lm::LmOptions;
use mfd::solve::surfaces::SurfaceOptions;

/// Options of the surface stage.
#[derive(Args, Clone, Debug)]
pub struct SurfaceArgs {
    /// Zernike terms per surface (Noll 1..=N, N from 3 to 231); default:
    /// chosen by the Bayesian information criterion up to --max-terms.
    #[arg(long, value_parser = super::check::terms)]
    pub terms: Option<usize>,
    /// Largest model the term choice considers (3 to 231).
    #[arg(long, value_parser = super::check::terms, default_value_t = 66)]
    pub max_terms: usize,
    /// Levenberg–Marquardt iteration limit per stage.
    #[arg(long, value_parser = super::check::positive_int::<usize>, default_value_t = 30)]
    pub max_iter: usize,
    /// Skip the joint refinement of front and back on S1 and S2 together.
    #[arg(long)]
    pub no_joint: bool,
    /// Skip the surface stage (spectral maps only).
    #[arg(long)]
    pub no_surfaces: bool,
    /// Which estimator makes the surfaces from the frames: auto (the
    /// surface-domain fit, started from the per-pixel surfaces where those
    /// exist), per-pixel (screen points per pixel, then the surfaces) or
    /// direct (the surface-domain fit, an error where it cannot run).
    #[arg(long, value_enum, default_value_t = mfd::pipeline::Estimator::Auto)]
    pub estimator: mfd::pipeline::Estimator,
    /// Report a surface as not reconstructed (with the reason) when its
    /// expected RMS error exceeds this, nm; without it, only when the
    /// expected error is as large as the fitted surface. A plane (no term
    /// beyond tilt: a flat face) is reported, flat within its expected
    /// error, only where this limit holds it; without it, it is withheld.
    #[arg(long, value_parser = super::check::positive)]
    pub max_expected_nm: Option<f64>,
    /// Wavelength of the transmitted wavefront's figure in waves
    /// (`summary.json`'s figures.plate.twe_rms_waves), nm; default 1053.
    #[arg(long, value_parser = super::check::positive)]
    pub wavelength_nm: Option<f64>,
}

impl SurfaceArgs {
    /// The estimator and the reporting limit (checked where parsed).
    pub fn estimator(&self) -> anyhow::Result<(mfd::pipeline::Estimator, Option<f64>)> {
        Ok((self.estimator, self.max_expected_nm))
    }

    /// The solver options these arguments ask for (their ranges checked
    /// where parsed).
    pub fn options(&self, edge_margin_mm: f64) -> anyhow::Result<SurfaceOptions> {
        Ok(SurfaceOptions {
            terms: self.terms,
            max_terms: self.max_terms,
            lm: LmOptions {
                max_iter: self.max_iter.max(2),
                ..LmOptions::default()
            },
            joint: !self.no_joint,
            edge_margin_mm,
            ..SurfaceOptions::default()
        })
    }
}

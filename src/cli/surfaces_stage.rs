//! The surface stage's options and printed summary (`mfd reconstruct`,
//! `mfd measure`); the stage itself is the library's pipeline.

use clap::Args;

use mfd::solve::surfaces::lm::LmOptions;
use mfd::solve::surfaces::SurfaceOptions;

/// Options of the surface stage.
#[derive(Args, Clone, Debug)]
pub struct SurfaceArgs {
    /// Zernike terms per surface (Noll 1..=N, up to 231); default: chosen
    /// by the Bayesian information criterion up to --max-terms.
    #[arg(long)]
    pub terms: Option<usize>,
    /// Largest model the term choice considers.
    #[arg(long, default_value_t = 66)]
    pub max_terms: usize,
    /// Levenberg–Marquardt iteration limit per stage.
    #[arg(long, default_value_t = 30)]
    pub max_iter: usize,
    /// Skip the joint refinement of front and back on S1 and S2 together.
    #[arg(long)]
    pub no_joint: bool,
    /// Skip the surface stage (spectral maps only).
    #[arg(long)]
    pub no_surfaces: bool,
}

impl SurfaceArgs {
    /// The solver options these arguments ask for.
    pub fn options(&self, edge_margin_mm: f64) -> anyhow::Result<SurfaceOptions> {
        if let Some(t) = self.terms {
            anyhow::ensure!((3..=231).contains(&t), "--terms {t}: must be 3..=231");
        }
        anyhow::ensure!(
            (3..=231).contains(&self.max_terms),
            "--max-terms {}: must be 3..=231",
            self.max_terms
        );
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

//! The surface stage's options and printed summary (`mfd reconstruct`,
//! `mfd measure`); the stage itself is the library's pipeline.

use clap::Args;

use mfd::pipeline::SurfaceStage;
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

/// Prints a surface solution's figures: per surface its terms, RMS ± σ, PV
/// and uncertainty; the stages' iterations and times; χ²/dof; outliers.
pub fn print_summary(stage: &SurfaceStage) {
    let (sol, summary) = (&stage.solution, &stage.summary);
    let seconds = summary.seconds;
    if summary.back.is_none() {
        println!("back: not reconstructed (no back reflection was measured)");
    }
    let surfaces = [
        ("front", Some(&summary.front)),
        ("back", summary.back.as_ref()),
    ];
    for (name, f) in surfaces.into_iter().filter_map(|(n, f)| Some((n, f?))) {
        println!(
            "{name}: {} terms, RMS {:.2} ± {:.2} nm, PV {:.1} nm (piston and tilt removed); \
             surface uncertainty {:.2} nm RMS",
            f.terms, f.rms_nm, f.rms_std_nm, f.pv_nm, f.error_rms_nm
        );
    }
    let iters: Vec<String> = sol
        .stages
        .iter()
        .map(|s| {
            let n = s.lm.as_ref().map_or_else(
                || s.front.as_ref().map_or(0, |f| f.iterations),
                |l| l.iterations,
            );
            format!("{} {} it {:.2} s", s.name, n, s.seconds)
        })
        .collect();
    println!(
        "surfaces: {seconds:.2} s ({}); χ²/dof {:.3}, condition number {:.3e}",
        iters.join(", "),
        sol.reduced_chi2,
        sol.condition_number
    );
    if !sol.rejected.is_empty() {
        println!(
            "  {} pixels left out as outliers (χ² > 49), e.g. (column, row) {:?}",
            sol.rejected.len(),
            &sol.rejected[..sol.rejected.len().min(5)]
        );
    }
}

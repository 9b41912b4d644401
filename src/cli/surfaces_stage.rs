//! The surface stage of `mfd reconstruct`: from screen points to
//! `surfaces.json`, height maps, pictures and `summary.json`.

use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use clap::Args;
use serde_json::json;

use mfd::formats::npy;
use mfd::formats::surfaces_file::SurfacesFile;
use mfd::optics::station::Station;
use mfd::solve::surfaces::lm::LmOptions;
use mfd::solve::surfaces::report::{figures, height_grid, SurfaceFigures};
use mfd::solve::surfaces::{
    reconstruct, Observations, SurfaceOptions, SurfaceSolution, Uncertainty,
};

/// Side of the height-map grids, pixels.
const GRID: usize = 256;

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

/// Runs the surface stage and writes its files into `out`; returns the
/// solution and its wall time.
pub fn run(
    station: &Station,
    coords: &[f64],
    unc: Uncertainty,
    opts: &SurfaceOptions,
    out: &Path,
) -> anyhow::Result<(SurfaceSolution, f64)> {
    let t = Instant::now();
    let obs = Observations::from_maps(station, coords, unc)?;
    let sol = reconstruct(&obs, station, opts).context("surface stage")?;
    let seconds = t.elapsed().as_secs_f64();
    let mut file = SurfacesFile::from_surfaces(&sol.front, &sol.back);
    if !sol.back_fitted {
        file.back = None; // spec: a surface that was not reconstructed is null
        println!("back: not reconstructed (no back reflection was measured)");
    }
    file.save(&out.join("surfaces.json"))?;
    let (front, back) = (figures(&sol, false), figures(&sol, true));
    let mut surfaces = vec![("front", &sol.front, &front)];
    if sol.back_fitted {
        surfaces.push(("back", &sol.back, &back));
    }
    for (name, s, f) in surfaces {
        let grid = height_grid(s, GRID);
        npy::write_f64(
            &out.join(format!("{name}_height_nm.npy")),
            &[GRID, GRID],
            &grid,
        )?;
        super::pictures::surface(out, name, &grid, GRID, f)?;
        super::pictures::coefficients(out, name, f)?;
    }
    let summary = summary_json(&obs, &sol, &front, &back, seconds);
    let text = serde_json::to_string_pretty(&summary)?;
    std::fs::write(out.join("summary.json"), text + "\n")
        .with_context(|| format!("writing {}", out.join("summary.json").display()))?;
    print_summary(&sol, &front, &back, seconds);
    Ok((sol, seconds))
}

fn summary_json(
    obs: &Observations,
    sol: &SurfaceSolution,
    front: &SurfaceFigures,
    back: &SurfaceFigures,
    seconds: f64,
) -> serde_json::Value {
    let stages: Vec<serde_json::Value> = sol
        .stages
        .iter()
        .map(|s| match (&s.front, &s.lm) {
            (Some(f), _) => {
                json!({"name": s.name, "seconds": s.seconds, "iterations": f.iterations,
                "last_change_nm": f.last_change_nm, "condition_number": f.condition_number,
                "points": f.points})
            }
            (_, Some(l)) => {
                json!({"name": s.name, "seconds": s.seconds, "iterations": l.iterations,
                "chi2_start": l.chi2_start, "chi2": l.chi2, "residuals": l.n_resid,
                "converged": l.converged, "reason": l.reason, "paths_lost": l.failed})
            }
            _ => json!({"name": s.name, "seconds": s.seconds}),
        })
        .collect();
    let choice = match &sol.choice {
        Some([f, b]) => json!({
            "criterion": "BIC = chi2 + p ln N over nested Noll orders (N ln(chi2/N) + p ln N when sigma is unknown)",
            "front": {"terms": f.terms, "candidates": f.candidates},
            "back": {"terms": b.terms, "candidates": b.candidates}}),
        None => json!({"criterion": "fixed by --terms"}),
    };
    json!({
        "format": "mfd-summary/1",
        "pixels": {"s1": obs.count(0), "s2": obs.count(1)},
        "sigma_from_data": obs.sigma_known,
        "outliers": {"rule": "pixel chi2 of its whitened residuals > 49 x max(1, median chi2 per component / 0.75), at most 1 % of the pixels",
                     "count": sol.rejected.len(), "pixels_col_row": sol.rejected.iter().take(1000).collect::<Vec<_>>()},
        "figures_note": "RMS, PV and pictures with piston and tilt (Noll 1-3) removed; front piston fixed at 0 by the reference plane; back piston fixed at the nominal thickness",
        "front": front,
        "back": if sol.back_fitted { json!(back) } else { serde_json::Value::Null },
        "terms": choice,
        "stages": stages,
        "chi2": sol.chi2, "residuals": sol.n_resid, "reduced_chi2": sol.reduced_chi2,
        "covariance_scale": sol.covariance_scale,
        "condition_number": sol.condition_number,
        "seconds": seconds,
    })
}

fn print_summary(
    sol: &SurfaceSolution,
    front: &SurfaceFigures,
    back: &SurfaceFigures,
    seconds: f64,
) {
    for (name, f) in [("front", front), ("back", back)]
        .into_iter()
        .take(1 + usize::from(sol.back_fitted))
    {
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

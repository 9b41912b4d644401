//! What `mfd reconstruct` and `mfd measure` print and write at the end: the
//! result folder, the spectral stage's counts, the surfaces' figures.

use std::path::Path;

use mfd::pipeline::{FoundUncertainty, Reconstruction, Staged, SurfaceStage, UncertaintySource};

use super::exit::{classified, Class};
use mfd::solve::spectral::{PixelFlags, SpectralMaps};

/// Writes a reconstruction into `out` and prints what it found. The result
/// is written beside `out` and renamed into place only when complete
/// ([`Staged`]): a surface stage that could not run is the command's error,
/// `out` keeps the previous complete result (or stays absent), and this
/// run's spectral maps are kept in `OUT.failed` with the error. A result
/// whose points contradict the station is written, flagged, and (without
/// `--accept-inconsistent`) exits with [`Class::Inconsistent`]'s status.
/// `mfd measure` calls this with its streamed solver's result.
pub fn write_and_print(
    rec: &Reconstruction,
    out: &Path,
    checks: &super::CheckArgs,
) -> anyhow::Result<()> {
    let staged = Staged::begin(out)?;
    if let Err(e) = rec.write(staged.path()) {
        let msg = e.to_string();
        let kept = staged.fail(&msg)?;
        return Err(super::exit::like(
            &e,
            format!(
                "{msg}; {} is unchanged; what this run wrote is in {}",
                out.display(),
                kept.display()
            ),
        ));
    }
    if let Some(s) = &rec.spectral {
        summarise(&s.maps, s.fitted_pixels, s.read_s, s.solve_s);
        println!("check against the station: {}", s.consistency.note);
        if let Some(w) = &s.wedge {
            println!("wedge: {}", w.describe());
        }
    }
    if let Some(Err(e)) = &rec.surfaces {
        let msg = format!("surface stage: {e}");
        let kept = staged.fail(&msg)?;
        // With the surface error's class (too few points: no signal).
        return Err(super::exit::like(
            e,
            format!(
                "{msg}; {} is unchanged (the previous result, if any); this run's spectral \
                 maps are in {}",
                out.display(),
                kept.display()
            ),
        ));
    }
    staged.commit()?;
    if let Some(Ok(stage)) = &rec.surfaces {
        print_surfaces(stage);
        println!("wrote {}", out.join("surfaces.json").display());
    } else if rec.spectral.is_some() {
        println!("wrote {}", out.join("screen_coords.npy").display());
    }
    if let Some(Ok(stage)) = &rec.surfaces {
        if stage.summary.unconverged() && !checks.accept_unconverged {
            return Err(classified(
                Class::Inconsistent,
                anyhow::anyhow!(
                    "a stage stopped at its iteration limit with a last step larger than its σ \
                     (above); the result in {} is complete but flagged (summary.json \
                     \"convergence\"); rerun with a larger --max-iter, fewer --terms, or \
                     --accept-unconverged to exit 0",
                    out.display()
                ),
            ));
        }
    }
    match rec.spectral.as_ref().map(|s| &s.consistency) {
        Some(c) if !c.consistent && !checks.accept_inconsistent => Err(classified(
            Class::Inconsistent,
            anyhow::anyhow!(
                "{}{}; the result in {} is complete but flagged (consistency.json, summary.json \
                 \"consistency\"); if the station is right and the part departs that far from \
                 flat, rerun with --max-departure-nm, or --accept-inconsistent to exit 0",
                c.note,
                wedge_seen(rec),
                out.display()
            ),
        )),
        _ => Ok(()),
    }
}

/// Where the points contradict the station and the wedge search saw a back
/// reflection away from the station's wedge, on too few sample pixels to
/// measure from ([`mfd::pipeline::wedge::FOUND_SHARE`]): that wedge, named,
/// and the station fields to set (a plate wedged otherwise than declared,
/// on a schedule whose τ span barely separates its back from the front).
fn wedge_seen(rec: &Reconstruction) -> String {
    use mfd::pipeline::wedge::{SEEN_SHARE, SHIFT_BINS};
    let Some(w) = rec.spectral.as_ref().and_then(|s| s.wedge) else {
        return String::new();
    };
    let s = &w.search;
    if w.used_found || s.seen_share < SEEN_SHARE || s.shift_bins < SHIFT_BINS {
        return String::new();
    }
    format!(
        "; the frames show a back reflection where a wedge of {:.2} arcmin at azimuth {:.1}° \
         would put it, on {:.0} % of {} sample pixels (where the station's wedge puts it: \
         {:.0} %), too few to measure from: if the plate is wedged, set element.wedge_arcmin \
         and wedge_azimuth_deg in the station (mfd-station/2) to the wedge it was made with",
        s.wedge.arcmin,
        s.wedge.azimuth_deg,
        100.0 * s.seen_share,
        s.pixels,
        100.0 * s.declared_seen_share
    )
}

fn summarise(maps: &SpectralMaps, fitted: usize, read_s: f64, solve_s: f64) {
    let both = maps.found_both();
    let median = |k: usize| {
        let mut v: Vec<f64> = maps
            .pixels
            .iter()
            .map(|p| p.std[k][0].hypot(p.std[k][1]))
            .filter(|s| s.is_finite())
            .collect();
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
    };
    println!(
        "spectral: {fitted} pixels fitted in {solve_s:.1} s (frames read in {read_s:.1} s); \
         both reflections found in {both}; median σ(S1) {:.4} px, σ(S2) {:.4} px",
        median(0),
        median(1)
    );
    // NO_DATA pixels are not counted; OUT_OF_BAND is told apart below.
    let names = PixelFlags::MEANINGS
        .into_iter()
        .filter(|(bit, _)| !bit.intersects(PixelFlags::NO_DATA | PixelFlags::OUT_OF_BAND));
    for (bit, name) in names {
        let n = maps
            .pixels
            .iter()
            .filter(|p| p.flags.intersects(bit) && !p.flags.intersects(PixelFlags::NO_DATA))
            .count();
        if n > 0 {
            println!("  {n} pixels: {name}");
        }
    }
    let count = |f: &dyn Fn(PixelFlags) -> bool| {
        maps.pixels
            .iter()
            .filter(|p| !p.flags.intersects(PixelFlags::NO_DATA) && f(p.flags))
            .count()
    };
    let left =
        count(&|f| f.intersects(PixelFlags::OUT_OF_BAND) && !f.intersects(PixelFlags::NO_SIGNAL));
    if left > 0 {
        println!("  {left} pixels: signal or fit outside the statistics engine's band");
    }
    let quiet =
        count(&|f| f.intersects(PixelFlags::OUT_OF_BAND) && f.intersects(PixelFlags::NO_SIGNAL));
    if quiet + left > fitted / 2 {
        println!(
            "  most pixels show no signal within the band the statistics engine keeps: the \
             element may sit away from where the station file puts it; rerun with \
             --band-bins 8 or --engine series"
        );
    }
    if let Some(s) = maps.saturation_counts {
        println!("  saturation level {s} counts");
    }
}

/// Prints where the station's uncertainty came from, or that there is none
/// and the geometry counts as exact.
pub fn print_uncertainty_source(found: Option<&FoundUncertainty>, station: &Path) {
    match found {
        Some(f) => {
            let how = match f.source {
                UncertaintySource::Given => "",
                UncertaintySource::BesideStation => " (found beside the station file)",
            };
            println!(
                "station uncertainty: {}{how}, {} degrees of freedom with a σ",
                f.path.display(),
                f.uncertainty.names.len()
            );
        }
        None => println!(
            "no station uncertainty (--uncertainty, or station_uncertainty.toml beside {}): \
             the geometry is taken as exact, σ are the noise alone",
            station.display()
        ),
    }
}

/// Prints a surface solution's figures: per surface its terms, RMS ± σ, PV
/// and uncertainty; the stages' iterations and times; χ²/dof; outliers.
fn print_surfaces(stage: &SurfaceStage) {
    let (sol, summary) = (&stage.solution, &stage.summary);
    let seconds = summary.seconds;
    if let Some(d) = &summary.direct {
        let conv = if d.converged {
            "converged"
        } else {
            "did not converge"
        };
        println!(
            "surfaces fitted to the frames (surface-domain fit): {} iterations, {conv}, {:.2} s",
            d.iterations.len(),
            d.seconds
        );
    }
    if summary.back.is_none() {
        println!("back: not reconstructed (no back reflection was measured)");
    }
    let surfaces = [
        ("front", Some(&summary.front)),
        ("back", summary.back.as_ref()),
    ];
    for (k, (name, f)) in surfaces.into_iter().enumerate() {
        let Some(f) = f else { continue };
        if let Some(why) = &stage.withheld[k] {
            println!("{name}: not reconstructed: {why}");
            continue;
        }
        println!(
            "{name}: {} terms, RMS {:.2} ± {:.2} nm, PV {:.1} nm (piston and tilt removed); \
             surface uncertainty {:.2} nm RMS",
            f.terms, f.rms_nm, f.rms_std_nm, f.pv_nm, f.error_rms_nm
        );
    }
    if summary.station.is_none() {
        println!("  {}", summary.uncertainty_note);
    }
    if let Some(f) = &summary.figures {
        for line in mfd::report::figures::table::lines(f) {
            println!("{line}");
        }
    }
    for r in &summary.refined {
        println!(
            "refined {}: {:+.6} from the station file, σ {:.3e} (prior {:.3e})",
            r.name, r.change, r.posterior_std, r.prior_std
        );
    }
    if let Some(st) = &summary.station {
        let splits = [("front", Some(&st.front)), ("back", st.back.as_ref())];
        for (name, s) in splits.into_iter().filter_map(|(n, s)| Some((n, s?))) {
            println!(
                "{name}: expected error {:.2} nm RMS = noise {:.2} ⊕ station {:.2} nm",
                s.total_rms_nm, s.noise_rms_nm, s.station_rms_nm
            );
        }
        let top: Vec<String> = st
            .largest
            .iter()
            .take(3)
            .map(|s| {
                format!(
                    "{} ±{} (front {:.2} nm, {:.0} %; back {:.2} nm, {:.0} %)",
                    s.name,
                    short(s.std),
                    s.front_rms_nm,
                    100.0 * s.front_share,
                    s.back_rms_nm,
                    100.0 * s.back_share
                )
            })
            .collect();
        println!(
            "  station: largest single shares (each alone at one σ; their correlations are in \
             the total) {}",
            top.join(", ")
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
    for c in summary.convergence.iter().filter(|c| !c.converged) {
        let line = c.describe();
        println!("{line}");
        if c.flags_result {
            eprintln!("warning: {line}");
        }
    }
    if !sol.rejected.is_empty() {
        println!(
            "  {} pixels left out as outliers (χ² > 49), e.g. (column, row) {:?}",
            sol.rejected.len(),
            &sol.rejected[..sol.rejected.len().min(5)]
        );
    }
}

/// A σ in at most four significant digits, exponent form below 1e-3.
fn short(x: f64) -> String {
    if x != 0.0 && x.abs() < 1e-3 {
        format!("{x:.3e}")
    } else {
        format!("{}", (x * 1e4).round() / 1e4)
    }
}

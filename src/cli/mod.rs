//! Subcommands of the `mfd` binary.

pub mod bench;
pub mod bench_extremes;
pub mod bench_surfaces;
pub mod bench_table;
pub mod compare;
pub mod display;
pub mod measure;
pub mod pictures;
pub mod reconstruct;
pub mod simulate;
pub mod station;
pub mod surfaces_stage;
pub mod trace;
pub mod tradeoff;

use std::path::Path;

use anyhow::Context;
use mfd::station::Station;
use mfd::surfaces_file::SurfacesFile;
use mfd::zernike::ZernikeSurface;

/// Front and back surfaces from a `surfaces.json`, or flat surfaces over the
/// station's aperture when none is given. A `null` surface is flat.
pub fn load_surfaces(
    path: Option<&Path>,
    station: &Station,
) -> anyhow::Result<(ZernikeSurface, ZernikeSurface)> {
    let e = &station.element;
    let centre = [e.aperture_center_mm.x, e.aperture_center_mm.y];
    let Some(path) = path else {
        let flat = ZernikeSurface::flat(e.aperture_radius_mm, centre)?;
        return Ok((flat.clone(), flat));
    };
    let file = SurfacesFile::load(path)?;
    let make = |coeffs: Option<&Vec<f64>>| -> anyhow::Result<ZernikeSurface> {
        mfd::surfaces_file::to_surface(&file, coeffs)
            .with_context(|| format!("{}: building the Zernike surface", path.display()))
    };
    Ok((
        make(file.front_coefficients())?,
        make(file.back_coefficients())?,
    ))
}

/// The spectral engine named on the command line (`--engine`).
pub fn parse_engine(name: &str) -> anyhow::Result<mfd::spectral::Engine> {
    use mfd::spectral::Engine;
    match name {
        "auto" => Ok(Engine::Auto),
        "series" => Ok(Engine::Series),
        "statistics" | "stats" => Ok(Engine::Statistics),
        other => anyhow::bail!("--engine: expected auto, series or statistics, found {other:?}"),
    }
}

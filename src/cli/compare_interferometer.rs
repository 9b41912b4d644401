//! `mfd compare --surfaces S --interferometer FILE`: an mfd surface against
//! an interferometer's height map (and the same options for `mfd report
//! --interferometer`).

use std::path::{Path, PathBuf};

use clap::Args;

use mfd::compare::{self, Comparison, LoadOptions, RegistrationOptions};
use mfd::formats::surfaces_file::SurfacesFile;

/// The interferometer map and its registration.
#[derive(Args, Clone, Default)]
pub struct InterferometerArgs {
    /// An interferometer's height map to compare with (Zygo MetroPro .dat,
    /// Zygo .datx with feature `datx`, .npy float64 [rows, columns] or
    /// .csv; row 0 at the top).
    #[arg(long, value_name = "FILE")]
    pub interferometer: Option<PathBuf>,
    /// Which surface of surfaces.json to compare.
    #[arg(long, default_value = "front", value_parser = ["front", "back"])]
    pub surface: String,
    /// The map's pixel size, mm (default: the file's; for NPY/CSV without
    /// it, set from the aperture's radius in pixels).
    #[arg(long, value_parser = super::check::positive)]
    pub pixel_mm: Option<f64>,
    /// The aperture centre in the map, column,row (pixel centres at +0.5);
    /// default: the centroid of the valid pixels.
    #[arg(long, value_parser = super::check::finite, value_delimiter = ',', allow_hyphen_values = true)]
    pub center_px: Option<Vec<f64>>,
    /// The measured aperture's radius in map pixels (sets the pixel size
    /// when it is not known); default: from the valid pixels' area.
    #[arg(long, value_parser = super::check::positive)]
    pub radius_px: Option<f64>,
    /// Rotation of the map onto mfd's world frame, degrees
    /// (counter-clockwise); default: fitted.
    #[arg(long, value_parser = super::check::finite, allow_hyphen_values = true)]
    pub rotation_deg: Option<f64>,
    /// Mirror the map's columns before rotating (true/false); default: fitted.
    #[arg(long)]
    pub flip: Option<bool>,
    /// NPY/CSV: multiply the stored values by this to get nm (1e9 for metres).
    #[arg(long, value_parser = super::check::height_scale, default_value_t = 1.0, allow_hyphen_values = true)]
    pub height_scale_nm: f64,
    /// Print the comparison as JSON (mfd-comparison/1) instead of text.
    #[arg(long)]
    pub json: bool,
    /// Folder for comparison.json and the pictures; default: `comparison`
    /// beside surfaces.json.
    #[arg(long = "comparison-out", value_name = "DIR")]
    pub comparison_out: Option<PathBuf>,
}

impl InterferometerArgs {
    /// The registration options given.
    pub fn registration(&self) -> anyhow::Result<RegistrationOptions> {
        let center_px = match self.center_px.as_deref() {
            None => None,
            Some([c, r]) => Some([*c, *r]),
            Some(v) => {
                return Err(super::exit::usage(anyhow::anyhow!(
                    "--center-px takes two numbers column,row, not {v:?}"
                )))
            }
        };
        Ok(RegistrationOptions {
            center_px,
            radius_px: self.radius_px,
            pixel_mm: self.pixel_mm,
            rotation_deg: self.rotation_deg,
            flip: self.flip,
        })
    }
}

/// Reads the map and compares it with `surfaces`.
pub fn comparison(
    args: &InterferometerArgs,
    surfaces: &Path,
) -> anyhow::Result<Option<Comparison>> {
    let Some(file) = &args.interferometer else {
        return Ok(None);
    };
    let map = compare::load(
        file,
        &LoadOptions {
            height_scale_nm: args.height_scale_nm,
        },
    )?;
    let s = SurfacesFile::load(surfaces)?;
    Ok(Some(compare::compare(
        &map,
        &s,
        surfaces,
        &args.surface,
        &args.registration()?,
    )?))
}

/// Runs the comparison, writes comparison.json and the pictures, prints it.
pub fn run(args: &InterferometerArgs, surfaces: &Path) -> anyhow::Result<()> {
    let Some(c) = comparison(args, surfaces)? else {
        return Ok(());
    };
    let dir = args.comparison_out.clone().unwrap_or_else(|| {
        surfaces
            .parent()
            .unwrap_or(Path::new("."))
            .join("comparison")
    });
    let pictures = compare::pictures::draw(&dir, &c)?;
    let json = serde_json::to_string_pretty(&c)?;
    let path = dir.join("comparison.json");
    std::fs::write(&path, format!("{json}\n"))
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    if args.json {
        println!("{json}");
        return Ok(());
    }
    for line in c.describe() {
        println!("{line}");
    }
    println!("  j   mfd nm    σ nm   interf. nm   diff nm  diff/σ");
    for row in c.table_rows() {
        println!(
            "{:>3} {:>9} {:>7} {:>12} {:>9} {:>7}",
            row[0], row[1], row[2], row[3], row[4], row[5]
        );
    }
    println!(
        "wrote {} and {} pictures in {}",
        path.display(),
        pictures.len(),
        dir.display()
    );
    Ok(())
}

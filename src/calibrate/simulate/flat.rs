//! The reference flat's acquisition of a simulated calibration session:
//! a flat mirror standing on the reference plane of the true station,
//! recorded with a short phase-shifting schedule on a display that is not
//! linearised (as labs record it), 8-bit.

use std::path::Path;

use crate::acquire::acquisition::FrameLayout;
use crate::formats::surfaces_file::SurfacesFile;
use crate::optics::station::Station;
use crate::optics::trace::{Plate, DEFAULT_EDGE_MARGIN_MM};
use crate::optics::zernike::ZernikeSurface;
use crate::sim::{
    phase_shift_patterns, simulate_mirror, PhaseShiftParams, SimError, SimParams, Simulation,
};

/// The schedule: τ = 1, 4, 16, 64 × four phase steps × ±45° (32 frames).
pub fn flat_schedule() -> Vec<crate::acquire::patterns::Pattern> {
    phase_shift_patterns(&[45.0, -45.0], &[1.0, 4.0, 16.0, 64.0], 4)
}

/// Writes `dir/flat/` (an `mfd-acquisition/1` folder) of a flat of radius
/// `radius_mm` at the true station's reference plane, and replaces the
/// station copy beside it with `nominal` (what a lab's recorder would
/// name); the flat's truth stays in `flat/truth/`.
///
/// # Errors
/// [`SimError`] naming the file that could not be written.
pub fn write_flat_acquisition(
    truth: &Station,
    nominal: &Station,
    radius_mm: f64,
    phase: PhaseShiftParams,
    dir: &Path,
) -> Result<(), SimError> {
    let mut station = truth.clone();
    station.element.pose = Default::default();
    station.element.aperture_radius_mm = radius_mm;
    station.element.aperture_center_mm = nalgebra::Point2::origin();
    let flat = ZernikeSurface::flat(radius_mm, [0.0, 0.0]).map_err(|e| SimError::Invalid {
        field: "flat radius",
        problem: e.to_string(),
    })?;
    let plate = Plate::new(&station, flat.clone(), flat.clone(), DEFAULT_EDGE_MARGIN_MM);
    let truth_file = SurfacesFile::from_surfaces(&flat, &flat);
    let patterns = flat_schedule();
    let sim = Simulation {
        station: &station,
        plate: &plate,
        truth: &truth_file,
        patterns: &patterns,
        params: SimParams::default(),
        layout: FrameLayout::Stack {
            dtype: crate::formats::npy::StackDtype::U8,
        },
        overwrite: true,
    };
    let out = dir.join("flat");
    simulate_mirror(&sim, phase, &out)?;
    let copy = out.join("station.toml");
    nominal.save(&copy)?;
    Ok(())
}

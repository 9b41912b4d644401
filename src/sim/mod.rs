//! The simulated station, all in one place: the renderer of what the real
//! camera would record ([`Renderer`]), the simulated camera behind the
//! [`Camera`](crate::acquire::camera::Camera) trait ([`SimulatedCamera`],
//! with injected [`SimFaults`]), what the simulated screen shows
//! ([`ScreenState`], [`SimDisplay`], [`MirroredDisplay`]), the frame feed of
//! the fake GigE Vision camera ([`GigeFeed`]), seeded random scenes
//! ([`RandomSurfaceSpec`]), a point target for calibration sessions
//! ([`SpotScene`], [`SpotCamera`]), a phase-shifting acquisition of a mirror
//! on a display with a gamma ([`PhaseShiftRenderer`]), and [`simulate`], which writes a whole
//! acquisition folder with its truth.
//!
//! Arrows point down: this module uses `acquire` (the camera trait, the
//! displays, patterns, the acquisition writer), `optics`, `formats` and
//! `kernels`, nothing above them; `acquire` uses nothing of it. The
//! simulated cameras are chosen by `--camera sim` and `aravis:fake` in
//! `live::camera::open`, above both.

#[cfg(feature = "aravis")]
pub mod aravis_fake;
mod camera;
mod gige_feed;
mod phase;
mod render;
mod screen;
mod target;

use std::path::{Path, PathBuf};
use std::time::Instant;

pub use crate::optics::zernike::RandomSurfaceSpec;
pub use camera::{SimFaults, SimulatedCamera};
pub use gige_feed::{Filled, GigeFeed};
pub use phase::{phase_shift_patterns, Luminance, PhaseShiftParams, PhaseShiftRenderer};
pub use render::{Falloff, Renderer, SimParams};
pub use screen::{MirroredDisplay, ScreenState, SimDisplay};
pub use target::{render_spot, SpotCamera, SpotScene};

use crate::acquire::acquisition::{
    AcquisitionError, AcquisitionWriter, FrameImage, FrameInfo, FrameLayout,
};
use crate::acquire::patterns::Pattern;
use crate::formats::npy::{self, NpyError};
use crate::formats::surfaces_file::{SurfacesFile, SurfacesFileError};
use crate::optics::station::{Station, StationError};
use crate::optics::trace::{Plate, TracedView};

/// What can go wrong simulating.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// A parameter is out of range.
    #[error("simulation: `{field}`: {problem}")]
    Invalid {
        /// The parameter (CLI flag) name.
        field: &'static str,
        /// What is wrong.
        problem: String,
    },
    /// Writing the acquisition failed.
    #[error(transparent)]
    Acquisition(#[from] AcquisitionError),
    /// Writing a truth array failed.
    #[error(transparent)]
    Npy(#[from] NpyError),
    /// Writing the station copy failed.
    #[error(transparent)]
    Station(#[from] StationError),
    /// Writing a target frame failed.
    #[error(transparent)]
    Image(#[from] crate::formats::image_io::ImageError),
    /// Writing the truth surfaces failed.
    #[error(transparent)]
    Surfaces(#[from] SurfacesFileError),
    /// Creating a folder failed.
    #[error("{path}: {source}")]
    Io {
        /// The folder.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
}

impl crate::outcome::Classify for SimError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        match self {
            SimError::Invalid { .. } => Some(Outcome::Input),
            SimError::Acquisition(e) => e.outcome(),
            SimError::Npy(e) => e.outcome(),
            SimError::Station(e) => e.outcome(),
            SimError::Image(e) => e.outcome(),
            SimError::Surfaces(e) => e.outcome(),
            SimError::Io { source, .. } => crate::outcome::io_outcome(source),
        }
    }
}

/// Figures of a finished simulation.
#[derive(Debug, Clone, PartialEq)]
pub struct SimulationReport {
    /// Frames written.
    pub frames: usize,
    /// Camera pixels that see the element.
    pub lit_pixels: usize,
    /// Pixels with a front (S1) / back (S2) / third (S3) path.
    pub paths: [usize; 3],
    /// Counts per unit radiance used.
    pub gain: f64,
    /// Seconds spent tracing.
    pub trace_s: f64,
    /// Mean seconds to render one frame (noise included, I/O excluded).
    pub render_s_per_frame: f64,
}

/// One simulated acquisition to write.
#[derive(Debug, Clone)]
pub struct Simulation<'a> {
    /// The station.
    pub station: &'a Station,
    /// The element with its true surfaces.
    pub plate: &'a Plate,
    /// The same surfaces as written to `truth/truth_surfaces.json`.
    pub truth: &'a SurfacesFile,
    /// Patterns in capture order.
    pub patterns: &'a [Pattern],
    /// Camera settings.
    pub params: SimParams,
    /// NPY stack or PNG files.
    pub layout: FrameLayout,
    /// Whether an existing acquisition in `out` may be replaced.
    pub overwrite: bool,
}

/// Renders the simulation's patterns into the acquisition folder `out`
/// (spec layout, `station.toml` copied beside it), and writes the truth into
/// `out/truth/`: `truth_surfaces.json`, `truth_screen_coords.npy`,
/// `fresnel_weights.npy`, `path_status.npy`.
///
/// # Errors
/// [`SimError`] for bad parameters or when a file cannot be written; frames
/// already written stay on disk.
pub fn simulate(sim: &Simulation, out: &Path) -> Result<SimulationReport, SimError> {
    sim.params.validate()?;
    let t0 = Instant::now();
    let view = TracedView::trace(sim.station, sim.plate);
    let trace_s = t0.elapsed().as_secs_f64();
    let mut camera = Renderer::new(&view, &sim.station.screen, sim.params.clone())?;
    let bit_depth = camera.params().bit_depth as u8;
    let render_s = write_frames(sim, out, &view, bit_depth, &mut |p, k, f| {
        camera.render(p, k, f)
    })?;
    Ok(SimulationReport {
        frames: sim.patterns.len(),
        lit_pixels: camera.lit_pixels(),
        paths: [view.count(0), view.count(1), view.count(2)],
        gain: camera.gain(),
        trace_s,
        render_s_per_frame: render_s / sim.patterns.len().max(1) as f64,
    })
}

/// [`simulate`] for a mirror (the element's front reflection alone) on a
/// display that is not linearised, rendered by [`PhaseShiftRenderer`] with
/// `phase` (its camera settings replace `sim.params`).
///
/// # Errors
/// As [`simulate`].
pub fn simulate_mirror(
    sim: &Simulation,
    phase: PhaseShiftParams,
    out: &Path,
) -> Result<SimulationReport, SimError> {
    let t0 = Instant::now();
    let view = TracedView::trace(sim.station, sim.plate);
    let trace_s = t0.elapsed().as_secs_f64();
    let bit_depth = phase.bit_depth as u8;
    let camera = PhaseShiftRenderer::new(&view, &sim.station.screen, phase)?;
    let render_s = write_frames(sim, out, &view, bit_depth, &mut |p, k, f| {
        camera.render(p, k, f)
    })?;
    Ok(SimulationReport {
        frames: sim.patterns.len(),
        lit_pixels: view.count(0),
        paths: [view.count(0), 0, 0],
        gain: camera.gain(),
        trace_s,
        render_s_per_frame: render_s / sim.patterns.len().max(1) as f64,
    })
}

/// Writes the acquisition folder (station copy, truth, every frame that
/// `render(pattern, index, frame)` makes); returns the seconds spent rendering.
fn write_frames(
    sim: &Simulation,
    out: &Path,
    view: &TracedView,
    bit_depth: u8,
    render: &mut dyn FnMut(&Pattern, u64, &mut [u16]),
) -> Result<f64, SimError> {
    let (w, h) = (view.width, view.height);
    let frames: Vec<FrameInfo> = FrameInfo::from_patterns(sim.patterns);
    let mut writer = AcquisitionWriter::create(
        out,
        "station.toml",
        sim.layout,
        &frames,
        w as u32,
        h as u32,
        sim.overwrite,
    )?;
    sim.station.save(&out.join("station.toml"))?;
    write_truth(out, view, sim.truth)?;
    let mut frame = vec![0u16; w * h];
    let mut render_s = 0.0;
    for (index, pattern) in sim.patterns.iter().enumerate() {
        let t = Instant::now();
        render(pattern, index as u64, &mut frame);
        render_s += t.elapsed().as_secs_f64();
        let image = FrameImage {
            width: w as u32,
            height: h as u32,
            bit_depth,
            data: &frame,
        };
        writer.write_frame(index, &image)?;
    }
    writer.finish()?;
    Ok(render_s)
}

fn write_truth(out: &Path, view: &TracedView, truth: &SurfacesFile) -> Result<(), SimError> {
    let dir = out.join("truth");
    std::fs::create_dir_all(&dir).map_err(|source| SimError::Io {
        path: dir.clone(),
        source,
    })?;
    let (h, w) = (view.height, view.width);
    truth.save(&dir.join("truth_surfaces.json"))?;
    npy::write_f64(
        &dir.join("truth_screen_coords.npy"),
        &[h, w, 2, 2],
        &view.screen_coords(),
    )?;
    npy::write_f64(
        &dir.join("fresnel_weights.npy"),
        &[h, w, 3],
        &view.weights(),
    )?;
    npy::write_u8(&dir.join("path_status.npy"), &[h, w, 3], &view.status())?;
    Ok(())
}

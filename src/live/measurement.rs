//! A whole live measurement as one object: a configured camera and a
//! display, the recorder (new or resumed), the streaming spectral solver fed
//! with what a resumed acquisition already holds, and the sequencer run
//! between them. `mfd measure` builds one from its arguments; a server or a
//! calibration step can build one the same way.

use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use super::SolverSink;
use super::{
    acquire_observed, Counters, FrameSink, LiveError, LiveTap, Recorder, Report, SequencerConfig,
    Session,
};
use crate::acquire::acquisition::{Acquisition, AcquisitionError, FrameInfo};
use crate::acquire::camera::{Camera, CameraConfig, CameraError, TriggerMode};
use crate::acquire::display::PatternDisplay;
use crate::acquire::patterns::Pattern;
use crate::optics::station::Station;
use crate::solve::spectral::{SpectralConfig, SpectralError, SpectralSolver};

/// Errors of setting up or running a measurement.
#[derive(Debug, thiserror::Error)]
pub enum MeasurementError {
    /// The camera refused its configuration.
    #[error(transparent)]
    Camera(#[from] CameraError),
    /// The camera's frames do not have the station's size.
    #[error(
        "camera {camera} delivers {width}x{height} frames, the station says \
         {expected_width}x{expected_height}: fix the station's [camera] resolution or the \
         camera's region"
    )]
    Resolution {
        /// The camera's id.
        camera: String,
        /// Columns it delivers.
        width: u32,
        /// Rows it delivers.
        height: u32,
        /// Columns the station says.
        expected_width: u32,
        /// Rows the station says.
        expected_height: u32,
    },
    /// Creating, resuming or reading the acquisition failed.
    #[error(transparent)]
    Acquisition(#[from] AcquisitionError),
    /// The streaming solver could not be set up or fed.
    #[error(transparent)]
    Spectral(#[from] SpectralError),
    /// The run stopped on an error; `recorded` frames are on disk.
    #[error(
        "{source}; {recorded} of {total} frames are recorded in {dir} (continue with --resume)"
    )]
    Run {
        /// What stopped it (boxed: it is large, and rare).
        #[source]
        source: Box<LiveError>,
        /// Frames recorded.
        recorded: usize,
        /// Frames of the schedule.
        total: usize,
        /// The acquisition folder.
        dir: String,
    },
}

/// How the acquisition folder is begun.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Start {
    /// A new acquisition; `overwrite` replaces an existing one.
    New {
        /// Replace an acquisition already in the folder.
        overwrite: bool,
    },
    /// Continue an interrupted acquisition in the folder.
    Resume,
}

/// A measurement ready to run.
pub struct Measurement<'a> {
    camera: Box<dyn Camera>,
    display: Box<dyn PatternDisplay + 'a>,
    patterns: Vec<Pattern>,
    trigger: TriggerMode,
    resolution: (u32, u32),
    recorder: Recorder,
    solver: Option<SpectralSolver>,
    config: SequencerConfig,
    tap: Option<Arc<dyn LiveTap>>,
}

impl<'a> Measurement<'a> {
    /// Configures `camera` with `camera_config` (the trigger chosen from
    /// what it supports), checks its frame size against the station, starts
    /// or resumes the acquisition in `dir`, and (with `solver`) sets up the
    /// streaming spectral solver and feeds it the frames already recorded.
    ///
    /// # Errors
    /// [`MeasurementError`] naming what refused.
    #[allow(clippy::too_many_arguments)]
    pub fn prepare(
        station: &Station,
        patterns: Vec<Pattern>,
        mut camera: Box<dyn Camera>,
        display: Box<dyn PatternDisplay + 'a>,
        camera_config: CameraConfig,
        dir: &Path,
        start: Start,
        solver: Option<SpectralConfig>,
        config: SequencerConfig,
    ) -> Result<Self, MeasurementError> {
        let info = camera.describe();
        let trigger = if info.software_trigger {
            TriggerMode::Software
        } else {
            TriggerMode::FreeRunning
        };
        camera.configure(&CameraConfig {
            trigger,
            ..camera_config
        })?;
        let (width, height) = camera.describe().resolution;
        let resolution = (station.camera.width, station.camera.height);
        if (width, height) != resolution {
            return Err(MeasurementError::Resolution {
                camera: info.id,
                width,
                height,
                expected_width: resolution.0,
                expected_height: resolution.1,
            });
        }
        let recorder = match start {
            Start::Resume => Recorder::resume(dir, &patterns)?,
            Start::New { overwrite } => Recorder::create(dir, station, &patterns, overwrite)?,
        };
        let solver = solver
            .map(|c| start_solver(station, &patterns, dir, recorder.recorded(), c))
            .transpose()?;
        Ok(Measurement {
            camera,
            display,
            patterns,
            trigger,
            resolution,
            recorder,
            solver,
            config,
            tap: None,
        })
    }

    /// Lets `tap` observe the runs (the operator's console); it never
    /// slows the sequencer (see [`LiveTap`]).
    pub fn set_tap(&mut self, tap: Arc<dyn LiveTap>) {
        self.tap = Some(tap);
    }

    /// The schedule.
    pub fn patterns(&self) -> &[Pattern] {
        &self.patterns
    }

    /// Frames on disk so far.
    pub fn recorded(&self) -> usize {
        self.recorder.recorded()
    }

    /// The acquisition folder.
    pub fn dir(&self) -> &Path {
        self.recorder.dir()
    }

    /// The camera (for its stream statistics).
    pub fn camera(&self) -> &dyn Camera {
        self.camera.as_ref()
    }

    /// The streaming solver, once the run is over: every frame is in.
    pub fn solver_mut(&mut self) -> Option<&mut SpectralSolver> {
        self.solver.as_mut()
    }

    /// Starts the camera, runs the sequencer from the first frame not yet
    /// recorded to the end of the schedule (or until `stop` is set), and
    /// stops the camera. `progress` sees the counters after each frame.
    ///
    /// # Errors
    /// [`MeasurementError::Run`] with what stopped it and how many frames
    /// are recorded; [`MeasurementError::Camera`] when it does not start.
    pub fn run(
        &mut self,
        stop: &AtomicBool,
        progress: &mut dyn FnMut(&Counters),
    ) -> Result<Report, MeasurementError> {
        self.camera.start()?;
        let session = Session {
            camera: self.camera.as_mut(),
            display: self.display.as_mut(),
            patterns: &self.patterns,
            first: self.recorder.recorded(),
            trigger: self.trigger,
            resolution: self.resolution,
            config: self.config.clone(),
            stop,
        };
        let mut solver_sink = self.solver.as_mut().map(|solver| SolverSink { solver });
        let mut sinks: Vec<&mut dyn FrameSink> = vec![&mut self.recorder];
        if let Some(s) = solver_sink.as_mut() {
            sinks.push(s);
        }
        let result = acquire_observed(session, &mut sinks, progress, self.tap.as_deref());
        if let Err(e) = self.camera.stop() {
            log::warn!("stopping the camera: {e}");
        }
        result.map_err(|source| MeasurementError::Run {
            source: Box::new(source),
            recorded: self.recorder.recorded(),
            total: self.patterns.len(),
            dir: self.recorder.dir().display().to_string(),
        })
    }
}

/// The spectral solver for the whole schedule, fed with the frames a
/// resumed acquisition already holds.
fn start_solver(
    station: &Station,
    patterns: &[Pattern],
    dir: &Path,
    recorded: usize,
    config: SpectralConfig,
) -> Result<SpectralSolver, MeasurementError> {
    let frames = FrameInfo::from_patterns(patterns);
    let mut solver = SpectralSolver::new(station, &frames, config)?;
    if recorded > 0 {
        let acq = Acquisition::open(dir)?;
        let mut frame = Vec::new();
        for index in 0..recorded {
            acq.read_frame(index, &mut frame)?;
            solver.push_frame(index, &frame)?;
        }
    }
    Ok(solver)
}

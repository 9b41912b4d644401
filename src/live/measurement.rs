//! A whole live measurement as one object: a configured camera and a
//! display, the recorder (new or resumed), the streaming spectral solver fed
//! with what a resumed acquisition already holds, and the sequencer run
//! between them. `mfd measure` builds one from its arguments; a server or a
//! calibration step can build one the same way.

use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use super::{
    acquire_observed, Counters, FrameSink, LiveError, LiveTap, Recorder, Report, SequencerConfig,
    Session,
};
use super::{Mismatch, RecordingSetup, SolverSink};
use crate::acquire::acquisition::{Acquisition, AcquisitionError, FrameInfo};
use crate::acquire::camera::{Camera, CameraConfig, CameraError, TriggerMode};
use crate::acquire::display::PatternDisplay;
use crate::acquire::patterns::Pattern;
use crate::optics::station::Station;
use crate::solve::spectral::{FeedError, SpectralConfig, SpectralError, SpectralSolver};

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
    /// `--resume` was given other settings than the acquisition was begun
    /// with: nothing is appended.
    #[error(
        "{dir}: cannot resume: it was begun with other settings ({}); nothing was \
         appended. Start anew: in a new --out folder, or without --resume (with \
         --overwrite to replace this one)",
        mismatches.iter().map(|m| format!("{}: held {}, given {}", m.what, m.held, m.given))
            .collect::<Vec<_>>().join("; ")
    )]
    ResumeMismatch {
        /// The acquisition folder.
        dir: String,
        /// Every setting that differs.
        mismatches: Vec<Mismatch>,
    },
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

impl crate::outcome::Classify for MeasurementError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        match self {
            MeasurementError::ResumeMismatch { .. } | MeasurementError::Resolution { .. } => {
                Some(Outcome::Input)
            }
            // Transparent: the inner error is not in the source chain.
            MeasurementError::Camera(e) => e.outcome(),
            MeasurementError::Acquisition(e) => e.outcome(),
            MeasurementError::Spectral(e) => e.outcome(),
            MeasurementError::Run { source, .. } => source.outcome(),
        }
    }
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

/// What a measurement records, and where: [`Measurement::prepare_checked`]'s
/// inputs besides the devices.
#[derive(Debug, Clone)]
pub struct Prepared<'s> {
    /// The station.
    pub station: &'s Station,
    /// SHA-256 (hex) of the station file's bytes.
    pub station_sha256: &'s str,
    /// The schedule, in display order.
    pub patterns: Vec<Pattern>,
    /// The camera's settings.
    pub camera_config: CameraConfig,
    /// The acquisition folder.
    pub dir: &'s Path,
    /// New or resumed.
    pub start: Start,
}

/// Refuses to resume the acquisition in `dir` with a setup other than the
/// one it was begun with. One begun before `recording.toml` existed is
/// resumed with a warning (only its recorded patterns are checked then).
fn check_resume(dir: &Path, given: &RecordingSetup) -> Result<(), MeasurementError> {
    let Some(held) = RecordingSetup::read(dir)? else {
        log::warn!(
            "{}: no {}: only the recorded frames' patterns can be checked on resume",
            dir.display(),
            super::RECORDING_FILE
        );
        return Ok(());
    };
    let mismatches = held.mismatches(given);
    if mismatches.is_empty() {
        return Ok(());
    }
    Err(MeasurementError::ResumeMismatch {
        dir: dir.display().to_string(),
        mismatches,
    })
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
    /// [`Measurement::prepare_checked`] for a station known only as
    /// loaded: its digest is that of its canonical text (the copy the
    /// acquisition holds).
    ///
    /// # Errors
    /// As [`Measurement::prepare_checked`].
    #[allow(clippy::too_many_arguments)]
    pub fn prepare(
        station: &Station,
        patterns: Vec<Pattern>,
        camera: Box<dyn Camera>,
        display: Box<dyn PatternDisplay + 'a>,
        camera_config: CameraConfig,
        dir: &Path,
        start: Start,
        solver: Option<SpectralConfig>,
        config: SequencerConfig,
    ) -> Result<Self, MeasurementError> {
        let digest = super::sha256_hex(station.to_toml_string().as_bytes());
        let prepared = Prepared {
            station,
            station_sha256: &digest,
            patterns,
            camera_config,
            dir,
            start,
        };
        Self::prepare_checked(prepared, camera, display, solver, config)
    }

    /// Configures `camera` with the camera settings (the trigger chosen
    /// from what it supports), checks its frame size against the station,
    /// starts or resumes the acquisition in `dir`, and (with `solver`) sets
    /// up the streaming spectral solver and feeds it the frames already
    /// recorded. A new acquisition keeps its setup (schedule, station
    /// digest, camera and settings) in `recording.toml`; a resumed one must
    /// match it in every setting.
    ///
    /// # Errors
    /// [`MeasurementError::ResumeMismatch`] naming every setting that
    /// differs on resume; [`MeasurementError`] naming what refused.
    pub fn prepare_checked(
        prepared: Prepared<'_>,
        mut camera: Box<dyn Camera>,
        display: Box<dyn PatternDisplay + 'a>,
        solver: Option<SpectralConfig>,
        config: SequencerConfig,
    ) -> Result<Self, MeasurementError> {
        let Prepared {
            station,
            station_sha256,
            patterns,
            camera_config,
            dir,
            start,
        } = prepared;
        let info = camera.describe();
        let setup = RecordingSetup::new(station_sha256, &info, &camera_config, &patterns);
        if start == Start::Resume {
            check_resume(dir, &setup)?;
        }
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
            Start::New { overwrite } => {
                let recorder = Recorder::create(dir, station, &patterns, overwrite)?;
                setup.write(dir)?;
                recorder
            }
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
        solver
            .push_acquisition(&acq, recorded, &mut |_, _| {})
            .map_err(FeedError::into_cause::<MeasurementError>)?;
    }
    Ok(solver)
}

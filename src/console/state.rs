//! What the console shows, shared between the measuring threads (which
//! write it) and the server (which reads it): the latest accepted frame, the
//! status (progress, the pattern shown, the stage, the spectral stage's
//! state) and the result folders.
//!
//! Both live values sit in `tokio::sync::watch` channels: a write replaces
//! the value and wakes the waiting server tasks, never waiting on them (a
//! reader holds the value only to clone an `Arc` or a small struct).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

use serde::{Deserialize, Serialize};
use tokio::sync::watch;

use crate::acquire::patterns::Pattern;
use crate::live::{Counters, LiveTap, SharedFrame};

/// What the process serving the console is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// `mfd measure`: a live measurement.
    Measure,
    /// A calibration session's capture step.
    Calibrate,
    /// `mfd serve`: finished results only.
    Results,
}

/// The progress of an acquisition, from the sequencer's [`Counters`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Progress {
    /// Frames of the schedule recorded (earlier runs included).
    pub done: usize,
    /// Frames in the schedule.
    pub total: usize,
    /// Frames taken in this run.
    pub captured: usize,
    /// Schedule index this run began at (a resumed run's first frame).
    pub first: usize,
    /// Accepted frames per second of this run.
    pub frames_per_s: f64,
    /// Seconds since this run's first pattern was shown.
    pub elapsed_s: f64,
    /// Seconds left at this run's rate; `None` before the first frame.
    pub time_left_s: Option<f64>,
    /// Times the sequencer waited on a full consumer buffer.
    pub waits: u64,
    /// Seconds spent in those waits.
    pub wait_s: f64,
    /// Patterns shown again after a failed attempt.
    pub reshoots: u64,
    /// Attempts that got no usable frame (timeouts and incomplete frames).
    pub drops: u64,
    /// Attempts that timed out.
    pub timeouts: u64,
    /// Frames delivered incomplete.
    pub incomplete: u64,
    /// Frames rejected by the association check.
    pub mismatches: u64,
    /// Gaps in the device's frame counter.
    pub lost_frames: u64,
    /// Free-running frames exposed before the settle point, skipped.
    pub stale: u64,
}

impl From<&Counters> for Progress {
    fn from(c: &Counters) -> Self {
        let done = c.first + c.captured;
        let rate = c.frames_per_s();
        Progress {
            done,
            total: c.total,
            captured: c.captured,
            first: c.first,
            frames_per_s: rate,
            elapsed_s: c.elapsed_s,
            time_left_s: (rate > 0.0).then(|| c.total.saturating_sub(done) as f64 / rate),
            waits: c.backpressure_waits,
            wait_s: c.backpressure_s,
            reshoots: c.reshoots,
            drops: c.timeouts + c.incomplete,
            timeouts: c.timeouts,
            incomplete: c.incomplete,
            mismatches: c.mismatches,
            lost_frames: c.lost_frames,
            stale: c.stale,
        }
    }
}

/// The pattern on the screen.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Showing {
    /// Schedule index.
    pub index: usize,
    /// Fringe direction, degrees.
    pub direction_deg: f64,
    /// Fringe periods across the screen (the spec's τ).
    pub tau: f64,
    /// Phase offset, radians.
    pub phase_rad: f64,
}

/// Where the run stands.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(tag = "state", rename_all = "snake_case")]
pub enum Stage {
    /// Nothing running yet (or `mfd serve`).
    #[default]
    Idle,
    /// Patterns shown and frames taken.
    Acquiring,
    /// The acquisition is complete; the stages after it run.
    Reconstructing,
    /// Everything is written.
    Done,
    /// Stopped before the end (Ctrl-C or the console's stop); the frames so
    /// far are recorded and the run resumable.
    Stopped,
    /// The run ended on an error.
    Failed {
        /// The error, as the terminal shows it.
        error: String,
    },
}

/// The spectral stage's state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(tag = "state", rename_all = "snake_case")]
pub enum Spectral {
    /// Not part of this run.
    #[default]
    Off,
    /// Frames stream into the solver as they are accepted.
    Streaming {
        /// Frames it holds.
        frames_in: usize,
        /// Frames of the schedule.
        frames_total: usize,
    },
    /// The per-pixel fits run.
    Fitting {
        /// Pixels fitted.
        pixels_done: usize,
        /// Pixels to fit.
        pixels_total: usize,
    },
    /// The maps exist.
    Done {
        /// Pixels where both reflections were found.
        both_found: usize,
        /// Pixels fitted.
        pixels: usize,
    },
}

/// Everything the page shows besides the frame, pushed on every change.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Status {
    /// What this process does.
    pub mode: Mode,
    /// The screen's size in pixels `[width, height]`, for drawing the pattern.
    pub screen_px: Option<[u32; 2]>,
    /// The acquisition's progress, once it has begun.
    pub progress: Option<Progress>,
    /// The pattern last put on the screen.
    pub showing: Option<Showing>,
    /// The run's stage.
    pub stage: Stage,
    /// The spectral stage's state.
    pub spectral: Spectral,
    /// Whether a stop was asked for (Ctrl-C or the console).
    pub stop_requested: bool,
    /// Whether this console can stop anything.
    pub can_stop: bool,
    /// Bumped whenever a result folder gains files (the page reloads them).
    pub results_version: u64,
}

/// A result folder the console serves.
#[derive(Debug, Clone, PartialEq)]
pub struct ResultDir {
    /// The name in the console's addresses (unique).
    pub name: String,
    /// The folder.
    pub path: PathBuf,
}

/// The console's shared state: cheap to clone, one per process.
#[derive(Clone)]
pub struct Console {
    inner: Arc<Shared>,
}

struct Shared {
    frame: watch::Sender<Option<Arc<SharedFrame>>>,
    status: watch::Sender<Status>,
    stop: Option<Arc<AtomicBool>>,
    results: Mutex<Vec<ResultDir>>,
}

impl Console {
    /// A console for a live run in `mode`; `stop` is the flag Ctrl-C sets
    /// (the console's stop sets the same one); `screen_px` the screen's size.
    pub fn live(mode: Mode, stop: Arc<AtomicBool>, screen_px: Option<[u32; 2]>) -> Self {
        Self::with(mode, Some(stop), screen_px)
    }

    /// A console that only serves finished result folders.
    pub fn results_only() -> Self {
        Self::with(Mode::Results, None, None)
    }

    fn with(mode: Mode, stop: Option<Arc<AtomicBool>>, screen_px: Option<[u32; 2]>) -> Self {
        let status = Status {
            mode,
            screen_px,
            progress: None,
            showing: None,
            stage: Stage::Idle,
            spectral: Spectral::Off,
            stop_requested: false,
            can_stop: stop.is_some(),
            results_version: 0,
        };
        Console {
            inner: Arc::new(Shared {
                frame: watch::Sender::new(None),
                status: watch::Sender::new(status),
                stop,
                results: Mutex::new(Vec::new()),
            }),
        }
    }

    /// The status now.
    pub fn status(&self) -> Status {
        self.inner.status.borrow().clone()
    }

    /// The latest accepted frame.
    pub fn latest_frame(&self) -> Option<Arc<SharedFrame>> {
        self.inner.frame.borrow().clone()
    }

    pub(crate) fn watch_status(&self) -> watch::Receiver<Status> {
        self.inner.status.subscribe()
    }

    pub(crate) fn watch_frame(&self) -> watch::Receiver<Option<Arc<SharedFrame>>> {
        self.inner.frame.subscribe()
    }

    /// Sets the run's stage.
    pub fn set_stage(&self, stage: Stage) {
        self.inner.status.send_modify(|s| s.stage = stage);
    }

    /// Sets the spectral stage's state.
    pub fn set_spectral(&self, spectral: Spectral) {
        self.inner.status.send_modify(|s| s.spectral = spectral);
    }

    /// Asks the run to stop after the current frame, as Ctrl-C does; false
    /// when this console has nothing to stop.
    pub fn request_stop(&self) -> bool {
        let Some(stop) = &self.inner.stop else {
            return false;
        };
        stop.store(true, Ordering::SeqCst);
        self.inner.status.send_modify(|s| s.stop_requested = true);
        true
    }

    /// Serves the folder `path` as result `name` (a second folder of the
    /// same name gets a numbered one); returns the name used.
    pub fn add_results(&self, name: &str, path: &Path) -> String {
        let mut dirs = lock(&self.inner.results);
        let clean: String = name
            .chars()
            .map(|c| match c {
                'a'..='z' | 'A'..='Z' | '0'..='9' | '-' | '_' | '.' => c,
                _ => '_',
            })
            .collect();
        let clean = if clean.trim_matches('.').is_empty() {
            "result".to_string()
        } else {
            clean
        };
        let mut unique = clean.clone();
        let mut k = 2;
        while dirs.iter().any(|d| d.name == unique) {
            unique = format!("{clean}-{k}");
            k += 1;
        }
        dirs.push(ResultDir {
            name: unique.clone(),
            path: path.to_path_buf(),
        });
        drop(dirs);
        self.results_changed();
        unique
    }

    /// Tells the page that files were written into the result folders.
    pub fn results_changed(&self) {
        self.inner.status.send_modify(|s| s.results_version += 1);
    }

    /// The result folders served.
    pub fn result_dirs(&self) -> Vec<ResultDir> {
        lock(&self.inner.results).clone()
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    // A panic elsewhere while holding the list leaves it usable.
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl LiveTap for Console {
    fn showing(&self, index: usize, pattern: &Pattern) {
        let showing = Showing {
            index,
            direction_deg: pattern.direction_deg,
            tau: pattern.tau,
            phase_rad: pattern.phase_rad,
        };
        self.inner.status.send_modify(|s| {
            s.showing = Some(showing);
            if s.stage == Stage::Idle {
                s.stage = Stage::Acquiring;
            }
        });
    }

    fn accepted(&self, frame: &Arc<SharedFrame>) {
        self.inner.frame.send_replace(Some(Arc::clone(frame)));
    }

    fn counters(&self, counters: &Counters) {
        let progress = Progress::from(counters);
        self.inner.status.send_modify(|s| {
            if let Spectral::Streaming { frames_in, .. } = &mut s.spectral {
                *frames_in = progress.done;
            }
            s.progress = Some(progress);
        });
    }
}

//! Live acquisition: the sequencer shows each pattern, takes a frame it can
//! prove was exposed while that pattern stood on the screen, and hands it
//! through bounded ring buffers to the consumers (the recorder and the
//! streaming spectral solver).
//!
//! ```text
//!  display ◄── show(i) ──┐
//!                        │ sequencer (this thread)
//!  camera  ── frame ────►│ verify: exposure ≥ settled, pattern i, counter
//!                        ├──► bounded channel ──► recorder thread (PNG + manifest)
//!                        └──► bounded channel ──► solver thread (push_frame)
//! ```
//!
//! Threads and crossbeam channels rather than tokio: the work is blocking
//! (driver calls, `sleep` to a settle point, disk, CPU-bound solving) and
//! there are three long-lived tasks, so an async runtime would add a
//! dependency and `spawn_blocking` everywhere without saving a thread.
//!
//! Backpressure is explicit: the sequencer never drops a frame; when a
//! consumer's buffer is full it waits, counts the wait and its duration in
//! [`Counters`], and shows nothing new meanwhile. Memory stays bounded by
//! `capacity` frames per consumer.

pub mod camera;
mod measurement;
mod recorder;
mod sequencer;
mod setup;
mod sinks;
mod tap;

use std::time::Duration;

pub use measurement::{Measurement, MeasurementError, Prepared, Start};
pub use recorder::Recorder;
pub use sequencer::{acquire, acquire_observed, Session};
pub use setup::{sha256_hex, Mismatch, RecordingSetup, RECORDING_FILE, RECORDING_FORMAT};
pub use sinks::{FrameSink, SinkError, SolverSink};
pub use tap::{LiveTap, SharedFrame};

use crate::acquire::acquisition::AcquisitionError;
use crate::acquire::camera::CameraError;
use crate::acquire::display::DisplayError;

/// What can stop a live acquisition.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    /// The camera failed while taking frame `frame` (a disconnect ends the
    /// run; frames before `frame` are kept).
    #[error("frame {frame}: {source}")]
    Camera {
        /// Schedule index being shot.
        frame: usize,
        /// The camera error.
        #[source]
        source: CameraError,
    },
    /// The display failed while showing pattern `frame`.
    #[error("frame {frame}: {source}")]
    Display {
        /// Schedule index being shown.
        frame: usize,
        /// The display error.
        #[source]
        source: DisplayError,
    },
    /// No verified frame after the allowed re-shoots.
    #[error(
        "frame {frame}: no usable frame after {attempts} attempts (last: {last}); \
         check the camera's trigger and the display's settle time"
    )]
    Reshoots {
        /// Schedule index.
        frame: usize,
        /// Attempts made.
        attempts: u32,
        /// Why the last attempt was rejected.
        last: String,
    },
    /// A frame has another size than the acquisition's.
    #[error("frame {frame}: {width}x{height} pixels, expected {expected_width}x{expected_height}")]
    FrameSize {
        /// Schedule index.
        frame: usize,
        /// Columns received.
        width: u32,
        /// Rows received.
        height: u32,
        /// Columns expected.
        expected_width: u32,
        /// Rows expected.
        expected_height: u32,
    },
    /// A consumer failed; it stopped taking frames at `frame`.
    #[error("{sink}: frame {frame}: {source}")]
    Sink {
        /// Which consumer.
        sink: &'static str,
        /// The frame it failed on.
        frame: usize,
        /// Its error.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// A consumer took every frame but failed to finish (flush, sync).
    #[error("{sink}: finishing after the last frame: {source}")]
    SinkFinish {
        /// Which consumer.
        sink: &'static str,
        /// Its error.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// The recorder could not prepare or resume the acquisition folder.
    #[error(transparent)]
    Acquisition(#[from] AcquisitionError),
    /// A consumer thread panicked.
    #[error("{sink}: the consumer thread panicked")]
    Panicked {
        /// Which consumer.
        sink: &'static str,
    },
}

impl crate::outcome::Classify for LiveError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        match self {
            LiveError::Reshoots { .. } | LiveError::FrameSize { .. } => Some(Outcome::Device),
            LiveError::Camera { source, .. } => source.outcome(),
            LiveError::Display { source, .. } => source.outcome(),
            LiveError::Acquisition(e) => e.outcome(),
            // A consumer's error is in the chain (downcast by the binary).
            LiveError::Sink { .. } | LiveError::SinkFinish { .. } | LiveError::Panicked { .. } => {
                None
            }
        }
    }
}

/// Settings of the sequencer.
#[derive(Debug, Clone, PartialEq)]
pub struct SequencerConfig {
    /// Longest wait for one frame after the settle point (exposure, readout,
    /// transfer and the camera's latency).
    pub frame_timeout: Duration,
    /// Re-shoots allowed per pattern before giving up.
    pub max_reshoots: u32,
    /// Frames each consumer's ring buffer holds.
    pub capacity: usize,
}

impl Default for SequencerConfig {
    fn default() -> Self {
        SequencerConfig {
            frame_timeout: Duration::from_secs(2),
            max_reshoots: 5,
            capacity: 16,
        }
    }
}

/// Running counts of one acquisition.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Counters {
    /// Patterns in the schedule.
    pub total: usize,
    /// Index of the first pattern shot in this run (resume point).
    pub first: usize,
    /// Frames accepted and handed to the consumers in this run.
    pub captured: usize,
    /// Patterns shown again after a failed attempt.
    pub reshoots: u64,
    /// Attempts that got no usable frame in time (a frame dropped on the
    /// way, or an incomplete one).
    pub timeouts: u64,
    /// Frames the driver delivered incomplete (missing packets), discarded.
    pub incomplete: u64,
    /// Frames rejected by the association check (exposed before the
    /// settle point, or the device reports another pattern).
    pub mismatches: u64,
    /// Gaps in the device's frame counter (frames lost in the device,
    /// transport or driver).
    pub lost_frames: u64,
    /// Free-running frames exposed before the settle point, skipped.
    pub stale: u64,
    /// Times a consumer's buffer was full and the sequencer waited.
    pub backpressure_waits: u64,
    /// Seconds spent waiting on full buffers.
    pub backpressure_s: f64,
    /// Seconds since the first pattern was shown.
    pub elapsed_s: f64,
    /// Smallest and largest time from the settle point to the start of an
    /// accepted frame's exposure, s (the association margin; ≥ 0 by
    /// construction, the spread shows how long the loop waits for a frame).
    pub margin_s: Option<(f64, f64)>,
    /// Sum of those margins, s (for the mean).
    pub margin_sum_s: f64,
}

impl Counters {
    /// Mean time from the settle point to the exposure start, s.
    pub fn mean_margin_s(&self) -> Option<f64> {
        (self.captured > 0).then(|| self.margin_sum_s / self.captured as f64)
    }

    fn note_margin(&mut self, margin_s: f64) {
        self.margin_sum_s += margin_s;
        self.margin_s = Some(match self.margin_s {
            None => (margin_s, margin_s),
            Some((lo, hi)) => (lo.min(margin_s), hi.max(margin_s)),
        });
    }

    /// Accepted frames per second of wall time.
    pub fn frames_per_s(&self) -> f64 {
        if self.elapsed_s > 0.0 {
            self.captured as f64 / self.elapsed_s
        } else {
            0.0
        }
    }
}

/// How an acquisition ended.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// Final counts.
    pub counters: Counters,
    /// Whether it was stopped (Ctrl-C, display closed) before the end.
    pub interrupted: bool,
}

//! The sequencer: show → settle → shoot → verify → hand over, per pattern.
//!
//! A frame is accepted for pattern `i` only if
//! 1. its exposure started at or after [`Shown::settled`] of `i` (frame
//!    timestamps mark the start of the exposure; each backend says how it
//!    knows it);
//! 2. a device that knows what it saw ([`Frame::exposed_pattern`]) saw `i`;
//! 3. its frame counter moved forward (gaps are counted as lost frames).
//!
//! A timeout or a failed check shows the pattern again (a re-shoot,
//! counted); nothing is dropped silently.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use crossbeam_channel::{bounded, Receiver, SendTimeoutError, Sender, TrySendError};

use super::sinks::FrameSink;
use super::tap::{LiveTap, SharedFrame};
use super::{Counters, LiveError, Report, SequencerConfig};
use crate::acquire::camera::{Camera, CameraError, Frame, TriggerMode};
use crate::acquire::display::{DisplayError, PatternDisplay, Shown};
use crate::acquire::patterns::Pattern;

/// One acquisition to run.
pub struct Session<'a> {
    /// The camera, configured and started.
    pub camera: &'a mut dyn Camera,
    /// The display.
    pub display: &'a mut dyn PatternDisplay,
    /// The whole schedule, in capture order.
    pub patterns: &'a [Pattern],
    /// First schedule index to shoot (0, or where a resumed run left off).
    pub first: usize,
    /// How the camera was configured to start exposures.
    pub trigger: TriggerMode,
    /// Frame size every frame must have `(width, height)`.
    pub resolution: (u32, u32),
    /// Settings.
    pub config: SequencerConfig,
    /// Set (e.g. by a Ctrl-C handler) to stop after the current frame.
    pub stop: &'a AtomicBool,
}

type Tagged = SharedFrame;

type Consumer = (&'static str, Sender<Arc<Tagged>>);

/// Runs the session: shoots patterns `first..` and streams every accepted
/// frame, in schedule order, to each of `sinks` (each on its own thread
/// behind a bounded buffer). `progress` sees the counters after each frame
/// and while waiting on a full buffer.
///
/// # Errors
/// [`LiveError`] naming the frame. Frames handed over before the error
/// reach every consumer that is still working.
pub fn acquire(
    session: Session<'_>,
    sinks: &mut [&mut dyn FrameSink],
    progress: &mut dyn FnMut(&Counters),
) -> Result<Report, LiveError> {
    acquire_observed(session, sinks, progress, None)
}

/// [`acquire`] with a [`LiveTap`] that sees each pattern shown, each
/// accepted frame (after every consumer has it) and the counters whenever
/// `progress` does.
///
/// # Errors
/// As [`acquire`].
pub fn acquire_observed(
    session: Session<'_>,
    sinks: &mut [&mut dyn FrameSink],
    progress: &mut dyn FnMut(&Counters),
    tap: Option<&dyn LiveTap>,
) -> Result<Report, LiveError> {
    let capacity = session.config.capacity.max(1);
    std::thread::scope(|scope| {
        let mut consumers: Vec<Consumer> = Vec::new();
        let mut handles = Vec::new();
        for sink in sinks.iter_mut() {
            let (tx, rx) = bounded::<Arc<Tagged>>(capacity);
            let sink: &mut dyn FrameSink = &mut **sink;
            let name = sink.name();
            handles.push((name, scope.spawn(move || drain(sink, rx))));
            consumers.push((name, tx));
        }
        let mut shooter = Shooter::new(session, tap);
        let mut observed = |c: &Counters| {
            progress(c);
            if let Some(tap) = tap {
                tap.counters(c);
            }
        };
        let result = shooter.run(&consumers, &mut observed);
        if let (Some(tap), Ok(report)) = (tap, &result) {
            // The final counts (elapsed time after the last frame).
            tap.counters(&report.counters);
        }
        drop(consumers);
        let mut sink_error = None;
        for (sink, handle) in handles {
            let outcome = handle.join().unwrap_or(Err(LiveError::Panicked { sink }));
            if let Err(e) = outcome {
                sink_error.get_or_insert(e);
            }
        }
        match (result, sink_error) {
            (Err(e), _) => Err(e),
            (Ok(_), Some(e)) => Err(e),
            (Ok(report), None) => Ok(report),
        }
    })
}

fn drain(sink: &mut dyn FrameSink, rx: Receiver<Arc<Tagged>>) -> Result<(), LiveError> {
    let name = sink.name();
    for t in rx {
        sink.accept(t.index, &t.frame)
            .map_err(|source| LiveError::Sink {
                sink: name,
                frame: t.index,
                source,
            })?;
    }
    sink.finish()
        .map_err(|source| LiveError::SinkFinish { sink: name, source })
}

struct Shooter<'a, 't> {
    s: Session<'a>,
    tap: Option<&'t dyn LiveTap>,
    counters: Counters,
    last_sequence: Option<u64>,
    started: Instant,
}

impl<'a, 't> Shooter<'a, 't> {
    fn new(s: Session<'a>, tap: Option<&'t dyn LiveTap>) -> Self {
        let counters = Counters {
            total: s.patterns.len(),
            first: s.first,
            ..Counters::default()
        };
        Shooter {
            s,
            tap,
            counters,
            last_sequence: None,
            started: Instant::now(),
        }
    }

    fn run(
        &mut self,
        consumers: &[Consumer],
        progress: &mut dyn FnMut(&Counters),
    ) -> Result<Report, LiveError> {
        self.started = Instant::now();
        let mut interrupted = false;
        for index in self.s.first..self.s.patterns.len() {
            if self.s.stop.load(Ordering::SeqCst) {
                interrupted = true;
                break;
            }
            let frame = match self.capture(index) {
                Ok(f) => f,
                Err(LiveError::Display {
                    source: DisplayError::Closed,
                    ..
                }) => {
                    interrupted = true;
                    break;
                }
                Err(e) => return Err(e),
            };
            let pattern = self.s.patterns[index];
            let tagged = Arc::new(Tagged {
                index,
                pattern,
                frame,
            });
            if !self.hand_over(&tagged, consumers, progress) {
                // A consumer failed: its error is reported by `acquire`.
                break;
            }
            if let Some(tap) = self.tap {
                tap.accepted(&tagged);
            }
            self.counters.captured += 1;
            self.counters.elapsed_s = self.started.elapsed().as_secs_f64();
            progress(&self.counters);
        }
        self.counters.elapsed_s = self.started.elapsed().as_secs_f64();
        Ok(Report {
            counters: self.counters.clone(),
            interrupted,
        })
    }

    /// Shows pattern `index` until a verified frame of it is in hand.
    fn capture(&mut self, index: usize) -> Result<Frame, LiveError> {
        let pattern = self.s.patterns[index];
        let attempts = self.s.config.max_reshoots + 1;
        let mut last = String::new();
        for attempt in 0..attempts {
            if attempt > 0 {
                self.counters.reshoots += 1;
            }
            let shown =
                self.s
                    .display
                    .show(index, &pattern)
                    .map_err(|source| LiveError::Display {
                        frame: index,
                        source,
                    })?;
            if let Some(tap) = self.tap {
                tap.showing(index, &pattern);
            }
            // The exposure must start once the screen has settled.
            std::thread::sleep(shown.settled.saturating_duration_since(Instant::now()));
            match self.shoot(&shown) {
                Ok(frame) => match self.verify(&shown, &frame)? {
                    None => {
                        let margin = frame.timestamp.duration_since(shown.settled);
                        self.counters.note_margin(margin.as_secs_f64());
                        return Ok(frame);
                    }
                    Some(problem) => {
                        self.counters.mismatches += 1;
                        last = problem;
                    }
                },
                Err(RetryOr::Fatal(e)) => return Err(e),
                Err(RetryOr::Timeout) => {
                    self.counters.timeouts += 1;
                    last = format!(
                        "no frame within {} ms",
                        self.s.config.frame_timeout.as_millis()
                    );
                }
                Err(RetryOr::Incomplete) => last = "an incomplete frame".into(),
            }
        }
        Err(LiveError::Reshoots {
            frame: index,
            attempts,
            last,
        })
    }

    /// One attempt: a frame exposed after `shown.settled`, or why not.
    fn shoot(&mut self, shown: &Shown) -> Result<Frame, RetryOr> {
        let timeout = self.s.config.frame_timeout;
        match self.s.trigger {
            TriggerMode::Software => {
                // Frames still queued from an earlier attempt are stale.
                loop {
                    match self.poll(shown.index, Duration::ZERO)? {
                        Polled::Frame(f) => {
                            self.note_sequence(&f);
                            self.counters.stale += 1;
                        }
                        Polled::Incomplete => {}
                        Polled::Timeout => break,
                    }
                }
                self.s.camera.trigger().map_err(|source| {
                    RetryOr::Fatal(LiveError::Camera {
                        frame: shown.index,
                        source,
                    })
                })?;
                match self.poll(shown.index, timeout)? {
                    Polled::Frame(f) => Ok(f),
                    Polled::Incomplete => Err(RetryOr::Incomplete),
                    Polled::Timeout => Err(RetryOr::Timeout),
                }
            }
            TriggerMode::FreeRunning => {
                // Skip frames exposed before the settle point, and
                // incomplete ones, until the deadline.
                let deadline = Instant::now() + timeout;
                loop {
                    let left = deadline.saturating_duration_since(Instant::now());
                    match self.poll(shown.index, left)? {
                        Polled::Frame(f) if f.timestamp >= shown.settled => return Ok(f),
                        Polled::Frame(f) => {
                            self.note_sequence(&f);
                            self.counters.stale += 1;
                        }
                        Polled::Incomplete if !left.is_zero() => {}
                        Polled::Incomplete => return Err(RetryOr::Incomplete),
                        Polled::Timeout => return Err(RetryOr::Timeout),
                    }
                }
            }
        }
    }

    /// The next frame; incomplete frames are counted; camera errors other
    /// than a timeout or an incomplete frame end the run.
    fn poll(&mut self, index: usize, timeout: Duration) -> Result<Polled, RetryOr> {
        match self.s.camera.next_frame(timeout) {
            Ok(f) => Ok(Polled::Frame(f)),
            Err(CameraError::Timeout { .. }) => Ok(Polled::Timeout),
            Err(CameraError::BadFrame { .. }) => {
                self.counters.incomplete += 1;
                Ok(Polled::Incomplete)
            }
            Err(source) => Err(RetryOr::Fatal(LiveError::Camera {
                frame: index,
                source,
            })),
        }
    }

    /// Counts a gap in the device counter; false if it went backwards.
    fn note_sequence(&mut self, frame: &Frame) -> bool {
        let forward = match self.last_sequence {
            Some(prev) if frame.sequence <= prev => false,
            Some(prev) => {
                self.counters.lost_frames += frame.sequence - prev - 1;
                true
            }
            None => true,
        };
        if forward {
            self.last_sequence = Some(frame.sequence);
        }
        forward
    }

    /// `None` if `frame` belongs to `shown`, else why not.
    fn verify(&mut self, shown: &Shown, frame: &Frame) -> Result<Option<String>, LiveError> {
        let (w, h) = self.s.resolution;
        if (frame.width, frame.height) != (w, h) || frame.data.len() != (w * h) as usize {
            return Err(LiveError::FrameSize {
                frame: shown.index,
                width: frame.width,
                height: frame.height,
                expected_width: w,
                expected_height: h,
            });
        }
        if !self.note_sequence(frame) {
            return Ok(Some(format!(
                "frame counter went back to {} (last {:?})",
                frame.sequence, self.last_sequence
            )));
        }
        if frame.timestamp < shown.settled {
            let early = shown.settled.duration_since(frame.timestamp);
            return Ok(Some(format!(
                "exposure started {:.1} ms before the pattern settled",
                early.as_secs_f64() * 1e3
            )));
        }
        match frame.exposed_pattern {
            Some(seen) if seen != shown.index => Ok(Some(format!(
                "the device recorded pattern {seen}, not {}",
                shown.index
            ))),
            _ => Ok(None),
        }
    }

    /// Sends `tagged` to every consumer, waiting (and counting the wait)
    /// when a buffer is full. False when a consumer has stopped.
    fn hand_over(
        &mut self,
        tagged: &Arc<Tagged>,
        consumers: &[Consumer],
        progress: &mut dyn FnMut(&Counters),
    ) -> bool {
        for (_, tx) in consumers {
            let mut item = match tx.try_send(Arc::clone(tagged)) {
                Ok(()) => continue,
                Err(TrySendError::Disconnected(_)) => return false,
                Err(TrySendError::Full(item)) => item,
            };
            self.counters.backpressure_waits += 1;
            let t0 = Instant::now();
            loop {
                match tx.send_timeout(item, Duration::from_millis(100)) {
                    Ok(()) => break,
                    Err(SendTimeoutError::Disconnected(_)) => return false,
                    Err(SendTimeoutError::Timeout(back)) => {
                        item = back;
                        self.counters.elapsed_s = self.started.elapsed().as_secs_f64();
                        progress(&self.counters);
                    }
                }
            }
            self.counters.backpressure_s += t0.elapsed().as_secs_f64();
        }
        true
    }
}

/// A failed attempt: retry (after a timeout or an incomplete frame), or
/// stop the run.
enum RetryOr {
    Timeout,
    Incomplete,
    Fatal(LiveError),
}

/// What one wait for a frame gave.
enum Polled {
    Frame(Frame),
    Timeout,
    Incomplete,
}

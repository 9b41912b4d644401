//! The simulated camera: the optical core's renderer ([`Renderer`])
//! looking at whatever a shared [`ScreenState`] says the screen shows, so
//! the whole live loop runs without hardware, with faults injected on
//! demand ([`SimFaults`]).
//!
//! An exposure starting at `t` records the pattern on the screen at `t`
//! (the screen model is [`ScreenState`]'s), and says so in
//! [`Frame::exposed_pattern`].
//!
//! Triggered mode renders at [`Camera::trigger`]; free-running mode exposes
//! at `t0 + k · period` and renders when [`Camera::next_frame`] reaches
//! frame `k`, keeping at most `buffers` frames queued like a driver's pool.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

use super::render::Renderer;
use super::screen::{ScreenState, BLANK};
use crate::acquire::camera::{
    Camera, CameraConfig, CameraError, CameraInfo, Frame, PixelFormat, TriggerMode,
};

/// Faults the simulated camera injects.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SimFaults {
    /// Delay between the start of an exposure and the frame's delivery.
    pub latency: Duration,
    /// Every k-th exposure (device counter 1-based) is lost.
    pub drop_every: Option<u64>,
    /// Each exposure is lost with this probability (seeded by `seed`).
    pub drop_probability: f64,
    /// Seed of the random drops.
    pub seed: u64,
    /// Every k-th triggered exposure starts 1 ms before the latest pattern
    /// settled, so it records the previous pattern (a mis-association).
    pub early_every: Option<u64>,
    /// The camera disconnects once this many frames were delivered.
    pub disconnect_after: Option<u64>,
}

struct Pending {
    ready_at: Instant,
    frame: Frame,
}

/// The simulated camera of a simulated station.
pub struct SimulatedCamera {
    renderer: Renderer,
    screen: ScreenState,
    faults: SimFaults,
    mode: TriggerMode,
    period: Duration,
    buffers: usize,
    streaming: bool,
    /// Exposures so far (the device counter).
    exposures: u64,
    delivered: u64,
    pending: VecDeque<Pending>,
    rng: Xoshiro256PlusPlus,
    /// Free running: time of exposure 0 and the next exposure to deliver.
    t0: Instant,
    next_k: u64,
}

impl std::fmt::Debug for SimulatedCamera {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimulatedCamera")
            .field("faults", &self.faults)
            .field("mode", &self.mode)
            .field("exposures", &self.exposures)
            .field("delivered", &self.delivered)
            .finish_non_exhaustive()
    }
}

impl SimulatedCamera {
    /// The simulated station's camera for a plate with surfaces `front` and
    /// `back` (traced with the default rim margin): it renders with
    /// `params` whatever `screen` shows, with `faults` injected.
    ///
    /// # Errors
    /// [`super::SimError`] when the renderer refuses `params`.
    pub fn of_plate(
        station: &crate::optics::station::Station,
        front: crate::optics::zernike::ZernikeSurface,
        back: crate::optics::zernike::ZernikeSurface,
        params: super::SimParams,
        screen: ScreenState,
        faults: SimFaults,
    ) -> Result<Self, super::SimError> {
        use crate::optics::trace::{Plate, TracedView, DEFAULT_EDGE_MARGIN_MM};
        let plate = Plate::new(station, front, back, DEFAULT_EDGE_MARGIN_MM);
        let view = TracedView::trace(station, &plate);
        let renderer = Renderer::new(&view, &station.screen, params)?;
        Ok(SimulatedCamera::new(renderer, screen, faults))
    }

    /// A camera rendering with `renderer` whatever `screen` shows.
    pub fn new(renderer: Renderer, screen: ScreenState, faults: SimFaults) -> Self {
        let rng = Xoshiro256PlusPlus::seed_from_u64(faults.seed);
        SimulatedCamera {
            renderer,
            screen,
            faults,
            mode: TriggerMode::Software,
            period: Duration::from_millis(10),
            buffers: 8,
            streaming: false,
            exposures: 0,
            delivered: 0,
            pending: VecDeque::new(),
            rng,
            t0: Instant::now(),
            next_k: 0,
        }
    }

    /// The screen this camera looks at.
    pub fn screen(&self) -> &ScreenState {
        &self.screen
    }

    /// Exposures started so far (delivered or lost).
    pub fn exposures(&self) -> u64 {
        self.exposures
    }

    /// Renders the screen as it was at `t` into a new frame.
    pub fn render_at(&mut self, t: Instant, sequence: u64) -> Frame {
        let (w, h) = self.renderer.resolution();
        let mut data = vec![0u16; w * h];
        let seen = self.screen.at(t);
        let pattern = seen.map_or(BLANK, |(_, p)| p);
        self.renderer.render(&pattern, sequence, &mut data);
        Frame {
            data,
            width: w as u32,
            height: h as u32,
            bit_depth: self.renderer.params().bit_depth as u8,
            timestamp: t,
            sequence,
            exposed_pattern: seen.map(|(i, _)| i),
        }
    }

    /// Whether exposure `sequence` (1-based) is lost.
    fn lost(&mut self, sequence: u64) -> bool {
        let every = self.faults.drop_every.is_some_and(|k| sequence % k == 0);
        let p = self.faults.drop_probability;
        let random = p > 0.0 && self.rng.random::<f64>() < p;
        every || random
    }

    fn check_connected(&self) -> Result<(), CameraError> {
        match self.faults.disconnect_after {
            Some(n) if self.delivered >= n => Err(CameraError::Disconnected {
                device: "sim".into(),
                problem: format!("injected fault: disconnected after {n} frames"),
            }),
            _ => Ok(()),
        }
    }

    fn not_streaming() -> CameraError {
        CameraError::Device {
            device: "sim".into(),
            problem: "not streaming: call start() first".into(),
        }
    }

    /// Waits up to `timeout` for `ready_at`; false if it lies beyond.
    fn wait_until(ready_at: Instant, timeout: Duration) -> bool {
        let now = Instant::now();
        if ready_at > now + timeout {
            std::thread::sleep(timeout);
            return false;
        }
        std::thread::sleep(ready_at.saturating_duration_since(now));
        true
    }

    fn next_triggered(&mut self, timeout: Duration) -> Result<Frame, CameraError> {
        let timed_out = CameraError::Timeout {
            device: "sim".into(),
            waited: timeout,
        };
        let Some(front) = self.pending.front() else {
            std::thread::sleep(timeout);
            return Err(timed_out);
        };
        if !Self::wait_until(front.ready_at, timeout) {
            return Err(timed_out);
        }
        let p = self.pending.pop_front().expect("front exists");
        Ok(p.frame)
    }

    fn next_free_running(&mut self, timeout: Duration) -> Result<Frame, CameraError> {
        let deadline = Instant::now() + timeout;
        loop {
            // Frames older than the buffer pool were overwritten.
            let now = Instant::now();
            let span = self.period * self.buffers as u32;
            let oldest = now.checked_sub(span + self.faults.latency);
            while oldest.is_some_and(|o| self.exposure_time(self.next_k) < o) {
                self.next_k += 1;
            }
            let k = self.next_k;
            let t = self.exposure_time(k);
            let wait = deadline.saturating_duration_since(Instant::now());
            if !Self::wait_until(t + self.faults.latency, wait) {
                return Err(CameraError::Timeout {
                    device: "sim".into(),
                    waited: timeout,
                });
            }
            self.next_k += 1;
            self.exposures = self.exposures.max(k + 1);
            if !self.lost(k + 1) {
                return Ok(self.render_at(t, k));
            }
        }
    }

    fn exposure_time(&self, k: u64) -> Instant {
        self.t0 + self.period * k as u32
    }
}

impl Camera for SimulatedCamera {
    fn describe(&self) -> CameraInfo {
        let (w, h) = self.renderer.resolution();
        CameraInfo {
            backend: "sim",
            id: "sim".into(),
            model: "mfd simulated camera".into(),
            sensor: (w as u32, h as u32),
            resolution: (w as u32, h as u32),
            pixel_formats: PixelFormat::from_bit_depth(self.renderer.params().bit_depth)
                .into_iter()
                .collect(),
            software_trigger: true,
        }
    }

    fn configure(&mut self, config: &CameraConfig) -> Result<(), CameraError> {
        let bad = |field, problem: String| CameraError::Config {
            device: "sim".into(),
            field,
            problem,
        };
        let bits = self.renderer.params().bit_depth;
        if let Some(f) = config
            .pixel_format
            .filter(|f| u32::from(f.bit_depth()) != bits)
        {
            return Err(bad(
                "pixel_format",
                format!("{f:?} asked, the simulation renders {bits} bits (set by --bit-depth)"),
            ));
        }
        if config.gain_db.is_some() {
            return Err(bad(
                "gain_db",
                "the simulated camera's gain is set by the simulation".into(),
            ));
        }
        let (w, h) = self.renderer.resolution();
        if let Some(r) = config
            .region
            .filter(|r| (r.x, r.y, r.width as usize, r.height as usize) != (0, 0, w, h))
        {
            return Err(bad(
                "region",
                format!("{r:?}: the simulated camera delivers its whole {w}x{h} sensor"),
            ));
        }
        if let Some(hz) = config.frame_rate_hz {
            if !(hz.is_finite() && hz > 0.0 && hz <= 100_000.0) {
                return Err(bad(
                    "frame_rate_hz",
                    format!("expected (0, 1e5], found {hz}"),
                ));
            }
            self.period = Duration::from_secs_f64(1.0 / hz);
        }
        self.mode = config.trigger;
        self.buffers = config.buffers.max(1);
        Ok(())
    }

    fn start(&mut self) -> Result<(), CameraError> {
        self.check_connected()?;
        self.streaming = true;
        self.pending.clear();
        self.t0 = Instant::now();
        self.next_k = self.exposures;
        self.t0 = self
            .t0
            .checked_sub(self.period * self.next_k as u32)
            .unwrap_or(self.t0);
        Ok(())
    }

    fn stop(&mut self) -> Result<(), CameraError> {
        self.streaming = false;
        self.pending.clear();
        Ok(())
    }

    fn next_frame(&mut self, timeout: Duration) -> Result<Frame, CameraError> {
        self.check_connected()?;
        if !self.streaming {
            return Err(Self::not_streaming());
        }
        let frame = match self.mode {
            TriggerMode::Software => self.next_triggered(timeout)?,
            TriggerMode::FreeRunning => self.next_free_running(timeout)?,
        };
        self.delivered += 1;
        Ok(frame)
    }

    fn trigger(&mut self) -> Result<(), CameraError> {
        self.check_connected()?;
        if !self.streaming || self.mode != TriggerMode::Software {
            return Err(CameraError::Device {
                device: "sim".into(),
                problem: "trigger() needs a started camera in software-trigger mode".into(),
            });
        }
        self.exposures += 1;
        let sequence = self.exposures;
        let mut t = Instant::now();
        if self.faults.early_every.is_some_and(|k| sequence % k == 0) {
            if let Some(latest) = self.screen.latest() {
                t = latest
                    .settled
                    .checked_sub(Duration::from_millis(1))
                    .unwrap_or(t);
            }
        }
        if self.lost(sequence) {
            return Ok(());
        }
        let frame = self.render_at(t, sequence);
        self.pending.push_back(Pending {
            ready_at: t.max(Instant::now()) + self.faults.latency,
            frame,
        });
        Ok(())
    }
}

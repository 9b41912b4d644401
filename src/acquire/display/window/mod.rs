//! The fullscreen fringe window (feature `display`): a borderless window
//! exactly covering one monitor, drawn by the same shader as the offscreen
//! renderer into a non-sRGB surface presented with `PresentMode::Fifo`.
//!
//! winit's event loop must own the main thread. [`run_fullscreen`] runs it
//! there and hands the caller's work, on its own thread, a [`WindowDisplay`]:
//! a `Send` handle implementing [`PatternDisplay`] that talks to the loop
//! through an `EventLoopProxy` and answers through a channel. winit allows
//! one event loop per process: call [`run_fullscreen`] or [`list_monitors`]
//! once.

mod app;
mod screen;

use std::sync::mpsc;
use std::thread;
use std::time::Duration;

use winit::event_loop::{EventLoop, EventLoopProxy};

use crate::acquire::patterns::Pattern;
use crate::optics::station::DisplayProfile;

use super::levels::{Dither, Shading};
use super::offscreen::settle_time;
use super::{DisplayError, PatternDisplay, Shown};
use app::{App, Command, MonitorLister};

/// What window to open.
#[derive(Debug, Clone, PartialEq)]
pub struct WindowConfig {
    /// Index of the monitor in [`list_monitors`]' order.
    pub monitor: usize,
    /// Intensity-to-level mapping.
    pub shading: Shading,
    /// Time from present until the panel shows the pattern.
    pub settle: Duration,
    /// The monitor must have this resolution `(width, height)` (the display
    /// profile's), or opening fails; `None` accepts any.
    pub expect_resolution: Option<(u32, u32)>,
}

impl WindowConfig {
    /// The window of a display profile on monitor `monitor`: its gamma,
    /// settle time, and resolution (required of the monitor).
    ///
    /// # Errors
    /// [`DisplayError::Invalid`] for a bad gamma or settle time.
    pub fn from_profile(
        profile: &DisplayProfile,
        monitor: usize,
        dither: Dither,
    ) -> Result<Self, DisplayError> {
        let [w, h] = profile.resolution;
        Ok(WindowConfig {
            monitor,
            shading: Shading::from_profile(profile, dither)?,
            settle: settle_time(profile)?,
            expect_resolution: Some((w, h)),
        })
    }
}

/// One monitor as the windowing system reports it.
#[derive(Debug, Clone, PartialEq)]
pub struct MonitorInfo {
    /// Index to pass as [`WindowConfig::monitor`].
    pub index: usize,
    /// Name, if the system gives one.
    pub name: Option<String>,
    /// Resolution `(width, height)`, physical pixels.
    pub size: (u32, u32),
    /// Top-left corner on the virtual desktop, physical pixels.
    pub position: (i32, i32),
    /// Refresh rate, millihertz, if known.
    pub refresh_mhz: Option<u32>,
}

impl std::fmt::Display for MonitorInfo {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let refresh = self.refresh_mhz.map_or("refresh unknown".to_string(), |m| {
            format!("{:.2} Hz", f64::from(m) / 1000.0)
        });
        write!(
            f,
            "{}: {} {}x{} at ({}, {}), {refresh}",
            self.index,
            self.name.as_deref().unwrap_or("(unnamed)"),
            self.size.0,
            self.size.1,
            self.position.0,
            self.position.1,
        )
    }
}

fn event_loop<T: 'static>() -> Result<EventLoop<T>, DisplayError> {
    EventLoop::<T>::with_user_event()
        .build()
        .map_err(|e| DisplayError::Unavailable {
            display: "window".into(),
            problem: format!(
                "no windowing system ({e}); run under X11 or Wayland (DISPLAY or \
                 WAYLAND_DISPLAY set; for tests `Xvfb :N`), from the main thread"
            ),
        })
}

/// The monitors, in the order [`WindowConfig::monitor`] indexes them.
/// Runs (and ends) this process's one winit event loop.
///
/// # Errors
/// [`DisplayError::Unavailable`] without a windowing system.
pub fn list_monitors() -> Result<Vec<MonitorInfo>, DisplayError> {
    let event_loop = event_loop::<()>()?;
    let mut lister = MonitorLister::default();
    event_loop
        .run_app(&mut lister)
        .map_err(|e| DisplayError::Unavailable {
            display: "window".into(),
            problem: format!("event loop: {e}"),
        })?;
    Ok(lister.monitors)
}

/// Opens the fullscreen window of `config` and runs the event loop on the
/// calling (main) thread while `work` runs on a thread of its own with the
/// window's [`WindowDisplay`]. Returns `work`'s result once it has returned
/// (the window then closes). If the window is closed first (a key, the close
/// button), `work`'s further calls to `show` return [`DisplayError::Closed`].
///
/// # Errors
/// [`DisplayError::Unavailable`] when no window, surface or adapter can be
/// had, or the window does not exactly cover the monitor.
///
/// # Panics
/// A panic in `work` is raised again on the calling thread.
pub fn run_fullscreen<R, F>(config: WindowConfig, work: F) -> Result<R, DisplayError>
where
    R: Send + 'static,
    F: FnOnce(&mut WindowDisplay) -> R + Send + 'static,
{
    let event_loop = event_loop::<Command>()?;
    let proxy = event_loop.create_proxy();
    let (ready_tx, ready_rx) = mpsc::channel();
    let mut app = App::new(config, ready_tx, event_loop.owned_display_handle());
    let worker = thread::Builder::new()
        .name("mfd patterns".into())
        .spawn(move || {
            let out = match ready_rx.recv() {
                Ok(Ok(resolution)) => {
                    let mut display = WindowDisplay {
                        proxy: proxy.clone(),
                        resolution,
                    };
                    Ok(work(&mut display))
                }
                Ok(Err(e)) => Err(e),
                Err(_) => Err(DisplayError::Closed),
            };
            // The loop may already be gone (window closed): nothing to stop.
            let _ = proxy.send_event(Command::Quit);
            out
        })
        .map_err(|e| DisplayError::Unavailable {
            display: "window".into(),
            problem: format!("cannot start the pattern thread: {e}"),
        })?;
    let ran = event_loop.run_app(&mut app);
    // Dropping the app drops any channel the worker may still wait on.
    drop(app);
    // A panic in `work` is the caller's: raise it again here.
    let out = worker
        .join()
        .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
    ran.map_err(|e| DisplayError::Unavailable {
        display: "window".into(),
        problem: format!("event loop: {e}"),
    })?;
    out
}

/// The `Send` handle of the fringe window, given to [`run_fullscreen`]'s
/// work. `show` returns after `queue.present`: `presented` is taken then and
/// `settled = presented + settle` (the settle time must cover the scan-out
/// delay of the panel, up to one refresh period, as well as the LCD response).
pub struct WindowDisplay {
    proxy: EventLoopProxy<Command>,
    resolution: (u32, u32),
}

impl WindowDisplay {
    /// Blocks until a key is pressed in the window (which then closes).
    ///
    /// # Errors
    /// [`DisplayError::Closed`] if the window closed without a key press.
    pub fn wait_key(&mut self) -> Result<(), DisplayError> {
        let (reply, answer) = mpsc::channel();
        self.proxy
            .send_event(Command::WaitKey { reply })
            .map_err(|_| DisplayError::Closed)?;
        answer.recv().map_err(|_| DisplayError::Closed)
    }
}

impl PatternDisplay for WindowDisplay {
    fn resolution(&self) -> (u32, u32) {
        self.resolution
    }

    fn show(&mut self, index: usize, pattern: &Pattern) -> Result<Shown, DisplayError> {
        let (reply, answer) = mpsc::channel();
        self.proxy
            .send_event(Command::Show {
                index,
                pattern: *pattern,
                reply,
            })
            .map_err(|_| DisplayError::Closed)?;
        answer.recv().map_err(|_| DisplayError::Closed)?
    }
}

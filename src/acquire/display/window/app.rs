//! The winit side of the fringe window: the application handler that owns
//! the [`Screen`] and answers the [`WindowDisplay`](super::WindowDisplay)'s
//! commands.

use std::sync::mpsc;
use std::time::{Duration, Instant};

use winit::application::ApplicationHandler;
use winit::event::{ElementState, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, OwnedDisplayHandle};
use winit::window::WindowId;

use crate::acquire::display::{DisplayError, Shown};
use crate::acquire::patterns::Pattern;

use super::screen::Screen;
use super::{MonitorInfo, WindowConfig};

/// What the handle asks of the event loop.
pub(crate) enum Command {
    /// Draw and present a pattern; answer with when.
    Show {
        index: usize,
        pattern: Pattern,
        reply: mpsc::Sender<Result<Shown, DisplayError>>,
    },
    /// Answer once a key is pressed.
    WaitKey { reply: mpsc::Sender<()> },
    /// The work is done: close the window and end the loop.
    Quit,
}

/// The answer to "is the window up": its resolution, or why not.
pub(crate) type Ready = Result<(u32, u32), DisplayError>;

/// How long the window may take to be sized to the monitor (a window
/// manager applies fullscreen asynchronously).
const FIT_TIMEOUT: Duration = Duration::from_secs(3);

/// Runs the fringe window.
pub(crate) struct App {
    config: WindowConfig,
    ready: Option<mpsc::Sender<Ready>>,
    display_handle: OwnedDisplayHandle,
    screen: Option<Screen>,
    key_waiters: Vec<mpsc::Sender<()>>,
    last: Option<(usize, Pattern)>,
    /// Until when the window may still be resized to fit the monitor
    /// before it is reported ready.
    fit_deadline: Option<Instant>,
}

impl App {
    pub(crate) fn new(
        config: WindowConfig,
        ready: mpsc::Sender<Ready>,
        display_handle: OwnedDisplayHandle,
    ) -> Self {
        App {
            config,
            ready: Some(ready),
            display_handle,
            screen: None,
            key_waiters: Vec::new(),
            last: None,
            fit_deadline: None,
        }
    }

    fn tell_ready(&mut self, ready: Ready) {
        if let Some(tx) = self.ready.take() {
            // A worker that is gone has nothing left to start.
            let _ = tx.send(ready);
        }
    }
}

impl ApplicationHandler<Command> for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.screen.is_some() {
            return;
        }
        match Screen::open(event_loop, &self.config, self.display_handle.clone()) {
            Ok(screen) => {
                self.screen = Some(screen);
                let deadline = Instant::now() + FIT_TIMEOUT;
                self.fit_deadline = Some(deadline);
                event_loop.set_control_flow(ControlFlow::WaitUntil(deadline));
                self.check_fit(event_loop);
            }
            Err(e) => {
                self.tell_ready(Err(e));
                event_loop.exit();
            }
        }
    }

    fn user_event(&mut self, event_loop: &ActiveEventLoop, command: Command) {
        match command {
            Command::Show {
                index,
                pattern,
                reply,
            } => {
                let shown = match self.screen.as_mut() {
                    Some(screen) => screen.show(index, &pattern),
                    None => Err(DisplayError::Closed),
                };
                if shown.is_ok() {
                    self.last = Some((index, pattern));
                }
                // A caller that stopped waiting needs no answer.
                let _ = reply.send(shown);
            }
            Command::WaitKey { reply } => self.key_waiters.push(reply),
            Command::Quit => event_loop.exit(),
        }
    }

    fn about_to_wait(&mut self, event_loop: &ActiveEventLoop) {
        self.check_fit(event_loop);
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::KeyboardInput {
                event,
                is_synthetic: false,
                ..
            } if event.state == ElementState::Pressed => {
                for waiter in self.key_waiters.drain(..) {
                    // Each waiter learns of the key; one that left is fine.
                    let _ = waiter.send(());
                }
                event_loop.exit();
            }
            WindowEvent::Resized(size) => {
                if let Some(screen) = self.screen.as_mut() {
                    screen.resize(size.width, size.height);
                }
                self.check_fit(event_loop);
            }
            WindowEvent::RedrawRequested => self.redraw(),
            _ => {}
        }
    }
}

impl App {
    /// Reports the window ready once it covers the monitor, or fails when
    /// it still does not at the deadline.
    fn check_fit(&mut self, event_loop: &ActiveEventLoop) {
        let (Some(deadline), Some(screen)) = (self.fit_deadline, self.screen.as_ref()) else {
            return;
        };
        match screen.misfit() {
            None => {
                let size = screen.size();
                self.fit_deadline = None;
                event_loop.set_control_flow(ControlFlow::Wait);
                self.tell_ready(Ok(size));
            }
            Some(problem) if Instant::now() >= deadline => {
                self.fit_deadline = None;
                self.tell_ready(Err(DisplayError::Unavailable {
                    display: format!("monitor {}", self.config.monitor),
                    problem: format!("after {FIT_TIMEOUT:?}: {problem}"),
                }));
                event_loop.exit();
            }
            Some(_) => {}
        }
    }

    /// Draws the last pattern again (the window was exposed or resized).
    fn redraw(&mut self) {
        if let (Some(screen), Some((index, pattern))) = (self.screen.as_mut(), self.last) {
            if let Err(e) = screen.show(index, &pattern) {
                log::error!("mfd display: redrawing pattern {index}: {e}");
            }
        }
    }
}

/// Collects the monitors and ends the loop.
#[derive(Default)]
pub(crate) struct MonitorLister {
    pub(crate) monitors: Vec<MonitorInfo>,
}

impl ApplicationHandler for MonitorLister {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        self.monitors = event_loop
            .available_monitors()
            .enumerate()
            .map(|(index, m)| MonitorInfo {
                index,
                name: m.name(),
                size: (m.size().width, m.size().height),
                position: (m.position().x, m.position().y),
                refresh_mhz: m.refresh_rate_millihertz(),
            })
            .collect();
        event_loop.exit();
    }

    fn window_event(&mut self, _: &ActiveEventLoop, _: WindowId, _: WindowEvent) {}
}

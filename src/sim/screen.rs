//! What the simulated screen shows: the shared [`ScreenState`] that
//! simulated cameras look at, and the displays that feed it.
//!
//! The screen model: a pattern is on the screen from its
//! [`Shown::settled`] on; before that the screen still shows the previous
//! one (the LCD's response is modelled as a clean switch at the settle
//! point), and black before the first.
//!
//! [`SimDisplay`] is a CPU-only stand-in for a screen: it draws nothing
//! (the simulated camera models the screen analytically from the pattern)
//! and reports a presentation time and a settle point like a real display.
//! It serves tests and `mfd measure --display offscreen` until the wgpu
//! offscreen renderer takes that place.
//!
//! [`MirroredDisplay`] wraps any display and publishes every shown pattern
//! to a [`ScreenState`], which is what simulated cameras look at.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::acquire::display::{DisplayError, PatternDisplay, Shown};
use crate::acquire::patterns::Pattern;

/// Patterns remembered by [`ScreenState`] (free-running frames may lag).
const HISTORY: usize = 16;

/// What the screen shows, shared between whoever shows patterns and the
/// simulated cameras that look at it. Cheap to clone (one `Arc`).
#[derive(Debug, Clone, Default)]
pub struct ScreenState {
    shown: Arc<Mutex<VecDeque<Shown>>>,
}

/// Black: `0.5 + 0.5 cos(π) = 0` everywhere.
pub(super) const BLANK: Pattern = Pattern {
    direction_deg: 0.0,
    tau: 0.0,
    phase_rad: std::f64::consts::PI,
};

impl ScreenState {
    /// A blank screen.
    pub fn new() -> Self {
        Self::default()
    }

    /// Records that `shown` is going up on the screen.
    pub fn publish(&self, shown: Shown) {
        let mut s = self.shown.lock().unwrap_or_else(|p| p.into_inner());
        if s.len() == HISTORY {
            s.pop_front();
        }
        s.push_back(shown);
    }

    /// The pattern on the screen at `t` and its schedule index; `None`
    /// while the screen is still blank.
    pub fn at(&self, t: Instant) -> Option<(usize, Pattern)> {
        let s = self.shown.lock().unwrap_or_else(|p| p.into_inner());
        s.iter()
            .rev()
            .find(|sh| sh.settled <= t)
            .map(|sh| (sh.index, sh.pattern))
    }

    /// The latest pattern published, settled or not.
    pub fn latest(&self) -> Option<Shown> {
        let s = self.shown.lock().unwrap_or_else(|p| p.into_inner());
        s.back().copied()
    }
}

/// A screen that shows patterns instantly and settles after a fixed time.
#[derive(Debug, Clone)]
pub struct SimDisplay {
    resolution: (u32, u32),
    settle: Duration,
}

impl SimDisplay {
    /// A `width × height` screen whose patterns settle `settle` after they
    /// are presented (an LCD's response time).
    pub fn new(resolution: (u32, u32), settle: Duration) -> Self {
        SimDisplay { resolution, settle }
    }
}

impl PatternDisplay for SimDisplay {
    fn resolution(&self) -> (u32, u32) {
        self.resolution
    }

    fn show(&mut self, index: usize, pattern: &Pattern) -> Result<Shown, DisplayError> {
        let presented = Instant::now();
        Ok(Shown {
            index,
            pattern: *pattern,
            presented,
            settled: presented + self.settle,
        })
    }
}

/// A display that also tells a [`ScreenState`] what it shows.
pub struct MirroredDisplay<'a> {
    inner: Box<dyn PatternDisplay + 'a>,
    screen: ScreenState,
}

impl<'a> MirroredDisplay<'a> {
    /// Wraps `inner`, publishing to `screen`.
    pub fn new(inner: Box<dyn PatternDisplay + 'a>, screen: ScreenState) -> Self {
        MirroredDisplay { inner, screen }
    }
}

impl PatternDisplay for MirroredDisplay<'_> {
    fn resolution(&self) -> (u32, u32) {
        self.inner.resolution()
    }

    fn show(&mut self, index: usize, pattern: &Pattern) -> Result<Shown, DisplayError> {
        let shown = self.inner.show(index, pattern)?;
        self.screen.publish(shown);
        Ok(shown)
    }
}

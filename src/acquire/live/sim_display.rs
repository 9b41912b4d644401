//! Displays for a simulated station.
//!
//! [`SimDisplay`] is a CPU-only stand-in for a screen: it draws nothing
//! (the simulated camera models the screen analytically from the pattern)
//! and reports a presentation time and a settle point like a real display.
//! It serves tests and `mfd measure --display offscreen` until the wgpu
//! offscreen renderer takes that place.
//!
//! [`MirroredDisplay`] wraps any display and publishes every shown pattern
//! to a [`ScreenState`], which is what simulated cameras look at.

use std::time::{Duration, Instant};

use crate::acquire::camera::ScreenState;
use crate::acquire::display::{DisplayError, PatternDisplay, Shown};
use crate::acquire::patterns::Pattern;

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

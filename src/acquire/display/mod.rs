//! The fringe display: what puts a [`Pattern`] on the screen and says when
//! it was really there.
//!
//! The sequencer (live acquisition) owns one [`PatternDisplay`] and calls
//! [`PatternDisplay::show`] for each pattern of the schedule; a frame counts
//! for that pattern only if it was exposed after [`Shown::settled`]. Backends:
//! the offscreen renderer (always built; what tests and the simulated station
//! use) and the fullscreen window (feature `display`).

use std::time::Instant;

use crate::acquire::patterns::Pattern;

pub mod levels;
pub mod offscreen;
mod render;
#[cfg(feature = "display")]
pub mod window;

pub use levels::{Dither, Shading};
pub use offscreen::OffscreenDisplay;
pub use render::DRIVER_HINT;

/// A pattern that is on the screen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shown {
    /// Index of the pattern in the schedule (the acquisition's frame index).
    pub index: usize,
    /// The pattern itself.
    pub pattern: Pattern,
    /// When the frame carrying it was presented (handed to the display).
    pub presented: Instant,
    /// `presented` plus the display profile's settle time: from here on the
    /// screen shows the pattern (LCD response over).
    pub settled: Instant,
}

/// Errors of a display backend.
#[derive(Debug, thiserror::Error)]
pub enum DisplayError {
    /// The backend was not compiled in.
    #[error("display backend `{backend}`: not built; rebuild with `--features {feature}`")]
    NotBuilt {
        /// The backend asked for.
        backend: String,
        /// The cargo feature that builds it.
        feature: &'static str,
    },
    /// No such monitor, or no adapter / surface could be created.
    #[error("display `{display}`: {problem}")]
    Unavailable {
        /// The monitor or backend name.
        display: String,
        /// What went wrong.
        problem: String,
    },
    /// Rendering or presenting one pattern failed.
    #[error("display: pattern {index}: {problem}")]
    Render {
        /// Schedule index of the pattern.
        index: usize,
        /// What went wrong.
        problem: String,
    },
    /// A display setting (profile value, size) is out of range.
    #[error("display: `{field}`: {problem}")]
    Invalid {
        /// The setting.
        field: &'static str,
        /// What is wrong.
        problem: String,
    },
    /// The display was closed (window closed, key pressed, Ctrl-C).
    #[error("display closed")]
    Closed,
}

impl crate::outcome::Classify for DisplayError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        Some(match self {
            DisplayError::NotBuilt { .. } => Outcome::Input,
            _ => Outcome::Device,
        })
    }
}

/// Something that shows fringe patterns. `Send`, so the sequencer can own it
/// on its own thread; a window backend whose event loop must stay on the main
/// thread implements this on a handle that talks to that loop.
pub trait PatternDisplay: Send {
    /// Screen size in pixels `(width, height)`, as rendered (no scaling).
    fn resolution(&self) -> (u32, u32);
    /// Show `pattern` (schedule index `index`) and return once it is
    /// presented; [`Shown::settled`] may lie in the future.
    fn show(&mut self, index: usize, pattern: &Pattern) -> Result<Shown, DisplayError>;
}

//! Acquiring frames: what the screen shows ([`patterns`]), the recorded
//! acquisition folder ([`acquisition`]: its manifest, reader and writer),
//! the cameras behind one narrow trait ([`camera`]), the fringe display
//! ([`display`]). The live sequencer that ties them to a recorder and the
//! streaming solver is [`crate::live`], above the solvers.

pub mod acquisition;
pub mod camera;
pub mod display;
pub mod patterns;
pub mod schedule_file;

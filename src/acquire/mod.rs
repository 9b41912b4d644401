//! Acquiring frames: what the screen shows ([`patterns`]), the recorded
//! acquisition folder ([`acquisition`]: its manifest, reader and writer),
//! the cameras behind one narrow trait ([`camera`]), the fringe display
//! ([`display`]), and the live sequencer that ties them to a recorder and
//! the streaming solver ([`live`]).

pub mod acquisition;
pub mod camera;
pub mod display;
pub mod live;
pub mod patterns;

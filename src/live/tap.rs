//! A tap on a live acquisition for observers that must never slow it (the
//! operator's console): the sequencer tells a [`LiveTap`] which pattern it
//! shows, hands it every accepted frame (the same shared allocation the
//! consumers get, no copy) and its counters.
//!
//! Unlike a [`FrameSink`](super::FrameSink) a tap has no buffer the
//! sequencer could wait on: an implementation keeps only the latest of each
//! and returns at once (a slot swap, a notification); an observer that falls
//! behind misses frames instead of holding one back.

use std::sync::Arc;

use super::Counters;
use crate::acquire::camera::Frame;
use crate::acquire::patterns::Pattern;

/// An accepted frame with the schedule entry it belongs to.
#[derive(Debug)]
pub struct SharedFrame {
    /// Schedule index.
    pub index: usize,
    /// The pattern that was on the screen during its exposure.
    pub pattern: Pattern,
    /// The frame, as the consumers receive it.
    pub frame: Frame,
}

/// An observer of the sequencer. Every method is called on the sequencer's
/// thread and must return without waiting on anything slower than a brief
/// lock (no I/O, no encoding, no channel that can be full).
pub trait LiveTap: Send + Sync {
    /// Pattern `index` has been put on the screen.
    fn showing(&self, index: usize, pattern: &Pattern);
    /// Frame `frame.index` was accepted and handed to every consumer.
    fn accepted(&self, frame: &Arc<SharedFrame>);
    /// The counters, whenever the sequencer reports progress.
    fn counters(&self, counters: &Counters);
}

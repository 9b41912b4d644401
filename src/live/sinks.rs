//! Consumers of accepted frames.

use crate::acquire::camera::Frame;
use crate::solve::spectral::SpectralSolver;

/// The error a consumer reports.
pub type SinkError = Box<dyn std::error::Error + Send + Sync>;

/// Something that takes every accepted frame, in schedule order, on its own
/// thread.
pub trait FrameSink: Send {
    /// Name for errors and reports.
    fn name(&self) -> &'static str;
    /// Takes frame `index` of the schedule.
    ///
    /// # Errors
    /// Whatever stops this consumer; the sequencer stops too.
    fn accept(&mut self, index: usize, frame: &Frame) -> Result<(), SinkError>;
    /// Called once the sequencer is done (normally or not).
    ///
    /// # Errors
    /// A failure to flush.
    fn finish(&mut self) -> Result<(), SinkError> {
        Ok(())
    }
}

/// Feeds the streaming spectral solver.
pub struct SolverSink<'a> {
    /// The solver, prepared for the whole schedule.
    pub solver: &'a mut SpectralSolver,
}

impl FrameSink for SolverSink<'_> {
    fn name(&self) -> &'static str {
        "spectral solver"
    }

    fn accept(&mut self, index: usize, frame: &Frame) -> Result<(), SinkError> {
        Ok(self.solver.push_frame(index, &frame.data)?)
    }
}

//! Frames fed into the spectral solver from where they are kept: a
//! recorded acquisition (the one loop that `pipeline::reconstruct`, the
//! calibration's reference flat and a resumed live measurement share), or
//! a source that makes them (a renderer: `mfd tradeoff`, the benches).

use crate::acquire::acquisition::{Acquisition, AcquisitionError};

use super::{SpectralError, SpectralSolver};

/// Why feeding an acquisition stopped: reading a frame, or the solver
/// refusing it. Callers report the two differently (a file at fault, or the
/// data).
#[derive(Debug, thiserror::Error)]
pub enum FeedError {
    /// A frame could not be read.
    #[error(transparent)]
    Read(#[from] AcquisitionError),
    /// The solver refused a frame.
    #[error(transparent)]
    Push(#[from] SpectralError),
}

impl crate::outcome::Classify for FeedError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        match self {
            FeedError::Read(e) => e.outcome(),
            FeedError::Push(e) => e.outcome(),
        }
    }
}

impl FeedError {
    /// The cause as the caller's own error, for an error type that holds
    /// both a reading and a solver failure.
    pub fn into_cause<E: From<AcquisitionError> + From<SpectralError>>(self) -> E {
        match self {
            FeedError::Read(e) => e.into(),
            FeedError::Push(e) => e.into(),
        }
    }
}

impl SpectralSolver {
    /// Reads the first `count` frames of `acq`, in its manifest's order, and
    /// pushes each under its own index; `progress(k, count)` after the k-th.
    /// Returns the largest count any of them holds (the saturation check's
    /// input).
    ///
    /// # Errors
    /// [`FeedError::Read`] for a frame that cannot be read,
    /// [`FeedError::Push`] for one the solver refuses; the frames before it
    /// stay pushed.
    pub fn push_acquisition(
        &mut self,
        acq: &Acquisition,
        count: usize,
        progress: &mut dyn FnMut(usize, usize),
    ) -> Result<u16, FeedError> {
        let count = count.min(acq.frames().len());
        let mut frame = Vec::new();
        let mut max_count = 0u16;
        for k in 0..count {
            let index = acq.frames()[k].index;
            acq.read_frame(index, &mut frame)?;
            max_count = frame.iter().copied().fold(max_count, u16::max);
            self.push_frame(index, &frame)?;
            progress(k + 1, count);
        }
        Ok(max_count)
    }

    /// Pushes the schedule's frames in its order, each written by
    /// `fill(k, frame)` into a buffer of the camera's pixel count and pushed
    /// under index `k`.
    ///
    /// # Errors
    /// [`SpectralError`] for a frame the solver refuses; the frames before
    /// it stay pushed.
    pub fn push_made(
        &mut self,
        mut fill: impl FnMut(usize, &mut [u16]),
    ) -> Result<(), SpectralError> {
        let mut frame = vec![0u16; self.width * self.height];
        for k in 0..self.frames() {
            fill(k, &mut frame);
            self.push_frame(k, &frame)?;
        }
        Ok(())
    }
}

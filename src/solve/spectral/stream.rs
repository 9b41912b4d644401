//! The solver's driver: frames arrive in capture order, the samples of the
//! pixels that can see the element are kept (pixel-major, 2 bytes each) or
//! reduced to their statistics, and every pixel is fitted on all cores
//! once its series is complete ([`SpectralSolver::solve`]).
//! Building the solver, the solve and a candidate's samples after it are
//! in `build`, `solve` and `samples`.

mod build;
mod samples;
mod solve;

use std::thread::JoinHandle;

use super::model::{Design, Falloff};
use super::periodogram::SpectrumPlans;
use super::phase::{PhaseSchedule, Response};
use super::pixel::PixelFits;
use super::prior::GeometryPrior;
use super::scene::no_data;
use super::statistics::{Statistics, FULL_SCALES, STATS_BLOCK};
use super::{PixelResult, SpectralConfig, SpectralError};
use crate::optics::trace::TracedView;

pub use build::design;

/// Frames buffered frame-major before they are transposed into the
/// pixel-major series (keeps the scatter cache-friendly).
const BLOCK: usize = 32;

/// The streaming spectral solver of one acquisition.
pub struct SpectralSolver {
    /// The camera's resolution, pixels (`feed` sizes frames by it).
    pub(super) width: usize,
    pub(super) height: usize,
    design: Design,
    plans: SpectrumPlans,
    prior: GeometryPrior,
    series: Vec<u16>,
    stats: Option<Box<Statistics>>,
    block: Vec<u16>,
    block_start: usize,
    /// The candidates as spans `(first, length)` of consecutive camera
    /// pixels (how a frame's samples are gathered into `block`).
    spans: Vec<(usize, usize)>,
    received: usize,
    max_seen: u16,
    config: SpectralConfig,
    /// A phase-shifting schedule's groups and the display's response: the
    /// one-reflection path of [`phase`](super::phase) instead of the periodogram's.
    phase: Option<(PhaseSchedule, Response)>,
    /// The solve's output arrays, allocated and written (their pages
    /// faulted in) on a thread of their own while the frames stream in,
    /// not after the last one; the first solve takes them.
    prepared: Option<JoinHandle<Prepared>>,
}

/// The solve's output arrays, blank: one [`PixelFits::none`] per candidate
/// and one no-data [`PixelResult`] per camera pixel.
struct Prepared {
    fits: Vec<PixelFits>,
    pixels: Vec<PixelResult>,
}

impl Prepared {
    fn new(candidates: usize, pixels: usize) -> Self {
        Prepared {
            fits: vec![PixelFits::none(); candidates],
            pixels: vec![no_data(); pixels],
        }
    }
}

impl SpectralSolver {
    /// Pixels that will be fitted.
    pub fn candidate_pixels(&self) -> usize {
        self.prior.candidates.len()
    }

    /// Frames expected.
    pub fn frames(&self) -> usize {
        self.design.frames.len()
    }

    /// Bytes held for the series (or, with the statistics engine, the statistics).
    pub fn series_bytes(&self) -> usize {
        self.series.len() * 2 + self.stats.as_ref().map_or(0, |s| s.bytes())
    }

    /// Whether the statistics engine is in use, with its node counts per
    /// direction (data, products).
    pub fn statistics_nodes(&self) -> Option<Vec<(usize, usize)>> {
        self.stats.as_ref().map(|s| s.tables().nodes())
    }

    /// Takes frame `index`, which must be the next in capture order.
    ///
    /// # Errors
    /// [`SpectralError::Frame`] for an out-of-order or wrongly sized frame.
    pub fn push_frame(&mut self, index: usize, frame: &[u16]) -> Result<(), SpectralError> {
        if index != self.received || index >= self.frames() {
            return Err(SpectralError::Frame {
                frame: index,
                problem: format!("expected frame {} of {}", self.received, self.frames()),
            });
        }
        if frame.len() != self.width * self.height {
            return Err(SpectralError::Frame {
                frame: index,
                problem: format!(
                    "{} pixels, expected {}x{}",
                    frame.len(),
                    self.width,
                    self.height
                ),
            });
        }
        // Gathered span by span of consecutive pixels (a copy each, not a
        // push per sample), and the frame's maximum taken in a separate
        // pass that vectorises: this runs on the caller's thread for every
        // frame (it was a quarter of the ingest's time on a full sensor).
        let start = self.block.len();
        for &(first, len) in &self.spans {
            self.block.extend_from_slice(&frame[first..first + len]);
        }
        let max = self.block[start..].iter().copied().max().unwrap_or(0);
        self.max_seen = self.max_seen.max(max);
        self.received += 1;
        let block = if self.stats.is_some() {
            STATS_BLOCK
        } else {
            BLOCK
        };
        if self.received - self.block_start == block || self.received == self.frames() {
            self.flush();
        }
        if self.received == self.frames() {
            if let Some(stats) = self.stats.as_mut() {
                stats.seal();
            }
            // The block buffer (32 frames of the candidates, 80 MB on a
            // full sensor) is not needed again: freed before the solve.
            self.block = Vec::new();
        }
        Ok(())
    }

    fn flush(&mut self) {
        if let Some(stats) = self.stats.as_mut() {
            stats.ingest(
                self.block_start,
                self.received - self.block_start,
                &self.block,
            );
            self.block.clear();
            self.block_start = self.received;
            return;
        }
        let n = self.frames();
        let c = self.prior.candidates.len();
        let rows = self.received - self.block_start;
        for q in 0..c {
            let dst = &mut self.series[q * n + self.block_start..q * n + self.received];
            for (r, d) in dst.iter_mut().enumerate().take(rows) {
                *d = self.block[r * c + q];
            }
        }
        self.block.clear();
        self.block_start = self.received;
    }

    fn saturation(&self) -> Option<u16> {
        self.config
            .saturation_counts
            .or_else(|| FULL_SCALES.into_iter().find(|&fs| fs == self.max_seen))
    }

    /// The phase-shifting schedule's groups and the display response, when
    /// the schedule is one ([`PhaseSchedule::detect`]).
    pub fn phase_schedule(&self) -> Option<(&PhaseSchedule, &Response)> {
        self.phase.as_ref().map(|(s, r)| (s, r))
    }

    /// The model's view of the schedule.
    pub fn design(&self) -> &Design {
        &self.design
    }

    /// The geometry prior (flat surfaces through the nominal station).
    pub fn prior(&self) -> &TracedView {
        &self.prior.view
    }

    /// Camera pixel index (row-major) of every candidate, in candidate order.
    pub fn candidates(&self) -> &[u32] {
        &self.prior.candidates
    }

    /// Whether candidate `q`'s back offset was borrowed from its neighbours
    /// at the rim (the flat plate's back path leaves through the edge there).
    pub fn borrowed(&self, q: usize) -> bool {
        self.prior.borrowed[q].is_some()
    }

    /// Starting κ = 1/τ_max² of the fits, in every falloff group.
    pub fn kappa_start(&self) -> Falloff {
        self.config.falloff_start(&self.design)
    }
}

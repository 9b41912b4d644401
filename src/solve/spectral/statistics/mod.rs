//! The pixels' series reduced, as frames arrive, to the sufficient
//! statistics of the per-pixel least squares, so that a full sensor never
//! has to be held as series (1296 × 966 × 2000 samples: 5 GB).
//!
//! The model of one direction (see [`super::model`]) is
//! `A + Σ_k B_k Re(α_k(τ) e^{iθ_i(μ_c)})` with `θ_i(μ) = 2π(μ τ_i + φ_i)`,
//! `α_k(τ) = e^{−κτ²} e^{2πi δ_k τ}`, `δ_k = μ_k − μ_c`: demodulated at a
//! centre `μ_c` near the pixel's two points, every column of the model and of
//! its Jacobian is `Re(α(τ) e^{iθ(μ_c)})` with `α` smooth in τ (a few cycles
//! over the schedule when `|δ|` is a few Fourier bins). The data enter the
//! normal equations only through `Σy`, `Σy²` and `Σ_i y_i α(τ_i) e^{iθ_i}`;
//! for `α` within a degree-(Q−1) polynomial in τ (to 1e-10 over the band
//! the pixel is allowed) that is `Σ_j α(τ_j) Z_j` over Q Chebyshev nodes
//! `τ_j`, with `Z_j = Σ_i y_i e^{iθ_i} L_j(τ_i)` (`L_j` the cardinal
//! polynomials of the nodes) — Q complex numbers per pixel and direction,
//! accumulated frame by frame. The products of two columns need, besides
//! the schedule's own `Σ_i L_j(τ_i)` (M) and `Σ_i e^{iθ_i} L_j(τ_i)` (E),
//! `Σ_i e^{2iθ_i} L_j(τ_i)` (D): `Re(a e^{iθ}) Re(b e^{iθ}) = ½Re(a b̄) +
//! ½Re(a b e^{2iθ})`. Centres are rounded to a grid of ¼ bin, so the
//! schedule sums are tables shared by every pixel of a grid point, and the
//! demodulation of a frame is one table per grid point, not one phase per
//! pixel. Excluded (clipped) samples are left out of the pixel's sums and
//! subtracted from its copy of the schedule sums.
//!
//! The least squares are then the series' own (same RSS, JᵀJ, Jᵀr to the
//! interpolation tolerance), at O(Q) instead of O(frames) per evaluation,
//! but only within the band: a point farther than the band from the
//! station's prediction is flagged [`super::PixelFlags::OUT_OF_BAND`], never
//! fitted with a wrong model.
//!
//! The parts: `nodes` (Chebyshev nodes and how many), `tables` (the
//! schedule's tables per direction), `ingest` (frames in, with the
//! clipping policy), `samples` (one pixel's statistics: normal equations
//! and linear fits), `sums` (the columns' inner products they are made
//! of), `scan` (periodogram peak and pair scan) and `simd` (the hot
//! loops' AVX2/FMA dispatch).

mod ingest;
mod nodes;
mod samples;
mod scan;
mod simd;
mod sums;
mod tables;
#[cfg(test)]
mod tests;

use rustfft::num_complex::Complex;

use crate::solve::spectral::model::Design;
use ingest::{SetAside, MAX_SET_ASIDE};

pub use samples::StatisticsSamples;
pub use simd::prefetch_lines;
pub use tables::StatisticsTables;

type C64 = Complex<f64>;

/// Grid of demodulation centres, in Fourier bins.
const GRID_BINS: f64 = 0.25;

/// Frames demodulated together (the pixel's sums stay in cache over a block).
pub const STATS_BLOCK: usize = 32;

/// Full scales of 8…16-bit cameras.
pub(crate) const FULL_SCALES: [u16; 5] = [255, 1023, 4095, 16383, 65535];

/// Why the statistics cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StatisticsError {
    /// The band (with κ down to the range's largest) is too wide to be
    /// interpolated to the node tolerance by 256 nodes.
    #[error(
        "direction {direction}: a band of ±{band_bins:.1} Fourier bins with τ_max down to \
         {tau_max_min:.0} needs more than 256 nodes; use a smaller band or the series engine"
    )]
    BandTooWide {
        /// Index of the fringe direction.
        direction: usize,
        /// Half-width of the band the nodes must hold (the configured band,
        /// the predicted spread and half a grid step), Fourier bins.
        band_bins: f64,
        /// Smallest τ_max of the κ range.
        tau_max_min: f64,
    },
}

impl crate::outcome::Classify for StatisticsError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        // The band asked for (--band-bins) against the falloff.
        Some(Outcome::Input)
    }
}

/// The running sufficient statistics of every candidate pixel.
pub struct Statistics {
    tables: StatisticsTables,
    /// Per pixel and direction: grid index of the centre (relative to g0).
    grid: Vec<u32>,
    /// Per pixel: the reference count y0 (its first sample), then for each
    /// direction Σ(y − y0), Σ(y − y0)², n. Sums about y0 keep the RSS,
    /// Σ(y − y0)² − …, free of the cancellation of Σy² (~10¹² for 2000
    /// samples of ~3·10⁴ counts, against an RSS of ~10² without noise).
    state: Vec<f64>,
    stride: usize,
    /// Per pixel, for each direction: Z (2·Q_data: re, im), single
    /// precision: nine tenths of the statistics' bytes, halved. A block's
    /// demodulation is summed in double precision and rounded once into
    /// them.
    ///
    /// What the rounding costs, relative to Z (RMS): each block adds its
    /// double-precision sum to the single-precision Z once (one rounding,
    /// at most 2⁻²⁴ of Z's magnitude, uniform: RMS 2⁻²⁴/√3), and the
    /// ⌈frames/32⌉ roundings are independent, so they add like a random
    /// walk: 2.7e-7 of |Z| at 2000 frames.
    ///
    /// Against the noise Z carries: with |Z| ≲ (B/2)·n/Q (B the fringe
    /// amplitude, n samples, Q nodes) and noise σ_y·√(n/Q) per node, the
    /// rounding is ≤ 2.7e-7 · (B/2σ_y) · √(n/Q) of the noise, 1.8e-5 at
    /// B/σ_y = 20 (5 % noise on a strong fringe), n = 2000, Q = 44. Measured
    /// against the series (`tests.rs`, B/σ_y ≈ 40, 2000 and 4000 samples):
    /// each Gauss–Newton step moves by ≤ 1.1e-5 of its σ, the pair scan's
    /// amplitudes by ≤ 5.1e-4 of theirs, and RSS by ≤ 5.7e-4 of its own
    /// sampling scatter √(2/n)·RSS (27 counts² there, below the 12-bit
    /// quantisation's own n/12 ≈ 170 of a noiseless series); the tests
    /// hold them to 1e-2.
    z: Vec<f32>,
    z_stride: usize,
    /// Per direction: where its Z starts in a pixel's `z`, and its sums in
    /// the pixel's `state`.
    z_offsets: Vec<usize>,
    offsets: Vec<usize>,
    set_aside: Vec<SetAside>,
    /// Per pixel: samples set aside; past `cap` (or once [`MAX_SET_ASIDE`]
    /// is reached) the pixel is given up.
    counts: Vec<u32>,
    cap: u32,
    /// Most samples set aside in all ([`MAX_SET_ASIDE`]).
    budget: usize,
    configured_saturation: Option<u16>,
}

impl Statistics {
    /// Statistics for `pixels` pixels whose centres, per pixel and
    /// direction, are `centres[d][pixel]` (μ), with band half-widths
    /// `band[d]` (μ); κ within `kappa_range`.
    ///
    /// # Errors
    /// [`StatisticsError::BandTooWide`] when a direction's band needs more
    /// than 256 nodes.
    pub fn new(
        design: &Design,
        centres: &[Vec<f64>],
        band: &[f64],
        kappa_range: [f64; 2],
        configured_saturation: Option<u16>,
    ) -> Result<Self, StatisticsError> {
        let tables = StatisticsTables::new(design, centres, band, kappa_range)?;
        let nd = tables.dirs.len();
        let pixels = centres.first().map_or(0, Vec::len);
        let mut offsets = Vec::with_capacity(nd);
        let mut z_offsets = Vec::with_capacity(nd);
        let (mut stride, mut z_stride) = (1, 0);
        for t in &tables.dirs {
            offsets.push(stride);
            stride += 3;
            z_offsets.push(z_stride);
            z_stride += 2 * t.data.len();
        }
        let mut grid = vec![0u32; pixels * nd];
        for (d, t) in tables.dirs.iter().enumerate() {
            for (p, &m) in centres[d].iter().enumerate() {
                grid[p * nd + d] = ((m / t.step).round() as i64 - t.g0) as u32;
            }
        }
        let frames = tables.frame_pos.len();
        Ok(Statistics {
            grid,
            state: vec![0.0; pixels * stride],
            stride,
            z: vec![0.0; pixels * z_stride],
            z_stride,
            z_offsets,
            offsets,
            set_aside: Vec::new(),
            counts: vec![0; pixels],
            // A pixel with more than a quarter of its samples clipped is
            // not fitted (flagged saturated, no data) and costs no memory.
            cap: (frames / 4) as u32,
            budget: MAX_SET_ASIDE,
            configured_saturation,
            tables,
        })
    }

    /// The schedule tables.
    pub fn tables(&self) -> &StatisticsTables {
        &self.tables
    }

    /// Bytes held by the per-pixel statistics and the set-aside samples.
    pub fn bytes(&self) -> usize {
        self.state.len() * 8
            + self.z.len() * 4
            + self.grid.len() * 4
            + self.counts.len() * 4
            + self.set_aside.capacity() * std::mem::size_of::<SetAside>()
    }

    /// Sorts the set-aside samples by pixel; call once all frames are in.
    pub fn seal(&mut self) {
        self.set_aside.sort_unstable_by_key(|s| (s.pixel, s.frame));
    }

    /// Asks the CPU to bring pixel `p`'s statistics into cache (the next
    /// pixel's, while this one is fitted: they are read once, from memory).
    pub fn prefetch(&self, p: usize) {
        if let Some(st) = self.state.get(p * self.stride..(p + 1) * self.stride) {
            prefetch_lines(st);
        }
        if let Some(z) = self.z.get(p * self.z_stride..(p + 1) * self.z_stride) {
            prefetch_lines(z);
        }
    }
}

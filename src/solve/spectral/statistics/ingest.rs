//! Frame ingest: a block of frames demodulated at each pixel's centre and
//! added to its sums, on all cores, with the clipping policy — samples that
//! may be clipped are set aside until the acquisition's saturation level is
//! known, within a budget per pixel and per acquisition.

use rayon::prelude::*;

use super::simd::{accumulate, has_avx2_fma};
use std::sync::atomic::{AtomicUsize, Ordering};

use super::tables::StatisticsTables;
use super::{Statistics, FULL_SCALES};
use crate::kernels::sincos_cycles;

/// A sample set aside at ingest because it may be clipped (0, a full scale
/// 2^b − 1, or at or above the configured saturation): whether it is
/// excluded is decided once the acquisition's saturation level is known.
#[derive(Debug, Clone, Copy)]
pub(super) struct SetAside {
    pub(super) pixel: u32,
    pub(super) frame: u32,
    pub(super) value: u16,
}

/// Most samples set aside over the whole acquisition (12 bytes each: 192 MB).
/// Bad input — dark or saturated frames for a quarter of a full-sensor run —
/// would otherwise set aside billions; past this, pixels with further
/// clipped samples are given up (flagged saturated, no data) instead.
pub(super) const MAX_SET_ASIDE: usize = 16 << 20;

/// The demodulation tables of one block: per row, per grid point of the
/// row's direction, `e^{iθ_i(μ_g)} L_j(τ_i)` on the data nodes, as
/// interleaved (re, im) pairs — the layout of a pixel's Z.
struct BlockWeights {
    /// Per row, where its tables start in `w`.
    row_start: Vec<usize>,
    w: Vec<f64>,
    /// Runs of rows of one direction: (first row, end, direction).
    runs: Vec<(usize, usize, usize)>,
}

impl BlockWeights {
    fn new(tables: &StatisticsTables, first: usize, rows: usize) -> Self {
        let mut row_start = Vec::with_capacity(rows);
        let mut w: Vec<f64> = Vec::new();
        let mut runs: Vec<(usize, usize, usize)> = Vec::new();
        for r in 0..rows {
            let (d, pos) = tables.frame_pos[first + r];
            match runs.last_mut() {
                Some(run) if run.2 == d => run.1 = r + 1,
                _ => runs.push((r, r + 1, d)),
            }
            let t = &tables.dirs[d];
            row_start.push(w.len());
            let q = t.data.len();
            let card = &t.card_data[pos * q..(pos + 1) * q];
            let (tau, ph) = tables.tau_phase[first + r];
            for g in 0..t.ng {
                let mu = (t.g0 + g as i64) as f64 * t.step;
                let (c, s) = sincos_cycles(mu * tau + ph);
                for &l in card {
                    w.push(c * l);
                    w.push(s * l);
                }
            }
        }
        BlockWeights { row_start, w, runs }
    }
}

/// What every pixel's ingest of one block reads.
struct BlockIngest<'a> {
    statistics: &'a Statistics,
    weights: BlockWeights,
    block: &'a [u16],
    first: usize,
    pixels: usize,
    avx2: bool,
    /// Samples set aside so far in the acquisition (all threads).
    budget: AtomicUsize,
}

impl BlockIngest<'_> {
    /// Whether `v` may be clipped: 0, a full scale, or at or above the
    /// configured saturation.
    fn clipped(&self, v: u16) -> bool {
        let configured = self.statistics.configured_saturation;
        v == 0 || FULL_SCALES.contains(&v) || configured.is_some_and(|s| v >= s)
    }

    /// Adds the block's samples of pixel `p` to its sums `st` and its Z
    /// `z` (through the scratch `items`, `acc`), setting aside (into `out`)
    /// the ones that may be clipped while the pixel's `count` and the
    /// acquisition's budget allow, else giving it up.
    fn pixel(
        &self,
        p: usize,
        st: &mut [f64],
        z: &mut [f32],
        count: &mut u32,
        (items, acc): (&mut Vec<(f64, usize)>, &mut Vec<f64>),
        out: &mut Vec<SetAside>,
    ) {
        let s = self.statistics;
        let (cap, nd) = (s.cap, s.tables.dirs.len());
        if *count > cap {
            return;
        }
        if self.first == 0 {
            st[0] = f64::from(self.block[p]);
        }
        let y0 = st[0];
        for &(r0, r1, d) in &self.weights.runs {
            let q = s.tables.dirs[d].data.len();
            let g = s.grid[p * nd + d] as usize;
            let (o, zo) = (s.offsets[d], s.z_offsets[d]);
            items.clear();
            let (mut s1, mut s2) = (0.0, 0.0);
            for r in r0..r1 {
                let v = self.block[r * self.pixels + p];
                if self.clipped(v) {
                    *count += 1;
                    let room = self.budget.fetch_add(1, Ordering::Relaxed) < s.budget;
                    if !room {
                        *count = cap + 1; // given up
                    }
                    if *count <= cap {
                        out.push(SetAside {
                            pixel: p as u32,
                            frame: (self.first + r) as u32,
                            value: v,
                        });
                    }
                    continue;
                }
                let y = f64::from(v);
                let c = y - y0;
                s1 += c;
                s2 += c * c;
                items.push((y, self.weights.row_start[r] + 2 * g * q));
            }
            // The block's sums in double precision, rounded once into Z.
            acc.clear();
            acc.resize(2 * q, 0.0);
            accumulate(acc, items, &self.weights.w, self.avx2);
            for (zk, &a) in z[zo..zo + 2 * q].iter_mut().zip(acc.iter()) {
                *zk = (f64::from(*zk) + a) as f32;
            }
            st[o] += s1;
            st[o + 1] += s2;
            st[o + 2] += items.len() as f64;
        }
    }
}

impl Statistics {
    /// Adds frames `first..first + rows` (capture order), given frame-major
    /// as `block[r * pixels + p]`, on all cores.
    pub fn ingest(&mut self, first: usize, rows: usize, block: &[u16]) {
        let pixels = self.counts.len();
        if pixels == 0 || rows == 0 {
            return;
        }
        let (stride, z_stride) = (self.stride, self.z_stride);
        let chunk = 256;
        // The state, Z and counts are written chunk by chunk while the
        // rest of `self` is read: taken out for the pass, put back after.
        let mut state = std::mem::take(&mut self.state);
        let mut z = std::mem::take(&mut self.z);
        let mut counts = std::mem::take(&mut self.counts);
        let ingest = BlockIngest {
            weights: BlockWeights::new(&self.tables, first, rows),
            statistics: self,
            block,
            first,
            pixels,
            avx2: has_avx2_fma(),
            budget: AtomicUsize::new(self.set_aside.len()),
        };
        let aside: Vec<Vec<SetAside>> = state
            .par_chunks_mut(chunk * stride)
            .zip(z.par_chunks_mut(chunk * z_stride))
            .zip(counts.par_chunks_mut(chunk))
            .enumerate()
            .map(|(ci, ((state, z), counts))| {
                let mut out = Vec::new();
                let mut items: Vec<(f64, usize)> = Vec::with_capacity(rows);
                let mut acc: Vec<f64> = Vec::new();
                let pixels = state
                    .chunks_mut(stride)
                    .zip(z.chunks_mut(z_stride))
                    .zip(counts.iter_mut());
                for (k, ((st, z), count)) in pixels.enumerate() {
                    let scratch = (&mut items, &mut acc);
                    ingest.pixel(ci * chunk + k, st, z, count, scratch, &mut out);
                }
                out
            })
            .collect();
        drop(ingest);
        self.state = state;
        self.z = z;
        self.counts = counts;
        for a in aside {
            self.set_aside.extend(a);
        }
    }
}

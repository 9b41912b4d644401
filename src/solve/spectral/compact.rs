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
//! station's prediction is flagged [`super::flags::OUT_OF_BAND`], never
//! fitted with a wrong model.

use std::borrow::Cow;

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use rustfft::num_complex::Complex;

use super::init::refine_peak;
use super::model::{Design, Normal, Params, Samples, MAX_REFLECTIONS};
use crate::kernels::{exp_fast, exp_fast_with, madd, sincos_cycles, sincos_cycles_with};

type C64 = Complex<f64>;

/// Interpolation tolerance of the node sets, relative to the largest value
/// of the interpolated function: the statistics reproduce the series' sums
/// to this fraction of `Σ|y|` (far below the noise: 1e-10 of a sum of 10³
/// samples is 1e-7 counts per sample; quantisation alone is 0.29).
const NODE_TOL: f64 = 1e-10;

/// Grid of demodulation centres, in Fourier bins.
const GRID_BINS: f64 = 0.25;

/// Frames demodulated together (the pixel's sums stay in cache over a block).
pub const STATS_BLOCK: usize = 32;

/// Chebyshev nodes on a τ interval and their cardinal polynomials.
#[derive(Debug, Clone)]
struct Nodes {
    tau: Vec<f64>,
    /// `T_q(s_j)` = cos(q θ_j), row j.
    tq: Vec<f64>,
    mid: f64,
    half: f64,
}

impl Nodes {
    fn new(lo: f64, hi: f64, q: usize) -> Nodes {
        let mid = 0.5 * (lo + hi);
        let half = (0.5 * (hi - lo)).max(1e-9);
        let mut tau = Vec::with_capacity(q);
        let mut tq = vec![0.0; q * q];
        for j in 0..q {
            let th = std::f64::consts::PI * (j as f64 + 0.5) / q as f64;
            tau.push(mid + half * th.cos());
            for k in 0..q {
                tq[j * q + k] = (k as f64 * th).cos();
            }
        }
        Nodes { tau, tq, mid, half }
    }

    fn len(&self) -> usize {
        self.tau.len()
    }

    /// `L_j(τ)` for every node j: `Σ_j L_j(τ) f(τ_j)` is the degree-(Q−1)
    /// interpolant of f. `L_j = (1/Q)[1 + 2 Σ_{q≥1} T_q(s_j) T_q(s)]`.
    fn cardinal(&self, tau: f64, out: &mut [f64]) {
        let q = self.len();
        let s = ((tau - self.mid) / self.half).clamp(-1.0, 1.0);
        let mut t = vec![0.0; q];
        t[0] = 1.0;
        if q > 1 {
            t[1] = s;
        }
        for k in 2..q {
            t[k] = 2.0 * s * t[k - 1] - t[k - 2];
        }
        for (j, o) in out.iter_mut().enumerate().take(q) {
            let row = &self.tq[j * q..(j + 1) * q];
            let mut acc = 0.5;
            for k in 1..q {
                acc += row[k] * t[k];
            }
            *o = 2.0 * acc / q as f64;
        }
    }

    /// Largest interpolation error over the τ interval of
    /// `(τ/hi)^deg e^{−κτ²} e^{2πiδτ}`, relative to its largest value, for
    /// `|δ| ≤ delta`, `κ ∈ kappas`, `deg ≤ degree`.
    fn error(&self, delta: f64, kappas: [f64; 2], degree: i32) -> f64 {
        let q = self.len();
        let lo = self.mid - self.half;
        let hi = self.mid + self.half;
        let mut card = vec![0.0; q];
        let mut worst: f64 = 0.0;
        let tests: Vec<f64> = (0..=96).map(|k| lo + (hi - lo) * k as f64 / 96.0).collect();
        for &dl in &[delta, -delta, 0.61 * delta, 0.0] {
            for &kappa in &kappas {
                for deg in [0, degree] {
                    let f = |t: f64| {
                        let (c, s) = sincos_cycles(dl * t);
                        C64::new(c, s) * ((t / hi).powi(deg) * (-kappa * t * t).exp())
                    };
                    let fj: Vec<C64> = self.tau.iter().map(|&t| f(t)).collect();
                    let scale = tests.iter().map(|&t| f(t).norm()).fold(1e-300, f64::max);
                    for &t in &tests {
                        self.cardinal(t, &mut card);
                        let v: C64 = fj.iter().zip(&card).map(|(a, &l)| a * l).sum();
                        worst = worst.max((v - f(t)).norm() / scale);
                    }
                }
            }
        }
        worst
    }

    /// The fewest nodes (multiple of 4, ≤ 256) meeting [`NODE_TOL`];
    /// `None` when 256 do not.
    fn enough(lo: f64, hi: f64, delta: f64, kappas: [f64; 2], degree: i32) -> Option<Nodes> {
        (8..=256)
            .step_by(4)
            .map(|q| Nodes::new(lo, hi, q))
            .find(|n| n.error(delta, kappas, degree) < NODE_TOL)
    }
}

/// Schedule tables of one fringe direction.
#[derive(Debug, Clone)]
struct DirTables {
    /// Nodes of the data sums (Z) and of the products of two columns.
    data: Nodes,
    gram: Nodes,
    /// Cardinals of every frame of the direction (by position), row-major.
    card_data: Vec<f64>,
    card_gram: Vec<f64>,
    /// `L^gram_k(τ^data_j)`, row j: lifts data-node sums onto the product
    /// nodes (`Σ_j Z_j f(τ^data_j) = Σ_k Z'_k f(τ^gram_k)` for the smooth f
    /// both node sets hold), so one evaluation of the columns serves both.
    lift: Vec<f64>,
    /// Grid step of the centres (μ), first grid index, count.
    step: f64,
    g0: i64,
    ng: usize,
    /// Per grid point: E on data nodes; on gram nodes, as the fits read
    /// them (real and imaginary parts apart), E and ½D; and ½M.
    ez_data: Vec<C64>,
    ez_re: Vec<f64>,
    ez_im: Vec<f64>,
    hd_re: Vec<f64>,
    hd_im: Vec<f64>,
    hm: Vec<f64>,
    /// Half-width of the band around the centre, μ.
    band: f64,
    /// One Fourier bin, μ.
    bin: f64,
    /// Periodogram offsets δ (¼ bin apart over the band) and
    /// `w(τ_j) e^{2πiδτ_j}` on the data nodes, w the Hann window.
    pdelta: Vec<f64>,
    pw: Vec<C64>,
    /// Σ_i w(τ_i)² over the direction's frames.
    w2: f64,
}

/// What the statistics of one acquisition share: the schedule's tables.
#[derive(Debug, Clone)]
pub struct CompactTables {
    dirs: Vec<DirTables>,
    /// Per frame: (direction, position among the direction's frames).
    frame_pos: Vec<(usize, usize)>,
    /// Per frame: τ and phase (cycles).
    tau_phase: Vec<(f64, f64)>,
    kappa_range: [f64; 2],
}

impl CompactTables {
    /// Tables for `design`; per direction, centres `centres[d]` (μ, one per
    /// pixel) with the band half-width `band[d]` (μ) around each; κ from
    /// `kappa_range`.
    fn new(
        design: &Design,
        centres: &[Vec<f64>],
        band: &[f64],
        kappa_range: [f64; 2],
    ) -> Result<Self, String> {
        let nd = design.axes.len();
        let mut frame_pos = vec![(0, 0); design.frames.len()];
        let mut per_dir: Vec<Vec<usize>> = vec![Vec::new(); nd];
        for (i, f) in design.frames.iter().enumerate() {
            frame_pos[i] = (f.dir, per_dir[f.dir].len());
            per_dir[f.dir].push(i);
        }
        let dirs = (0..nd)
            .map(|d| {
                let frames = &per_dir[d];
                let taus: Vec<f64> = frames.iter().map(|&i| design.frames[i].tau).collect();
                let lo = taus.iter().copied().fold(f64::INFINITY, f64::min);
                let hi = taus.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                let bin = 1.0 / (hi - lo).max(1e-9);
                let step = GRID_BINS * bin;
                let delta = band[d] + 0.5 * step;
                let too_wide = || {
                    format!(
                        "direction {d}: a band of ±{:.1} Fourier bins with τ_max down to {:.0} \
                         needs more than 256 nodes; use a smaller band or the series engine",
                        delta / bin,
                        kappa_range[1].max(1e-300).sqrt().recip()
                    )
                };
                let data = Nodes::enough(lo, hi, delta, kappa_range, 2).ok_or_else(too_wide)?;
                let gram = Nodes::enough(
                    lo,
                    hi,
                    2.0 * delta,
                    [2.0 * kappa_range[0], 2.0 * kappa_range[1]],
                    4,
                )
                .ok_or_else(too_wide)?;
                let (qd, qg) = (data.len(), gram.len());
                let mut card_data = vec![0.0; taus.len() * qd];
                let mut card_gram = vec![0.0; taus.len() * qg];
                for (k, &t) in taus.iter().enumerate() {
                    data.cardinal(t, &mut card_data[k * qd..(k + 1) * qd]);
                    gram.cardinal(t, &mut card_gram[k * qg..(k + 1) * qg]);
                }
                let mut lift = vec![0.0; qd * qg];
                for (j, &t) in data.tau.iter().enumerate() {
                    gram.cardinal(t, &mut lift[j * qg..(j + 1) * qg]);
                }
                let mut mz = vec![0.0; qg];
                for row in card_gram.chunks(qg) {
                    for (m, &c) in mz.iter_mut().zip(row) {
                        *m += c;
                    }
                }
                let gi: Vec<i64> = centres[d]
                    .iter()
                    .map(|&m| (m / step).round() as i64)
                    .collect();
                let g0 = gi.iter().copied().min().unwrap_or(0);
                let ng = (gi.iter().copied().max().unwrap_or(0) - g0 + 1) as usize;
                let phases: Vec<f64> = frames
                    .iter()
                    .map(|&i| design.frames[i].phase_cycles)
                    .collect();
                let per_g: Vec<(Vec<C64>, Vec<C64>, Vec<C64>)> = (0..ng)
                    .into_par_iter()
                    .map(|g| {
                        let mu = (g0 + g as i64) as f64 * step;
                        let mut ed = vec![C64::new(0.0, 0.0); qd];
                        let mut eg = vec![C64::new(0.0, 0.0); qg];
                        let mut dg = vec![C64::new(0.0, 0.0); qg];
                        for (k, (&t, &ph)) in taus.iter().zip(&phases).enumerate() {
                            let (c, s) = sincos_cycles(mu * t + ph);
                            let e1 = C64::new(c, s);
                            let e2 = e1 * e1;
                            for (o, &l) in ed.iter_mut().zip(&card_data[k * qd..(k + 1) * qd]) {
                                *o += e1 * l;
                            }
                            let row = &card_gram[k * qg..(k + 1) * qg];
                            for ((oe, od), &l) in eg.iter_mut().zip(dg.iter_mut()).zip(row) {
                                *oe += e1 * l;
                                *od += e2 * l;
                            }
                        }
                        (ed, eg, dg)
                    })
                    .collect();
                let mut ez_data = Vec::with_capacity(ng * qd);
                let mut ez_gram = Vec::with_capacity(ng * qg);
                let mut dz = Vec::with_capacity(ng * qg);
                for (a, b, c) in per_g {
                    ez_data.extend(a);
                    ez_gram.extend(b);
                    dz.extend(c);
                }
                let hann = |t: f64| {
                    let x = std::f64::consts::PI * (t - lo) * bin;
                    x.sin().powi(2)
                };
                let w2 = taus.iter().map(|&t| hann(t).powi(2)).sum();
                let nk = (band[d] / (0.25 * bin)).floor() as i64;
                let pdelta: Vec<f64> = (-nk..=nk).map(|k| k as f64 * 0.25 * bin).collect();
                let mut pw = Vec::with_capacity(pdelta.len() * qd);
                for &dl in &pdelta {
                    for &t in &data.tau {
                        let (c, s) = sincos_cycles(dl * t);
                        pw.push(C64::new(c, s) * hann(t));
                    }
                }
                Ok(DirTables {
                    data,
                    gram,
                    card_data,
                    card_gram,
                    lift,
                    step,
                    g0,
                    ng,
                    ez_data,
                    ez_re: ez_gram.iter().map(|z| z.re).collect(),
                    ez_im: ez_gram.iter().map(|z| z.im).collect(),
                    hd_re: dz.iter().map(|z| 0.5 * z.re).collect(),
                    hd_im: dz.iter().map(|z| 0.5 * z.im).collect(),
                    hm: mz.iter().map(|m| 0.5 * m).collect(),
                    band: band[d],
                    bin,
                    pdelta,
                    pw,
                    w2,
                })
            })
            .collect::<Result<Vec<_>, String>>()?;
        Ok(CompactTables {
            dirs,
            frame_pos,
            tau_phase: design
                .frames
                .iter()
                .map(|f| (f.tau, f.phase_cycles))
                .collect(),
            kappa_range,
        })
    }

    /// Nodes per direction: (data, products).
    pub fn nodes(&self) -> Vec<(usize, usize)> {
        self.dirs
            .iter()
            .map(|t| (t.data.len(), t.gram.len()))
            .collect()
    }
}

/// A sample set aside at ingest because it may be clipped (0, a full scale
/// 2^b − 1, or at or above the configured saturation): whether it is
/// excluded is decided once the acquisition's saturation level is known.
#[derive(Debug, Clone, Copy)]
struct SetAside {
    pixel: u32,
    frame: u32,
    value: u16,
}

/// Most samples set aside over the whole acquisition (12 bytes each: 192 MB).
/// Bad input — dark or saturated frames for a quarter of a full-sensor run —
/// would otherwise set aside billions; past this, pixels with further
/// clipped samples are given up (flagged saturated, no data) instead.
const MAX_SET_ASIDE: usize = 16 << 20;

/// Full scales of 8…16-bit cameras.
pub(super) const FULL_SCALES: [u16; 5] = [255, 1023, 4095, 16383, 65535];

/// The running sufficient statistics of every candidate pixel.
pub struct CompactStats {
    tables: CompactTables,
    /// Per pixel and direction: grid index of the centre (relative to g0).
    grid: Vec<u32>,
    /// Per pixel: the reference count y0 (its first sample), then for each
    /// direction Z (2·Q_data: re, im), Σ(y − y0), Σ(y − y0)², n. Sums about
    /// y0 keep the RSS, Σ(y − y0)² − …, free of the cancellation of Σy²
    /// (~10¹² for 2000 samples of ~3·10⁴ counts, against an RSS of ~10²
    /// without noise).
    state: Vec<f64>,
    stride: usize,
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

impl CompactStats {
    /// Statistics for `pixels` pixels whose centres, per pixel and
    /// direction, are `centres[d][pixel]` (μ), with band half-widths
    /// `band[d]` (μ); κ within `kappa_range`.
    ///
    /// # Errors
    /// When the band is too wide for 256 nodes.
    pub fn new(
        design: &Design,
        centres: &[Vec<f64>],
        band: &[f64],
        kappa_range: [f64; 2],
        configured_saturation: Option<u16>,
    ) -> Result<Self, String> {
        let tables = CompactTables::new(design, centres, band, kappa_range)?;
        let nd = tables.dirs.len();
        let pixels = centres.first().map_or(0, Vec::len);
        let mut offsets = Vec::with_capacity(nd);
        let mut stride = 1;
        for t in &tables.dirs {
            offsets.push(stride);
            stride += 2 * t.data.len() + 3;
        }
        let mut grid = vec![0u32; pixels * nd];
        for (d, t) in tables.dirs.iter().enumerate() {
            for (p, &m) in centres[d].iter().enumerate() {
                grid[p * nd + d] = ((m / t.step).round() as i64 - t.g0) as u32;
            }
        }
        let frames = tables.frame_pos.len();
        Ok(CompactStats {
            grid,
            state: vec![0.0; pixels * stride],
            stride,
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
    pub fn tables(&self) -> &CompactTables {
        &self.tables
    }

    /// Bytes held by the per-pixel statistics and the set-aside samples.
    pub fn bytes(&self) -> usize {
        self.state.len() * 8
            + self.grid.len() * 4
            + self.counts.len() * 4
            + self.set_aside.capacity() * std::mem::size_of::<SetAside>()
    }

    /// Adds frames `first..first + rows` (capture order), given frame-major
    /// as `block[r * pixels + p]`, on all cores.
    pub fn ingest(&mut self, first: usize, rows: usize, block: &[u16]) {
        let pixels = self.counts.len();
        if pixels == 0 || rows == 0 {
            return;
        }
        let nd = self.tables.dirs.len();
        // Demodulation tables of the block: per row, per grid point of the
        // row's direction, e^{iθ_i(μ_g)} L_j(τ_i) on the data nodes, as
        // interleaved (re, im) pairs — the layout of a pixel's Z.
        let mut row_start = Vec::with_capacity(rows);
        let mut w: Vec<f64> = Vec::new();
        // Runs of rows of one direction: (first row, end, direction).
        let mut runs: Vec<(usize, usize, usize)> = Vec::new();
        for r in 0..rows {
            let (d, pos) = self.tables.frame_pos[first + r];
            match runs.last_mut() {
                Some(run) if run.2 == d => run.1 = r + 1,
                _ => runs.push((r, r + 1, d)),
            }
            let t = &self.tables.dirs[d];
            row_start.push(w.len());
            let q = t.data.len();
            let card = &t.card_data[pos * q..(pos + 1) * q];
            let (tau, ph) = self.tables.tau_phase[first + r];
            for g in 0..t.ng {
                let mu = (t.g0 + g as i64) as f64 * t.step;
                let (c, s) = sincos_cycles(mu * tau + ph);
                for &l in card {
                    w.push(c * l);
                    w.push(s * l);
                }
            }
        }
        let stride = self.stride;
        let chunk = 256;
        let tables = &self.tables;
        let grid = &self.grid;
        let offsets = &self.offsets;
        let cap = self.cap;
        let configured = self.configured_saturation;
        let clipped =
            |v: u16| v == 0 || FULL_SCALES.contains(&v) || configured.is_some_and(|s| v >= s);
        let avx2 = has_avx2_fma();
        let budget = std::sync::atomic::AtomicUsize::new(self.set_aside.len());
        let limit = self.budget;
        let aside: Vec<Vec<SetAside>> = self
            .state
            .par_chunks_mut(chunk * stride)
            .zip(self.counts.par_chunks_mut(chunk))
            .enumerate()
            .map(|(ci, (state, counts))| {
                let mut out = Vec::new();
                let mut items: Vec<(f64, usize)> = Vec::with_capacity(rows);
                for (k, (st, count)) in state.chunks_mut(stride).zip(counts.iter_mut()).enumerate()
                {
                    let p = ci * chunk + k;
                    if *count > cap {
                        continue;
                    }
                    if first == 0 {
                        st[0] = f64::from(block[p]);
                    }
                    let y0 = st[0];
                    for &(r0, r1, d) in &runs {
                        let q = tables.dirs[d].data.len();
                        let g = grid[p * nd + d] as usize;
                        let o = offsets[d];
                        items.clear();
                        let (mut s1, mut s2) = (0.0, 0.0);
                        for r in r0..r1 {
                            let v = block[r * pixels + p];
                            if clipped(v) {
                                *count += 1;
                                let room = budget
                                    .fetch_add(1, std::sync::atomic::Ordering::Relaxed)
                                    < limit;
                                if !room {
                                    *count = cap + 1; // given up
                                }
                                if *count <= cap {
                                    out.push(SetAside {
                                        pixel: p as u32,
                                        frame: (first + r) as u32,
                                        value: v,
                                    });
                                }
                                continue;
                            }
                            let y = f64::from(v);
                            let c = y - y0;
                            s1 += c;
                            s2 += c * c;
                            items.push((y, row_start[r] + 2 * g * q));
                        }
                        accumulate(&mut st[o..o + 2 * q], &items, &w, avx2);
                        st[o + 2 * q] += s1;
                        st[o + 2 * q + 1] += s2;
                        st[o + 2 * q + 2] += items.len() as f64;
                    }
                }
                out
            })
            .collect();
        for a in aside {
            self.set_aside.extend(a);
        }
    }
}

/// Whether this CPU has AVX2 and FMA (checked once).
fn has_avx2_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        static HAS: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
        *HAS.get_or_init(|| is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma"))
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// `z += Σ y · w[o..o + z.len()]` over `items = (y, o)`: the hot loop of the
/// ingest, four rows at a time so that z is loaded and stored once per four.
#[inline(always)]
fn accumulate_portable(z: &mut [f64], items: &[(f64, usize)], w: &[f64]) {
    let n = z.len();
    let mut quads = items.chunks_exact(4);
    for c in &mut quads {
        let w0 = &w[c[0].1..c[0].1 + n];
        let w1 = &w[c[1].1..c[1].1 + n];
        let w2 = &w[c[2].1..c[2].1 + n];
        let w3 = &w[c[3].1..c[3].1 + n];
        let (y0, y1, y2, y3) = (c[0].0, c[1].0, c[2].0, c[3].0);
        for k in 0..n {
            z[k] += y0 * w0[k] + y1 * w1[k] + y2 * w2[k] + y3 * w3[k];
        }
    }
    for &(y, o) in quads.remainder() {
        for (zk, wk) in z.iter_mut().zip(&w[o..o + n]) {
            *zk += y * wk;
        }
    }
}

/// [`accumulate_portable`] compiled for AVX2 and FMA.
///
/// # Safety
/// The CPU must have AVX2 and FMA ([`has_avx2_fma`]).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn accumulate_avx2(z: &mut [f64], items: &[(f64, usize)], w: &[f64]) {
    accumulate_portable(z, items, w);
}

fn accumulate(z: &mut [f64], items: &[(f64, usize)], w: &[f64], avx2: bool) {
    #[cfg(target_arch = "x86_64")]
    if avx2 {
        // SAFETY: `avx2` is true only where the CPU has AVX2 and FMA.
        unsafe { accumulate_avx2(z, items, w) };
        return;
    }
    let _ = avx2;
    accumulate_portable(z, items, w);
}

impl CompactStats {
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
    }

    /// Pixel `p`'s statistics with samples at 0 or at/above `saturation`
    /// excluded, and the number excluded; `None` when more than a quarter
    /// of its samples were clipped (given up at ingest). Needs [`Self::seal`].
    pub fn samples<'a>(
        &'a self,
        design: &'a Design,
        p: usize,
        saturation: Option<u16>,
    ) -> Option<(CompactSamples<'a>, usize)> {
        if self.counts[p] > self.cap {
            return None;
        }
        let nd = self.tables.dirs.len();
        let st = &self.state[p * self.stride..(p + 1) * self.stride];
        let y0 = st[0];
        let mut dirs: Vec<PixelDir> = self
            .tables
            .dirs
            .iter()
            .enumerate()
            .map(|(d, t)| {
                let q = t.data.len();
                let qg = t.gram.len();
                let o = self.offsets[d];
                let g = self.grid[p * nd + d] as usize;
                let gram = g * qg..(g + 1) * qg;
                let (mut z, mut zg_re, mut zg_im) = spare();
                z.clear();
                z.extend(
                    st[o..o + 2 * q]
                        .chunks_exact(2)
                        .map(|c| C64::new(c[0], c[1])),
                );
                for v in [&mut zg_re, &mut zg_im] {
                    v.clear();
                    v.resize(qg, 0.0);
                }
                PixelDir {
                    mu_c: (t.g0 + g as i64) as f64 * t.step,
                    z,
                    hm: Cow::Borrowed(&t.hm),
                    hd_re: Cow::Borrowed(&t.hd_re[gram.clone()]),
                    hd_im: Cow::Borrowed(&t.hd_im[gram.clone()]),
                    ez_re: Cow::Borrowed(&t.ez_re[gram.clone()]),
                    ez_im: Cow::Borrowed(&t.ez_im[gram]),
                    zg_re,
                    zg_im,
                    ez_data: Cow::Borrowed(&t.ez_data[g * q..(g + 1) * q]),
                    sy: st[o + 2 * q],
                    syy: st[o + 2 * q + 1],
                    n: st[o + 2 * q + 2],
                }
            })
            .collect();
        let from = self.set_aside.partition_point(|s| (s.pixel as usize) < p);
        let to = self.set_aside.partition_point(|s| (s.pixel as usize) <= p);
        let mut excluded = 0;
        for s in &self.set_aside[from..to] {
            let (d, pos) = self.tables.frame_pos[s.frame as usize];
            let (tau, ph) = self.tables.tau_phase[s.frame as usize];
            let t = &self.tables.dirs[d];
            let pd = &mut dirs[d];
            let (c, sn) = sincos_cycles(pd.mu_c * tau + ph);
            let e1 = C64::new(c, sn);
            let (q, qg) = (t.data.len(), t.gram.len());
            let cd = &t.card_data[pos * q..(pos + 1) * q];
            let cg = &t.card_gram[pos * qg..(pos + 1) * qg];
            if s.value == 0 || saturation.is_some_and(|sat| s.value >= sat) {
                excluded += 1;
                for (o, &l) in pd.ez_data.to_mut().iter_mut().zip(cd) {
                    *o -= e1 * l;
                }
                let e2 = e1 * e1;
                let (ez_re, ez_im) = (pd.ez_re.to_mut(), pd.ez_im.to_mut());
                let (hd_re, hd_im, hm) = (pd.hd_re.to_mut(), pd.hd_im.to_mut(), pd.hm.to_mut());
                for (j, &l) in cg.iter().enumerate() {
                    ez_re[j] -= e1.re * l;
                    ez_im[j] -= e1.im * l;
                    hd_re[j] -= 0.5 * e2.re * l;
                    hd_im[j] -= 0.5 * e2.im * l;
                    hm[j] -= 0.5 * l;
                }
            } else {
                let y = f64::from(s.value);
                for (o, &l) in pd.z.iter_mut().zip(cd) {
                    *o += e1 * (y * l);
                }
                pd.sy += y - y0;
                pd.syy += (y - y0) * (y - y0);
                pd.n += 1.0;
            }
        }
        for (pd, t) in dirs.iter_mut().zip(&self.tables.dirs) {
            lift(&pd.z, &t.lift, &mut pd.zg_re, &mut pd.zg_im);
        }
        let n = dirs.iter().map(|d| d.n).sum();
        let sy = dirs.iter().map(|d| d.sy).sum();
        let syy = dirs.iter().map(|d| d.syy).sum();
        Some((
            CompactSamples {
                design,
                tables: &self.tables,
                dirs,
                y0,
                n,
                sy,
                syy,
            },
            excluded,
        ))
    }
}

/// Asks the CPU to bring the cache lines of `v` into cache (a hint: no
/// effect on results, none at all off x86-64).
pub fn prefetch_lines<T>(v: &[T]) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        let bytes = std::mem::size_of_val(v);
        let base = v.as_ptr().cast::<i8>();
        for off in (0..bytes).step_by(64) {
            // SAFETY: a prefetch reads nothing architecturally and cannot
            // fault; the address lies within `v`.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(base.add(off)) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = v;
}

/// `Z' = Lᵀ Z`, row by row: Z lifted from the data nodes onto the product
/// nodes (real and imaginary parts apart).
fn lift(z: &[C64], l: &[f64], re: &mut [f64], im: &mut [f64]) {
    /// Columns `c0..c0 + W` over every row, their sums in registers (one
    /// load per two multiply–adds, not five), each taken over the rows in
    /// order. Not fused: with `mul_add` the compiler left these scalar.
    #[inline(always)]
    fn columns<const W: usize>(z: &[C64], l: &[f64], c0: usize, re: &mut [f64], im: &mut [f64]) {
        let qg = re.len();
        let mut ar = [0.0f64; W];
        let mut ai = [0.0f64; W];
        for (z, row) in z.iter().zip(l.chunks_exact(qg)) {
            let lw: &[f64; W] = row[c0..c0 + W].try_into().expect("W columns");
            for t in 0..W {
                ar[t] += z.re * lw[t];
                ai[t] += z.im * lw[t];
            }
        }
        for t in 0..W {
            re[c0 + t] += ar[t];
            im[c0 + t] += ai[t];
        }
    }
    #[inline(always)]
    fn body(z: &[C64], l: &[f64], re: &mut [f64], im: &mut [f64]) {
        let qg = re.len();
        let mut c0 = 0;
        while c0 + 16 <= qg {
            columns::<16>(z, l, c0, re, im);
            c0 += 16;
        }
        while c0 + 4 <= qg {
            columns::<4>(z, l, c0, re, im);
            c0 += 4;
        }
        while c0 < qg {
            columns::<1>(z, l, c0, re, im);
            c0 += 1;
        }
    }
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn body_avx2(z: &[C64], l: &[f64], re: &mut [f64], im: &mut [f64]) {
        body(z, l, re, im);
    }
    #[cfg(target_arch = "x86_64")]
    if has_avx2_fma() {
        // SAFETY: the CPU has AVX2 and FMA (checked at run time).
        unsafe { body_avx2(z, l, re, im) };
        return;
    }
    body(z, l, re, im);
}

/// One direction of one pixel: its statistics and the schedule sums of its
/// grid point (a copy only where clipped samples are subtracted from them).
#[derive(Debug, Clone)]
struct PixelDir<'a> {
    mu_c: f64,
    z: Vec<C64>,
    /// On the product nodes, as arrays (real and imaginary parts apart):
    /// ½M, ½D, E and Z lifted from the data nodes.
    hm: Cow<'a, [f64]>,
    hd_re: Cow<'a, [f64]>,
    hd_im: Cow<'a, [f64]>,
    ez_re: Cow<'a, [f64]>,
    ez_im: Cow<'a, [f64]>,
    zg_re: Vec<f64>,
    zg_im: Vec<f64>,
    ez_data: Cow<'a, [C64]>,
    /// Σ(y − y0), Σ(y − y0)², samples.
    sy: f64,
    syy: f64,
    n: f64,
}

/// One pixel's sufficient statistics, as the fits see them.
pub struct CompactSamples<'a> {
    design: &'a Design,
    tables: &'a CompactTables,
    dirs: Vec<PixelDir<'a>>,
    /// Reference count; `sy`, `syy` are about it.
    y0: f64,
    n: f64,
    sy: f64,
    syy: f64,
}

/// The arrays of one [`PixelDir`] a pixel owns: `z`, `zg_re`, `zg_im`.
type DirArrays = (Vec<C64>, Vec<f64>, Vec<f64>);

thread_local! {
    /// Per-thread spare [`DirArrays`]: a pixel's go back here when its
    /// samples are dropped, so the next pixel's allocate nothing.
    static SPARE: std::cell::RefCell<Vec<DirArrays>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Spare arrays for a [`PixelDir`] (contents unspecified), or new ones.
fn spare() -> DirArrays {
    SPARE
        .try_with(|s| s.borrow_mut().pop())
        .ok()
        .flatten()
        .unwrap_or_default()
}

impl Drop for CompactSamples<'_> {
    fn drop(&mut self) {
        let _ = SPARE.try_with(|s| {
            let mut s = s.borrow_mut();
            for d in self.dirs.drain(..) {
                // A few pixels' worth (samples may nest): the rest are freed.
                if s.len() < 16 {
                    s.push((d.z, d.zg_re, d.zg_im));
                }
            }
        });
    }
}

thread_local! {
    /// Per-thread work arrays of [`CompactSamples::dir_sums`].
    static SCRATCH: std::cell::RefCell<Vec<f64>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// `Σ_j wr_j c^re_{y,j} + sign · wi_j c^im_{y,j}` for the `n` columns
/// `y = y0 … y0 + n − 1` of `cre`/`cim` (rows of length `q`), in one pass
/// over the nodes, four at a time with `n` accumulators in registers;
/// multiply–adds fused where `FMA`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn row_dots<const FMA: bool>(
    n: usize,
    wr: &[f64],
    wi: &[f64],
    sign: f64,
    cre: &[f64],
    cim: &[f64],
    q: usize,
    y0: usize,
) -> [f64; NX] {
    #[inline(always)]
    fn fixed<const N: usize, const FMA: bool>(
        wr: &[f64],
        wi: &[f64],
        sign: f64,
        cre: &[f64],
        cim: &[f64],
        q: usize,
        y0: usize,
    ) -> [f64; NX] {
        let rows = (y0 + N) * q;
        assert!(wr.len() >= q && wi.len() >= q && cre.len() >= rows && cim.len() >= rows);
        // Four values from `v` at `o`.
        #[inline(always)]
        fn four(v: &[f64], o: usize) -> [f64; 4] {
            debug_assert!(o + 4 <= v.len());
            // SAFETY: every call below has o + 4 ≤ v.len(): the weights
            // at j + 4 ≤ quads ≤ q ≤ wr.len(), wi.len(), the columns at
            // (y0 + t) q + j + 4 ≤ (y0 + N) q ≤ cre.len(), cim.len() (both
            // asserted above). Unchecked: the checks and their index
            // arithmetic were a quarter of the products' time.
            unsafe { v.as_ptr().add(o).cast::<[f64; 4]>().read_unaligned() }
        }
        let mut acc = [[0.0f64; 4]; N];
        let quads = q - q % 4;
        let mut j = 0;
        while j < quads {
            let a = four(wr, j);
            let b = four(wi, j);
            let sb = [sign * b[0], sign * b[1], sign * b[2], sign * b[3]];
            for (t, acc) in acc.iter_mut().enumerate() {
                let o = (y0 + t) * q + j;
                let c = four(cre, o);
                let d = four(cim, o);
                for l in 0..4 {
                    acc[l] = madd::<FMA>(sb[l], d[l], madd::<FMA>(a[l], c[l], acc[l]));
                }
            }
            j += 4;
        }
        let mut out = [0.0; NX];
        for (t, acc) in acc.iter().enumerate() {
            let o = (y0 + t) * q;
            let mut tail = 0.0;
            for j in quads..q {
                tail += wr[j] * cre[o + j] + sign * (wi[j] * cim[o + j]);
            }
            out[t] = (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail;
        }
        out
    }
    match n {
        1 => fixed::<1, FMA>(wr, wi, sign, cre, cim, q, y0),
        2 => fixed::<2, FMA>(wr, wi, sign, cre, cim, q, y0),
        3 => fixed::<3, FMA>(wr, wi, sign, cre, cim, q, y0),
        4 => fixed::<4, FMA>(wr, wi, sign, cre, cim, q, y0),
        5 => fixed::<5, FMA>(wr, wi, sign, cre, cim, q, y0),
        6 => fixed::<6, FMA>(wr, wi, sign, cre, cim, q, y0),
        7 => fixed::<7, FMA>(wr, wi, sign, cre, cim, q, y0),
        _ => fixed::<8, FMA>(wr, wi, sign, cre, cim, q, y0),
    }
}

/// Columns of one direction: `a_k` (B_k), `β_k` (μ_k), the κ column and the
/// model, at most 2K + 2.
const NX: usize = 2 * MAX_REFLECTIONS + 2;

/// Inner products over one direction's samples: of two columns (`g`, upper
/// triangle), of the constant with a column (`e`), of the data with a column (`y`).
struct DirSums {
    g: [[f64; NX]; NX],
    e: [f64; NX],
    y: [f64; NX],
}

impl DirSums {
    fn zero() -> Self {
        DirSums {
            g: [[0.0; NX]; NX],
            e: [0.0; NX],
            y: [0.0; NX],
        }
    }
}

impl CompactSamples<'_> {
    /// Whether `p` stays where the statistics hold (band and κ range), on
    /// direction `dir` alone when given.
    fn inside(&self, p: &Params, margin_bins: f64, dir: Option<usize>) -> bool {
        let [klo, khi] = self.tables.kappa_range;
        if !(p.kappa >= klo && p.kappa <= khi) {
            return false;
        }
        self.dirs
            .iter()
            .zip(&self.tables.dirs)
            .enumerate()
            .all(|(d, (pd, t))| {
                if dir.is_some_and(|x| x != d) {
                    return true;
                }
                let ax = self.design.axes[d];
                p.uv[..p.k].iter().all(|uv| {
                    (ax.s(uv[0], uv[1]) - pd.mu_c).abs()
                        <= t.band + (0.5 * GRID_BINS - margin_bins) * t.bin
                })
            })
    }

    /// The sums of direction `d` at `p` into `out` (written in place: they
    /// are 640 bytes, and returning them cost copies); only the entries the
    /// model's columns use are written, `y` zeroed without `data`.
    fn dir_sums(&self, d: usize, p: &Params, derivs: bool, data: bool, out: &mut DirSums) {
        SCRATCH.with(|s| {
            let mut s = s.borrow_mut();
            #[cfg(target_arch = "x86_64")]
            if has_avx2_fma() {
                // SAFETY: the CPU has AVX2 and FMA (checked at run time).
                unsafe { self.dir_sums_avx2(d, p, derivs, data, &mut s, out) };
                return;
            }
            self.dir_sums_body::<false>(d, p, derivs, data, &mut s, out);
        })
    }

    /// [`Self::dir_sums_body`] compiled for AVX2 and FMA.
    ///
    /// # Safety
    /// The CPU must have AVX2 and FMA ([`has_avx2_fma`]).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn dir_sums_avx2(
        &self,
        d: usize,
        p: &Params,
        derivs: bool,
        data: bool,
        scratch: &mut Vec<f64>,
        out: &mut DirSums,
    ) {
        self.dir_sums_body::<true>(d, p, derivs, data, scratch, out);
    }

    /// The inner products of one direction, node-major passes over arrays
    /// (structure of arrays) that the compiler vectorises: the columns at
    /// every product node — `a_k = e^{−κτ²} e^{2πiδ_kτ}`; with derivatives
    /// `β_k = 2πiτ B_k a_k` and the κ column `−τ² m` — then their weighted
    /// dot products. The model column `m = Σ B_k a_k` is last in the sums;
    /// being a combination of the `a_k`, its products are combined from
    /// theirs, not computed (a quarter to a third of the dot products).
    /// Multiply–adds are fused where `FMA` (the AVX2 and FMA build).
    #[inline(always)]
    fn dir_sums_body<const FMA: bool>(
        &self,
        d: usize,
        p: &Params,
        derivs: bool,
        data: bool,
        scratch: &mut Vec<f64>,
        out: &mut DirSums,
    ) {
        let pd = &self.dirs[d];
        let t = &self.tables.dirs[d];
        let ax = self.design.axes[d];
        let k = p.k;
        let nx = if derivs { 2 * k + 2 } else { k + 1 };
        // Columns computed: all but the model's.
        let nc = nx - 1;
        let q = t.gram.len();
        let tau = &t.gram.tau[..q];
        // Every array below is written before it is read, but for the model
        // (m), which is accumulated: only that one is zeroed.
        if scratch.len() < (3 + 4 * nc) * q {
            scratch.resize((3 + 4 * nc) * q, 0.0);
        }
        let (e, rest) = scratch.split_at_mut(q);
        let (mre, rest) = rest.split_at_mut(q);
        let (mim, rest) = rest.split_at_mut(q);
        let (cre, rest) = rest.split_at_mut(nc * q);
        let (cim, rest) = rest.split_at_mut(nc * q);
        let (pre, rest) = rest.split_at_mut(nc * q);
        let pim = &mut rest[..nc * q];
        for (ej, &tj) in e.iter_mut().zip(tau) {
            *ej = exp_fast_with::<FMA>(-p.kappa * tj * tj);
        }
        for j in 0..k {
            let dl = ax.s(p.uv[j][0], p.uv[j][1]) - pd.mu_c;
            let (re, im) = (&mut cre[j * q..(j + 1) * q], &mut cim[j * q..(j + 1) * q]);
            for (((r, i), &ej), &tj) in re.iter_mut().zip(im.iter_mut()).zip(&*e).zip(tau) {
                let (c, s) = sincos_cycles_with::<FMA>(dl * tj);
                *r = ej * c;
                *i = ej * s;
            }
        }
        if derivs {
            // m = Σ B_k a_k, for the κ column.
            mre.fill(0.0);
            mim.fill(0.0);
            for j in 0..k {
                let b = p.amp[j];
                let (ar, ai) = (&cre[j * q..(j + 1) * q], &cim[j * q..(j + 1) * q]);
                for (((mr, mi), &r), &i) in mre.iter_mut().zip(mim.iter_mut()).zip(ar).zip(ai) {
                    *mr = madd::<FMA>(b, r, *mr);
                    *mi = madd::<FMA>(b, i, *mi);
                }
            }
            for j in 0..k {
                let f = std::f64::consts::TAU * p.amp[j];
                let (ar, br) = cre.split_at_mut(k * q);
                let (ai, bi) = cim.split_at_mut(k * q);
                let (ar, ai) = (&ar[j * q..(j + 1) * q], &ai[j * q..(j + 1) * q]);
                let (br, bi) = (&mut br[j * q..(j + 1) * q], &mut bi[j * q..(j + 1) * q]);
                for ((((r2, i2), &r), &i), &tj) in
                    br.iter_mut().zip(bi.iter_mut()).zip(ar).zip(ai).zip(tau)
                {
                    *r2 = -i * f * tj;
                    *i2 = r * f * tj;
                }
            }
            let kr = &mut cre[2 * k * q..(2 * k + 1) * q];
            let ki = &mut cim[2 * k * q..(2 * k + 1) * q];
            for ((((r2, i2), &r), &i), &tj) in kr
                .iter_mut()
                .zip(ki.iter_mut())
                .zip(&*mre)
                .zip(&*mim)
                .zip(tau)
            {
                *r2 = -tj * tj * r;
                *i2 = -tj * tj * i;
            }
        }
        // Weighted columns: ½Re(M a b̄) + ½Re(D a b) = pr·b.re + pi·b.im with
        // pr + i·pi = ½M a + conj(½D a) (M real).
        for x in 0..nc {
            let r = x * q..(x + 1) * q;
            let it = pre[r.clone()]
                .iter_mut()
                .zip(pim[r.clone()].iter_mut())
                .zip(&cre[r.clone()])
                .zip(&cim[r])
                .zip(pd.hm.iter())
                .zip(pd.hd_re.iter().zip(pd.hd_im.iter()));
            for (((((pr, pi), &cr), &ci), &hm), (&hr, &hi)) in it {
                *pr = madd::<FMA>(hm + hr, cr, -hi * ci);
                *pi = madd::<FMA>(hm - hr, ci, -hi * cr);
            }
        }
        // One pass over the nodes per weight row: the constant's and the
        // data's against every column, each weighted column against the
        // columns from its own on (the upper triangle) — each row loaded
        // once per pass, not once per product.
        out.e = row_dots::<FMA>(nc, &pd.ez_re, &pd.ez_im, -1.0, cre, cim, q, 0);
        out.y = if data {
            row_dots::<FMA>(nc, &pd.zg_re, &pd.zg_im, -1.0, cre, cim, q, 0)
        } else {
            [0.0; NX]
        };
        for x in 0..nc {
            let (wr, wi) = (&pre[x * q..(x + 1) * q], &pim[x * q..(x + 1) * q]);
            let row = row_dots::<FMA>(nc - x, wr, wi, 1.0, cre, cim, q, x);
            out.g[x][x..nc].copy_from_slice(&row[..nc - x]);
        }
        // The model column m = Σ B_j a_j, by linearity.
        let m = nx - 1;
        let g = |x: usize, y: usize| out.g[x.min(y)][x.max(y)];
        let mut gm = [0.0; NX];
        for (x, gmx) in gm.iter_mut().enumerate().take(nc) {
            *gmx = (0..k).map(|j| p.amp[j] * g(x, j)).sum();
        }
        let gmm: f64 = (0..k).map(|j| p.amp[j] * gm[j]).sum();
        for (x, &v) in gm.iter().enumerate().take(nc) {
            out.g[x][m] = v;
        }
        out.g[m][m] = gmm;
        out.e[m] = (0..k).map(|j| p.amp[j] * out.e[j]).sum();
        out.y[m] = (0..k).map(|j| p.amp[j] * out.y[j]).sum();
    }

    fn normal_with(&self, p: &Params, data: bool) -> Normal {
        let k = p.k;
        let np = p.len();
        let mut jtj = DMatrix::<f64>::zeros(np, np);
        let mut jtr = DVector::<f64>::zeros(np);
        if !self.inside(p, 0.0, None) {
            return Normal {
                rss: f64::INFINITY,
                jtj: DMatrix::identity(np, np),
                jtr,
            };
        }
        let a = p.offset;
        // The offset about the reference: A' = A − y0, data y' = y − y0.
        let ac = a - self.y0;
        let m = 2 * k + 1;
        jtj[(0, 0)] = self.n;
        let mut rss = self.syy - 2.0 * ac * self.sy + ac * ac * self.n;
        jtr[0] = self.sy - ac * self.n;
        let mut s = DirSums::zero();
        for d in 0..self.dirs.len() {
            self.dir_sums(d, p, true, data, &mut s);
            let ax = self.design.axes[d];
            // Parameter → (column, factor).
            let mut map = [(0usize, 0.0f64); 3 * MAX_REFLECTIONS + 2];
            for j in 0..k {
                map[1 + j] = (j, 1.0);
                map[1 + k + 2 * j] = (k + j, ax.a);
                map[2 + k + 2 * j] = (k + j, ax.b);
            }
            map[1 + 3 * k] = (2 * k, 1.0);
            let g = |x: usize, y: usize| s.g[x.min(y)][x.max(y)];
            rss += -2.0 * (s.y[m] - self.y0 * s.e[m]) + 2.0 * ac * s.e[m] + g(m, m);
            jtr[0] -= s.e[m];
            for pi in 1..np {
                let (x, f) = map[pi];
                jtj[(0, pi)] += f * s.e[x];
                jtr[pi] += f * (s.y[x] - a * s.e[x] - g(x, m));
                for pj in pi..np {
                    let (y, h) = map[pj];
                    jtj[(pi, pj)] += f * h * g(x, y);
                }
            }
        }
        for i in 0..np {
            for j in 0..i {
                jtj[(i, j)] = jtj[(j, i)];
            }
        }
        Normal {
            rss: if data { rss.max(0.0) } else { f64::NAN },
            jtj,
            jtr,
        }
    }
}

impl Samples for CompactSamples<'_> {
    fn count(&self) -> usize {
        self.n as usize
    }

    fn normal(&self, p: &Params) -> Normal {
        self.normal_with(p, true)
    }

    fn information(&self, p: &Params) -> DMatrix<f64> {
        self.normal_with(p, false).jtj
    }

    fn linear(&self, p: &Params, dir: Option<usize>) -> (Params, f64) {
        let k = p.k;
        let n = 1 + k;
        let mut out = *p;
        if !self.inside(p, 0.0, dir) {
            return (out, f64::INFINITY);
        }
        let mut g = DMatrix::<f64>::zeros(n, n);
        let mut h = DVector::<f64>::zeros(n);
        let mut yy = 0.0;
        let mut s = DirSums::zero();
        for d in 0..self.dirs.len() {
            if dir.is_some_and(|x| x != d) {
                continue;
            }
            let pd = &self.dirs[d];
            self.dir_sums(d, p, false, true, &mut s);
            g[(0, 0)] += pd.n;
            h[0] += pd.sy;
            yy += pd.syy;
            for x in 0..k {
                g[(0, 1 + x)] += s.e[x];
                h[1 + x] += s.y[x] - self.y0 * s.e[x];
                for y in x..k {
                    g[(1 + x, 1 + y)] += s.g[x][y];
                }
            }
        }
        for i in 0..n {
            for j in 0..i {
                g[(i, j)] = g[(j, i)];
            }
        }
        let mut rss = f64::INFINITY;
        if let Some(sol) = g.cholesky().map(|c| c.solve(&h)) {
            out.offset = sol[0] + self.y0;
            out.amp[..k].copy_from_slice(&sol.as_slice()[1..n]);
            rss = (yy - h.dot(&sol)).max(0.0);
        }
        (out, rss)
    }

    fn peak(&self, d: usize) -> Option<(f64, f64)> {
        let pd = &self.dirs[d];
        let t = &self.tables.dirs[d];
        if pd.n < 8.0 {
            return None;
        }
        let mean = pd.sy / pd.n;
        let var = pd.syy / pd.n - mean * mean;
        let mean = mean + self.y0;
        // Counts are integers: no variance below the rounding's 1/12 count²
        // (also keeps Σy²/n − ȳ²'s cancellation on a constant pixel from
        // passing for a signal).
        let var = var.max(1.0 / 12.0);
        let zc: Vec<C64> =
            pd.z.iter()
                .zip(pd.ez_data.iter())
                .map(|(z, e)| z - e * mean)
                .collect();
        let q = zc.len();
        let power: Vec<f64> =
            t.pw.chunks_exact(q)
                .map(|w| {
                    w.iter()
                        .zip(&zc)
                        .map(|(a, b)| a * b)
                        .sum::<C64>()
                        .norm_sqr()
                })
                .collect();
        let mus: Vec<f64> = t.pdelta.iter().map(|dl| pd.mu_c + dl).collect();
        let (k, _) = power.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1))?;
        // Pure noise of variance σ² has periodogram power with mean
        // σ² Σ w², median ln 2 of that: the ratio is on the scale of
        // [`super::pixel::DETECTION_RATIO`].
        let ratio = power[k] / (std::f64::consts::LN_2 * var * t.w2);
        if k == 0 || k + 1 == power.len() {
            // The strongest power is at the band's edge: the signal may lie
            // outside it.
            return Some((f64::NAN, ratio));
        }
        let (mu, _) = refine_peak(&mus, &power, 3.0 * t.bin)?;
        Some((mu, ratio))
    }

    fn within_band(&self, p: &Params) -> bool {
        let [klo, khi] = self.tables.kappa_range;
        // A quarter bin inside the band and 10 % inside the κ range: a fit
        // stopped at the edge by the bounds is not reported.
        p.kappa > 0.9 * klo && p.kappa < 0.9 * khi && self.inside(p, 0.25 + 0.5 * GRID_BINS, None)
    }

    fn band_limited(&self) -> bool {
        true
    }

    fn pair_scan(
        &self,
        dir: usize,
        [mu0, step, offset]: [f64; 3],
        count: usize,
        kappa: f64,
        _point: &dyn Fn(f64) -> [f64; 2],
    ) -> Vec<([f64; 2], f64)> {
        // The pairs' columns at node τ: a0 = e ρ0 r^k, a1 = a0 o, with
        // e = e^{−κτ²}, ρ0 = e^{2πi(μ0 − μc)τ}, r = e^{2πi·step·τ},
        // o = e^{2πi·offset·τ}: one complex product per pair and node
        // instead of two sine–cosines and an exponential. The M part of the
        // products is the same for every pair: ½Σ M e² (|a|²) and
        // ½Σ M e² cos(2π·offset·τ) (Re a0 ā1).
        let pd = &self.dirs[dir];
        let t = &self.tables.dirs[dir];
        let [klo, khi] = self.tables.kappa_range;
        let lim = t.band + 0.5 * GRID_BINS * t.bin;
        let cis = |x: f64| {
            let (c, s) = sincos_cycles(x);
            C64::new(c, s)
        };
        struct Node {
            cur: C64,
            cur2: C64,
            rot: C64,
            rot2: C64,
            off: C64,
        }
        let node = |tau: f64| {
            let e = exp_fast(-kappa * tau * tau);
            let off = cis(offset * tau);
            let cur = cis((mu0 - pd.mu_c) * tau) * e;
            let rot = cis(step * tau);
            Node {
                cur,
                cur2: cur * cur,
                rot,
                rot2: rot * rot,
                off,
            }
        };
        let mut gram: Vec<Node> = t.gram.tau.iter().map(|&tau| node(tau)).collect();
        let (mut m00, mut m01) = (0.0, 0.0);
        for (j, nd) in gram.iter().enumerate() {
            let e2 = nd.cur.norm_sqr();
            m00 += pd.hm[j] * e2;
            m01 += pd.hm[j] * e2 * nd.off.re;
        }
        let mut out = Vec::with_capacity(count);
        for k in 0..count {
            let m0 = mu0 + k as f64 * step - pd.mu_c;
            let inside =
                kappa >= klo && kappa <= khi && m0.abs() <= lim && (m0 + offset).abs() <= lim;
            let (mut e0, mut e1, mut g00, mut g01, mut g11) = (0.0, 0.0, m00, m01, m00);
            let (mut y0, mut y1) = (0.0, 0.0);
            for (j, nd) in gram.iter_mut().enumerate() {
                let a0 = nd.cur;
                let a1 = a0 * nd.off;
                let ez = C64::new(pd.ez_re[j], pd.ez_im[j]);
                e0 += (ez * a0).re;
                e1 += (ez * a1).re;
                let z = C64::new(pd.zg_re[j], pd.zg_im[j]);
                y0 += (z * a0).re;
                y1 += (z * a1).re;
                let w = C64::new(pd.hd_re[j], pd.hd_im[j]) * nd.cur2;
                let wo = w * nd.off;
                g00 += w.re;
                g01 += wo.re;
                g11 += (wo * nd.off).re;
                nd.cur *= nd.rot;
                nd.cur2 *= nd.rot2;
            }
            if !inside {
                out.push(([0.0; 2], f64::INFINITY));
                continue;
            }
            let g = nalgebra::Matrix3::new(pd.n, e0, e1, e0, g00, g01, e1, g01, g11);
            let h = nalgebra::Vector3::new(pd.sy, y0 - self.y0 * e0, y1 - self.y0 * e1);
            out.push(match g.cholesky() {
                Some(c) => {
                    let b = c.solve(&h);
                    ([b[1], b[2]], (pd.syy - h.dot(&b)).max(0.0))
                }
                None => ([0.0; 2], f64::INFINITY),
            });
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::acquire::patterns::FringeAxis;
    use crate::solve::spectral::init::SpectrumPlans;
    use crate::solve::spectral::model::{Axis, FrameMeta, SeriesSamples};

    /// The paper's schedule (±45°, τ = 0.2…200) on a 1600×1200 screen, with
    /// a phase shift on every other τ so that the phases are exercised.
    fn design() -> Design {
        let dirs = [45.0, -45.0];
        let mut frames = Vec::new();
        for (d, _) in dirs.iter().enumerate() {
            for k in 0..1000 {
                frames.push(FrameMeta {
                    tau: 0.2 * (k + 1) as f64,
                    phase_cycles: if k % 2 == 0 { 0.0 } else { 0.25 },
                    dir: d,
                });
            }
        }
        Design {
            frames,
            axes: dirs
                .iter()
                .map(|&a| Axis::from_fringe(&FringeAxis::new(a, 1600, 1200)))
                .collect(),
            directions_deg: dirs.to_vec(),
        }
    }

    fn truth() -> Params {
        Params {
            k: 2,
            offset: 1800.0,
            amp: [900.0, 700.0, 0.0],
            uv: [[800.3, 600.7], [808.9, 603.1], [0.0; 2]],
            kappa: 1.3 / 200.0f64.powi(2),
        }
    }

    /// Counts of the model at `p` plus a deterministic ±`noise` pattern;
    /// every 97th sample clipped to 4095.
    fn series(design: &Design, p: &Params, noise: f64) -> Vec<u16> {
        design
            .frames
            .iter()
            .enumerate()
            .map(|(i, f)| {
                if i % 97 == 5 {
                    return 4095;
                }
                let ax = design.axes[f.dir];
                let e = (-p.kappa * f.tau * f.tau).exp();
                let mut v = p.offset;
                for j in 0..p.k {
                    let x = f.tau * ax.s(p.uv[j][0], p.uv[j][1]) + f.phase_cycles;
                    v += e * p.amp[j] * (std::f64::consts::TAU * x).cos();
                }
                let n = noise * ((i as f64 * 12.9898).sin() * 43758.5453).fract();
                (v + n).round().clamp(0.0, 4095.0) as u16
            })
            .collect()
    }

    /// The statistics give the series' RSS, JᵀJ and Jᵀr (to the node
    /// tolerance; relative 1e-8 leaves room for the sums' rounding), with
    /// clipped samples left out of both, at the truth and away from it.
    #[test]
    fn statistics_reproduce_the_series_normal_equations() {
        let design = design();
        let plans = SpectrumPlans::new(&design);
        let t = truth();
        let raw = series(&design, &t, 40.0);
        let centres: Vec<Vec<f64>> = design
            .axes
            .iter()
            .map(|ax| vec![0.5 * (ax.s(800.0, 600.0) + ax.s(809.0, 603.0))])
            .collect();
        let band: Vec<f64> = vec![3.0 / 199.8; 2];
        let k0 = 200.0f64.powi(-2);
        let mut stats =
            CompactStats::new(&design, &centres, &band, [-k0, 16.0 * k0], None).unwrap();
        for (r, chunk) in raw.chunks(STATS_BLOCK).enumerate() {
            stats.ingest(r * STATS_BLOCK, chunk.len(), chunk);
        }
        stats.seal();
        let (compact, excluded) = stats.samples(&design, 0, Some(4095)).unwrap();
        let y: Vec<f64> = raw
            .iter()
            .map(|&v| if v >= 4095 { f64::NAN } else { f64::from(v) })
            .collect();
        let series = SeriesSamples::new(&design, &plans, &y, k0);
        assert_eq!(excluded, raw.iter().filter(|&&v| v >= 4095).count());
        assert_eq!(compact.count(), series.count());
        let mut off = t;
        off.uv[0][0] += 3.0;
        off.uv[1][1] -= 2.0;
        off.kappa *= 1.7;
        off.amp[1] *= 0.8;
        let mut one = t;
        one.k = 1;
        for p in [t, off, one] {
            let a = series.normal(&p);
            let b = compact.normal(&p);
            let scale = a.jtj.abs().max();
            assert!(
                (a.rss - b.rss).abs() <= 1e-8 * a.rss,
                "rss {} vs {}",
                a.rss,
                b.rss
            );
            let dj = (&a.jtj - &b.jtj).abs().max();
            assert!(
                dj <= 1e-8 * scale,
                "JᵀJ differs by {dj} of {scale}\n{}\n{}",
                a.jtj,
                b.jtj
            );
            let dr = (&a.jtr - &b.jtr).abs().max();
            let rscale = a.jtr.abs().max().max(scale.sqrt() * a.rss.sqrt());
            assert!(
                dr <= 1e-8 * rscale,
                "Jᵀr differs by {dr} of {rscale}\n{}\n{}",
                a.jtr,
                b.jtr
            );
            for dir in [None, Some(0), Some(1)] {
                let (pa, ra) = series.linear(&p, dir);
                let (pb, rb) = compact.linear(&p, dir);
                assert!(
                    (ra - rb).abs() <= 1e-8 * ra.max(1.0),
                    "{dir:?}: {ra} vs {rb}"
                );
                assert!((pa.offset - pb.offset).abs() < 1e-6, "{dir:?}");
            }
        }
        // The pair scan's recurrences give the direct linear fits.
        for (d, ax) in design.axes.iter().enumerate() {
            let n2 = ax.a * ax.a + ax.b * ax.b;
            let point = |mu: f64| [(mu - ax.c) * ax.a / n2, (mu - ax.c) * ax.b / n2];
            let mu = ax.s(t.uv[0][0], t.uv[0][1]);
            let off = ax.s(t.uv[1][0], t.uv[1][1]) - mu;
            let args = [mu - 1.25 * off, 0.125 * off, off];
            let a = series.pair_scan(d, args, 13, k0, &point);
            let b = compact.pair_scan(d, args, 13, k0, &point);
            for ((aa, ra), (ab, rb)) in a.iter().zip(&b) {
                assert!((ra - rb).abs() <= 1e-8 * ra, "{d}: {ra} vs {rb}");
                assert!((aa[0] - ab[0]).abs() < 1e-6 && (aa[1] - ab[1]).abs() < 1e-6);
            }
        }
        // Past the acquisition's budget of set-aside samples the pixel is
        // given up, not fitted on sums that still hold its clipped samples.
        let mut tight =
            CompactStats::new(&design, &centres, &band, [-k0, 16.0 * k0], None).unwrap();
        tight.budget = 5;
        for (r, chunk) in raw.chunks(STATS_BLOCK).enumerate() {
            tight.ingest(r * STATS_BLOCK, chunk.len(), chunk);
        }
        tight.seal();
        assert!(tight.samples(&design, 0, Some(4095)).is_none());
        for d in 0..2 {
            let (ma, _) = series.peak(d).unwrap();
            let (mb, rb) = compact.peak(d).unwrap();
            assert!((ma - mb).abs() < 0.3 / 199.8, "{d}: {ma} vs {mb}");
            // Far above the detection threshold (a strong, clean signal).
            assert!(rb > 100.0, "{rb}");
        }
    }

    /// The portable code paths (taken on CPUs without AVX2/FMA, as CI's may
    /// be) give what the dispatched ones give, to rounding (FMA contracts
    /// products; 1e-12 relative is ~10⁴ ulps of slack over sums of ~10²).
    #[test]
    fn portable_paths_match_the_dispatched_ones() {
        let w: Vec<f64> = (0..4 * 88)
            .map(|k| ((k * 37 % 101) as f64 - 50.0) / 7.0)
            .collect();
        let items: Vec<(f64, usize)> = (0..7).map(|r| (100.0 + r as f64, (r % 4) * 88)).collect();
        let mut a = vec![0.5; 88];
        let mut b = a.clone();
        accumulate(&mut a, &items, &w, has_avx2_fma());
        accumulate(&mut b, &items, &w, false);
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() <= 1e-12 * x.abs().max(1.0), "{x} vs {y}");
        }
        let design = design();
        let t = truth();
        let raw = series(&design, &t, 40.0);
        let centres: Vec<Vec<f64>> = design
            .axes
            .iter()
            .map(|ax| vec![0.5 * (ax.s(800.0, 600.0) + ax.s(809.0, 603.0))])
            .collect();
        let k0 = 200.0f64.powi(-2);
        let band = vec![3.0 / 199.8; 2];
        let mut stats =
            CompactStats::new(&design, &centres, &band, [-k0, 16.0 * k0], None).unwrap();
        for (r, chunk) in raw.chunks(STATS_BLOCK).enumerate() {
            stats.ingest(r * STATS_BLOCK, chunk.len(), chunk);
        }
        stats.seal();
        let (c, _) = stats.samples(&design, 0, Some(4095)).unwrap();
        let mut scratch = Vec::new();
        for d in 0..2 {
            let (mut a, mut b) = (DirSums::zero(), DirSums::zero());
            c.dir_sums(d, &t, true, true, &mut a);
            c.dir_sums_body::<false>(d, &t, true, true, &mut scratch, &mut b);
            let close = |x: f64, y: f64| (x - y).abs() <= 1e-12 * x.abs().max(y.abs()).max(1.0);
            for x in 0..NX {
                assert!(close(a.e[x], b.e[x]) && close(a.y[x], b.y[x]), "{d} {x}");
                for y in 0..NX {
                    assert!(close(a.g[x][y], b.g[x][y]), "{d} {x} {y}");
                }
            }
        }
    }
}

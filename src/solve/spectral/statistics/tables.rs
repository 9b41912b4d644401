//! The schedule's tables that every pixel of an acquisition shares, per
//! fringe direction: the node sets, every frame's cardinals, and per grid
//! centre the sums `Σ L_j`, `Σ e^{iθ} L_j`, `Σ e^{2iθ} L_j` the products of
//! two columns need, with the periodogram's weights over the band.

use rayon::prelude::*;

use super::nodes::Nodes;
use super::{StatisticsError, C64, GRID_BINS};
use crate::kernels::sincos_cycles;
use crate::solve::spectral::model::Design;

/// Schedule tables of one fringe direction.
#[derive(Debug, Clone)]
pub(super) struct DirTables {
    /// Nodes of the data sums (Z) and of the products of two columns.
    pub(super) data: Nodes,
    pub(super) gram: Nodes,
    /// Cardinals of every frame of the direction (by position), row-major.
    pub(super) card_data: Vec<f64>,
    pub(super) card_gram: Vec<f64>,
    /// `L^gram_k(τ^data_j)`, row j: lifts data-node sums onto the product
    /// nodes (`Σ_j Z_j f(τ^data_j) = Σ_k Z'_k f(τ^gram_k)` for the smooth f
    /// both node sets hold), so one evaluation of the columns serves both.
    pub(super) lift: Vec<f64>,
    /// Grid step of the centres (μ), first grid index, count.
    pub(super) step: f64,
    pub(super) g0: i64,
    pub(super) ng: usize,
    /// Per grid point: E on data nodes; on gram nodes, as the fits read
    /// them (real and imaginary parts apart), E and ½D; and ½M.
    pub(super) ez_data: Vec<C64>,
    pub(super) ez_re: Vec<f64>,
    pub(super) ez_im: Vec<f64>,
    pub(super) hd_re: Vec<f64>,
    pub(super) hd_im: Vec<f64>,
    pub(super) hm: Vec<f64>,
    /// Half-width of the band around the centre, μ.
    pub(super) band: f64,
    /// One Fourier bin, μ.
    pub(super) bin: f64,
    /// Periodogram offsets δ (¼ bin apart over the band) and
    /// `w(τ_j) e^{2πiδτ_j}` on the data nodes, w the Hann window.
    pub(super) pdelta: Vec<f64>,
    pub(super) pw: Vec<C64>,
    /// Σ_i w(τ_i)² over the direction's frames.
    pub(super) w2: f64,
}

/// What the statistics of one acquisition share: the schedule's tables.
#[derive(Debug, Clone)]
pub struct StatisticsTables {
    pub(super) dirs: Vec<DirTables>,
    /// Per frame: (direction, position among the direction's frames).
    pub(super) frame_pos: Vec<(usize, usize)>,
    /// Per frame: τ and phase (cycles).
    pub(super) tau_phase: Vec<(f64, f64)>,
    pub(super) kappa_range: [f64; 2],
}

impl StatisticsTables {
    /// Tables for `design`; per direction, centres `centres[d]` (μ, one per
    /// pixel) with the band half-width `band[d]` (μ) around each; κ from
    /// `kappa_range`.
    pub(super) fn new(
        design: &Design,
        centres: &[Vec<f64>],
        band: &[f64],
        kappa_range: [f64; 2],
    ) -> Result<Self, StatisticsError> {
        let nd = design.axes.len();
        let mut frame_pos = vec![(0, 0); design.frames.len()];
        let mut per_dir: Vec<Vec<usize>> = vec![Vec::new(); nd];
        for (i, f) in design.frames.iter().enumerate() {
            frame_pos[i] = (f.dir, per_dir[f.dir].len());
            per_dir[f.dir].push(i);
        }
        let dirs = (0..nd)
            .map(|d| DirTables::new(design, d, &per_dir[d], &centres[d], band[d], kappa_range))
            .collect::<Result<Vec<_>, StatisticsError>>()?;
        Ok(StatisticsTables {
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

/// Per grid point of one direction, the schedule sums on the data nodes
/// (E) and on the product nodes (E and D), each grid point's concatenated.
struct GridSums {
    ez_data: Vec<C64>,
    ez_gram: Vec<C64>,
    dz: Vec<C64>,
}

impl DirTables {
    /// The tables of direction `d`, whose frames are `frames` (indices into
    /// the design, capture order), for the pixels' centres `centres` (μ)
    /// with band half-width `band` (μ). (About 80 lines: the node counts,
    /// the grid sums and the periodogram weights of one direction are built
    /// in one pass over its frames; split, each part would walk them again.)
    fn new(
        design: &Design,
        d: usize,
        frames: &[usize],
        centres: &[f64],
        band: f64,
        kappa_range: [f64; 2],
    ) -> Result<Self, StatisticsError> {
        let taus: Vec<f64> = frames.iter().map(|&i| design.frames[i].tau).collect();
        let lo = taus.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = taus.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let bin = 1.0 / (hi - lo).max(1e-9);
        let step = GRID_BINS * bin;
        let delta = band + 0.5 * step;
        let too_wide = || StatisticsError::BandTooWide {
            direction: d,
            band_bins: delta / bin,
            tau_max_min: kappa_range[1].max(1e-300).sqrt().recip(),
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
        let gi: Vec<i64> = centres.iter().map(|&m| (m / step).round() as i64).collect();
        let g0 = gi.iter().copied().min().unwrap_or(0);
        let ng = (gi.iter().copied().max().unwrap_or(0) - g0 + 1) as usize;
        let phases: Vec<f64> = frames
            .iter()
            .map(|&i| design.frames[i].phase_cycles)
            .collect();
        let sums = grid_sums(
            &taus,
            &phases,
            (g0, ng, step),
            &card_data,
            &card_gram,
            (qd, qg),
        );
        let (pdelta, pw, w2) = periodogram_weights(&taus, &data.tau, lo, bin, band);
        Ok(DirTables {
            data,
            gram,
            card_data,
            card_gram,
            lift,
            step,
            g0,
            ng,
            ez_data: sums.ez_data,
            ez_re: sums.ez_gram.iter().map(|z| z.re).collect(),
            ez_im: sums.ez_gram.iter().map(|z| z.im).collect(),
            hd_re: sums.dz.iter().map(|z| 0.5 * z.re).collect(),
            hd_im: sums.dz.iter().map(|z| 0.5 * z.im).collect(),
            hm: mz.iter().map(|m| 0.5 * m).collect(),
            band,
            bin,
            pdelta,
            pw,
            w2,
        })
    }
}

/// The periodogram over the band on the data nodes `nodes`: the offsets δ
/// (¼ bin apart within `band`, μ), `w(τ_j) e^{2πiδτ_j}` per offset and
/// node, w the Hann window over the direction's `taus` (from `lo`, one
/// Fourier bin `bin`), and `Σ_i w(τ_i)²`.
fn periodogram_weights(
    taus: &[f64],
    nodes: &[f64],
    lo: f64,
    bin: f64,
    band: f64,
) -> (Vec<f64>, Vec<C64>, f64) {
    let hann = |t: f64| {
        let x = std::f64::consts::PI * (t - lo) * bin;
        x.sin().powi(2)
    };
    let w2 = taus.iter().map(|&t| hann(t).powi(2)).sum();
    let nk = (band / (0.25 * bin)).floor() as i64;
    let pdelta: Vec<f64> = (-nk..=nk).map(|k| k as f64 * 0.25 * bin).collect();
    let mut pw = Vec::with_capacity(pdelta.len() * nodes.len());
    for &dl in &pdelta {
        for &t in nodes {
            let (c, s) = sincos_cycles(dl * t);
            pw.push(C64::new(c, s) * hann(t));
        }
    }
    (pdelta, pw, w2)
}

/// The schedule sums `Σ_i e^{iθ_i(μ_g)} L_j(τ_i)` (data and product nodes)
/// and `Σ_i e^{2iθ_i(μ_g)} L_j(τ_i)` (product nodes) at every grid point
/// `μ_g = (g0 + g) step`, `g < ng`, on all cores; `q = (data, product)`
/// node counts, the cardinals row-major per frame.
fn grid_sums(
    taus: &[f64],
    phases: &[f64],
    (g0, ng, step): (i64, usize, f64),
    card_data: &[f64],
    card_gram: &[f64],
    (qd, qg): (usize, usize),
) -> GridSums {
    let per_g: Vec<(Vec<C64>, Vec<C64>, Vec<C64>)> = (0..ng)
        .into_par_iter()
        .map(|g| {
            let mu = (g0 + g as i64) as f64 * step;
            let mut ed = vec![C64::new(0.0, 0.0); qd];
            let mut eg = vec![C64::new(0.0, 0.0); qg];
            let mut dg = vec![C64::new(0.0, 0.0); qg];
            for (k, (&t, &ph)) in taus.iter().zip(phases).enumerate() {
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
    let mut sums = GridSums {
        ez_data: Vec::with_capacity(ng * qd),
        ez_gram: Vec::with_capacity(ng * qg),
        dz: Vec::with_capacity(ng * qg),
    };
    for (a, b, c) in per_g {
        sums.ez_data.extend(a);
        sums.ez_gram.extend(b);
        sums.dz.extend(c);
    }
    sums
}

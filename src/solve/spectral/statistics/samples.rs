//! One pixel's statistics as the fits see them ([`StatisticsSamples`]):
//! its sums with the set-aside samples put back or subtracted from its copy
//! of the schedule sums, the band it may be fitted in, and the normal
//! equations and linear fits of the least squares ([`Samples`]).

use std::borrow::Cow;

use nalgebra::{DMatrix, DVector};

use super::ingest::SetAside;
use super::simd::lift;
use super::sums::DirSums;
use super::tables::StatisticsTables;
use super::{Statistics, C64, GRID_BINS};
use crate::kernels::sincos_cycles;
use crate::solve::spectral::model::{Design, Falloff, Normal, Params, Samples, MAX_PARAMS};

impl Statistics {
    /// Pixel `p`'s statistics with samples at 0 or at/above `saturation`
    /// excluded, and the number excluded; `None` when more than a quarter
    /// of its samples were clipped (given up at ingest). Needs [`Self::seal`].
    pub fn samples<'a>(
        &'a self,
        design: &'a Design,
        p: usize,
        saturation: Option<u16>,
    ) -> Option<(StatisticsSamples<'a>, usize)> {
        self.samples_with(design, p, saturation, None)
    }

    /// [`Self::samples`] with each clipped sample put back at the value
    /// `impute(frame, reading)` gives (its conditional mean under a model:
    /// [`crate::solve::spectral::model::censored`]) instead of left out;
    /// the count returned is still that of the clipped samples.
    pub fn samples_imputed<'a>(
        &'a self,
        design: &'a Design,
        p: usize,
        saturation: Option<u16>,
        impute: &dyn Fn(usize, u16) -> f64,
    ) -> Option<(StatisticsSamples<'a>, usize)> {
        self.samples_with(design, p, saturation, Some(impute))
    }

    fn samples_with<'a>(
        &'a self,
        design: &'a Design,
        p: usize,
        saturation: Option<u16>,
        impute: Option<&dyn Fn(usize, u16) -> f64>,
    ) -> Option<(StatisticsSamples<'a>, usize)> {
        if self.counts[p] > self.cap {
            return None;
        }
        let st = &self.state[p * self.stride..(p + 1) * self.stride];
        let z = &self.z[p * self.z_stride..(p + 1) * self.z_stride];
        let y0 = st[0];
        let mut dirs: Vec<PixelDir> = (0..self.tables.dirs.len())
            .map(|d| self.pixel_dir(p, d, (st, z)))
            .collect();
        let from = self.set_aside.partition_point(|s| (s.pixel as usize) < p);
        let to = self.set_aside.partition_point(|s| (s.pixel as usize) <= p);
        let mut excluded = 0;
        for s in &self.set_aside[from..to] {
            let pd = &mut dirs[self.tables.frame_pos[s.frame as usize].0];
            if s.value == 0 || saturation.is_some_and(|sat| s.value >= sat) {
                excluded += 1;
                match impute {
                    Some(f) => self.restore(pd, s, y0, f(s.frame as usize, s.value)),
                    None => self.exclude(pd, s),
                }
            } else {
                self.restore(pd, s, y0, f64::from(s.value));
            }
        }
        for (pd, t) in dirs.iter_mut().zip(&self.tables.dirs) {
            lift(&pd.z, &t.lift, &mut pd.zg_re, &mut pd.zg_im);
        }
        let n = dirs.iter().map(|d| d.n).sum();
        let sy = dirs.iter().map(|d| d.sy).sum();
        let syy = dirs.iter().map(|d| d.syy).sum();
        Some((
            StatisticsSamples {
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

    /// Direction `d` of pixel `p`, whose sums are `st` and Z `zs`: its Z (spare
    /// arrays, the lifted ones zeroed) and its grid point's schedule sums,
    /// borrowed.
    fn pixel_dir<'a>(&'a self, p: usize, d: usize, (st, zs): (&[f64], &[f32])) -> PixelDir<'a> {
        let t = &self.tables.dirs[d];
        let nd = self.tables.dirs.len();
        let q = t.data.len();
        let qg = t.gram.len();
        let (o, zo) = (self.offsets[d], self.z_offsets[d]);
        let g = self.grid[p * nd + d] as usize;
        let gram = g * qg..(g + 1) * qg;
        let (mut z, mut zg_re, mut zg_im) = spare();
        z.clear();
        z.extend(
            zs[zo..zo + 2 * q]
                .chunks_exact(2)
                .map(|c| C64::new(f64::from(c[0]), f64::from(c[1]))),
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
            sy: st[o],
            syy: st[o + 1],
            n: st[o + 2],
        }
    }

    /// `e^{iθ}` of the set-aside sample `s` at `pd`'s centre, with its
    /// frame's cardinals on the data and product nodes.
    fn set_aside_terms<'t>(&'t self, pd: &PixelDir, s: &SetAside) -> (C64, &'t [f64], &'t [f64]) {
        let (d, pos) = self.tables.frame_pos[s.frame as usize];
        let (tau, ph) = self.tables.tau_phase[s.frame as usize];
        let t = &self.tables.dirs[d];
        let (c, sn) = sincos_cycles(pd.mu_c * tau + ph);
        let (q, qg) = (t.data.len(), t.gram.len());
        let cd = &t.card_data[pos * q..(pos + 1) * q];
        let cg = &t.card_gram[pos * qg..(pos + 1) * qg];
        (C64::new(c, sn), cd, cg)
    }

    /// Leaves the clipped sample `s` out: subtracted from `pd`'s copy of
    /// the schedule sums (it was never in the data sums).
    fn exclude(&self, pd: &mut PixelDir, s: &SetAside) {
        let (e1, cd, cg) = self.set_aside_terms(pd, s);
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
    }

    /// Puts the set-aside sample `s` (not clipped after all, or clipped and
    /// standing at its imputed value) into `pd`'s data sums at value `y`,
    /// about the pixel's reference count `y0`.
    fn restore(&self, pd: &mut PixelDir, s: &SetAside, y0: f64, y: f64) {
        let (e1, cd, _) = self.set_aside_terms(pd, s);
        for (o, &l) in pd.z.iter_mut().zip(cd) {
            *o += e1 * (y * l);
        }
        pd.sy += y - y0;
        pd.syy += (y - y0) * (y - y0);
        pd.n += 1.0;
    }
}

/// One direction of one pixel: its statistics and the schedule sums of its
/// grid point (a copy only where clipped samples are subtracted from them).
#[derive(Debug, Clone)]
pub(super) struct PixelDir<'a> {
    pub(super) mu_c: f64,
    pub(super) z: Vec<C64>,
    /// On the product nodes, as arrays (real and imaginary parts apart):
    /// ½M, ½D, E and Z lifted from the data nodes.
    pub(super) hm: Cow<'a, [f64]>,
    pub(super) hd_re: Cow<'a, [f64]>,
    pub(super) hd_im: Cow<'a, [f64]>,
    pub(super) ez_re: Cow<'a, [f64]>,
    pub(super) ez_im: Cow<'a, [f64]>,
    pub(super) zg_re: Vec<f64>,
    pub(super) zg_im: Vec<f64>,
    pub(super) ez_data: Cow<'a, [C64]>,
    /// Σ(y − y0), Σ(y − y0)², samples.
    pub(super) sy: f64,
    pub(super) syy: f64,
    pub(super) n: f64,
}

/// One pixel's sufficient statistics, as the fits see them.
pub struct StatisticsSamples<'a> {
    pub(super) design: &'a Design,
    pub(super) tables: &'a StatisticsTables,
    pub(super) dirs: Vec<PixelDir<'a>>,
    /// Reference count; `sy`, `syy` are about it.
    pub(super) y0: f64,
    pub(super) n: f64,
    pub(super) sy: f64,
    pub(super) syy: f64,
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

impl Drop for StatisticsSamples<'_> {
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

impl StatisticsSamples<'_> {
    /// Whether `p` stays where the statistics hold (band and κ range), on
    /// direction `dir` alone when given.
    pub(super) fn inside(&self, p: &Params, margin_bins: f64, dir: Option<usize>) -> bool {
        let [klo, khi] = self.tables.kappa_range;
        if !p.kappa.within(klo, khi) {
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
            // The κ of other falloff groups: no column here (factor 0).
            let mut map = [(0usize, 0.0f64); MAX_PARAMS];
            for j in 0..k {
                map[1 + j] = (j, 1.0);
                map[1 + k + 2 * j] = (k + j, ax.a);
                map[2 + k + 2 * j] = (k + j, ax.b);
            }
            map[p.kappa_index(self.design.falloff_group[d])] = (2 * k, 1.0);
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

impl Samples for StatisticsSamples<'_> {
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
        self.band_peak(d)
    }

    fn within_band(&self, p: &Params) -> bool {
        let [klo, khi] = self.tables.kappa_range;
        // A quarter bin inside the band and 10 % inside the κ range: a fit
        // stopped at the edge by the bounds is not reported.
        p.kappa
            .values()
            .iter()
            .all(|&k| k > 0.9 * klo && k < 0.9 * khi)
            && self.inside(p, 0.25 + 0.5 * GRID_BINS, None)
    }

    fn band_limited(&self) -> bool {
        true
    }

    fn pair_scan(
        &self,
        dir: usize,
        scan: [f64; 3],
        count: usize,
        kappa: Falloff,
        _point: &dyn Fn(f64) -> [f64; 2],
    ) -> Vec<([f64; 2], f64)> {
        let kappa = kappa[self.design.falloff_group[dir]];
        self.band_pair_scan(dir, scan, count, kappa)
    }
}

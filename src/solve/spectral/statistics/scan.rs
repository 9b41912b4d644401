//! The searches over a pixel's band: the periodogram's strongest peak and
//! the scan of front/back pairs along one direction, both from the sums.

use super::samples::StatisticsSamples;
use super::{C64, GRID_BINS};
use crate::kernels::{exp_fast, sincos_cycles};
use crate::solve::spectral::periodogram::refine_peak;
use crate::solve::spectral::pixel::DETECTION_RATIO;

/// The band's strongest local maxima besides the peak tried for a second
/// sinusoid in [`StatisticsSamples::noise_variance`].
const SECOND_MAXIMA: usize = 4;

/// The extra sinusoids of [`StatisticsSamples::noise_variance`] are fitted
/// only where the peak is detected against one sinusoid's residual at
/// no less than 1/`PAIR_GATE` of the threshold.
const PAIR_GATE: f64 = 3.0;

impl StatisticsSamples<'_> {
    /// The strongest periodogram peak of direction `d` within the band,
    /// refined, with its power over the noise's median ([`Samples::peak`](crate::solve::spectral::model::Samples::peak)).
    pub(super) fn band_peak(&self, d: usize) -> Option<(f64, f64)> {
        self.band_peak_with(d, true)
    }

    /// [`Self::band_peak`] with the extra sinusoids of the noise estimate
    /// fitted only where they can decide detection (`gated`, [`PAIR_GATE`])
    /// or always.
    pub(super) fn band_peak_with(&self, d: usize, gated: bool) -> Option<(f64, f64)> {
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
        // [`super::pixel::DETECTION_RATIO`], which the series engine holds
        // against the periodogram's median over the whole spectrum, the
        // noise's. σ² is the residual variance after the band's signal
        // (the background and the peak's sinusoid, with a second one where
        // that leaves less: [`Self::noise_variance`]), not the series'
        // variance: that holds the signal too, and capped the ratio at ≈ n/2
        // times the falloff's share whatever the noise (a direction of 180
        // frames never reached 30: issue 39).
        let var = self
            .noise_variance(d, (&mus, &power, k), gated)
            .unwrap_or(var);
        let ratio = power[k] / (std::f64::consts::LN_2 * var * t.w2);
        if k == 0 || k + 1 == power.len() {
            // The strongest power is at the band's edge: the signal may lie
            // outside it.
            return Some((f64::NAN, ratio));
        }
        let (mu, _) = refine_peak(&mus, &power, 3.0 * t.bin)?;
        Some((mu, ratio))
    }

    /// The noise the periodogram's peak `k` (of `power` at `mus`) is held
    /// against: the residual variance of direction `d`'s samples after the
    /// least-squares background and a sinusoid of free phase at the peak,
    /// or, where it leaves less, after a second one too, at the band's next
    /// strongest maxima or half and one bin beside the peak (and then a
    /// third among the same). A pair in the
    /// band leaves its second reflection (or the beat of a pair merged in
    /// one peak) in one sinusoid's residual, which then holds signal, not
    /// noise: with a gap in the τ grid that pushed pixels whose pair the
    /// series finds below detection (spectral soak, seed 39058: 259 of 1033
    /// pixels). On pure noise the second sinusoid takes two of the n
    /// degrees of freedom and one noise peak, a few percent of σ² at most,
    /// far inside detection's margin (a noise peak sits ~10× the median
    /// power, detection at 30×). Never below the counts' rounding, 1/12
    /// count².
    fn noise_variance(
        &self,
        d: usize,
        (mus, power, k): (&[f64], &[f64], usize),
        gated: bool,
    ) -> Option<f64> {
        let one = self.residual_variance(d, &[mus[k]])?.max(1.0 / 12.0);
        // Only where it can decide detection: the peak not detected against
        // one sinusoid's residual, but within a factor PAIR_GATE of it (the
        // extra sinusoids must take over two thirds of that residual away;
        // a pure-noise band's peak sits ~4–10× its median power and is
        // skipped). Elsewhere the extra fits only cost time: on the
        // paper-sim station's full sensor, where ~10 000 candidates see no
        // fringe, they took the solve from 8 to 13 µs a pixel.
        let ratio = power[k] / (std::f64::consts::LN_2 * one * self.tables.dirs[d].w2);
        if gated && !(DETECTION_RATIO / PAIR_GATE..DETECTION_RATIO).contains(&ratio) {
            return Some(one);
        }
        // Candidates at least half a bin (two grid steps, ¼ bin each) from
        // the peak: the band's strongest local maxima, and the peak's sides.
        let mut maxima: Vec<usize> = (1..power.len().saturating_sub(1))
            .filter(|&i| i.abs_diff(k) >= 2 && power[i] >= power[i - 1] && power[i] >= power[i + 1])
            .collect();
        maxima.sort_by(|&a, &b| power[b].total_cmp(&power[a]));
        maxima.truncate(SECOND_MAXIMA);
        let sides = [k.wrapping_sub(2), k + 2, k.wrapping_sub(4), k + 4];
        let cands: Vec<usize> = maxima
            .into_iter()
            .chain(sides.into_iter().filter(|&i| i < power.len()))
            .collect();
        let (best, at) = cands
            .iter()
            .filter_map(|&i| Some((self.residual_variance(d, &[mus[k], mus[i]])?, i)))
            .fold((one, usize::MAX), |a, b| if b.0 < a.0 { b } else { a });
        // A third where the second helped: a pair's sidelobes in a gapped
        // grid, or a third reflection.
        let best = if at == usize::MAX {
            best
        } else {
            cands
                .iter()
                .filter(|&&i| i.abs_diff(at) >= 2)
                .filter_map(|&i| self.residual_variance(d, &[mus[k], mus[at], mus[i]]))
                .fold(best, f64::min)
        };
        Some(best.max(1.0 / 12.0))
    }

    /// The residual variance of direction `d`'s samples after the
    /// least-squares background and a sinusoid of free phase (two
    /// quadratures) at each of `mus`, with the falloff the scans start from
    /// (κ0, the κ range's `[−κ0, 16κ0]`): `RSS / (n − 1 − 2·len)`. `None`
    /// without a sample to spare or where the fit is singular.
    fn residual_variance(&self, d: usize, mus: &[f64]) -> Option<f64> {
        let pd = &self.dirs[d];
        let t = &self.tables.dirs[d];
        let kappa = (-self.tables.kappa_range[0]).max(0.0);
        let q = t.gram.len();
        let m = 1 + 2 * mus.len();
        if pd.n <= m as f64 + 1.0 {
            return None;
        }
        // The columns on the product nodes, each sinusoid's and its
        // quadrature's (·i).
        let mut cols: Vec<C64> = Vec::with_capacity((m - 1) * q);
        for &mu in mus {
            let first = cols.len();
            cols.extend(
                t.gram
                    .tau
                    .iter()
                    .map(|&tau| cis((mu - pd.mu_c) * tau) * exp_fast(-kappa * tau * tau)),
            );
            for j in 0..q {
                let c = cols[first + j];
                cols.push(C64::new(-c.im, c.re));
            }
        }
        let col = |x: usize| &cols[x * q..(x + 1) * q];
        let mut g = nalgebra::DMatrix::<f64>::zeros(m, m);
        let mut h = nalgebra::DVector::<f64>::zeros(m);
        g[(0, 0)] = pd.n;
        h[0] = pd.sy;
        for x in 1..m {
            let cx = col(x - 1);
            let (mut e, mut y) = (0.0, 0.0);
            for (j, c) in cx.iter().enumerate() {
                e += (C64::new(pd.ez_re[j], pd.ez_im[j]) * c).re;
                y += (C64::new(pd.zg_re[j], pd.zg_im[j]) * c).re;
            }
            g[(0, x)] = e;
            g[(x, 0)] = e;
            h[x] = y - self.y0 * e;
            for z in x..m {
                // ½Re(M a b̄) + ½Re(D a b), ½M and ½D as the tables hold them.
                let v: f64 = cx
                    .iter()
                    .zip(col(z - 1))
                    .enumerate()
                    .map(|(j, (a, b))| {
                        pd.hm[j] * (a * b.conj()).re
                            + (C64::new(pd.hd_re[j], pd.hd_im[j]) * a * b).re
                    })
                    .sum();
                g[(x, z)] = v;
                g[(z, x)] = v;
            }
        }
        let sol = g.cholesky()?.solve(&h);
        let rss = (pd.syy - h.dot(&sol)).max(0.0);
        rss.is_finite().then(|| rss / (pd.n - m as f64))
    }

    /// The linear fits of `count` front/back pairs along direction `dir`
    /// ([`Samples::pair_scan`](crate::solve::spectral::model::Samples::pair_scan)): the pairs' columns at node τ are
    /// `a0 = e ρ0 r^k`, `a1 = a0 o`, with `e = e^{−κτ²}`,
    /// `ρ0 = e^{2πi(μ0 − μc)τ}`, `r = e^{2πi·step·τ}`,
    /// `o = e^{2πi·offset·τ}`: one complex product per pair and node
    /// instead of two sine–cosines and an exponential. The M part of the
    /// products is the same for every pair: `½Σ M e²` (|a|²) and
    /// `½Σ M e² cos(2π·offset·τ)` (Re a0 ā1).
    pub(super) fn band_pair_scan(
        &self,
        dir: usize,
        [mu0, step, offset]: [f64; 3],
        count: usize,
        kappa: f64,
    ) -> Vec<([f64; 2], f64)> {
        let pd = &self.dirs[dir];
        let t = &self.tables.dirs[dir];
        let [klo, khi] = self.tables.kappa_range;
        let lim = t.band + 0.5 * GRID_BINS * t.bin;
        let mut gram: Vec<PairNode> = t
            .gram
            .tau
            .iter()
            .map(|&tau| PairNode::new(tau, kappa, [mu0 - pd.mu_c, step, offset]))
            .collect();
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
            let sums = self.pair_sums(dir, &mut gram, [m00, m01]);
            out.push(if inside {
                self.pair_fit(dir, &sums)
            } else {
                ([0.0; 2], f64::INFINITY)
            });
        }
        out
    }

    /// The sums of the current pair over the product nodes — `[e0, e1,
    /// g00, g01, g11, y0, y1]`: constant, products and data with its two
    /// columns, `m` the shared M parts — with every node then stepped to
    /// the next pair.
    fn pair_sums(&self, dir: usize, gram: &mut [PairNode], [m00, m01]: [f64; 2]) -> [f64; 7] {
        let pd = &self.dirs[dir];
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
        [e0, e1, g00, g01, g11, y0, y1]
    }

    /// The pair's linear fit (offset and two amplitudes) from its sums
    /// ([`Self::pair_sums`]): the amplitudes and the RSS.
    fn pair_fit(&self, dir: usize, &[e0, e1, g00, g01, g11, y0, y1]: &[f64; 7]) -> ([f64; 2], f64) {
        let pd = &self.dirs[dir];
        let g = nalgebra::Matrix3::new(pd.n, e0, e1, e0, g00, g01, e1, g01, g11);
        let h = nalgebra::Vector3::new(pd.sy, y0 - self.y0 * e0, y1 - self.y0 * e1);
        match g.cholesky() {
            Some(c) => {
                let b = c.solve(&h);
                ([b[1], b[2]], (pd.syy - h.dot(&b)).max(0.0))
            }
            None => ([0.0; 2], f64::INFINITY),
        }
    }
}

/// One product node of the pair scan: the current pair's front column
/// (`cur`) and its square, the steps to the next pair, and the back
/// column's factor `o`.
struct PairNode {
    cur: C64,
    cur2: C64,
    rot: C64,
    rot2: C64,
    off: C64,
}

impl PairNode {
    /// At node `tau`, for `[μ0 − μc, step, offset]`.
    fn new(tau: f64, kappa: f64, [start, step, offset]: [f64; 3]) -> Self {
        let e = exp_fast(-kappa * tau * tau);
        let off = cis(offset * tau);
        let cur = cis(start * tau) * e;
        let rot = cis(step * tau);
        PairNode {
            cur,
            cur2: cur * cur,
            rot,
            rot2: rot * rot,
            off,
        }
    }
}

/// `e^{2πix}`.
fn cis(x: f64) -> C64 {
    let (c, s) = sincos_cycles(x);
    C64::new(c, s)
}

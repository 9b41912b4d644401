//! One candidate's samples as the fits see them, after the solve: its
//! series or statistics, the clipped samples left out or standing at their
//! conditional means.

use super::SpectralSolver;
use crate::solve::spectral::model::censored::Clip;
use crate::solve::spectral::model::{eval_row, Params, Samples, SeriesSamples, MAX_PARAMS};

impl SpectralSolver {
    /// [`Self::with_samples`] with the clipped samples standing at their
    /// conditional means under the model at `p` with noise `sigma`
    /// ([`crate::solve::spectral::model::censored`]) instead of left out: a least-squares fit on them has
    /// the censored likelihood's gradient at `p`.
    pub fn with_samples_at<R>(
        &self,
        q: usize,
        p: &Params,
        sigma: f64,
        f: impl FnOnce(&dyn Samples, usize) -> R,
    ) -> Option<R> {
        if self.phase.is_some() || q >= self.prior.candidates.len() {
            return None;
        }
        let sat = self.saturation();
        let clip = Clip::new(sat);
        let level = |i: usize, v: u16| {
            let mut row = [0.0; MAX_PARAMS];
            let mu = eval_row(&self.design, &self.design.frames[i], p, &mut row);
            clip.imputed(v, mu, sigma)
        };
        if let Some(stats) = &self.stats {
            let (data, clipped) = stats.samples_imputed(&self.design, q, sat, &level)?;
            return Some(f(&data, clipped));
        }
        let n = self.frames();
        let mut clipped = 0;
        let y: Vec<f64> = self.series[q * n..(q + 1) * n]
            .iter()
            .enumerate()
            .map(|(i, &v)| {
                if v == 0 || sat.is_some_and(|s| v >= s) {
                    clipped += 1;
                    level(i, v)
                } else {
                    f64::from(v)
                }
            })
            .collect();
        let data = SeriesSamples::new(&self.design, &self.plans, &y, self.kappa_start());
        Some(f(&data, clipped))
    }

    /// `f` of candidate `q`'s samples as the fits see them (its series, or
    /// its statistics with that engine; clipped samples left out), with
    /// the number left out; `None` where the pixel has too many clipped
    /// samples to be fitted, or the schedule is a phase-shifting one (its
    /// path keeps no per-pixel model of this kind).
    pub fn with_samples<R>(&self, q: usize, f: impl FnOnce(&dyn Samples, usize) -> R) -> Option<R> {
        if self.phase.is_some() || q >= self.prior.candidates.len() {
            return None;
        }
        let sat = self.saturation();
        if let Some(stats) = &self.stats {
            let (data, excluded) = stats.samples(&self.design, q, sat)?;
            return Some(f(&data, excluded));
        }
        let n = self.frames();
        let mut excluded = 0;
        let y: Vec<f64> = self.series[q * n..(q + 1) * n]
            .iter()
            .map(|&v| {
                if v == 0 || sat.is_some_and(|s| v >= s) {
                    excluded += 1;
                    f64::NAN
                } else {
                    f64::from(v)
                }
            })
            .collect();
        let data = SeriesSamples::new(&self.design, &self.plans, &y, self.kappa_start());
        Some(f(&data, excluded))
    }
}

//! Clipped samples in the least squares.
//!
//! A camera reports 0 for any level below half a count and its full scale
//! for any at or above full scale less half a count: such a sample is
//! censored — it says only that the level lay beyond the clip. Leaving it
//! out keeps the samples that happened to stay inside, so near a fringe's
//! trough the kept samples sit above the model and a fit moves to meet
//! them. Pixel by pixel the shift is a small fraction of the noise, but it
//! is the same in every pixel whose troughs reach the dark level: where two
//! reflections of nearly one frequency beat (thin or high-index plates,
//! whose bright Fresnel reflections push the dark level below the read
//! noise) it is a smooth bias over the pupil, many times the surfaces' σ.
//!
//! The censored (Tobit) likelihood's score of a clipped sample equals a
//! Gaussian sample's score at the sample's conditional mean under the model
//! and the clip, `E[y | y < c] = μ − σ φ(α)/Φ(α)` with `α = (c − μ)/σ` (and
//! mirrored at the top). So a least-squares fit in which each clipped
//! sample stands at that conditional mean, taken at the current parameters,
//! has the censored likelihood's gradient there; refreshed at every
//! iteration (the EM algorithm for censored data) its fixed point is the
//! censored maximum-likelihood estimate. The Gauss–Newton information
//! counts each clipped sample as a full one, which over-states it by the
//! clipped share of a pixel's samples (at most a quarter: pixels with more
//! are given up), and far less where few are clipped.
//!
//! Written by hand: the conditional mean is two lines on `libm::erfc`.

use std::f64::consts::{FRAC_1_SQRT_2, PI};

/// Where a camera's counts clip, as levels: a reading of 0 means a level
/// below `low`, a reading at the saturation count one at or above `high`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Clip {
    /// Levels below this read 0: half a count.
    pub low: f64,
    /// Levels at or above this read the saturation count (half a count
    /// below it); `None` when no saturation is known.
    pub high: Option<f64>,
}

impl Clip {
    /// The clip of a camera whose saturation count is `saturation`.
    pub fn new(saturation: Option<u16>) -> Self {
        Clip {
            low: 0.5,
            high: saturation.map(|s| f64::from(s) - 0.5),
        }
    }

    /// The conditional mean of clipped reading `value` (0, or the
    /// saturation count) under a model level `mu` with noise `sigma`,
    /// kept within [`REACH`] σ of the clip.
    ///
    /// A light level is never below 0, so at the bottom the mean lies
    /// within ~0.8σ of the clip for any physical model; a model that puts
    /// the level further beyond a clip than that is not describing this
    /// pixel's data yet (a start far off, κ running away), and its
    /// conditional mean would pull the pixel's fit after it.
    pub fn imputed(&self, value: u16, mu: f64, sigma: f64) -> f64 {
        let reach = REACH * sigma.max(0.0);
        match (value, self.high) {
            (0, _) | (_, None) => mean_below(mu, sigma, self.low).max(self.low - reach),
            (_, Some(high)) => (-mean_below(-mu, sigma, -high)).min(high + reach),
        }
    }
}

/// How far beyond its clip, in σ, a clipped sample is put at most.
pub const REACH: f64 = 4.0;

/// `E[y | y < c]` for `y ~ N(mu, sigma²)`: `mu − sigma φ(α)/Φ(α)`,
/// `α = (c − mu)/sigma`. Tends to `c` where the clip lies far below the
/// model (Φ underflows) and to `mu` where it lies far above it.
pub fn mean_below(mu: f64, sigma: f64, c: f64) -> f64 {
    // No noise (or a NaN σ): the level itself, at most the clip.
    if sigma.is_nan() || sigma <= 0.0 {
        return mu.min(c);
    }
    let a = (c - mu) / sigma;
    // Φ(α) through erfc keeps its relative accuracy in the lower tail.
    let cdf = 0.5 * libm::erfc(-a * FRAC_1_SQRT_2);
    let pdf = (-0.5 * a * a).exp() / (2.0 * PI).sqrt();
    let mills = pdf / cdf;
    if !(cdf > 1e-290 && mills.is_finite()) {
        return c;
    }
    (mu - sigma * mills).min(c)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The conditional mean against a direct quadrature of the truncated
    /// normal, over clips from far below to far above the model: the
    /// quadrature (Simpson, 20 000 panels over ±12σ) is exact to ~1e-10σ.
    #[test]
    fn mean_below_matches_quadrature() {
        let (mu, sigma) = (3.0, 2.0);
        for &a in &[-8.0, -3.0, -1.0, 0.0, 0.7, 2.5, 6.0] {
            let c = mu + a * sigma;
            let lo = mu - 12.0 * sigma;
            let n = 20_000;
            let h = (c - lo) / n as f64;
            let (mut m0, mut m1) = (0.0, 0.0);
            for i in 0..=n {
                let x = lo + i as f64 * h;
                let w = if i == 0 || i == n {
                    1.0
                } else if i % 2 == 1 {
                    4.0
                } else {
                    2.0
                };
                let d = (-0.5 * ((x - mu) / sigma).powi(2)).exp();
                m0 += w * d;
                m1 += w * d * x;
            }
            let want = m1 / m0;
            let got = mean_below(mu, sigma, c);
            assert!((got - want).abs() < 1e-8 * sigma, "α {a}: {got} vs {want}");
        }
    }

    /// The limits: a clip far below the model (a reading of 0 the model
    /// cannot explain) stands at the clip; one far above it at the model.
    #[test]
    fn limits_and_the_top_clip() {
        assert_eq!(mean_below(100.0, 1.0, 0.5), 0.5);
        assert!((mean_below(0.0, 1.0, 40.0) - 0.0).abs() < 1e-12);
        let clip = Clip::new(Some(4095));
        // A saturated reading: above 4094.5, mirrored from the bottom.
        let top = clip.imputed(4095, 4094.5, 10.0);
        let want = 4094.5 + 10.0 * (2.0 / PI).sqrt();
        assert!((top - want).abs() < 1e-9, "{top} vs {want}");
        let bottom = clip.imputed(0, 0.5, 10.0);
        assert!((bottom - (0.5 - 10.0 * (2.0 / PI).sqrt())).abs() < 1e-9);
    }
}

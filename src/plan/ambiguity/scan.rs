//! The ambiguity function scanned over the screen in time linear in the
//! distinct τ values. A direct scan calls `cos` once per frame per step, and
//! its steps grow with the largest τ: for a uniform schedule both grow with
//! the frame count, so 100 000 frames (50 000 τ per direction up to τ =
//! 500) took 54 s of `mfd plan`'s 96 (issue 37). Here frames of one τ
//! (repeats, phase steps) are one term with their summed weight, and each
//! term's `cos(2π τ k δ)` advances by one complex rotation per step,
//! recomputed exactly every [`RESYNC`] steps.

use std::f64::consts::TAU;

/// Steps between exact recomputations of every term. A rotation by a unit
/// complex number rounded to 1 ulp adds at most a few ulp of error per
/// step, so 256 steps keep each term within ~1e-13 of its cosine: far
/// below anything [`super::SIDELOBE_MAX`] is compared with.
pub(super) const RESYNC: usize = 256;

/// The normalised correlation `Σ_f e_f² cos(2π τ_f Δ) / Σ_f e_f²` at
/// `Δ = k·step`, `k = 1, 2, …` ([`super::ambiguity_at`]'s value).
pub(super) struct Scan {
    tau: Vec<f64>,
    weight: Vec<f64>,
    /// `cos` and `sin` of each term's angle at the current step.
    re: Vec<f64>,
    im: Vec<f64>,
    /// The rotation of one step, `e^{i 2π τ step}`.
    rot_re: Vec<f64>,
    rot_im: Vec<f64>,
    sum: f64,
    step: f64,
    k: usize,
}

impl Scan {
    /// The scan of `taus` (any order, repeats allowed) with falloff `kappa`.
    pub(super) fn new(taus: &[f64], kappa: f64, step: f64) -> Scan {
        let mut sorted = taus.to_vec();
        sorted.sort_by(f64::total_cmp);
        let (mut tau, mut weight) = (Vec::new(), Vec::<f64>::new());
        for t in sorted {
            let e2 = (-2.0 * kappa * t * t).exp();
            match tau.last() {
                Some(&last) if last == t => *weight.last_mut().expect("one per τ") += e2,
                _ => {
                    tau.push(t);
                    weight.push(e2);
                }
            }
        }
        let (rot_im, rot_re) = tau.iter().map(|&t| (TAU * t * step).sin_cos()).unzip();
        Scan {
            sum: weight.iter().sum(),
            re: vec![1.0; tau.len()],
            im: vec![0.0; tau.len()],
            tau,
            weight,
            rot_re,
            rot_im,
            step,
            k: 0,
        }
    }

    /// The value at the next step.
    pub(super) fn next_value(&mut self) -> f64 {
        self.k += 1;
        if self.k % RESYNC == 0 {
            let d = self.k as f64 * self.step;
            for ((t, re), im) in self.tau.iter().zip(&mut self.re).zip(&mut self.im) {
                (*im, *re) = (TAU * t * d).sin_cos();
            }
        } else {
            let rot = self.rot_re.iter().zip(&self.rot_im);
            for ((re, im), (rr, ri)) in self.re.iter_mut().zip(&mut self.im).zip(rot) {
                (*re, *im) = (*re * rr - *im * ri, *re * ri + *im * rr);
            }
        }
        if self.sum > 0.0 {
            self.weight
                .iter()
                .zip(&self.re)
                .map(|(w, c)| w * c)
                .sum::<f64>()
                / self.sum
        } else {
            0.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn follows_the_direct_sum_over_many_resyncs() {
        // Uneven τ with repeats and a falloff; 3000 steps cross 11 resyncs.
        let taus: Vec<f64> = (0..400).map(|k| 0.37 + 0.61 * (k % 150) as f64).collect();
        let (kappa, step) = (1.0 / 150.0f64.powi(2), 1.0 / (32.0 * 91.0));
        let mut scan = Scan::new(&taus, kappa, step);
        for k in 1..=3000 {
            let direct = super::super::ambiguity_at(&taus, kappa, k as f64 * step);
            let fast = scan.next_value();
            // The rotation's drift over < 256 steps (~1e-13) plus the
            // sums' different order: 1e-12 absolute on a value in [-1, 1].
            assert!(
                (fast - direct).abs() < 1e-12,
                "step {k}: {fast} vs {direct}"
            );
        }
    }
}

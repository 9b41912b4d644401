//! Temporal phase unwrapping: per (direction, τ) the wrapped phase of τ·s
//! from the least-squares cosine over the group's phase steps, and per
//! direction the fringe coordinate s that makes every τ's phase agree,
//! carried up from the lowest τ (hierarchical unwrapping). Hand-written: a
//! 3 × 3 solve and a loop over the lowest τ's fringe orders.

use super::{Group, PhaseSchedule};
use crate::solve::spectral::model::Design;

/// Range of the fringe coordinate searched: the screen's `[0, 1]` (off
/// the screen there is no pattern to see) and a margin of 10⁻³ for the
/// noise of a point at the edge. With integer τ the patterns repeat with
/// period 1 in s, so a point within the margin of s = 0 or 1 is
/// ambiguous, and reported so ([`Unwrapped::runner_up`]).
const S_RANGE: [f64; 2] = [-1e-3, 1.0 + 1e-3];

/// A group's wrapped phase.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wrapped {
    /// `τ s` modulo 1, cycles in `[0, 1)`.
    pub frac: f64,
    /// Amplitude of the cosine, counts.
    pub amp: f64,
    /// Samples used.
    pub samples: usize,
}

/// The least-squares `a + C cos 2πφ + S sin 2πφ` of the group's finite
/// samples; `None` with fewer than three distinct phases among them.
pub fn wrapped(design: &Design, group: &Group, y_by_frame: &[f64]) -> Option<Wrapped> {
    let used: Vec<u32> = group
        .frames
        .iter()
        .copied()
        .filter(|&i| y_by_frame[i as usize].is_finite())
        .collect();
    if super::distinct_phases(design, &used) < super::MIN_PHASES {
        return None;
    }
    let mut g = [[0.0; 3]; 3];
    let mut h = [0.0; 3];
    for &i in &used {
        let (s, c) = (std::f64::consts::TAU * design.frames[i as usize].phase_cycles).sin_cos();
        let row = [1.0, c, s];
        let y = y_by_frame[i as usize];
        for a in 0..3 {
            h[a] += row[a] * y;
            for b in 0..3 {
                g[a][b] += row[a] * row[b];
            }
        }
    }
    let m = nalgebra::Matrix3::from_fn(|a, b| g[a][b]);
    let sol = m.cholesky()?.solve(&nalgebra::Vector3::from(h));
    // y = a + B cos(2π(τs + φ)) = a + B cos θ cos 2πφ − B sin θ sin 2πφ.
    let (c, s) = (sol[1], sol[2]);
    let theta = (-s).atan2(c) / std::f64::consts::TAU;
    Some(Wrapped {
        frac: theta.rem_euclid(1.0),
        amp: c.hypot(s),
        samples: used.len(),
    })
}

/// One direction unwrapped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Unwrapped {
    /// The fringe coordinate.
    pub s: f64,
    /// Its score `Σ_τ n_τ B_τ² wrap(τ s − frac_τ)²` (cycles² counts²):
    /// `2π² score / σ²` is the χ² of the phases at noise σ.
    pub score: f64,
    /// The best score of a candidate that differs from `s` by more than half
    /// the finest period (infinite when there is none).
    pub runner_up: f64,
}

/// The distance of `x` to the nearest integer, signed.
fn wrap(x: f64) -> f64 {
    x - x.round()
}

/// Direction `d` unwrapped from its groups' wrapped phases `phases` (one
/// per group of the schedule, `None` where not measurable); `None` when no
/// group of the direction is measurable.
pub fn unwrap_direction(
    schedule: &PhaseSchedule,
    d: usize,
    phases: &[Option<Wrapped>],
) -> Option<Unwrapped> {
    let used: Vec<(f64, Wrapped)> = schedule
        .of_direction(d)
        .filter_map(|k| phases[k].map(|w| (schedule.groups[k].tau, w)))
        .collect();
    let &(tau0, w0) = used.first()?;
    let finest = used.last().map_or(tau0, |u| u.0);
    let score = |s: f64| {
        used.iter()
            .map(|(t, w)| w.samples as f64 * w.amp * w.amp * wrap(t * s - w.frac).powi(2))
            .sum::<f64>()
    };
    let k_lo = (S_RANGE[0] * tau0 - w0.frac).floor() as i64;
    let k_hi = (S_RANGE[1] * tau0 - w0.frac).ceil() as i64;
    let mut cands: Vec<(f64, f64)> = (k_lo..=k_hi)
        .map(|k| {
            let mut s = (w0.frac + k as f64) / tau0;
            for (t, w) in &used[1..] {
                let order = (t * s - w.frac).round();
                s = (w.frac + order) / t;
            }
            (s, score(s))
        })
        .filter(|(s, _)| (S_RANGE[0]..=S_RANGE[1]).contains(s))
        .collect();
    cands.sort_by(|a, b| a.1.total_cmp(&b.1));
    let &(s, best) = cands.first()?;
    let runner_up = cands
        .iter()
        .find(|(c, _)| (c - s).abs() > 0.5 / finest)
        .map_or(f64::INFINITY, |c| c.1);
    Some(Unwrapped {
        s,
        score: best,
        runner_up,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solve::spectral::model::{Axis, FrameMeta};

    fn design(taus: &[f64]) -> Design {
        let frames = taus
            .iter()
            .flat_map(|&tau| {
                (0..4).map(move |k| FrameMeta {
                    tau,
                    phase_cycles: k as f64 / 4.0,
                    dir: 0,
                })
            })
            .collect();
        Design::new(
            frames,
            vec![Axis {
                a: 1e-3,
                b: 0.0,
                c: 0.0,
                stretch: 1.0,
            }],
            vec![0.0],
        )
    }

    /// Noise-free cosines at any s come back exactly, for τ sets whose
    /// lowest τ is 1 and for ones that start higher (4, 7, 10, 13: periods
    /// differing by 3, which alias a periodogram every third of the screen).
    #[test]
    fn exact_cosines_unwrap_to_their_coordinate() {
        for taus in [vec![1.0, 4.0, 16.0, 64.0], vec![4.0, 7.0, 10.0, 13.0]] {
            let d = design(&taus);
            let sched = PhaseSchedule::detect(&d).unwrap();
            for s_true in [0.013, 0.2817, 0.5, 0.6543, 0.987] {
                let y: Vec<f64> = d
                    .frames
                    .iter()
                    .map(|f| {
                        100.0
                            + 50.0
                                * (std::f64::consts::TAU * (f.tau * s_true + f.phase_cycles)).cos()
                    })
                    .collect();
                let w: Vec<Option<Wrapped>> =
                    sched.groups.iter().map(|g| wrapped(&d, g, &y)).collect();
                let u = unwrap_direction(&sched, 0, &w).unwrap();
                assert!(
                    (u.s - s_true).abs() < 1e-12,
                    "{taus:?}: {} vs {s_true}",
                    u.s
                );
                assert!(u.score < 1e-12 && u.runner_up > 1.0, "{u:?}");
            }
        }
    }
}

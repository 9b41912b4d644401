//! Fringe patterns: the one place that defines what the screen shows.
//!
//! A [`Pattern`] is `(direction_deg, tau, phase_rad)`; its normalised
//! intensity at screen point `(u, v)` is `g = 0.5 + 0.5 cos(2π τ s + φ)` with
//! the fringe coordinate `s(u, v)` of the interchange spec, running over
//! `[0, 1]` across the screen. A [`Schedule`] is the ordered list of patterns
//! of one measurement. The display and the simulated camera both use these
//! functions; nothing else computes fringes.

use std::f64::consts::TAU;

/// The most frames one schedule, schedule file or acquisition may hold.
/// The paper's schedule is 2 000 frames; 100 000 is 50 times that, 28
/// minutes of patterns at a display's 60 Hz, and a 250 GB stack of
/// 1296×966 16-bit frames: beyond it a schedule is a typing error (a step
/// of 0.001 for 0.1), not a measurement, and expanding it would exhaust
/// memory before anything is shown.
pub const MAX_FRAMES: usize = 100_000;

/// Errors in a pattern schedule.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ScheduleError {
    /// A schedule parameter is out of range.
    #[error("schedule: `{field}`: {problem}")]
    Invalid {
        /// The parameter (CLI flag or field) name.
        field: &'static str,
        /// What is wrong.
        problem: String,
    },
}

impl crate::outcome::Classify for ScheduleError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        Some(Outcome::Input)
    }
}

/// One displayed pattern.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pattern {
    /// Fringe direction θ, degrees (±45 diagonals, 0, 90).
    pub direction_deg: f64,
    /// Number of fringe periods across the screen (the spec's τ).
    pub tau: f64,
    /// Phase offset, radians.
    pub phase_rad: f64,
}

impl Pattern {
    /// Normalised displayed intensity `g ∈ [0, 1]` at fringe coordinate `s`.
    pub fn intensity_at(&self, s: f64) -> f64 {
        0.5 + 0.5 * (TAU * self.tau * s + self.phase_rad).cos()
    }
}

/// The fringe coordinate of one direction on one screen:
/// `s(u, v) = (u cos θ + v sin θ − s0) / L` (spec, "Fringe patterns").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FringeAxis {
    cos: f64,
    sin: f64,
    s0: f64,
    inv_l: f64,
    /// Screen pixels per unit of `s` (the spec's `L`).
    pub length_px: f64,
}

impl FringeAxis {
    /// The axis of direction `direction_deg` on a `width × height` screen.
    pub fn new(direction_deg: f64, width: u32, height: u32) -> Self {
        let (sin, cos) = direction_deg.to_radians().sin_cos();
        let (w, h) = (f64::from(width), f64::from(height));
        let proj = [0.0, w * cos, h * sin, w * cos + h * sin];
        let s0 = proj.iter().copied().fold(f64::INFINITY, f64::min);
        let s1 = proj.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let length_px = s1 - s0;
        FringeAxis {
            cos,
            sin,
            s0,
            inv_l: 1.0 / length_px,
            length_px,
        }
    }

    /// `s(u, v)`, dimensionless, in `[0, 1]` on the screen.
    #[inline]
    pub fn s(&self, u: f64, v: f64) -> f64 {
        (u * self.cos + v * self.sin - self.s0) * self.inv_l
    }

    /// How much finer this direction's fringes are on the screen than the
    /// diagonals' at equal τ, `L₄₅ / L` (1 on ±45°; 1.24 at 0° and 1.65 at
    /// 90° on a 1600 × 1200 screen): the factor on τ of a falloff that
    /// acts on the fringe's period in screen pixels.
    pub fn stretch_from_diagonal(&self, width: u32, height: u32) -> f64 {
        FringeAxis::new(45.0, width, height).length_px / self.length_px
    }

    /// κ of this direction under a blur that acts on the fringe's period
    /// in screen pixels, `kappa_diagonal` being the diagonals':
    /// `κ (L₄₅ / L)²` (the falloff `e(ℓτ)` of [`Self::stretch_from_diagonal`]).
    pub fn physical_kappa(&self, kappa_diagonal: f64, width: u32, height: u32) -> f64 {
        let l = self.stretch_from_diagonal(width, height);
        kappa_diagonal * l * l
    }

    /// The largest τ this screen can show in this direction: the display's
    /// Nyquist limit. Pixel centres sample the fringe; one period spans
    /// `L / τ` screen pixels along the fringe direction (`s` runs over
    /// `[0, 1]` across `L` px), and a period needs at least 2 pixels to be
    /// shown as a fringe rather than an alias of a coarser one:
    /// `L / τ ≥ 2`, so `τ ≤ L / 2`.
    pub fn max_tau(&self) -> f64 {
        self.length_px / 2.0
    }

    /// Gradient `(∂s/∂u, ∂s/∂v)`, per screen pixel.
    pub fn gradient(&self) -> (f64, f64) {
        (self.cos * self.inv_l, self.sin * self.inv_l)
    }
}

/// An ordered set of patterns: for each direction, for each τ, for each phase.
#[derive(Debug, Clone, PartialEq)]
pub struct Schedule {
    /// Fringe directions, degrees, in display order.
    pub directions_deg: Vec<f64>,
    /// First τ.
    pub tau_start: f64,
    /// Last τ (included when it falls on the grid).
    pub tau_stop: f64,
    /// τ increment.
    pub tau_step: f64,
    /// Phase offsets, radians, shown at every τ (`[0]` for none).
    pub phases_rad: Vec<f64>,
}

impl Default for Schedule {
    /// The paper's schedule (§3, §4.3): ±45°, τ = 0.2 … 200 step 0.2, no phase shift.
    fn default() -> Self {
        Schedule {
            directions_deg: vec![45.0, -45.0],
            tau_start: 0.2,
            tau_stop: 200.0,
            tau_step: 0.2,
            phases_rad: vec![0.0],
        }
    }
}

impl Schedule {
    /// Checks the parameters.
    ///
    /// # Errors
    /// [`ScheduleError::Invalid`] naming the parameter.
    pub fn validate(&self) -> Result<(), ScheduleError> {
        let bad = |field, problem: String| Err(ScheduleError::Invalid { field, problem });
        if self.directions_deg.is_empty() || self.directions_deg.iter().any(|d| !d.is_finite()) {
            return bad(
                "directions",
                format!("expected finite angles, found {:?}", self.directions_deg),
            );
        }
        if !(self.tau_start.is_finite() && self.tau_start > 0.0) {
            return bad(
                "tau-start",
                format!("expected τ > 0, found {}", self.tau_start),
            );
        }
        if !(self.tau_step.is_finite() && self.tau_step > 0.0) {
            return bad(
                "tau-step",
                format!("expected a step > 0, found {}", self.tau_step),
            );
        }
        if !(self.tau_stop.is_finite() && self.tau_stop >= self.tau_start) {
            return bad(
                "tau-stop",
                format!(
                    "expected ≥ tau-start {}, found {}",
                    self.tau_start, self.tau_stop
                ),
            );
        }
        if self.phases_rad.is_empty() || self.phases_rad.iter().any(|p| !p.is_finite()) {
            return bad(
                "phases",
                format!("expected finite phases, found {:?}", self.phases_rad),
            );
        }
        // Counted before anything is expanded: τ up to 1e9 in steps of 0.001
        // is 1e12 values, which `taus()` must never be asked to allocate.
        let per_direction = self.tau_count();
        let frames = per_direction * (self.directions_deg.len() * self.phases_rad.len()) as f64;
        if frames.is_nan() || frames > MAX_FRAMES as f64 {
            return bad(
                "tau-step",
                format!(
                    "{frames:.0} frames ({per_direction:.0} τ values × {} directions × {} \
                     phases): above the {MAX_FRAMES} frames a schedule may have",
                    self.directions_deg.len(),
                    self.phases_rad.len()
                ),
            );
        }
        Ok(())
    }

    /// How many τ values [`Schedule::taus`] gives, as a float so that no
    /// schedule overflows the count.
    fn tau_count(&self) -> f64 {
        ((self.tau_stop - self.tau_start) / self.tau_step + 1e-9).floor() + 1.0
    }

    /// Checks that a `width × height` screen can show every τ of the
    /// schedule in every direction ([`FringeAxis::max_tau`]). Call after
    /// [`Schedule::validate`].
    ///
    /// # Errors
    /// [`ScheduleError::Invalid`] naming `tau-stop`, the direction and the limit.
    pub fn check_against_screen(&self, width: u32, height: u32) -> Result<(), ScheduleError> {
        let last = self.tau_start + (self.tau_count() - 1.0).max(0.0) * self.tau_step;
        match first_beyond_screen(
            self.directions_deg.iter().map(|&d| (d, last)),
            width,
            height,
        ) {
            None => Ok(()),
            Some((_, problem)) => Err(ScheduleError::Invalid {
                field: "tau-stop",
                problem,
            }),
        }
    }

    /// The τ values, computed as `start + k·step` (no accumulated rounding);
    /// a stop within 1e-9 steps of the grid is included.
    pub fn taus(&self) -> Vec<f64> {
        let n = ((self.tau_stop - self.tau_start) / self.tau_step + 1e-9).floor() as usize + 1;
        (0..n)
            .map(|k| self.tau_start + k as f64 * self.tau_step)
            .collect()
    }

    /// Every pattern in display order.
    pub fn patterns(&self) -> Vec<Pattern> {
        let taus = self.taus();
        let mut out =
            Vec::with_capacity(self.directions_deg.len() * taus.len() * self.phases_rad.len());
        for &direction_deg in &self.directions_deg {
            for &tau in &taus {
                for &phase_rad in &self.phases_rad {
                    out.push(Pattern {
                        direction_deg,
                        tau,
                        phase_rad,
                    });
                }
            }
        }
        out
    }
}

/// The first `(direction_deg, tau)` of `patterns` that a `width × height`
/// screen cannot show ([`FringeAxis::max_tau`]): its index and what is
/// wrong, in words that name the value and the allowed range.
pub fn first_beyond_screen(
    patterns: impl IntoIterator<Item = (f64, f64)>,
    width: u32,
    height: u32,
) -> Option<(usize, String)> {
    patterns
        .into_iter()
        .enumerate()
        .find_map(|(index, (direction_deg, tau))| {
            let max = FringeAxis::new(direction_deg, width, height).max_tau();
            (tau.is_nan() || tau > max).then(|| {
                (
                    index,
                    format!(
                        "τ = {tau} is above the {max:.2} a {width}x{height} px screen can show \
                         at {direction_deg}° (a fringe period needs ≥ 2 screen pixels: τ ≤ L/2, \
                         L = {:.1} px across the screen along the fringe direction)",
                        2.0 * max
                    ),
                )
            })
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_schedule_has_1000_taus_per_direction() {
        let s = Schedule::default();
        let taus = s.taus();
        assert_eq!(taus.len(), 1000);
        assert_eq!(taus[0], 0.2);
        // 0.2 + 999 · 0.2 rounds to 200 within one ulp of 200 (2.8e-14).
        assert!((taus[999] - 200.0).abs() < 1e-12);
        assert_eq!(s.patterns().len(), 2000);
    }

    #[test]
    fn fringe_coordinate_spans_the_screen() {
        for dir in [45.0, -45.0, 0.0, 90.0, 30.0, 180.0] {
            let a = FringeAxis::new(dir, 1600, 1200);
            let corners = [(0.0, 0.0), (1600.0, 0.0), (0.0, 1200.0), (1600.0, 1200.0)];
            let s: Vec<f64> = corners.iter().map(|&(u, v)| a.s(u, v)).collect();
            let lo = s.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = s.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            // By construction s0 and L come from these corners: exact up to rounding.
            assert!(
                lo.abs() < 1e-12 && (hi - 1.0).abs() < 1e-12,
                "{dir}: {lo} {hi}"
            );
        }
        // +45°: L = (W + H)/√2 (closed form).
        let a = FringeAxis::new(45.0, 1600, 1200);
        assert!((a.length_px - 2800.0 / 2f64.sqrt()).abs() < 1e-9);
    }

    /// Issue 19: τ up to 1e9 in steps of 0.001 aborted out of memory in
    /// `mfd simulate` (1e12 τ values expanded before any check).
    #[test]
    fn a_schedule_of_a_trillion_frames_is_refused_before_expansion() {
        let s = Schedule {
            tau_stop: 1e9,
            tau_step: 0.001,
            ..Schedule::default()
        };
        let err = s.validate().unwrap_err().to_string();
        assert!(err.contains("tau-step") && err.contains("100000"), "{err}");
        // The limit itself is allowed: 2 directions × 50 000 τ.
        let s = Schedule {
            tau_start: 1.0,
            tau_stop: 50_000.0,
            tau_step: 1.0,
            ..Schedule::default()
        };
        assert_eq!(s.validate(), Ok(()));
    }

    #[test]
    fn nyquist_limit_of_the_screen() {
        // +45° on 1600×1200: L = 2800/√2 = 1979.9 px, τ ≤ L/2 = 989.95.
        let a = FringeAxis::new(45.0, 1600, 1200);
        assert!((a.max_tau() - 1400.0 / 2f64.sqrt()).abs() < 1e-9);
        // 0°: L = W = 1600 px, τ ≤ 800.
        assert_eq!(FringeAxis::new(0.0, 1600, 1200).max_tau(), 800.0);
        let ok = Schedule::default();
        assert_eq!(ok.check_against_screen(1600, 1200), Ok(()));
        let s = Schedule {
            tau_stop: 1000.0,
            ..Schedule::default()
        };
        let err = s.check_against_screen(1600, 1200).unwrap_err().to_string();
        assert!(err.contains("tau-stop") && err.contains("989.95"), "{err}");
        assert_eq!(
            first_beyond_screen([(0.0, 800.0), (0.0, 800.5)], 1600, 1200).map(|e| e.0),
            Some(1)
        );
        assert!(first_beyond_screen([(0.0, f64::NAN)], 1600, 1200).is_some());
    }

    #[test]
    fn bad_schedules_name_the_parameter() {
        let s = Schedule {
            tau_step: 0.0,
            ..Schedule::default()
        };
        let err = s.validate().unwrap_err();
        assert!(err.to_string().contains("tau-step"), "{err}");
    }
}

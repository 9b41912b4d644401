//! How long an acquisition takes: the sequencer shows a pattern, waits for
//! the display's next refresh and its settle time (`hw/display/*.toml`,
//! `settle_ms`), then takes frames at the camera's frame period (the
//! exposure, or the camera's rate where that is slower). A repeat of the
//! pattern on screen (the same direction, τ and phase right after it) costs
//! one frame period and no settle.

use serde::Serialize;

use crate::acquire::acquisition::FrameInfo;
use crate::optics::station::DisplayProfile;

use super::{invalid, PlanError};

/// The paper's LCD profile's settle time, ms (`hw/display/mtiph-e2m21gm.toml`).
pub const DEFAULT_SETTLE_MS: f64 = 30.0;

/// The timing of one station's acquisition.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Timing {
    /// The display's settle time after a new pattern is presented, ms.
    pub settle_ms: f64,
    /// The display's refresh rate, Hz (a new pattern waits up to one refresh).
    pub display_rate_hz: f64,
    /// The camera's exposure, ms.
    pub exposure_ms: f64,
    /// The camera's largest frame rate, Hz.
    pub camera_rate_hz: f64,
}

impl Default for Timing {
    /// The paper's LCD (30 ms settle, 60 Hz), a 10 ms exposure and the
    /// paper's camera's 30 frames/s.
    fn default() -> Self {
        Timing {
            settle_ms: DEFAULT_SETTLE_MS,
            display_rate_hz: 60.0,
            exposure_ms: 10.0,
            camera_rate_hz: 30.0,
        }
    }
}

impl Timing {
    /// The default timing with a display profile's settle time.
    pub fn with_profile(profile: &DisplayProfile) -> Self {
        Timing {
            settle_ms: profile.settle_ms,
            ..Timing::default()
        }
    }

    /// Checks the ranges.
    ///
    /// # Errors
    /// [`PlanError::Invalid`] naming the option.
    pub fn validate(&self) -> Result<(), PlanError> {
        for (name, v, zero_ok) in [
            ("settle_ms", self.settle_ms, true),
            ("--display-rate-hz", self.display_rate_hz, false),
            ("--exposure-ms", self.exposure_ms, false),
            ("--camera-rate-hz", self.camera_rate_hz, false),
        ] {
            if !(v.is_finite() && (v > 0.0 || (zero_ok && v == 0.0))) {
                return Err(invalid(
                    name,
                    format!("expected a positive number, found {v}"),
                ));
            }
        }
        Ok(())
    }

    /// Seconds between two frames of one pattern.
    pub fn frame_s(&self) -> f64 {
        (self.exposure_ms * 1e-3).max(1.0 / self.camera_rate_hz)
    }

    /// Seconds a new pattern costs before its first frame.
    pub fn switch_s(&self) -> f64 {
        1.0 / self.display_rate_hz + self.settle_ms * 1e-3
    }

    /// Seconds to acquire `frames` in their order.
    pub fn seconds(&self, frames: &[FrameInfo]) -> f64 {
        let switches = switches(frames);
        switches as f64 * self.switch_s() + frames.len() as f64 * self.frame_s()
    }
}

/// How many times the screen changes pattern: the frames that are not a
/// repeat of the one before.
pub fn switches(frames: &[FrameInfo]) -> usize {
    frames
        .iter()
        .enumerate()
        .filter(|(k, f)| {
            *k == 0 || {
                let p = &frames[k - 1];
                (p.direction_deg, p.tau, p.phase_rad) != (f.direction_deg, f.tau, f.phase_rad)
            }
        })
        .count()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn repeats_cost_no_settle() {
        let f = |index, tau| FrameInfo {
            index,
            direction_deg: 45.0,
            tau,
            phase_rad: 0.0,
        };
        let frames = [f(0, 1.0), f(1, 1.0), f(2, 2.0), f(3, 1.0)];
        assert_eq!(switches(&frames), 3);
        let t = Timing::default();
        // Closed form: 3 switches of (1/60 + 0.030) s and 4 frames of 1/30 s.
        let want = 3.0 * (1.0 / 60.0 + 0.030) + 4.0 / 30.0;
        assert!((t.seconds(&frames) - want).abs() < 1e-12);
    }
}

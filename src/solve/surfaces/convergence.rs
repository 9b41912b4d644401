//! How every stage of the surface solvers ended, said aloud: whether it
//! converged or stopped at its iteration limit, and then how large its last
//! step was against the σ of what it moved. A stage that stops at its
//! limit with a last step larger than that σ has not reached the fit: its
//! answer is off by about the step, more than the uncertainty reported with
//! it, and the result is flagged ([`Convergence::flags_result`]) unless a
//! later stage refitted the same surfaces from there.

use serde::{Deserialize, Serialize};

use super::solve::Stage;

/// The size of a stage's last step against its uncertainty.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StepSize {
    /// The last step, nm: of the coefficient that moved most in units of
    /// its σ (a Levenberg–Marquardt stage), or the length of the change of
    /// the coefficient vector (the slope iteration).
    pub step_nm: f64,
    /// The σ it is measured against, nm: that coefficient's, or the length
    /// of the coefficient σ vector (√ of the covariance's trace).
    pub sigma_nm: f64,
}

impl StepSize {
    /// The step in units of its σ (infinite for a zero σ).
    pub fn in_sigma(&self) -> f64 {
        if self.step_nm == 0.0 {
            0.0
        } else if self.sigma_nm > 0.0 {
            self.step_nm / self.sigma_nm
        } else {
            f64::INFINITY
        }
    }
}

/// One stage's ending, as `summary.json`'s `convergence` lists it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Convergence {
    /// The stage ("front slopes", "back", "joint", …, "surface-domain fit",
    /// "spectral per-pixel fits").
    pub stage: String,
    /// Why it stopped, in words ("iteration limit 30", "step below …").
    pub stopped_by: String,
    /// Whether its stopping rule was met (not stopped by a limit).
    pub converged: bool,
    /// The last step, nm (see [`StepSize`]); absent where not measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub last_step_nm: Option<f64>,
    /// The σ the step is measured against, nm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_nm: Option<f64>,
    /// The last step in units of that σ.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step_in_sigma: Option<f64>,
    /// Pixels that stopped at their limit (the per-pixel fits).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pixels: Option<usize>,
    /// Whether a later stage refitted the same surfaces from this one's end
    /// (so its ending does not decide the result).
    #[serde(default)]
    pub superseded: bool,
    /// Whether this ending flags the result: not converged, the last step
    /// larger than its σ (or not measured), and not superseded.
    pub flags_result: bool,
}

impl Convergence {
    /// A stage's ending; `flags_result` follows from the rest.
    pub fn new(
        stage: &str,
        stopped_by: String,
        converged: bool,
        step: Option<StepSize>,
        superseded: bool,
    ) -> Convergence {
        let in_sigma = step.map(|s| s.in_sigma());
        let beyond_sigma = in_sigma.is_none_or(|r| r.is_nan() || r > 1.0);
        Convergence {
            stage: stage.into(),
            stopped_by,
            converged,
            last_step_nm: step.map(|s| s.step_nm),
            sigma_nm: step.map(|s| s.sigma_nm),
            step_in_sigma: in_sigma.filter(|r| r.is_finite()),
            pixels: None,
            superseded,
            flags_result: !converged && beyond_sigma && !superseded,
        }
    }

    /// The ending in one line for the console, e.g. "joint: stopped by
    /// iteration limit 30, last step 12.3 nm = 4.1 σ (σ 3.0 nm)".
    pub fn describe(&self) -> String {
        let mut s = format!("{}: stopped by {}", self.stage, self.stopped_by);
        if let (Some(step), Some(sigma)) = (self.last_step_nm, self.sigma_nm) {
            let r = self
                .step_in_sigma
                .map_or_else(|| "∞".into(), |r| format!("{r:.3}"));
            s += &format!(", last step {step:.4} nm = {r} σ (σ {sigma:.4} nm)");
        }
        if let Some(n) = self.pixels {
            s += &format!(" in {n} pixels");
        }
        s += if self.converged {
            ""
        } else if self.pixels.is_some() {
            ": those pixels are flagged NOT_CONVERGED in flags.npy"
        } else if self.flags_result {
            ": not converged, the result is flagged"
        } else if self.superseded {
            ": not converged; a later stage refitted from there"
        } else if self.step_in_sigma.is_some_and(|r| r <= 1.0) {
            ": not converged, within its σ"
        } else {
            ": not converged"
        };
        s
    }
}

/// The ending of every stage of a surface solve, in order. A stage counts
/// as superseded when a later joint stage (front and back on S1 and S2)
/// refitted the surfaces from its end.
pub fn of_stages(stages: &[Stage]) -> Vec<Convergence> {
    stages
        .iter()
        .enumerate()
        .filter_map(|(k, s)| {
            let superseded = stages[k + 1..].iter().any(|l| l.name.starts_with("joint"));
            if let Some(f) = &s.front {
                let stopped_by = if f.converged {
                    format!("change below {} nm", super::front::CHANGE_TOL_NM)
                } else {
                    format!("iteration limit {}", f.iterations)
                };
                let step = StepSize {
                    step_nm: f.last_change_nm,
                    sigma_nm: f.sigma_nm,
                };
                let step = step.step_nm.is_finite().then_some(step);
                return Some(Convergence::new(
                    s.name,
                    stopped_by,
                    f.converged,
                    step,
                    superseded,
                ));
            }
            let l = s.lm.as_ref()?;
            Some(Convergence::new(
                s.name,
                l.reason.clone(),
                l.converged,
                l.last_step,
                superseded,
            ))
        })
        .collect()
}

/// Whether any ending in `list` flags the result.
pub fn flagged(list: &[Convergence]) -> bool {
    list.iter().any(|c| c.flags_result)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solve::surfaces::lm::LmReport;

    fn lm_stage(name: &'static str, converged: bool, step: Option<StepSize>) -> Stage {
        Stage {
            name,
            seconds: 0.0,
            front: None,
            lm: Some(LmReport {
                iterations: 30,
                chi2_start: 1.0,
                chi2: 1.0,
                n_resid: 10,
                converged,
                reason: if converged {
                    "step below 0.0001 nm".into()
                } else {
                    "iteration limit 30".into()
                },
                failed: [0, 0],
                last_step: step,
            }),
        }
    }

    const BEYOND: StepSize = StepSize {
        step_nm: 3.0,
        sigma_nm: 1.0,
    };
    const WITHIN: StepSize = StepSize {
        step_nm: 0.5,
        sigma_nm: 1.0,
    };

    /// The rule: flagged only when not converged, beyond σ (or not
    /// measured), and the last word on its surfaces.
    #[test]
    fn only_a_last_stage_stopped_beyond_its_sigma_flags() {
        let c = |conv, step, sup| Convergence::new("s", String::new(), conv, step, sup);
        assert!(c(false, Some(BEYOND), false).flags_result);
        assert!(c(false, None, false).flags_result);
        assert!(!c(false, Some(WITHIN), false).flags_result);
        assert!(!c(false, Some(BEYOND), true).flags_result);
        assert!(!c(true, Some(BEYOND), false).flags_result);
        assert_eq!(c(false, Some(BEYOND), false).step_in_sigma, Some(3.0));
    }

    /// A stage refitted by a later joint stage is superseded; the last one
    /// decides.
    #[test]
    fn a_later_joint_stage_supersedes() {
        let stages = [
            lm_stage("back", false, Some(BEYOND)),
            lm_stage("joint", false, Some(BEYOND)),
        ];
        let list = of_stages(&stages);
        assert!(list[0].superseded && !list[0].flags_result);
        assert!(!list[1].superseded && list[1].flags_result);
        assert!(flagged(&list));
        let list = of_stages(&stages[..1]);
        assert!(list[0].flags_result, "back with no joint after it decides");
        let fine = [
            lm_stage("back", false, Some(BEYOND)),
            lm_stage("joint", true, Some(WITHIN)),
        ];
        assert!(!flagged(&of_stages(&fine)));
    }
}

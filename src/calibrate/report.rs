//! The calibration's report: each step's residuals by block against the
//! noise each block expects, χ²/dof, what was held and why, with the
//! normal matrix's condition numbers, and the readings that stand out of
//! their noise (a marked screen pixel whose reading disagrees with the
//! calibrated screen: a wrong reading). Serialised to `report.json` and
//! printed as a short summary for the operator.

use nalgebra::Matrix2;
use serde::Serialize;

use super::adjust::{Adjusted, Selection};
use super::input::CalibrationInput;
use super::residuals::{raw, Blocks, Whitening};
use super::spread::chi2_quantile_999;
use super::weak::WeakDirection;

/// One residual block's figures at the end of a step.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BlockReport {
    /// `flat_points`, `element_points`, `targets`, `flat_map` or
    /// `screen_points`.
    pub name: &'static str,
    /// The unit of the RMS figures.
    pub unit: &'static str,
    /// Residual count (readings, or 2-D points).
    pub count: usize,
    /// RMS residual (per coordinate).
    pub rms: f64,
    /// RMS the block's noise alone would give (per coordinate).
    pub expected_rms: f64,
    /// χ² of the block's whitened residuals.
    pub chi2: f64,
}

/// One step of the calibration.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StepReport {
    /// `resection`, `screen` or `joint`.
    pub name: &'static str,
    /// Trial steps of its least squares.
    pub trials: usize,
    /// Why its least squares stopped (`SmallDecrease`, `Stalled`, …).
    pub stop: String,
    /// χ² of the data at its end.
    pub chi2: f64,
    /// The priors' part of the cost at its end (`Σ ((x − nominal)/prior)²`).
    pub prior_chi2: f64,
    /// Residuals minus what the estimated parameters take of them.
    pub dof: usize,
    /// `chi2 / dof` (≈ 1 when the model and the stated noise hold).
    pub chi2_per_dof: f64,
    /// What it estimated and held.
    pub selection: Selection,
    /// Combinations of the estimated parameters that the data leave at
    /// their priors ([`super::weak`]), worst first.
    pub weak: Vec<WeakDirection>,
    /// Its residual blocks.
    pub blocks: Vec<BlockReport>,
    /// Readings whose whitened residual lies beyond χ²'s 99.9 % quantile
    /// for its dimension, worst first. Only the last step's (the joint
    /// adjustment's, against all the data) say that a reading is wrong:
    /// an earlier step fits part of the station with the rest still rough.
    pub suspects: Vec<Suspect>,
}

/// A reading that stands out of its noise.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Suspect {
    /// The session entry, `screen_point[3]`.
    pub entry: String,
    /// Its residual's length, in the block's unit.
    pub residual: f64,
    /// Its whitened residual's squared length (χ² of the reading).
    pub chi2: f64,
    /// In the operator's words, with what to do.
    pub message: String,
}

/// The marked screen pixels' block and its suspects: residuals in mm (the
/// predicted focus against the reading, world frame), each against the
/// stage noise and its focus spread (`w` the whiteners).
fn screen_points(
    e: &[nalgebra::Vector3<f64>],
    w: &[nalgebra::Matrix3<f64>],
) -> (BlockReport, Vec<Suspect>) {
    let (r, _) = rms(e.iter().flat_map(|v| [v.x, v.y, v.z]));
    let var: f64 = w
        .iter()
        .map(|l| l.try_inverse().map_or(f64::NAN, |c| c.norm_squared() / 3.0))
        .sum();
    let chi: Vec<f64> = e
        .iter()
        .zip(w)
        .map(|(v, l)| (l * v).norm_squared())
        .collect();
    let limit = chi2_quantile_999(3.0);
    let mut suspects: Vec<Suspect> = e
        .iter()
        .zip(&chi)
        .enumerate()
        .filter(|(_, (_, &c))| c > limit)
        .map(|(k, (v, &c))| Suspect {
            entry: format!("screen_point[{k}]"),
            residual: v.norm(),
            chi2: c,
            message: format!(
                "screen_point[{k}]: the reading is {:.4} mm from where the calibrated screen puts \
                 the mark's focus (χ² {c:.1} over 3 axes, 99.9 % of readings stay below \
                 {limit:.1}): wrong reading or wrong mark? Read it again",
                v.norm()
            ),
        })
        .collect();
    suspects.sort_by(|a, b| b.chi2.total_cmp(&a.chi2));
    let block = BlockReport {
        name: "screen_points",
        unit: "mm",
        count: e.len(),
        rms: r,
        expected_rms: (var / e.len().max(1) as f64).sqrt(),
        chi2: chi.iter().sum(),
    };
    (block, suspects)
}

/// The whole report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// The steps, in order.
    pub steps: Vec<StepReport>,
    /// What the calibration takes as given or could not determine, in words.
    pub notes: Vec<String>,
    /// The estimates `mfd-station-uncertainty/1` has no name for (the
    /// cover glass's thickness, the camera's aspect ratio): their value
    /// and σ from the joint step, here only.
    pub beside_the_uncertainty_file: Vec<Estimate>,
}

/// One estimated parameter's value and 1 σ.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Estimate {
    /// Its name ([`super::params::Param::name`]).
    pub name: &'static str,
    /// The calibrated value.
    pub value: f64,
    /// 1 σ from the joint step's covariance.
    pub std: f64,
}

fn rms(values: impl Iterator<Item = f64>) -> (f64, usize) {
    let (mut s, mut n) = (0.0, 0);
    for v in values {
        s += v * v;
        n += 1;
    }
    (if n > 0 { (s / n as f64).sqrt() } else { 0.0 }, n)
}

fn block_2d(
    name: &'static str,
    unit: &'static str,
    e: &[nalgebra::Vector2<f64>],
    w: &[Matrix2<f64>],
) -> BlockReport {
    let (r, _) = rms(e.iter().flat_map(|v| [v.x, v.y]));
    let var: f64 = w
        .iter()
        .map(|l| l.try_inverse().map_or(f64::NAN, |c| c.norm_squared() / 2.0))
        .sum::<f64>();
    let chi2 = e.iter().zip(w).map(|(v, l)| (l * v).norm_squared()).sum();
    BlockReport {
        name,
        unit,
        count: e.len(),
        rms: r,
        expected_rms: (var / e.len().max(1) as f64).sqrt(),
        chi2,
    }
}

impl StepReport {
    /// The figures of one adjusted step over its blocks.
    pub fn new(name: &'static str, input: &CalibrationInput, a: &Adjusted, blocks: Blocks) -> Self {
        let r = raw(input, &a.state, blocks);
        let w = Whitening::at(input, &a.state).ok();
        let s_um = input.stage_std_mm * 1000.0;
        let mut out = Vec::new();
        let mut suspects = Vec::new();
        for (on, bname, v) in [
            (blocks.flat_points, "flat_points", &r.flat_points),
            (blocks.element_points, "element_points", &r.element_points),
        ] {
            if on && !v.is_empty() {
                let (x, n) = rms(v.iter().map(|z| z * 1000.0));
                out.push(BlockReport {
                    name: bname,
                    unit: "um",
                    count: n,
                    rms: x,
                    expected_rms: s_um,
                    chi2: v.iter().map(|z| (z * 1000.0 / s_um).powi(2)).sum(),
                });
            }
        }
        if let Some(w) = &w {
            if blocks.targets {
                out.push(block_2d("targets", "px", &r.targets, &w.targets));
            }
            if blocks.flat_map {
                out.push(block_2d("flat_map", "screen px", &r.flat_map, &w.flat_map));
            }
            if blocks.screen_points && !r.screen_points.is_empty() {
                let (b, s) = screen_points(&r.screen_points, &w.screen_points);
                out.push(b);
                suspects = s;
            }
        }
        StepReport {
            name,
            trials: a.trials,
            stop: format!("{:?}", a.stop),
            chi2: a.chi2,
            prior_chi2: a.prior_chi2,
            dof: a.dof,
            chi2_per_dof: a.chi2 / a.dof.max(1) as f64,
            selection: a.selection.clone(),
            weak: a.weak.clone(),
            blocks: out,
            suspects,
        }
    }
}

impl Report {
    /// The report of a calibration's steps, with the notes the session implies.
    pub fn new(input: &CalibrationInput, steps: Vec<StepReport>) -> Self {
        let mut notes = vec![format!(
            "element thickness {} ± {} mm and index {} ± {} taken from the session as given",
            input.thickness_mm.0,
            input.thickness_mm.1,
            input.refractive_index.0,
            input.refractive_index.1
        )];
        if input.element_points_stage_mm.is_empty() {
            notes.push(
                "no element points: the element is taken to stand on the reference plane, its \
                 height and tilts held with the σ placing it where the flat stood leaves open"
                    .into(),
            );
        }
        if input.nominal.screen.cover_glass.is_some() {
            notes.push(
                "the screen's cover-glass index is taken from the nominal station; its \
                 thickness is estimated where the flat's rays determine it, but it is not a \
                 degree of freedom of mfd-station-uncertainty/1 and its σ is in report.json only"
                    .into(),
            );
        }
        if !input.screen_points.is_empty() {
            notes.push(format!(
                "{} marked screen pixels: the PSM is taken to look along the stage's z axis{}",
                input.screen_points.len(),
                if input.nominal.screen.cover_glass.is_some() {
                    "; through the cover glass its focus is taken midway between the mark's \
                     sagittal and tangential images, their spread added to the stage noise \
                     along its axis"
                } else {
                    ""
                }
            ));
        }
        if input.nominal.camera.aspect_ratio.is_some() {
            notes.push(
                "the nominal station declares the camera's aspect ratio (fy / fx): it is \
                 estimated beside the focal length, but it is not a degree of freedom of \
                 mfd-station-uncertainty/1 and its σ is in report.json only"
                    .into(),
            );
        }
        Report {
            steps,
            notes,
            beside_the_uncertainty_file: Vec::new(),
        }
    }

    /// `report.json`.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    /// A short summary for the operator.
    pub fn summary(&self) -> String {
        let mut s = String::new();
        let last = self.steps.len().saturating_sub(1);
        for (k, step) in self.steps.iter().enumerate() {
            s += &format!(
                "{:<10} χ²/dof {:.2} ({} dof, {} trials, condition {:.1e})\n",
                step.name,
                step.chi2_per_dof,
                step.dof,
                step.trials,
                step.selection.condition_estimated
            );
            for b in &step.blocks {
                s += &format!(
                    "  {:<15} {:>6} × RMS {:.4} {} (noise alone: {:.4})\n",
                    b.name, b.count, b.rms, b.unit, b.expected_rms
                );
            }
            if k == last {
                for x in &step.suspects {
                    s += &format!("  suspect: {}\n", x.message);
                }
            }
            for h in &step.selection.held {
                s += &format!(
                    "  held {} at its nominal value: the data leave σ {:.3e} of its prior {:.3e} \
                     (condition {:.1e})\n",
                    h.name, h.marginal_std, h.prior_std, h.condition_before
                );
            }
            if k == last {
                for w in &step.weak {
                    s += &format!(
                        "  weakly determined (the data leave it near its prior): {}\n",
                        w.describe()
                    );
                }
            }
        }
        for n in &self.notes {
            s += &format!("note: {n}\n");
        }
        s
    }
}

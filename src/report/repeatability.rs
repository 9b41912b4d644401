//! `repeatability.json` (`mfd-repeatability/1`): N measurements of the
//! same element in a row (`mfd measure --repeat N`) against what each
//! reported. Per figure and per coefficient the mean, the spread over the
//! runs, the mean reported σ and their ratio; per surface the spread of
//! the whole surface over its mean expected error, the one honesty check
//! that needs no truth.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::report::figures::table::std_key;
use crate::report::summary::Summary;

/// The `format` value of the file.
pub const REPEATABILITY_FORMAT: &str = "mfd-repeatability/1";

/// How the figures are made, for the file's reader.
pub const REPEATABILITY_NOTE: &str = "spread: the sample standard deviation over the runs \
(divisor N - 1); mean_reported_std: the mean over the runs of each run's reported 1 sigma; \
ratio: spread / mean_reported_std (near 1 when the reported sigma are right). Per surface, \
spread_over_reported: the RMS over runs of the surface's departure from the runs' mean \
(piston and tilt removed: the root sum of squares of the coefficient departures from Noll \
j = 4; the RMS with divisor N - 1, as the mean is estimated from the same runs) over the mean \
expected_error_rms_nm";

/// One quantity over the runs.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Stat {
    /// Mean over the runs.
    pub mean: f64,
    /// Sample standard deviation over the runs.
    pub spread: f64,
    /// Mean of the runs' reported 1σ.
    pub mean_reported_std: f64,
    /// `spread / mean_reported_std` (NaN written as null when σ is 0).
    pub ratio: Option<f64>,
}

/// One surface over the runs.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct SurfaceRepeat {
    /// RMS over the runs of the surface's departure from the runs' mean,
    /// piston and tilt removed, nm.
    pub departure_rms_nm: f64,
    /// Mean of the runs' `expected_error_rms_nm`, nm.
    pub mean_expected_error_rms_nm: f64,
    /// `departure_rms_nm / mean_expected_error_rms_nm`.
    pub spread_over_reported: f64,
    /// Per coefficient (Noll j = k + 1 at index k).
    pub coefficients: Vec<Stat>,
}

/// The whole file.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Repeatability {
    /// Always [`REPEATABILITY_FORMAT`].
    pub format: String,
    /// The number of runs.
    pub runs: usize,
    /// Their result folders, in order.
    pub run_folders: Vec<String>,
    /// What the numbers are ([`REPEATABILITY_NOTE`]).
    pub note: String,
    /// Per figure (`front.power_nm`, `plate.wedge_arcsec`, …).
    pub figures: BTreeMap<String, Stat>,
    /// The front over the runs; `null` unless every run reported it.
    pub front: Option<SurfaceRepeat>,
    /// The back over the runs; `null` unless every run reported it.
    pub back: Option<SurfaceRepeat>,
}

/// The repeatability of the runs' summaries (`folders` their names).
pub fn repeatability(folders: &[String], runs: &[Summary]) -> Repeatability {
    Repeatability {
        format: REPEATABILITY_FORMAT.into(),
        runs: runs.len(),
        run_folders: folders.to_vec(),
        note: REPEATABILITY_NOTE.into(),
        figures: figures(runs),
        front: surface(runs, false),
        back: surface(runs, true),
    }
}

fn stat(values: &[f64], stds: &[f64]) -> Stat {
    let n = values.len().max(1) as f64;
    let mean = values.iter().sum::<f64>() / n;
    let spread = if values.len() > 1 {
        (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
    } else {
        0.0
    };
    let reported = stds.iter().sum::<f64>() / stds.len().max(1) as f64;
    Stat {
        mean,
        spread,
        mean_reported_std: reported,
        ratio: (reported > 0.0).then(|| spread / reported),
    }
}

/// Every figure with a σ that every run reported.
fn figures(runs: &[Summary]) -> BTreeMap<String, Stat> {
    let json: Vec<Value> = runs
        .iter()
        .map(|s| serde_json::to_value(&s.figures).unwrap_or(Value::Null))
        .collect();
    let mut out = BTreeMap::new();
    let Some(first) = json.first() else {
        return out;
    };
    for part in ["front", "back", "plate"] {
        let Some(keys) = first[part].as_object() else {
            continue;
        };
        for key in keys.keys().filter(|k| !k.contains("_std_")) {
            let Some(sk) = std_key(key) else { continue };
            let pairs: Option<Vec<(f64, f64)>> = json
                .iter()
                .map(|j| Some((j[part][key].as_f64()?, j[part][&sk].as_f64()?)))
                .collect();
            let Some(pairs) = pairs else { continue };
            let mut values: Vec<f64> = pairs.iter().map(|p| p.0).collect();
            if key.ends_with("_deg") {
                // Angles about the first run's, wrapped to ±180°.
                let a = values[0];
                for v in &mut values {
                    *v = a + (*v - a + 180.0).rem_euclid(360.0) - 180.0;
                }
            }
            let stds: Vec<f64> = pairs.iter().map(|p| p.1).collect();
            out.insert(format!("{part}.{key}"), stat(&values, &stds));
        }
    }
    out
}

/// One surface over the runs, when every run reported it.
fn surface(runs: &[Summary], back: bool) -> Option<SurfaceRepeat> {
    let mut coefficients = Vec::new();
    let mut stds = Vec::new();
    let mut expected = Vec::new();
    for s in runs {
        if s.withheld[usize::from(back)].is_some() {
            return None;
        }
        let c = if back { s.back.as_ref()? } else { &s.front };
        let (std, e) = s.reported(back)?;
        coefficients.push(c.coefficients_nm.clone());
        stds.push(std.to_vec());
        expected.push(e);
    }
    let n = coefficients.iter().map(Vec::len).max()?;
    let at = |v: &Vec<f64>, k: usize| v.get(k).copied().unwrap_or(0.0);
    let per: Vec<Stat> = (0..n)
        .map(|k| {
            let v: Vec<f64> = coefficients.iter().map(|c| at(c, k)).collect();
            let s: Vec<f64> = stds.iter().map(|c| at(c, k)).collect();
            stat(&v, &s)
        })
        .collect();
    let runs_n = coefficients.len() as f64;
    let sum_sq: f64 = coefficients
        .iter()
        .map(|c| {
            (3..n)
                .map(|k| (at(c, k) - per[k].mean).powi(2))
                .sum::<f64>()
        })
        .sum();
    let departure = (sum_sq / (runs_n - 1.0).max(1.0)).sqrt();
    let mean_expected = expected.iter().sum::<f64>() / runs_n;
    Some(SurfaceRepeat {
        departure_rms_nm: departure,
        mean_expected_error_rms_nm: mean_expected,
        spread_over_reported: departure / mean_expected,
        coefficients: per,
    })
}

//! The figures as a short table for the console (`mfd reconstruct`,
//! `mfd measure`, `mfd compare --surfaces`), and each figure set against a
//! truth's in units of its σ.

use serde_json::Value;

use super::{FaceFigures, Figures};

/// One figure of a result beside the truth's.
#[derive(Debug, Clone, PartialEq)]
pub struct Score {
    /// `front.power_nm`, `plate.wedge_arcsec`, …
    pub key: String,
    /// The result's value.
    pub value: f64,
    /// The truth's.
    pub truth: f64,
    /// The result's 1σ.
    pub std: f64,
    /// `(value − truth) / std` (the azimuth's difference wrapped to ±180°);
    /// NaN for a zero σ.
    pub z: f64,
}

/// The `_std` key of a figure's key: `_std` before the unit
/// (`power_nm` → `power_std_nm`).
pub fn std_key(key: &str) -> Option<String> {
    let (stem, unit) = key.rsplit_once('_')?;
    Some(format!("{stem}_std_{unit}"))
}

/// Every figure of `ours` that has a σ and a value in `truth`, with its
/// z-score, in the order front, back, plate.
pub fn scores(ours: &Figures, truth: &Figures) -> Vec<Score> {
    let (a, b) = (json(ours), json(truth));
    let mut out = Vec::new();
    for part in ["front", "back", "plate"] {
        let (Some(x), Some(y)) = (a[part].as_object(), b[part].as_object()) else {
            continue;
        };
        for (key, v) in x {
            if key.contains("_std_") {
                continue;
            }
            let Some(sk) = std_key(key) else { continue };
            let (Some(value), Some(std), Some(t)) = (
                v.as_f64(),
                x.get(&sk).and_then(Value::as_f64),
                y.get(key).and_then(Value::as_f64),
            ) else {
                continue;
            };
            let mut d = value - t;
            if key.ends_with("_deg") {
                d = (d + 180.0).rem_euclid(360.0) - 180.0;
            }
            out.push(Score {
                key: format!("{part}.{key}"),
                value,
                truth: t,
                std,
                z: if std > 0.0 { d / std } else { f64::NAN },
            });
        }
    }
    out
}

fn json(f: &Figures) -> Value {
    serde_json::to_value(f).unwrap_or(Value::Null)
}

/// The figures as console lines: a face table, the plate, what was removed
/// and how the σ were made.
pub fn lines(f: &Figures) -> Vec<String> {
    let mut out = vec![format!(
        "figures (± 1σ; power linear, the others {}; {}):",
        f.std_method
            .get("rms_t_std_nm")
            .map_or("drawn", |s| s.split(" from").next().unwrap_or(s)),
        f.covariance
    )];
    out.push(format!(
        "  {:<6}{:>20}{:>24}{:>18}{:>18}{:>18}",
        "face", "power nm", "irregularity PV nm", "RMSt nm", "RMSi nm", "RMSa nm"
    ));
    for (k, (name, face)) in [("front", &f.front), ("back", &f.back)]
        .into_iter()
        .enumerate()
    {
        match face {
            Some(x) => out.push(face_line(name, x)),
            None => out.push(format!(
                "  {name:<6}not reported: {}",
                f.why_null[k].as_deref().unwrap_or("")
            )),
        }
    }
    match &f.plate {
        Some(p) => {
            out.push(format!(
                "  plate: wedge {} arcsec thinning towards {} deg (element frame); thickness \
                 variation PV {} nm, RMS {} nm",
                pm(p.wedge_arcsec, p.wedge_std_arcsec),
                pm(p.wedge_azimuth_deg, p.wedge_azimuth_std_deg),
                pm(p.thickness_variation_pv_nm, p.thickness_variation_pv_std_nm),
                pm(
                    p.thickness_variation_rms_nm,
                    p.thickness_variation_rms_std_nm
                ),
            ));
            out.push(format!(
                "  transmitted wavefront (n = {}): RMS {} nm = {} waves at {} nm, PV {} nm",
                p.refractive_index,
                pm(p.twe_rms_nm, p.twe_rms_std_nm),
                pm4(p.twe_rms_waves, p.twe_rms_std_waves),
                p.wavelength_nm,
                pm(p.twe_pv_nm, p.twe_pv_std_nm),
            ));
        }
        None => out.push(format!(
            "  plate: not reported: {}",
            f.why_null[2].as_deref().unwrap_or("")
        )),
    }
    out.push(format!("  removed: {}", f.removed));
    out
}

fn face_line(name: &str, x: &FaceFigures) -> String {
    format!(
        "  {name:<6}{:>20}{:>24}{:>18}{:>18}{:>18}",
        pm(x.power_nm, x.power_std_nm),
        pm(x.irregularity_pv_nm, x.irregularity_pv_std_nm),
        pm(x.rms_t_nm, x.rms_t_std_nm),
        pm(x.rms_i_nm, x.rms_i_std_nm),
        pm(x.rms_a_nm, x.rms_a_std_nm),
    )
}

/// `value ± σ` with two decimals.
fn pm(v: f64, s: f64) -> String {
    format!("{v:.2} ± {s:.2}")
}

/// `value ± σ` with five decimals (waves).
fn pm4(v: f64, s: f64) -> String {
    format!("{v:.5} ± {s:.5}")
}

//! The calibration soak test of issue 35: random calibration sessions
//! from an independent generator ([`gen`], written from `calibration.md`
//! and `interchange.md`, not from mfd's optics), each calibrated by
//! `calibrate` and required to end one of two ways ([`judge`]): a station
//! whose error against the truth is within its reported covariance (χ²)
//! and whose flat-reflected screen points match the truth's within their
//! predicted spread, or a clear statement of what could not be done.
//!
//! - `MFD_SOAK_SESSIONS=n`: draw `n` sessions (default 50, about a minute
//!   and a half on 2 cores in the test profile).
//! - `MFD_SOAK_SEED=s`: run seed `s` alone.
//! - `MFD_SOAK_FAILURES=path`: where failing seeds are appended (default
//!   `target/soak-failures.txt` under the crate).
//!
//! It prints one JSON line of figures (`soak-figures: {...}`); they are in
//! `docs/figures.md`.

mod curve;
mod draw;
mod gen;
mod judge;
mod optics;
mod selfcheck;
mod toml;

use std::io::Write;
use std::path::PathBuf;

use draw::Draw;
use gen::Session;
use judge::{chi2_sf, judge, Ending, Judged, MIN_P};

use crate::common::env_u64;

/// Seeds of the default run start here (any fixed start will do; this one
/// names the issue).
const FIRST_SEED: u64 = 35_000;

/// The most sessions that may end in a clear error: the lead's bound (a
/// lab's valid sessions should calibrate, 1 in 10 may be refused).
const MAX_ERR_FRACTION: f64 = 0.1;

/// The most sessions whose covariance may fail its χ² test (p < 0.001).
/// Not the issue's goal (none); where issue 35 stands: along a curved weak
/// valley (target depth under a tenth of the camera's distance, no marks)
/// the truth lies off the tangent ellipse in the tight combinations.
/// Measured: 27 of 500 sessions (5.4 %) with the linear covariance alone;
/// 3 of 50 with each long direction's own bend (`calibrate::valley`,
/// `3 q qᵀ`); 6 of 500 (1.2 %; 35047 alone of the first 50) with the
/// pairs' bends and the held parameters'. A regression past 1 in 10
/// fails.
const MAX_COVARIANCE_FAIL_FRACTION: f64 = 0.1;

/// The linear χ² tests a session failed.
fn covariance_failures(j: &Judged) -> &[String] {
    match &j.ending {
        Ending::Ok { covariance, .. } => covariance,
        _ => &[],
    }
}

fn failures_path() -> PathBuf {
    std::env::var_os("MFD_SOAK_FAILURES").map_or_else(
        || PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/soak-failures.txt"),
        PathBuf::from,
    )
}

/// Prints a failing seed and appends it, with everything it was drawn
/// with, to the failures file.
fn save_failure(session: &Session, why: &str) {
    let draw = &session.draw;
    let text = format!(
        "seed {} failed: {why}\n  {draw:?}\n{}\n",
        draw.seed,
        curve::explain(session)
    );
    eprint!("{text}");
    let path = failures_path();
    if let Some(dir) = path.parent() {
        let _ = std::fs::create_dir_all(dir);
    }
    let written = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
        .and_then(|mut f| f.write_all(text.as_bytes()));
    if let Err(e) = written {
        eprintln!("could not append to {}: {e}", path.display());
    }
}

/// What is wrong with one judged session (empty: nothing).
fn problems(j: &Judged) -> Vec<String> {
    match &j.ending {
        Ending::Ok { problems, fit, .. } => problems
            .iter()
            .map(|p| {
                let mut worst = fit.each.clone();
                worst.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
                let top: Vec<String> = worst
                    .iter()
                    .take(4)
                    .map(|(n, z)| format!("{n} {z:+.1}σ"))
                    .collect();
                format!(
                    "{p}; largest errors {}; the data's χ² rises {:.1} from the estimate to the \
                     truth, {:.1} halfway",
                    top.join(", "),
                    fit.rise[0],
                    fit.rise[1]
                )
            })
            .collect(),
        Ending::Clear(_) => Vec::new(),
        Ending::Unclear(e) => vec![format!("an unclear error: {e}")],
    }
}

#[test]
fn random_sessions_calibrate_within_their_covariance_or_say_why_not() {
    let seeds: Vec<u64> = match env_u64("MFD_SOAK_SEED") {
        Some(s) => vec![s],
        None => {
            let n = env_u64("MFD_SOAK_SESSIONS").unwrap_or(50);
            (FIRST_SEED..FIRST_SEED + n).collect()
        }
    };
    let mut judged = Vec::new();
    let mut failed = Vec::new();
    let mut linear = Vec::new();
    for &seed in &seeds {
        let session = Session::new(&Draw::new(seed));
        let j = judge(&session);
        match &j.ending {
            Ending::Clear(e) => eprintln!("seed {seed}: ended in a clear error: {e}"),
            Ending::Ok { fit, .. } => eprintln!(
                "seed {seed}: χ²/k {:.1}/{} (p {:.1e}), data directions {:.1}/{}, rise {:.1} \
                 (halfway {:.1}), flat {:.4} px {:.2} σ, {} trials, {:.2} s",
                fit.chi2,
                fit.k,
                fit.p,
                fit.chi2_data,
                fit.k_data,
                fit.rise[0],
                fit.rise[1],
                fit.flat_max_px,
                fit.flat_max_sigma,
                fit.trials,
                j.seconds
            ),
            Ending::Unclear(_) => {}
        }
        let p = problems(&j);
        if !p.is_empty() {
            save_failure(&session, &p.join("; "));
            failed.push(seed);
        }
        let c = covariance_failures(&j);
        if !c.is_empty() {
            save_failure(&session, &c.join("; "));
            linear.push(seed);
        }
        judged.push(j);
    }
    let fig = figures(&judged);
    println!("seeds whose linear covariance fails its χ² test: {linear:?}");
    println!("soak-figures: {}", fig.json());
    assert!(
        failed.is_empty(),
        "failing seeds (saved in {}): {failed:?}",
        failures_path().display()
    );
    let errs = judged.len() - fig.ok;
    assert!(
        errs as f64 <= MAX_ERR_FRACTION * judged.len() as f64,
        "{errs} of {} sessions ended in an error (at most {MAX_ERR_FRACTION} of them may)",
        judged.len()
    );
    assert!(
        linear.len() as f64 <= MAX_COVARIANCE_FAIL_FRACTION * judged.len() as f64,
        "{} of {} sessions fail the linear covariance's χ² test: {linear:?}",
        linear.len(),
        judged.len()
    );
    // The data's χ² at the truth less at the estimate, summed over the Ok
    // sessions, is χ²(Σk) over the data's directions when the estimator is
    // at the likelihood's optimum and the noise is as stated, whatever the
    // parameterisation ([`curve`]): its mean per direction is 1 ± √(2/Σk);
    // four of those σ bound it (±0.16 at Σk ≈ 1200, 50 sessions). The
    // covariance's own χ² over those directions is printed (the figures):
    // along curved valleys it is above 1, issue 35's open part.
    if fig.k_data > 0 {
        let band = 4.0 * (2.0 / fig.k_data as f64).sqrt();
        assert!(
            (fig.mean_rise_data - 1.0).abs() <= band,
            "mean likelihood rise per data direction {:.3}, outside 1 ± {band:.3}",
            fig.mean_rise_data
        );
    }
}

/// The run's figures. `mean_rise_data`: the data's χ² at the truth less
/// at the estimate, summed over the Ok sessions, per data direction: the
/// likelihood ratio of the truth, which is χ²(k_data) in the linear model
/// whatever the parameterisation ([`curve`]).
struct Figures {
    sessions: usize,
    ok: usize,
    mean_chi2_per_k: f64,
    mean_chi2_data: f64,
    mean_rise_data: f64,
    k_data: usize,
    max_flat_px: f64,
    max_flat_sigma: f64,
    over_005_px: usize,
    max_trials: usize,
    median_s: f64,
    max_s: f64,
}

fn figures(judged: &[Judged]) -> Figures {
    let fits: Vec<&judge::Fit> = judged
        .iter()
        .filter_map(|j| match &j.ending {
            Ending::Ok { fit, .. } => Some(fit),
            _ => None,
        })
        .collect();
    let sum = |f: &dyn Fn(&judge::Fit) -> f64| fits.iter().map(|x| f(x)).sum::<f64>();
    let k: f64 = sum(&|x| x.k as f64);
    let k_data: f64 = sum(&|x| x.k_data as f64);
    let mut secs: Vec<f64> = judged.iter().map(|j| j.seconds).collect();
    secs.sort_by(f64::total_cmp);
    let max = |f: &dyn Fn(&judge::Fit) -> f64| fits.iter().map(|x| f(x)).fold(0.0, f64::max);
    Figures {
        sessions: judged.len(),
        ok: fits.len(),
        mean_chi2_per_k: sum(&|x| x.chi2) / k,
        mean_chi2_data: sum(&|x| x.chi2_data) / k_data,
        mean_rise_data: sum(&|x| x.rise[0]) / k_data,
        k_data: k_data as usize,
        max_flat_px: max(&|x| x.flat_max_px),
        max_flat_sigma: max(&|x| x.flat_max_sigma),
        over_005_px: fits.iter().filter(|x| x.flat_max_px > 0.05).count(),
        max_trials: fits.iter().map(|x| x.trials).max().unwrap_or(0),
        median_s: secs.get(secs.len() / 2).copied().unwrap_or(0.0),
        max_s: secs.last().copied().unwrap_or(0.0),
    }
}

impl Figures {
    fn json(&self) -> String {
        format!(
            "{{\"sessions\": {}, \"ok\": {}, \"err\": {}, \"mean_chi2_per_k\": {:.3}, \
             \"mean_chi2_per_k_data\": {:.3}, \"mean_rise_per_k_data\": {:.3}, \"k_data\": {}, \"max_flat_err_px\": {:.4}, \
             \"max_flat_err_sigma\": {:.2}, \"sessions_over_0.05_px\": {}, \"max_trials\": {}, \
             \"median_s\": {:.2}, \"max_s\": {:.2}}}",
            self.sessions,
            self.ok,
            self.sessions - self.ok,
            self.mean_chi2_per_k,
            self.mean_chi2_data,
            self.mean_rise_data,
            self.k_data,
            self.max_flat_px,
            self.max_flat_sigma,
            self.over_005_px,
            self.max_trials,
            self.median_s,
            self.max_s
        )
    }
}

#[test]
fn the_chi2_tail_matches_known_values() {
    // Reference values from the closed forms: χ²(2) has P(> x) = e^{−x/2};
    // χ²(1) has P(> 3.841459) = 0.05 (the 95 % point of every table), and
    // χ²(30) has P(> 59.7022) = 0.001 (tables, e.g. NIST's). The series
    // and the continued fraction are both exercised (x/2 below and above
    // k/2 + 1).
    for x in [0.1, 1.0, 5.0, 30.0] {
        assert!((chi2_sf(x, 2) - (-x / 2.0).exp()).abs() < 1e-12, "x = {x}");
    }
    assert!((chi2_sf(3.841459, 1) - 0.05).abs() < 1e-6);
    assert!((chi2_sf(59.7022, 30) - 0.001).abs() < 1e-6);
    assert!((chi2_sf(29.336, 30) - 0.5).abs() < 1e-3);
}

#[test]
fn the_sessions_of_issue_35_calibrate() {
    // The report's sessions (`Draw::issue_35`: ±2.3°, 850 mm, layers 20 mm
    // apart, 0.08 px centroids, no marks) over ten seeds of their noise:
    // each must end Ok with its flat points on the truth's.
    let mut failed = Vec::new();
    let mut linear = Vec::new();
    let mut whole = Vec::new();
    for seed in 0..10 {
        let session = Session::new(&Draw::issue_35(seed));
        let j = judge(&session);
        let mut p = problems(&j);
        if let Ending::Clear(e) = &j.ending {
            p.push(format!("ended in an error: {e}"));
        }
        if !p.is_empty() {
            save_failure(&session, &p.join("; "));
            failed.push(seed);
        }
        if let Ending::Ok { fit, .. } = &j.ending {
            println!(
                "issue 35's session, seed {seed}: χ² {:.1} for k = {} (p {:.1e}), {:.1} over \
                 the data's {} directions",
                fit.chi2, fit.k, fit.p, fit.chi2_data, fit.k_data
            );
            if fit.p < MIN_P {
                whole.push(seed);
            }
        }
        let c = covariance_failures(&j);
        if !c.is_empty() {
            println!("issue 35's session, seed {seed}: {}", c.join("; "));
            linear.push(seed);
        }
    }
    // Issue 35's line for these sessions: the covariance's χ² test at
    // p ≥ 0.001 over every reported parameter, in each. The soak's tests
    // failed at 6 of 10 seeds with the linear covariance and 5 with each
    // long direction's own bend (`3 q qᵀ`); with the pairs' bends and the
    // held parameters' (`calibrate::valley`) the whole χ² passes at every
    // seed (18–53 for k = 30). The soak's
    // stricter test over the data's directions alone is printed: seed 2
    // fails it at p 5.3e-4 (45.8 for k = 19), its data's χ² at the truth
    // 34.8 above the estimate's.
    println!("issue 35's session: the χ² tests fail at seeds {linear:?}");
    assert!(
        failed.is_empty(),
        "issue 35's session failed at seeds {failed:?}"
    );
    assert!(
        whole.is_empty(),
        "issue 35's session: the covariance's χ² over every parameter has p < 0.001 at seeds \
         {whole:?}"
    );
}

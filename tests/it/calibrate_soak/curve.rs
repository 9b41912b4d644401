//! Why a session fails the χ² test: the data's own χ² along the straight
//! line from the estimate to the truth. Where the reported covariance
//! describes the error, that χ² rises as the covariance's quadratic form
//! does (`t² eᵀC⁻¹e`). Where the truth lies along a curved valley of the
//! cost (a weak direction whose partners follow it non-linearly in the
//! spec's degrees of freedom), the line leaves the valley and comes back:
//! the rise halfway exceeds the rise at the truth, and the truth's own rise
//! is small (a likelihood ratio consistent with the noise) while the
//! linear χ² is large. The residuals are mfd's
//! (`mfd::calibrate::residuals`): the self-check shows they agree with the
//! generator's geometry to 1e-12 on exact data, and here they only tell
//! the shape of the cost, not the truth.

use mfd::calibrate::calibration::{calibrate, Calibration};
use mfd::calibrate::params::{difference, Param, State};
use mfd::calibrate::residuals::{item, item_count, Blocks, Whitening};
use nalgebra::{DMatrix, DVector};

use super::gen::Session;

fn states(s: &Session, cal: &Calibration) -> (State, State, Vec<Param>) {
    let params = cal
        .names
        .iter()
        .filter_map(|n| Param::from_name(n))
        .collect();
    let est = State {
        frame: cal.frame,
        station: cal.station.clone(),
    };
    let truth = State {
        frame: s.stage.world_frame(),
        station: s.truth.clone(),
    };
    (est, truth, params)
}

/// The data's χ² (every block, whitened as at the estimate) at `st`.
fn data_chi2(s: &Session, w: &Whitening, st: &State) -> f64 {
    (0..item_count(&s.input, Blocks::ALL))
        .map(|i| {
            let (r, len) = item(&s.input, st, Blocks::ALL, w, i);
            r[..len].iter().map(|x| x * x).sum::<f64>()
        })
        .sum()
}

/// The data's χ² at the truth and halfway to it, less at the estimate.
pub fn rise(s: &Session, cal: &Calibration) -> [f64; 2] {
    let (est, truth, params) = states(s, cal);
    let Ok(w) = Whitening::at(&s.input, &est) else {
        return [f64::NAN; 2];
    };
    let e = difference(&est, &truth, &params);
    let half = params
        .iter()
        .zip(&e)
        .fold(est.clone(), |st, (p, d)| st.perturbed(*p, 0.5 * d));
    let base = data_chi2(s, &w, &est);
    [
        data_chi2(s, &w, &truth) - base,
        data_chi2(s, &w, &half) - base,
    ]
}

/// What a failing session's calibration says and where its error lies:
/// the report's summary, then the combinations of parameters (eigenvectors
/// of the correlation matrix, errors in σ units) that carry most of its χ².
pub fn explain(s: &Session) -> String {
    let cal = &match calibrate(&s.input) {
        Ok(c) => c,
        Err(e) => return format!("error: {e}"),
    };
    let mut out = cal.report.summary();
    let (est, truth, params) = states(s, cal);
    let e = DVector::from_vec(difference(&truth, &est, &params));
    let c = &cal.covariance;
    let k = params.len();
    let sd = DVector::from_fn(k, |i, _| c[(i, i)].sqrt());
    let r = DMatrix::from_fn(k, k, |i, j| c[(i, j)] / (sd[i] * sd[j]));
    let z = e.component_div(&sd);
    let eig = r.symmetric_eigen();
    let mut parts: Vec<(f64, usize)> = (0..k)
        .map(|i| {
            (
                eig.eigenvectors.column(i).dot(&z).powi(2) / eig.eigenvalues[i],
                i,
            )
        })
        .collect();
    parts.sort_by(|a, b| b.0.total_cmp(&a.0));
    for (chi2, i) in parts.iter().take(3) {
        let v = eig.eigenvectors.column(*i);
        let mut w: Vec<(usize, f64)> = (0..k).map(|m| (m, v[m])).collect();
        w.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
        let names: Vec<String> = w
            .iter()
            .take(6)
            .map(|(m, x)| format!("{x:+.2} {} (err {:+.2}σ)", cal.names[*m], z[*m]))
            .collect();
        out += &format!(
            "χ² {chi2:.1} along a combination of correlation-eigenvalue {:.2e}: {}\n",
            eig.eigenvalues[*i],
            names.join(", ")
        );
    }
    out
}

//! The budget as the paper tabulates it (§5.1, Tables 1–4): one row per
//! degree of freedom (its change of each coefficient at one σ), the imaging
//! noise and the other entries, the total; columns Z1…Z15 and the root sum
//! of squares over j ≥ 4; a front and a back table. Markdown and CSV for
//! people and spreadsheets, JSON for scripts.

use serde_json::{json, Value};

use super::monte_carlo::MonteCarlo;
use super::{Budget, OtherEntry};

/// Columns of the paper's tables: Z1…Z15.
pub const TABLE_TERMS: usize = 15;

/// What the budget leaves out, said under every table.
pub const NOT_INCLUDED: &[&str] = &[
    "multiple reflection (second internal round trip, paper §5.1b): not included; the \
     spectral model fits two reflections and the budget does not yet estimate the bias of \
     the third (its Fresnel weight is ~0.06 % against ~4 %, paper Fig. 23)",
    "reference flat's figure: not included (no calibration with a flat is given)",
];

/// The usual name of Noll term `j` (1-based) up to j = 15; empty beyond.
pub fn noll_name(j: usize) -> &'static str {
    const NAMES: [&str; 15] = [
        "piston",
        "tilt x",
        "tilt y",
        "defocus",
        "astig. 45°",
        "astig. 0°",
        "coma y",
        "coma x",
        "trefoil y",
        "trefoil x",
        "spherical",
        "2nd astig. 0°",
        "2nd astig. 45°",
        "tetrafoil 0°",
        "tetrafoil 45°",
    ];
    NAMES.get(j.wrapping_sub(1)).copied().unwrap_or("")
}

/// Root sum of squares over j ≥ 4 (index 3 on) of per-coefficient values.
pub fn rss_j4(values: &[f64]) -> f64 {
    values.iter().skip(3).fold(0.0, |s, v| s + v * v).sqrt()
}

/// The total 1σ per coefficient of one surface (`back`): the root of the
/// total covariance's diagonal, with the biases added in quadrature.
pub fn total_std_nm(budget: &Budget, back: bool) -> Vec<f64> {
    let (cov, n) = if back {
        (&budget.back_total_cov_nm2, budget.terms[1])
    } else {
        (&budget.front_total_cov_nm2, budget.terms[0])
    };
    (0..n)
        .map(|i| {
            let bias2: f64 = budget
                .others
                .iter()
                .filter(|o| o.bias)
                .map(|o| side(o, back).get(i).map_or(0.0, |b| b * b))
                .sum();
            (cov.get((i, i)).copied().unwrap_or(0.0).max(0.0) + bias2).sqrt()
        })
        .collect()
}

fn side(o: &OtherEntry, back: bool) -> &[f64] {
    if back {
        &o.back_nm
    } else {
        &o.front_nm
    }
}

/// One row of a table: its label and per-coefficient values (all terms).
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// What the row is: a spec name, "imaging noise", "total (RSS)".
    pub label: String,
    /// nm per coefficient, Noll order from j = 1.
    pub values_nm: Vec<f64>,
}

/// The rows of one surface's table (`back`), in the paper's order: the
/// degrees of freedom, the others, the total, and the Monte Carlo RMS.
pub fn rows(budget: &Budget, back: bool, mc: Option<&MonteCarlo>) -> Vec<Row> {
    let mut out: Vec<Row> = budget
        .dofs
        .iter()
        .map(|d| Row {
            label: format!("{} (σ {})", d.dof.name(), d.std),
            values_nm: if back {
                d.back_contribution_nm()
            } else {
                d.front_contribution_nm()
            },
        })
        .collect();
    for o in &budget.others {
        let label = if o.bias {
            format!("{} (bias)", o.name)
        } else {
            o.name.clone()
        };
        out.push(Row {
            label,
            values_nm: side(o, back).to_vec(),
        });
    }
    out.push(Row {
        label: "total (RSS)".into(),
        values_nm: total_std_nm(budget, back),
    });
    if let Some(mc) = mc {
        out.push(Row {
            label: format!("Monte Carlo RMS ({} draws)", mc.draws),
            values_nm: if back {
                mc.back_rms_nm.clone()
            } else {
                mc.front_rms_nm.clone()
            },
        });
    }
    out
}

fn columns(budget: &Budget) -> usize {
    budget.terms[0].max(budget.terms[1]).min(TABLE_TERMS)
}

/// The markdown tables (front, then back when it was reconstructed), nm.
pub fn markdown(budget: &Budget, mc: Option<&MonteCarlo>) -> String {
    let n = columns(budget);
    let mut s = String::new();
    let surfaces: &[(bool, &str)] = if budget.back_fitted {
        &[(false, "Front"), (true, "Back")]
    } else {
        &[(false, "Front")]
    };
    for &(back, title) in surfaces {
        let all = budget.terms[usize::from(back)];
        s += &format!("### {title} surface: change of each Zernike coefficient at 1σ, nm\n\n");
        s += "| |";
        for j in 1..=n {
            s += &format!(" Z{j} {} |", noll_name(j));
        }
        s += &format!(" RSS j≥4 (all {all} terms) |\n|---|");
        s += &"---:|".repeat(n + 1);
        s.push('\n');
        for row in rows(budget, back, mc) {
            s += &format!("| {} |", row.label);
            for j in 0..n {
                s += &format!(" {} |", fmt(row.values_nm.get(j).copied()));
            }
            s += &format!(" {} |\n", fmt(Some(rss_j4(&row.values_nm))));
        }
        s.push('\n');
    }
    if !budget.back_fitted {
        s += "Back: not reconstructed (no back reflection measured).\n\n";
    }
    for note in NOT_INCLUDED {
        s += &format!("- {note}\n");
    }
    s
}

fn fmt(v: Option<f64>) -> String {
    match v {
        Some(v) if v.is_finite() => {
            let v = if v.abs() < 5e-4 { 0.0 } else { v };
            format!("{v:.3}")
        }
        _ => String::new(),
    }
}

/// The same as CSV: `surface,row,Z1,…,Z15,rss_j4_nm`, every value in nm.
pub fn csv(budget: &Budget, mc: Option<&MonteCarlo>) -> String {
    let n = columns(budget);
    let mut s = String::from("surface,row");
    for j in 1..=n {
        s += &format!(",Z{j}");
    }
    s += ",rss_j4_nm\n";
    for back in [false, true] {
        if back && !budget.back_fitted {
            continue;
        }
        for row in rows(budget, back, mc) {
            s += &format!(
                "{},\"{}\"",
                if back { "back" } else { "front" },
                row.label.replace('"', "'")
            );
            for j in 0..n {
                s += &format!(
                    ",{}",
                    row.values_nm
                        .get(j)
                        .map_or(String::new(), |v| format!("{v:.6}"))
                );
            }
            s += &format!(",{:.6}\n", rss_j4(&row.values_nm));
        }
    }
    s
}

/// The budget for scripts: per degree of freedom by its spec name its
/// `std`, `sensitivity_nm_per_unit` and `contribution_nm` (front and back,
/// Noll order from j = 1), the correlation, the others, the totals, what
/// the data pin down, the Monte Carlo check when run, and what is left out.
pub fn json(budget: &Budget, mc: Option<&MonteCarlo>) -> Value {
    let mut dofs = serde_json::Map::new();
    for d in &budget.dofs {
        dofs.insert(
            d.dof.name().into(),
            json!({
                "std": d.std,
                "sensitivity_nm_per_unit": {"front": d.front_nm_per_unit, "back": d.back_nm_per_unit},
                "contribution_nm": {"front": d.front_contribution_nm(), "back": d.back_contribution_nm()},
            }),
        );
    }
    let names: Vec<&str> = budget.dofs.iter().map(|d| d.dof.name()).collect();
    let corr: Vec<Vec<f64>> = (0..budget.correlation.nrows())
        .map(|r| budget.correlation.row(r).iter().copied().collect())
        .collect();
    let others: Vec<Value> = budget
        .others
        .iter()
        .map(|o| json!({"name": o.name, "bias": o.bias, "front_nm": o.front_nm, "back_nm": o.back_nm}))
        .collect();
    let (tf, tb) = (total_std_nm(budget, false), total_std_nm(budget, true));
    let identifiability: Vec<Value> = budget
        .identifiability
        .iter()
        .map(|i| {
            json!({
                "combination": i.combination.iter().map(|(d, w)| json!({"dof": d.name(), "weight": w})).collect::<Vec<_>>(),
                "prior_std": i.prior_std,
                "data_std": i.data_std,
                "posterior_std": i.posterior_std,
            })
        })
        .collect();
    json!({
        "zernike": {"ordering": "noll", "normalization": "rms"},
        "terms": {"front": budget.terms[0], "back": budget.terms[1]},
        "back_fitted": budget.back_fitted,
        "dofs": dofs,
        "correlation": {"names": names, "matrix": corr},
        "others": others,
        "total": {
            "std_nm": {"front": tf, "back": tb},
            "rss_j4_nm": {"front": rss_j4(&tf), "back": rss_j4(&tb)},
        },
        "identifiability": identifiability,
        "monte_carlo": mc.map(|m| json!({
            "draws": m.draws,
            "seed": m.seed,
            "rms_nm": {"front": m.front_rms_nm, "back": m.back_rms_nm},
            "rss_j4_nm": {"front": rss_j4(&m.front_rms_nm), "back": rss_j4(&m.back_rms_nm)},
            "linear_std_nm": {"front": tf, "back": tb},
        })),
        "not_included": NOT_INCLUDED,
    })
}

//! Every `mfd bench …` prints its figures as JSON lines that a user's `jq`
//! (here serde_json) reads, with the fields `scripts/bench.sh` and the docs
//! quote. Small stations keep each run to seconds.

use crate::common;

fn json_lines(args: &[&str]) -> Vec<serde_json::Value> {
    let out = common::mfd(args);
    assert!(
        out.status.success(),
        "mfd {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<serde_json::Value> = text
        .lines()
        .map(|l| {
            serde_json::from_str(l).unwrap_or_else(|e| panic!("mfd {args:?}: not JSON ({e}): {l}"))
        })
        .collect();
    assert!(!lines.is_empty(), "mfd {args:?} printed nothing");
    lines
}

fn station() -> String {
    common::public_small()
        .join("station.toml")
        .display()
        .to_string()
}

#[test]
fn render_spectral_and_surfaces_benches_print_json() {
    let st = station();
    let render = json_lines(&["bench", "render", "--station", &st, "--frames", "2"]);
    assert_eq!(render[0]["bench"], "render");
    assert_eq!(render[0]["pixels"], 48 * 48);
    assert!(render[0]["ms_per_frame"].as_f64().unwrap() > 0.0);

    let spectral = json_lines(&["bench", "spectral", "--station", &st, "--pixels", "0"]);
    let s = &spectral[0];
    assert_eq!(s["bench"], "spectral");
    assert_eq!(s["engine"], "statistics");
    // `nodes` is a list of [direction 1, direction 2] pairs, not Rust's
    // tuple debug text.
    let nodes = s["nodes"].as_array().unwrap();
    assert!(nodes
        .iter()
        .all(|n| n.as_array().is_some_and(|p| p.len() == 2)));
    assert!(s["both_found"].as_u64().unwrap() > 1000);

    let surfaces = json_lines(&["bench", "surfaces", "--station", &st, "--terms", "15"]);
    assert_eq!(surfaces[0]["bench"], "surfaces");
    assert!(surfaces[0]["front_rms_err_nm"]
        .as_f64()
        .unwrap()
        .is_finite());
}

#[test]
fn table_benches_print_one_json_line_per_row() {
    let thickness = json_lines(&[
        "bench",
        "thickness",
        "--thickness-mm",
        "10,30",
        "--index",
        "1.5",
    ]);
    assert_eq!(thickness.len(), 2);
    assert_eq!(thickness[1]["thickness_mm"], 30.0);
    assert!(thickness[0]["s1_error_over_bound"].as_f64().is_some());

    let extremes = json_lines(&["bench", "extremes", "--case", "reference,thin"]);
    assert_eq!(extremes.len(), 2);
    assert!(extremes.iter().all(|r| r["bench"] == "extremes"));
    assert_eq!(extremes[0]["case"], "reference");
    // The reference case is exact without noise (the surface solvers'
    // convergence tolerance, far below a picometre).
    assert!(extremes[0]["noise_free_front_rms_err_nm"].as_f64().unwrap() < 1e-3);
    let out = common::mfd(&["bench", "extremes", "--case", "nonsense"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("reference"));
}

//! `mfd plan` on a schedule whose frames repeat: the planner sums each
//! distinct frame's samples (`solve::spectral::model::RepeatSamples`, the
//! bound's `Repeats::information`) instead of visiting every frame, and
//! must predict what it predicted frame by frame.

use crate::common::{mfd, public_small};

/// `front_rms_nm` and `back_rms_nm` of `mfd plan --station public-small
/// ARGS --json`, with the stage's and the separation's fractions.
fn predicted(args: &[&str], tag: &str) -> [f64; 4] {
    let dir = std::env::temp_dir().join(format!("mfd-plan-repeats-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let station = public_small().join("station.toml");
    let json = dir.join(format!("{tag}.json"));
    let mut all = vec![
        "plan",
        "--station",
        station.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ];
    all.extend_from_slice(args);
    let out = mfd(&all);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    [
        j["predicted"]["front_rms_nm"].as_f64().unwrap(),
        j["predicted"]["back_rms_nm"].as_f64().unwrap(),
        j["stage"]["found_fraction"].as_f64().unwrap(),
        j["separation"]["separable_fraction"].as_f64().unwrap(),
    ]
}

/// The paper's schedule with every pattern shown twice (`--phases 0,0`,
/// 4000 frames of 2000 distinct ones). Pinned: the prediction of main
/// 40515a7, which summed the 4000 frames one by one (`mfd plan --station
/// tests/fixtures/public-small/station.toml --phases 0,0 --json`, release
/// build). Now the 2000 distinct frames are summed with weight 2: the same
/// sums in another grouping, each within ~N ε = 4000 × 1.1e-16 ≈ 4.4e-13
/// of the other (relative), carried through the information's inverse
/// and the surfaces' fit; 1e-9 allows those a condition of 2000 (the two
/// differed by 4e-16 when measured). The stage's and the separation's
/// verdicts are counts of sample pixels: equal.
#[test]
fn a_schedule_of_repeated_frames_predicts_what_the_series_did() {
    let twice = predicted(&["--phases", "0,0"], "twice");
    for (got, want, what) in [
        (twice[0], 5.482862459092942, "front"),
        (twice[1], 5.121689128743832, "back"),
    ] {
        assert!(
            (got - want).abs() <= 1e-9 * want,
            "{what}: {got} nm, the series gave {want} nm"
        );
    }
    assert_eq!([twice[2], twice[3]], [1.0, 1.0]);
    // Twice the frames of every pattern: twice the information, every σ
    // over √2 (closed form), to the same rounding.
    let once = predicted(&[], "once");
    for k in 0..2 {
        let r = once[k] / twice[k];
        assert!((r - 2f64.sqrt()).abs() <= 1e-9 * r, "{k}: {r}");
    }
}

//! `mfd plan` end to end on the 48 × 48 public-small station: a design
//! written as mfd-schedule/1 with its JSON, its prediction read back from
//! the file, and `mfd simulate --schedule` and `mfd measure --schedule`
//! (simulated camera, offscreen display) showing exactly that sequence.

use crate::common::{mfd, public_small};

#[test]
fn plan_designs_predicts_and_simulate_shows_the_schedule() {
    let dir = std::env::temp_dir().join(format!("mfd-plan-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let station = public_small().join("station.toml");
    let st = station.to_str().unwrap();
    let sched = dir.join("schedule.toml");
    let json = dir.join("plan.json");
    let out = mfd(&[
        "plan",
        "--station",
        st,
        "--frames",
        "300",
        "--out",
        sched.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(j["frames"].as_u64(), Some(300));
    assert!(j["seconds"].as_f64().unwrap() > 0.0);
    let front = j["predicted"]["front_rms_nm"].as_f64().unwrap();
    assert!(front > 0.0 && front.is_finite());
    assert!(j["predicted"].get("back_rms_nm").is_some());
    let e = j["design"]["efficiency"].as_f64().unwrap();
    assert!(e > 0.0 && e <= 1.0, "{e}");
    // Predicting the written file gives the design's own prediction.
    let json2 = dir.join("again.json");
    let out = mfd(&[
        "plan",
        "--station",
        st,
        "--schedule",
        sched.to_str().unwrap(),
        "--json",
        json2.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let j2: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json2).unwrap()).unwrap();
    assert_eq!(
        j2["predicted"]["front_rms_nm"],
        j["predicted"]["front_rms_nm"]
    );
    // The simulator shows exactly that sequence.
    let acq = dir.join("acq");
    let out = mfd(&[
        "simulate",
        "--station",
        st,
        "--schedule",
        sched.to_str().unwrap(),
        "--out",
        acq.to_str().unwrap(),
        "--noise",
        "0.05",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let frames = mfd::acquire::acquisition::Acquisition::open(&acq)
        .unwrap()
        .frames()
        .to_vec();
    let want = mfd::acquire::schedule_file::load(&sched).unwrap().frames();
    assert_eq!(frames.len(), want.len());
    for (a, b) in frames.iter().zip(&want) {
        assert_eq!(
            (a.direction_deg, a.tau, a.phase_rad),
            (b.direction_deg, b.tau, b.phase_rad)
        );
    }
    // A schedule and the flags together are refused, naming the flag.
    let out = mfd(&[
        "simulate",
        "--station",
        st,
        "--schedule",
        sched.to_str().unwrap(),
        "--tau-stop",
        "5",
        "--out",
        acq.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--tau-stop"));
    // mfd measure shows it (simulated camera, offscreen display) and the
    // recorder writes it, in that order.
    let meas = dir.join("meas");
    let out = mfd(&[
        "measure",
        "--station",
        st,
        "--camera",
        "sim",
        "--display",
        "offscreen",
        "--schedule",
        sched.to_str().unwrap(),
        "--out",
        meas.to_str().unwrap(),
        "--noise",
        "0.05",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rec = mfd::acquire::acquisition::Acquisition::open(&meas.join("acquisition"))
        .unwrap()
        .frames()
        .to_vec();
    assert_eq!(rec.len(), want.len());
    for (a, b) in rec.iter().zip(&want) {
        assert_eq!(
            (a.direction_deg, a.tau, a.phase_rad),
            (b.direction_deg, b.tau, b.phase_rad)
        );
    }
    assert!(meas.join("result/surfaces.json").exists());
    std::fs::remove_dir_all(&dir).ok();
}

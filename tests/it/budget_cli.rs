//! `mfd budget` end to end on the 48 × 48 public-small station: the flags,
//! the files it writes, the JSON's fields and their lengths, and the error
//! messages on bad input (each naming the flag or the file and field).

use std::path::Path;

use crate::common::{mfd, public_small};

const TERMS: usize = 15;

/// A folder with the station, an uncertainty of it and a short schedule.
fn setup(dir: &Path) {
    std::fs::copy(
        public_small().join("station.toml"),
        dir.join("station.toml"),
    )
    .unwrap();
    std::fs::write(
        dir.join("station.uncertainty.toml"),
        r#"format = "mfd-station-uncertainty/1"
station = "station.toml"
[std]
"screen.rz_deg" = 0.02
"element.thickness_mm" = 0.005
[covariance]
names = ["camera.z_mm", "screen.z_mm"]
matrix = [[0.25, 0.1], [0.1, 0.25]]
"#,
    )
    .unwrap();
    let mut schedule = String::from("format = \"mfd-schedule/1\"\n");
    for dir in [45.0, -45.0] {
        for k in 1..=100 {
            schedule += &format!("[[frame]]\ndirection_deg = {dir}\ntau = {}\n", k as f64);
        }
    }
    std::fs::write(dir.join("schedule.toml"), schedule).unwrap();
}

fn arg(p: &Path) -> String {
    p.to_str().unwrap().to_string()
}

fn run(args: &[String]) -> std::process::Output {
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    mfd(&refs)
}

fn base(dir: &Path) -> Vec<String> {
    [
        "budget",
        "--station",
        &arg(&dir.join("station.toml")),
        "--schedule",
        &arg(&dir.join("schedule.toml")),
        "--terms",
        &TERMS.to_string(),
        "--noise",
        "0.02",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect()
}

#[test]
fn budget_writes_tables_json_and_picture() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    setup(d);
    let mut args = base(d);
    for (flag, file) in [
        ("--uncertainty", "station.uncertainty.toml"),
        ("--markdown", "budget.md"),
        ("--csv", "budget.csv"),
        ("--json", "budget.json"),
        ("--picture", "budget.png"),
    ] {
        args.push(flag.into());
        args.push(arg(&d.join(file)));
    }
    args.extend(["--std".into(), "camera.x_mm=0.3".into()]);
    let out = run(&args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.stdout.is_empty(), "the tables go to the files named");
    let md = std::fs::read_to_string(d.join("budget.md")).unwrap();
    assert!(
        md.contains("Z4 defocus") && md.contains("Z15 tetrafoil 45°"),
        "{md}"
    );
    assert!(md.contains("| imaging noise |") && md.contains("| total (RSS) |"));
    assert!(
        md.contains("multiple reflection"),
        "the table says what it leaves out"
    );
    let csv = std::fs::read_to_string(d.join("budget.csv")).unwrap();
    let header = csv.lines().next().unwrap();
    assert_eq!(header.split(',').count(), 2 + TERMS + 1, "{header}");
    // 5 degrees of freedom + imaging noise + total, front and back.
    assert_eq!(csv.lines().count(), 1 + 2 * 7, "{csv}");
    let png = std::fs::read(d.join("budget.png")).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");

    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("budget.json")).unwrap()).unwrap();
    let dofs = json["dofs"].as_object().unwrap();
    let names = [
        "camera.z_mm",
        "screen.z_mm",
        "screen.rz_deg",
        "element.thickness_mm",
        "camera.x_mm",
    ];
    assert_eq!(dofs.len(), names.len());
    let stds = [0.5, 0.5, 0.02, 0.005, 0.3];
    for (name, std) in names.iter().zip(stds) {
        let e = &dofs[*name];
        assert!((e["std"].as_f64().unwrap() - std).abs() < 1e-12, "{name}");
        for side in ["front", "back"] {
            let s = e["sensitivity_nm_per_unit"][side].as_array().unwrap();
            let c = e["contribution_nm"][side].as_array().unwrap();
            assert_eq!((s.len(), c.len()), (TERMS, TERMS), "{name} {side}");
            for (s, c) in s.iter().zip(c) {
                let (s, c) = (s.as_f64().unwrap(), c.as_f64().unwrap());
                assert!((s * std - c).abs() <= 1e-9 * c.abs().max(1.0));
            }
        }
    }
    assert_eq!(json["correlation"]["names"].as_array().unwrap().len(), 5);
    let r = json["correlation"]["matrix"][0][1].as_f64().unwrap();
    assert!((r - 0.4).abs() < 1e-12, "0.1 / (0.5 · 0.5): {r}");
    assert_eq!(json["others"][0]["name"], "imaging noise");
    assert_eq!(
        json["others"][0]["front_nm"].as_array().unwrap().len(),
        TERMS
    );
    for side in ["front", "back"] {
        assert_eq!(
            json["total"]["std_nm"][side].as_array().unwrap().len(),
            TERMS
        );
        assert!(json["total"]["rss_j4_nm"][side].as_f64().unwrap() > 0.0);
    }
    assert!(json["identifiability"].is_array());
    assert!(json["monte_carlo"].is_null());
}

#[test]
fn budget_prints_markdown_from_an_acquisition_and_checks_by_monte_carlo() {
    let station = public_small().join("station.toml");
    let out = mfd(&[
        "budget",
        "--station",
        station.to_str().unwrap(),
        "--acquisition",
        public_small().to_str().unwrap(),
        "--std",
        "screen.rz_deg=0.02",
        "--terms",
        "10",
        "--monte-carlo",
        "4",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let md = String::from_utf8(out.stdout).unwrap();
    assert!(
        md.contains("### Front surface") && md.contains("### Back surface"),
        "{md}"
    );
    assert!(md.contains("| screen.rz_deg (σ 0.02) |"), "{md}");
    assert!(md.contains("| Monte Carlo RMS (4 draws) |"), "{md}");
    assert!(
        md.contains("Z10 trefoil x") && !md.contains("Z11"),
        "10 terms, 10 columns"
    );
}

fn stderr_of(args: &[String]) -> String {
    let out = run(args);
    assert!(!out.status.success());
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn bad_input_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    setup(d);
    let with = |extra: &[&str]| {
        let mut a = base(d);
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    };
    let e = stderr_of(&with(&["--std", "camera.q_mm=1"]));
    assert!(
        e.contains("--std camera.q_mm=1") && e.contains("not a degree of freedom"),
        "{e}"
    );
    let e = stderr_of(&with(&["--std", "camera.z_mm=0"]));
    assert!(
        e.contains("--std camera.z_mm=0") && e.contains("> 0"),
        "{e}"
    );
    let e = stderr_of(&with(&["--std", "camera.z_mm"]));
    assert!(e.contains("NAME=SIGMA"), "{e}");
    let e = stderr_of(&with(&[]));
    assert!(e.contains("--uncertainty") && e.contains("--std"), "{e}");

    // An uncertainty of another station.
    std::fs::write(
        d.join("other.uncertainty.toml"),
        "format = \"mfd-station-uncertainty/1\"\nstation = \"other.toml\"\n[std]\n\"camera.z_mm\" = 0.5\n",
    )
    .unwrap();
    let u = arg(&d.join("other.uncertainty.toml"));
    let e = stderr_of(&with(&["--uncertainty", &u]));
    assert!(
        e.contains("other.uncertainty.toml: station") && e.contains("other.toml"),
        "{e}"
    );

    // A schedule with a bad τ names the file and the frame.
    std::fs::write(
        d.join("bad.toml"),
        "format = \"mfd-schedule/1\"\n[[frame]]\ndirection_deg = 45.0\ntau = -1.0\n",
    )
    .unwrap();
    let mut a = with(&["--std", "camera.z_mm=0.5"]);
    let k = a.iter().position(|s| s == "--schedule").unwrap();
    a[k + 1] = arg(&d.join("bad.toml"));
    let e = stderr_of(&a);
    assert!(e.contains("bad.toml: frame[0].tau"), "{e}");
    a[k + 1] = arg(&d.join("station.toml"));
    let e = stderr_of(&a);
    assert!(
        e.contains("station.toml") && e.contains("mfd-schedule/1"),
        "{e}"
    );
}

//! Sizes refused up front and plans that answer (issue 37): requests that
//! used to allocate until the kernel killed `mfd` (exit 134) or ran for
//! minutes are refused at once with the limit and the memory they would
//! need (exit 2: a number out of range), and `mfd plan` answers within
//! seconds at the documented maximum of frames. Every command runs under a
//! deadline: a test that hangs fails naming the command instead.

use std::io::Read;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::public_small;

/// Runs `mfd args`, killed at `deadline`: its exit status (None when it
/// was killed or died of a signal), its output and how long it took.
fn mfd_within(args: &[&str], deadline: Duration) -> (Option<i32>, String, Duration) {
    let start = Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_mfd"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The pipes are drained on threads so a chatty command cannot block.
    let drain = |mut r: Box<dyn Read + Send>| {
        std::thread::spawn(move || {
            let mut s = String::new();
            let _ = r.read_to_string(&mut s);
            s
        })
    };
    let out = drain(Box::new(child.stdout.take().unwrap()));
    let err = drain(Box::new(child.stderr.take().unwrap()));
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s.code();
        }
        if start.elapsed() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("mfd {args:?} did not answer within {deadline:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let text = out.join().unwrap() + &err.join().unwrap();
    (status, text, start.elapsed())
}

fn station() -> String {
    public_small().join("station.toml").display().to_string()
}

fn out_file(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("mfd-bad-sizes-{}-{name}", std::process::id()))
}

/// A refusal: exit status `code`, within `secs` s (what loading the
/// station takes in a debug build, with room for a loaded machine), and
/// each of `needles` in the message.
fn refused(args: &[&str], code: i32, needles: &[&str]) {
    let (status, text, took) = mfd_within(args, Duration::from_secs(60));
    assert_eq!(status, Some(code), "mfd {args:?} ({took:?}):\n{text}");
    for n in needles {
        assert!(text.contains(n), "mfd {args:?}: no {n:?} in:\n{text}");
    }
}

#[test]
fn plan_budgets_above_the_largest_schedule_are_refused_first() {
    let (st, out) = (station(), out_file("plan.toml"));
    let o = out.to_str().unwrap();
    for frames in ["1000000000", "100001"] {
        refused(
            &["plan", "--station", &st, "--frames", frames, "--out", o],
            2,
            &["--frames", "100000 frames a schedule may have", "of memory"],
        );
    }
    refused(
        &["plan", "--station", &st, "--time-s", "1e12", "--out", o],
        2,
        &[
            "--time-s",
            "100000 frames a schedule may have",
            "at most",
            "of memory",
        ],
    );
    assert!(!out.exists(), "a schedule was written");
}

#[test]
fn monte_carlo_draws_above_the_limit_are_refused_first() {
    let st = station();
    refused(
        &[
            "budget",
            "--station",
            &st,
            "--schedule",
            "none.toml",
            "--monte-carlo",
            "1000000000",
        ],
        2,
        &["--monte-carlo", "expected 1 to 100000", "of memory"],
    );
}

#[test]
fn a_target_grid_finer_than_the_sensor_is_refused() {
    let st = station();
    refused(
        &[
            "calibrate",
            "targets",
            "--nominal",
            &st,
            "--grid",
            "100000,100000",
        ],
        2,
        &[
            "--grid 100000,100000",
            "at most 17,17 on this 48x48 px sensor",
        ],
    );
}

#[test]
fn tau_beyond_the_screen_is_refused_by_plan_and_budget_as_by_simulate() {
    let st = station();
    let beyond = ["--tau-stop", "5000"];
    let (_, simulate, _) = mfd_within(
        &[
            &["simulate", "--station", &st, "--out", "x"][..],
            &beyond[..],
        ]
        .concat(),
        Duration::from_secs(60),
    );
    let why = "is above the 989.95 a 1600x1200 px screen can show at 45°";
    assert!(simulate.contains(why), "{simulate}");
    refused(
        &[&["plan", "--station", &st][..], &beyond[..]].concat(),
        3,
        &[why],
    );
    let dir = tempfile::tempdir().unwrap();
    let sched = dir.path().join("beyond.toml");
    std::fs::write(
        &sched,
        "format = \"mfd-schedule/1\"\n[[frame]]\ndirection_deg = 45.0\ntau = 5000.0\n",
    )
    .unwrap();
    let s = sched.to_str().unwrap();
    refused(
        &["plan", "--station", &st, "--schedule", s],
        3,
        &[why, "frame[0].tau"],
    );
    let budget = [
        "budget",
        "--station",
        &st,
        "--std",
        "camera.z_mm=0.5",
        "--schedule",
        s,
    ];
    refused(&budget, 3, &[why, "frame[0].tau"]);
}

//! Every subcommand's bad input and bad options exit with the status the
//! README's "Exit status" table gives their class (issue 37: 126 findings
//! had a good message and the wrong status). The statuses are read from
//! the README, so the table and the program are held to each other; the
//! cases name a missing file, an unparsable one, a wrong field value, a
//! number out of range and an unknown option for each subcommand. Each
//! case fails before any heavy work, so the table runs in seconds.
//!
//! Beside it: every error type of the library says its class
//! (`mfd::outcome::Classify`) and the binary's one mapping place
//! (`src/cli/exit.rs`) lists it, so that no subcommand can forget one.

use std::path::Path;

use crate::common::{mfd, public_small, repo};

/// The status the README's table gives the class whose meaning begins
/// with `meaning` ("bad input", "bad command line").
fn readme_status(meaning: &str) -> i32 {
    let readme = std::fs::read_to_string(repo("README.md")).unwrap();
    let table = readme
        .split("## Exit status")
        .nth(1)
        .expect("README has an \"Exit status\" section");
    table
        .lines()
        .filter_map(|l| {
            let cells: Vec<&str> = l.split('|').map(str::trim).collect();
            let status = cells.get(1)?.parse::<i32>().ok()?;
            cells.get(2)?.starts_with(meaning).then_some(status)
        })
        .next()
        .unwrap_or_else(|| panic!("README's exit status table has no row \"{meaning}\""))
}

/// The files the cases refer to, in a temporary folder.
struct Files {
    dir: tempfile::TempDir,
}

impl Files {
    fn new() -> Files {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let station = std::fs::read_to_string(repo("calib/paper-sim.toml")).unwrap();
        let field = |from: &str, to: &str| {
            assert!(station.contains(from), "{from}");
            station.replacen(from, to, 1)
        };
        let write = |name: &str, text: &str| std::fs::write(d.join(name), text).unwrap();
        write("bad.toml", "format = \"x\"\n");
        write("garbage.json", "{");
        write("garbage.npy", "not an npy file");
        let focal = station
            .lines()
            .find(|l| l.starts_with("focal_length_mm"))
            .unwrap();
        write(
            "negative_focal.toml",
            &field(focal, "focal_length_mm = -16.0"),
        );
        write("tiny_focal.toml", &field(focal, "focal_length_mm = 1e-9"));
        write(
            "negative_tau.toml",
            "format = \"mfd-schedule/1\"\n[[frame]]\ndirection_deg = 45.0\ntau = -1.0\n",
        );
        let mut schedule = String::from("format = \"mfd-schedule/1\"\n");
        for d in [45, -45] {
            for k in 1..=40 {
                schedule.push_str(&format!(
                    "[[frame]]\ndirection_deg = {d}.0\ntau = {}\n",
                    f64::from(k) * 0.5
                ));
            }
        }
        write("schedule.toml", &schedule);
        let surfaces = public_small().join("truth/truth_surfaces.json");
        for (folder, files) in [
            ("corrupt_surfaces", &[("surfaces.json", "{")][..]),
            ("summary_only", &[("summary.json", "{}")][..]),
        ] {
            std::fs::create_dir_all(d.join(folder)).unwrap();
            for (name, text) in files {
                write(&format!("{folder}/{name}"), text);
            }
        }
        std::fs::create_dir_all(d.join("corrupt_summary")).unwrap();
        std::fs::copy(&surfaces, d.join("corrupt_summary/surfaces.json")).unwrap();
        write("corrupt_summary/summary.json", "{");
        std::fs::create_dir_all(d.join("acq")).unwrap();
        write(
            "acq/acquisition.toml",
            "format = \"mfd-acquisition/1\"\n[[frame]]\n",
        );
        std::fs::create_dir_all(d.join("session")).unwrap();
        write(
            "session/session.toml",
            "format = \"mfd-calibration/1\"\nnonsense = 1\n",
        );
        Files { dir }
    }

    /// `name` in the folder, as an argument.
    fn p(&self, name: &str) -> String {
        self.dir.path().join(name).to_string_lossy().into_owned()
    }
}

/// (command line, the class it must exit with, what the case is).
type Case = (Vec<String>, &'static str, &'static str);

const USAGE: &str = "bad command line";
const INPUT: &str = "bad input";

// One case a line: the table reads as a table.
#[rustfmt::skip]
fn cases(f: &Files) -> Vec<Case> {
    let station = repo("calib/paper-sim.toml").to_string_lossy().into_owned();
    let surfaces = public_small()
        .join("truth/truth_surfaces.json")
        .to_string_lossy()
        .into_owned();
    let acq = public_small().to_string_lossy().into_owned();
    let out = f.p("out");
    let s = station.as_str();
    let c = |args: &[&str], class: &'static str, why: &'static str| -> Case {
        (args.iter().map(|a| a.to_string()).collect(), class, why)
    };
    let (missing, bad, garbage) = (f.p("missing"), f.p("bad.toml"), f.p("garbage.json"));
    let (m, b, g, o) = (
        missing.as_str(),
        bad.as_str(),
        garbage.as_str(),
        out.as_str(),
    );
    let (neg_focal, tiny_focal) = (f.p("negative_focal.toml"), f.p("tiny_focal.toml"));
    let (nf, tf) = (neg_focal.as_str(), tiny_focal.as_str());
    let (neg_tau, sched) = (f.p("negative_tau.toml"), f.p("schedule.toml"));
    let (nt, sc) = (neg_tau.as_str(), sched.as_str());
    let npy = f.p("garbage.npy");
    let std = "--std=camera.z_mm=0.5";
    vec![
        // trace
        c(&["trace", "--station", m, "--out", o], INPUT, "missing station"),
        c(&["trace", "--station", b, "--out", o], INPUT, "unparsable station"),
        c(&["trace", "--station", nf, "--out", o], INPUT, "focal length < 0"),
        c(&["trace", "--station", s, "--surfaces", g, "--out", o], INPUT, "unparsable surfaces"),
        c(&["trace", "--edge-margin-mm=NaN"], USAGE, "NaN option"),
        c(&["trace", "--bogus"], USAGE, "unknown option"),
        // simulate
        c(&["simulate", "--station", m, "--out", o], INPUT, "missing station"),
        c(&["simulate", "--station", tf, "--out", o], INPUT, "focal length 1e-9"),
        c(&["simulate", "--station", s, "--out", o, "--bit-depth", "7"], USAGE, "bit depth 7"),
        c(&["simulate", "--noise=-1"], USAGE, "noise < 0"),
        c(&["simulate", "--station", s, "--schedule", nt, "--out", o], INPUT, "τ < 0 in a schedule"),
        c(&["simulate", "--station", s, "--surfaces", g, "--out", o], INPUT, "unparsable surfaces"),
        c(&["simulate", "--bogus"], USAGE, "unknown option"),
        // station
        c(&["station", "--camera", m, "--out", o], INPUT, "missing camera profile"),
        c(&["station", "--camera", b, "--out", o], INPUT, "unparsable camera profile"),
        c(&["station", "--thickness-mm=0"], USAGE, "thickness 0"),
        c(&["station", "--tilt-deg=95"], USAGE, "tilt 95°"),
        c(&["station", "--bogus"], USAGE, "unknown option"),
        // reconstruct
        c(&["reconstruct", m, "--out", o], INPUT, "missing acquisition"),
        c(&["reconstruct", &f.p("acq"), "--out", o], INPUT, "unparsable manifest"),
        c(&["reconstruct", &acq, "--out", o, "--station", nf], INPUT, "focal length < 0"),
        c(&["reconstruct", &acq, "--out", o, "--terms", "1"], USAGE, "--terms 1"),
        c(&["reconstruct", &acq, "--out", o, "--max-terms", "2"], USAGE, "--max-terms 2"),
        c(&["reconstruct", &acq, "--out", o, "--roi", "1,2,3"], USAGE, "--roi of 3 numbers"),
        c(&["reconstruct", "--bogus"], USAGE, "unknown option"),
        // measure
        c(&["measure", "--station", m, "--out", o], INPUT, "missing station"),
        c(&["measure", "--station", b, "--out", o], INPUT, "unparsable station"),
        c(&["measure", "--bit-depth", "7"], USAGE, "bit depth 7"),
        c(&["measure", "--noise=NaN"], USAGE, "NaN noise"),
        c(&["measure", "--terms", "1"], USAGE, "--terms 1"),
        c(&["measure", "--station", s, "--schedule", nt, "--out", o], INPUT, "τ < 0 in a schedule"),
        c(&["measure", "--station", s, "--sim-surfaces", g, "--out", o], INPUT, "unparsable surfaces"),
        // compare
        c(&["compare", "--surfaces", g, "--truth-surfaces", &surfaces], INPUT, "unparsable surfaces"),
        c(&["compare", "--surfaces", &surfaces, "--truth-surfaces", m], INPUT, "missing truth"),
        c(&["compare", "--screen-coords", &npy, "--truth", &npy], INPUT, "unparsable NPY"),
        c(&["compare", "--surfaces", &surfaces, "--interferometer", b], INPUT, "unknown map format"),
        c(&["compare", "--surfaces", &surfaces, "--interferometer", &npy], INPUT, "unparsable map"),
        c(&["compare", "--surfaces", &surfaces, "--truth-surfaces", &surfaces, "--summary", g], INPUT, "unparsable summary"),
        c(&["compare", "--surfaces", &surfaces, "--interferometer", &npy, "--height-scale-nm", "1e308"], USAGE, "height scale 1e308"),
        c(&["compare", "--interferometer", &npy], USAGE, "map without surfaces"),
        c(&["compare", "--bogus"], USAGE, "unknown option"),
        // report
        c(&["report", m], INPUT, "missing result"),
        c(&["report", &f.p("corrupt_surfaces")], INPUT, "unparsable surfaces.json"),
        c(&["report", &f.p("summary_only")], INPUT, "summary.json without surfaces.json"),
        c(&["report", &f.p("corrupt_summary")], INPUT, "unparsable summary.json"),
        c(&["report", &f.p("corrupt_summary"), "--calibration", m], INPUT, "missing calibration"),
        c(&["report", "--bogus"], USAGE, "unknown option"),
        // bench
        c(&["bench", "render", "--frames=0"], USAGE, "0 frames"),
        c(&["bench", "budget", "--terms", "1"], USAGE, "--terms 1"),
        c(&["bench", "surfaces", "--terms", "232"], USAGE, "--terms 232"),
        c(&["bench", "spectral", "--noise=-1"], USAGE, "noise < 0"),
        c(&["bench", "spectral", "--schedule", m], INPUT, "missing schedule"),
        c(&["bench", "spectral", "--schedule", nt], INPUT, "τ < 0 in a schedule"),
        c(&["bench", "bogus"], USAGE, "unknown bench"),
        // tradeoff
        c(&["tradeoff", "--station", m, "--out", o], INPUT, "missing station"),
        c(&["tradeoff", "--station", b, "--out", o], INPUT, "unparsable station"),
        c(&["tradeoff", "--frames=0,100"], USAGE, "0 frames"),
        c(&["tradeoff", "--terms", "1"], USAGE, "--terms 1"),
        c(&["tradeoff", "--bogus"], USAGE, "unknown option"),
        // display
        c(&["display"], USAGE, "nothing to do"),
        c(&["display", "--pattern", "x"], USAGE, "unparsable pattern"),
        c(&["display", "--hold-s=-1"], USAGE, "hold < 0"),
        c(&["display", "--offscreen", "--pattern", "45,10", "--png", &f.p("p.png"), "--profile", m], INPUT, "missing profile"),
        c(&["display", "--offscreen", "--pattern", "45,10", "--png", &f.p("p.png"), "--profile", b], INPUT, "unparsable profile"),
        c(&["display", "--bogus"], USAGE, "unknown option"),
        // calibrate
        c(&["calibrate", "check", m], INPUT, "missing session"),
        c(&["calibrate", "check", &f.p("session")], INPUT, "unparsable session"),
        c(&["calibrate", "solve", m, "--out", o], INPUT, "missing session"),
        c(&["calibrate", "solve", &f.p("session"), "--out", o], INPUT, "unparsable session"),
        c(&["calibrate", "targets", "--nominal", m], INPUT, "missing nominal station"),
        c(&["calibrate", "targets", "--nominal", s, "--grid", "1,2,3"], USAGE, "grid of 3"),
        c(&["calibrate", "template", o, "--nominal", b], INPUT, "unparsable nominal station"),
        c(&["calibrate", "capture", &f.p("session"), "--stage-mm", "1,2"], USAGE, "stage of 2 numbers"),
        c(&["calibrate", "simulate", "--out", o, "--bin=0"], USAGE, "bin 0"),
        c(&["calibrate", "bogus"], USAGE, "unknown step"),
        // budget
        c(&["budget", "--station", m, "--schedule", sc, std], INPUT, "missing station"),
        c(&["budget", "--station", s, "--schedule", m, std], INPUT, "missing schedule"),
        c(&["budget", "--station", s, "--schedule", b, std], INPUT, "unparsable schedule"),
        c(&["budget", "--station", s, "--schedule", nt, std], INPUT, "τ < 0 in a schedule"),
        c(&["budget", "--station", s, "--schedule", sc, std, "--surfaces", g], INPUT, "unparsable surfaces"),
        c(&["budget", "--station", s, "--schedule", sc, "--std=camera.nothing=1"], USAGE, "no such degree of freedom"),
        c(&["budget", "--station", s, "--schedule", sc, std, "--noise", "0"], USAGE, "noise 0"),
        c(&["budget", "--station", s, "--schedule", sc, std, "--bit-depth", "7"], USAGE, "bit depth 7"),
        c(&["budget", "--station", s, "--schedule", sc, std, "--terms", "2"], USAGE, "--terms 2"),
        c(&["budget", "--bogus"], USAGE, "unknown option"),
        // serve
        c(&["serve", m], INPUT, "missing folder"),
        c(&["serve", b], INPUT, "a file, not a folder"),
        c(&["serve"], USAGE, "no folder"),
        c(&["serve", &acq, "--addr", "not an address"], USAGE, "unparsable address"),
        c(&["serve", "--bogus"], USAGE, "unknown option"),
        // plan
        c(&["plan", "--station", m], INPUT, "missing station"),
        c(&["plan", "--station", b], INPUT, "unparsable station"),
        c(&["plan", "--station", tf], INPUT, "focal length 1e-9"),
        c(&["plan", "--station", s, "--schedule", b], INPUT, "unparsable schedule"),
        c(&["plan", "--station", s, "--noise", "0"], USAGE, "noise 0"),
        c(&["plan", "--station", s, "--frames", "1"], USAGE, "1 frame"),
        c(&["plan", "--station", s, "--bit-depth", "7"], USAGE, "bit depth 7"),
        c(&["plan", "--station", s, "--terms", "2"], USAGE, "--terms 2"),
        c(&["plan", "--bogus"], USAGE, "unknown option"),
    ]
}

#[test]
fn every_subcommand_exits_with_the_readme_status_of_its_error() {
    let files = Files::new();
    let cases = cases(&files);
    // At least five cases for every subcommand `mfd --help` lists.
    let help = String::from_utf8_lossy(&mfd(&["--help"]).stdout).into_owned();
    let commands: Vec<&str> = help
        .split("Commands:")
        .nth(1)
        .unwrap()
        .split("Options:")
        .next()
        .unwrap()
        .lines()
        .filter_map(|l| l.split_whitespace().next())
        .filter(|&c| c != "help")
        .collect();
    assert!(commands.len() >= 14, "{help}");
    for command in &commands {
        let n = cases.iter().filter(|(a, _, _)| a[0] == *command).count();
        assert!(n >= 5, "`mfd {command}` has {n} cases, at least 5 wanted");
    }
    let mut failures = Vec::new();
    for (args, class, why) in &cases {
        let want = readme_status(class);
        let got = mfd(&args.iter().map(String::as_str).collect::<Vec<_>>());
        if got.status.code() != Some(want) {
            failures.push(format!(
                "{why}: mfd {}: exit {:?}, the README says {want} ({class}): {}",
                args.join(" "),
                got.status.code(),
                String::from_utf8_lossy(&got.stderr).trim()
            ));
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {} cases:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
}

/// Error types in the floor-0 modules, which stand below `outcome`'s
/// users and may not use it (tests/it/architecture.rs): they have no class
/// of their own, and the errors that carry them say theirs.
const BELOW_OUTCOME: &[&str] = &["plot", "kernels", "conventions"];

/// `(type name, file)` of every `thiserror` error type in `dir`.
fn error_types(dir: &Path, out: &mut Vec<(String, String)>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            error_types(&path, out);
            continue;
        }
        if path.extension().is_none_or(|e| e != "rs") {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        for (i, l) in lines.iter().enumerate() {
            if !(l.starts_with("#[derive(") && l.contains("thiserror::Error")) {
                continue;
            }
            // The item follows its attributes and doc comments.
            let item = lines[i + 1..]
                .iter()
                .find(|l| l.starts_with("pub enum ") || l.starts_with("pub struct "));
            if let Some(item) = item {
                let name = item.split_whitespace().nth(2).unwrap();
                let name = name.trim_end_matches(['{', '(', ';']).to_string();
                out.push((name, path.to_string_lossy().into_owned()));
            }
        }
    }
}

#[test]
fn every_library_error_has_a_class_and_the_binary_maps_it() {
    let src = repo("src");
    let mut types = Vec::new();
    error_types(&src, &mut types);
    let library: Vec<_> = types
        .into_iter()
        .filter(|(_, file)| {
            let rel = Path::new(file).strip_prefix(&src).unwrap();
            let top = rel
                .components()
                .next()
                .unwrap()
                .as_os_str()
                .to_string_lossy();
            let top = top.trim_end_matches(".rs");
            top != "cli" && top != "main" && !BELOW_OUTCOME.contains(&top)
        })
        .collect();
    assert!(library.len() >= 30, "{library:?}");
    let exit = std::fs::read_to_string(repo("src/cli/exit.rs")).unwrap();
    let mut missing = Vec::new();
    for (name, file) in &library {
        let text = std::fs::read_to_string(file).unwrap();
        if !text.contains(&format!("impl crate::outcome::Classify for {name} ")) {
            missing.push(format!("{file}: {name} has no `Classify` impl beside it"));
        }
        if !exit.contains(&format!("::{name},")) {
            missing.push(format!("{name} ({file}) is not in src/cli/exit.rs's list"));
        }
    }
    assert!(missing.is_empty(), "{}", missing.join("\n"));
}

//! Every numeric command-line option refuses values it cannot mean (NaN,
//! infinities, a wrong sign, zero where a count or length is needed, out of
//! range) with an error naming the option, before any work starts (issue
//! 19: "every number that enters is checked where it enters"). Rules:
//! `src/cli/check.rs`; table: docs/input-checks.md, "Command-line options".

use crate::common::mfd;

/// (command line, the option the error must name as the one whose value is
/// refused). The values are given as `--option=value` so that negative
/// numbers reach the option's parser.
const CASES: &[(&[&str], &str)] = &[
    (&["measure", "--noise=NaN"], "--noise"),
    (&["measure", "--noise=1.5"], "--noise"),
    (&["measure", "--bit-depth=10"], "--bit-depth"),
    (&["measure", "--exposure-us=-100"], "--exposure-us"),
    (&["measure", "--gain-db=inf"], "--gain-db"),
    (&["measure", "--frame-rate=0"], "--frame-rate"),
    (&["measure", "--settle-ms=-1"], "--settle-ms"),
    (&["measure", "--gamma=0"], "--gamma"),
    (&["measure", "--ring=0"], "--ring"),
    (&["measure", "--frame-timeout-ms=0"], "--frame-timeout-ms"),
    (&["measure", "--sim-latency-ms=-3"], "--sim-latency-ms"),
    (
        &["measure", "--sim-drop-probability=2"],
        "--sim-drop-probability",
    ),
    (&["measure", "--tau-step=0"], "--tau-step"),
    (&["measure", "--tau-start=-1"], "--tau-start"),
    (&["measure", "--directions=45,NaN"], "--directions"),
    (&["measure", "--phases=inf"], "--phases"),
    (&["measure", "--band-bins=-1"], "--band-bins"),
    (&["measure", "--display-gamma=NaN"], "--display-gamma"),
    (&["measure", "--terms=0"], "--terms"),
    (&["measure", "--max-iter=0"], "--max-iter"),
    (&["reconstruct", "acq", "--margin-px=100000"], "--margin-px"),
    (
        &["reconstruct", "acq", "--edge-margin-mm=-5"],
        "--edge-margin-mm",
    ),
    (
        &["reconstruct", "acq", "--tau-max-guess=0"],
        "--tau-max-guess",
    ),
    (&["reconstruct", "acq", "--saturation=0"], "--saturation"),
    (&["reconstruct", "acq", "--terms=232"], "--terms"),
    (
        &["reconstruct", "acq", "--max-expected-nm=-1"],
        "--max-expected-nm",
    ),
    (
        &["reconstruct", "acq", "--out", "o", "--roi=10,10,5,5"],
        "--roi 10,10,5,5: an empty or reversed region",
    ),
    (&["simulate", "--noise=-0.1"], "--noise"),
    (&["simulate", "--tau-max=0"], "--tau-max"),
    (&["simulate", "--ambient=2"], "--ambient"),
    (&["simulate", "--bit-depth=0"], "--bit-depth"),
    (&["simulate", "--full-well=-1"], "--full-well"),
    (&["simulate", "--back-scale=-1"], "--back-scale"),
    (&["trace", "--edge-margin-mm=NaN"], "--edge-margin-mm"),
    (&["station", "--thickness-mm=0"], "--thickness-mm"),
    (&["station", "--refractive-index=0.9"], "--refractive-index"),
    (&["station", "--tilt-deg=95"], "--tilt-deg"),
    (&["station", "--focal-length-mm=-16"], "--focal-length-mm"),
    (
        &["station", "--aperture-radius-mm=0"],
        "--aperture-radius-mm",
    ),
    (&["plan", "--noise=NaN"], "--noise"),
    (&["plan", "--frames=0"], "--frames"),
    (&["plan", "--time-s=-1"], "--time-s"),
    (&["plan", "--index=1"], "--index"),
    (&["plan", "--exposure-ms=0"], "--exposure-ms"),
    (&["plan", "--display-rate-hz=-60"], "--display-rate-hz"),
    (&["budget", "--tau-max=-1"], "--tau-max"),
    (&["budget", "--monte-carlo=0"], "--monte-carlo"),
    (&["budget", "--std=camera.z_mm=NaN"], "--std"),
    (&["tradeoff", "--frames=0,100"], "--frames"),
    (&["tradeoff", "--noise=-1"], "--noise"),
    (&["compare", "--radius-px=0"], "--radius-px"),
    (&["compare", "--pixel-mm=NaN"], "--pixel-mm"),
    (&["display", "--hold-s=-1"], "--hold-s"),
    (&["calibrate", "targets", "--grid=0,3"], "--grid"),
    (
        &["calibrate", "capture", "--exposure-us=0"],
        "--exposure-us",
    ),
    (
        &["calibrate", "simulate", "--stage-std-um=-1"],
        "--stage-std-um",
    ),
    (&["calibrate", "simulate", "--bin=0"], "--bin"),
    (&["bench", "spectral", "--noise=-1"], "--noise"),
    (&["bench", "render", "--frames=0"], "--frames"),
    (&["bench", "thin", "--index=0.5"], "--index"),
    (
        &["bench", "thickness", "--thickness-mm=0"],
        "--thickness-mm",
    ),
    (&["bench", "surfaces", "--sigma1-px=0"], "--sigma1-px"),
    (&["bench", "extremes", "--sigma-px=NaN"], "--sigma-px"),
    (&["bench", "budget", "--terms=0"], "--terms"),
    (&["bench", "console", "--settle-ms=20000"], "--settle-ms"),
];

#[test]
fn every_bad_number_is_refused_naming_its_option() {
    let mut failures = Vec::new();
    for (args, option) in CASES {
        let out = mfd(args);
        let err = String::from_utf8_lossy(&out.stderr);
        let code = out.status.code();
        // clap's refusal of the value itself, not of a missing argument
        // (whose usage line would name the option too).
        let named = if option.starts_with("--roi ") {
            err.contains(option)
        } else {
            err.contains("invalid value") && err.contains(&format!("for '{option} <"))
        };
        if !matches!(code, Some(2 | 3)) || !named {
            failures.push(format!("mfd {}: exit {code:?}: {err}", args.join(" ")));
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {} cases:\n{}",
        failures.len(),
        CASES.len(),
        failures.join("\n")
    );
}

#[test]
fn the_defaults_pass_the_checks() {
    // Each command gets past its options (defaults parsed by the same
    // checks) to the input it cannot read: exit 3, naming the file.
    let missing = "/nonexistent/station.toml";
    let cases: &[&[&str]] = &[
        &["simulate", "--station", missing, "--out", "/tmp/x"],
        &["trace", "--station", missing, "--out", "/tmp/x"],
        &["plan", "--station", missing],
        &["measure", "--station", missing, "--out", "/tmp/x"],
        &["reconstruct", "/nonexistent/acq", "--out", "/tmp/x"],
    ];
    for args in cases {
        let out = mfd(args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(3), "mfd {}: {err}", args.join(" "));
        assert!(
            err.contains("/nonexistent/"),
            "mfd {}: {err}",
            args.join(" ")
        );
    }
    let out = mfd(&["--help"]);
    let help = String::from_utf8_lossy(&out.stdout);
    assert!(
        help.contains("Exit status") && help.contains("130"),
        "{help}"
    );
}

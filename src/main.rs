//! `mfd`: the command line. All logic lives in the library; this file only
//! parses arguments, calls it and prints what happened.

mod cli;

use clap::{Parser, Subcommand};

/// Multi-frequency fringe deflectometry of both faces of transparent plates.
///
/// Lengths are millimetres, angles degrees, surface heights and Zernike
/// coefficients nanometres (Noll order, RMS-normalised). File formats follow
/// the interchange spec: station.toml (mfd-station/1), acquisition folders
/// (mfd-acquisition/1), surfaces.json (mfd-surfaces/2; /1 read), screen_coords.npy.
#[derive(Parser)]
#[command(name = "mfd", version, about, long_about = None, after_help = EXIT_STATUS)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// The exit statuses (`cli::exit::Class`), as `--help` shows them.
const EXIT_STATUS: &str = "\
Exit status:
  0    success: the result is complete
  1    failure not classed below (a write that failed, a bug)
  2    bad command line: an unknown option, or a value out of its range
  3    bad input: a file or option that is not valid input (the error names
       the file or option, the field and the value), or a --resume whose
       settings differ from the acquisition's
  4    no signal: the data hold nothing to measure (too few points for the
       surfaces)
  5    inconsistent: the result contradicts the station (written whole and
       flagged in consistency.json; --accept-inconsistent exits 0), or a
       surface stage stopped at its iteration limit with a last step
       larger than its σ (flagged in summary.json's convergence;
       --accept-unconverged exits 0)
  6    device: the camera or display failed (disconnect, no usable frame)
  130  interrupted (Ctrl-C): what was recorded is kept; `--resume` continues";

#[derive(Subcommand)]
enum Command {
    /// Trace the station: where every camera pixel's rays land on the screen.
    Trace(cli::trace::TraceArgs),
    /// Render a simulated acquisition of a station and scene, with its truth.
    Simulate(cli::simulate::SimulateArgs),
    /// Build a station.toml from camera and display profiles and the paper's layout.
    Station(cli::station::StationArgs),
    /// Reconstruct from an acquisition: screen points S1, S2 with uncertainty and quality maps.
    Reconstruct(cli::reconstruct::ReconstructArgs),
    /// Measure live: show the schedule, record frames as they come, reconstruct.
    Measure(Box<cli::measure::MeasureArgs>),
    /// Compare screen coordinates or surfaces with a truth, or surfaces with an interferometer map.
    Compare(cli::compare::CompareArgs),
    /// The measurement report: one self-contained HTML file of a result folder.
    Report(cli::report::ReportArgs),
    /// Benchmarks: print figures as one JSON line.
    Bench(cli::bench::BenchArgs),
    /// Speed against accuracy: surface error and compute time over schedules, terms, iterations.
    Tradeoff(cli::tradeoff::TradeoffArgs),
    /// Fringe display: list monitors, show one pattern fullscreen, or render one offscreen.
    Display(cli::display::DisplayArgs),
    /// Calibration sessions: template, target positions, check, capture.
    Calibrate(cli::calibrate::CalibrateArgs),
    /// Error budget: every degree of freedom's effect on every Zernike term (paper Tables 1–4).
    Budget(cli::budget::BudgetArgs),
    /// The operator's console over finished result folders (pictures, summary.json).
    Serve(cli::serve::ServeArgs),
    /// Plan a measurement: a schedule's predicted accuracy and time, or a schedule designed for a budget.
    Plan(cli::plan::PlanArgs),
}

/// The library's diagnostics (`log`) on stderr: warnings and errors with
/// their level, notes as they are; `MFD_LOG=debug` (or `warn`, `error`,
/// `off`) sets how much is shown, `info` by default.
struct StderrLogger;

impl log::Log for StderrLogger {
    fn enabled(&self, metadata: &log::Metadata) -> bool {
        metadata.level() <= log::max_level()
    }

    fn log(&self, record: &log::Record) {
        if !self.enabled(record.metadata()) {
            return;
        }
        // Other crates' diagnostics (wgpu probing EGL drivers it then does
        // not use, ...) are not the operator's errors: shown at debug only.
        let ours = record.target().split("::").next() == Some("mfd");
        if !ours && log::max_level() < log::LevelFilter::Debug {
            return;
        }
        match record.level() {
            log::Level::Error => eprintln!("error: {}", record.args()),
            log::Level::Warn => eprintln!("warning: {}", record.args()),
            _ => eprintln!("{}", record.args()),
        }
    }

    fn flush(&self) {}
}

fn init_logging() {
    let level = std::env::var("MFD_LOG")
        .ok()
        .and_then(|v| v.parse::<log::LevelFilter>().ok())
        .unwrap_or(log::LevelFilter::Info);
    if log::set_logger(&StderrLogger).is_ok() {
        log::set_max_level(level);
    }
}

/// libwayland (through Mesa's EGL, which wgpu probes for the offscreen
/// display) prints "error: XDG_RUNTIME_DIR is invalid or not set" unless
/// the variable names a directory: give it a private 0700 one where it
/// does not (as `scripts/test.sh` does). Called first in `main`, while
/// the process has one thread.
fn ensure_runtime_dir() {
    use std::os::unix::fs::{DirBuilderExt, MetadataExt, PermissionsExt};
    let given = std::env::var_os("XDG_RUNTIME_DIR").map(std::path::PathBuf::from);
    if given.is_some_and(|p| p.is_absolute() && p.is_dir()) {
        return;
    }
    // The process's uid, without libc: the owner of /proc/self.
    let uid = std::fs::metadata("/proc/self").map_or(0, |m| m.uid());
    let dir = std::env::temp_dir().join(format!("mfd-runtime-{uid}"));
    let made = std::fs::DirBuilder::new().mode(0o700).create(&dir);
    let ours = std::fs::metadata(&dir)
        .is_ok_and(|m| m.is_dir() && m.uid() == uid && m.permissions().mode() & 0o077 == 0);
    if made.is_ok() || ours {
        std::env::set_var("XDG_RUNTIME_DIR", &dir);
    }
}

fn main() -> std::process::ExitCode {
    ensure_runtime_dir();
    init_logging();
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            // --help and --version print to stdout and succeed.
            let code = if e.use_stderr() {
                cli::exit::Class::Usage.code()
            } else {
                0
            };
            let _ = e.print();
            return std::process::ExitCode::from(code);
        }
    };
    let result = match cli.command {
        Command::Trace(args) => cli::trace::run(&args),
        Command::Simulate(args) => cli::simulate::run(&args),
        Command::Station(args) => cli::station::run(&args),
        Command::Bench(args) => cli::bench::run(&args),
        Command::Reconstruct(args) => cli::reconstruct::run(&args),
        Command::Compare(args) => cli::compare::run(&args),
        Command::Report(args) => cli::report::run(&args),
        Command::Tradeoff(args) => cli::tradeoff::run(&args),
        Command::Display(args) => cli::display::run(&args),
        Command::Measure(args) => cli::measure::run(&args),
        Command::Calibrate(args) => cli::calibrate::run(&args),
        Command::Budget(args) => cli::budget::run(&args),
        Command::Serve(args) => cli::serve::run(&args),
        Command::Plan(args) => cli::plan::run(&args),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {}", error_chain(&err));
            std::process::ExitCode::from(cli::exit::classify(&err).code())
        }
    }
}

/// The error and its causes on one line, each said once: the library's
/// errors already quote their source, so a cause whose text is already
/// there is not repeated.
fn error_chain(err: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in err.chain() {
        let msg = cause.to_string();
        if !text.contains(&msg) {
            if !text.is_empty() {
                text.push_str(": ");
            }
            text.push_str(&msg);
        }
    }
    text
}

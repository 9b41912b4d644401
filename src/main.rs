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
#[command(name = "mfd", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

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

fn main() -> std::process::ExitCode {
    init_logging();
    let cli = Cli::parse();
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

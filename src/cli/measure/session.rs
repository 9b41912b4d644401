//! The acquisition as it runs: the progress bar, the operator's console
//! (`--serve`) and the summary of what was captured.

use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use indicatif::{ProgressBar, ProgressStyle};

use mfd::live::{Counters, Measurement, Report};
use mfd::optics::station::Station;

use super::MeasureArgs;

/// `--serve`: the console, tapping the measurement.
pub(super) fn serve_measurement(
    addr: std::net::SocketAddr,
    args: &MeasureArgs,
    station: &Station,
    stop: &Arc<AtomicBool>,
    measurement: &mut Measurement<'_>,
) -> anyhow::Result<super::super::serve::Served> {
    use mfd::console::{Mode, Spectral};
    let screen = [station.screen.width, station.screen.height];
    let served = super::super::serve::Served::start(
        addr,
        Mode::Measure,
        stop,
        screen,
        &args.out.join("result"),
        &args.allow_host,
    )?;
    if !args.no_reconstruct {
        served.console.set_spectral(Spectral::Streaming {
            frames_in: measurement.recorded(),
            frames_total: measurement.patterns().len(),
        });
    }
    measurement.set_tap(Arc::new(served.console.clone()));
    Ok(served)
}

/// Runs the acquisition with a progress bar until it ends or `stop` is set.
pub(super) fn run_session(
    measurement: &mut Measurement<'_>,
    stop: &AtomicBool,
) -> anyhow::Result<Report> {
    let total = measurement.patterns().len() as u64;
    let bar = ProgressBar::new(total).with_style(
        ProgressStyle::with_template(
            "[{bar:30}] {pos}/{len} frames, {msg}, {elapsed} elapsed, eta {eta}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_position(measurement.recorded() as u64);
    let mut progress = |c: &Counters| {
        bar.set_position((c.first + c.captured) as u64);
        bar.set_message(format!(
            "{:.1} frames/s, {} dropped, {} re-shot, {} waits on consumers",
            c.frames_per_s(),
            c.timeouts + c.incomplete,
            c.reshoots,
            c.backpressure_waits
        ));
    };
    let report = measurement.run(stop, &mut progress);
    bar.finish_and_clear();
    Ok(report?)
}

/// Prints what the acquisition captured: frames and rate, re-shoots and
/// losses, the exposures' margin after the settle point, the stream's
/// statistics.
pub(super) fn summarise(report: &Report, measurement: &Measurement<'_>) {
    let camera = measurement.camera();
    let c = &report.counters;
    println!(
        "{} {} frames in {:.1} s ({:.1} frames/s); {} of {} recorded in {}",
        if report.interrupted {
            "stopped after"
        } else {
            "captured"
        },
        c.captured,
        c.elapsed_s,
        c.frames_per_s(),
        measurement.recorded(),
        c.total,
        measurement.dir().display()
    );
    println!(
        "  re-shoots {} (timeouts {}, mismatched frames {}, incomplete {}); \
         lost frames {}; stale frames skipped {}; waits on consumers {} ({:.2} s)",
        c.reshoots,
        c.timeouts,
        c.mismatches,
        c.incomplete,
        c.lost_frames,
        c.stale,
        c.backpressure_waits,
        c.backpressure_s
    );
    if let (Some((lo, hi)), Some(mean)) = (c.margin_s, c.mean_margin_s()) {
        println!(
            "  exposures started {:.2} to {:.2} ms (mean {:.2} ms) after the settle point",
            lo * 1e3,
            hi * 1e3,
            mean * 1e3
        );
    }
    if let Some(s) = camera.stream_statistics() {
        println!(
            "  stream: {} buffers completed, {} failed, {} underruns, \
             {} packets resent, {} missing",
            s.completed, s.failures, s.underruns, s.resent_packets, s.missing_packets
        );
    }
}

//! `mfd serve RESULT_DIR…`: the console over finished results (the
//! pictures and summary.json of each folder); and [`Served`], the console a
//! live command (`mfd measure --serve`) runs beside its measurement.

use std::net::{SocketAddr, ToSocketAddrs};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;

use mfd::console::{self, Console, ConsoleHandle, Mode, Spectral, Stage};
use mfd::live::Report;

/// Arguments of `mfd serve`.
#[derive(Args)]
pub struct ServeArgs {
    /// Result folders (as `mfd reconstruct --out` writes them, or an
    /// `mfd measure --out` folder, whose result/ is served).
    #[arg(required = true)]
    dirs: Vec<PathBuf>,
    /// Address to listen on: PORT (on 127.0.0.1) or HOST:PORT; any address
    /// but a loopback one needs the token printed at start.
    #[arg(long, default_value = "127.0.0.1:8089", value_parser = parse_addr)]
    addr: SocketAddr,
    /// A name of this machine the console may be opened by (the `Host` a
    /// browser sends), besides its addresses, loopback names and, off
    /// loopback, its hostname; repeatable. Any other name is refused (DNS
    /// rebinding).
    #[arg(long, value_name = "NAME")]
    allow_host: Vec<String>,
}

/// `PORT` (on 127.0.0.1) or `HOST:PORT`.
pub fn parse_addr(s: &str) -> Result<SocketAddr, String> {
    if let Ok(port) = s.parse::<u16>() {
        return Ok(SocketAddr::from(([127, 0, 0, 1], port)));
    }
    s.to_socket_addrs()
        .map_err(|e| format!("{s}: expected PORT or HOST:PORT ({e})"))?
        .next()
        .ok_or_else(|| format!("{s}: the name resolves to no address"))
}

/// Runs `mfd serve` until Ctrl-C.
pub fn run(args: &ServeArgs) -> anyhow::Result<()> {
    let console = Console::results_only();
    for dir in &args.dirs {
        let dir = if dir.join("result").is_dir() && !dir.join("summary.json").is_file() {
            dir.join("result")
        } else {
            dir.clone()
        };
        anyhow::ensure!(
            dir.is_dir(),
            super::exit::input(anyhow::anyhow!("{}: not a folder", dir.display()))
        );
        let name = name_of(&dir);
        console.add_results(&name, &dir);
    }
    let handle = console::serve_with_names(args.addr, console, &args.allow_host)?;
    announce(&handle);
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
        .context("installing the Ctrl-C handler")?;
    println!(
        "serving {} result folder(s); Ctrl-C to quit",
        args.dirs.len()
    );
    while !stop.load(Ordering::SeqCst) {
        std::thread::sleep(Duration::from_millis(100));
    }
    handle.shutdown();
    Ok(())
}

/// A readable name for a result folder: its own name, or its parent's when
/// it is a `result/` folder.
fn name_of(dir: &Path) -> String {
    let abs = std::fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf());
    let own = abs.file_name().map(|n| n.to_string_lossy().into_owned());
    match own.as_deref() {
        Some("result") => abs
            .parent()
            .and_then(|p| p.file_name())
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "result".into()),
        Some(n) => n.to_string(),
        None => "result".into(),
    }
}

fn announce(handle: &ConsoleHandle) {
    println!("console: {}", handle.url());
    if handle.token().is_some() {
        println!(
            "  (listening beyond this machine: every request needs the token in that address)"
        );
    }
}

/// The console of a live command: the shared state, its server, the
/// command's stop flag.
pub struct Served {
    /// The state the run writes.
    pub console: Console,
    handle: ConsoleHandle,
    stop: Arc<AtomicBool>,
}

impl Served {
    /// Starts the console on `addr` for a run in `mode` whose stop flag is
    /// `stop`, serving `result_dir` as it fills; `allow_host` as `mfd serve
    /// --allow-host`.
    ///
    /// # Errors
    /// The address cannot be listened on.
    pub fn start(
        addr: SocketAddr,
        mode: Mode,
        stop: &Arc<AtomicBool>,
        screen_px: [u32; 2],
        result_dir: &Path,
        allow_host: &[String],
    ) -> anyhow::Result<Self> {
        let console = Console::live(mode, Arc::clone(stop), Some(screen_px));
        console.add_results("result", result_dir);
        let handle = console::serve_with_names(addr, console.clone(), allow_host)?;
        announce(&handle);
        Ok(Served {
            console,
            handle,
            stop: Arc::clone(stop),
        })
    }

    /// Records how the acquisition ended.
    pub fn acquired(&self, report: &anyhow::Result<Report>) {
        self.console.set_stage(match report {
            Ok(r) if r.interrupted => Stage::Stopped,
            Ok(_) => Stage::Reconstructing,
            Err(e) => Stage::Failed {
                error: format!("{e:#}"),
            },
        });
    }

    /// The spectral stage's fits progress (the pipeline's callback).
    pub fn fitting(&self, pixels_done: usize, pixels_total: usize) {
        self.console.set_spectral(Spectral::Fitting {
            pixels_done,
            pixels_total,
        });
    }

    /// Records the end of the command: the result files are written
    /// (`outcome` Ok) or what failed.
    pub fn finished(&self, outcome: &anyhow::Result<()>) {
        self.console.results_changed();
        match outcome {
            Ok(()) => {
                if self.console.status().stage == Stage::Reconstructing {
                    self.console.set_stage(Stage::Done);
                }
            }
            Err(e) => self.console.set_stage(Stage::Failed {
                error: format!("{e:#}"),
            }),
        }
    }

    /// Keeps the console up for the operator after the run: until Ctrl-C
    /// or the page's stop, or at most `keep` (forever when `None`); at
    /// once when the run was stopped.
    pub fn linger(self, keep: Option<Duration>) {
        if !self.stop.load(Ordering::SeqCst) && keep != Some(Duration::ZERO) {
            println!("console: {} stays open; Ctrl-C to quit", self.handle.url());
            let t0 = Instant::now();
            while !self.stop.load(Ordering::SeqCst) && keep.is_none_or(|k| t0.elapsed() < k) {
                std::thread::sleep(Duration::from_millis(100));
            }
        }
        self.handle.shutdown();
    }
}

//! The console's HTTP and WebSocket interface against a server on
//! 127.0.0.1 port 0 during a simulated measurement (`mfd measure`'s library
//! path: `Measurement::prepare`, the simulated camera, a simulated screen):
//! the preview's pixels are the recorded frames', the progress is the
//! sequencer's counters, stop acts as Ctrl-C, and the token rule holds.

use crate::console_support;

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::console_support::{decode_png, get, request, BIT_DEPTH};
use base64::Engine as _;
use futures_util::StreamExt;
use mfd::acquire::acquisition::Acquisition;
use mfd::console::preview::{display_level, full_scale, SATURATED_RGB};
use mfd::console::{self, Console, Mode, Preview, Progress, Stage, Status};
use mfd::live::{Counters, Start};

fn loopback() -> SocketAddr {
    "127.0.0.1:0".parse().unwrap()
}

/// Every status the WebSocket sends until one says `Done`.
fn collect_statuses(addr: SocketAddr) -> std::thread::JoinHandle<Vec<Status>> {
    std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        rt.block_on(async move {
            let url = format!("ws://{addr}/api/ws");
            let (mut ws, _) = tokio_tungstenite::connect_async(url).await.unwrap();
            let mut seen = Vec::new();
            let deadline = Instant::now() + Duration::from_secs(120);
            while let Ok(Some(msg)) = tokio::time::timeout_at(deadline.into(), ws.next()).await {
                let msg = msg.unwrap();
                if let tokio_tungstenite::tungstenite::Message::Text(t) = msg {
                    let st: Status = serde_json::from_str(&t).unwrap();
                    let done = st.stage == Stage::Done;
                    seen.push(st);
                    if done {
                        break;
                    }
                }
            }
            seen
        })
    })
}

/// Previews and raw frames fetched one after the other while `running`.
type Fetched = (BTreeMap<usize, Preview>, BTreeMap<usize, Vec<u16>>);

fn fetch_while(addr: SocketAddr, running: &std::sync::atomic::AtomicBool) -> Fetched {
    let (mut previews, mut raws) = (BTreeMap::new(), BTreeMap::new());
    let mut after: Option<usize> = None;
    while running.load(Ordering::SeqCst) {
        let q = after.map(|a| format!("&after={a}")).unwrap_or_default();
        let a = get(addr, &format!("/api/preview?wait_ms=500{q}"));
        if a.status == 204 {
            continue;
        }
        assert_eq!(a.status, 200);
        let p: Preview = a.json();
        assert!(after.is_none_or(|x| p.index > x), "previews go forward");
        assert_eq!(
            a.header("x-mfd-frame-index"),
            Some(p.index.to_string().as_str())
        );
        after = Some(p.index);
        let q = match p.index {
            0 => String::new(),
            i => format!("?after={}", i - 1),
        };
        let r = get(addr, &format!("/api/frame.png{q}"));
        if r.status == 200 {
            let index: usize = r.header("x-mfd-frame-index").unwrap().parse().unwrap();
            let (w, h, ch, bits, samples) = decode_png(&r.body);
            assert_eq!((w, h, ch, bits), (48, 48, 1, 16));
            raws.insert(index, samples);
        }
        previews.insert(p.index, p);
    }
    (previews, raws)
}

#[test]
fn the_preview_is_the_recorded_frame_and_the_progress_the_counters() {
    let tmp = tempfile::tempdir().unwrap();
    let station = console_support::station();
    // 20 τ × 2 directions = 40 patterns, ≥ 15 ms settle each: ≥ 0.6 s of
    // acquisition, several previews and status messages (every 100 ms).
    let patterns = console_support::patterns(20);
    let total = patterns.len();
    let dir = tmp.path().join("acquisition");
    let mut m = console_support::measurement(
        &station,
        patterns.clone(),
        &dir,
        Start::New { overwrite: false },
        Duration::from_millis(15),
        None,
    );
    let stop = console_support::flag();
    let console = Console::live(Mode::Measure, Arc::clone(&stop), Some([1920, 1080]));
    let server = console::serve(loopback(), console.clone()).unwrap();
    assert!(server.token().is_none(), "loopback needs no token");
    let addr = server.local_addr();
    m.set_tap(Arc::new(console.clone()));

    let ws = collect_statuses(addr);
    // Let the WebSocket client connect before the first frame.
    std::thread::sleep(Duration::from_millis(300));
    let running = std::sync::atomic::AtomicBool::new(true);
    let mut last_counters = Counters::default();
    let (report, (previews, raws)) = std::thread::scope(|s| {
        let fetcher = s.spawn(|| fetch_while(addr, &running));
        let report = m.run(&stop, &mut |c: &Counters| last_counters = c.clone());
        running.store(false, Ordering::SeqCst);
        (report.unwrap(), fetcher.join().unwrap())
    });
    console.set_stage(Stage::Done);
    assert!(!report.interrupted);
    assert_eq!(report.counters.captured, total);

    // The pixels: each preview against the recorded frame of its index.
    assert!(
        previews.len() >= 3,
        "only {} previews during the run",
        previews.len()
    );
    let acq = Acquisition::open(&dir).unwrap();
    let mut recorded = Vec::new();
    let top = full_scale(BIT_DEPTH as u8);
    for (index, p) in &previews {
        acq.read_frame(*index, &mut recorded).unwrap();
        let png = base64::engine::general_purpose::STANDARD
            .decode(&p.png_base64)
            .unwrap();
        let (w, h, ch, bits, rgb) = decode_png(&png);
        assert_eq!((w, h, ch, bits), (48, 48, 3, 8));
        for (k, &c) in recorded.iter().enumerate() {
            let want = if c >= top {
                SATURATED_RGB.map(u16::from)
            } else {
                [u16::from(display_level(c, BIT_DEPTH as u8)); 3]
            };
            assert_eq!(rgb[3 * k..3 * k + 3], want, "frame {index} pixel {k}");
        }
        let pat = patterns[*index];
        assert_eq!(
            (p.pattern.tau, p.pattern.phase_rad),
            (pat.tau, pat.phase_rad)
        );
        assert_eq!(p.histogram.iter().sum::<u64>(), 48 * 48);
        assert_eq!(p.max, *recorded.iter().max().unwrap());
    }
    assert!(!raws.is_empty());
    for (index, raw) in &raws {
        acq.read_frame(*index, &mut recorded).unwrap();
        assert!(
            *raw == recorded,
            "raw frame {index} differs from the recorded one"
        );
    }

    // The progress: what the page is told is what the sequencer counted.
    let statuses = ws.join().unwrap();
    let with_progress: Vec<&Progress> = statuses
        .iter()
        .filter_map(|s| s.progress.as_ref())
        .collect();
    assert!(
        with_progress.len() >= 3,
        "{} status messages",
        with_progress.len()
    );
    for w in with_progress.windows(2) {
        assert!(w[0].done <= w[1].done && w[0].reshoots <= w[1].reshoots);
    }
    for p in &with_progress {
        assert_eq!(p.done, p.first + p.captured);
    }
    let final_progress = Progress::from(&report.counters);
    assert_eq!(**with_progress.last().unwrap(), final_progress);
    let state: Status = get(addr, "/api/state").json();
    assert_eq!(state.progress.as_ref(), Some(&final_progress));
    assert_eq!(Progress::from(&last_counters).done, total);
    let shown = state.showing.unwrap();
    assert_eq!(shown.index, total - 1);
    assert_eq!(shown.tau, patterns[total - 1].tau);
    server.shutdown();
}

#[test]
fn stop_does_what_ctrl_c_does_and_the_run_resumes() {
    let tmp = tempfile::tempdir().unwrap();
    let station = console_support::station();
    let patterns = console_support::patterns(60); // 120 patterns, ≥ 20 ms each
    let total = patterns.len();
    let dir = tmp.path().join("acquisition");
    let start = Start::New { overwrite: false };
    let mut m = console_support::measurement(
        &station,
        patterns.clone(),
        &dir,
        start,
        Duration::from_millis(20),
        None,
    );
    let stop = console_support::flag();
    let console = Console::live(Mode::Measure, Arc::clone(&stop), None);
    let server = console::serve(loopback(), console.clone()).unwrap();
    let addr = server.local_addr();
    m.set_tap(Arc::new(console.clone()));
    assert_eq!(get(addr, "/api/stop").status, 405, "stop is a POST");
    let report = std::thread::scope(|s| {
        s.spawn(|| {
            // Stop once a few frames are in.
            let a = get(addr, "/api/preview?wait_ms=20000&after=4");
            assert_eq!(a.status, 200);
            let a = console_support::page_stop(addr);
            assert_eq!(a.status, 202);
            assert!(a.json::<Status>().stop_requested);
        });
        m.run(&stop, &mut |_| {}).unwrap()
    });
    assert!(report.interrupted);
    let n = m.recorded();
    assert!(n > 5 && n < total, "{n} of {total} recorded");
    let acq = Acquisition::open(&dir).unwrap();
    assert_eq!((acq.frames().len(), acq.complete_frames()), (n, n));
    drop(m);
    let m = console_support::measurement(
        &station,
        patterns,
        &dir,
        Start::Resume,
        Duration::from_millis(20),
        None,
    );
    assert_eq!(m.recorded(), n, "the stopped run resumes where it stopped");
    // A console with nothing to stop says so.
    let idle = console::serve(loopback(), Console::results_only()).unwrap();
    assert_eq!(console_support::page_stop(idle.local_addr()).status, 409);
    server.shutdown();
}

#[test]
fn beyond_loopback_every_request_needs_the_token() {
    let server = console::serve("0.0.0.0:0".parse().unwrap(), Console::results_only()).unwrap();
    let token = server.token().expect("a token off loopback").to_string();
    assert_eq!(token.len(), 32);
    assert!(token.chars().all(|c| c.is_ascii_hexdigit()));
    assert!(server.url().ends_with(&format!("/?token={token}")));
    let addr = SocketAddr::from(([127, 0, 0, 1], server.local_addr().port()));
    let wrong = "0".repeat(32);
    for path in ["/", "/api/state", "/console.js", "/api/results"] {
        assert_eq!(get(addr, path).status, 401, "{path}");
        let q = if path.contains('?') { '&' } else { '?' };
        assert_eq!(get(addr, &format!("{path}{q}token={wrong}")).status, 401);
        assert_eq!(
            get(addr, &format!("{path}{q}token={token}")).status,
            200,
            "{path}"
        );
        let bearer = format!("Authorization: Bearer {token}");
        assert_eq!(request(addr, "GET", path, &[&bearer]).status, 200);
    }
    assert_eq!(request(addr, "POST", "/api/stop", &[]).status, 401);
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let bare = tokio_tungstenite::connect_async(format!("ws://{addr}/api/ws")).await;
        assert!(bare.is_err(), "a WebSocket without the token is refused");
        let with = format!("ws://{addr}/api/ws?token={token}");
        let (mut ws, _) = tokio_tungstenite::connect_async(with).await.unwrap();
        let first = ws.next().await.unwrap().unwrap();
        let st: Status = serde_json::from_str(first.to_text().unwrap()).unwrap();
        assert_eq!(st.mode, Mode::Results);
    });
    server.shutdown();
}

#[test]
fn result_files_are_served_as_they_appear_and_nothing_else() {
    let tmp = tempfile::tempdir().unwrap();
    let console = Console::results_only();
    let name = console.add_results("run 1", tmp.path());
    assert_eq!(name, "run_1");
    let server = console::serve(loopback(), console.clone()).unwrap();
    let addr = server.local_addr();
    let list: Vec<console::ResultListing> = get(addr, "/api/results").json();
    assert!(list[0].files.is_empty());
    std::fs::write(tmp.path().join("front.png"), b"\x89PNG fake").unwrap();
    std::fs::write(tmp.path().join("summary.json"), b"{\"a\":1}").unwrap();
    let list: Vec<console::ResultListing> = get(addr, "/api/results").json();
    let names: Vec<&str> = list[0].files.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(names, ["front.png", "summary.json"]);
    let a = get(addr, "/results/run_1/front.png");
    assert_eq!((a.status, a.body.as_slice()), (200, &b"\x89PNG fake"[..]));
    assert_eq!(a.header("content-type"), Some("image/png"));
    for bad in [
        "/results/run_1/..%2Fsecret.png",
        "/results/run_1/x.png",
        "/results/other/front.png",
    ] {
        assert_eq!(get(addr, bad).status, 404, "{bad}");
    }
    let page = get(addr, "/");
    assert_eq!(page.status, 200);
    let html = String::from_utf8(page.body).unwrap();
    assert!(
        html.contains("console.js") && !html.contains("http"),
        "no outside address"
    );
    assert_eq!(
        get(addr, "/font.ttf").header("content-type"),
        Some("font/ttf")
    );
    server.shutdown();
}

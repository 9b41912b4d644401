//! The console end to end in a real headless browser (Debian's
//! `chromium`, as `scripts/install-deps.sh` installs it) during a simulated
//! measurement: the page's own state (`window.mfdConsole`) must show the
//! preview and the progress moving, the canvas must hold the frame's pixels
//! (not a blank page), the stop button must stop the run as Ctrl-C does
//! (the page sending its token), a result picture must appear, and the
//! content security policy must block nothing of the page's own; a
//! screenshot is written under the test's temporary folder (and copied to
//! `$MFD_CONSOLE_SCREENSHOT` when set).

use crate::console_support;

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use chromiumoxide::browser::{Browser, BrowserConfig};
use chromiumoxide::handler::viewport::Viewport;
use chromiumoxide::page::ScreenshotParams;
use chromiumoxide::Page;
use futures_util::StreamExt;
use mfd::acquire::acquisition::Acquisition;
use mfd::console::preview::{display_level, full_scale};
use mfd::console::{self, Console, Mode};
use mfd::live::Start;
use serde_json::Value;

pub(crate) const CHROMIUM: &str = "/usr/bin/chromium";

/// The page's state.
pub(crate) async fn state(page: &Page) -> Value {
    page.evaluate("JSON.stringify(window.mfdConsole || null)")
        .await
        .unwrap()
        .into_value::<String>()
        .map(|s| serde_json::from_str(&s).unwrap())
        .unwrap()
}

/// Polls the page's state until `ok` holds, or panics after `limit`.
pub(crate) async fn until(
    page: &Page,
    limit: Duration,
    what: &str,
    ok: impl Fn(&Value) -> bool,
) -> Value {
    let t0 = Instant::now();
    loop {
        let s = state(page).await;
        if ok(&s) {
            return s;
        }
        assert!(t0.elapsed() < limit, "the page never showed {what}: {s}");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// Non-black pixels on the preview canvas, counted in the page.
async fn lit_canvas_pixels(page: &Page) -> u64 {
    let js = "(() => { const c = document.getElementById('preview'); \
              const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data; \
              let n = 0; for (let k = 0; k < d.length; k += 4) if (d[k] || d[k+1] || d[k+2]) n++; \
              return n; })()";
    page.evaluate(js).await.unwrap().into_value().unwrap()
}

/// A headless browser with a fresh profile at `profile`, and `args`
/// (`("name", "value")` as `--name=value`).
pub(crate) fn launch_config(profile: &Path, args: &[(&str, &str)]) -> BrowserConfig {
    BrowserConfig::builder()
        .chrome_executable(CHROMIUM)
        .args(args.iter().copied())
        .no_sandbox()
        .user_data_dir(profile)
        .window_size(1400, 1000)
        .viewport(Viewport {
            width: 1400,
            height: 1000,
            device_scale_factor: Some(1.0),
            emulating_mobile: false,
            is_landscape: true,
            has_touch: false,
        })
        .build()
        .unwrap()
}

#[test]
fn the_page_shows_the_live_measurement_and_stops_it() {
    assert!(
        Path::new(CHROMIUM).exists(),
        "{CHROMIUM} is missing: run scripts/install-deps.sh (it installs chromium)"
    );
    let tmp = tempfile::tempdir().unwrap();
    let station = console_support::station();
    // 150 τ × 2 directions = 300 patterns at ≥ 40 ms each: still running
    // when the page has shown a few frames and its stop button is pressed.
    let patterns = console_support::patterns(150);
    let total = patterns.len();
    let dir = tmp.path().join("acquisition");
    let mut m = console_support::measurement(
        &station,
        patterns,
        &dir,
        Start::New { overwrite: false },
        Duration::from_millis(40),
        None,
    );
    let stop = console_support::flag();
    let screen = [station.screen.width, station.screen.height];
    let console = Console::live(Mode::Measure, Arc::clone(&stop), Some(screen));
    let results = tmp.path().join("result");
    std::fs::create_dir_all(&results).unwrap();
    console.add_results("result", &results);
    let server = console::serve("127.0.0.1:0".parse().unwrap(), console.clone()).unwrap();
    let url = server.url();
    m.set_tap(Arc::new(console.clone()));

    let profile = tmp.path().join("chromium-profile");
    let shot = tmp.path().join("console.png");
    let ended = AtomicBool::new(false);
    let page_ready = AtomicBool::new(false);
    let report = std::thread::scope(|s| {
        let browser = s.spawn(|| {
            let rt = tokio::runtime::Builder::new_multi_thread()
                .worker_threads(2)
                .enable_all()
                .build()
                .unwrap();
            let run = Run {
                console: &console,
                results: &results,
                total,
                ended: &ended,
                page_ready: &page_ready,
            };
            rt.block_on(drive(&url, &profile, &shot, run))
        });
        // The run starts once the page is connected (a slow browser start
        // must not find it over).
        let t0 = Instant::now();
        while !page_ready.load(Ordering::SeqCst) && t0.elapsed() < Duration::from_secs(60) {
            std::thread::sleep(Duration::from_millis(20));
        }
        let report = m.run(&stop, &mut |_| {});
        ended.store(true, Ordering::SeqCst);
        (report.unwrap(), browser.join().unwrap())
    });
    let (report, after_stop) = report;
    assert!(report.interrupted, "the page's stop button stopped the run");
    let n = m.recorded();
    assert!(n > 0 && n < total, "{n} of {total}");

    // What the page drew is the last frame: the same pixels lit as in the
    // recorded frame it names (a blank or stale canvas fails here).
    let (index, lit) = after_stop;
    let acq = Acquisition::open(&dir).unwrap();
    assert_eq!(acq.complete_frames(), n);
    let mut frame = Vec::new();
    acq.read_frame(index, &mut frame).unwrap();
    let bits = console_support::BIT_DEPTH as u8;
    let expected = frame
        .iter()
        .filter(|&&c| c >= full_scale(bits) || display_level(c, bits) > 0)
        .count() as u64;
    assert!(expected > 100, "the simulated frame itself is nearly dark");
    assert_eq!(
        lit, expected,
        "lit canvas pixels against recorded frame {index}"
    );

    let png = std::fs::read(&shot).unwrap();
    let (w, h, _, _, samples) = console_support::decode_png(&png);
    assert_eq!((w, h), (1400, 1000));
    assert!(
        samples.iter().any(|&v| v != samples[0]),
        "a uniform screenshot"
    );
    if let Ok(copy) = std::env::var("MFD_CONSOLE_SCREENSHOT") {
        std::fs::copy(&shot, copy).unwrap();
    }
    server.shutdown();
}

/// The run the page watches.
struct Run<'a> {
    console: &'a Console,
    results: &'a Path,
    total: usize,
    ended: &'a AtomicBool,
    page_ready: &'a AtomicBool,
}

/// Drives the page: waits for the preview and progress to move, presses
/// stop, waits for a result picture, takes the screenshot. Returns the
/// frame index last drawn and the canvas' lit pixels.
async fn drive(url: &str, profile: &Path, shot: &Path, run: Run<'_>) -> (usize, u64) {
    let Run {
        console,
        results,
        total,
        ended,
        page_ready,
    } = run;
    let (mut browser, mut handler) = Browser::launch(launch_config(profile, &[])).await.unwrap();
    let events = tokio::spawn(async move { while let Some(Ok(_)) = handler.next().await {} });
    let page = browser.new_page(url).await.unwrap();
    let limit = Duration::from_secs(60);
    until(&page, limit, "a status message", |s| {
        s["statusMessages"].as_u64() >= Some(1)
    })
    .await;
    page_ready.store(true, Ordering::SeqCst);

    let first = until(&page, limit, "a preview and progress", |s| {
        s["previews"].as_u64() >= Some(1) && s["status"]["progress"]["done"].as_u64() >= Some(1)
    })
    .await;
    let (p0, d0) = (
        first["lastPreview"]["index"].as_u64().unwrap(),
        first["status"]["progress"]["done"].as_u64().unwrap(),
    );
    let moved = until(&page, limit, "the preview and progress moving", |s| {
        s["lastPreview"]["index"].as_u64() > Some(p0)
            && s["status"]["progress"]["done"].as_u64() > Some(d0)
            && s["statusMessages"].as_u64() >= Some(3)
    })
    .await;
    assert_eq!(
        moved["status"]["progress"]["total"].as_u64(),
        Some(total as u64)
    );
    assert!(moved["status"]["showing"]["tau"].as_f64().is_some());

    page.find_element("#stop")
        .await
        .unwrap()
        .click()
        .await
        .unwrap();
    until(&page, limit, "the run stopped", |s| {
        s["status"]["stop_requested"] == Value::Bool(true)
    })
    .await;
    // The run ends as Ctrl-C ends it; the command then marks the stage.
    let t0 = Instant::now();
    while !ended.load(Ordering::SeqCst) {
        assert!(t0.elapsed() < limit, "the run did not stop");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    console.set_stage(mfd::console::Stage::Stopped);
    let picture = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/tradeoff.png");
    std::fs::copy(picture, results.join("tradeoff.png")).unwrap();
    console.results_changed();
    until(&page, limit, "the stage and a result picture", |s| {
        s["status"]["stage"]["state"] == "stopped"
            && s["results"][0]["files"][0]["name"] == "tradeoff.png"
    })
    .await;
    let t0 = Instant::now();
    loop {
        let loaded: bool = page
            .evaluate(
                "(() => { const i = document.querySelector('#results img'); \
                 return !!i && i.complete && i.naturalWidth > 0; })()",
            )
            .await
            .unwrap()
            .into_value()
            .unwrap();
        if loaded {
            break;
        }
        assert!(t0.elapsed() < limit, "the result picture did not load");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    // The last frame recorded is drawn once the page has asked for it.
    let last = console.latest_frame().unwrap().index as u64;
    let s = until(&page, limit, "the last frame", |s| {
        s["lastPreview"]["index"].as_u64() == Some(last)
    })
    .await;
    assert!(s["previewNonBlank"].as_u64() > Some(0));
    // The policy (default-src 'self') blocked nothing of the page's own.
    assert_eq!(s["policyViolations"], serde_json::json!([]), "{s}");
    let lit = lit_canvas_pixels(&page).await;
    page.save_screenshot(ScreenshotParams::builder().build(), shot)
        .await
        .unwrap();
    browser.close().await.unwrap();
    let _ = browser.wait().await;
    events.abort();
    (last as usize, lit)
}

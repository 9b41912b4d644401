//! The report in a real headless browser (Debian's chromium): the page's
//! own state must show every image loaded (`naturalWidth > 0`), the
//! sections rendered, and nothing fetched from a network; a screenshot is
//! taken (to `MFD_REPORT_SCREENSHOT` when set, e.g. docs/report.png).

use crate::common;
use crate::report_support;

use chromiumoxide::browser::{Browser, BrowserConfig};
use chromiumoxide::page::ScreenshotParams;
use futures_util::StreamExt;

const CHROMIUM: &str = "/usr/bin/chromium";

/// The page's state: images, those loaded, sections, body height.
const STATE: &str = "(() => { const imgs = [...document.images]; return { \
images: imgs.length, loaded: imgs.filter(i => i.complete && i.naturalWidth > 0).length, \
sections: document.querySelectorAll('h2').length, \
height: document.body.scrollHeight, \
resources: performance.getEntriesByType('resource').filter(r => !r.name.startsWith('data:')).length }; })()";

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_image_of_the_report_loads_in_chromium() {
    assert!(
        std::path::Path::new(CHROMIUM).is_file(),
        "{CHROMIUM} missing: scripts/install-deps.sh installs chromium"
    );
    let dir = tempfile::tempdir().unwrap();
    let result = report_support::simulated_result(dir.path());
    let out = common::mfd(&["report", result.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let html = std::fs::read_to_string(result.join("report.html")).unwrap();
    let expected = report_support::check_self_contained(&html).len();

    let profile = dir.path().join("chromium-profile");
    let config = BrowserConfig::builder()
        .chrome_executable(CHROMIUM)
        .no_sandbox()
        .user_data_dir(&profile)
        .window_size(1200, 1500)
        .viewport(chromiumoxide::handler::viewport::Viewport {
            width: 1200,
            height: 1500,
            ..Default::default()
        })
        .build()
        .unwrap();
    let (mut browser, mut handler) = Browser::launch(config).await.unwrap();
    let events = tokio::spawn(async move { while handler.next().await.is_some() {} });
    let url = format!("file://{}", result.join("report.html").display());
    let page = browser.new_page(url.as_str()).await.unwrap();
    page.wait_for_navigation().await.unwrap();
    // Data URLs decode asynchronously: poll the page's state (for at most
    // 20 s; a page that shows nothing never gets there).
    let mut state = serde_json::Value::Null;
    for _ in 0..100 {
        state = page.evaluate(STATE).await.unwrap().into_value().unwrap();
        if state["loaded"] == state["images"] && state["images"].as_u64() > Some(0) {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(200)).await;
    }
    assert_eq!(state["images"].as_u64(), Some(expected as u64), "{state}");
    assert_eq!(
        state["loaded"], state["images"],
        "not every image loaded: {state}"
    );
    assert!(state["sections"].as_u64() >= Some(7), "{state}");
    assert!(
        state["height"].as_u64() > Some(1500),
        "the page is nearly empty: {state}"
    );
    assert_eq!(
        state["resources"].as_u64(),
        Some(0),
        "the page fetched something: {state}"
    );
    let shot = std::env::var_os("MFD_REPORT_SCREENSHOT")
        .map_or_else(|| dir.path().join("report.png"), std::path::PathBuf::from);
    page.save_screenshot(ScreenshotParams::builder().build(), &shot)
        .await
        .unwrap();
    assert!(std::fs::metadata(&shot).unwrap().len() > 10_000);
    browser.close().await.unwrap();
    let _ = browser.wait().await;
    events.abort();
}

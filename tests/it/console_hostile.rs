//! The console against another site's page in a real headless browser
//! (Debian's `chromium`, started as `console_browser.rs` starts it) during
//! a simulated measurement:
//!
//! * a page of another origin (served by a small server of this test on a
//!   second loopback port) tries `fetch` POST `/api/stop` (no-cors,
//!   `text/plain`), a form POST, `fetch` GET `/api/state` and a WebSocket:
//!   the measurement runs on to its end and nothing of the state reaches the
//!   page;
//! * a page of a name re-pointed at 127.0.0.1 (DNS rebinding, played by
//!   chromium's `--host-resolver-rules`) is the console's origin as far as
//!   the browser knows, and still reads nothing;
//! * a result picture named `<img src=x onerror=…>.png` shows in the
//!   console as its name, as text, and loads as a picture.

use crate::console_browser::{launch_config, until, CHROMIUM};
use crate::console_support;

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use chromiumoxide::browser::Browser;
use chromiumoxide::Page;
use futures_util::StreamExt;
use mfd::console::{self, Console, Mode};
use mfd::live::Start;
use serde_json::Value;

/// A result picture's hostile name: markup that sets the title if run.
const HOSTILE_NAME: &str = "<img src=x onerror=document.title='pwned'>.png";

/// The page of another origin: `attack(console)` tries what a page may
/// make a browser send, and answers with what it got back.
const HOSTILE_PAGE: &str = r#"<!doctype html>
<html><body><iframe name="sink"></iframe><script>
function wsRead(url) {
  return new Promise((done) => {
    const ws = new WebSocket(url);
    ws.onmessage = (e) => { done("read: " + e.data); ws.close(); };
    ws.onerror = () => done("refused");
    setTimeout(() => done("nothing in 5 s"), 5000);
  });
}
window.attack = async (base) => {
  const out = {};
  try {
    await fetch(base + "/api/stop", { method: "POST", mode: "no-cors",
      headers: { "Content-Type": "text/plain" }, body: "stop" });
    out.noCorsPost = "sent";
  } catch (e) { out.noCorsPost = "error: " + e; }
  const form = document.createElement("form");
  form.method = "POST"; form.action = base + "/api/stop";
  form.enctype = "text/plain"; form.target = "sink";
  const input = document.createElement("input");
  input.name = "stop"; input.value = "now"; form.append(input);
  document.body.append(form);
  const landed = new Promise((r) => { document.querySelector("iframe").onload = r; });
  form.submit();
  await Promise.race([landed, new Promise((r) => setTimeout(r, 3000))]);
  out.form = "submitted";
  try { out.state = await (await fetch(base + "/api/state")).text(); }
  catch (e) { out.stateError = String(e); }
  try {
    const r = await fetch(base + "/api/state", { mode: "no-cors" });
    out.stateNoCors = r.type + ": " + await r.text();
  } catch (e) { out.stateNoCorsError = String(e); }
  out.ws = await wsRead(base.replace("http://", "ws://") + "/api/ws");
  return JSON.stringify(out);
};
</script></body></html>"#;

/// A server on its own loopback port answering every request with
/// [`HOSTILE_PAGE`]; stops when dropped.
struct Hostile {
    addr: SocketAddr,
    done: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Hostile {
    fn start() -> Self {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = listener.local_addr().unwrap();
        let done = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&done);
        let thread = std::thread::spawn(move || {
            for stream in listener.incoming() {
                if flag.load(Ordering::SeqCst) {
                    break;
                }
                if let Ok(s) = stream {
                    answer(s);
                }
            }
        });
        Hostile {
            addr,
            done,
            thread: Some(thread),
        }
    }
}

/// Reads one request's head and answers with the hostile page.
fn answer(mut s: TcpStream) {
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let mut head = Vec::new();
    let mut byte = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") && s.read(&mut byte).is_ok_and(|n| n == 1) {
        head.push(byte[0]);
    }
    let reply = format!(
        "HTTP/1.1 200 OK\r\nContent-Type: text/html; charset=utf-8\r\n\
         Content-Length: {}\r\nConnection: close\r\n\r\n{HOSTILE_PAGE}",
        HOSTILE_PAGE.len()
    );
    let _ = s.write_all(reply.as_bytes());
}

impl Drop for Hostile {
    fn drop(&mut self) {
        self.done.store(true, Ordering::SeqCst);
        let _ = TcpStream::connect(self.addr);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// What the browser showed.
struct Seen {
    /// `attack`'s answer.
    attack: Value,
    /// Whether the run was still going once the attack was over.
    running_after_attack: bool,
    /// The stop flag then.
    stopped_after_attack: bool,
    /// `GET /api/state` from the rebound name: status and body.
    rebound: String,
    /// The console page's result section and policy violations.
    page: Value,
}

#[test]
fn another_sites_page_can_neither_stop_nor_read_and_names_show_as_text() {
    assert!(
        Path::new(CHROMIUM).exists(),
        "{CHROMIUM} is missing: run scripts/install-deps.sh (it installs chromium)"
    );
    let tmp = tempfile::tempdir().unwrap();
    let station = console_support::station();
    // 240 patterns at ≥ 25 ms each (≥ 6 s): the attack (about 1 s) is
    // over long before the run.
    let patterns = console_support::patterns(120);
    let total = patterns.len();
    let dir = tmp.path().join("acquisition");
    let start = Start::New { overwrite: false };
    let settle = Duration::from_millis(25);
    let mut m = console_support::measurement(&station, patterns, &dir, start, settle, None);
    let stop = console_support::flag();
    let console = Console::live(Mode::Measure, Arc::clone(&stop), None);
    let results = tmp.path().join("result");
    std::fs::create_dir_all(&results).unwrap();
    let picture = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/tradeoff.png");
    std::fs::copy(picture, results.join(HOSTILE_NAME)).unwrap();
    console.add_results("result", &results);
    let server = console::serve("127.0.0.1:0".parse().unwrap(), console.clone()).unwrap();
    m.set_tap(Arc::new(console.clone()));
    let hostile = Hostile::start();
    let profile = tmp.path().join("chromium-profile");
    let ended = AtomicBool::new(false);
    let page_ready = AtomicBool::new(false);
    let ctx = Ctx {
        console_addr: server.local_addr(),
        console_url: server.url(),
        hostile: hostile.addr,
        profile: &profile,
        stop: &stop,
        ended: &ended,
        page_ready: &page_ready,
    };
    let (report, seen) = std::thread::scope(|s| {
        let browser = s.spawn(|| {
            let rt = tokio::runtime::Builder::new_multi_thread()
                .worker_threads(2)
                .enable_all()
                .build()
                .unwrap();
            rt.block_on(drive(ctx))
        });
        let t0 = Instant::now();
        while !page_ready.load(Ordering::SeqCst) && t0.elapsed() < Duration::from_secs(60) {
            std::thread::sleep(Duration::from_millis(20));
        }
        let report = m.run(&stop, &mut |_| {});
        ended.store(true, Ordering::SeqCst);
        (report.unwrap(), browser.join().unwrap())
    });

    // The attack ran during the measurement, and did not stop it.
    let a = &seen.attack;
    assert!(
        !seen.stopped_after_attack,
        "another site's page stopped the run: {a}"
    );
    assert!(!report.interrupted, "the run was stopped: {a}");
    assert!(
        seen.running_after_attack,
        "the run was over before the attack was: {a}"
    );
    assert_eq!(report.counters.captured, total);
    // The no-cors POST was sent (its answer, refused and marked
    // same-origin only, reaches the page as an error).
    assert!(
        a["noCorsPost"].is_string() && a["form"] == "submitted",
        "{a}"
    );
    // Nothing of the state reached the page: the reads failed or came back
    // opaque (empty), and the WebSocket was refused.
    assert!(
        a.get("state").is_none() && a["stateError"].is_string(),
        "{a}"
    );
    let opaque = a["stateNoCors"].as_str().unwrap_or_default();
    assert!(opaque.is_empty() || opaque == "opaque: ", "{a}");
    assert_eq!(a["ws"].as_str(), Some("refused"), "{a}");
    assert!(!a.to_string().contains("stage"), "{a}");
    // The rebound name is refused by the console itself.
    assert!(seen.rebound.starts_with("403 "), "{}", seen.rebound);
    assert!(!seen.rebound.contains("stage"), "{}", seen.rebound);

    // The hostile name is text in the console, and its picture loads.
    let p = &seen.page;
    assert_eq!(p["captions"], serde_json::json!([HOSTILE_NAME]), "{p}");
    assert_eq!(p["alts"], serde_json::json!([HOSTILE_NAME]), "{p}");
    assert_eq!(p["injected"].as_u64(), Some(0), "markup from a name: {p}");
    assert_eq!(p["title"].as_str(), Some("mfd console"), "{p}");
    assert_eq!(p["violations"], serde_json::json!([]), "{p}");
    drop(hostile);
    server.shutdown();
}

/// What [`drive`] needs.
struct Ctx<'a> {
    console_addr: SocketAddr,
    console_url: String,
    hostile: SocketAddr,
    profile: &'a Path,
    stop: &'a AtomicBool,
    ended: &'a AtomicBool,
    page_ready: &'a AtomicBool,
}

async fn evaluate_string(page: &Page, js: &str) -> String {
    page.evaluate(js).await.unwrap().into_value().unwrap()
}

/// Opens the console, runs the attack once frames come in, tries the
/// rebound name, reads the console's result section.
async fn drive(ctx: Ctx<'_>) -> Seen {
    let port = ctx.console_addr.port();
    let rule = "MAP rebind.test 127.0.0.1";
    let config = launch_config(ctx.profile, &[("host-resolver-rules", rule)]);
    let (mut browser, mut handler) = Browser::launch(config).await.unwrap();
    let events = tokio::spawn(async move { while let Some(Ok(_)) = handler.next().await {} });
    let limit = Duration::from_secs(60);
    let console_page = browser.new_page(ctx.console_url.as_str()).await.unwrap();
    until(&console_page, limit, "a status message", |s| {
        s["statusMessages"].as_u64() >= Some(1)
    })
    .await;
    ctx.page_ready.store(true, Ordering::SeqCst);
    until(&console_page, limit, "frames coming in", |s| {
        s["status"]["progress"]["done"].as_u64() >= Some(1)
    })
    .await;

    let hostile_page = browser
        .new_page(format!("http://{}/", ctx.hostile))
        .await
        .unwrap();
    let call = format!("window.attack('http://127.0.0.1:{port}')");
    let attack = evaluate_string(&hostile_page, &call).await;
    let running_after_attack = !ctx.ended.load(Ordering::SeqCst);
    let stopped_after_attack = ctx.stop.load(Ordering::SeqCst);

    let rebound_page = browser
        .new_page(format!("http://rebind.test:{port}/"))
        .await
        .unwrap();
    let read = "fetch('/api/state').then(async (r) => r.status + ' ' + await r.text())";
    let rebound = evaluate_string(&rebound_page, read).await;

    let page = section(&console_page, limit).await;
    browser.close().await.unwrap();
    let _ = browser.wait().await;
    events.abort();
    Seen {
        attack: serde_json::from_str(&attack).unwrap(),
        running_after_attack,
        stopped_after_attack,
        rebound,
        page,
    }
}

/// The console's result section once its picture (the one it made: in
/// its link in its figure) has loaded: captions, alt texts, elements made
/// from markup (`img[src="x"]`, any `onerror`), the title, and the policy
/// violations the page saw.
async fn section(page: &Page, limit: Duration) -> Value {
    let js = "(() => { \
        const imgs = [...document.querySelectorAll('#results figure > a > img')]; \
        return JSON.stringify({ \
          captions: [...document.querySelectorAll('#results figcaption')].map((e) => e.textContent), \
          alts: imgs.map((i) => i.alt), \
          loaded: imgs.length > 0 && imgs.every((i) => i.complete && i.naturalWidth > 0), \
          injected: document.querySelectorAll('#results img[src=\"x\"], #results [onerror]').length, \
          title: document.title, \
          violations: window.mfdConsole.policyViolations }); })()";
    let t0 = Instant::now();
    loop {
        let v: Value = serde_json::from_str(&evaluate_string(page, js).await).unwrap();
        if v["loaded"] == Value::Bool(true) {
            return v;
        }
        assert!(t0.elapsed() < limit, "the result picture never loaded: {v}");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

//! The console against what another site's page can make a browser send,
//! request by request over HTTP (the browser itself: `console_hostile.rs`):
//! a cross-site POST cannot stop a running measurement, a foreign `Host`
//! (DNS rebinding) and a foreign WebSocket `Origin` are refused, every
//! answer carries the policy headers, the page has no inline script, and a
//! result folder's files are served so that none runs in the console's
//! origin.

use crate::console_support;

use std::net::SocketAddr;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;

use crate::console_support::{get, page_token, send, Answer};
use futures_util::StreamExt;
use mfd::console::{self, Console, Mode, ResultListing, Status};
use mfd::live::Start;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::http::HeaderValue;

fn loopback() -> SocketAddr {
    "127.0.0.1:0".parse().unwrap()
}

/// `POST /api/stop` with `Content-Type: text/plain` (what a form or a
/// no-cors `fetch` of another site sends) and `extra` header lines.
fn post_stop(addr: SocketAddr, extra: &[&str]) -> Answer {
    let mut lines = vec!["Content-Type: text/plain"];
    lines.extend_from_slice(extra);
    let host = format!("Host: {addr}");
    send(addr, "POST /api/stop HTTP/1.1", &host, &lines, b"stop")
}

#[test]
fn a_cross_site_post_does_not_stop_the_measurement() {
    let tmp = tempfile::tempdir().unwrap();
    let station = console_support::station();
    // 120 patterns at ≥ 20 ms each: still running after the refused posts.
    let patterns = console_support::patterns(60);
    let total = patterns.len();
    let dir = tmp.path().join("acquisition");
    let start = Start::New { overwrite: false };
    let settle = Duration::from_millis(20);
    let mut m = console_support::measurement(&station, patterns, &dir, start, settle, None);
    let stop = console_support::flag();
    let console = Console::live(Mode::Measure, Arc::clone(&stop), None);
    let server = console::serve(loopback(), console.clone()).unwrap();
    let addr = server.local_addr();
    m.set_tap(Arc::new(console.clone()));
    let token = page_token(addr);
    assert_eq!(token.len(), 32, "128 bits, hexadecimal");
    let with_token = format!("X-Mfd-Token: {token}");
    let own = format!("Origin: http://{addr}");
    let report = std::thread::scope(|s| {
        s.spawn(|| {
            let a = get(addr, "/api/preview?wait_ms=20000&after=2");
            assert_eq!(a.status, 200);
            let attempts: [(&str, Vec<&str>); 7] = [
                (
                    "another site's page",
                    vec!["Origin: http://attacker.example"],
                ),
                ("another port", vec!["Origin: http://127.0.0.1:1"]),
                ("an opaque origin", vec!["Origin: null"]),
                ("no Origin and no token", vec![]),
                ("its own Origin but no token", vec![&own]),
                (
                    "the token but another site",
                    vec![&with_token, "Origin: http://attacker.example"],
                ),
                (
                    "the token, sent by another site's page",
                    vec![&with_token, "Sec-Fetch-Site: same-site"],
                ),
            ];
            for (what, headers) in &attempts {
                let a = post_stop(addr, headers);
                assert_eq!(
                    a.status,
                    403,
                    "{what}: {}",
                    String::from_utf8_lossy(&a.body)
                );
            }
            let wrong = format!("X-Mfd-Token: {}", "0".repeat(32));
            assert_eq!(post_stop(addr, &[&wrong, &own]).status, 403);
            let in_query = format!("POST /api/stop?token={token} HTTP/1.1");
            let host = format!("Host: {addr}");
            assert_eq!(
                send(addr, &in_query, &host, &[], b"").status,
                403,
                "token in the address"
            );
            assert!(
                !stop.load(Ordering::SeqCst),
                "a refused request set the stop flag"
            );
            // Frames keep coming after the refused posts: the run goes on.
            let last = console.latest_frame().unwrap().index;
            let after = get(addr, &format!("/api/preview?wait_ms=20000&after={last}"));
            assert_eq!(after.status, 200, "the run stopped after refused requests");
            let st: Status = get(addr, "/api/state").json();
            assert!(!st.stop_requested);
            // What the page sends stops it; without an Origin (a client
            // that is not a browser) the token alone does.
            let a = post_stop(addr, &[&with_token]);
            assert_eq!(a.status, 202, "{}", String::from_utf8_lossy(&a.body));
        });
        m.run(&stop, &mut |_| {}).unwrap()
    });
    assert!(report.interrupted, "the token's stop stopped it");
    assert!(m.recorded() < total);
    server.shutdown();
}

#[test]
fn a_foreign_host_is_refused_whatever_it_asks() {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join("front.png"), b"\x89PNG fake").unwrap();
    let console = Console::results_only();
    console.add_results("r", tmp.path());
    let server = console::serve(loopback(), console).unwrap();
    let addr = server.local_addr();
    let port = addr.port();
    let paths = [
        "/",
        "/api/state",
        "/api/results",
        "/results/r/front.png",
        "/console.js",
    ];
    for path in paths {
        let line = format!("GET {path} HTTP/1.1");
        for host in [
            format!("Host: rebind.example:{port}"),
            "Host: rebind.example".to_string(),
            format!("Host: 127.0.0.1:{}", port.wrapping_add(1)),
            format!("Host: 127.0.0.2:{port}"),
        ] {
            let a = send(addr, &line, &host, &[], b"");
            assert_eq!(a.status, 403, "{path} with {host}");
            assert!(!String::from_utf8_lossy(&a.body).contains("stage"));
        }
        for host in [
            format!("Host: {addr}"),
            format!("Host: localhost:{port}"),
            format!("Host: LocalHost:{port}"),
            format!("Host: [::1]:{port}"),
        ] {
            assert_eq!(
                send(addr, &line, &host, &[], b"").status,
                200,
                "{path} {host}"
            );
        }
    }
    // HTTP/1.0 needs no Host: a request that names none is refused too.
    assert_eq!(
        send(addr, "GET /api/state HTTP/1.0", "", &[], b"").status,
        403
    );
    server.shutdown();

    // Off loopback the token does not make a foreign Host acceptable.
    let open = console::serve("0.0.0.0:0".parse().unwrap(), Console::results_only()).unwrap();
    let at = SocketAddr::from(([127, 0, 0, 1], open.local_addr().port()));
    let line = format!("GET /api/state?token={} HTTP/1.1", open.token().unwrap());
    let foreign = format!("Host: rebind.example:{}", at.port());
    assert_eq!(send(at, &line, &foreign, &[], b"").status, 403);
    assert_eq!(
        send(at, &line, &format!("Host: {at}"), &[], b"").status,
        200
    );
    open.shutdown();
}

/// The answer to a WebSocket handshake with `origin` and `host` (`None`:
/// the client's own): `Ok(first status message)` or the refusal's status.
async fn ws_handshake(
    addr: SocketAddr,
    origin: Option<&str>,
    host: Option<&str>,
) -> Result<Status, u16> {
    let mut req = format!("ws://{addr}/api/ws").into_client_request().unwrap();
    if let Some(o) = origin {
        req.headers_mut()
            .insert("origin", HeaderValue::from_str(o).unwrap());
    }
    if let Some(h) = host {
        req.headers_mut()
            .insert("host", HeaderValue::from_str(h).unwrap());
    }
    match tokio_tungstenite::connect_async(req).await {
        Ok((mut ws, _)) => {
            let first = ws.next().await.unwrap().unwrap();
            Ok(serde_json::from_str(first.to_text().unwrap()).unwrap())
        }
        Err(tokio_tungstenite::tungstenite::Error::Http(r)) => Err(r.status().as_u16()),
        Err(e) => panic!("the handshake failed otherwise: {e}"),
    }
}

#[test]
fn a_websocket_from_another_origin_is_refused() {
    let server = console::serve(loopback(), Console::results_only()).unwrap();
    let addr = server.local_addr();
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        for origin in ["http://attacker.example", "http://127.0.0.1:1", "null"] {
            assert_eq!(
                ws_handshake(addr, Some(origin), None).await.err(),
                Some(403),
                "{origin}"
            );
        }
        let foreign = format!("rebind.example:{}", addr.port());
        let own = format!("http://{foreign}");
        assert_eq!(
            ws_handshake(addr, Some(&own), Some(&foreign)).await.err(),
            Some(403)
        );
        let page = format!("http://{addr}");
        let st = ws_handshake(addr, Some(&page), None)
            .await
            .expect("the page's own origin");
        assert_eq!(st.mode, Mode::Results);
        let st = ws_handshake(addr, None, None)
            .await
            .expect("no Origin: not a browser");
        assert_eq!(st.mode, Mode::Results);
    });
    server.shutdown();
}

/// The headers every answer must carry.
fn assert_policy_headers(a: &Answer, what: &str) {
    let csp = a.header("content-security-policy").unwrap_or_default();
    assert!(csp.contains("default-src 'self'"), "{what}: CSP {csp:?}");
    assert!(
        csp.contains("frame-ancestors 'none'"),
        "{what}: CSP {csp:?}"
    );
    assert_eq!(
        a.header("x-content-type-options"),
        Some("nosniff"),
        "{what}"
    );
    assert_eq!(a.header("referrer-policy"), Some("no-referrer"), "{what}");
    assert_eq!(a.header("x-frame-options"), Some("DENY"), "{what}");
    assert_eq!(
        a.header("cross-origin-resource-policy"),
        Some("same-origin"),
        "{what}"
    );
}

#[test]
fn every_answer_carries_the_policy_and_the_page_no_inline_script() {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join("front.png"), b"\x89PNG fake").unwrap();
    let console = Console::results_only();
    console.add_results("r", tmp.path());
    let server = console::serve(loopback(), console).unwrap();
    let addr = server.local_addr();
    let foreign = format!("Host: rebind.example:{}", addr.port());
    let answers = [
        ("the page", get(addr, "/"), 200),
        ("the script", get(addr, "/console.js"), 200),
        ("the style", get(addr, "/console.css"), 200),
        ("the font", get(addr, "/font.ttf"), 200),
        ("the state", get(addr, "/api/state"), 200),
        ("the results", get(addr, "/api/results"), 200),
        ("a result file", get(addr, "/results/r/front.png"), 200),
        ("no such result", get(addr, "/results/r/none.png"), 404),
        ("no such route", get(addr, "/nowhere"), 404),
        ("stop by GET", get(addr, "/api/stop"), 405),
        ("stop without token", post_stop(addr, &[]), 403),
        (
            "a foreign Host",
            send(addr, "GET / HTTP/1.1", &foreign, &[], b""),
            403,
        ),
    ];
    for (what, a, status) in &answers {
        assert_eq!(a.status, *status, "{what}");
        assert_policy_headers(a, what);
    }
    let html = String::from_utf8(answers[0].1.body.clone())
        .unwrap()
        .to_ascii_lowercase();
    assert_eq!(answers[0].1.header("cache-control"), Some("no-store"));
    // Inline script, inline style or event-handler attributes would need
    // the policy loosened ('unsafe-inline'): none may be in the page.
    for script in html.split("<script").skip(1) {
        let tag = script.split('>').next().unwrap();
        assert!(tag.contains("src="), "an inline <script{tag}>");
        assert!(script
            .split("</script>")
            .next()
            .unwrap()
            .split_once('>')
            .unwrap()
            .1
            .trim()
            .is_empty());
    }
    assert!(
        !html.contains("<style") && !html.contains(" style="),
        "inline style"
    );
    let words: Vec<&str> = html
        .split(|c: char| c.is_whitespace() || c == '<')
        .collect();
    let handlers: Vec<&&str> = words
        .iter()
        .filter(|w| w.starts_with("on") && w.contains('='))
        .collect();
    assert!(
        handlers.is_empty(),
        "event-handler attributes: {handlers:?}"
    );
    // The script builds its DOM from data as text: no markup sinks at all.
    let js = String::from_utf8(answers[1].1.body.clone()).unwrap();
    for sink in [
        "innerHTML",
        "outerHTML",
        "insertAdjacentHTML",
        "document.write",
        "eval(",
    ] {
        assert!(!js.contains(sink), "console.js uses {sink}");
    }
    server.shutdown();
}

#[test]
fn result_files_that_could_run_script_are_downloads_and_names_are_data() {
    let tmp = tempfile::tempdir().unwrap();
    let hostile = "<img src=x onerror=alert(1)>.png";
    let files: [(&str, &[u8]); 9] = [
        (hostile, b"\x89PNG fake"),
        (
            "page.html",
            b"<script>fetch('/api/stop',{method:'POST'})</script>",
        ),
        (
            "chart.svg",
            b"<svg xmlns='http://www.w3.org/2000/svg'><script>1</script></svg>",
        ),
        ("frames.npy", b"\x93NUMPY"),
        ("notes.md", b"# notes"),
        ("table.csv", b"a,b\n1,2\n"),
        ("summary.json", b"{\"a\":1}"),
        ("front.png", b"\x89PNG fake"),
        ("tool.exe", b"MZ"),
    ];
    for (name, bytes) in files {
        std::fs::write(tmp.path().join(name), bytes).unwrap();
    }
    let console = Console::results_only();
    console.add_results("r", tmp.path());
    let server = console::serve(loopback(), console).unwrap();
    let addr = server.local_addr();
    let list: Vec<ResultListing> = get(addr, "/api/results").json();
    let kinds: Vec<(&str, &str)> = list[0]
        .files
        .iter()
        .map(|f| (f.name.as_str(), f.kind.as_str()))
        .collect();
    assert_eq!(
        kinds,
        [
            (hostile, "picture"),
            ("front.png", "picture"),
            ("chart.svg", "download"),
            ("frames.npy", "download"),
            ("notes.md", "download"),
            ("page.html", "download"),
            ("summary.json", "data"),
            ("table.csv", "data"),
        ],
        "listed raw, by kind; tool.exe not at all"
    );
    let url_of = |name: &str| {
        let f = list[0].files.iter().find(|f| f.name == name).unwrap();
        f.url.clone()
    };
    let url = url_of(hostile);
    assert_eq!(
        url,
        "/results/r/%3Cimg%20src%3Dx%20onerror%3Dalert%281%29%3E.png"
    );
    let a = get(addr, &url);
    assert_eq!(
        (a.status, a.header("content-type")),
        (200, Some("image/png"))
    );
    for name in ["page.html", "chart.svg", "frames.npy", "notes.md"] {
        let a = get(addr, &url_of(name));
        assert_eq!(a.status, 200, "{name}");
        assert_eq!(
            a.header("content-type"),
            Some("application/octet-stream"),
            "{name}"
        );
        let disposition = a.header("content-disposition").unwrap_or_default();
        assert!(
            disposition.starts_with(&format!("attachment; filename=\"{name}\"")),
            "{name}: {disposition}"
        );
    }
    for (name, kind) in [
        ("table.csv", "text/csv; charset=utf-8"),
        ("summary.json", "application/json"),
        ("front.png", "image/png"),
    ] {
        let a = get(addr, &url_of(name));
        assert_eq!(a.header("content-type"), Some(kind), "{name}");
        assert_eq!(a.header("content-disposition"), None, "{name} is shown");
    }
    // Every file opened on its own is sandboxed: no script, no origin.
    let a = get(addr, &url_of("summary.json"));
    let policies: Vec<&str> = a
        .headers
        .iter()
        .filter(|(k, _)| k == "content-security-policy")
        .map(|(_, v)| v.as_str())
        .collect();
    assert!(policies.contains(&"sandbox"), "{policies:?}");
    assert_eq!(get(addr, "/results/r/tool.exe").status, 404);
    server.shutdown();
}

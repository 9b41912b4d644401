//! The HTTP server: axum on a tokio runtime of its own thread, so that the
//! sequencer's threads stay as they are. Routes:
//!
//! | route | what |
//! |---|---|
//! | `GET /` | the page (with `console.js`, `console.css`, `font.ttf`: nothing from elsewhere), holding this process's token |
//! | `GET /api/state` | the [`Status`](super::Status) as JSON |
//! | `GET /api/ws` | WebSocket: the status on connect and on every change (at most every 100 ms) |
//! | `GET /api/preview?after=N&wait_ms=T` | the latest frame's [`Preview`](super::Preview) once one newer than `N` exists (204 after `T` ms without) |
//! | `GET /api/frame.png?after=N&wait_ms=T` | the same frame's raw counts as PNG (`x-mfd-frame-index` header) |
//! | `POST /api/stop` | stop as Ctrl-C does (202; 409 where nothing runs); needs the token in `X-Mfd-Token` |
//! | `GET /api/results` | the result folders and their files |
//! | `GET /results/{dir}/{file}` | one of those files (PNG, JSON, CSV to view; the rest as downloads) |
//!
//! Every request passes `guard` (`console/guard.rs`) first (its `Host`,
//! `Origin`, token), and every answer carries its headers.
//!
//! The preview is throttled by its client: the page asks for the next
//! frame once it has drawn the last, and gets the latest one, so a slow
//! page skips frames and the sequencer never knows.

use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::body::Body;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{Path as UrlPath, Query, State};
use axum::http::{header, HeaderValue, StatusCode};
use axum::middleware;
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::Router;
use serde::Deserialize;
use tokio::sync::watch;

use super::guard::{guard, Reached};
use super::preview::{encode, Encoded};
use super::results::{list_results, result_file};
use super::state::Console;
use super::{page, ConsoleError};
use crate::live::SharedFrame;

/// Longest a preview request waits for a newer frame.
const MAX_WAIT: Duration = Duration::from_secs(30);
/// Shortest time between two status messages on one WebSocket.
const STATUS_EVERY: Duration = Duration::from_millis(100);

/// What every handler shares.
#[derive(Clone)]
pub(super) struct App {
    console: Console,
    /// This process's token: the page's (`X-Mfd-Token` on state-changing
    /// requests), and off loopback the one every request needs.
    pub(super) token: Arc<str>,
    /// Whether every request needs [`App::token`] (off loopback).
    pub(super) token_everywhere: bool,
    /// Names the `Host` may give besides addresses and loopback names
    /// ([`super::guard::machine_names`]).
    pub(super) host_names: Arc<[String]>,
    closing: watch::Receiver<bool>,
    cache: Arc<Mutex<Option<Arc<Encoded>>>>,
}

/// A running console server; dropping it stops the server.
pub struct ConsoleHandle {
    addr: SocketAddr,
    token: Option<String>,
    close: Option<watch::Sender<bool>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl ConsoleHandle {
    /// The address it listens on (the port chosen when asked for port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// The token requests must carry (`?token=` or `Authorization: Bearer`),
    /// when the server listens beyond the loopback interface.
    pub fn token(&self) -> Option<&str> {
        self.token.as_deref()
    }

    /// The page's address, with the token when one is needed.
    pub fn url(&self) -> String {
        let host = if self.addr.ip().is_unspecified() {
            "127.0.0.1".to_string()
        } else {
            self.addr.ip().to_string()
        };
        let host = if self.addr.is_ipv6() && !self.addr.ip().is_unspecified() {
            format!("[{host}]")
        } else {
            host
        };
        match &self.token {
            Some(t) => format!("http://{host}:{}/?token={t}", self.addr.port()),
            None => format!("http://{host}:{}/", self.addr.port()),
        }
    }

    /// Stops the server: open streams are closed, the thread joined.
    pub fn shutdown(mut self) {
        self.stop();
    }

    fn stop(&mut self) {
        if let Some(close) = self.close.take() {
            close.send_replace(true);
        }
        if let Some(thread) = self.thread.take() {
            if thread.join().is_err() {
                log::warn!("the console's server thread panicked");
            }
        }
    }
}

impl Drop for ConsoleHandle {
    fn drop(&mut self) {
        self.stop();
    }
}

/// A random token of 128 bits, hexadecimal (from the operating system's
/// generator through `rand`'s thread generator, drawn once per process).
fn new_token() -> String {
    use rand::RngCore;
    let mut bytes = [0u8; 16];
    rand::rng().fill_bytes(&mut bytes);
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Starts the console on `addr`, serving `console`. A loopback address
/// serves anyone on this machine who names it by its address or a loopback
/// name; any other needs the token [`ConsoleHandle::token`] on every
/// request (print it for the operator). Either way a state-changing request
/// needs the token the page holds (see the `guard` module).
///
/// # Errors
/// [`ConsoleError::Bind`] when the address cannot be taken;
/// [`ConsoleError::Runtime`] when the server thread cannot start.
pub fn serve(addr: SocketAddr, console: Console) -> Result<ConsoleHandle, ConsoleError> {
    serve_with_names(addr, console, &[])
}

/// [`serve`], the `Host` also allowed to name each of `allowed_hosts` (the
/// operator's `--allow-host`) and, off loopback, the machine's hostname
/// ([`super::guard::machine_names`]).
///
/// # Errors
/// As [`serve`].
pub fn serve_with_names(
    addr: SocketAddr,
    console: Console,
    allowed_hosts: &[String],
) -> Result<ConsoleHandle, ConsoleError> {
    let token = new_token();
    let token_everywhere = !addr.ip().is_loopback();
    let host_names = super::guard::machine_names(allowed_hosts, token_everywhere).into();
    let listener =
        std::net::TcpListener::bind(addr).map_err(|source| ConsoleError::Bind { addr, source })?;
    listener
        .set_nonblocking(true)
        .map_err(|source| ConsoleError::Bind { addr, source })?;
    let local = listener
        .local_addr()
        .map_err(|source| ConsoleError::Bind { addr, source })?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .thread_name("mfd-console")
        .enable_all()
        .build()
        .map_err(|source| ConsoleError::Runtime { source })?;
    let (close, closing) = watch::channel(false);
    let app = App {
        console,
        token: Arc::from(token.as_str()),
        token_everywhere,
        host_names,
        closing: closing.clone(),
        cache: Arc::new(Mutex::new(None)),
    };
    let thread = std::thread::Builder::new()
        .name("mfd-console".into())
        .spawn(move || {
            runtime.block_on(run(listener, app, closing));
            runtime.shutdown_timeout(Duration::from_millis(200));
        })
        .map_err(|source| ConsoleError::Runtime { source })?;
    Ok(ConsoleHandle {
        addr: local,
        token: token_everywhere.then_some(token),
        close: Some(close),
        thread: Some(thread),
    })
}

async fn run(listener: std::net::TcpListener, app: App, mut closing: watch::Receiver<bool>) {
    let listener = match tokio::net::TcpListener::from_std(listener) {
        Ok(l) => l,
        Err(e) => {
            log::error!("console: the listening socket: {e}");
            return;
        }
    };
    let router = router(app);
    let mut until = closing.clone();
    let shutdown = async move {
        let _ = until.wait_for(|c| *c).await;
    };
    let service = router.into_make_service_with_connect_info::<Reached>();
    let server = axum::serve(listener, service).with_graceful_shutdown(shutdown);
    tokio::select! {
        r = server => if let Err(e) = r { log::error!("console: {e}") },
        // Long polls and streams see `closing` too; give them a moment.
        _ = async {
            let _ = closing.wait_for(|c| *c).await;
            tokio::time::sleep(Duration::from_millis(500)).await;
        } => {}
    }
}

fn router(app: App) -> Router {
    Router::new()
        .route("/", get(index))
        .route("/console.js", get(|| async { page::script() }))
        .route("/console.css", get(|| async { page::style() }))
        .route("/font.ttf", get(|| async { page::font() }))
        .route("/api/state", get(state))
        .route("/api/ws", get(ws))
        .route("/api/preview", get(preview))
        .route("/api/frame.png", get(frame_png))
        .route("/api/stop", post(stop))
        .route("/api/results", get(results))
        .route("/results/{dir}/{file}", get(file))
        .layer(middleware::from_fn_with_state(app.clone(), guard))
        .with_state(app)
}

async fn index(State(app): State<App>) -> Response {
    page::index(&app.token)
}

async fn state(State(app): State<App>) -> Response {
    axum::Json(app.console.status()).into_response()
}

async fn ws(State(app): State<App>, upgrade: WebSocketUpgrade) -> Response {
    upgrade.on_upgrade(move |socket| stream_status(socket, app))
}

/// Sends the status on connect and after every change, at most every
/// [`STATUS_EVERY`]; a client that reads slowly only delays its own stream.
async fn stream_status(mut socket: WebSocket, app: App) {
    let mut status = app.console.watch_status();
    let mut closing = app.closing.clone();
    loop {
        let snapshot = status.borrow_and_update().clone();
        let text = match serde_json::to_string(&snapshot) {
            Ok(t) => t,
            Err(e) => {
                log::warn!("console: the status as JSON: {e}");
                return;
            }
        };
        if socket.send(Message::Text(text.into())).await.is_err() {
            return;
        }
        tokio::time::sleep(STATUS_EVERY).await;
        tokio::select! {
            changed = status.changed() => if changed.is_err() { break },
            _ = closing.wait_for(|c| *c) => break,
            msg = socket.recv() => match msg {
                Some(Ok(Message::Close(_))) | None | Some(Err(_)) => return,
                Some(Ok(_)) => {}
            },
        }
    }
    let _ = socket.send(Message::Close(None)).await;
}

#[derive(Deserialize)]
struct Wait {
    after: Option<usize>,
    wait_ms: Option<u64>,
}

/// The latest frame once it is newer than `after`, or `None` after the wait.
async fn newer_frame(app: &App, q: &Wait) -> Option<Arc<SharedFrame>> {
    let mut rx = app.console.watch_frame();
    let mut closing = app.closing.clone();
    let wait = Duration::from_millis(q.wait_ms.unwrap_or(10_000)).min(MAX_WAIT);
    let after = q.after;
    let newer = move |f: &Option<Arc<SharedFrame>>| match (f, after) {
        (Some(f), Some(a)) => f.index > a,
        (Some(_), None) => true,
        (None, _) => false,
    };
    tokio::select! {
        r = tokio::time::timeout(wait, async { rx.wait_for(newer).await.map(|r| r.clone()) }) => {
            r.ok().and_then(Result::ok).flatten()
        }
        _ = closing.wait_for(|c| *c) => None,
    }
}

/// The frame's encoding, from the cache or the blocking pool.
async fn encoded(app: &App, frame: Arc<SharedFrame>) -> Result<Arc<Encoded>, Response> {
    let cached = app
        .cache
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .clone()
        .filter(|e| e.index == frame.index);
    if let Some(e) = cached {
        return Ok(e);
    }
    let done = tokio::task::spawn_blocking(move || encode(&frame)).await;
    let e = match done {
        Ok(Ok(e)) => Arc::new(e),
        Ok(Err(e)) => return Err(server_error(e.to_string())),
        Err(e) => return Err(server_error(format!("the encoder task: {e}"))),
    };
    *app.cache
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner) = Some(Arc::clone(&e));
    Ok(e)
}

fn server_error(msg: String) -> Response {
    log::warn!("console: {msg}");
    (StatusCode::INTERNAL_SERVER_ERROR, msg).into_response()
}

async fn preview(State(app): State<App>, Query(q): Query<Wait>) -> Response {
    let Some(frame) = newer_frame(&app, &q).await else {
        return StatusCode::NO_CONTENT.into_response();
    };
    match encoded(&app, frame).await {
        Ok(e) => bytes_response(e.json.clone(), "application/json", e.index),
        Err(r) => r,
    }
}

async fn frame_png(State(app): State<App>, Query(q): Query<Wait>) -> Response {
    let Some(frame) = newer_frame(&app, &q).await else {
        return StatusCode::NO_CONTENT.into_response();
    };
    match encoded(&app, frame).await {
        Ok(e) => bytes_response(e.raw_png.clone(), "image/png", e.index),
        Err(r) => r,
    }
}

fn bytes_response(bytes: Vec<u8>, kind: &'static str, index: usize) -> Response {
    let mut r = Response::new(Body::from(bytes));
    let h = r.headers_mut();
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static(kind));
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    h.insert("x-mfd-frame-index", HeaderValue::from(index));
    r
}

async fn stop(State(app): State<App>) -> Response {
    if app.console.request_stop() {
        (StatusCode::ACCEPTED, axum::Json(app.console.status())).into_response()
    } else {
        (StatusCode::CONFLICT, "nothing runs here to stop\n").into_response()
    }
}

async fn results(State(app): State<App>) -> Response {
    let dirs = app.console.result_dirs();
    match tokio::task::spawn_blocking(move || list_results(&dirs)).await {
        Ok(list) => axum::Json(list).into_response(),
        Err(e) => server_error(format!("listing the results: {e}")),
    }
}

async fn file(State(app): State<App>, UrlPath((dir, name)): UrlPath<(String, String)>) -> Response {
    let dirs = app.console.result_dirs();
    let found = tokio::task::spawn_blocking(move || result_file(&dirs, &dir, &name)).await;
    match found {
        Ok(Some(served)) => served.into_response(),
        Ok(None) => (StatusCode::NOT_FOUND, "no such result file\n").into_response(),
        Err(e) => server_error(format!("reading a result file: {e}")),
    }
}

//! A deliberately slow console client, for the benchmark that shows a
//! preview falling behind never delays a frame (`mfd bench console`): it
//! asks for previews one after the other like the page, but takes
//! `draw_delay` to "draw" each and reads every response in small chunks
//! with pauses; beside it, WebSocket clients that complete the handshake
//! and then never read a byte, so the server's sends back up.
//!
//! Plain blocking sockets on threads of their own, HTTP/1.1 by hand: the
//! probe must not share the server's runtime, or it would slow the server
//! instead of being a slow remote client.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use serde::Serialize;

/// How slow the client is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Slowness {
    /// Time between receiving a preview and asking for the next.
    pub draw_delay: Duration,
    /// Bytes read at a time from a preview response.
    pub chunk_bytes: usize,
    /// Pause after each chunk.
    pub chunk_pause: Duration,
    /// WebSocket clients that never read.
    pub stalled_sockets: usize,
}

/// What the slow client got.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct ProbeReport {
    /// Previews received whole.
    pub previews: u64,
    /// Bytes of preview responses read.
    pub preview_bytes: u64,
    /// Requests that failed (connection refused or cut).
    pub failed_requests: u64,
    /// WebSocket clients whose handshake the server accepted.
    pub stalled_sockets_open: usize,
}

/// A running slow client.
pub struct SlowClient {
    stop: Arc<AtomicBool>,
    previews: Arc<AtomicU64>,
    bytes: Arc<AtomicU64>,
    failed: Arc<AtomicU64>,
    poller: Option<JoinHandle<()>>,
    stalled: Vec<TcpStream>,
}

impl SlowClient {
    /// Connects to the console at `addr` (with `token` when it needs one).
    ///
    /// # Errors
    /// The I/O error of opening a stalled WebSocket.
    pub fn start(addr: SocketAddr, token: Option<&str>, how: Slowness) -> std::io::Result<Self> {
        let token_q = token.map(|t| format!("&token={t}")).unwrap_or_default();
        let mut stalled = Vec::new();
        for _ in 0..how.stalled_sockets {
            stalled.push(open_stalled_socket(addr, &token_q)?);
        }
        let stop = Arc::new(AtomicBool::new(false));
        let (previews, bytes, failed) = (
            Arc::new(AtomicU64::new(0)),
            Arc::new(AtomicU64::new(0)),
            Arc::new(AtomicU64::new(0)),
        );
        let poller = {
            let (stop, previews, bytes, failed) = (
                Arc::clone(&stop),
                Arc::clone(&previews),
                Arc::clone(&bytes),
                Arc::clone(&failed),
            );
            std::thread::Builder::new()
                .name("mfd-slow-client".into())
                .spawn(move || {
                    let mut after: Option<usize> = None;
                    while !stop.load(Ordering::SeqCst) {
                        match slow_get_preview(addr, &token_q, after, how) {
                            Ok((Some(index), n)) => {
                                after = Some(index);
                                previews.fetch_add(1, Ordering::SeqCst);
                                bytes.fetch_add(n, Ordering::SeqCst);
                                std::thread::sleep(how.draw_delay);
                            }
                            Ok((None, _)) => {}
                            Err(_) => {
                                failed.fetch_add(1, Ordering::SeqCst);
                                std::thread::sleep(Duration::from_millis(50));
                            }
                        }
                    }
                })?
        };
        Ok(SlowClient {
            stop,
            previews,
            bytes,
            failed,
            poller: Some(poller),
            stalled,
        })
    }

    /// Stops the client and says what it got.
    pub fn finish(mut self) -> ProbeReport {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(p) = self.poller.take() {
            if p.join().is_err() {
                log::warn!("the slow client's thread panicked");
            }
        }
        ProbeReport {
            previews: self.previews.load(Ordering::SeqCst),
            preview_bytes: self.bytes.load(Ordering::SeqCst),
            failed_requests: self.failed.load(Ordering::SeqCst),
            stalled_sockets_open: self.stalled.len(),
        }
    }
}

fn open_stalled_socket(addr: SocketAddr, token_q: &str) -> std::io::Result<TcpStream> {
    let mut s = TcpStream::connect(addr)?;
    write!(
        s,
        "GET /api/ws?x=1{token_q} HTTP/1.1\r\nHost: {addr}\r\nUpgrade: websocket\r\n\
         Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\
         Sec-WebSocket-Version: 13\r\n\r\n"
    )?;
    let mut head = [0u8; 12];
    s.read_exact(&mut head)?;
    if &head[9..12] != b"101" {
        return Err(std::io::Error::other(format!(
            "the console refused the WebSocket: {}",
            String::from_utf8_lossy(&head)
        )));
    }
    // From here on nothing is read: the server's messages pile up.
    Ok(s)
}

/// One preview request read slowly: the frame index (`None` on 204) and
/// the bytes read.
fn slow_get_preview(
    addr: SocketAddr,
    token_q: &str,
    after: Option<usize>,
    how: Slowness,
) -> std::io::Result<(Option<usize>, u64)> {
    let mut s = TcpStream::connect(addr)?;
    let after_q = after.map(|a| format!("&after={a}")).unwrap_or_default();
    write!(
        s,
        "GET /api/preview?wait_ms=1000{after_q}{token_q} HTTP/1.1\r\nHost: {addr}\r\n\
         Connection: close\r\n\r\n"
    )?;
    let mut response = Vec::new();
    let mut chunk = vec![0u8; how.chunk_bytes.max(1)];
    loop {
        let n = s.read(&mut chunk)?;
        if n == 0 {
            break;
        }
        response.extend_from_slice(&chunk[..n]);
        std::thread::sleep(how.chunk_pause);
    }
    let text = String::from_utf8_lossy(&response[..response.len().min(4096)]);
    let status = text.split_whitespace().nth(1).unwrap_or("");
    if status == "204" {
        return Ok((None, response.len() as u64));
    }
    let index = text
        .lines()
        .find_map(|l| l.strip_prefix("x-mfd-frame-index:"))
        .and_then(|v| v.trim().parse().ok());
    match (status, index) {
        ("200", Some(i)) => Ok((Some(i), response.len() as u64)),
        _ => Err(std::io::Error::other(format!(
            "unexpected answer: {}",
            text.lines().next().unwrap_or("")
        ))),
    }
}

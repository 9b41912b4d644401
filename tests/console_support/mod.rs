//! Shared by the console tests: a simulated measurement through
//! `mfd measure`'s library path (`Measurement::prepare` with the simulated
//! camera and a simulated screen), and a minimal blocking HTTP/1.1 client.
#![allow(dead_code)]

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use mfd::acquire::camera::CameraConfig;
use mfd::acquire::patterns::{Pattern, Schedule};
use mfd::live::{Measurement, SequencerConfig, Start};
use mfd::optics::station::Station;
use mfd::optics::zernike::ZernikeSurface;
use mfd::sim::{MirroredDisplay, ScreenState, SimDisplay, SimFaults, SimParams, SimulatedCamera};

/// The fixture station (48×48 camera).
pub fn station() -> Station {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/public-small");
    Station::load(&dir.join("station.toml")).unwrap()
}

/// The default schedule's two directions at τ = 1, 2, …, `n_tau`: `2 n_tau` patterns.
pub fn patterns(n_tau: usize) -> Vec<Pattern> {
    Schedule {
        tau_start: 1.0,
        tau_stop: n_tau as f64,
        tau_step: 1.0,
        ..Schedule::default()
    }
    .patterns()
}

/// Bits per sample of the simulated camera.
pub const BIT_DEPTH: u32 = 12;

/// A measurement of `patterns` into `dir` on the simulated station: a flat
/// plate, no noise, the screen settling `settle` after each pattern, and
/// `gain` counts per unit radiance (`None`: the brightest pixel at 90 % of
/// full scale, nothing saturates).
pub fn measurement(
    station: &Station,
    patterns: Vec<Pattern>,
    dir: &Path,
    start: Start,
    settle: Duration,
    gain: Option<f64>,
) -> Measurement<'static> {
    let e = &station.element;
    let centre = [e.aperture_center_mm.x, e.aperture_center_mm.y];
    let flat = ZernikeSurface::flat(e.aperture_radius_mm, centre).unwrap();
    let params = SimParams {
        bit_depth: BIT_DEPTH,
        gain,
        ..SimParams::default()
    };
    let screen = ScreenState::new();
    let camera = SimulatedCamera::of_plate(
        station,
        flat.clone(),
        flat,
        params,
        screen.clone(),
        SimFaults::default(),
    )
    .unwrap();
    let res = (station.screen.width, station.screen.height);
    let display = MirroredDisplay::new(Box::new(SimDisplay::new(res, settle)), screen);
    let config = CameraConfig {
        pixel_format: mfd::acquire::camera::PixelFormat::from_bit_depth(BIT_DEPTH),
        ..CameraConfig::default()
    };
    Measurement::prepare(
        station,
        patterns,
        Box::new(camera),
        Box::new(display),
        config,
        dir,
        start,
        None,
        SequencerConfig::default(),
    )
    .unwrap()
}

/// A stop flag.
pub fn flag() -> Arc<AtomicBool> {
    Arc::new(AtomicBool::new(false))
}

/// An HTTP answer.
pub struct Answer {
    /// Status code.
    pub status: u16,
    /// Header lines, names lower-cased.
    pub headers: Vec<(String, String)>,
    /// The body.
    pub body: Vec<u8>,
}

impl Answer {
    /// A header's value.
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(k, _)| k == name)
            .map(|(_, v)| v.as_str())
    }

    /// The body as JSON.
    pub fn json<T: serde::de::DeserializeOwned>(&self) -> T {
        serde_json::from_slice(&self.body)
            .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&self.body)))
    }
}

/// One request (`Connection: close`), `extra` header lines included.
pub fn request(addr: SocketAddr, method: &str, path: &str, extra: &[&str]) -> Answer {
    let host = format!("Host: {addr}");
    send(
        addr,
        &format!("{method} {path} HTTP/1.1"),
        &host,
        extra,
        b"",
    )
}

/// One request: its first line, its `Host` line (empty: none), `extra`
/// header lines and `body` (with its `Content-Length`).
pub fn send(addr: SocketAddr, first: &str, host: &str, extra: &[&str], body: &[u8]) -> Answer {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
    let mut head = format!("{first}\r\n");
    for h in std::iter::once(&host)
        .chain(extra)
        .filter(|h| !h.is_empty())
    {
        head.push_str(h);
        head.push_str("\r\n");
    }
    head.push_str(&format!(
        "Connection: close\r\nContent-Length: {}\r\n\r\n",
        body.len()
    ));
    s.write_all(head.as_bytes()).unwrap();
    s.write_all(body).unwrap();
    let mut raw = Vec::new();
    s.read_to_end(&mut raw).unwrap();
    let split = raw
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .expect("a complete HTTP head");
    let head = String::from_utf8_lossy(&raw[..split]).into_owned();
    let mut lines = head.lines();
    let status = lines.next().unwrap().split_whitespace().nth(1).unwrap();
    let headers: Vec<(String, String)> = lines
        .filter_map(|l| l.split_once(':'))
        .map(|(k, v)| (k.trim().to_ascii_lowercase(), v.trim().to_string()))
        .collect();
    let mut body = raw[split + 4..].to_vec();
    let chunked = headers
        .iter()
        .any(|(k, v)| k == "transfer-encoding" && v.contains("chunked"));
    if chunked {
        body = dechunk(&body);
    }
    Answer {
        status: status.parse().unwrap(),
        headers,
        body,
    }
}

fn dechunk(mut b: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    loop {
        let eol = b.windows(2).position(|w| w == b"\r\n").unwrap();
        let size =
            usize::from_str_radix(std::str::from_utf8(&b[..eol]).unwrap().trim(), 16).unwrap();
        if size == 0 {
            return out;
        }
        out.extend_from_slice(&b[eol + 2..eol + 2 + size]);
        b = &b[eol + 2 + size + 2..];
    }
}

/// `GET path`.
pub fn get(addr: SocketAddr, path: &str) -> Answer {
    request(addr, "GET", path, &[])
}

/// The token the console's page holds (its `<meta name="mfd-token">`).
pub fn page_token(addr: SocketAddr) -> String {
    let page = get(addr, "/");
    assert_eq!(page.status, 200);
    let html = String::from_utf8(page.body).unwrap();
    let after = html
        .split_once("<meta name=\"mfd-token\" content=\"")
        .expect("the page holds a token")
        .1;
    after.split_once('"').unwrap().0.to_string()
}

/// `POST /api/stop` as the console's page sends it: its token in
/// `X-Mfd-Token`, its own `Origin`.
pub fn page_stop(addr: SocketAddr) -> Answer {
    let token = format!("X-Mfd-Token: {}", page_token(addr));
    let origin = format!("Origin: http://{addr}");
    request(addr, "POST", "/api/stop", &[&token, &origin])
}

/// Decodes a PNG: (width, height, channels, bits, samples as u16).
pub fn decode_png(bytes: &[u8]) -> (u32, u32, usize, u8, Vec<u16>) {
    let mut r = png::Decoder::new(std::io::Cursor::new(bytes.to_vec()))
        .read_info()
        .unwrap();
    let mut buf = vec![0; r.output_buffer_size().unwrap()];
    let info = r.next_frame(&mut buf).unwrap();
    let channels = info.color_type.samples();
    let bits = info.bit_depth as u8;
    let samples = if bits == 16 {
        buf.chunks_exact(2)
            .map(|c| u16::from_be_bytes([c[0], c[1]]))
            .collect()
    } else {
        buf.iter().map(|&v| u16::from(v)).collect()
    };
    (info.width, info.height, channels, bits, samples)
}

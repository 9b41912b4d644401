//! The page and everything it loads, embedded in the binary: the console
//! works without a network beyond the link to mfd (no CDN, no web font
//! service; the font is the DejaVu Sans the pictures use). No script or
//! style is inline: the policy (`default-src 'self'`) forbids it.

use axum::http::{header, HeaderValue};
use axum::response::{IntoResponse, Response};

static INDEX: &str = include_str!("page/index.html");
static SCRIPT: &str = include_str!("page/console.js");
static STYLE: &str = include_str!("page/console.css");
/// DejaVu Sans (Bitstream Vera licence, `assets/fonts/LICENSE`).
static FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");

fn with_type(body: impl IntoResponse, kind: &'static str) -> Response {
    let mut r = body.into_response();
    r.headers_mut()
        .insert(header::CONTENT_TYPE, HeaderValue::from_static(kind));
    r
}

/// Where `index.html` takes the process's token.
const TOKEN_SLOT: &str = "{{MFD_TOKEN}}";

/// `GET /`, holding `token` (hexadecimal: nothing to escape) for the
/// script's state-changing requests. Never cached: a page kept from an
/// earlier process would hold a token this one refuses.
pub fn index(token: &str) -> Response {
    debug_assert!(token.bytes().all(|b| b.is_ascii_hexdigit()));
    let mut r = with_type(INDEX.replace(TOKEN_SLOT, token), "text/html; charset=utf-8");
    r.headers_mut()
        .insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    r
}

/// `GET /console.js`.
pub fn script() -> Response {
    with_type(SCRIPT, "text/javascript; charset=utf-8")
}

/// `GET /console.css`.
pub fn style() -> Response {
    with_type(STYLE, "text/css; charset=utf-8")
}

/// `GET /font.ttf`.
pub fn font() -> Response {
    with_type(FONT, "font/ttf")
}

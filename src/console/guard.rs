//! What every request must show before a handler sees it, and the headers
//! every answer carries: the console runs beside a measurement, on a machine
//! where the operator also browses the web, so another site's page must not
//! be able to read anything from it or change anything in it.
//!
//! In the order checked (the first that fails answers):
//!
//! 1. **Host.** The `Host` (or, in HTTP/2, the request's authority) must name
//!    the address the connection reached (`ip:port`) or a loopback name
//!    (`localhost`, `127.0.0.1`, `[::1]`) with the console's port, or, off
//!    loopback, one of the machine's own names ([`machine_names`]: its
//!    hostname, and each `--allow-host NAME` the operator gave); else 403.
//!    A page of another site whose name an attacker re-points at 127.0.0.1
//!    (DNS rebinding) sends its own name, so it is refused although the
//!    browser thinks it is talking to its own origin.
//! 2. **Access token** (only off loopback): `?token=` or
//!    `Authorization: Bearer`; else 401.
//! 3. **Origin.** A request that carries an `Origin` must come from the
//!    console itself (`http://` + its `Host`); else 403. Browsers send one
//!    on every cross-origin fetch, form POST and WebSocket handshake.
//! 4. **Fetch metadata.** A browser's request made for another site's page
//!    (`Sec-Fetch-Site: cross-site` or `same-site`: another port on
//!    127.0.0.1 is the same site) is refused (403) unless it is a top-level
//!    `GET` navigation, i.e. the operator following a link.
//! 5. **State-changing requests** (any method but `GET` and `HEAD`): need the
//!    process's token in `X-Mfd-Token` (or `Authorization: Bearer`); else 403. The
//!    page holds it (a `<meta name="mfd-token">` in `GET /`, which another
//!    origin cannot read), and a page of another origin can neither know it
//!    nor send a custom header without a CORS preflight, which this server
//!    never grants. So a "simple" cross-site POST (a form, or `fetch` with
//!    `text/plain`) cannot stop a measurement, with or without `Origin`.
//!
//! Every answer, refusals included, carries [`CSP`] (only the console's own
//! files: no inline script or style, no framing), `X-Content-Type-Options:
//! nosniff`, `Referrer-Policy: no-referrer` (the token in an address does
//! not travel on), `X-Frame-Options: DENY` and
//! `Cross-Origin-Resource-Policy: same-origin` (another site cannot even
//! embed a result picture).

use std::net::{IpAddr, SocketAddr};

use axum::extract::connect_info::Connected;
use axum::extract::{ConnectInfo, Request, State};
use axum::http::{header, HeaderMap, HeaderName, HeaderValue, Method, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use axum::serve::IncomingStream;

use super::server::App;

/// The content security policy of every answer.
pub const CSP: &str =
    "default-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'";

/// The header the page sends its token in on state-changing requests.
pub const TOKEN_HEADER: &str = "x-mfd-token";

/// The address a connection reached (the console's own, on the interface
/// the client used): the `Host` must name it or a loopback name.
#[derive(Clone, Copy, Debug)]
pub struct Reached(pub SocketAddr);

impl Connected<IncomingStream<'_, tokio::net::TcpListener>> for Reached {
    fn connect_info(stream: IncomingStream<'_, tokio::net::TcpListener>) -> Self {
        // A socket that cannot say its own address is answered as if it
        // reached the listener's: only loopback names and that pass.
        let local = stream
            .io()
            .local_addr()
            .unwrap_or_else(|_| SocketAddr::from(([127, 0, 0, 1], 0)));
        Reached(local)
    }
}

/// The checks of the module doc, then the headers.
pub async fn guard(
    State(app): State<App>,
    ConnectInfo(Reached(local)): ConnectInfo<Reached>,
    req: Request,
    next: Next,
) -> Response {
    let mut response = match refusal(&app, local, &req) {
        Some(r) => r,
        None => next.run(req).await,
    };
    let h = response.headers_mut();
    // A handler's own policy (a result file's `sandbox`) stays beside this
    // one: a browser enforces every policy it is sent.
    let own: Vec<HeaderValue> = h
        .get_all(header::CONTENT_SECURITY_POLICY)
        .iter()
        .cloned()
        .collect();
    h.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(CSP),
    );
    for v in own {
        h.append(header::CONTENT_SECURITY_POLICY, v);
    }
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    h.insert(
        header::REFERRER_POLICY,
        HeaderValue::from_static("no-referrer"),
    );
    h.insert(header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
    h.insert(
        HeaderName::from_static("cross-origin-resource-policy"),
        HeaderValue::from_static("same-origin"),
    );
    response
}

/// The answer refusing `req`, or `None` when it may pass.
fn refusal(app: &App, local: SocketAddr, req: &Request) -> Option<Response> {
    let headers = req.headers();
    let Some(host) = authority(req) else {
        return Some(forbidden("the request names no Host"));
    };
    if !host_is_ours(host, local, &app.host_names) {
        return Some(forbidden(&format!(
            "Host {host:?} is not this console's address: open it as \
             http://127.0.0.1:{}/ (or the address mfd printed; `--allow-host NAME` \
             admits another name of this machine)",
            local.port()
        )));
    }
    if app.token_everywhere && !carries_access_token(req, &app.token) {
        return Some(
            (
                StatusCode::UNAUTHORIZED,
                "this console needs the token mfd printed when it started: open the address \
                 it printed (…/?token=…)\n",
            )
                .into_response(),
        );
    }
    if let Some(origin) = headers.get(header::ORIGIN) {
        if !same_origin(origin, host) {
            return Some(forbidden(
                "a request from another site's page (its Origin is not this console)",
            ));
        }
    }
    if from_another_site(req) {
        return Some(forbidden(
            "a request made for another site's page (Sec-Fetch-Site)",
        ));
    }
    let changes_state = !matches!(*req.method(), Method::GET | Method::HEAD);
    if changes_state && !carries_page_token(headers, &app.token) {
        return Some(forbidden(
            "a request that changes something needs the console's token in X-Mfd-Token \
             (the console's page sends it)",
        ));
    }
    None
}

fn forbidden(why: &str) -> Response {
    (StatusCode::FORBIDDEN, format!("refused: {why}\n")).into_response()
}

/// The authority the request is addressed to: `Host`, or the URI's (HTTP/2).
fn authority(req: &Request) -> Option<&str> {
    match req.headers().get(header::HOST) {
        Some(h) => h.to_str().ok(),
        None => req.uri().authority().map(|a| a.as_str()),
    }
}

/// The names the console answers to besides addresses and loopback names:
/// `allowed` (the operator's `--allow-host`), and, when it listens beyond
/// loopback (`off_loopback`), the machine's hostname (the kernel's, as
/// `gethostname(2)` gives it: `/proc/sys/kernel/hostname`, else
/// `/etc/hostname`). Lower case, no trailing dot. A rebinding page names
/// its attacker's domain, never one of these: the attacker does not choose
/// this machine's name nor what the operator allowed.
pub fn machine_names(allowed: &[String], off_loopback: bool) -> Vec<String> {
    let mut names: Vec<String> = allowed.iter().map(|n| normal_name(n)).collect();
    if off_loopback {
        let own = ["/proc/sys/kernel/hostname", "/etc/hostname"]
            .iter()
            .find_map(|p| std::fs::read_to_string(p).ok())
            .map(|n| normal_name(&n));
        names.extend(own);
    }
    names.retain(|n| !n.is_empty());
    names.sort();
    names.dedup();
    names
}

fn normal_name(n: &str) -> String {
    n.trim().trim_end_matches('.').to_ascii_lowercase()
}

/// Whether `host` (`name[:port]`) is `local`'s address, a loopback name or
/// one of `names` ([`machine_names`], lower case), with `local`'s port
/// (none written: 80).
pub fn host_is_ours(host: &str, local: SocketAddr, names: &[String]) -> bool {
    let (name, port) = if let Some(rest) = host.strip_prefix('[') {
        let Some((inside, after)) = rest.split_once(']') else {
            return false;
        };
        (&host[..inside.len() + 2], after)
    } else {
        match host.split_once(':') {
            Some((n, _)) => (n, &host[n.len()..]),
            None => (host, ""),
        }
    };
    let port_ok = match port.strip_prefix(':') {
        Some(p) => p.parse::<u16>().ok() == Some(local.port()),
        None => port.is_empty() && local.port() == 80,
    };
    if !port_ok {
        return false;
    }
    let name = name.to_ascii_lowercase();
    if matches!(name.as_str(), "localhost" | "127.0.0.1" | "[::1]") || names.contains(&name) {
        return true;
    }
    let ip = match name.strip_prefix('[').and_then(|n| n.strip_suffix(']')) {
        Some(v6) => v6.parse::<IpAddr>().ok(),
        None => name.parse::<std::net::Ipv4Addr>().ok().map(IpAddr::V4),
    };
    ip.is_some_and(|ip| ip.to_canonical() == local.ip().to_canonical())
}

/// Whether `origin` is the console's own: `http://` or `https://` and the
/// `Host` the request names (the opaque origin `null` is not).
fn same_origin(origin: &HeaderValue, host: &str) -> bool {
    let Ok(origin) = origin.to_str() else {
        return false;
    };
    let rest = origin
        .strip_prefix("http://")
        .or_else(|| origin.strip_prefix("https://"));
    rest.is_some_and(|r| r.eq_ignore_ascii_case(host))
}

/// Whether a browser made this request for a page of another site, other
/// than by the operator navigating to the console.
fn from_another_site(req: &Request) -> bool {
    let h = req.headers();
    let value = |name: &str| h.get(name).and_then(|v| v.to_str().ok());
    let foreign = matches!(value("sec-fetch-site"), Some("cross-site" | "same-site"));
    let navigation = req.method() == Method::GET
        && value("sec-fetch-mode") == Some("navigate")
        && value("sec-fetch-dest").is_none_or(|d| d == "document");
    foreign && !navigation
}

/// Whether the query or `Authorization: Bearer` carries `token`.
fn carries_access_token(req: &Request, token: &str) -> bool {
    let in_query = req.uri().query().is_some_and(|q| {
        q.split('&')
            .filter_map(|kv| kv.split_once('='))
            .any(|(k, v)| k == "token" && same(v, token))
    });
    in_query || bearer(req.headers(), token)
}

/// Whether `X-Mfd-Token` or `Authorization: Bearer` carries `token` (never
/// the query: an address is what another page can make a browser send).
fn carries_page_token(headers: &HeaderMap, token: &str) -> bool {
    let in_header = headers
        .get(TOKEN_HEADER)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| same(v.trim(), token));
    in_header || bearer(headers, token)
}

fn bearer(headers: &HeaderMap, token: &str) -> bool {
    headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "))
        .is_some_and(|v| same(v.trim(), token))
}

/// Equality that takes as long whatever the first difference.
fn same(a: &str, b: &str) -> bool {
    a.len() == b.len()
        && a.bytes()
            .zip(b.bytes())
            .fold(0u8, |acc, (x, y)| acc | (x ^ y))
            == 0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hosts_are_the_reached_address_or_loopback_names_with_the_port() {
        let v4: SocketAddr = "192.168.1.5:8089".parse().unwrap();
        for ok in [
            "192.168.1.5:8089",
            "localhost:8089",
            "LOCALHOST:8089",
            "127.0.0.1:8089",
            "[::1]:8089",
        ] {
            assert!(host_is_ours(ok, v4, &[]), "{ok}");
        }
        for bad in [
            "attacker.example:8089",
            "192.168.1.5:8090",
            "192.168.1.5",
            "localhost",
            "127.0.0.2:8089",
            "localhost.:8089",
            "[::1]",
            "[::1:8089",
            "192.168.1.5:8089:1",
            "",
            ":8089",
        ] {
            assert!(!host_is_ours(bad, v4, &[]), "{bad}");
        }
        let v6: SocketAddr = "[fe80::1]:80".parse().unwrap();
        assert!(host_is_ours("[fe80::1]", v6, &[]));
        assert!(host_is_ours("[FE80:0::1]:80", v6, &[]));
        assert!(host_is_ours("localhost", v6, &[]));
        // Bound to [::] and reached over IPv4: the socket says ::ffff:a.b.c.d.
        let mapped: SocketAddr = "[::ffff:10.0.0.7]:8089".parse().unwrap();
        assert!(host_is_ours("10.0.0.7:8089", mapped, &[]));
    }

    #[test]
    fn the_machines_own_names_pass_and_no_other() {
        let v4: SocketAddr = "192.168.1.5:8089".parse().unwrap();
        let names = machine_names(&["Bench-PC.lab.example.".into(), "bench".into()], false);
        assert_eq!(names, ["bench", "bench-pc.lab.example"]);
        for ok in [
            "bench-pc.lab.example:8089",
            "BENCH:8089",
            "192.168.1.5:8089",
        ] {
            assert!(host_is_ours(ok, v4, &names), "{ok}");
        }
        for bad in [
            "bench:8090",
            "bench",
            "bench.attacker.example:8089",
            "attacker.example:8089",
            "lab.example:8089",
            "bench-pc:8089",
        ] {
            assert!(!host_is_ours(bad, v4, &names), "{bad}");
        }
        // Off loopback the kernel's hostname joins them; on loopback only
        // the names given.
        let own = std::fs::read_to_string("/proc/sys/kernel/hostname").map(|n| normal_name(&n));
        if let Some(own) = own.ok().filter(|n| !n.is_empty()) {
            assert!(machine_names(&[], true).contains(&own));
            assert!(!machine_names(&[], false).contains(&own));
        }
    }

    #[test]
    fn only_the_console_itself_is_its_origin() {
        let h = |s: &'static str| HeaderValue::from_static(s);
        assert!(same_origin(&h("http://127.0.0.1:8089"), "127.0.0.1:8089"));
        assert!(same_origin(&h("http://localhost:8089"), "LocalHost:8089"));
        for bad in [
            "http://attacker.example",
            "http://127.0.0.1:8090",
            "null",
            "http://127.0.0.1:8089.attacker.example",
            "file://",
        ] {
            assert!(!same_origin(&h(bad), "127.0.0.1:8089"), "{bad}");
        }
    }
}

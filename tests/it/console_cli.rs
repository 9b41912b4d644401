//! The console from the command line: `mfd measure --serve` prints the
//! console's address and finishes its run; `mfd serve` serves a result
//! folder until interrupted.

use crate::console_support;

use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::process::{Command, Stdio};

use mfd::console::ResultListing;

fn station() -> String {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    dir.join("tests/fixtures/public-small/station.toml")
        .display()
        .to_string()
}

/// The address in a `console: http://HOST:PORT/…` line.
fn console_addr(line: &str) -> Option<SocketAddr> {
    let rest = line.strip_prefix("console: http://")?;
    rest.split('/').next()?.parse().ok()
}

#[test]
fn measure_serve_prints_the_console_and_completes_the_run() {
    let tmp = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_mfd"))
        .args(["measure", "--station", &station(), "--out"])
        .arg(tmp.path())
        .args(["--tau-start", "2", "--tau-stop", "20", "--tau-step", "2"])
        .args(["--no-reconstruct", "--serve", "0", "--serve-keep-s", "0"])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let addr = text
        .lines()
        .find_map(console_addr)
        .expect("the console's address");
    assert!(addr.ip().is_loopback() && addr.port() != 0, "{addr}");
    assert!(text.contains("captured 20 frames"), "{text}");
}

#[test]
fn serve_browses_a_result_folder_until_interrupted() {
    let tmp = tempfile::tempdir().unwrap();
    let result = tmp.path().join("run7/result");
    std::fs::create_dir_all(&result).unwrap();
    std::fs::write(result.join("summary.json"), b"{}").unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_mfd"))
        .arg("serve")
        .arg(tmp.path().join("run7"))
        .args(["--addr", "0"])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let addr = lines
        .by_ref()
        .map_while(Result::ok)
        .find_map(|l| console_addr(&l))
        .expect("the console's address");
    let list: Vec<ResultListing> = console_support::get(addr, "/api/results").json();
    assert_eq!(list.len(), 1);
    assert_eq!(
        list[0].name, "run7",
        "a result/ folder is named after its parent"
    );
    assert_eq!(list[0].files[0].name, "summary.json");
    let status = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    assert!(child.wait().unwrap().success());
}

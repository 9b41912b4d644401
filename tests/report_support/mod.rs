//! A small simulated measurement laid out as `mfd measure` leaves it
//! (`OUT/acquisition`, `OUT/result`), for the report tests, and the checks
//! every report must pass.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use base64::Engine as _;

/// Simulates the public-small station with random surfaces and
/// reconstructs it into `dir/result`; returns that folder.
pub fn simulated_result(dir: &Path) -> PathBuf {
    let station = super::common::public_small().join("station.toml");
    let acq = dir.join("acquisition");
    let run = |args: &[&str]| {
        let out = super::common::mfd(args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    run(&[
        "simulate",
        "--station",
        station.to_str().unwrap(),
        "--random-surfaces",
        "4",
        "--tau-start",
        "0.5",
        "--tau-stop",
        "100",
        "--tau-step",
        "0.5",
        "--noise",
        "0.02",
        "--out",
        acq.to_str().unwrap(),
    ]);
    let result = dir.join("result");
    run(&[
        "reconstruct",
        acq.to_str().unwrap(),
        "--out",
        result.to_str().unwrap(),
    ]);
    result
}

/// Every `src=` of the page, in order.
pub fn sources(html: &str) -> Vec<&str> {
    html.match_indices("src=\"")
        .map(|(i, m)| {
            let rest = &html[i + m.len()..];
            &rest[..rest.find('"').unwrap()]
        })
        .collect()
}

/// The page fetches nothing: no script, stylesheet link or URL, every
/// image a data URL of a PNG that decodes; returns the images' sizes.
pub fn check_self_contained(html: &str) -> Vec<(u32, u32)> {
    for bad in ["http://", "https://", "<script", "<link", "url(", "file:"] {
        assert!(!html.contains(bad), "the page contains {bad:?}");
    }
    let mut sizes = Vec::new();
    for src in sources(html) {
        let b64 = src
            .strip_prefix("data:image/png;base64,")
            .unwrap_or_else(|| panic!("image not inlined: {}", &src[..src.len().min(60)]));
        let bytes = base64::engine::general_purpose::STANDARD
            .decode(b64)
            .unwrap();
        let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
        let mut reader = decoder.read_info().expect("PNG header");
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).expect("PNG data");
        assert!(info.width > 0 && info.height > 0);
        sizes.push((info.width, info.height));
    }
    sizes
}

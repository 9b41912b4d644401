//! The result folders the console serves: the files each holds, listed
//! when asked (so files appear as soon as they are written), and one file
//! by name (only plain files directly in a served folder, of the kinds
//! below; nothing else on the disk is reachable).
//!
//! A result folder may hold files the console did not write, so a file is
//! served as what it is only where the browser cannot run it in the
//! console's origin:
//!
//! | extension | served as | shown |
//! |---|---|---|
//! | `.png` | `image/png` | in the page (`picture`) |
//! | `.json` | `application/json` | inline, as data (`data`) |
//! | `.csv` | `text/csv` | inline, as data (`data`) |
//! | `.npy`, `.svg`, `.html`, `.toml`, `.md`, `.txt` | `application/octet-stream`, `Content-Disposition: attachment` | a download (`download`) |
//! | anything else | not listed, `404` | – |
//!
//! So an `.svg` or `.html` someone put in a result folder is saved, never
//! rendered where its script would have the console's rights. Every file
//! answer also carries `Content-Security-Policy: sandbox` (beside the
//! console's policy): a file opened on its own runs no script and has no
//! origin. Names are listed as they are (JSON strings); the page shows them
//! as text, and [`ResultFile::url`] is percent-encoded.

use std::path::Path;

use axum::body::Body;
use axum::http::{header, HeaderValue};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};

use super::state::ResultDir;

/// One result folder's files.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ResultListing {
    /// The folder's name in the console's addresses.
    pub name: String,
    /// The folder on disk.
    pub path: String,
    /// Its files, pictures first, by name.
    pub files: Vec<ResultFile>,
}

/// One file of a result folder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ResultFile {
    /// File name.
    pub name: String,
    /// Address on the console (`/results/{dir}/{file}`, percent-encoded).
    pub url: String,
    /// `picture` (PNG), `data` (JSON, CSV) or `download` (the rest the
    /// module doc lists).
    pub kind: String,
    /// Size, bytes.
    pub bytes: u64,
}

/// The content type of a file the console serves, by extension, and its
/// kind (see the module doc).
fn content_type(name: &str) -> Option<(&'static str, &'static str)> {
    let ext = name.rsplit_once('.')?.1.to_ascii_lowercase();
    Some(match ext.as_str() {
        "png" => ("image/png", "picture"),
        "json" => ("application/json", "data"),
        "csv" => ("text/csv; charset=utf-8", "data"),
        "npy" | "svg" | "html" | "htm" | "toml" | "md" | "txt" => {
            ("application/octet-stream", "download")
        }
        _ => return None,
    })
}

/// One result file's answer.
#[derive(Debug)]
pub struct Served {
    /// The file's bytes.
    pub bytes: Vec<u8>,
    /// Its content type.
    pub content_type: &'static str,
    /// The file name, when it is sent as an attachment (`download`).
    pub attachment: Option<String>,
}

impl IntoResponse for Served {
    fn into_response(self) -> Response {
        let mut r = Response::new(Body::from(self.bytes));
        let h = r.headers_mut();
        h.insert(
            header::CONTENT_TYPE,
            HeaderValue::from_static(self.content_type),
        );
        h.append(
            header::CONTENT_SECURITY_POLICY,
            HeaderValue::from_static("sandbox"),
        );
        if let Some(name) = &self.attachment {
            if let Ok(v) = HeaderValue::from_str(&disposition(name)) {
                h.insert(header::CONTENT_DISPOSITION, v);
            }
        }
        r
    }
}

/// `attachment` with the name as RFC 6266 allows: an ASCII stand-in
/// (anything but letters, digits and `._-` as `_`) and the exact name,
/// percent-encoded UTF-8, for browsers that read `filename*`.
fn disposition(name: &str) -> String {
    let plain: String = name
        .chars()
        .map(|c| match c {
            'a'..='z' | 'A'..='Z' | '0'..='9' | '.' | '_' | '-' => c,
            _ => '_',
        })
        .collect();
    format!(
        "attachment; filename=\"{plain}\"; filename*=UTF-8''{}",
        percent_encode(name)
    )
}

/// `s` with every byte but the unreserved ones of RFC 3986 as `%XX`: safe
/// in a path segment and in `filename*`.
pub fn percent_encode(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for b in s.bytes() {
        if b.is_ascii_alphanumeric() || matches!(b, b'-' | b'.' | b'_' | b'~') {
            out.push(char::from(b));
        } else {
            out.push_str(&format!("%{b:02X}"));
        }
    }
    out
}

fn servable(name: &str) -> bool {
    !name.starts_with('.') && !name.contains(['/', '\\']) && content_type(name).is_some()
}

/// Lists every served folder (a folder not yet written lists no files).
pub fn list_results(dirs: &[ResultDir]) -> Vec<ResultListing> {
    dirs.iter()
        .map(|d| ResultListing {
            name: d.name.clone(),
            path: d.path.display().to_string(),
            files: list_dir(&d.name, &d.path),
        })
        .collect()
}

fn list_dir(dir_name: &str, path: &Path) -> Vec<ResultFile> {
    let Ok(entries) = std::fs::read_dir(path) else {
        return Vec::new();
    };
    let mut files: Vec<ResultFile> = entries
        .filter_map(Result::ok)
        .filter(|e| e.file_type().is_ok_and(|t| t.is_file()))
        .filter_map(|e| {
            let name = e.file_name().into_string().ok()?;
            let (_, kind) = content_type(&name).filter(|_| servable(&name))?;
            Some(ResultFile {
                url: format!(
                    "/results/{}/{}",
                    percent_encode(dir_name),
                    percent_encode(&name)
                ),
                kind: kind.into(),
                bytes: e.metadata().map(|m| m.len()).unwrap_or(0),
                name,
            })
        })
        .collect();
    files.sort_by(|a, b| (a.kind != "picture", &a.name).cmp(&(b.kind != "picture", &b.name)));
    files
}

/// File `name` of the served folder `dir`, as it is to be sent; `None`
/// when there is no such folder, the name is not one the console serves, or
/// the file cannot be read.
pub fn result_file(dirs: &[ResultDir], dir: &str, name: &str) -> Option<Served> {
    if !servable(name) {
        return None;
    }
    let d = dirs.iter().find(|d| d.name == dir)?;
    let path = d.path.join(name);
    if !std::fs::symlink_metadata(&path).ok()?.is_file() {
        return None;
    }
    let bytes = std::fs::read(&path).ok()?;
    let (content_type, kind) = content_type(name)?;
    Some(Served {
        bytes,
        content_type,
        attachment: (kind == "download").then(|| name.to_string()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_plain_files_of_known_kinds_directly_inside_are_served() {
        let tmp = tempfile::tempdir().unwrap();
        std::fs::write(tmp.path().join("front.png"), b"png").unwrap();
        std::fs::write(tmp.path().join("summary.json"), b"{}").unwrap();
        std::fs::write(tmp.path().join("secret.key"), b"k").unwrap();
        std::fs::create_dir(tmp.path().join("sub.png")).unwrap();
        let dirs = vec![ResultDir {
            name: "r".into(),
            path: tmp.path().to_path_buf(),
        }];
        let list = list_results(&dirs);
        let names: Vec<&str> = list[0].files.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(names, ["front.png", "summary.json"]);
        assert_eq!(list[0].files[0].url, "/results/r/front.png");
        let png = result_file(&dirs, "r", "front.png").unwrap();
        assert_eq!((png.content_type, png.attachment), ("image/png", None));
        for bad in ["secret.key", "../r/front.png", "sub.png", ".png", "x.png"] {
            assert!(result_file(&dirs, "r", bad).is_none(), "{bad}");
        }
        assert!(result_file(&dirs, "other", "front.png").is_none());
    }
}

#[cfg(test)]
mod names {
    use super::*;

    #[test]
    fn markup_in_a_name_is_encoded_in_the_address_and_the_disposition() {
        let name = "<img src=x onerror=alert(1)> é\"q.svg";
        assert_eq!(
            percent_encode(name),
            "%3Cimg%20src%3Dx%20onerror%3Dalert%281%29%3E%20%C3%A9%22q.svg"
        );
        let d = disposition(name);
        assert!(HeaderValue::from_str(&d).is_ok(), "{d}");
        assert!(d.starts_with("attachment; filename=\"_img_src_x_onerror_alert_1___"));
        assert_eq!(
            content_type("A.SVG"),
            Some(("application/octet-stream", "download"))
        );
        assert_eq!(content_type("a.html").unwrap().1, "download");
        assert_eq!(content_type("a.csv").unwrap().1, "data");
        assert_eq!(content_type("a.exe"), None);
    }
}

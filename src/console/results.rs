//! The result folders the console serves: the pictures and JSON files each
//! holds, listed when asked (so files appear as soon as they are written),
//! and one file by name (only plain files directly in a served folder, of
//! the kinds listed; nothing else on the disk is reachable).

use std::path::Path;

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
    /// Address on the console (`/results/{dir}/{file}`).
    pub url: String,
    /// `picture` (PNG, SVG) or `data` (JSON, CSV, TOML, Markdown, HTML).
    pub kind: String,
    /// Size, bytes.
    pub bytes: u64,
}

/// The content type of a file the console serves, by extension.
fn content_type(name: &str) -> Option<(&'static str, &'static str)> {
    let ext = name.rsplit_once('.')?.1.to_ascii_lowercase();
    Some(match ext.as_str() {
        "png" => ("image/png", "picture"),
        "svg" => ("image/svg+xml", "picture"),
        "json" => ("application/json", "data"),
        "csv" => ("text/csv; charset=utf-8", "data"),
        "toml" | "md" | "txt" => ("text/plain; charset=utf-8", "data"),
        "html" => ("text/html; charset=utf-8", "data"),
        _ => return None,
    })
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
                url: format!("/results/{dir_name}/{name}"),
                kind: kind.into(),
                bytes: e.metadata().map(|m| m.len()).unwrap_or(0),
                name,
            })
        })
        .collect();
    files.sort_by(|a, b| (a.kind != "picture", &a.name).cmp(&(b.kind != "picture", &b.name)));
    files
}

/// File `name` of the served folder `dir`, with its content type; `None`
/// when there is no such folder, the name is not one the console serves, or
/// the file cannot be read.
pub fn result_file(dirs: &[ResultDir], dir: &str, name: &str) -> Option<(Vec<u8>, &'static str)> {
    if !servable(name) {
        return None;
    }
    let d = dirs.iter().find(|d| d.name == dir)?;
    let path = d.path.join(name);
    if !std::fs::symlink_metadata(&path).ok()?.is_file() {
        return None;
    }
    let bytes = std::fs::read(&path).ok()?;
    Some((bytes, content_type(name)?.0))
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
        assert_eq!(result_file(&dirs, "r", "front.png").unwrap().1, "image/png");
        for bad in ["secret.key", "../r/front.png", "sub.png", ".png", "x.png"] {
            assert!(result_file(&dirs, "r", bad).is_none(), "{bad}");
        }
        assert!(result_file(&dirs, "other", "front.png").is_none());
    }
}

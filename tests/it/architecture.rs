//! The house rules of `src/`, checked: which top-level module may use which.
//!
//! The library's modules stand on floors (the table below, the same as in
//! `docs/architecture.md`); a module may use only modules on lower floors, so
//! data flows down and no two modules can import each other, directly or
//! round a circle. The test reads every file under `src/` (the binary's
//! `cli/` and `main.rs` excepted: the binary sits above every floor), finds
//! each path into another top-level module (`crate::x`, `crate::{x, y}`,
//! `super::…` reaching the crate root), and fails naming the file, the line
//! and the rule it breaks. A new top-level module must be given a floor here
//! before anything builds on it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

mod reader;
use reader::{blank_comments_and_strings, tokens, uses_in, Tok, Use};

/// Each top-level module of the library and its floor: a module may use the
/// modules of lower floors only. Keep `docs/architecture.md`'s table equal.
const FLOORS: &[(&str, u32)] = &[
    // Floor 0: the vocabulary and the shared kernels, importing nothing.
    ("conventions", 0),
    ("kernels", 0),
    ("plot", 0),
    ("outcome", 0),
    // Floor 1: the exact optics (station, Zernike surfaces, the tracer).
    ("optics", 1),
    // Also floor 1: sizes refused before they are allocated (uses `outcome`).
    ("limits", 1),
    // Floor 2: file formats of the optics' results.
    ("formats", 2),
    // Floor 3: patterns, schedules, frames, acquisitions, cameras, display.
    ("acquire", 3),
    // Floor 4: the solvers, and the simulated station that stands in for the
    // hardware; neither knows the other.
    ("solve", 4),
    ("sim", 4),
    // Floor 5: what is built on the solvers' results.
    ("budget", 5),
    ("compare", 5),
    // Floor 6: planning a schedule; the report of a result.
    ("plan", 6),
    ("report", 6),
    // Floor 7: the workflows: reconstruction, calibration, a live measurement.
    ("pipeline", 7),
    ("calibrate", 7),
    ("live", 7),
    // Floor 8: the operator's console, above a live measurement.
    ("console", 8),
];

/// Outside the floors: the binary (`src/main.rs` and `src/cli/`) may use all.
const BINARY: &[&str] = &["cli", "main"];

/// A file's module path from the crate root: `src/plan/design.rs` is
/// `plan::design`, `src/solve/mod.rs` is `solve`, `src/pipeline.rs` is
/// `pipeline`; `#[path]` attributes are not used in `src/`.
fn module_path(src_dir: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src_dir).expect("file under src/");
    let mut parts: Vec<String> = rel
        .iter()
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    let last = parts.pop().expect("a file name");
    let stem = last.trim_end_matches(".rs").to_string();
    if stem != "mod" {
        parts.push(stem);
    }
    parts
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.expect("a directory entry").path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

fn src_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

/// Every cross-module use in the library, and the rule each one breaks.
fn violations(src: &Path) -> (Vec<Use>, Vec<String>) {
    let floors: BTreeMap<&str, u32> = FLOORS.iter().copied().collect();
    let tops: Vec<&str> = FLOORS.iter().map(|(m, _)| *m).collect();
    let mut files = Vec::new();
    rust_files(src, &mut files);
    let (mut all, mut broken) = (Vec::new(), Vec::new());
    for file in files {
        let path = module_path(src, &file);
        let Some(top) = path.first() else { continue };
        if top == "lib" || BINARY.contains(&top.as_str()) {
            continue;
        }
        let text = std::fs::read_to_string(&file).unwrap();
        for u in uses_in(&text, &path, &file, &tops) {
            let (Some(f), Some(t)) = (floors.get(u.from.as_str()), floors.get(u.to.as_str()))
            else {
                broken.push(format!(
                    "{}:{}: module `{}` has no floor in tests/it/architecture.rs's FLOORS",
                    u.file.display(),
                    u.line,
                    u.from
                ));
                continue;
            };
            if t >= f {
                let line = text
                    .lines()
                    .nth(u.line - 1)
                    .unwrap_or("")
                    .trim()
                    .to_string();
                broken.push(format!(
                    "{}:{}: `{}` (floor {f}) uses `{}` (floor {t}); a module may use only lower floors\n    {line}",
                    u.file.strip_prefix(src.parent().unwrap()).unwrap_or(&u.file).display(),
                    u.line,
                    u.from,
                    u.to
                ));
            }
            all.push(u);
        }
    }
    (all, broken)
}

#[test]
fn every_module_uses_only_lower_floors() {
    let (uses, broken) = violations(&src_dir());
    // The scan itself must see the house: the main line's imports are there.
    for (from, to) in [
        ("solve", "optics"),
        ("pipeline", "solve"),
        ("console", "live"),
        ("report", "plot"),
    ] {
        assert!(
            uses.iter().any(|u| u.from == from && u.to == to),
            "the scan found no use of `{to}` in `{from}`: the reader is broken"
        );
    }
    assert!(
        broken.is_empty(),
        "{} uses break the floors:\n{}",
        broken.len(),
        broken.join("\n")
    );
}

#[test]
fn every_top_level_module_has_a_floor() {
    let lib = std::fs::read_to_string(src_dir().join("lib.rs")).unwrap();
    let clean = blank_comments_and_strings(&lib);
    let declared: Vec<String> = tokens(&clean)
        .windows(2)
        .filter_map(|w| match (&w[0].0, &w[1].0) {
            (Tok::Ident(m), Tok::Ident(name)) if m == "mod" => Some(name.clone()),
            _ => None,
        })
        .collect();
    assert!(
        declared.len() >= 10,
        "found only {declared:?} in src/lib.rs"
    );
    let floors: Vec<&str> = FLOORS.iter().map(|(m, _)| *m).collect();
    for m in &declared {
        assert!(floors.contains(&m.as_str()), "src/lib.rs declares `mod {m}`, which has no floor in FLOORS (tests/it/architecture.rs); give it one and add it to docs/architecture.md");
    }
    for m in &floors {
        assert!(
            declared.iter().any(|d| d == m),
            "FLOORS lists `{m}`, which src/lib.rs does not declare"
        );
    }
}

#[test]
fn the_floors_table_in_the_docs_matches() {
    let doc =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/architecture.md"))
            .unwrap();
    for (m, f) in FLOORS {
        let row = format!("| {f} | `{m}` |");
        assert!(
            doc.contains(&row),
            "docs/architecture.md lacks the row `{row}` of the floors table"
        );
    }
}

/// A use that breaks the floors is reported with its file, line and text.
#[test]
fn a_use_of_a_higher_floor_is_named() {
    let dir = std::env::temp_dir().join(format!("mfd-arch-{}", std::process::id()));
    let src = dir.join("src");
    std::fs::create_dir_all(src.join("optics")).unwrap();
    std::fs::write(src.join("lib.rs"), "pub mod optics;\n").unwrap();
    std::fs::write(
        src.join("optics/mod.rs"),
        "//! Optics.\n\nuse crate::solve::Thing;\nuse crate::conventions::Axes;\n",
    )
    .unwrap();
    let (_, broken) = violations(&src);
    std::fs::remove_dir_all(&dir).ok();
    assert_eq!(broken.len(), 1, "{broken:?}");
    assert!(
        broken[0].starts_with("src/optics/mod.rs:3: `optics` (floor 1) uses `solve` (floor 4)")
            && broken[0].ends_with("use crate::solve::Thing;"),
        "{}",
        broken[0]
    );
}

/// The house keeps files short enough to read whole (STYLE.md: under ~500
/// lines): every `.rs` file of the library, the binary, the tests and the
/// examples, counted as `wc -l` does.
const MAX_FILE_LINES: usize = 500;

#[test]
fn no_source_file_is_over_500_lines() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    for dir in ["src", "tests", "examples"] {
        rust_files(&root.join(dir), &mut files);
    }
    assert!(
        files.len() > 100,
        "found only {} files: the walk is broken",
        files.len()
    );
    let long: Vec<String> = files
        .iter()
        .filter_map(|f| {
            let text =
                std::fs::read_to_string(f).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
            let lines = text.matches('\n').count();
            (lines > MAX_FILE_LINES).then(|| {
                format!(
                    "{}: {lines} lines",
                    f.strip_prefix(root).unwrap_or(f).display()
                )
            })
        })
        .collect();
    assert!(
        long.is_empty(),
        "{} files over {MAX_FILE_LINES} lines; split each by concern:\n{}",
        long.len(),
        long.join("\n")
    );
}

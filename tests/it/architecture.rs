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

/// Each top-level module of the library and its floor: a module may use the
/// modules of lower floors only. Keep `docs/architecture.md`'s table equal.
const FLOORS: &[(&str, u32)] = &[
    // Floor 0: the vocabulary and the shared kernels, importing nothing.
    ("conventions", 0),
    ("kernels", 0),
    ("plot", 0),
    // Floor 1: the exact optics (station, Zernike surfaces, the tracer).
    ("optics", 1),
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

/// One path from a file of one top-level module into another.
#[derive(Debug, Clone, PartialEq)]
struct Use {
    from: String,
    to: String,
    file: PathBuf,
    line: usize,
}

/// Source text with comments, string and char literals blanked to spaces
/// (newlines kept, so line numbers stay true).
fn blank_comments_and_strings(src: &str) -> String {
    let b = src.as_bytes();
    let mut out = b.to_vec();
    let mut i = 0;
    let blank = |out: &mut Vec<u8>, from: usize, to: usize| {
        for c in &mut out[from..to] {
            if *c != b'\n' {
                *c = b' ';
            }
        }
    };
    while i < b.len() {
        if b[i..].starts_with(b"//") {
            let end = b[i..]
                .iter()
                .position(|&c| c == b'\n')
                .map_or(b.len(), |p| i + p);
            blank(&mut out, i, end);
            i = end;
        } else if b[i..].starts_with(b"/*") {
            let (mut depth, mut j) = (1, i + 2);
            while j < b.len() && depth > 0 {
                if b[j..].starts_with(b"/*") {
                    depth += 1;
                    j += 2;
                } else if b[j..].starts_with(b"*/") {
                    depth -= 1;
                    j += 2;
                } else {
                    j += 1;
                }
            }
            blank(&mut out, i, j);
            i = j;
        } else if b[i] == b'r'
            && (b.get(i + 1) == Some(&b'"') || b.get(i + 1) == Some(&b'#'))
            && (i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_'))
        {
            // Raw string r"…" or r#"…"#.
            let mut j = i + 1;
            let mut hashes = 0;
            while b.get(j) == Some(&b'#') {
                hashes += 1;
                j += 1;
            }
            if b.get(j) != Some(&b'"') {
                i += 1;
                continue;
            }
            let mut close = vec![b'"'];
            close.extend(std::iter::repeat_n(b'#', hashes));
            let end = b[j + 1..]
                .windows(close.len())
                .position(|w| w == close.as_slice())
                .map_or(b.len(), |p| j + 1 + p + close.len());
            blank(&mut out, i, end);
            i = end;
        } else if b[i] == b'"' {
            let mut j = i + 1;
            while j < b.len() && b[j] != b'"' {
                j += if b[j] == b'\\' { 2 } else { 1 };
            }
            let end = (j + 1).min(b.len());
            blank(&mut out, i, end);
            i = end;
        } else if b[i] == b'\'' {
            // A char literal ('x', '\n', '\u{..}'), not a lifetime ('a).
            let end = if b.get(i + 1) == Some(&b'\\') {
                b[i + 2..]
                    .iter()
                    .position(|&c| c == b'\'')
                    .map(|p| i + 2 + p + 1)
            } else if b.get(i + 2) == Some(&b'\'') {
                Some(i + 3)
            } else {
                None
            };
            match end {
                Some(end) => {
                    blank(&mut out, i, end);
                    i = end;
                }
                None => i += 1,
            }
        } else {
            i += 1;
        }
    }
    String::from_utf8(out).expect("blanking keeps UTF-8: only ASCII bytes are replaced")
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Ident(String),
    PathSep,
    Open,
    Close,
    Comma,
    Other,
}

/// Identifiers, `::`, braces and commas with their line numbers; the rest
/// collapsed to `Other`.
fn tokens(clean: &str) -> Vec<(Tok, usize)> {
    let b = clean.as_bytes();
    let (mut out, mut i, mut line) = (Vec::new(), 0, 1);
    while i < b.len() {
        let c = b[i];
        if c == b'\n' {
            line += 1;
            i += 1;
        } else if c.is_ascii_whitespace() {
            i += 1;
        } else if c.is_ascii_alphabetic() || c == b'_' {
            let start = i;
            while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_') {
                i += 1;
            }
            out.push((Tok::Ident(clean[start..i].to_string()), line));
        } else if b[i..].starts_with(b"::") {
            out.push((Tok::PathSep, line));
            i += 2;
        } else {
            let t = match c {
                b'{' => Tok::Open,
                b'}' => Tok::Close,
                b',' => Tok::Comma,
                _ => Tok::Other,
            };
            out.push((t, line));
            i += 1;
        }
    }
    out
}

/// The first segments of the paths a use-tree names after `crate::` when it
/// starts with `{` at `toks[at]`: `{a::b, c, d::{e, f}}` gives a, c, d.
fn group_heads(toks: &[(Tok, usize)], at: usize) -> Vec<(String, usize)> {
    let mut heads = Vec::new();
    let (mut depth, mut expect_head) = (0usize, true);
    for (t, line) in &toks[at..] {
        match t {
            Tok::Open => {
                depth += 1;
                expect_head = depth == 1;
            }
            Tok::Close => {
                depth -= 1;
                if depth == 0 {
                    break;
                }
            }
            Tok::Comma if depth == 1 => expect_head = true,
            Tok::Ident(name) if depth == 1 && expect_head => {
                heads.push((name.clone(), *line));
                expect_head = false;
            }
            _ => {}
        }
    }
    heads
}

/// Every use of another top-level module in one file of module `module_path`
/// (its path from the crate root, e.g. `["plan", "design"]`).
fn uses_in(src: &str, module_path: &[String], file: &Path, tops: &[&str]) -> Vec<Use> {
    let from = &module_path[0];
    let toks = tokens(&blank_comments_and_strings(src));
    let mut found = Vec::new();
    let mut push = |name: &str, line: usize| {
        if name != from && tops.contains(&name) {
            found.push(Use {
                from: from.clone(),
                to: name.to_string(),
                file: file.to_path_buf(),
                line,
            });
        }
    };
    // Inline modules (`mod tests { … }`) deepen `super::`; track them by the
    // brace depth at which each opened.
    let mut inline: Vec<usize> = Vec::new();
    let mut depth = 0usize;
    let mut i = 0;
    while i < toks.len() {
        match &toks[i].0 {
            Tok::Open => depth += 1,
            Tok::Close => {
                depth = depth.saturating_sub(1);
                if inline.last() == Some(&depth) {
                    inline.pop();
                }
            }
            Tok::Ident(kw) if kw == "mod" => {
                if let (Some((Tok::Ident(_), _)), Some((Tok::Open, _))) =
                    (toks.get(i + 1), toks.get(i + 2))
                {
                    inline.push(depth);
                }
            }
            Tok::Ident(kw)
                if kw == "crate" && i + 1 < toks.len() && toks[i + 1].0 == Tok::PathSep =>
            {
                let preceded_by_sep = i > 0 && toks[i - 1].0 == Tok::PathSep;
                if !preceded_by_sep {
                    match toks.get(i + 2) {
                        Some((Tok::Ident(name), line)) => push(name, *line),
                        Some((Tok::Open, _)) => {
                            for (name, line) in group_heads(&toks, i + 2) {
                                push(&name, line);
                            }
                        }
                        _ => {}
                    }
                }
            }
            Tok::Ident(kw) if kw == "super" && !(i > 0 && toks[i - 1].0 == Tok::PathSep) => {
                // Count the chain `super::super::…` and see where it lands.
                let mut ups = 0;
                let mut j = i;
                while matches!(&toks.get(j), Some((Tok::Ident(s), _)) if s == "super")
                    && toks.get(j + 1).map(|t| &t.0) == Some(&Tok::PathSep)
                {
                    ups += 1;
                    j += 2;
                }
                let here = module_path.len() + inline.len();
                if ups >= here {
                    match toks.get(j) {
                        Some((Tok::Ident(name), line)) => push(name, *line),
                        Some((Tok::Open, _)) => {
                            for (name, line) in group_heads(&toks, j) {
                                push(&name, line);
                            }
                        }
                        _ => {}
                    }
                }
                i = j;
                continue;
            }
            _ => {}
        }
        i += 1;
    }
    found
}

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

/// The reader finds what it must and nothing else: every spelling of a path
/// into another module, none in comments or strings, `super` resolved
/// through inline modules.
#[test]
fn the_reader_finds_each_spelling_of_a_use() {
    let src = r#"
//! use crate::console; (a comment)
use crate::optics::station::Station;
use crate::{
    acquire::Frame,
    kernels::{lm, SmallCholesky},
};
const S: &str = "crate::live::Measurement";
fn f() { let _ = crate::solve::spectral::run(); let c = '}'; }
mod tests {
    use super::*;
    use super::super::plan::Design;
    #[test]
    fn t() { let _ = super::super::super::report::Summary::default(); }
}
"#;
    let path = vec!["pipeline".to_string(), "estimator".to_string()];
    let tops = [
        "optics", "acquire", "kernels", "solve", "console", "live", "report", "plan", "pipeline",
    ];
    let found: Vec<(String, usize)> = uses_in(src, &path, Path::new("x.rs"), &tops)
        .into_iter()
        .map(|u| (u.to, u.line))
        .collect();
    let expect: Vec<(String, usize)> = [
        ("optics", 3),
        ("acquire", 5),
        ("kernels", 6),
        ("solve", 9),
        ("report", 14),
    ]
    .iter()
    .map(|(m, l)| (m.to_string(), *l))
    .collect();
    // `super::super::plan` from pipeline::estimator::tests lands in
    // `pipeline::plan`, not the crate root: not a use of `plan`.
    assert_eq!(found, expect);
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

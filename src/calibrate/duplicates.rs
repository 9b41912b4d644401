//! Session entries that repeat another (issue 37). `calibration.md` names
//! no target by an id: a target point is "a point target at the PSM's
//! focus", known by its stage reading `stage_mm` and its camera frame
//! `image`; a screen point is "a marked screen pixel", known by its
//! `screen_px`; a flat or element point is a stage reading. So an entry
//! that repeats another's reading, frame file or marked pixel is the same
//! target (or reading) written twice: counted twice it would weigh double
//! in the adjustment and claim more data than there is. Equality is exact:
//! two readings of a stage agree to the last digit only when one is copied.

use std::collections::HashMap;
use std::path::Path;

use super::session::{folder_of, SessionError};
use super::session_file::SessionFile;
use crate::acquire::acquisition::file_identity;

/// The first entry of `file` (the `session.toml` at `path`) that repeats an
/// earlier one, as an error naming both.
pub(super) fn first_duplicate(file: &SessionFile, path: &Path) -> Option<SessionError> {
    let stage = |points: &mut dyn Iterator<Item = [f64; 3]>| first_repeat(points.map(bits3));
    let dup = |kind: &str, field: &str, (j, i): (usize, usize), value: String| {
        Some(SessionError::Invalid {
            path: path.to_path_buf(),
            entry: format!("{kind}[{i}].{field}"),
            found: format!("{value}, the same as {kind}[{j}].{field}"),
            expected: format!("each {kind} once"),
            todo: "remove the repeated entry, or correct its reading".into(),
        })
    };
    let show = |p: [f64; 3]| format!("{p:?}");
    if let Some(r) = stage(&mut file.flat_point.iter().map(|p| p.stage_mm)) {
        return dup(
            "flat_point",
            "stage_mm",
            r,
            show(file.flat_point[r.1].stage_mm),
        );
    }
    if let Some(r) = stage(&mut file.element_point.iter().map(|p| p.stage_mm)) {
        let value = show(file.element_point[r.1].stage_mm);
        return dup("element_point", "stage_mm", r, value);
    }
    if let Some(r) = stage(&mut file.target_point.iter().map(|p| p.stage_mm)) {
        return dup(
            "target_point",
            "stage_mm",
            r,
            show(file.target_point[r.1].stage_mm),
        );
    }
    let dir = folder_of(path);
    let images = file
        .target_point
        .iter()
        .enumerate()
        .filter_map(|(i, t)| Some((i, t.image.as_deref()?)));
    let mut seen = HashMap::new();
    for (i, name) in images {
        if let Some(j) = seen.insert(file_identity(&dir.join(name)), i) {
            return dup("target_point", "image", (j, i), format!("\"{name}\""));
        }
    }
    if let Some(r) = stage(&mut file.screen_point.iter().map(|p| p.stage_mm)) {
        return dup(
            "screen_point",
            "stage_mm",
            r,
            show(file.screen_point[r.1].stage_mm),
        );
    }
    let marks = file.screen_point.iter().map(|p| bits2(p.screen_px));
    if let Some(r) = first_repeat(marks) {
        let value = format!("{:?}", file.screen_point[r.1].screen_px);
        return dup("screen_point", "screen_px", r, value);
    }
    None
}

/// Exact identity of a reading (`-0.0` and `0.0` are one value).
fn bits3(p: [f64; 3]) -> [u64; 3] {
    p.map(|v| (v + 0.0).to_bits())
}

fn bits2(p: [f64; 2]) -> [u64; 2] {
    p.map(|v| (v + 0.0).to_bits())
}

/// `(j, i)`, j < i, for the first item `i` equal to an earlier item `j`.
fn first_repeat<K: std::hash::Hash + Eq>(items: impl Iterator<Item = K>) -> Option<(usize, usize)> {
    let mut seen = HashMap::new();
    items
        .enumerate()
        .find_map(|(i, k)| seen.insert(k, i).map(|j| (j, i)))
}

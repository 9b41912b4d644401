//! The generator's stations as `mfd-station/2` text (`/3` with an aspect
//! ratio, `docs/proposals/aspect.md`), written field by field from
//! `interchange.md` (not through mfd's own writer), so that the truth
//! reaches mfd through its reader as a lab's file would.

use std::fmt::Write;

use super::gen::Elem;
use super::optics::{Cam, Scr};

/// A float as TOML reads it back exactly: Rust's shortest round-trip form
/// (`1e-5`, `0.25`, `3.0`) is a valid TOML float.
fn f(x: f64) -> String {
    format!("{x:?}")
}

fn list(xs: &[f64]) -> String {
    let items: Vec<String> = xs.iter().map(|&x| f(x)).collect();
    format!("[{}]", items.join(", "))
}

/// The station file of a camera, screen and element.
pub fn station_toml(cam: &Cam, scr: &Scr, elem: &Elem) -> String {
    let version = if cam.aspect.is_some() { 3 } else { 2 };
    let mut s = format!("format = \"mfd-station/{version}\"\n\n[camera]\n");
    let r = &cam.rotation;
    let rows: Vec<String> = (0..3)
        .map(|i| list(&[r[(i, 0)], r[(i, 1)], r[(i, 2)]]))
        .collect();
    let c = &cam.centre;
    let [w, h] = cam.resolution;
    let _ = writeln!(s, "position_mm = {}", list(&[c.x, c.y, c.z]));
    let _ = writeln!(s, "rotation = [{}]", rows.join(", "));
    let _ = writeln!(s, "focal_length_mm = {}", f(cam.focal_mm));
    let _ = writeln!(s, "pixel_pitch_um = {}", f(cam.pitch_um));
    let _ = writeln!(s, "resolution = [{w}, {h}]");
    let _ = writeln!(s, "principal_point_px = {}", list(&cam.principal_px));
    if let Some(a) = cam.aspect {
        let _ = writeln!(s, "aspect_ratio = {}", f(a));
    }
    if cam.k.iter().chain(&cam.p).any(|&v| v != 0.0) {
        s += "\n[camera.distortion]\nmodel = \"brown-conrady\"\n";
        let _ = writeln!(s, "k = {}", list(&cam.k));
        let _ = writeln!(s, "p = {}", list(&cam.p));
    }
    let [sw, sh] = scr.resolution;
    let o = &scr.origin;
    s += "\n[screen]\n";
    let _ = writeln!(s, "resolution = [{sw}, {sh}]");
    let _ = writeln!(s, "pixel_pitch_mm = {}", f(scr.pitch_mm));
    let _ = writeln!(s, "origin_mm = {}", list(&[o.x, o.y, o.z]));
    let _ = writeln!(s, "u_axis = {}", list(scr.u.as_slice()));
    let _ = writeln!(s, "v_axis = {}", list(scr.v.as_slice()));
    if let Some((t, n)) = scr.glass {
        s += "\n[screen.cover_glass]\n";
        let _ = writeln!(s, "thickness_mm = {}", f(t));
        let _ = writeln!(s, "refractive_index = {}", f(n));
    }
    s += "\n[element]\n";
    let _ = writeln!(s, "refractive_index = {}", f(elem.index));
    let _ = writeln!(s, "thickness_mm = {}", f(elem.thickness_mm));
    let _ = writeln!(s, "aperture_radius_mm = {}", f(elem.radius_mm));
    let _ = writeln!(s, "aperture_center_mm = [0.0, 0.0]");
    let _ = writeln!(s, "offset_mm = {}", list(elem.offset_mm.as_slice()));
    let _ = writeln!(s, "tilt_deg = {}", list(&elem.tilt_deg));
    s
}

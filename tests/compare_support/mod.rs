//! Known maps for the comparison tests: an mfd surface in a surfaces.json,
//! and the same surface plus one known Zernike term sampled on an
//! interferometer's pixel grid, placed by the registration's documented
//! convention (`mfd::compare::register`), written here by writers of the
//! test's own.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use mfd::optics::zernike::{ZernikeBasis, ZernikeSurface};

/// mfd's aperture: radius and centre, mm.
pub const RADIUS_MM: f64 = 25.0;
pub const CENTER_MM: [f64; 2] = [1.5, -2.0];
/// Terms of the mfd surface.
pub const TERMS: usize = 21;

/// mfd's coefficients (nm): a fixed, seedless pattern of sizes an optical
/// flat shows (tens of nm falling with order).
pub fn coefficients() -> Vec<f64> {
    (0..TERMS)
        .map(|k| {
            if k < 3 {
                [3.0, 40.0, -25.0][k]
            } else {
                60.0 * ((k as f64) * 1.7).sin() / (1.0 + 0.3 * k as f64)
            }
        })
        .collect()
}

/// mfd's σ per coefficient, nm.
pub fn std() -> Vec<f64> {
    (0..TERMS).map(|k| 0.2 + 0.01 * k as f64).collect()
}

/// Writes `dir/surfaces.json` (mfd-surfaces/2) with [`coefficients`].
pub fn write_surfaces(dir: &Path) -> PathBuf {
    write_surfaces_with(dir, &coefficients())
}

/// Writes `dir/surfaces.json` with these front coefficients and [`std`].
pub fn write_surfaces_with(dir: &Path, coefficients: &[f64]) -> PathBuf {
    let path = dir.join("surfaces.json");
    let json = serde_json::json!({
        "format": "mfd-surfaces/2",
        "zernike": {"ordering": "noll", "normalization": "rms",
                    "radius_mm": RADIUS_MM, "center_mm": CENTER_MM},
        "front": {"coefficients_nm": coefficients, "std_nm": std(),
                  "expected_error_rms_nm": 0.9, "not_reconstructed_because": null},
        "back": null
    });
    std::fs::write(&path, serde_json::to_string_pretty(&json).unwrap()).unwrap();
    path
}

/// Where the map lies: centre in map pixels, pixel size, rotation, flip.
#[derive(Clone, Copy)]
pub struct Placement {
    pub width: usize,
    pub height: usize,
    pub center_px: [f64; 2],
    pub pixel_mm: f64,
    pub rotation_deg: f64,
    pub flip: bool,
    /// Radius of the map's valid disk, mm (beyond mfd's aperture, as an
    /// interferometer's clear aperture is).
    pub valid_radius_mm: f64,
}

impl Placement {
    /// A 201 × 201 map of 0.3 mm pixels centred on the grid.
    pub fn centred(rotation_deg: f64, flip: bool) -> Placement {
        Placement {
            width: 201,
            height: 201,
            center_px: [100.5, 100.5],
            pixel_mm: 0.3,
            rotation_deg,
            flip,
            valid_radius_mm: 27.0,
        }
    }
}

/// The map: mfd's surface plus `added_nm` of Noll term `added_j`, in nm,
/// row-major, row 0 at the top, NaN outside the valid disk. Pixel
/// (c, r) sits at the offset ((c + 0.5 − cx) p, (cy − r − 0.5) p),
/// mirrored in x when flipped, then turned by the rotation around mfd's
/// aperture centre.
pub fn map(p: &Placement, added_j: usize, added_nm: f64) -> Vec<f64> {
    let mut c = coefficients();
    c[added_j - 1] += added_nm;
    let s =
        ZernikeSurface::new(ZernikeBasis::new(TERMS, RADIUS_MM, CENTER_MM).unwrap(), c).unwrap();
    let (sn, cs) = p.rotation_deg.to_radians().sin_cos();
    let mut out = Vec::with_capacity(p.width * p.height);
    for r in 0..p.height {
        for col in 0..p.width {
            let dx = (col as f64 + 0.5 - p.center_px[0]) * p.pixel_mm;
            let dy = (p.center_px[1] - r as f64 - 0.5) * p.pixel_mm;
            if dx.hypot(dy) > p.valid_radius_mm {
                out.push(f64::NAN);
                continue;
            }
            let dx = if p.flip { -dx } else { dx };
            let x = CENTER_MM[0] + dx * cs - dy * sn;
            let y = CENTER_MM[1] + dx * sn + dy * cs;
            out.push(s.height_mm(x, y) * 1e6);
        }
    }
    out
}

/// Fields of a MetroPro header to write (the Reference Guide's names).
pub struct DatHeader {
    pub magic: u32,
    pub format: i16,
    pub size: i32,
    pub phase_res: i16,
    pub wavelength_m: f32,
    pub scale: f32,
    pub obliquity: f32,
    pub lateral_res_m: f32,
    /// Intensity buckets written before the phase block (u16 each pixel).
    pub buckets: usize,
}

impl DatHeader {
    /// Format 3 (4096-byte header), R = 32768, HeNe, S = 0.5, O = 1.
    pub fn format3(pixel_mm: f64) -> DatHeader {
        DatHeader {
            magic: 0x881B_0371,
            format: 3,
            size: 4096,
            phase_res: 1,
            wavelength_m: 632.8e-9,
            scale: 0.5,
            obliquity: 1.0,
            lateral_res_m: (pixel_mm * 1e-3) as f32,
            buckets: 1,
        }
    }

    /// nm per phase count: W S O / R.
    pub fn nm_per_count(&self) -> f64 {
        let r = match self.phase_res {
            0 => 4096.0,
            1 => 32768.0,
            _ => 131072.0,
        };
        f64::from(self.wavelength_m) * f64::from(self.scale) * f64::from(self.obliquity) / r * 1e9
    }
}

/// Writes a MetroPro `.dat` of `heights_nm` (`w × h`) following the
/// Reference Guide's header table: big-endian fields at their offsets, an
/// intensity block, then the phase block of i32 counts with 0x7FFFFFF8 for
/// no data.
pub fn write_dat(path: &Path, hd: &DatHeader, w: usize, h: usize, heights_nm: &[f64]) {
    let size = hd.size.max(0) as usize;
    let mut b = vec![0u8; size.max(834)];
    let put =
        |b: &mut Vec<u8>, at: usize, bytes: &[u8]| b[at..at + bytes.len()].copy_from_slice(bytes);
    let ac_bytes = 2 * w * h * hd.buckets;
    put(&mut b, 0, &hd.magic.to_be_bytes());
    put(&mut b, 4, &hd.format.to_be_bytes());
    put(&mut b, 6, &hd.size.to_be_bytes());
    put(&mut b, 52, &(w as u16).to_be_bytes()); // ac_width
    put(&mut b, 54, &(h as u16).to_be_bytes()); // ac_height
    put(&mut b, 56, &(hd.buckets as u16).to_be_bytes()); // ac_n_buckets
    put(&mut b, 60, &(ac_bytes as i32).to_be_bytes()); // ac_n_bytes
    put(&mut b, 68, &(w as u16).to_be_bytes()); // cn_width
    put(&mut b, 70, &(h as u16).to_be_bytes()); // cn_height
    put(&mut b, 72, &((4 * w * h) as i32).to_be_bytes()); // cn_n_bytes
    put(&mut b, 164, &hd.scale.to_be_bytes()); // intf_scale_factor
    put(&mut b, 168, &hd.wavelength_m.to_be_bytes()); // wavelength_in
    put(&mut b, 176, &hd.obliquity.to_be_bytes()); // obliquity_factor
    put(&mut b, 184, &hd.lateral_res_m.to_be_bytes()); // lateral_res
    put(&mut b, 218, &hd.phase_res.to_be_bytes()); // phase_res
    b.truncate(size.max(834));
    // Intensity: a recognisable ramp, to catch a reader that starts the
    // phase block in the wrong place.
    for k in 0..w * h * hd.buckets {
        b.extend_from_slice(&((k % 4000) as u16).to_be_bytes());
    }
    let q = hd.nm_per_count();
    for v in heights_nm {
        let count: i32 = if v.is_finite() {
            (v / q).round() as i32
        } else {
            0x7FFF_FFF8
        };
        b.extend_from_slice(&count.to_be_bytes());
    }
    std::fs::write(path, b).unwrap();
}

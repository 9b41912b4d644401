//! A simulated session's folder: `session.toml`, `nominal.toml` and the
//! rendered target frames.

use std::path::Path;

use nalgebra::{Point2, Vector3};
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

use super::{gauss, SimulatedSession};
use crate::calibrate::session_file::{
    ReferenceFlat, ScreenPoint, SessionElement, SessionFile, StagePoint, TargetPoint,
    SESSION_FORMAT,
};
use crate::formats::image_io::write_png;
use crate::sim::SimError;

/// A rendered target frame: a Gaussian spot (σ 1.5 px, 3000 counts peak)
/// at `pixel` on 200 counts of ambient, with 10 counts of Gaussian noise,
/// 16-bit.
pub fn render_target(width: u32, height: u32, pixel: Point2<f64>, seed: u64) -> Vec<u16> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let (w, h) = (width as usize, height as usize);
    let mut out = vec![0u16; w * h];
    for (k, v) in out.iter_mut().enumerate() {
        let (x, y) = ((k % w) as f64 + 0.5, (k / w) as f64 + 0.5);
        let r2 = (x - pixel.x).powi(2) + (y - pixel.y).powi(2);
        let spot = if r2 < 100.0 {
            3000.0 * (-r2 / (2.0 * 1.5 * 1.5)).exp()
        } else {
            0.0
        };
        *v = (200.0 + spot + gauss(&mut rng, 10.0))
            .round()
            .clamp(0.0, 65535.0) as u16;
    }
    out
}

/// Writes the session folder: `session.toml` (`mfd-calibration/1`),
/// `nominal.toml`, `targets/NNN.png`; the reference flat's entry points to
/// `flat/acquisition.toml`, which this does not write.
///
/// # Errors
/// [`SimError::Io`], [`SimError::Image`] or [`SimError::Station`] naming the file.
pub fn write_session(session: &SimulatedSession, dir: &Path) -> Result<(), SimError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| SimError::Io { path, source }
    };
    let targets_dir = dir.join("targets");
    std::fs::create_dir_all(&targets_dir).map_err(io(&targets_dir))?;
    let input = &session.input;
    input.nominal.save(&dir.join("nominal.toml"))?;
    let cam = &session.truth.camera;
    let mut target_point = Vec::new();
    for (k, t) in input.targets.iter().enumerate() {
        let name = format!("targets/{k:03}.png");
        let frame = render_target(cam.width, cam.height, t.pixel, k as u64);
        write_png(&dir.join(&name), cam.width, cam.height, 16, &frame)?;
        target_point.push(TargetPoint {
            stage_mm: t.stage_mm.into(),
            image: Some(name),
            image_px: None,
        });
    }
    let points = |v: &[Vector3<f64>]| {
        v.iter()
            .map(|p| StagePoint {
                stage_mm: (*p).into(),
            })
            .collect()
    };
    let file = SessionFile {
        format: SESSION_FORMAT.into(),
        nominal_station: "nominal.toml".into(),
        stage_std_um: input.stage_std_mm * 1000.0,
        element: SessionElement {
            center_stage_mm: input.element_center_stage_mm,
            thickness_mm: input.thickness_mm.0,
            thickness_std_mm: input.thickness_mm.1,
            refractive_index: input.refractive_index.0,
            refractive_index_std: input.refractive_index.1,
        },
        flat_point: points(&input.flat_points_stage_mm),
        element_point: points(&input.element_points_stage_mm),
        target_point,
        screen_point: input
            .screen_points
            .iter()
            .map(|m| ScreenPoint {
                stage_mm: m.stage_mm.into(),
                screen_px: m.screen_px.into(),
            })
            .collect(),
        reference_flat: ReferenceFlat {
            acquisition: "flat/acquisition.toml".into(),
            flat_pv_nm: 63.0,
        },
    };
    let path = dir.join("session.toml");
    let text = toml::to_string(&file).unwrap_or_default();
    std::fs::write(&path, text).map_err(io(&path))
}

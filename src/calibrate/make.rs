//! Making a session: the template folder with its commented
//! `session.toml` ([`write_template`]), the target positions to visit
//! ([`plan_targets`]), and capturing one target frame from a camera into
//! the session ([`capture_target`]), appended to `session.toml` with
//! everything already there (comments included) kept.

use std::path::{Path, PathBuf};
use std::time::Duration;

use nalgebra::{Point2, Point3};

use super::centroid::{centroid_of_file, Centroid, CentroidError};
use super::frame::WorldFrame;
use super::session::{read_file, session_toml, SessionError};
use crate::acquire::camera::{Camera, CameraConfig, CameraError, Frame, TriggerMode};
use crate::formats::image_io::{self, ImageError};
use crate::optics::station::Station;

/// What went wrong making a session.
#[derive(Debug, thiserror::Error)]
pub enum MakeError {
    /// A file or folder could not be written.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The template would overwrite a session.
    #[error("{path} exists; choose an empty folder, or edit that session")]
    Exists {
        /// The existing `session.toml`.
        path: PathBuf,
    },
    /// The session could not be read, or would not read back after appending.
    #[error(transparent)]
    Session(#[from] SessionError),
    /// The camera failed.
    #[error(transparent)]
    Camera(#[from] CameraError),
    /// The frame could not be written.
    #[error(transparent)]
    Image(#[from] ImageError),
    /// The planned targets' heights do not span two levels.
    #[error("--heights {heights:?}: give two or more distinct heights (mm above the reference plane), or the targets lie in one plane")]
    Heights {
        /// The heights given.
        heights: Vec<f64>,
    },
    /// A target grid finer than the sensor can tell apart, or larger than
    /// memory holds.
    #[error("--grid {nx},{ny}: {problem}")]
    Grid {
        /// Targets across.
        nx: u32,
        /// Targets down.
        ny: u32,
        /// What is wrong, with the limit.
        problem: String,
    },
}

impl crate::outcome::Classify for MakeError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        match self {
            MakeError::Io { source, .. } => crate::outcome::io_outcome(source),
            MakeError::Exists { .. } | MakeError::Heights { .. } => Some(Outcome::Input),
            MakeError::Grid { .. } => Some(Outcome::Range),
            MakeError::Session(e) => e.outcome(),
            MakeError::Camera(e) => e.outcome(),
            MakeError::Image(e) => e.outcome(),
        }
    }
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> MakeError + '_ {
    move |source| MakeError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Writes `dir/session.toml` (each step explained in comments), `targets/`
/// and `flat/`; with `nominal`, copies it as `nominal.toml` and takes the
/// element's thickness and index from it as starting values.
///
/// # Errors
/// [`MakeError::Exists`] when `dir` already holds a session; I/O errors.
pub fn write_template(
    dir: &Path,
    nominal: Option<(&Path, &Station)>,
) -> Result<PathBuf, MakeError> {
    let path = dir.join("session.toml");
    if path.exists() {
        return Err(MakeError::Exists { path });
    }
    for sub in [dir.to_path_buf(), dir.join("targets"), dir.join("flat")] {
        std::fs::create_dir_all(&sub).map_err(io(&sub))?;
    }
    let (thickness, index) = match nominal {
        Some((file, station)) => {
            let copy = dir.join("nominal.toml");
            std::fs::copy(file, &copy).map_err(io(&copy))?;
            (
                station.element.thickness_mm,
                station.element.refractive_index,
            )
        }
        None => (10.0, 1.5),
    };
    let text = TEMPLATE
        .replace("{THICKNESS}", &format!("{thickness}"))
        .replace("{INDEX}", &format!("{index}"));
    std::fs::write(&path, text).map_err(io(&path))?;
    Ok(path)
}

const TEMPLATE: &str = r#"# A calibration session (mfd-calibration/1, spec calibration.md).
# Fill it in step by step; `mfd calibrate check THIS_FOLDER` says at any time
# what is missing or wrong. Every stage reading is the PSM's focus in the
# stage frame (the encoders' x, y, z), in mm; paths are relative to this file.
format = "mfd-calibration/1"

# Step 0: the nominal station (`mfd station` builds one from the camera and
# display profiles): sensor, pitches, resolutions and a rough geometry.
nominal_station = "nominal.toml"

# 1 sigma of one stage reading, each axis, in um (focus and encoders).
stage_std_um = 1.0

# Step 1: the element. Its centre's stage x, y becomes the world origin.
# Thickness (spherometer) and index (refractometer) with their 1 sigma
# replace the nominal station's values. Replace these starting values.
[element]
center_stage_mm = [0.0, 0.0]
thickness_mm = {THICKNESS}
thickness_std_mm = 0.002
refractive_index = {INDEX}
refractive_index_std = 0.0002

# Step 2: the reference flat where the element will stand. Focus the PSM on
# its surface (cat's-eye return) at 3 or more places spread over it, not on
# one line; one stanza per reading:
# [[flat_point]]
# stage_mm = [80.0, 70.0, 12.3456]

# Step 3 (optional): the element standing where the flat stood. Focus the
# PSM on its front at 3 or more places; none, and the element is taken to
# stand on the reference plane.
# [[element_point]]
# stage_mm = [85.0, 75.0, 12.3502]

# Step 4: a point target at the PSM's focus, seen by the camera, at 6 or
# more positions spread over the sensor at two or more heights:
# `mfd calibrate targets --nominal nominal.toml --session .` lists them;
# `mfd calibrate capture . --stage-mm X,Y,Z --camera ...` grabs the frame
# into targets/ and appends the stanza, e.g.
# [[target_point]]
# stage_mm = [90.0, 80.0, 15.0]
# image = "targets/000.png"      # or the centroid itself: image_px = [611.37, 402.81]

# Step 5 (optional): the PSM focused on marked screen pixels.
# [[screen_point]]
# stage_mm = [40.0, 260.0, 830.1]
# screen_px = [800.5, 600.5]

# Step 6: the reference flat's acquisition, one reflection, any schedule:
# `mfd measure --station nominal.toml --no-reconstruct --out flat
#  --tau-start 1 --tau-stop 64 ...` from this folder.
[reference_flat]
acquisition = "flat/acquisition/acquisition.toml"
flat_pv_nm = 63.0                # its certified flatness, nm PV (reported, not modelled)
"#;

/// A target position to visit.
#[derive(Debug, Clone, PartialEq)]
pub struct PlannedTarget {
    /// Where the PSM's focus goes: stage frame with a session frame, else
    /// the nominal station's world frame, mm.
    pub stage_mm: Point3<f64>,
    /// Its world position, mm.
    pub world_mm: Point3<f64>,
    /// Where the nominal station images it, px.
    pub expected_px: Point2<f64>,
}

/// Inset of the planned targets from the sensor's edges, a fraction of each
/// side: 52 × 39 px on the paper's 1296 × 966 sensor. That leaves room for
/// where the nominal station misplaces a spot (millimetres and tenths of a
/// degree at 825 mm are tens of pixels), and puts targets into the sensor's
/// corners, where the lens's distortion and the camera's pose are otherwise
/// extrapolated: with targets 4–12 % in from the edges the flat-reflected
/// screen points at the sensor's rim came out up to 0.079 screen px off,
/// with these 0.044 (docs/figures.md, "Calibration").
pub const TARGET_INSET: f64 = 0.04;

/// The least inset, px: the centroid's window is ±(4σ + 1) px about the
/// spot ([`crate::calibrate::centroid`]), 13 px for a spot of σ = 3 px,
/// and a binned sensor's 4 % is only 10 px.
pub const TARGET_EDGE_PX: f64 = 16.0;

/// Where the targets of height number `level` land on a `width` × `height`
/// sensor, px, row by row: even levels span the inset sensor ([`TARGET_INSET`],
/// at least [`TARGET_EDGE_PX`]) edge to edge on a `grid` (columns, rows; 2
/// or more each), odd ones sit in their gaps, so the heights fill each
/// other's.
pub fn target_layout(level: usize, grid: (u32, u32), width: u32, height: u32) -> Vec<Point2<f64>> {
    let (nx, ny) = (grid.0.max(2), grid.1.max(2));
    let at = |k: u32, n: u32, side: u32| {
        let side = f64::from(side);
        let inset = (TARGET_INSET * side).max(TARGET_EDGE_PX).min(0.5 * side);
        let f = if level % 2 == 0 {
            f64::from(k) / f64::from(n - 1)
        } else {
            (f64::from(k) + 0.5) / f64::from(n)
        };
        inset + (side - 2.0 * inset) * f
    };
    (0..ny)
        .flat_map(|row| (0..nx).map(move |col| (col, row)))
        .map(|(col, row)| Point2::new(at(col, nx, width), at(row, ny, height)))
        .collect()
}

/// Target positions landing on a `grid` (columns, rows) over the sensor
/// ([`target_layout`]: inset from the edges, every other height on the
/// grid's gaps), at each of `heights_mm` above the reference plane (world
/// z). With `frame` the positions are stage readings.
///
/// # Errors
/// [`MakeError::Heights`] unless the heights hold two distinct values;
/// [`MakeError::Grid`] for a grid finer than
/// [`max_targets_across`](super::target_grid::max_targets_across).
pub fn plan_targets(
    station: &Station,
    frame: Option<&WorldFrame>,
    heights_mm: &[f64],
    grid: (u32, u32),
) -> Result<Vec<PlannedTarget>, MakeError> {
    let distinct = heights_mm.iter().any(|h| (h - heights_mm[0]).abs() > 0.0);
    if heights_mm.is_empty() || !distinct || heights_mm.iter().any(|h| !h.is_finite()) {
        return Err(MakeError::Heights {
            heights: heights_mm.to_vec(),
        });
    }
    let cam = &station.camera;
    super::target_grid::check_grid(grid, heights_mm.len(), cam.width, cam.height)?;
    let mut out = Vec::new();
    for (level, &z) in heights_mm.iter().enumerate() {
        for px in target_layout(level, grid, cam.width, cam.height) {
            let d = cam.ray_through(px.x, px.y);
            // The ray C + t d meets the plane z = height.
            let t = (z - cam.position_mm.z) / d.z;
            if !(t.is_finite() && t > 0.0) {
                continue;
            }
            let world = cam.position_mm + d.into_inner() * t;
            let expected = cam.project(&world).unwrap_or(px);
            let stage = frame.map_or(world, |f| f.to_stage(&world));
            out.push(PlannedTarget {
                stage_mm: stage,
                world_mm: world,
                expected_px: expected,
            });
        }
    }
    Ok(out)
}

/// What one capture did.
#[derive(Debug)]
pub struct Captured {
    /// The new entry's index (`target_point[index]`).
    pub index: usize,
    /// The frame written, relative to the session folder.
    pub image: String,
    /// Its centroid, or why none was found.
    pub centroid: Result<Centroid, CentroidError>,
    /// Where the nominal station puts the target, px (with 3 or more flat
    /// points for the frame).
    pub predicted_px: Option<Point2<f64>>,
}

/// The first complete frame within `timeout`: a frame the camera delivers
/// incomplete (a GigE Vision stream that lost packets, or one started in
/// the middle of a frame) is passed over with a warning, and the next one
/// taken (triggered again when `trigger` is software).
fn next_good_frame(
    camera: &mut dyn Camera,
    trigger: TriggerMode,
    timeout: Duration,
) -> Result<Frame, CameraError> {
    let deadline = std::time::Instant::now() + timeout;
    loop {
        if trigger == TriggerMode::Software {
            camera.trigger()?;
        }
        let left = deadline.saturating_duration_since(std::time::Instant::now());
        match camera.next_frame(left) {
            Err(e @ CameraError::BadFrame { .. }) if !left.is_zero() => {
                log::warn!("{e}; taking the next frame");
            }
            other => return other,
        }
    }
}

/// Grabs one frame of the target at `stage_mm` from `camera` (configured
/// with `config`: software-triggered, or free running where the camera
/// ignores software triggers), writes it as `targets/NNN.png`,
/// appends its `[[target_point]]` to the session's `session.toml`, and
/// finds its centroid.
///
/// # Errors
/// [`MakeError`] when the session cannot be read, the camera fails, or the
/// file cannot be written; the session file is left as it was then.
pub fn capture_target(
    session: &Path,
    stage_mm: [f64; 3],
    camera: &mut dyn Camera,
    config: &CameraConfig,
    timeout: Duration,
) -> Result<Captured, MakeError> {
    let path = session_toml(session);
    let file = read_file(&path)?;
    let dir = super::session::folder_of(&path);
    let index = file.target_point.len();
    let mut n = index;
    let image = loop {
        let rel = format!("targets/{n:03}.png");
        if !dir.join(&rel).exists() {
            break rel;
        }
        n += 1;
    };
    // A camera that ignores software triggers runs free: the first frame
    // its stream delivers after `start` was exposed after the call, so it
    // shows the target where it stands now.
    let software = camera.describe().software_trigger;
    let config = CameraConfig {
        trigger: if software {
            config.trigger
        } else {
            TriggerMode::FreeRunning
        },
        ..config.clone()
    };
    camera.configure(&config)?;
    camera.start()?;
    let frame = next_good_frame(camera, config.trigger, timeout);
    if let Err(e) = camera.stop() {
        log::warn!("stopping the camera after the capture: {e}");
    }
    let frame = frame?;
    let file_path = dir.join(&image);
    if let Some(parent) = file_path.parent() {
        std::fs::create_dir_all(parent).map_err(io(parent))?;
    }
    let bits = if frame.bit_depth <= 8 { 8 } else { 16 };
    image_io::write_png(&file_path, frame.width, frame.height, bits, &frame.data)?;
    append_target(&path, stage_mm, &image)?;
    let nominal = Station::load(&dir.join(&file.nominal_station)).ok();
    let entry = format!("target_point[{index}]");
    let size = nominal.as_ref().map(|s| (s.camera.width, s.camera.height));
    let centroid = centroid_of_file(&file_path, &entry, size);
    let predicted_px = nominal.and_then(|station| {
        let flat: Vec<Point3<f64>> = file
            .flat_point
            .iter()
            .map(|p| Point3::from(p.stage_mm))
            .collect();
        let frame = WorldFrame::from_flat_points(
            &flat,
            file.element.center_stage_mm,
            file.stage_std_um * 1e-3,
        )
        .ok()?;
        station
            .camera
            .project(&frame.to_world(&Point3::from(stage_mm)))
    });
    Ok(Captured {
        index,
        image,
        centroid,
        predicted_px,
    })
}

/// The `[[target_point]]` stanza of a reading and its frame.
pub fn target_stanza(stage_mm: [f64; 3], image: &str) -> String {
    format!(
        "\n[[target_point]]\nstage_mm = [{:?}, {:?}, {:?}]\nimage = \"{image}\"\n",
        stage_mm[0], stage_mm[1], stage_mm[2]
    )
}

/// Appends a target to `session.toml` as text (comments and layout kept),
/// and restores the file if the result would not read back.
///
/// # Errors
/// [`MakeError::Io`], or [`MakeError::Session`] when the appended file
/// does not parse (the original is restored).
pub fn append_target(path: &Path, stage_mm: [f64; 3], image: &str) -> Result<(), MakeError> {
    let before = std::fs::read_to_string(path).map_err(io(path))?;
    let mut after = before.clone();
    if !after.ends_with('\n') {
        after.push('\n');
    }
    after.push_str(&target_stanza(stage_mm, image));
    std::fs::write(path, &after).map_err(io(path))?;
    if let Err(e) = read_file(path) {
        std::fs::write(path, before).map_err(io(path))?;
        return Err(e.into());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn planned_targets_land_where_planned_at_each_height() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("calib/paper-sim.toml");
        let station = Station::load(&path).unwrap();
        let planned = plan_targets(&station, None, &[0.0, 25.0, 50.0], (4, 3)).unwrap();
        assert_eq!(planned.len(), 3 * 12);
        let (w, h) = (
            f64::from(station.camera.width),
            f64::from(station.camera.height),
        );
        for (k, t) in planned.iter().enumerate() {
            assert!((t.world_mm.z - [0.0, 25.0, 50.0][k / 12]).abs() < 1e-9);
            let p = station.camera.project(&t.world_mm).unwrap();
            // Inset by TARGET_INSET (here more than TARGET_EDGE_PX): the
            // centroid window has room.
            let (lo, hi) = (TARGET_INSET - 1e-9, 1.0 - TARGET_INSET + 1e-9);
            assert!((lo * w..=hi * w).contains(&p.x), "{p}");
            assert!((lo * h..=hi * h).contains(&p.y), "{p}");
        }
        // The even heights reach the inset sensor's four corners.
        let corners = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]];
        for [cx, cy] in corners {
            let want = Point2::new(
                w * (TARGET_INSET + (1.0 - 2.0 * TARGET_INSET) * cx),
                h * (TARGET_INSET + (1.0 - 2.0 * TARGET_INSET) * cy),
            );
            for level in [0, 2] {
                let hit = planned[12 * level..12 * (level + 1)]
                    .iter()
                    .any(|t| (t.expected_px - want).norm() < 1e-6);
                assert!(hit, "no target of height {level} at corner {want}");
            }
        }
        // A small (binned) sensor keeps TARGET_EDGE_PX from every edge.
        for p in target_layout(0, (3, 3), 324, 241) {
            assert!(
                p.x >= TARGET_EDGE_PX && p.x <= 324.0 - TARGET_EDGE_PX,
                "{p}"
            );
            assert!(
                p.y >= TARGET_EDGE_PX && p.y <= 241.0 - TARGET_EDGE_PX,
                "{p}"
            );
        }
        // No two targets of one height share a pixel.
        for level in planned.chunks(12) {
            for (a, ta) in level.iter().enumerate() {
                for tb in &level[a + 1..] {
                    assert!((ta.expected_px - tb.expected_px).norm() > 1.0);
                }
            }
        }
        // With the lens's distortion (k1 = −0.12, the issue's case) the
        // targets still land on the planned pixels: ray and projection are
        // each other's inverse.
        let mut distorted = station.clone();
        distorted.camera.distortion = Some(crate::optics::station::Distortion {
            k: [-0.12, 0.0, 0.0],
            p: [0.0, 0.0],
        });
        let plain = plan_targets(&station, None, &[0.0, 10.0], (3, 3)).unwrap();
        let bent = plan_targets(&distorted, None, &[0.0, 10.0], (3, 3)).unwrap();
        for (a, b) in plain.iter().zip(&bent) {
            assert!((a.expected_px - b.expected_px).norm() < 1e-6);
        }
        assert!((plain[0].world_mm - bent[0].world_mm).norm() > 0.1);
        assert!(matches!(
            plan_targets(&station, None, &[5.0, 5.0], (3, 3)),
            Err(MakeError::Heights { .. })
        ));
    }
}
